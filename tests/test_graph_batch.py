"""Batch solver: convergence, invariance, fast path vs CustomFactor, covariances, kernels."""

from __future__ import annotations

import copy
import signal
from dataclasses import replace

import gtsam
import numpy as np
import pytest

from linefit.line import wrap_angle
from slam.errors import EstimationError
from slam.geometry import line_to_parent, pose_between, pose_compose, pose_log
from slam.graph import BatchSolver, LineGraph, SolverConfig, line_custom_factor, synthetic_problem
from slam.graph.linear import keys_of, native_odometry_factors
from slam.models.anchored import anchored_from_r_alpha

GAUSSIAN = SolverConfig(robust_kernel="none")
"""The least-squares model itself (the default Cauchy kernel's IRLS changes the cost and its
convergence): χ² of the minimum, chart invariance and the CustomFactor reference are properties
of the Gaussian cost."""


def pose_errors(est, truth):
    return pose_log(pose_between(truth, est))


@pytest.mark.parametrize("linear_solver", ["sparse", "gtsam"])
def test_converges_from_dead_reckoning_to_the_optimum(linear_solver):
    p = synthetic_problem(250, seed=1)
    g = p.graph
    st = BatchSolver(replace(GAUSSIAN, linear_solver=linear_solver)).solve(g)
    assert st.converged and st.iterations <= 6
    # the same problem solved from the truth reaches the same minimum
    q = synthetic_problem(250, seed=1).graph
    q.poses[:] = p.poses_true
    q.landmarks[:] = anchored_from_r_alpha(p.landmarks_true, q.anchors)
    st_true = BatchSolver(GAUSSIAN).solve(q)
    assert st.final_cost == pytest.approx(st_true.final_cost, rel=1e-6)
    np.testing.assert_allclose(g.poses, q.poses, atol=1e-5)
    # and χ² of the minimum is about its degrees of freedom (2F + 3E + 3 − 3N − 2M) / 2
    dof = 2 * g.n_line_factors + 3 * g.n_odometry + 3 - 3 * g.n_poses - 2 * g.n_landmarks
    assert 2 * st.final_cost == pytest.approx(dof, rel=5 * np.sqrt(2 / dof))


def test_solution_is_invariant_to_where_the_world_origin_is():
    """The anchored chart: the same problem 1 km away converges the same way."""
    base = synthetic_problem(250, seed=1)
    BatchSolver(GAUSSIAN).solve(base.graph)
    off = np.array([1000.0, -1000.0, 0.7])
    p = synthetic_problem(250, seed=1)
    g = p.graph
    lra = g.landmarks_r_alpha.copy()
    g.poses[:] = pose_compose(off, g.poses)
    assert g.prior_pose is not None
    g.set_prior(pose_compose(off, g.prior_pose), g.prior_cov)
    g.anchors[:] = pose_compose(off, np.column_stack([g.anchors, np.zeros(len(lra))]))[:, :2]
    lra_w = line_to_parent(np.column_stack([lra, np.zeros(len(lra))]), off, normal_form=False)[0]
    g.landmarks[:] = anchored_from_r_alpha(lra_w[:, :2], g.anchors)
    st = BatchSolver(GAUSSIAN).solve(g)
    assert st.converged and st.iterations <= 6
    back = pose_compose(np.array(pose_between(off, np.zeros(3))), g.poses)
    np.testing.assert_allclose(back[:, :2], base.graph.poses[:, :2], atol=1e-6)


