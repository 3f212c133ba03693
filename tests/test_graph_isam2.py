"""iSAM2 back-end: same solution and covariances as batch, relinearisation policy, fusion."""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest

from linefit.line import wrap_angle
from slam.errors import EstimationError
from slam.geometry import line_to_parent, pose_compose
from slam.graph import (
    BatchSolver,
    Isam2Config,
    Isam2Solver,
    LineGraph,
    SolverConfig,
    synthetic_problem,
)
from slam.graph.linear import keys_of
from slam.models.anchored import anchored_jacobian

GAUSSIAN = SolverConfig(robust_kernel="none")
"""iSAM2 and batch reach the same optimum of the least-squares model; with a robust kernel the
two weight by different rules (IRLS per batch iteration, per block rebuild in iSAM2), so these
tests state the Gaussian cost explicitly for both."""


def to_r_alpha(g: LineGraph, P: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """A joint covariance of one pose and ``landmarks`` with the landmark blocks in (r, α)."""
    T = np.eye(P.shape[0])
    J = anchored_jacobian(g.landmarks[landmarks], g.anchors[landmarks])
    for k in range(len(landmarks)):
        T[3 + 2 * k : 5 + 2 * k, 3 + 2 * k : 5 + 2 * k] = J[k]
    return T @ P @ T.T


def close_covariances(P, Q, rel):
    """|P − Q| within ``rel`` of the scale ``√(P_ii P_jj)`` entry by entry."""
    d = np.sqrt(np.diag(Q))
    assert np.all(np.abs(P - Q) <= rel * np.outer(d, d))


def feed(src: LineGraph, solver: Isam2Solver | None) -> LineGraph:
    """Replay ``src`` pose by pose into a new graph (dead reckoning on the current estimate,
    landmarks initialised from their first measurement), updating ``solver`` after each pose.
    Landmarks keep their indices only if ``src`` numbers them in order of first observation
    (``synthetic_problem`` does); others are created when first seen."""
    g = LineGraph()
    assert src.prior_pose is not None and src.prior_cov is not None
    g.set_prior(src.prior_pose, src.prior_cov)
    n = src.n_poses
    for i in range(n):
        if i == 0:
            g.add_pose(src.prior_pose)
        else:
            g.add_pose(pose_compose(g.poses[i - 1], src.odometry_measured[i - 1]))
            g.add_odometry(i - 1, i, src.odometry_measured[i - 1], src.odometry_cov[i - 1])
        fs = np.flatnonzero(src.factor_pose == i)
        lms = src.factor_landmark[fs]
        new = np.arange(g.n_landmarks, lms.max() + 1)
        new = new[np.isin(new, lms)]
        if new.size:
            assert new[0] == g.n_landmarks, "landmarks must be numbered by first observation"
            first = np.array([fs[np.flatnonzero(lms == j)[0]] for j in new])
            z3 = np.column_stack([src.factor_z[first], np.zeros(new.size)])
            la = line_to_parent(z3, g.poses[i], normal_form=False)[0][:, :2]
            # anchors at the measured segments' mid-points seen from the current estimate
            mid = src.factor_endpoints[first].mean(axis=1)
            anchors = pose_compose(g.poses[i], np.column_stack([mid, np.zeros(new.size)]))
            g.add_landmarks(la, anchors[:, :2])
        g.add_line_factors(i, lms, src.factor_z[fs], src.factor_cov[fs], src.factor_endpoints[fs])
        if solver is not None:
            solver.update(g)
    return g


@pytest.fixture(scope="module")
def incremental():
    src = synthetic_problem(150, seed=11).graph
    solver = Isam2Solver(solver=GAUSSIAN)
    g = feed(src, solver)
    solver.optimize(g)
    batch = feed(src, None)
    BatchSolver(GAUSSIAN).solve(batch)
    return g, solver, batch


def test_isam2_reaches_the_batch_solution(incremental):
    g, _, batch = incremental
    np.testing.assert_allclose(g.poses[:, :2], batch.poses[:, :2], atol=2e-3)
    # (each graph anchors its landmarks where it first saw them: compare the lines themselves)
    # iSAM2 linearises up to its relinearisation thresholds away from the estimate
    np.testing.assert_allclose(wrap_angle(g.poses[:, 2] - batch.poses[:, 2]), 0.0, atol=3e-4)
    # (each graph anchors its landmarks where it first saw them: compare the lines themselves)
    np.testing.assert_allclose(g.landmarks_r_alpha, batch.landmarks_r_alpha, atol=2e-3)
    cost_isam = BatchSolver(GAUSSIAN).cost(g, g.poses, g.landmarks)
    cost_batch = BatchSolver(GAUSSIAN).cost(batch, batch.poses, batch.landmarks)
    assert cost_isam == pytest.approx(cost_batch, rel=1e-3)


def test_whole_estimate_read_back_equals_calculate_estimate(incremental):
    """``read_all`` (iSAM2's δ retracted onto the mirrored θ in numpy) is iSAM2's estimate."""
    g, solver, _ = incremental
    solver.read_all(g)
    est = solver.isam.calculateEstimate()
    poses = np.asarray(gtsam.utilities.extractPose2(est)).reshape(-1, 3)
    lms = np.asarray(gtsam.utilities.extractPoint2(est)).reshape(-1, 2)
    np.testing.assert_allclose(g.poses[:, :2], poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(g.poses[:, 2] - poses[:, 2]), 0.0, atol=1e-12)
    np.testing.assert_allclose(g.landmarks[:, 0], lms[:, 0], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(g.landmarks[:, 1] - lms[:, 1]), 0.0, atol=1e-12)


def test_isam2_marginals_match_batch(incremental):
    g, solver, batch = incremental
    m = BatchSolver(GAUSSIAN).marginals(batch)
    for i in (0, 75, 149):
        P_batch = m.marginalCovariance(keys_of("x", np.array([i]))[0])
        close_covariances(solver.pose_covariance(i), P_batch, 0.01)
    lms = np.array([3, 40])
    J = solver.joint_covariance(np.array([149]), lms)
    J_batch = m.jointMarginalCovariance(
        gtsam.KeyVector(keys_of("x", np.array([149])) + keys_of("l", lms))
    ).fullMatrix()
    # landmark blocks to (r, α): each graph has its own anchors
    close_covariances(to_r_alpha(g, J, lms), to_r_alpha(batch, J_batch, lms), 0.01)


def _blocks_off_isam2s_theta(solver: Isam2Solver, g: LineGraph) -> float:
    """Largest distance of a line factor's linearisation point from iSAM2's θ now."""
    poses, lms = solver._isam_theta()
    n = g.n_line_factors
    dp = solver._lin_pose.data[:n] - poses[g.factor_pose[:n]]
    dp[:, 2] = wrap_angle(dp[:, 2])
    dl = solver._lin_lm.data[:n] - lms[g.factor_landmark[:n]]
    return float(max(np.abs(dp).max(initial=0.0), np.abs(dl).max(initial=0.0)))


def test_relinearisation_policy_keeps_blocks_at_isam2s_linearisation_point(incremental):
    g, solver, _ = incremental
    st = solver.stats
    assert st.updates >= 150 and st.variables_relinearized > 0
    assert st.blocks_relinearized > 0  # blocks were rebuilt because iSAM2 moved θ
    # after optimize every block is linearised at iSAM2's θ (to rounding)
    assert _blocks_off_isam2s_theta(solver, g) < 1e-9
    # the number of factors in iSAM2 stayed one block per keyframe (+ odometry + prior)
    n_factors = sum(
        1
        for k in range(solver.isam.getFactorsUnsafe().size())
        if solver.isam.getFactorsUnsafe().exists(k)
    )
    assert n_factors == g.n_poses + g.n_odometry + 1


@pytest.mark.parametrize("in_step", [True, False])
def test_blocks_are_relinearised_in_the_update_where_isam2_relinearises(in_step):
    """With the full relinearisation check, the variables iSAM2 is about to move are foreseen
    and their blocks rebuilt at the new θ in the same update: after every update each line
    factor is linearised at iSAM2's θ.  Without it the blocks follow one update later."""
    src = synthetic_problem(120, seed=13).graph
    solver = Isam2Solver(Isam2Config(blocks_relinearized_in_step=in_step), GAUSSIAN)
    worst = 0.0

    original = solver.update

    def update(graph, force_relinearize=False):
        nonlocal worst
        result = original(graph, force_relinearize)
        worst = max(worst, _blocks_off_isam2s_theta(solver, graph))
        return result

    solver.update = update  # type: ignore[method-assign]
    g = feed(src, solver)
    st = solver.stats
    if in_step:
        assert st.relinearizations_predicted > 0
        assert st.relinearizations_unforeseen == 0
        assert worst < 1e-9
    else:
        assert st.relinearizations_predicted == 0
        assert worst > 1e-3  # a relinearisation step leaves blocks at the old θ
    batch = feed(src, None)
    BatchSolver(GAUSSIAN).solve(batch)
    solver.optimize(g)
    np.testing.assert_allclose(g.poses[:, :2], batch.poses[:, :2], atol=2e-3)


def test_coarser_thresholds_trade_accuracy_for_fewer_rebuilds():
    src = synthetic_problem(80, seed=12).graph
    fine, coarse = (
        Isam2Solver(solver=GAUSSIAN),
        Isam2Solver(
            Isam2Config(relinearize_threshold_m=0.1, relinearize_threshold_rad=0.1), GAUSSIAN
        ),
    )
    g_fine, g_coarse = feed(src, fine), feed(src, coarse)
    fine.optimize(g_fine)
    coarse.optimize(g_coarse)
    assert coarse.stats.blocks_built < fine.stats.blocks_built
    batch = feed(src, None)
    BatchSolver(GAUSSIAN).solve(batch)
    err_fine = np.max(np.abs(g_fine.poses[:, :2] - batch.poses[:, :2]))
    err_coarse = np.max(np.abs(g_coarse.poses[:, :2] - batch.poses[:, :2]))
    assert err_fine < 2e-3 and err_fine <= err_coarse


def test_exact_optimize_relinearises_to_the_batch_solution():
    """With coarse thresholds iSAM2 leaves updates below them linear; ``optimize(exact=True)``
    rebuilds it at the estimate until the Gauss-Newton step vanishes: the batch optimum."""
    src = synthetic_problem(80, seed=12).graph
    coarse = Isam2Config(
        relinearize_threshold_m=0.1,
        relinearize_threshold_rad=0.1,
        final_relinearizations=5,
        final_solver="incremental",
    )
    linear, exact = Isam2Solver(coarse, GAUSSIAN), Isam2Solver(coarse, GAUSSIAN)
    g_linear, g_exact = feed(src, linear), feed(src, exact)
    linear.optimize(g_linear)
    exact.optimize(g_exact, exact=True)
    assert linear.stats.final_relinearizations == 0
    assert 1 <= exact.stats.final_relinearizations <= coarse.final_relinearizations
    assert exact.stats.final_step < coarse.final_step_tolerance
    batch = feed(src, None)
    BatchSolver(GAUSSIAN).solve(batch)
    err_linear = np.max(np.abs(g_linear.poses[:, :2] - batch.poses[:, :2]))
    err_exact = np.max(np.abs(g_exact.poses[:, :2] - batch.poses[:, :2]))
    assert err_exact < 1e-4 < err_linear
    np.testing.assert_allclose(
        g_exact.landmarks_r_alpha, batch.landmarks_r_alpha, atol=coarse.final_step_tolerance
    )
    # the restarted iSAM2 holds the graph once: one block per keyframe, odometry, the prior
    factors = exact.isam.getFactorsUnsafe()
    n_factors = sum(1 for k in range(factors.size()) if factors.exists(k))
    assert n_factors == g_exact.n_poses + g_exact.n_odometry + 1


def test_batch_final_solver_ends_at_the_batch_solution_with_its_covariances():
    """``final_solver = "batch"``: the final convergence is the batch solver's solution of
    the whole graph (with the Cauchy kernel), not iSAM2's online estimate, which coarse
    thresholds leave centimetres away; iSAM2, rebuilt there, holds that estimate and the
    batch marginals at it."""
    src = synthetic_problem(120, seed=14).graph
    cauchy = SolverConfig(robust_kernel="cauchy", robust_k=3.0)
    coarse = dict(relinearize_threshold_m=0.1, relinearize_threshold_rad=0.1)
    online = Isam2Solver(Isam2Config(**coarse), cauchy)
    g_online = feed(src, online)
    solver = Isam2Solver(Isam2Config(**coarse, final_solver="batch"), cauchy)
    g = feed(src, solver)
    np.testing.assert_array_equal(g.poses, g_online.poses)  # the same online estimate
    solver.optimize(g, exact=True)
    assert solver.stats.final_relinearizations >= 1
    online_poses = g_online.poses.copy()
    reference = g_online  # solved in place by the batch solver, to the last digits
    assert BatchSolver(replace(cauchy, absolute_tolerance=0.0)).solve(reference).converged
    err_online = np.max(np.abs(online_poses[:, :2] - reference.poses[:, :2]))
    err = np.max(np.abs(g.poses[:, :2] - reference.poses[:, :2]))
    # the final solve stops once an iteration gains less than 0.01 in cost: a tenth of a
    # millimetre from the optimum here, where the online estimate is centimetres away
    assert err < 2e-4 and err < 0.01 * err_online
    # iSAM2 holds the final estimate
    for i in (0, 60, 119):
        p = solver.isam.calculateEstimatePose2(keys_of("x", np.array([i]))[0])
        np.testing.assert_allclose([p.x(), p.y()], g.poses[i, :2], atol=1e-9)
    # and its covariances are the batch marginals at the estimate
    at_estimate = BatchSolver(cauchy).marginals(g)
    for i in (30, 60, 119):
        key = keys_of("x", np.array([i]))[0]
        close_covariances(solver.pose_covariance(i), at_estimate.marginalCovariance(key), 0.02)


def test_landmark_fusion_rewires_isam2_blocks():
    """Split one landmark's observations over a duplicate, then merge: iSAM2 ends where batch
    ends on the merged graph, and the retired variable keeps only its weak prior."""
    src = synthetic_problem(60, seed=13).graph
    dup_of = 5
    # give the later observations of landmark 5 their own landmark (a duplicate) numbered where
    # it is first seen: build the source graph again with the duplicate inserted
    fs = np.flatnonzero(src.factor_landmark == dup_of)
    late = fs[len(fs) // 2 :]
    first_late = int(src.factor_pose[late[0]])
    lm = src.factor_landmark.copy()
    seen_before = np.unique(lm[src.factor_pose < first_late])
    dup = int(seen_before.max()) + 1  # the next new index at that pose
    lm[lm >= dup] += 1
    lm[late] = dup
    src2 = LineGraph()
    assert src.prior_pose is not None and src.prior_cov is not None
    src2.set_prior(src.prior_pose, src.prior_cov)
    for p in src.poses:
        src2.add_pose(p)
    for e in range(src.n_odometry):
        src2.add_odometry(e, e + 1, src.odometry_measured[e], src.odometry_cov[e])
    anchors = np.insert(src.anchors, dup, src.anchors[dup_of], axis=0)
    la = np.insert(src.landmarks_r_alpha, dup, src.landmarks_r_alpha[dup_of], axis=0)
    src2.add_landmarks(la, anchors)
    src2.add_line_factors(0, lm[:0], src.factor_z[:0], src.factor_cov[:0], src.factor_endpoints[:0])
    for i in range(src.n_poses):
        f = np.flatnonzero(src.factor_pose == i)
        src2.add_line_factors(i, lm[f], src.factor_z[f], src.factor_cov[f], src.factor_endpoints[f])
    src = src2
    solver = Isam2Solver(solver=GAUSSIAN)
    g = feed(src, solver)
    assert g.n_landmarks == src.n_landmarks
    g.merge_landmarks(dup_of, dup)
    solver.update(g)
    solver.optimize(g)
    assert solver.stats.blocks_merged == len(np.unique(g.factor_pose[late]))
    batch = feed(src, None)
    batch.merge_landmarks(dup_of, dup)
    BatchSolver(GAUSSIAN).solve(batch)
    np.testing.assert_allclose(g.poses[:, :2], batch.poses[:, :2], atol=2e-3)
    np.testing.assert_allclose(
        g.landmarks_r_alpha[dup_of], batch.landmarks_r_alpha[dup_of], atol=2e-3
    )
    assert not g.landmark_alive[dup] and np.all(g.factor_landmark != dup)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"relinearize_threshold_m": 0.0},
        {"relinearize_threshold_rad": float("nan")},
        {"final_relinearizations": -1},
        {"final_step_tolerance": 0.0},
    ],
)
def test_invalid_isam2_settings_are_rejected(kwargs):
    from linefit import ConfigError

    with pytest.raises(ConfigError, match=next(iter(kwargs))):
        Isam2Config(**kwargs)


