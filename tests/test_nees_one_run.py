"""The interval of one run's mean NEES with correlated errors: poses (correlated_nees_bounds)
and relations (joint draws)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slam.errors import EvaluationError
from slam.evaluation import correlated_nees_bounds, nees_bounds, pose_nees
from slam.evaluation import nees as nees_module
from slam.evaluation.relations_nees import relations_nees
from slam.geometry import pose_compose, pose_exp, pose_inverse
from slam.io import Trajectory
from slam.io.relations import Relations


def _drift_covariance(rng: np.random.Generator, n: int, shared: float) -> np.ndarray:
    """Joint covariance of the errors of ``n`` poses that drift: ``ξᵢ = G s + Σ_{j≤i} Bⱼ wⱼ``
    (a shared error ``s`` of weight ``shared`` plus a random walk), all standard normal."""
    G = shared * rng.normal(size=(3, 3))
    B = 0.3 * rng.normal(size=(n, 3, 3))
    A = np.zeros((3 * n, 3 + 3 * n))
    for i in range(n):
        A[3 * i : 3 * i + 3, :3] = G
        for j in range(i + 1):
            A[3 * i : 3 * i + 3, 3 + 3 * j : 6 + 3 * j] = B[j]
    return A @ A.T + 1e-9 * np.eye(3 * n)


@pytest.mark.parametrize("n", [1, 4, 300])
def test_independent_poses_give_the_chi2_interval(n):
    b = correlated_nees_bounds(np.eye(3 * n))
    lower, upper = nees_bounds(3, n)
    assert b.lower == pytest.approx(lower, rel=0.012)
    assert b.upper == pytest.approx(upper, rel=0.012)
    assert b.effective_dof == pytest.approx(3 * n) and b.n == n


def test_one_shared_error_gives_the_interval_of_one_pose():
    """Every pose with the same error (in its own frame, any covariance scale): the mean is
    one χ²₃ value."""
    rng = np.random.default_rng(1)
    n = 50
    T = rng.normal(size=(n, 3, 3)) + 3 * np.eye(3)  # ξᵢ = Tᵢ s
    A = T.reshape(3 * n, 3)
    b = correlated_nees_bounds(A @ A.T)
    assert b.lower == pytest.approx(chi2.ppf(0.025, 3), rel=0.02)
    assert b.upper == pytest.approx(chi2.ppf(0.975, 3), rel=0.015)
    assert b.effective_dof == pytest.approx(3.0, rel=1e-6)


def test_monte_carlo_runs_fall_in_the_one_run_interval_95_percent_of_the_time():
    """Draw whole runs of correlated errors: the mean NEES of a run lies inside the one-run
    interval in 95 % of them, and far less often inside the independent-pose interval."""
    rng = np.random.default_rng(7)
    n, runs = 60, 2000
    S = _drift_covariance(rng, n, shared=0.5)
    b = correlated_nees_bounds(S)
    xi = rng.standard_normal((runs, 3 * n)) @ np.linalg.cholesky(S).T
    P = S.reshape(n, 3, n, 3)[np.arange(n), :, np.arange(n), :]
    e = xi.reshape(runs, n, 3)
    means = np.einsum("rni,nij,rnj->rn", e, np.linalg.inv(P), e).mean(axis=1)
    inside = np.mean((means >= b.lower) & (means <= b.upper))
    assert inside == pytest.approx(0.95, abs=0.015)
    lo, hi = nees_bounds(3, n)
    assert np.mean((means >= lo) & (means <= hi)) < 0.5
    assert 3.0 < b.effective_dof < 3 * n / 3


def test_bad_joint_covariances_are_named():
    with pytest.raises(EvaluationError, match=r"not \(n\*3, n\*3\)"):
        correlated_nees_bounds(np.eye(4))
    S = np.eye(9)
    S[4, 4] = -1.0
    with pytest.raises(EvaluationError, match="pose 1 is not positive definite"):
        correlated_nees_bounds(S)
    S = np.eye(6)
    S[0, 0] = np.nan
    with pytest.raises(EvaluationError, match="non-finite"):
        correlated_nees_bounds(S)


def test_pose_nees_tests_the_one_run_interval_over_evenly_spaced_poses(monkeypatch):
    """With a joint covariance, ``consistent`` is decided by the one-run interval; above
    MAX_BOUND_POSES poses, over an evenly spaced subset of them."""
    rng = np.random.default_rng(3)
    n = 40
    stamps = np.arange(float(n))
    truth = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    S = _drift_covariance(rng, n, shared=2.0)
    xi = (np.linalg.cholesky(S) @ rng.standard_normal(3 * n)).reshape(n, 3)
    estimate = pose_compose(truth, pose_inverse(pose_exp(xi)))
    P = S.reshape(n, 3, n, 3)[np.arange(n), :, np.arange(n), :]
    asked: list[np.ndarray] = []

    def joint(t: np.ndarray) -> np.ndarray:
        asked.append(t)
        i = np.searchsorted(stamps, t)
        idx = (3 * i[:, None] + np.arange(3)).reshape(-1)
        return S[np.ix_(idx, idx)]

    est, gt = Trajectory(stamps, estimate), Trajectory(stamps, truth)
    full = pose_nees(est, P, gt, joint_covariance=joint)
    assert full.one_run is not None and full.one_run.n == n
    assert full.one_run_mean == pytest.approx(full.mean)
    assert full.consistent == (full.one_run.lower <= full.mean <= full.one_run.upper)
    np.testing.assert_array_equal(asked[-1], stamps)
    assert full.to_dict()["one_run"]["bounds"] == [full.one_run.lower, full.one_run.upper]
    monkeypatch.setattr(nees_module, "MAX_BOUND_POSES", 9)
    sub = pose_nees(est, P, gt, joint_covariance=joint)
    np.testing.assert_array_equal(asked[-1], stamps[np.linspace(0, n - 1, 9).round().astype(int)])
    assert sub.one_run is not None and sub.one_run.n == 9
    assert sub.one_run_mean == pytest.approx(full.values[np.isin(stamps, asked[-1])].mean())
    # the interval does not depend on the covariances' scale; an over-confident run fails it
    scaled = pose_nees(est, P * 0.05, gt, joint_covariance=lambda t: joint(t) * 0.05)
    assert scaled.one_run is not None
    assert scaled.one_run.lower == pytest.approx(sub.one_run.lower, rel=1e-9)
    assert scaled.one_run.upper == pytest.approx(sub.one_run.upper, rel=1e-9)
    assert scaled.one_run_mean == pytest.approx(sub.one_run_mean / 0.05)
    assert scaled.one_run_mean > scaled.one_run.upper and not scaled.consistent


def _relations(n: int) -> tuple[Trajectory, Relations]:
    stamps = np.arange(2.0 * n)
    poses = np.zeros((2 * n, 3))
    poses[:, 0] = stamps
    rel = Relations(
        stamps[:n],
        stamps[n:],
        np.tile([float(n), 0.0, 0.0], (n, 1)),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.arange(n, dtype=np.int64),
    )
    return Trajectory(stamps, poses), rel


@pytest.mark.parametrize("shared", [False, True])
def test_relations_one_run_interval_from_joint_draws(shared):
    """Independent draws give the χ² interval of the mean of n relations; one error shared by
    every relation (in its own whitened frame) gives the interval of a single χ²₃."""
    n = 200
    traj, rel = _relations(n)
    cov = np.tile(np.diag([0.01, 0.02, 0.003]), (n, 1, 1))
    L = np.linalg.cholesky(cov[0])

    def draws(t1, t2, k, seed):
        rng = np.random.default_rng(seed)
        for start in range(0, k, 500):
            size = min(500, k - start)
            z = rng.standard_normal((size, 1 if shared else n, 3))
            yield np.broadcast_to(z @ L.T, (size, n, 3))

    res = relations_nees(traj, rel, lambda a, b: cov, error_draws=draws)
    assert res.one_run is not None
    # 2,000 draws: quantiles to a few per cent, the lower one of a single χ²₃ to ~10 %
    if shared:
        (lower, upper), tolerance = chi2.ppf([0.025, 0.975], 3), (0.3, 0.08)
        assert res.one_run.effective_dof == pytest.approx(3.0, rel=0.1)
    else:
        (lower, upper), tolerance = nees_bounds(3, n), (0.03, 0.03)
        assert res.one_run.effective_dof == pytest.approx(3 * n, rel=0.1)
    assert res.one_run.lower == pytest.approx(lower, rel=tolerance[0])
    assert res.one_run.upper == pytest.approx(upper, rel=tolerance[1])
    assert res.consistent == (res.one_run.lower <= res.mean <= res.one_run.upper)
    assert res.to_dict()["one_run"]["bounds_95"] == [res.one_run.lower, res.one_run.upper]