def test_fast_path_and_custom_factor_reach_the_same_solution():
    p = synthetic_problem(40, seed=4)
    g = p.graph
    # reference: CustomFactors + native odometry, GTSAM's own Levenberg-Marquardt
    nfg = native_odometry_factors(g)
    kx = keys_of("x", g.factor_pose)
    kl = keys_of("l", g.factor_landmark)
    for f in range(g.n_line_factors):
        nfg.add(
            line_custom_factor(
                kx[f], kl[f], g.anchors[g.factor_landmark[f]], g.factor_z[f], g.factor_cov[f]
            )
        )
    values = gtsam.Values()
    for key, pose in zip(keys_of("x", np.arange(g.n_poses)), g.poses, strict=True):
        values.insert(key, gtsam.Pose2(*pose))
    for key, v in zip(keys_of("l", np.arange(g.n_landmarks)), g.landmarks, strict=True):
        values.insert(key, gtsam.Point2(*v))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    ref = gtsam.LevenbergMarquardtOptimizer(nfg, values, params).optimize()
    ref_poses = gtsam.utilities.extractPose2(ref)
    st = BatchSolver(
        SolverConfig(
            robust_kernel="none",
            relative_tolerance=1e-12,
            absolute_tolerance=0.0,
            step_tolerance=1e-10,
        )
    ).solve(g)
    assert st.final_cost == pytest.approx(nfg.error(ref), rel=1e-8)
    np.testing.assert_allclose(g.poses[:, :2], ref_poses[:, :2], atol=1e-7)
    np.testing.assert_allclose(wrap_angle(g.poses[:, 2] - ref_poses[:, 2]), 0.0, atol=1e-8)
    # the linearised systems agree too: same marginal of the last pose
    m_ref = gtsam.Marginals(nfg, ref).marginalCovariance(keys_of("x", np.array([39]))[0])
    m_fast = BatchSolver(GAUSSIAN).marginals(g).marginalCovariance(keys_of("x", np.array([39]))[0])
    np.testing.assert_allclose(m_fast, m_ref, rtol=1e-5)


def test_marginals_are_consistent_monte_carlo():
    """Pose NEES of the last pose and a middle pose over seeded runs within χ² bounds."""
    nees = []
    for seed in range(40):
        p = synthetic_problem(25, seed=100 + seed, sigma_r_m=0.02, sigma_alpha_rad=0.01)
        g = p.graph
        BatchSolver().solve(g)
        m = BatchSolver().marginals(g)
        for i in (12, 24):
            e = pose_errors(g.poses[i], p.poses_true[i])
            P = m.marginalCovariance(keys_of("x", np.array([i]))[0])
            nees.append(float(e @ np.linalg.solve(P, e)))
    nees = np.array(nees)
    # 80 samples of χ²₃ (two per run, correlated): a generous 99 % band on their mean
    assert 3.0 * 0.72 < nees.mean() < 3.0 * 1.33


@pytest.mark.parametrize("linear_solver", ["sparse", "gtsam"])
def test_robust_kernel_resists_an_outlier(linear_solver):
    clean = synthetic_problem(60, seed=7)
    BatchSolver().solve(clean.graph)
    results = {}
    for kernel in ("none", "huber", "cauchy"):
        p = synthetic_problem(60, seed=7)
        p.graph.factor_z[100, 0] += 1.0  # one gross outlier (≈ 100 σ)
        cfg = SolverConfig(robust_kernel=kernel, robust_k=2.0, linear_solver=linear_solver)
        BatchSolver(cfg).solve(p.graph)
        results[kernel] = np.max(np.abs(p.graph.poses[:, :2] - clean.graph.poses[:, :2]))
    assert results["none"] > 0.02
    assert results["huber"] < 0.3 * results["none"]
    assert results["cauchy"] < 0.1 * results["none"]


def test_gauge_is_required_and_empty_graph_is_fine():
    g = LineGraph()
    assert BatchSolver().solve(g).reason == "empty graph"
    g.add_pose(np.zeros(3))
    with pytest.raises(EstimationError, match="prior"):
        BatchSolver().solve(g)


def test_revert_merges_restores_the_graph_exactly():
    g = synthetic_problem(20, seed=3).graph
    before = (g.factor_landmark.copy(), g.landmark_alive.copy(), g.landmark_merged_into.copy())
    n_log = len(g.merge_log)
    first = g.merge_landmarks(0, 1)
    g.merge_landmarks(2, 3)
    g.unmerge(g.merge_log[n_log])  # an undo record among the reverted ones
    assert first.size > 0 and g.landmark_alive[1] and not g.landmark_alive[3]
    g.revert_merges(n_log)
    assert len(g.merge_log) == n_log
    np.testing.assert_array_equal(g.factor_landmark, before[0])
    np.testing.assert_array_equal(g.landmark_alive, before[1])
    np.testing.assert_array_equal(g.landmark_merged_into, before[2])
    with pytest.raises(EstimationError, match="merge log"):
        g.revert_merges(n_log + 1)


