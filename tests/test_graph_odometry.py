"""Odometry / prior factors in numpy against GTSAM's native factors."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from slam.geometry import pose_exp, pose_log, pose_retract, right_jacobian_pose2
from slam.graph.odometry import between_costs, linearize_between, linearize_prior, sqrt_information
from slam.models.motion import MotionNoiseConfig


def test_right_jacobian_matches_gtsam_and_numerical(rng):
    xi = np.column_stack([rng.normal(0, 2, (40, 2)), rng.uniform(-3, 3, 40)])
    xi[0, 2] = 1e-6  # the series branch
    xi[1, 2] = 0.0
    xi[2, 2] = 1.5e-4  # just above it
    J = right_jacobian_pose2(xi)
    for n in range(40):
        # GTSAM drops the O(ω) terms below |ω| < 1e-5; elsewhere the two agree to round-off
        np.testing.assert_allclose(J[n], gtsam.Pose2.ExpmapDerivative(xi[n]), atol=1e-6)
    xi, J = xi[3:], J[3:]  # numerical derivatives need |ω| ≫ eps (pose_exp's own precision)
    eps = 1e-6
    for n in range(xi.shape[0]):
        cols = []
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            # Exp(ξ + d) = Exp(ξ) Exp(J_r d)  =>  J_r d ≈ Log(Exp(ξ)⁻¹ Exp(ξ + d))
            e0 = pose_exp(xi[n])
            plus = pose_log(np.asarray(_between(e0, pose_exp(xi[n] + d))))
            minus = pose_log(np.asarray(_between(e0, pose_exp(xi[n] - d))))
            cols.append((plus - minus) / (2 * eps))
        np.testing.assert_allclose(J[n], np.stack(cols, -1), atol=1e-6)


def _between(a, b):
    from slam.geometry import pose_between

    return pose_between(a, b)


def test_between_and_prior_match_gtsam(rng):
    for _ in range(20):
        pi = np.r_[rng.normal(0, 5, 2), rng.uniform(-3, 3)]
        pj = np.r_[rng.normal(0, 5, 2), rng.uniform(-3, 3)]
        m = np.r_[rng.normal(0, 1, 2), rng.uniform(-3, 3)]
        A = rng.normal(size=(3, 3))
        cov = A @ A.T + 0.1 * np.eye(3)
        W = sqrt_information(cov[None])
        noise = gtsam.noiseModel.Gaussian.Covariance(cov)
        values = gtsam.Values()
        values.insert(X(0), gtsam.Pose2(*pi))
        values.insert(X(1), gtsam.Pose2(*pj))
        f = gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(*m), noise)
        Ab, b = f.linearize(values).jacobian()
        Ai, Aj, bb = linearize_between(pi[None], pj[None], m[None], W)
        np.testing.assert_allclose(Ab, np.hstack([Ai[0], Aj[0]]), atol=1e-9)
        np.testing.assert_allclose(b, bb[0], atol=1e-9)
        assert between_costs(pi[None], pj[None], m[None], W)[0] == pytest.approx(f.error(values))
        pf = gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*m), noise)
        Ap, bp = pf.linearize(values).jacobian()
        A2, b2, c2 = linearize_prior(pi, m, W[0])
        np.testing.assert_allclose(Ap, A2, atol=1e-9)
        np.testing.assert_allclose(bp, b2, atol=1e-9)
        assert c2 == pytest.approx(pf.error(values))


def test_motion_noise_random_walk(rng):
    cfg = MotionNoiseConfig(sigma_xy_per_m=0.1, sigma_theta_per_rad=0.2)
    one = cfg.covariance(np.array([2.0, 0.0, 0.0]))
    halves = cfg.covariance(np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])).sum(0)
    # variances grow linearly with distance (the floors count once per step)
    floor = np.diag([cfg.sigma_xy_min_m**2] * 2 + [cfg.sigma_theta_min_rad**2])
    np.testing.assert_allclose(halves - floor, one, rtol=1e-12)
    assert one[0, 0] == pytest.approx(cfg.sigma_xy_min_m**2 + 0.1**2 * 2.0 + 0.0)
    turn = cfg.covariance(np.array([0.0, 0.0, -0.5]))
    assert turn[2, 2] == pytest.approx(cfg.sigma_theta_min_rad**2 + 0.2**2 * 0.5)
    # a retracted pose with noise of this covariance has that empirical covariance
    xi = rng.multivariate_normal(np.zeros(3), one, 20000)
    p = pose_retract(np.zeros((20000, 3)), xi)
    assert np.cov(pose_log(p).T)[0, 0] == pytest.approx(one[0, 0], rel=0.05)
