"""The odometry's persistent error, estimated during a run (slam.line_slam.odometry_calibration)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from line_world import corridor_loop, loop_path, relations_error, simulate_run

from slam.geometry import pose_between, pose_compose, pose_inverse, pose_log
from slam.line_slam import LineSlam, SlamConfig, SlamWarning
from slam.line_slam.odometry_calibration import MountingEstimator, OdometryCalibrator
from slam.models.motion import MotionNoiseConfig, OdometryCalibration

BIAS = OdometryCalibration(scale=0.03, turn_gain=-0.05, heading_drift_rad_per_m=0.03)
MOUNT = OdometryCalibration(mount_x_m=0.3)


def test_calibration_jacobian_matches_numerical_derivative(rng):
    for step in rng.normal(scale=[0.4, 0.1, 0.3], size=(5, 3)):
        A = OdometryCalibration().jacobian(step)
        num = np.zeros((3, 5))
        for k in range(5):
            e = np.zeros(5)
            e[k] = 1e-6
            plus = OdometryCalibration(*e).apply(step)
            minus = OdometryCalibration(*(-e)).apply(step)
            num[:, k] = pose_log(pose_between(step, plus)) - pose_log(pose_between(step, minus))
            num[:, k] /= 2e-6
        np.testing.assert_allclose(A, num, atol=1e-7)


def test_a_mounted_laser_moves_by_the_step_seen_from_the_mounting(rng):
    """``M⁻¹ · δ · M``: the laser's motion when the odometry reports the motion of a point
    ``m`` behind it, composed pose by pose (a known answer, not the formula again)."""
    m = np.array([0.08, -0.03, 0.0])
    cal = OdometryCalibration(mount_x_m=m[0], mount_y_m=m[1])
    for step in rng.normal(scale=[0.4, 0.1, 0.8], size=(5, 3)):
        base_i = rng.normal(size=3)
        base_j = pose_compose(base_i, step)
        laser_i, laser_j = pose_compose(base_i, m), pose_compose(base_j, m)
        np.testing.assert_allclose(cal.apply(step), pose_between(laser_i, laser_j), atol=1e-12)
    # a turn on the spot moves the laser sideways by m·sin θ; a straight step not at all
    np.testing.assert_allclose(
        cal.apply(np.array([0.0, 0.0, 0.3])),
        [
            m[0] * (np.cos(0.3) - 1) - m[1] * np.sin(0.3),
            m[0] * np.sin(0.3) + m[1] * (np.cos(0.3) - 1),
            0.3,
        ],
        atol=1e-15,
    )
    np.testing.assert_allclose(cal.apply(np.array([0.5, 0.0, 0.0])), [0.5, 0.0, 0.0])


@pytest.mark.parametrize("mount", [(0.08, -0.03), (0.0, 0.0)])
def test_mounting_estimator_recovers_the_mounting_from_exact_step_estimates(rng, mount):
    """Steps estimated exactly (the graph's poses are the truth): the fit is the mounting
    within four standard deviations and significant; with none it is not applied."""
    truth = OdometryCalibration(mount_x_m=mount[0], mount_y_m=mount[1])
    M = np.array([*mount, 0.0])
    est = MountingEstimator(min_samples=20, update_every=10)
    Q = np.diag([0.01, 0.01, 0.01]) ** 2
    poses = [np.zeros(3)]
    for k in range(400):
        turn = k % 2 == 1
        laser_step = np.array(
            [0.0, 0.0, rng.choice([-1, 1]) * rng.uniform(0.2, 0.6)]
            if turn
            else [rng.uniform(0.2, 0.4), 0.0, rng.normal(0.0, 0.02)]
        )
        base_step = pose_compose(pose_compose(M, laser_step), pose_inverse(M))
        raw = pose_compose(base_step, rng.multivariate_normal(np.zeros(3), Q))
        poses.append(pose_compose(poses[-1], laser_step))
        est.add_step(k, k + 1, est.apply(raw), Q)
        est.keyframe(np.array(poses))
    got = est.summary()
    assert got["fits"] >= 1 and got["turning_samples"] > 100
    for name, value in (("mount_x_m", mount[0]), ("mount_y_m", mount[1])):
        assert abs(got[f"fit_{name}"] - value) < 4 * got[f"sd_{name}"], name
    assert got["significant"] == (mount != (0.0, 0.0))
    applied = np.array([got["mount_x_m"], got["mount_y_m"]])
    expected = np.array(mount) if got["significant"] else np.zeros(2)
    np.testing.assert_array_equal(applied == 0.0, expected == 0.0)
    turn = np.array([0.0, 0.0, 0.5])
    assert np.linalg.norm((est.apply(turn) - truth.apply(turn))[:2]) < 3e-3


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


def _slam(run, motion, mode):
    """The run's result with ``odometry_calibration = mode``."""
    slam = LineSlam(SlamConfig(motion=motion, odometry_calibration=mode))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SlamWarning)
        for scan, lines in zip(run.scans, run.lines, strict=True):
            slam.add_scan(scan, lines)
        slam.optimize()
    return slam.result()