def test_joint_pose_covariance_of_both_backends_matches_the_marginals(incremental):
    """Two poses' joint covariance: iSAM2's and the batch back-end's equal GTSAM's marginals;
    the batch back-end compounds poses added since its last solve along their odometry, which
    is exact when nothing else constrains them."""
    from slam.graph.backend import BatchBackend, Isam2Backend
    from slam.graph.config import Isam2Config

    g, solver, batch = incremental
    pair = np.array([20, 140])
    keys = gtsam.KeyVector(keys_of("x", pair))
    P_exact = BatchSolver(GAUSSIAN).marginals(batch).jointMarginalCovariance(keys).fullMatrix()
    backend_b = BatchBackend(GAUSSIAN)
    close_covariances(backend_b.joint_pose_covariance(batch, pair), P_exact, 1e-6)
    backend_i = Isam2Backend(Isam2Config(), GAUSSIAN)
    backend_i.solver = solver  # the fixture's iSAM2, fed pose by pose
    close_covariances(backend_i.joint_pose_covariance(g, pair), P_exact, 0.01)
    # three poses more, on odometry only and not solved: compounded from pose 149
    longer = feed(synthetic_problem(150, seed=11).graph, None)
    BatchSolver(GAUSSIAN).solve(longer)
    backend_b = BatchBackend(GAUSSIAN)
    backend_b.joint_pose_covariance(longer, pair)  # marginals of the 150 solved poses
    step, Q = np.array([0.5, 0.1, 0.2]), np.diag([0.01, 0.004, 0.002])
    for i in range(150, 153):
        longer.add_pose(pose_compose(longer.poses[i - 1], step))
        longer.add_odometry(i - 1, i, step, Q)
    new_pair = np.array([20, 152])
    P_exact = (
        BatchSolver(GAUSSIAN)
        .marginals(longer)
        .jointMarginalCovariance(gtsam.KeyVector(keys_of("x", new_pair)))
        .fullMatrix()
    )
    close_covariances(backend_b.joint_pose_covariance(longer, new_pair), P_exact, 1e-6)
    with pytest.raises(EstimationError, match="distinct"):
        backend_b.joint_pose_covariance(longer, np.array([3, 3]))


