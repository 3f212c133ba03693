"""EKF-SLAM baseline: conventions, Jacobians, update forms, augmentation, association, guards."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from linefit.errors import ConfigError
from slam.association import AssociationConfig
from slam.config import RunConfig
from slam.ekf import EkfConfig, EkfSlam, MotionNoiseConfig
from slam.ekf.augment import augment_state, landmark_from_measurement
from slam.ekf.conventions import (
    cov_state_to_tangent,
    cov_tangent_to_state,
    state_jacobian_from_tangent,
)
from slam.ekf.motion import odometry_covariance, predict_pose
from slam.ekf.update import filterpy_update, joseph_update, line_measurements
from slam.errors import InputError
from slam.geometry import (
    line_to_parent,
    pose_between,
    pose_compose,
    pose_exp,
    pose_inverse,
    predict_line_measurement,
    wrap_angle,
)
from slam.lines.lineset import LineSet
from slam.types import Scan

# the overlap test off (landmarks set without seen extents)
NO_OVERLAP_TEST = AssociationConfig(overlap_margin_m=1e9)


def numdiff(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    f0 = np.asarray(f(x))
    J = np.empty((f0.size, x.size))
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        diff = np.asarray(f(x + d)) - np.asarray(f(x - d))
        J[:, i] = diff.ravel() / (2 * eps)
    return J


def ang_safe(v):
    """Wrap the angle entries (index 1 of each (r, α) pair) of a difference."""
    v = np.array(v, dtype=float)
    v[1::2] = wrap_angle(v[1::2])
    return v


# -------------------------------------------------------------------------------- conventions
def random_cases(rng, n=40):
    poses = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    lms = np.column_stack([rng.uniform(-4, 4, n), rng.uniform(-np.pi, np.pi, n)])
    # edge cases: world line through the origin, line through the laser, α near ±π
    lms[0] = [0.0, 0.3]
    lms[1] = [2.0, np.pi - 1e-9]
    lms[2] = [1.0, -np.pi + 1e-9]
    lms[3, 0] = poses[3, 0] * np.cos(lms[3, 1]) + poses[3, 1] * np.sin(lms[3, 1])
    return poses, lms


def test_state_jacobian_of_measurement_matches_numerical_derivative(rng):
    poses, lms = random_cases(rng)
    for pose, lm in zip(poses, lms, strict=True):
        _, H_xi, _ = predict_line_measurement(lm, pose)
        H_state = state_jacobian_from_tangent(H_xi, pose[2])

        def h_of_pose(p, lm=lm, z0=None):
            z, _, _ = predict_line_measurement(lm, p)
            return z

        z0 = h_of_pose(pose)

        def h_rel(p, lm=lm, z0=z0):
            z, _, _ = predict_line_measurement(lm, p)
            return np.array([z[0] - z0[0], wrap_angle(z[1] - z0[1])])

        np.testing.assert_allclose(numdiff(h_rel, pose), H_state, atol=1e-6)
        # the right-perturbation Jacobian it came from, for comparison
        num_xi = numdiff(lambda xi, pose=pose: h_rel(pose_compose(pose, pose_exp(xi))), np.zeros(3))
        np.testing.assert_allclose(num_xi, H_xi, atol=1e-6)


def test_covariance_conversion_round_trip_and_first_order_equivalence(rng):
    theta = 0.9
    A = rng.standard_normal((3, 3))
    cov_xi = A @ A.T * 1e-4
    P = cov_tangent_to_state(cov_xi, theta)
    np.testing.assert_allclose(cov_state_to_tangent(P, theta), cov_xi, atol=1e-15)
    # Monte Carlo: pose·Exp(ξ) with ξ ~ N(0, cov_xi) has additive covariance ≈ P
    pose = np.array([1.0, -2.0, theta])
    xi = rng.multivariate_normal(np.zeros(3), cov_xi, 40000)
    d = pose_compose(np.broadcast_to(pose, xi.shape), pose_exp(xi)) - pose
    d[:, 2] = wrap_angle(d[:, 2])
    emp = np.cov(d.T)
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))
    assert np.max(np.abs(emp - P) / scale) < 0.03


# -------------------------------------------------------------------------------- motion
def test_motion_jacobian_and_process_noise(rng):
    pose = np.array([0.5, 1.0, 2.8])
    u = np.array([0.3, -0.05, 0.2])
    Q_u = odometry_covariance(u, MotionNoiseConfig())
    new, F, Q = predict_pose(pose, u, Q_u)

    def f(p):
        out = pose_compose(p, u) - new
        out[2] = wrap_angle(out[2])
        return out

    np.testing.assert_allclose(numdiff(f, pose), F, atol=1e-7)
    # Q is the additive covariance of pose·u·Exp(n), n ~ N(0, Q_u)
    n = rng.multivariate_normal(np.zeros(3), Q_u, 40000)
    d = pose_compose(np.broadcast_to(new, n.shape), pose_exp(n)) - new
    d[:, 2] = wrap_angle(d[:, 2])
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q)))
    assert np.max(np.abs(np.cov(d.T) - Q) / scale) < 0.03
    # noise per metre / per radian as documented
    d = math.hypot(0.3, 0.05)
    m = MotionNoiseConfig()
    assert Q_u[0, 0] == pytest.approx(
        m.sigma_xy_per_m**2 * d + m.sigma_xy_per_rad**2 * 0.2 + m.sigma_xy_min_m**2
    )
    assert Q_u[2, 2] == pytest.approx(
        m.sigma_theta_per_rad**2 * 0.2 + m.sigma_theta_per_m**2 * d + m.sigma_theta_min_rad**2
    )


# -------------------------------------------------------------------------------- augmentation
def test_augmentation_jacobians_match_numerical_derivatives(rng):
    poses, _ = random_cases(rng, 20)
    for pose in poses:
        z = np.array([[rng.uniform(0.2, 5), rng.uniform(-np.pi, np.pi)]])
        lm, G_x, G_z = landmark_from_measurement(z, pose)

        def of_pose(p, z=z, lm=lm):
            out, _, _ = landmark_from_measurement(z, p)
            return ang_safe((out - lm).ravel())

        def of_z(zz, pose=pose, lm=lm):
            out, _, _ = landmark_from_measurement(zz.reshape(1, 2), pose)
            return ang_safe((out - lm).ravel())

        if lm[0, 0] < 1e-3:  # normal-form flip makes r non-differentiable at 0
            continue
        np.testing.assert_allclose(numdiff(of_pose, pose), G_x[0], atol=1e-6)
        np.testing.assert_allclose(numdiff(of_z, z.ravel()), G_z[0], atol=1e-6)


def test_augmentation_cross_covariances_match_monte_carlo(rng):
    # state: pose + one existing landmark correlated with it
    x = np.array([1.0, 2.0, 0.4, 3.0, 1.1])
    A = rng.standard_normal((5, 5))
    P = A @ A.T * 1e-4 + np.diag([1e-3, 1e-3, 1e-4, 1e-3, 1e-4])
    z = np.array([[2.5, -0.7], [1.5, 1.9]])
    R = np.array([[[4e-4, 1e-5], [1e-5, 1e-4]], [[1e-4, -2e-6], [-2e-6, 5e-5]]])
    x_new, P_new = augment_state(x, P, z, R)
    assert x_new.shape == (9,) and P_new.shape == (9, 9)
    n = 40000
    xs = rng.multivariate_normal(x, P, n)
    zs = np.stack([rng.multivariate_normal(z[i], R[i], n) for i in range(2)], axis=1)
    samples = np.empty((n, 9))
    samples[:, :5] = xs
    line_s = np.concatenate([zs, np.zeros((n, 2, 1))], axis=-1)
    lm_w, _, _ = line_to_parent(line_s, xs[:, None, :3], normal_form=True)
    samples[:, 5:] = lm_w[..., :2].reshape(n, 4)
    d = samples - x_new
    d[:, [2, 4, 6, 8]] = wrap_angle(d[:, [2, 4, 6, 8]])
    emp = np.cov(d.T)
    scale = np.sqrt(np.outer(np.diag(P_new), np.diag(P_new)))
    err = np.abs(emp - P_new) / scale
    assert np.max(err) < 0.04, np.max(err)
    # the cross-covariance with the old landmark is present and correct, not zero
    assert np.max(np.abs(P_new[5:, 3:5]) / scale[5:, 3:5]) > 0.1


# -------------------------------------------------------------------------------- update
def test_sparse_joseph_update_equals_filterpy_reference(rng):
    M = 6
    x = np.concatenate(
        [[0.3, -0.2, 0.5], np.column_stack([rng.uniform(1, 5, M), rng.uniform(-3, 3, M)]).ravel()]
    )
    A = rng.standard_normal((3 + 2 * M, 3 + 2 * M))
    P = A @ A.T * 1e-3 + 1e-4 * np.eye(3 + 2 * M)
    idx = np.array([4, 1, 2])
    lm = x[3:].reshape(M, 2)[idx]
    z_pred, _, _ = predict_line_measurement(lm, x[:3])
    z = z_pred + rng.normal(0, 0.01, z_pred.shape)
    # one measurement given in the other representative (flipped): residual must handle it
    z[1] = [-z[1, 0], wrap_angle(z[1, 1] + np.pi)]
    R = np.stack([np.diag([1e-4, 2e-5])] * 3)
    meas = line_measurements(x, idx, z, R)
    x1, P1, S1, K1 = joseph_update(x, P, meas)
    x2, P2, S2, K2 = filterpy_update(x, P, idx, z, R)
    np.testing.assert_allclose(x1, x2, atol=1e-12)
    np.testing.assert_allclose(P1, P2, atol=1e-12)
    np.testing.assert_allclose(S1, S2, atol=1e-12)
    np.testing.assert_allclose(K1, K2, atol=1e-10)
    # innovation is small although one z is the flipped representative
    assert np.all(np.abs(meas.y) < 0.1)
    # Joseph form with a sub-optimal gain is still the right covariance of the estimator
    # (here: check symmetry and positive definiteness of the posterior)
    assert np.allclose(P1, P1.T)
    assert np.all(np.linalg.eigvalsh(P1) > 0)


def test_linear_gaussian_case_nees_matches_state_dimension():
    """Heading-only motion and known landmark angles: the line EKF is an exact Kalman filter.

    With pure rotations (``u = (0, 0, ω)``), isotropic translation noise and landmark angles
    known exactly, every model the filter uses is linear in ``(x, y, θ, r_1..r_M)``; the pose
    NEES averaged over runs must then follow ``χ²_3`` and the full NEES ``χ²_{3+M}``.
    """
    rng = np.random.default_rng(8)
    n_runs, n_steps, M = 150, 25, 4
    alphas = np.array([0.1, 1.7, -1.4, 3.0])
    r_true0 = np.array([3.0, 2.5, 4.0, 3.5])
    P0_pose = np.diag([0.04, 0.04, 0.01])
    P0_r = 0.25
    Q_u = np.diag([1e-3, 1e-3, 4e-4])  # isotropic in x, y
    R = np.array([[1e-3, 2e-4], [2e-4, 5e-4]])
    cfg = EkfConfig(association=NO_OVERLAP_TEST)
    dim = 3 + M
    nees_pose = np.zeros((n_runs, n_steps))
    nees_full = np.zeros((n_runs, n_steps))
    for run in range(n_runs):
        x0 = np.concatenate([[0.0, 0.0, 0.2], np.column_stack([r_true0, alphas]).ravel()])
        P0 = np.zeros((3 + 2 * M, 3 + 2 * M))
        P0[:3, :3] = P0_pose
        P0[3::2, 3::2] = np.eye(M) * P0_r
        truth = x0.copy()
        truth[:3] += rng.multivariate_normal(np.zeros(3), P0_pose)
        truth[3::2] += rng.normal(0.0, math.sqrt(P0_r), M)
        ekf = EkfSlam(cfg)
        ekf.set_state(x0, P0)
        for k in range(n_steps):
            omega = 0.3 * math.sin(0.5 * k)
            ekf.predict(np.array([0.0, 0.0, omega]), Q_u)
            noise_add = rng.multivariate_normal(np.zeros(3), Q_u)  # isotropic: same in any frame
            truth[:3] = truth[:3] + np.array([0.0, 0.0, omega]) + noise_add
            lm_true = truth[3:].reshape(M, 2)
            z_true, _, _ = predict_line_measurement(lm_true, truth[:3])
            z = z_true + rng.multivariate_normal(np.zeros(2), R, M)
            ekf.update(np.arange(M), z, np.stack([R] * M))
            e = ekf.x - truth
            e[2] = wrap_angle(e[2])
            e[4::2] = wrap_angle(e[4::2])
            keep = np.r_[0, 1, 2, 3 + 2 * np.arange(M)]
            ek, Pk = e[keep], ekf.P[np.ix_(keep, keep)]
            nees_full[run, k] = ek @ np.linalg.solve(Pk, ek)
            from slam.evaluation import pose_nees_values

            nees_pose[run, k] = pose_nees_values(ekf.x[:3], ekf.pose_covariance, truth[:3])
        # landmark angles stayed exactly known
        np.testing.assert_allclose(ekf.x[4::2], alphas, atol=1e-12)
    from slam.evaluation import nees_bounds

    for nees, d in ((nees_pose, 3), (nees_full, dim)):
        anees = nees.mean(axis=0)
        lo, hi = nees_bounds(d, n_runs, 0.95)
        inside = np.mean((anees > lo) & (anees < hi))
        assert inside >= 0.8, (d, anees)
        lo99, hi99 = nees_bounds(d, n_runs * n_steps, 0.99)
        assert lo99 * 0.97 < nees.mean() < hi99 * 1.03, (d, nees.mean())


# -------------------------------------------------------------------------------- association
def _corridor_state(pred_y=0.0, sigma_y=0.5):
    # walls: A y=1 (α=π/2, r=1), B y=1.5 (r=1.5), C x=3 (α=0, r=3)
    x = np.array([0.0, pred_y, 0.0, 1.0, np.pi / 2, 1.5, np.pi / 2, 3.0, 0.0])
    P = np.diag([0.01, sigma_y**2, 1e-4, 1e-6, 1e-8, 1e-6, 1e-8, 1e-6, 1e-8])
    return x, P


def _lines_from_truth(x_true, lm_idx, R):
    lm = x_true[3:].reshape(-1, 2)[lm_idx]
    z, _, _ = predict_line_measurement(lm, x_true[:3])
    ends = np.zeros((len(lm_idx), 2, 2))
    return LineSet(z, np.stack([R] * len(lm_idx)), ends, np.asarray(lm_idx, dtype=np.int64))


def test_jcbb_resolves_what_nearest_neighbour_gets_wrong():
    x_pred, P = _corridor_state()
    x_true = x_pred.copy()
    x_true[1] = 0.5  # the robot is 0.5 m further up than predicted
    R = np.diag([1e-4, 1e-4])
    lines = _lines_from_truth(x_true, [0, 1, 2], R)
    results = {}
    for method in ("nn", "jcbb"):
        ekf = EkfSlam(EkfConfig(association=replace(NO_OVERLAP_TEST, method=method)))
        ekf.set_state(x_pred, P)
        matches, _ = ekf.associate(lines)
        results[method] = matches.tolist()
    assert results["jcbb"] == [0, 1, 2]
    assert results["nn"] != [0, 1, 2]


def test_overlap_gating_keeps_collinear_walls_apart():
    # one landmark y=1 seen between x in [0, 2]; a measurement of the same line at x in [6, 8]
    ekf = EkfSlam(EkfConfig(association=AssociationConfig(overlap_margin_m=0.5)))
    x = np.array([5.0, 0.0, 0.0, 1.0, np.pi / 2])
    P = np.diag([1e-4, 1e-4, 1e-6, 1e-4, 1e-6])
    ekf.set_state(x, P, ends_world=np.array([[[0.0, 1.0], [2.0, 1.0]]]))
    z = np.array([[1.0, np.pi / 2]])
    far = LineSet(
        z, np.array([np.diag([1e-4, 1e-5])]), np.array([[[1.0, 1.0], [3.0, 1.0]]]), np.array([0])
    )
    near = LineSet(
        z, np.array([np.diag([1e-4, 1e-5])]), np.array([[[-4.0, 1.0], [-2.8, 1.0]]]), np.array([0])
    )
    m_far, amb_far = ekf.associate(far)
    m_near, _ = ekf.associate(near)
    assert m_far.tolist() == [-1] and not amb_far[0]
    assert m_near.tolist() == [0]


# -------------------------------------------------------------------------------- merging
def test_merging_two_independent_landmarks_gives_the_information_fusion():
    ekf = EkfSlam(EkfConfig(association=NO_OVERLAP_TEST))
    l1, l2 = np.array([2.00, 0.50]), np.array([2.03, 0.49])
    P1 = np.array([[4e-4, 1e-5], [1e-5, 1e-4]])
    P2 = np.array([[2e-4, -2e-5], [-2e-5, 3e-4]])
    x = np.concatenate(
        [[0.0, 0.0, 0.0], l1, [-2.03, 0.49 + np.pi]]
    )  # l2 in the other representative
    P = np.zeros((7, 7))
    P[:3, :3] = np.eye(3) * 1e-6
    P[3:5, 3:5] = P1
    flip = np.diag([-1.0, 1.0])
    P[5:7, 5:7] = flip @ P2 @ flip
    ekf.set_state(x, P)
    assert ekf.merge_landmarks() == 1
    assert ekf.n_landmarks == 1
    info = np.linalg.inv(P1) + np.linalg.inv(P2)
    fused = np.linalg.solve(info, np.linalg.solve(P1, l1) + np.linalg.solve(P2, l2))
    np.testing.assert_allclose(ekf.x[3:5], fused, atol=1e-9)
    np.testing.assert_allclose(ekf.P[3:5, 3:5], np.linalg.inv(info), atol=1e-12)


def test_constraint_and_removal_equal_the_joseph_update_then_deletion():
    from slam.ekf.update import MeasurementStack, constrain_and_remove

    rng = np.random.default_rng(12)
    n = 3 + 2 * 6
    A = rng.standard_normal((n, n))
    P = A @ A.T / n + 0.01 * np.eye(n)
    x = rng.standard_normal(n)
    H_sub = np.hstack([np.diag([-1.0, 1.0]), -np.eye(2)])
    cols = np.array([5, 6, 11, 12])
    meas = MeasurementStack(rng.standard_normal(2), H_sub, cols, np.zeros((2, 2)))
    x_j, P_j, _, _ = joseph_update(x, P, meas)
    keep = np.setdiff1d(np.arange(n), cols[2:])
    x_c, P_c = constrain_and_remove(x, P, meas, cols[2:])
    np.testing.assert_allclose(x_c, x_j[keep], atol=1e-10)
    np.testing.assert_allclose(P_c, P_j[np.ix_(keep, keep)], atol=1e-10)
    assert np.array_equal(P_c, P_c.T)
    # the constraint holds exactly after conditioning (before removal, in the Joseph result)
    np.testing.assert_allclose(H_sub @ x_j[cols], H_sub @ x[cols] + meas.y, atol=1e-10)


def test_distinct_landmarks_are_not_merged():
    ekf = EkfSlam(EkfConfig(association=NO_OVERLAP_TEST))
    x = np.array([0.0, 0.0, 0.0, 2.0, 0.5, 2.5, 0.5])
    P = np.diag([1e-6] * 3 + [1e-4, 1e-5, 1e-4, 1e-5])
    ekf.set_state(x, P)
    assert ekf.merge_landmarks() == 0 and ekf.n_landmarks == 2


# -------------------------------------------------------------------------------- object API
def _scan(k, odom, t=None):
    return Scan(
        index=k,
        timestamp=float(k) if t is None else t,
        ranges=np.zeros(0),
        bearings=np.zeros(0),
        pose_odom_laser=np.asarray(odom, float),
        source=f"test:{k}",
    )


def test_bad_input_gives_clear_errors():
    ekf = EkfSlam()
    no_odom = Scan(
        index=0, timestamp=0.0, ranges=np.zeros(0), bearings=np.zeros(0), source="log.clf:7"
    )
    with pytest.raises(InputError, match=r"log\.clf:7.*no odometry"):
        ekf.add_scan(no_odom, LineSet.empty())
    with pytest.raises(InputError, match=r"scan 0: odometry is not finite"):
        ekf.add_scan(_scan(0, [0.0, np.nan, 0.0]), LineSet.empty())
    # a line with a singular or NaN covariance is skipped and counted, not used
    ekf = EkfSlam(EkfConfig(association=NO_OVERLAP_TEST))
    bad = LineSet(
        np.array([[1.0, 0.0], [2.0, 1.0]]),
        np.array([np.zeros((2, 2)), np.full((2, 2), np.nan)]),
        np.zeros((2, 2, 2)),
        np.array([0, 1]),
    )
    rep = ekf.add_scan(_scan(0, [0, 0, 0]), bad)
    assert rep.n_invalid == 2 and ekf.n_landmarks == 0
    for kwargs in (
        {"new_landmark_probability": 1.5},
        {"association": "gnn"},
        {"max_landmarks": 0},
        {"initial_pose_sigma": (0.1, -1.0, 0.0)},
        {"update_impl": "dense"},
    ):
        with pytest.raises(ConfigError):
            EkfConfig(**kwargs)
    with pytest.raises(ConfigError):
        MotionNoiseConfig(sigma_xy_min_m=0.0)


def _line_run(seed=3, loops=1.0):
    from slam.experiments.linesim import corridor_loop_world, loop_trajectory, simulate_line_run

    world = corridor_loop_world()
    return simulate_line_run(world, loop_trajectory(loops=loops), seed=seed)


def test_max_landmarks_guard_stops_or_freezes():
    run = _line_run()
    ekf = EkfSlam(EkfConfig(max_landmarks=5, on_max_landmarks="stop"))
    n_fed = 0
    for scan, lines in zip(run.scans, run.lines, strict=True):
        if ekf.stopped:
            break
        ekf.add_scan(scan, lines)
        n_fed += 1
    assert ekf.stopped and "max_landmarks=5" in ekf.stop_reason
    res = ekf.result()
    assert res.stats["stopped_at_scan"] == n_fed - 1 and res.n_scans == n_fed
    assert ekf.n_landmarks <= 5
    rep = ekf.add_scan(run.scans[n_fed], run.lines[n_fed])  # ignored after the stop
    assert rep.skipped and ekf.result().n_scans == n_fed
    assert ekf.result().stats["scans_after_stop"] == 1
    ekf = EkfSlam(EkfConfig(max_landmarks=5, on_max_landmarks="freeze"))
    for scan, lines in zip(run.scans, run.lines, strict=True):
        ekf.add_scan(scan, lines)
    assert not ekf.stopped and ekf.n_landmarks == 5
    assert ekf.result().stats["lines_not_added"] > 0


def test_results_files_follow_the_interfaces(tmp_path):
    run = _line_run()
    ekf = EkfSlam()
    for scan, lines in zip(run.scans[:40], run.lines[:40], strict=True):
        ekf.add_scan(scan, lines)
    res = ekf.result()
    res.write(tmp_path)
    rows = np.loadtxt(tmp_path / "trajectory.tum")
    assert rows.shape == (40, 8)
    np.testing.assert_allclose(rows[:, 0], res.timestamps, atol=1e-6)
    yaw = 2 * np.arctan2(rows[:, 6], rows[:, 7])
    np.testing.assert_allclose(wrap_angle(yaw - res.poses_world_laser[:, 2]), 0, atol=1e-9)
    np.testing.assert_allclose(rows[:, 1:3], res.poses_world_laser[:, :2], atol=1e-8)
    m = json.loads((tmp_path / "map.json").read_text())
    assert m["frame"] == "world" and len(m["lines"]) == ekf.n_landmarks
    for line in m["lines"]:
        assert line["r"] >= 0 and -np.pi < line["alpha"] <= np.pi
        assert np.all(np.linalg.eigvalsh(np.array(line["cov"])) > 0)
        assert len(line["segments"]) >= 1
    s = json.loads((tmp_path / "summary.json").read_text())
    for key in (
        "scans",
        "points",
        "lines_fit",
        "lines_merged",
        "compression",
        "runtime_s",
        "frame",
    ):
        assert key in s
    assert s["scans"] == 40 and s["frame"] == "laser"
    assert s["backend"] == "ekf" and s["state_dim"] == 3 + 2 * ekf.n_landmarks
    # the pose covariances are written too (the graph's file), in the tangent space
    from slam.io import read_results

    back = read_results(tmp_path)
    assert back.covariances is not None
    np.testing.assert_allclose(back.covariances, res.pose_covariances, rtol=1e-8, atol=1e-15)


def test_the_map_keeps_landmarks_with_enough_observations(tmp_path):
    run = _line_run()
    ekf = EkfSlam()
    for scan, lines in zip(run.scans[:80], run.lines[:80], strict=True):
        ekf.add_scan(scan, lines)
    res = ekf.result()
    n_obs = res.landmark_n_observations
    assert np.any(n_obs < 5) and np.any(n_obs >= 5)  # the threshold below separates them
    res.write(tmp_path, min_observations=5)
    m = json.loads((tmp_path / "map.json").read_text())
    assert [line["id"] for line in m["lines"]] == np.flatnonzero(n_obs >= 5).tolist()
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["lines_merged"] == len(m["lines"]) and s["landmarks"] == ekf.n_landmarks
    n_seg = sum(len(line["segments"]) for line in m["lines"])
    assert s["segments"] == n_seg
    assert s["points"] == 0 and s["compression"] is None  # line-level scans: no readings


def test_updates_are_the_keyframes_of_the_result():
    """Scans whose lines updated the filter are the result's keyframes; the others hang from
    the last one, their pose that one's composed with the odometry since."""
    run = _line_run()
    ekf = EkfSlam(EkfConfig(update_min_distance_m=0.5, update_min_angle_rad=0.5))
    reports = [ekf.add_scan(s, ls) for s, ls in zip(run.scans[:60], run.lines[:60], strict=True)]
    res = ekf.result()
    updated = np.array([r.updated for r in reports])
    assert res.is_keyframe[0] and 3 < np.count_nonzero(res.is_keyframe) < 40
    np.testing.assert_array_equal(res.is_keyframe[1:], updated[1:])
    kf = res.keyframe_of_scan
    np.testing.assert_array_equal(kf, np.cumsum(res.is_keyframe) - 1)
    scan_of_kf = np.flatnonzero(res.is_keyframe)
    odom = np.array([s.pose_odom_laser for s in run.scans[:60]])
    for k in np.flatnonzero(~res.is_keyframe):
        j = scan_of_kf[kf[k]]
        offset = pose_between(odom[j], odom[k])
        np.testing.assert_allclose(
            res.poses_world_laser[k], pose_compose(res.poses_world_laser[j], offset), atol=1e-12
        )