def _loop_runs(laps, bias, modes):
    """The corridor loop driven ``laps`` times with an odometry erring by ``bias``: the path
    and the run's result with each ``odometry_calibration`` of ``modes``."""
    motion = MotionNoiseConfig(
        sigma_xy_per_m=0.01, sigma_theta_per_m=0.01, sigma_theta_per_rad=0.01
    )
    world = corridor_loop(piece=3.0, door=1.0)
    path = loop_path(16, 8, 0.4, laps=laps)
    run = simulate_run(world, path, seed=3, motion=motion, bias=bias)
    return path, {mode: _slam(run, motion, mode) for mode in modes}


@pytest.fixture(scope="module")
def biased_loop():
    return _loop_runs(1.25, BIAS, ("off", "estimated"))


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


@pytest.fixture(scope="module")
def mounted_loop():
    """Four laps of the corridor loop with the laser 30 cm ahead of the point the odometry
    reports (a mounting the log does not state), and without: each run with and without the
    calibration of the mounting."""
    motion = MotionNoiseConfig(
        sigma_xy_per_m=0.01, sigma_theta_per_m=0.01, sigma_theta_per_rad=0.01
    )
    world = corridor_loop(piece=3.0, door=1.0)
    path = loop_path(16, 8, 0.4, laps=4)
    out = {}
    for mounted in (True, False):
        run = simulate_run(
            world, path, seed=3, motion=motion, bias=MOUNT if mounted else OdometryCalibration()
        )
        for mode in ("off", "mounting"):
            out[mounted, mode] = _slam(run, motion, mode)
    return path, out


def test_a_run_estimates_an_unstated_mounting_and_is_more_accurate(mounted_loop):
    """The graph's estimate of a step is the odometry fused with the lines, so the fit lags
    the truth (it approaches it as the calibration is applied), but not its sign; relative
    poses 4 m apart are then far closer to the truth."""
    path, out = mounted_loop
    got = out[True, "mounting"].stats["odometry_calibration"]
    assert got["parameters"] == "mounting" and got["fits"] >= 1 and got["significant"]
    assert 0.5 * MOUNT.mount_x_m < got["mount_x_m"] <= 1.1 * MOUNT.mount_x_m
    assert abs(got["mount_y_m"]) < 0.1 * MOUNT.mount_x_m
    assert got["scale"] == got["turn_gain"] == got["heading_drift_rad_per_m"] == 0.0
    off, mounted = (
        relations_error(out[True, m].poses_world_laser, path, 10).mean()
        for m in ("off", "mounting")
    )
    assert mounted < 0.6 * off


def test_a_mounting_the_steps_cannot_tell_from_none_is_not_applied(mounted_loop):
    """Without a mounting the fit is not significant: the steps are used as logged, and the
    run is the one without the calibration, pose for pose."""
    _, out = mounted_loop
    got = out[False, "mounting"].stats["odometry_calibration"]
    assert got["fits"] >= 1 and not got["significant"]
    assert got["mount_x_m"] == got["mount_y_m"] == 0.0
    assert abs(got["fit_mount_x_m"]) < 4 * got["sd_mount_x_m"]
    np.testing.assert_array_equal(
        out[False, "mounting"].poses_world_laser, out[False, "off"].poses_world_laser
    )


