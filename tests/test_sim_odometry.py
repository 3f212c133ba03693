"""Odometry noise: per-step covariance, per-metre semantics, biases, integration."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from slam.geometry import pose_between
from slam.sim import (
    OdometryNoiseConfig,
    integrate_motions,
    motion_noise_covariance,
    noisy_motions,
    relative_motions,
    simulate_odometry,
)


def _chi2_ok(sum_sq: float, dof: int, alpha: float = 0.001) -> bool:
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], dof)
    return bool(lo < sum_sq < hi)


def test_noisy_motion_covariance_matches_the_configured_noise(rng):
    config = OdometryNoiseConfig(
        sigma_trans_per_m=0.05, sigma_rot_per_rad=0.1, sigma_rot_per_m=0.02
    )
    motion = np.array([0.3, 0.04, 0.2])
    n = 20000
    u = np.tile(motion, (n, 1))
    noisy = noisy_motions(u, config, rng)
    cov = motion_noise_covariance(u[:1], config)[0]
    trans = np.hypot(0.3, 0.04)
    np.testing.assert_allclose(
        np.diag(cov), [0.05**2 * trans, 0.05**2 * trans, 0.1**2 * 0.2 + 0.02**2 * trans]
    )
    err = noisy - motion
    # Mean zero, each variance as predicted (chi-square), NEES ≈ 3.
    assert (np.abs(err.mean(axis=0)) < 4.0 * np.sqrt(np.diag(cov) / n)).all()
    for k in range(3):
        assert _chi2_ok(float((err[:, k] ** 2).sum() / cov[k, k]), n), k
    nees = np.einsum("ni,ij,nj->n", err, np.linalg.inv(cov), err)
    assert _chi2_ok(float(nees.sum()), 3 * n)
    # Components independent.
    c = np.corrcoef(err.T)
    assert np.abs(c[np.triu_indices(3, 1)]).max() < 4.0 / np.sqrt(n)


@pytest.mark.parametrize("step_m", [0.1, 1.0])
def test_noise_per_metre_does_not_depend_on_the_step_size(rng, step_m):
    """After 20 m straight, heading std = σ_rot_per_m·√20 and along-track std = σ_t·√20."""
    config = OdometryNoiseConfig(
        sigma_trans_per_m=0.03, sigma_rot_per_rad=0.0, sigma_rot_per_m=0.01
    )
    length, trials = 20.0, 4000
    steps = round(length / step_m)
    u = np.tile([step_m, 0.0, 0.0], (trials * steps, 1))
    noisy = noisy_motions(u, config, rng).reshape(trials, steps, 3)
    heading = noisy[:, :, 2].sum(axis=1)
    along = noisy[:, :, 0].sum(axis=1) - length
    assert _chi2_ok(float((heading**2).sum() / (0.01**2 * length)), trials)
    assert _chi2_ok(float((along**2).sum() / (0.03**2 * length)), trials)


def test_biases_without_noise_are_exact():
    config = OdometryNoiseConfig(
        sigma_trans_per_m=0.0,
        sigma_rot_per_rad=0.0,
        sigma_rot_per_m=0.0,
        scale_bias=0.01,
        rot_scale_bias=-0.02,
        heading_drift_rad_per_m=0.002,
    )
    # 100 m straight in 0.5 m steps, then a 90° turn on the spot.
    u = np.vstack([np.tile([0.5, 0.0, 0.0], (200, 1)), [[0.0, 0.0, np.pi / 2]]])
    noisy = noisy_motions(u, config, np.random.default_rng(0))
    assert np.hypot(noisy[:, 0], noisy[:, 1]).sum() == pytest.approx(101.0, rel=1e-12)
    assert noisy[:200, 2].sum() == pytest.approx(0.2, rel=1e-12)
    assert noisy[200, 2] == pytest.approx(0.98 * np.pi / 2, rel=1e-12)


def test_integration_inverts_relative_motions(rng):
    poses = np.cumsum(rng.normal(0.0, [0.3, 0.3, 0.4], (50, 3)), axis=0)
    poses[:, 2] = np.angle(np.exp(1j * poses[:, 2]))
    again = integrate_motions(poses[0], relative_motions(poses))
    np.testing.assert_allclose(pose_between(again, poses), 0.0, atol=1e-10)


def test_noise_free_odometry_is_the_true_trajectory_and_noise_drifts(rng):
    t = np.linspace(0.0, 2 * np.pi, 200)
    poses = np.column_stack([5 * np.cos(t), 5 * np.sin(t), np.angle(np.exp(1j * (t + np.pi / 2)))])
    quiet = OdometryNoiseConfig(sigma_trans_per_m=0.0, sigma_rot_per_rad=0.0, sigma_rot_per_m=0.0)
    np.testing.assert_allclose(
        pose_between(simulate_odometry(poses, quiet, rng), poses), 0.0, atol=1e-10
    )
    odom = simulate_odometry(poses, OdometryNoiseConfig(), rng)
    np.testing.assert_array_equal(odom[0], poses[0])  # odometry frame = world frame at scan 0
    assert np.linalg.norm(odom[-1, :2] - poses[-1, :2]) > 1e-3