def test_base_output_frame_reports_base_poses_with_covariances_by_the_adjoint():
    """``InputPolicy(output_frame="base")``: each pose is the laser's composed with the inverse
    mounting, each covariance carried to the base's tangent space (checked against a numerical
    Jacobian of ``ξ_base(ξ_laser)``)."""
    from slam.geometry import pose_log
    from slam.inputs import InputPolicy

    run = _line_run()
    mount = np.array([0.25, -0.08, 0.3])
    laser = EkfSlam(policy=InputPolicy(pose_base_laser=tuple(mount)))
    base = EkfSlam(policy=InputPolicy(pose_base_laser=tuple(mount), output_frame="base"))
    for scan, lines in zip(run.scans[:40], run.lines[:40], strict=True):
        laser.add_scan(scan, lines)
        base.add_scan(scan, lines)
    res_l, res_b = laser.result(), base.result()
    assert res_l.frame == "laser" and res_b.frame == "base"
    pl = res_l.poses_world_laser
    th = pl[:, 2] - mount[2]
    expected = np.column_stack(
        [
            pl[:, 0] - np.cos(th) * mount[0] + np.sin(th) * mount[1],
            pl[:, 1] - np.sin(th) * mount[0] - np.cos(th) * mount[1],
            th,
        ]
    )
    np.testing.assert_allclose(res_b.poses_world_laser[:, :2], expected[:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(res_b.poses_world_laser[:, 2] - th), 0.0, atol=1e-12)
    m_inv = pose_inverse(mount)
    eps = 1e-6
    for k in (5, 17, 39):
        b0 = pose_compose(pl[k], m_inv)
        J = np.zeros((3, 3))
        for i in range(3):
            step = np.zeros(3)
            step[i] = eps
            plus = pose_compose(pose_compose(pl[k], pose_exp(step)), m_inv)
            minus = pose_compose(pose_compose(pl[k], pose_exp(-step)), m_inv)
            J[:, i] = (pose_log(pose_between(b0, plus)) - pose_log(pose_between(b0, minus))) / (
                2 * eps
            )
        P_l = res_l.pose_covariances[k]
        assert np.trace(P_l) > 0.0
        np.testing.assert_allclose(res_b.pose_covariances[k], J @ P_l @ J.T, rtol=1e-6)
    np.testing.assert_array_equal(res_b.landmarks_r_alpha, res_l.landmarks_r_alpha)


def test_run_config_round_trip_with_ekf_table(tmp_path):
    cfg = RunConfig(
        ekf=EkfConfig(
            association=AssociationConfig(method="nn", gate_probability=0.99),
            max_landmarks=300,
            max_runtime_s=60.0,
            odometry=MotionNoiseConfig(sigma_xy_per_m=0.1),
            initial_pose_sigma=(0.1, 0.1, 0.01),
        )
    )
    cfg.to_toml(tmp_path / "c.toml")
    assert RunConfig.from_toml(tmp_path / "c.toml") == cfg
    (tmp_path / "bad.toml").write_text("[ekf]\nassociation = 'magic'\n")
    with pytest.raises(ConfigError, match="association"):
        RunConfig.from_toml(tmp_path / "bad.toml")


def test_filterpy_and_sparse_runs_agree_on_a_simulated_stretch():
    run = _line_run(seed=5)
    out = []
    for impl in ("sparse", "filterpy"):
        ekf = EkfSlam(EkfConfig(update_impl=impl))
        for scan, lines in zip(run.scans[:60], run.lines[:60], strict=True):
            ekf.add_scan(scan, lines)
        out.append((ekf.x.copy(), ekf.P.copy()))
    np.testing.assert_allclose(out[0][0], out[1][0], atol=1e-9)
    np.testing.assert_allclose(out[0][1], out[1][1], atol=1e-11)


def test_the_per_log_configs_load():
    from pathlib import Path

    files = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.toml"))
    assert files
    for path in files:
        cfg = RunConfig.from_toml(path)
        assert cfg.ekf.odometry.sigma_xy_per_m > 0.0, path  # the calibrated table was read
