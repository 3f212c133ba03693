"""ATE (SE(2) alignment), RPE over distances, pose NEES: known answers and Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import EvaluationError
from slam.evaluation import (
    align_se2,
    ate,
    distance_pairs,
    evaluate_results,
    nees_bounds,
    pose_nees,
    pose_nees_values,
    rpe,
    rpe_errors,
)
from slam.geometry import pose_between, pose_compose, pose_exp, pose_inverse, pose_log
from slam.io import Trajectory


def random_walk(rng, n):
    steps = np.column_stack(
        [rng.uniform(0.1, 0.5, n), rng.normal(0, 0.05, n), rng.normal(0, 0.2, n)]
    )
    poses = np.zeros((n, 3))
    for k in range(1, n):
        poses[k] = pose_compose(poses[k - 1], steps[k])
    return poses


def test_alignment_recovers_a_rigid_motion_and_ate_is_zero(rng):
    truth = random_walk(rng, 200)
    stamps = np.arange(200) * 0.1
    motion = np.array([3.0, -7.0, 2.5])
    estimate = pose_compose(pose_inverse(motion), truth)  # truth = motion · estimate
    result = ate(Trajectory(stamps, estimate), Trajectory(stamps, truth))
    np.testing.assert_allclose(result.alignment, motion, atol=1e-9)
    assert result.translation_m.rmse < 1e-9 and result.rotation_deg.max < 1e-7
    unaligned = ate(Trajectory(stamps, estimate), Trajectory(stamps, truth), align=False)
    assert unaligned.translation_m.rmse > 1.0


def test_ate_with_noise_equals_noise_rms(rng):
    truth = random_walk(rng, 2000)
    stamps = np.arange(2000) * 0.1
    noise = rng.normal(0, 0.05, (2000, 2))
    estimate = truth.copy()
    estimate[:, :2] += noise
    result = ate(Trajectory(stamps, estimate), Trajectory(stamps, truth))
    # alignment absorbs ~3 of 4000 degrees of freedom
    assert result.translation_m.rmse == pytest.approx(
        np.sqrt(np.mean(np.sum(noise**2, 1))), rel=0.01
    )


def test_ate_keeps_the_matched_poses_and_their_errors(rng):
    truth = random_walk(rng, 50)
    estimate = truth + rng.normal(0.0, 0.02, (50, 3))
    # the estimate skips ground-truth pose 7 and has one pose (the last) without ground truth
    est_stamps = np.r_[np.delete(np.arange(50.0), 7), 99.0]
    est = Trajectory(est_stamps, np.r_[np.delete(estimate, 7, axis=0), estimate[:1]])
    result = ate(est, Trajectory(np.arange(50.0), truth), max_unmatched_fraction=0.1)
    assert result.n_unmatched == 1
    np.testing.assert_array_equal(result.index_estimate, np.arange(49))
    np.testing.assert_array_equal(result.index_reference, np.delete(np.arange(50), 7))
    errors = result.translation_errors_m
    assert errors.shape == (49,) and result.translation_m.n == 49
    assert result.translation_m.rmse == pytest.approx(np.sqrt(np.mean(errors**2)), rel=1e-12)
    unaligned = ate(
        est, Trajectory(np.arange(50.0), truth), align=False, max_unmatched_fraction=0.1
    )
    moved = est.poses[:49, :2] - truth[np.delete(np.arange(50), 7), :2]
    np.testing.assert_allclose(unaligned.translation_errors_m, np.hypot(*moved.T), rtol=1e-12)


def test_alignment_of_collapsed_positions_is_an_error():
    with pytest.raises(EvaluationError, match="undetermined"):
        align_se2(np.ones((5, 2)), np.ones((5, 2)))


def test_rpe_known_answer_for_a_scale_error():
    n = 101
    truth = np.column_stack([np.arange(n) * 1.0, np.zeros(n), np.zeros(n)])
    estimate = truth * [1.1, 1.0, 1.0]
    stamps = np.arange(n) * 0.5
    for all_pairs in (False, True):
        result = rpe(
            Trajectory(stamps, estimate), Trajectory(stamps, truth), 5.0, all_pairs=all_pairs
        )
        assert result.translation_m.mean == pytest.approx(0.5)
        assert result.translation_m.std == pytest.approx(0.0, abs=1e-9)
        assert result.translation_m.n == (20 if not all_pairs else 96)
    pairs = distance_pairs(truth[:, :2], 5.0)
    assert pairs[0].tolist() == [0, 5] and pairs[-1].tolist() == [95, 100]


def test_rpe_errors_are_the_pairs_behind_the_statistics():
    """A heading drift of 0.01 rad per metre: over 5 m every relative pose is off by 0.05 rad;
    rpe's statistics are those of the rows."""
    n = 101
    s = np.arange(n) * 1.0
    truth = np.column_stack([s, np.zeros(n), np.zeros(n)])
    estimate = np.zeros((n, 3))
    for k in range(1, n):  # 1 m ahead, then a 0.01 rad turn
        estimate[k] = pose_compose(estimate[k - 1], np.array([1.0, 0.0, 0.01]))
    stamps = np.arange(n) * 0.5
    e = rpe_errors(Trajectory(stamps, estimate), Trajectory(stamps, truth), 5.0, all_pairs=True)
    assert e.shape == (96, 3)
    np.testing.assert_allclose(e[:, 2], 0.05, atol=1e-12)
    result = rpe(Trajectory(stamps, estimate), Trajectory(stamps, truth), 5.0, all_pairs=True)
    t = np.hypot(e[:, 0], e[:, 1])
    assert result.translation_m.max == pytest.approx(t.max())
    assert result.translation_m.rmse == pytest.approx(np.sqrt(np.mean(t**2)))
    assert result.rotation_deg.mean == pytest.approx(np.degrees(0.05))


