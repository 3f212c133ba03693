"""The odometry's persistent error, estimated during a run (slam.line_slam.odometry_calibration)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from line_world import corridor_loop, loop_path, relations_error, simulate_run

from slam.geometry import pose_between, pose_log
from slam.line_slam import LineSlam, SlamConfig, SlamWarning
from slam.line_slam.odometry_calibration import OdometryCalibrator
from slam.models.motion import MotionNoiseConfig, OdometryCalibration

BIAS = OdometryCalibration(scale=0.03, turn_gain=-0.05, heading_drift_rad_per_m=0.03)


def test_calibration_jacobian_matches_numerical_derivative(rng):
    for step in rng.normal(scale=[0.4, 0.1, 0.3], size=(5, 3)):
        A = OdometryCalibration().jacobian(step)
        num = np.zeros((3, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1e-6
            plus = OdometryCalibration(*e).apply(step)
            minus = OdometryCalibration(*(-e)).apply(step)
            num[:, k] = pose_log(pose_between(step, plus)) - pose_log(pose_between(step, minus))
            num[:, k] /= 2e-6
        np.testing.assert_allclose(A, num, atol=1e-7)


def test_calibrator_recovers_a_bias_while_it_corrects_the_steps(rng):
    """Each sample is measured against the step calibrated with the estimate of its time."""
    cal = OdometryCalibrator(min_samples=20, update_every=10)
    noise = np.diag([0.01, 0.01, 0.005]) ** 2
    for _ in range(600):
        raw = np.array([rng.uniform(0.2, 0.6), rng.normal(0, 0.02), rng.normal(0, 0.4)])
        used = cal.apply(raw)
        truth = BIAS.apply(raw)
        nu = pose_log(pose_between(used, truth)) + rng.multivariate_normal(np.zeros(3), noise)
        cal.add(raw, nu, noise)
        cal.keyframe()
    got = cal.summary()
    assert got["fits"] == 59 and got["samples"] == 600
    for name, sd in (
        ("scale", "sd_scale"),
        ("turn_gain", "sd_turn_gain"),
        ("heading_drift_rad_per_m", "sd_heading_drift_rad_per_m"),
    ):
        # within 4 standard deviations, plus what first order leaves over a 0.6 m step
        assert abs(got[name] - getattr(BIAS, name)) < 4 * got[sd] + 2e-3, name


@pytest.fixture(scope="module")
def biased_loop():
    motion = MotionNoiseConfig(
        sigma_xy_per_m=0.01, sigma_theta_per_m=0.01, sigma_theta_per_rad=0.01
    )
    world = corridor_loop(piece=3.0, door=1.0)
    path = loop_path(16, 8, 0.4, laps=1.25)
    run = simulate_run(world, path, seed=3, motion=motion, bias=BIAS)
    out = {}
    for mode in ("off", "estimated"):
        slam = LineSlam(SlamConfig(motion=motion, odometry_calibration=mode))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SlamWarning)
            for scan, lines in zip(run.scans, run.lines, strict=True):
                slam.add_scan(scan, lines)
            slam.optimize()
        out[mode] = slam.result()
    return path, out


def test_a_run_estimates_the_bias_of_a_simulated_odometry(biased_loop):
    _, out = biased_loop
    assert "odometry_calibration" not in out["off"].stats
    got = out["estimated"].stats["odometry_calibration"]
    assert got["samples"] >= 30 and got["fits"] >= 1
    assert got["scale"] == pytest.approx(BIAS.scale, abs=4 * got["sd_scale"] + 0.005)
    assert got["heading_drift_rad_per_m"] == pytest.approx(
        BIAS.heading_drift_rad_per_m, abs=4 * got["sd_heading_drift_rad_per_m"] + 0.005
    )


def test_the_calibrated_run_is_more_accurate_on_a_biased_odometry(biased_loop):
    # relative poses 10 scans (4 m) apart against the truth
    path, out = biased_loop
    off, calibrated = (relations_error(out[m].poses_world_laser, path, 10).mean() for m in out)
    assert calibrated < 0.7 * off