@pytest.mark.parametrize("linear_solver", ["sparse", "gtsam"])
def test_solve_with_held_poses_returns_to_the_full_optimum(linear_solver):
    """Poses before ``free_from`` are constants; at the full optimum they are the right ones,
    so a perturbed rest of the graph must come back to the full optimum exactly."""
    p = synthetic_problem(40, seed=11)
    g = p.graph
    solver = BatchSolver(
        SolverConfig(
            robust_kernel="none",
            relative_tolerance=1e-14,
            absolute_tolerance=0.0,
            step_tolerance=1e-11,
            linear_solver=linear_solver,
        )
    )
    solver.solve(g)
    best_poses, best_landmarks = g.poses.copy(), g.landmarks.copy()
    k = 25
    rng = np.random.default_rng(0)
    g.poses[k:] += rng.normal(0.0, [0.05, 0.05, 0.01], size=(g.n_poses - k, 3))
    seen_late = np.unique(g.factor_landmark[g.factor_pose >= k])
    g.landmarks[seen_late] += rng.normal(0.0, [0.03, 0.005], size=(seen_late.size, 2))
    moved = g.landmarks.copy()
    stats = solver.solve(g, free_from=k)
    assert stats.converged
    np.testing.assert_array_equal(g.poses[:k], best_poses[:k])  # held, bit for bit
    only_early = np.setdiff1d(np.arange(g.n_landmarks), seen_late)
    np.testing.assert_array_equal(g.landmarks[only_early], moved[only_early])
    np.testing.assert_allclose(g.poses[k:, :2], best_poses[k:, :2], atol=1e-7)
    np.testing.assert_allclose(wrap_angle(g.poses[k:, 2] - best_poses[k:, 2]), 0.0, atol=1e-8)
    np.testing.assert_allclose(g.landmarks[seen_late], best_landmarks[seen_late], atol=1e-7)
    with pytest.raises(EstimationError, match="free_from"):
        solver.solve(g, free_from=g.n_poses)


def test_landmark_prior_factors_keep_the_normal_equations():
    """Factors from held poses summed per landmark: the same AᵀA and Aᵀb (a rank-deficient
    landmark keeps its factors one by one)."""
    from slam.graph.linear import UNIT2, landmark_prior_factors

    rng = np.random.default_rng(3)
    lm = np.array([4, 4, 7, 4, 9, 7, 9])
    A = rng.normal(size=(7, 2, 2))
    A[lm == 9] = np.array([[1.0, 2.0], [2.0, 4.0]])  # landmark 9: rank one, twice
    b = rng.normal(size=(7, 2))

    def normal_equations(factors):
        gfg = gtsam.GaussianFactorGraph()
        for f in factors:
            gfg.push_back(f)
        ordering = gtsam.Ordering()
        for key in keys_of("l", np.array([4, 7, 9])):
            ordering.push_back(key)
        A_full, b_full = gfg.jacobian(ordering)
        return A_full.T @ A_full, A_full.T @ b_full

    one_by_one = [
        gtsam.JacobianFactor(k, a, r, UNIT2) for k, a, r in zip(keys_of("l", lm), A, b, strict=True)
    ]
    summed = landmark_prior_factors(lm, A, b)
    assert len(summed) == 2 + 2  # landmarks 4 and 7 summed, 9's two factors kept
    H1, g1 = normal_equations(one_by_one)
    H2, g2 = normal_equations(summed)
    np.testing.assert_allclose(H2, H1, atol=1e-12)
    np.testing.assert_allclose(g2, g1, atol=1e-12)