def test_final_weight_refresh_gives_the_covariances_at_the_estimate():
    """With the Cauchy kernel iSAM2's blocks carry IRLS weights from the linearisation point
    θ, which lags the estimate: its marginals are those of the graph weighted at θ (larger).
    The final weight refresh rebuilds iSAM2 at the estimate: its marginals then equal the
    batch marginals of the graph weighted at its estimate."""
    src = synthetic_problem(120, seed=13).graph
    cauchy = SolverConfig(robust_kernel="cauchy", robust_k=3.0)
    coarse = dict(relinearize_threshold_m=0.03, relinearize_threshold_rad=0.03)
    traces = {}
    for refresh in (False, True):
        config = Isam2Config(**coarse, final_weight_refresh=refresh, final_solver="incremental")
        solver = Isam2Solver(config, cauchy)
        g = feed(src, solver)
        solver.optimize(g, exact=True)
        assert solver.stats.final_relinearizations == int(refresh)
        at_estimate = BatchSolver(cauchy).marginals(g)
        ratio = [
            np.trace(solver.pose_covariance(i))
            / np.trace(at_estimate.marginalCovariance(keys_of("x", np.array([i]))[0]))
            for i in (30, 60, 119)
        ]
        traces[refresh] = np.array(ratio)
    assert np.all(traces[False] > 1.05)  # weights at θ: less information
    np.testing.assert_allclose(traces[True], 1.0, atol=0.02)


