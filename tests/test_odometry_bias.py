"""A persistent odometry error: seen in the relations' NEES, recovered from the short ones."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slam.errors import EvaluationError
from slam.evaluation.odometry_bias import (
    OdometryCalibration,
    fit_odometry_calibration,
    odometry_relations_nees,
    relation_pairs,
    relations_frame_offset,
)
from slam.geometry import pose_between, pose_compose, pose_inverse
from slam.lines.transform import compose_chain
from slam.models.motion import MotionNoiseConfig

TRUE_BIAS = OdometryCalibration(scale=0.02, turn_gain=-0.03, heading_drift_rad_per_m=0.02)


def _biased_odometry(rng, noise, bias, n=4000):
    """A smooth true path, and the odometry that misreads every step by ``bias``, plus noise."""
    true_steps = np.column_stack([np.full(n, 0.1), np.zeros(n), 0.08 * np.sin(np.arange(n) / 40.0)])
    truth, _ = compose_chain(true_steps)
    # invert the calibration step by step, then add the random walk of the model
    c = bias
    raw = true_steps.copy()
    raw[:, :2] /= 1.0 + c.scale
    d_raw = np.hypot(raw[:, 0], raw[:, 1])
    raw[:, 2] = (true_steps[:, 2] - c.heading_drift_rad_per_m * d_raw) / (1.0 + c.turn_gain)
    cov = noise.covariance(raw)
    raw = raw + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((n, 3)))
    odometry, _ = compose_chain(raw)
    return truth, odometry


def _relations(rng, truth, lag, count):
    first = rng.choice(truth.shape[0] - lag, size=count, replace=False)
    second = first + lag
    t = np.arange(truth.shape[0], dtype=float)
    return t, t[first], t[second], pose_between(truth[first], truth[second])


def test_relation_pairs_match_stamps_and_invert_backward_relations():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    poses = np.array([[1.0, 0.0, 0.5], [2.0, 1.0, -0.2], [0.0, 0.0, 0.0]])
    pairs = relation_pairs(t, np.array([0.0, 3.0, 1.5]), np.array([2.0, 1.0005, 2.5]), poses)
    # the third relation's stamps are not in the odometry (1 ms tolerance)
    assert pairs.first.tolist() == [0, 1] and pairs.second.tolist() == [2, 3]
    np.testing.assert_allclose(pairs.poses[0], poses[0])
    np.testing.assert_allclose(pose_between(pairs.poses[1], np.zeros(3)), poses[1], atol=1e-12)
    np.testing.assert_allclose(pairs.duration_s, [2.0, 1.9995])
    # stamps out of order (a log's jitter): matched by stamp, ordered by position
    shuffled = relation_pairs(
        np.array([0.0, 2.0, 1.0, 3.0]), np.array([2.0]), np.array([1.0]), poses[:1]
    )
    assert shuffled.first.tolist() == [1] and shuffled.second.tolist() == [2]
    np.testing.assert_allclose(shuffled.poses[0], poses[0])
    with pytest.raises(EvaluationError, match="no relation"):
        relation_pairs(t, np.array([10.0]), np.array([11.0]), poses[:1])


def test_unbiased_odometry_is_consistent_at_every_length(rng):
    noise = MotionNoiseConfig().scaled(0.5)
    truth, odometry = _biased_odometry(rng, noise, OdometryCalibration())
    # 300 relations of 3 dof each; the long ones overlap (4,000 steps hold four independent
    # stretches of 1,000), so their mean scatters more
    for lag, low, high in ((5, 2.5, 3.5), (1000, 1.5, 4.5)):
        t, t1, t2, rel = _relations(rng, truth, lag, 300)
        nees = odometry_relations_nees(odometry, relation_pairs(t, t1, t2, rel), noise)
        assert low < nees.mean() < high, (lag, nees.mean())


def test_short_relations_recover_the_bias_and_make_long_ones_consistent(rng):
    noise = MotionNoiseConfig().scaled(0.5)
    truth, odometry = _biased_odometry(rng, noise, TRUE_BIAS)
    t, t1, t2, rel = _relations(rng, truth, 5, 600)  # 0.5 m of path each
    short = relation_pairs(t, t1, t2, rel)
    t, t1, t2, rel = _relations(rng, truth, 1000, 300)  # 100 m of path each
    long = relation_pairs(t, t1, t2, rel)
    # the random walk cannot explain the long relations of a biased odometry
    assert odometry_relations_nees(odometry, short, noise).mean() < 5.0
    assert odometry_relations_nees(odometry, long, noise).mean() > 30.0
    fit = fit_odometry_calibration(odometry, short, noise)
    assert fit.scale == pytest.approx(TRUE_BIAS.scale, abs=0.01)
    assert fit.turn_gain == pytest.approx(TRUE_BIAS.turn_gain, abs=0.015)
    assert fit.heading_drift_rad_per_m == pytest.approx(
        TRUE_BIAS.heading_drift_rad_per_m, abs=0.005
    )
    assert 1.5 < odometry_relations_nees(odometry, long, noise, fit).mean() < 4.5
    with pytest.raises(EvaluationError, match="fewer than 3"):
        fit_odometry_calibration(odometry, short, noise, use=np.arange(len(short.first)) < 2)


def test_short_relations_recover_a_laser_mounted_ahead_of_the_odometry(rng):
    """The odometry reports the motion of a point 8 cm behind the laser (and 2 cm to its
    left): every turn moves the laser sideways, which the short relations show."""
    noise = MotionNoiseConfig().scaled(0.5)
    n = 4000
    true_steps = np.column_stack(
        [np.full(n, 0.05), np.zeros(n), 0.15 * np.sin(np.arange(n) / 25.0)]
    )
    truth, _ = compose_chain(true_steps)
    mount = np.array([0.08, -0.02, 0.0])
    base = pose_compose(pose_compose(mount, true_steps), pose_inverse(mount))
    cov = noise.covariance(base)
    raw = base + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((n, 3)))
    odometry, _ = compose_chain(raw)
    t, t1, t2, rel = _relations(rng, truth, 5, 600)
    short = relation_pairs(t, t1, t2, rel)
    fit = fit_odometry_calibration(odometry, short, noise, parameters="mounting")
    assert fit.mount_x_m == pytest.approx(0.08, abs=0.01)
    assert fit.mount_y_m == pytest.approx(-0.02, abs=0.01)
    assert fit.scale == fit.turn_gain == fit.heading_drift_rad_per_m == 0.0
    # the random walk cannot explain the sideways motion on turns; with the mounting it can
    assert odometry_relations_nees(odometry, short, noise).mean() > 6.0
    assert 2.4 < odometry_relations_nees(odometry, short, noise, fit).mean() < 3.6
    with pytest.raises(EvaluationError, match="bias or mounting"):
        fit_odometry_calibration(odometry, short, noise, parameters="scale")  # type: ignore[arg-type]


@pytest.mark.parametrize("offset", [(0.05, -0.02), (0.0, 0.0)])
def test_relations_frame_offset_finds_the_frame_the_relations_relate(rng, offset):
    """Relations of a frame 5 cm ahead and 2 cm right of a trajectory's (or of the trajectory's
    own frame), with noise: the fit finds it within four of its bootstrap standard deviations,
    and those are a few millimetres."""
    n = 3000
    steps = np.column_stack([np.full(n, 0.05), np.zeros(n), 0.15 * np.sin(np.arange(n) / 25.0)])
    trajectory, _ = compose_chain(steps)
    M = np.array([offset[0], offset[1], 0.0])
    frame = pose_compose(trajectory, M)
    t, t1, t2, rel = _relations(rng, frame, 5, 500)
    rel = pose_compose(rel, rng.normal(0.0, [0.005, 0.005, 0.002], size=rel.shape))
    off = relations_frame_offset(t, trajectory, t1, t2, rel, short_s=10.0, resamples=20, seed=1)
    assert off.relations == 500
    assert 0.0 < off.sd_x_m < 0.005 and 0.0 < off.sd_y_m < 0.005
    assert abs(off.x_m - offset[0]) < 4 * off.sd_x_m + 1e-4
    assert abs(off.y_m - offset[1]) < 4 * off.sd_y_m + 1e-4
    # the relations are 5 steps long: none is shorter than 1 s of these 1 s steps
    with pytest.raises(EvaluationError, match="at least 3"):
        relations_frame_offset(t, trajectory, t1, t2, rel, short_s=1.0)


def test_a_model_that_leaves_a_turn_on_the_spot_no_error_is_a_clear_error():
    """Turns on the spot under a model with no translation noise per radian and negligible
    floors (as ``scripts/odometry_bias.py --noise-from`` uses a run's fit):
    the relations across them have a singular covariance, said in an EvaluationError (not a
    LinAlgError from inside numpy)."""
    noise = MotionNoiseConfig(
        sigma_xy_per_m=0.02,
        sigma_xy_per_rad=0.0,
        sigma_theta_per_m=0.02,
        sigma_theta_per_rad=0.05,
        sigma_xy_min_m=1e-9,
        sigma_theta_min_rad=1e-9,
    )
    steps = np.tile([0.0, 0.0, 0.1], (50, 1))  # turning on the spot
    odometry, _ = compose_chain(steps)
    t = np.arange(51, dtype=float)
    pairs = relation_pairs(t, t[:10], t[:10] + 5, pose_between(odometry[:10], odometry[5:15]))
    with pytest.raises(EvaluationError, match="no error in some direction"):
        odometry_relations_nees(odometry, pairs, noise)
    floored = replace(noise, sigma_xy_min_m=0.001)
    assert np.all(np.isfinite(odometry_relations_nees(odometry, pairs, floored)))