def test_packed_factors_hold_the_same_rows():
    """Line factors paired per pose and odometry paired along the chain: the same whitened
    system ``[A | b]`` row for row as one factor each (breaks in the chain, a pose seeing one
    landmark twice and odd counts included)."""
    from slam.graph.factors import LineLinearization
    from slam.graph.linear import (
        UNIT2,
        UNIT3,
        line_factor_groups,
        line_jacobian_factors,
        odometry_jacobian_factors,
    )

    rng = np.random.default_rng(4)
    pose = np.array([0, 0, 0, 1, 2, 2, 2, 2, 3, 3])
    lm = np.array([0, 1, 2, 0, 1, 1, 2, 3, 0, 3])  # pose 2 sees landmark 1 twice in a row
    n = pose.size
    lin = LineLinearization(
        rng.normal(size=(n, 2, 3)),
        rng.normal(size=(n, 2, 2)),
        rng.normal(size=(n, 2)),
        np.zeros((n, 2)),
        np.ones(n),
    )
    first = np.array([0, 1, 2, 4, 5, 6, 8])
    second = np.array([1, 2, 3, 5, 6, 7, 9])
    A1, A2, b = rng.normal(size=(7, 3, 3)), rng.normal(size=(7, 3, 3)), rng.normal(size=(7, 3))

    def system(factors, keys):
        gfg = gtsam.GaussianFactorGraph()
        for f in factors:
            gfg.push_back(f)
        ordering = gtsam.Ordering()
        for key in keys:
            ordering.push_back(key)
        return gfg.jacobian(ordering)

    keys = keys_of("l", np.arange(4)) + keys_of("x", np.arange(4))
    single = [
        gtsam.JacobianFactor(kx, ax, kl, al, r, UNIT2)
        for kx, ax, kl, al, r in zip(
            keys_of("x", pose), lin.A_pose, keys_of("l", lm), lin.A_landmark, lin.b, strict=True
        )
    ]
    packed = line_jacobian_factors(pose, lm, lin)
    starts, paired = line_factor_groups(pose, lm)
    # pose 2 sees landmark 1 twice in a row: 4 stays alone, 5 pairs with 6, 7 alone
    assert starts.tolist() == [0, 2, 3, 4, 5, 7, 8] and len(packed) == 7
    assert paired.tolist() == [True, False, False, False, True, False, True]
    for a, c in zip(system(single, keys), system(packed, keys), strict=True):
        np.testing.assert_array_equal(c, a)
    single = [
        gtsam.JacobianFactor(ka, aa, kb, ab, r, UNIT3)
        for ka, aa, kb, ab, r in zip(
            keys_of("x", first), A1, keys_of("x", second), A2, b, strict=True
        )
    ]
    packed = odometry_jacobian_factors(first, second, A1, A2, b)
    assert len(packed) == 5  # 0→1→2 | 2→3 | 4→5→6 | 6→7 | 8→9
    keys = keys_of("x", np.arange(10))
    for a, c in zip(system(single, keys), system(packed, keys), strict=True):
        np.testing.assert_array_equal(c, a)


def test_solve_stops_once_an_iteration_gains_less_than_the_absolute_tolerance():
    """The first iteration whose cost decrease is below ``absolute_tolerance`` ends the solve;
    without it the same iterations come first, and the solve gains less than the tolerance
    after them."""
    p = synthetic_problem(80, seed=6)
    tight = SolverConfig(robust_kernel="cauchy", relative_tolerance=0.0, absolute_tolerance=0.0)
    runs = {}
    for tol in (0.0, 0.5):
        g = copy.deepcopy(p.graph)
        g.poses[1:] += np.random.default_rng(2).normal(0.0, [0.05, 0.05, 0.02], (g.n_poses - 1, 3))
        st = BatchSolver(replace(tight, absolute_tolerance=tol)).solve(g)
        runs[tol] = (st, g.poses.copy())
    st, _ = runs[0.5]
    assert st.reason == "decrease below absolute tolerance"
    costs = [st.initial_cost] + [c for c, _, accepted in st.history if accepted]
    gains = -np.diff(costs)
    assert gains[-1] <= 0.5 and np.all(gains[:-1] > 0.5)
    full, _ = runs[0.0]
    assert full.iterations > st.iterations
    assert full.history[: len(st.history)] == st.history  # the same steps up to there
    assert 0.0 <= st.final_cost - full.final_cost < 0.5