def test_every_run_reports_the_mounting_its_final_estimate_implies(mounted_loop):
    """``laser_mounting_fit`` (never applied): significant and of the right sign where the
    laser is mounted ahead, short of it where the graph leans on the odometry; not
    significant without a mounting."""
    _, out = mounted_loop
    mounted = out[True, "off"].stats["laser_mounting_fit"]
    assert mounted["significant"] and mounted["turning_samples"] >= 30
    assert mounted["fit_mount_x_m"] > 4 * mounted["sd_mount_x_m"]
    assert mounted["fit_mount_x_m"] < MOUNT.mount_x_m
    # with the calibration applied the graph's steps follow the mounting further
    calibrated = out[True, "mounting"].stats["laser_mounting_fit"]
    assert calibrated["fit_mount_x_m"] > mounted["fit_mount_x_m"]
    assert not out[False, "off"].stats["laser_mounting_fit"]["significant"]


BIAS_AND_MOUNT = OdometryCalibration(
    scale=0.03, turn_gain=-0.05, heading_drift_rad_per_m=0.03, mount_x_m=0.3
)


@pytest.fixture(scope="module")
def biased_mounted_loop():
    """Four laps of the corridor loop with a biased odometry and the laser 30 cm ahead of the
    point it reports, run with each calibration."""
    return _loop_runs(4, BIAS_AND_MOUNT, ("mounting", "estimated"))


def test_estimated_calibration_recovers_bias_and_mounting_together(biased_mounted_loop):
    """``"estimated"`` fits the biases and the mounting at once: the scale and the heading
    drift within their standard deviations (plus first order's slack), the mounting
    significant, ahead and short of none; the run is more accurate than with the mounting
    alone, whose fit the bias misleads."""
    path, out = biased_mounted_loop
    got = out["estimated"].stats["odometry_calibration"]
    assert got["parameters"] == "scale, turn gain, heading drift and mounting"
    assert got["fits"] >= 1 and got["mounting_fits"] >= 1 and got["significant"]
    assert got["scale"] == pytest.approx(BIAS_AND_MOUNT.scale, abs=4 * got["sd_scale"] + 0.005)
    assert got["heading_drift_rad_per_m"] == pytest.approx(
        BIAS_AND_MOUNT.heading_drift_rad_per_m, abs=4 * got["sd_heading_drift_rad_per_m"] + 0.005
    )
    assert 0.5 * BIAS_AND_MOUNT.mount_x_m < got["mount_x_m"] <= 1.1 * BIAS_AND_MOUNT.mount_x_m
    assert abs(got["mount_y_m"]) < 0.1 * BIAS_AND_MOUNT.mount_x_m
    mounting, estimated = (relations_error(out[m].poses_world_laser, path, 10).mean() for m in out)
    assert estimated < 0.8 * mounting


def test_bias_samples_are_referred_to_the_mounting_as_now_estimated(rng):
    """A calibrator told the mounting fits the biases to what the mounting leaves: errors of
    steps seen from the true mounting give the true biases, whatever mounting was applied
    when each sample was taken."""
    cal = OdometryCalibrator(min_samples=20, update_every=10)
    noise = np.diag([0.005, 0.005, 0.003]) ** 2
    truth = BIAS_AND_MOUNT
    for k in range(600):
        if k == 300:
            cal.set_mounting(truth.mount_x_m, truth.mount_y_m)
        raw = np.array([rng.uniform(0.2, 0.6), rng.normal(0, 0.02), rng.normal(0, 0.4)])
        used = cal.apply(raw)
        nu = pose_log(pose_between(used, truth.apply(raw)))
        cal.add(raw, nu + rng.multivariate_normal(np.zeros(3), noise), noise)
        cal.keyframe()
    got = cal.summary()
    assert got["mount_x_m"] == truth.mount_x_m
    for name in ("scale", "turn_gain", "heading_drift_rad_per_m"):
        assert abs(got[name] - getattr(truth, name)) < 4 * got[f"sd_{name}"] + 2e-3, name
    # the calibrated steps are the true ones (to a millimetre over 0.6 m, a milliradian)
    steps = np.stack(np.meshgrid([0.2, 0.6], [0.0], [-0.6, 0.0, 0.6]), -1).reshape(-1, 3)
    err = np.abs(pose_log(pose_between(cal.apply(steps), truth.apply(steps))))
    assert err[:, :2].max() < 1e-3 and err[:, 2].max() < 1e-3