def test_rebuilt_blocks_from_templates_equal_blocks_stacked_by_gtsam():
    """A keyframe block rebuilt by overwriting its last stacked factor (same landmarks) is the
    block GTSAM's stacking gives, bit for bit."""
    g = synthetic_problem(120, seed=6).graph
    solver = Isam2Solver()
    solver.update(g)  # every block built once: the templates
    poses = list(range(g.n_poses))
    assert set(solver._templates) == set(poses)
    rng = np.random.default_rng(1)
    solver._theta_poses.data[:] += rng.normal(scale=1e-2, size=solver._theta_poses.data.shape)
    solver._theta_lms.data[:] += rng.normal(scale=1e-2, size=solver._theta_lms.data.shape)
    from_templates = solver._build_blocks(g, poses)
    solver._templates.clear()
    stacked = solver._build_blocks(g, poses)
    for a, b in zip(from_templates, stacked, strict=True):
        assert list(a.keys()) == list(b.keys())
        ja, jb = a.toJacobian(), b.toJacobian()
        np.testing.assert_array_equal(ja.augmentedJacobian(), jb.augmentedJacobian())


class _Indeterminate:
    """An ``ISAM2`` whose next ``update`` fails as GTSAM's Cholesky does on a stiff system."""

    def __init__(self, isam: gtsam.ISAM2, message: str) -> None:
        self._isam = isam
        self._message = message

    def update(self, *args, **kwargs):
        raise RuntimeError(self._message)

    def __getattr__(self, name):
        return getattr(self._isam, name)