@pytest.mark.parametrize("linear_solver", ["sparse", "gtsam"])
def test_solve_stops_when_the_caller_says_so(linear_solver):
    """``stop`` sees every accepted step's estimate and can end the solve there."""
    g = synthetic_problem(60, seed=5).graph
    seen = []

    def stop(iterations, poses, landmarks):
        seen.append((iterations, poses.shape, landmarks.shape))
        return iterations == 2

    stats = BatchSolver(replace(GAUSSIAN, linear_solver=linear_solver)).solve(g, stop=stop)
    assert stats.reason == "stopped" and stats.iterations == 2 and not stats.converged
    assert [s[0] for s in seen] == [1, 2]
    assert seen[0][1] == (g.n_poses, 3) and seen[0][2] == (g.n_landmarks, 2)


def test_pairing_order_groups_poses_and_spreads_repeated_landmarks():
    from slam.graph.linear import line_factor_groups, pairing_order

    pose = np.array([3, 1, 3, 1, 3, 2, 3, 1])
    lm = np.array([7, 4, 7, 5, 8, 4, 9, 4])
    o = pairing_order(pose, lm)
    assert sorted(o.tolist()) == list(range(8))
    assert pose[o].tolist() == sorted(pose.tolist())  # grouped by pose
    # pose 3 sees landmark 7 twice: not next to each other, so all four pair up
    assert lm[o][pose[o] == 3].tolist() == [7, 8, 9, 7]
    _, paired = line_factor_groups(pose[o], lm[o])
    assert (~paired).sum() == 2  # pose 1: (4, 5) then 4 alone; pose 2: alone


@pytest.mark.parametrize("free_from", [0, 120])
@pytest.mark.parametrize("lam", [0.0, 1e-2])
def test_sparse_normal_equations_solve_the_same_system_as_gtsam(free_from, lam):
    """One (damped) step of the sparse LDLᵀ path equals GTSAM's elimination to rounding."""
    from slam.graph.batch import BatchSolver as Solver

    g = synthetic_problem(250, seed=3).graph
    solver = Solver(SolverConfig())
    lms = solver.active_landmarks(g)
    solved = None
    if free_from:
        seen = np.zeros(g.n_landmarks, dtype=bool)
        seen[g.factor_landmark[g.factor_pose >= free_from]] = True
        lms = lms[seen[lms]]
        solved = np.zeros(g.n_landmarks, dtype=bool)
        solved[lms] = True
    system, parts = solver._region(g, free_from, lms, solved)
    values, lin, cost = solver._linearize_point(g, g.poses, g.landmarks, parts)
    system.assemble(values)
    if solved is None:  # the cost of every factor, as cost() sums it
        assert cost == solver.cost(g, g.poses, g.landmarks)
    gfg, lin_ref, used = solver._linearize(g, g.poses, g.landmarks, free_from, solved)
    np.testing.assert_array_equal(parts["used"], used)
    assert lin is not None and lin_ref is not None
    np.testing.assert_array_equal(lin.b, lin_ref.b)
    scale = solver.damping_scale(g, g.poses, g.landmarks, lin, used)
    damping = lam * np.r_[scale[1][lms].ravel(), scale[0][free_from:].ravel()]
    delta = system.solve(damping if lam else None)
    ref_graph = solver._damped(gfg, lms, scale[0], scale[1], lam, free_from) if lam else gfg
    ref = ref_graph.optimize(solver._ordering(gfg))
    ref_vec = np.asarray(ref.vector())
    np.testing.assert_allclose(delta, ref_vec, rtol=0, atol=1e-10 * np.max(np.abs(ref_vec)))
    # the model's decrease of the undamped system, as GTSAM's error() gives it
    predicted = float(gfg.error(ref.scale(0.0)) - gfg.error(ref))
    assert system.predicted_decrease(delta) == pytest.approx(predicted, rel=1e-9)