def test_rpe_ignores_a_global_rigid_motion(rng):
    truth = random_walk(rng, 300)
    stamps = np.arange(300) * 0.1
    estimate = pose_compose(np.array([1.0, 2.0, 0.7]), truth)
    result = rpe(Trajectory(stamps, estimate), Trajectory(stamps, truth), 2.0, all_pairs=True)
    assert result.translation_m.max < 1e-9 and result.rotation_deg.max < 1e-7


def random_covariances(rng, n):
    a = rng.normal(0, 1, (n, 3, 3)) * [[0.1], [0.1], [0.02]]
    return a @ np.swapaxes(a, 1, 2) + np.diag([1e-4, 1e-4, 1e-5])


def test_nees_monte_carlo_consistent_and_overconfident(rng):
    n = 4000
    truth = random_walk(rng, n)
    stamps = np.arange(n) * 0.1
    cov = random_covariances(rng, n)
    xi = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 3)))
    # exact: truth = estimate · Exp(ξ)  ⇔  estimate = truth · Exp(ξ)⁻¹
    estimate = pose_compose(truth, pose_inverse(pose_exp(xi)))
    result = pose_nees(Trajectory(stamps, estimate), cov, Trajectory(stamps, truth))
    assert result.consistent, (result.mean, result.lower, result.upper)
    assert result.fraction_within == pytest.approx(0.95, abs=0.015)
    over = pose_nees(Trajectory(stamps, estimate), cov * 0.7, Trajectory(stamps, truth))
    assert not over.consistent and over.mean > over.upper


def test_nees_rejects_a_singular_covariance(rng):
    truth = random_walk(rng, 5)
    cov = random_covariances(rng, 5)
    cov[2] = np.diag([1.0, 0.0, 1.0])
    with pytest.raises(EvaluationError, match="covariance 2 is not positive definite"):
        pose_nees(Trajectory(np.arange(5.0), truth), cov, Trajectory(np.arange(5.0), truth))