class _FailsOnce(Isam2Solver):
    """Its ``at``-th update meets an ``_Indeterminate`` iSAM2."""

    def __init__(self, at: int, message: str) -> None:
        super().__init__(solver=GAUSSIAN)
        self.at = at
        self.message = message
        self.calls = 0

    def update(self, graph, force_relinearize=False):
        self.calls += 1
        if self.calls == self.at:
            self.isam = _Indeterminate(self.isam, self.message)
        return super().update(graph, force_relinearize)


INDETERMINATE = "\nIndeterminate linear system detected while working near variable 7 (Symbol: x7)."


def test_indeterminate_cholesky_falls_back_to_qr(incremental):
    """An update that GTSAM's Cholesky finds indeterminate rebuilds iSAM2 with QR from the graph
    (once, for the rest of the run): the run goes on and ends at the batch solution."""
    _, _, batch = incremental
    src = synthetic_problem(150, seed=11).graph
    solver = _FailsOnce(at=60, message=INDETERMINATE)
    g = feed(src, solver)
    solver.optimize(g)
    assert solver.stats.qr_fallbacks == 1
    assert solver.isam.params().getFactorization() == "QR"
    np.testing.assert_allclose(g.poses[:, :2], batch.poses[:, :2], atol=2e-3)
    np.testing.assert_allclose(wrap_angle(g.poses[:, 2] - batch.poses[:, 2]), 0.0, atol=3e-4)


@pytest.mark.parametrize("message", [INDETERMINATE, "\nsome other GTSAM failure"])
def test_other_or_repeated_isam2_failures_are_estimation_errors(message):
    src = synthetic_problem(40, seed=12).graph
    solver = _FailsOnce(at=10, message=message)
    if message == INDETERMINATE:
        solver.stats.qr_fallbacks = 1  # already on QR: no second fallback
    with pytest.raises(EstimationError, match="iSAM2 update failed"):
        feed(src, solver)