def test_sparse_and_gtsam_solves_agree_and_singular_systems_raise():
    a = synthetic_problem(200, seed=4).graph
    b = synthetic_problem(200, seed=4).graph
    st_a = BatchSolver(SolverConfig(linear_solver="sparse")).solve(a)
    st_b = BatchSolver(SolverConfig(linear_solver="gtsam")).solve(b)
    assert st_a.iterations == st_b.iterations and st_a.reason == st_b.reason
    np.testing.assert_allclose(a.poses, b.poses, atol=1e-9)
    np.testing.assert_allclose(a.landmarks, b.landmarks, atol=1e-9)
    c = synthetic_problem(200, seed=4).graph  # another elimination order, the same solution
    BatchSolver(SolverConfig(ordering="metis", linear_solver="sparse")).solve(c)
    np.testing.assert_allclose(c.poses, a.poses, atol=1e-9)
    # a pose without any factor: its block of the normal equations is zero
    for linear_solver, match in (("sparse", "at pose 20"), ("gtsam", "has no factor")):
        g = synthetic_problem(20, seed=5).graph
        g.add_pose(g.poses[-1])
        with pytest.raises(EstimationError, match=match):
            BatchSolver(SolverConfig(linear_solver=linear_solver)).solve(g)


@pytest.mark.parametrize("linear_solver", ["sparse", "gtsam"])
def test_a_pose_determined_by_one_line_only_is_an_indeterminant_system(linear_solver):
    """Rank 2 of 3 (a pose seeing one line, no odometry): an error, not a wild step."""
    g = synthetic_problem(20, seed=5).graph
    i = g.add_pose(g.poses[-1])
    f = np.flatnonzero(g.factor_pose == i - 1)[:1]
    ends = np.array([[[0.0, 0.0], [1.0, 1.0]]])
    for _ in range(2):  # the same line twice is still rank 2
        g.add_line_factors(i, g.factor_landmark[f], g.factor_z[f], g.factor_cov[f], ends)
    match = "at pose 20" if linear_solver == "sparse" else "could not be solved"
    with pytest.raises(EstimationError, match=match):
        BatchSolver(SolverConfig(linear_solver=linear_solver)).solve(g)


@pytest.mark.parametrize("free_from", [0, 100])
def test_sparse_and_gtsam_take_the_same_damped_steps(free_from):
    """From a bad start (rejected steps, Levenberg-Marquardt damping) both paths agree."""
    runs = []
    for linear_solver in ("sparse", "gtsam"):
        g = synthetic_problem(200, seed=4).graph
        BatchSolver(SolverConfig()).solve(g)
        rng = np.random.default_rng(1)
        g.poses[free_from + 1 :] += rng.normal(0.0, [3.0, 3.0, 1.5], (199 - free_from, 3))
        held = g.poses[:free_from].copy()
        st = BatchSolver(SolverConfig(linear_solver=linear_solver)).solve(g, free_from=free_from)
        np.testing.assert_array_equal(g.poses[:free_from], held)
        runs.append((st, g))
    (st_s, g_s), (st_g, g_g) = runs
    accepted = [h[2] for h in st_s.history]
    assert not all(accepted)  # the damped path was taken
    assert accepted == [h[2] for h in st_g.history]
    np.testing.assert_allclose([h[1] for h in st_s.history], [h[1] for h in st_g.history])
    np.testing.assert_allclose(
        [h[0] for h in st_s.history], [h[0] for h in st_g.history], rtol=1e-9
    )
    np.testing.assert_allclose(g_s.poses, g_g.poses, atol=1e-9)
    np.testing.assert_allclose(g_s.landmarks, g_g.landmarks, atol=1e-9)


@pytest.mark.parametrize("free_from", [0, 120])
def test_reused_graph_holds_the_factors_a_new_one_would(free_from):
    """Linearising into the last iteration's factors (``ReusableGraph``) gives the graph a new
    build gives, bit for bit, and the same graph object; another structure gives a new graph."""
    from slam.graph.linear import ReusableGraph

    g = synthetic_problem(250, seed=3).graph
    solver = BatchSolver(SolverConfig())
    solved = None
    if free_from:
        solved = np.zeros(g.n_landmarks, dtype=bool)
        solved[g.factor_landmark[g.factor_pose >= free_from]] = True
    reuse = ReusableGraph()
    first, _, _ = solver._linearize(g, g.poses, g.landmarks, free_from, solved, reuse)
    rng = np.random.default_rng(0)
    poses = g.poses + rng.normal(scale=1e-2, size=g.poses.shape)
    landmarks = g.landmarks + rng.normal(scale=1e-2, size=g.landmarks.shape)
    again, _, _ = solver._linearize(g, poses, landmarks, free_from, solved, reuse)
    fresh, _, _ = solver._linearize(g, poses, landmarks, free_from, solved)
    assert again is first and fresh is not first
    assert again.size() == fresh.size()
    for i in range(fresh.size()):
        a, f = again.at(i), fresh.at(i)
        assert list(a.keys()) == list(f.keys())
        np.testing.assert_array_equal(a.augmentedJacobian(), f.augmentedJacobian())
    # a different structure (fewer poses free) is a new graph
    other, _, _ = solver._linearize(g, poses, landmarks, free_from + 10, None, reuse)
    assert other is not first