def test_nees_leaves_out_the_gauge_pose_with_zero_covariance(rng):
    """The EKF's first pose defines the frame (covariance exactly 0): not in the NEES; the
    others' values are those without it."""
    n = 50
    truth = random_walk(rng, n)
    stamps = np.arange(float(n))
    cov = random_covariances(rng, n)
    xi = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(n, 3)))
    estimate = pose_compose(truth, pose_inverse(pose_exp(xi)))
    estimate[0] = truth[0]
    cov[0] = 0.0
    got = pose_nees(Trajectory(stamps, estimate), cov, Trajectory(stamps, truth))
    rest = pose_nees(
        Trajectory(stamps[1:], estimate[1:]), cov[1:], Trajectory(stamps[1:], truth[1:])
    )
    assert got.n == n - 1 and got.mean == pytest.approx(rest.mean)
    with pytest.raises(EvaluationError, match="zero covariance"):
        pose_nees(Trajectory(stamps, estimate), cov * 0.0, Trajectory(stamps, truth))


def test_pose_nees_values_pair_by_index_and_leave_unusable_covariances_undefined(rng):
    truth = random_walk(rng, 40)
    cov = random_covariances(rng, 40)
    xi = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(40, 3)))
    estimate = pose_compose(truth, pose_inverse(pose_exp(xi)))
    cov[0] = 0.0  # an anchored first pose
    cov[5] = np.diag([1.0, -1.0, -1.0])  # indefinite, with a positive determinant
    cov[9, 1, 1] = np.nan  # no covariance
    values = pose_nees_values(estimate, cov, truth)
    assert values.shape == (40,)
    np.testing.assert_array_equal(np.flatnonzero(np.isnan(values)), [0, 5, 9])
    # ξᵀ P⁻¹ ξ with ξ = Log(estimate⁻¹ · truth), computed here independently
    e = pose_log(pose_between(estimate, truth))
    ok = np.isfinite(values)
    expected = np.einsum("ni,nij,nj->n", e[ok], np.linalg.inv(cov[ok]), e[ok])
    np.testing.assert_allclose(values[ok], expected, rtol=1e-10)
    # the trajectory version gives the same numbers where every covariance is usable
    stamps = np.arange(40.0)
    keep = np.flatnonzero(ok)
    result = pose_nees(
        Trajectory(stamps[keep], estimate[keep]), cov[keep], Trajectory(stamps, truth)
    )
    np.testing.assert_array_equal(result.values, values[keep])
    # one pose on its own (no leading dimension)
    assert pose_nees_values(estimate[3], cov[3], truth[3]).shape == ()
    assert float(pose_nees_values(estimate[3], cov[3], truth[3])) == values[3]
    with pytest.raises(EvaluationError, match="do not match"):
        pose_nees_values(estimate, cov[:-1], truth)


def test_nees_bounds_are_the_chi2_interval_of_the_mean(rng):
    lo, hi = nees_bounds(3, 1, 0.95)
    assert (lo, hi) == pytest.approx((0.2158, 9.3484), abs=1e-4)  # χ²₃ quantiles 2.5 %, 97.5 %
    lo50, hi50 = nees_bounds(3, 50, 0.95)
    assert lo < lo50 < 3.0 < hi50 < hi  # the mean of many concentrates around the dof
    # coverage: the mean of 50 χ²₃ samples falls inside in 95 % of trials
    means = rng.chisquare(3, (20000, 50)).mean(axis=1)
    assert np.mean((means >= lo50) & (means <= hi50)) == pytest.approx(0.95, abs=0.006)


def test_report_of_a_perfect_trajectory(rng):
    from slam.io import relations_from_trajectory

    truth = random_walk(rng, 300)
    stamps = np.round(np.arange(300) * 0.1 + 1000, 6)
    rel = relations_from_trajectory(stamps, truth, rng.integers(0, 300, (100, 2)))
    report = evaluate_results(
        Trajectory(stamps, truth),
        relations=rel,
        ground_truth=Trajectory(stamps, truth),
        rpe_deltas_m=(1.0, 5.0),
    )
    d = report.to_dict()
    assert d["relations"]["abs_trans_m"]["mean"] < 1e-9 and d["ate"]["rmse_m"] < 1e-9
    assert [r["delta_m"] for r in d["rpe"]] == [1.0, 5.0]
    assert "abs trans (m)" in report.format_table()
