"""Odometry from noisy relative motions between consecutive true poses.

The noise model (per step, in the frame of the earlier pose) is documented on
:class:`~slam.sim.config.OdometryNoiseConfig`.  The odometry poses are the noisy motions
integrated from the true first pose.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.line import wrap_angle
from slam.errors import InputError
from slam.geometry import pose_between
from slam.sim.config import OdometryNoiseConfig

__all__ = [
    "integrate_motions",
    "motion_noise_covariance",
    "noisy_motions",
    "relative_motions",
    "simulate_odometry",
]

FloatArray = NDArray[np.float64]


def _poses(poses: ArrayLike, name: str) -> FloatArray:
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise InputError(f"{name} contains NaN or infinite values")
    return p


def relative_motions(poses_world_base: ArrayLike) -> FloatArray:
    """``pose[k]⁻¹ · pose[k + 1]`` for consecutive poses, shape ``(n − 1, 3)``."""
    p = _poses(poses_world_base, "poses_world_base")
    return pose_between(p[:-1], p[1:])


def motion_noise_covariance(motions: ArrayLike, config: OdometryNoiseConfig) -> FloatArray:
    """Covariance ``(m, 3, 3)`` of the random part of the noisy motions (biases excluded).

    Diagonal: ``σ_t²·Δs`` for x and y, ``σ_rr²·|dθ| + σ_rm²·Δs`` for θ.
    """
    u = _poses(motions, "motions")
    trans = np.hypot(u[:, 0], u[:, 1])
    var_xy = config.sigma_trans_per_m**2 * trans
    var_th = config.sigma_rot_per_rad**2 * np.abs(u[:, 2]) + config.sigma_rot_per_m**2 * trans
    cov = np.zeros((u.shape[0], 3, 3))
    cov[:, 0, 0] = var_xy
    cov[:, 1, 1] = var_xy
    cov[:, 2, 2] = var_th
    return cov


def noisy_motions(
    motions: ArrayLike, config: OdometryNoiseConfig, rng: np.random.Generator
) -> FloatArray:
    """The motions as the odometry reads them (bias + Gaussian noise), shape ``(m, 3)``."""
    u = _poses(motions, "motions")
    trans = np.hypot(u[:, 0], u[:, 1])
    std = np.sqrt(np.diagonal(motion_noise_covariance(u, config), axis1=1, axis2=2))
    noise = rng.standard_normal(u.shape) * std
    out = np.empty_like(u)
    out[:, 0] = (1.0 + config.scale_bias) * u[:, 0] + noise[:, 0]
    out[:, 1] = (1.0 + config.scale_bias) * u[:, 1] + noise[:, 1]
    out[:, 2] = (
        (1.0 + config.rot_scale_bias) * u[:, 2]
        + config.heading_drift_rad_per_m * trans
        + noise[:, 2]
    )
    return out


def integrate_motions(start_pose: ArrayLike, motions: ArrayLike) -> FloatArray:
    """Poses ``start · u_0 · u_1 ⋯``, shape ``(m + 1, 3)`` (one step per motion)."""
    u = _poses(motions, "motions")
    start = np.asarray(start_pose, dtype=np.float64)
    # θ_k = θ_0 + Σ_{j<k} dθ_j (unwrapped), p_{k+1} = p_k + Rot(θ_k)·(dx_k, dy_k).
    theta = start[2] + np.concatenate([[0.0], np.cumsum(u[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    steps = np.column_stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]])
    xy = start[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, wrap_angle(theta)])


def simulate_odometry(
    poses_world_base: ArrayLike, config: OdometryNoiseConfig, rng: np.random.Generator
) -> FloatArray:
    """Odometry poses ``pose_odom_base`` ``(n, 3)`` for the true poses ``poses_world_base``.

    The odometry frame is the world frame at the first scan (``pose_odom_base[0]`` is the true
    first pose); every later pose integrates the noisy relative motions.
    """
    p = _poses(poses_world_base, "poses_world_base")
    return integrate_motions(p[0], noisy_motions(relative_motions(p), config, rng))