@pytest.mark.parametrize("free_from", [0, 120])
def test_linearisation_gives_the_cost_of_its_factors(free_from):
    """The cost a linearisation reports (the trial point's, reused when the step is accepted)
    is the number ``cost`` gives for the same factors, exactly."""
    g = synthetic_problem(250, seed=3).graph
    rng = np.random.default_rng(2)
    g.poses[:] += rng.normal(scale=0.05, size=g.poses.shape)
    solver = BatchSolver(SolverConfig())
    if free_from:
        solved = np.zeros(g.n_landmarks, dtype=bool)
        solved[g.factor_landmark[g.factor_pose >= free_from]] = True
        point = solver._linear_batches(g, g.poses, g.landmarks, free_from, solved)
        expected = solver.cost(
            g,
            g.poses,
            g.landmarks,
            line_factors=np.flatnonzero(solved[g.factor_landmark]),
            odometry=np.flatnonzero(g.odometry_second >= free_from),
            with_prior=False,
        )
    else:
        point = solver._linear_batches(g, g.poses, g.landmarks)
        expected = solver.cost(g, g.poses, g.landmarks)
    assert point.cost == expected


@pytest.mark.parametrize("method", ["colamd", "metis"])
def test_fill_reducing_order_covers_uncoupled_variables(method):
    """Every variable once, those no factor couples included (METIS alone cannot take them)."""
    from slam.graph.sparse import fill_reducing_order

    dims = np.full(6, 3)
    a, b = np.array([0, 1, 3]), np.array([1, 2, 4])  # 5 is coupled to nothing
    order = fill_reducing_order(dims, a, b, method)
    assert sorted(order.tolist()) == list(range(6))
    alone = fill_reducing_order(dims[:2], np.zeros(0, np.int64), np.zeros(0, np.int64), method)
    assert sorted(alone.tolist()) == [0, 1]


def test_metis_cut_short_by_sigterm_passes_the_signal_on(monkeypatch):
    """METIS fails when SIGTERM arrives while it runs and returns part of an ordering, the
    signal lost: it is sent again (a run records it: ``slam.interrupts``) and COLAMD orders
    every variable instead."""
    from types import SimpleNamespace

    import slam.graph.sparse as sparse
    from slam import interrupts

    def cut_short(sfg):
        full = gtsam.Ordering.MetisSymbolicFactorGraph(sfg)
        part = gtsam.Ordering()
        for i in range(full.size() - 1):
            part.push_back(full.at(i))
        return part

    ordering = SimpleNamespace(
        MetisSymbolicFactorGraph=cut_short,
        ColamdSymbolicFactorGraph=gtsam.Ordering.ColamdSymbolicFactorGraph,
    )
    monkeypatch.setattr(
        sparse,
        "gtsam",
        SimpleNamespace(SymbolicFactorGraph=gtsam.SymbolicFactorGraph, Ordering=ordering),
    )
    dims = np.full(6, 3)
    a, b = np.array([0, 1, 3]), np.array([1, 2, 4])
    with interrupts.handling_signals():
        order = sparse.fill_reducing_order(dims, a, b, "metis")
        assert interrupts.requested() == signal.SIGTERM
    assert sorted(order.tolist()) == list(range(6))
    colamd = sparse.fill_reducing_order(dims, a, b, "colamd")
    np.testing.assert_array_equal(order, colamd)
