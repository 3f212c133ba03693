"""Odometry motion model of the EKF prediction step.

The filter is driven by the odometry **increment** between consecutive scans,
``u_k = pose_odom_laser[k-1]⁻¹ · pose_odom_laser[k]`` (laser frame at ``k-1``), composed on the
right: ``pose_k = pose_{k-1} · u_k · Exp(n_k)`` with ``n_k ~ N(0, Q_u)`` in the tangent space
of the new pose, the same error model as a GTSAM ``BetweenFactorPose2(u_k, Q_u)``.

Noise per metre and per radian (:class:`OdometryNoiseConfig`), the random-walk model of the
simulator (:mod:`slam.sim.odometry`): with ``Δs = ‖(u_x, u_y)‖`` and ``|Δθ| = |u_θ|``

``σ_xy² = σ_t²·Δs + σ_xy,min²``,  ``σ_θ² = σ_rr²·|Δθ| + σ_rm²·Δs + σ_θ,min²``,

``Q_u = diag(σ_xy², σ_xy², σ_θ²)``.  Variances grow linearly with distance and angle, so the
integrated uncertainty does not depend on how often scans arrive; the small floors keep ``Q_u``
positive definite when the robot stands still.

State Jacobians for the additive ``(x, y, θ)`` error of :mod:`slam.ekf.conventions`:
``F = ∂pose_k/∂pose_{k-1} = [[1, 0, −s u_x − c u_y], [0, 1, c u_x − s u_y], [0, 0, 1]]``
(``c, s`` of ``θ_{k-1}``) and ``Q = J(θ_k) Q_u J(θ_k)ᵀ``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.ekf.conventions import tangent_to_state_jacobian
from slam.errors import ConfigError
from slam.geometry import pose_compose

__all__ = ["OdometryNoiseConfig", "odometry_covariance", "predict_pose"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Odometry noise per metre and per radian (random walk; field names as in ``slam.sim``).

    Attributes
    ----------
    sigma_trans_per_m : float
        ``σ_t`` (m/√m): standard deviation per axis of the translation error after 1 m.
    sigma_rot_per_rad : float
        ``σ_rr`` (rad/√rad): heading error after turning 1 rad.
    sigma_rot_per_m : float
        ``σ_rm`` (rad/√m): heading error after 1 m of travel.
    sigma_xy_min_m : float
        Floor added to the translation σ of every increment (m).
    sigma_theta_min_rad : float
        Floor added to the heading σ of every increment (rad).
    """

    sigma_trans_per_m: float = 0.02
    sigma_rot_per_rad: float = 0.02
    sigma_rot_per_m: float = 0.005
    sigma_xy_min_m: float = 1e-4
    sigma_theta_min_rad: float = 1e-4

    def __post_init__(self) -> None:
        for name in (
            "sigma_trans_per_m",
            "sigma_rot_per_rad",
            "sigma_rot_per_m",
            "sigma_xy_min_m",
            "sigma_theta_min_rad",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"odometry noise {name} must be a number >= 0, got {value!r}")
        if self.sigma_xy_min_m <= 0.0 or self.sigma_theta_min_rad <= 0.0:
            raise ConfigError("odometry noise floors sigma_xy_min_m, sigma_theta_min_rad: > 0")

    def scaled(self, factor: float) -> OdometryNoiseConfig:
        """The same model with the per-metre and per-radian σ multiplied by ``factor``."""
        return OdometryNoiseConfig(
            sigma_trans_per_m=self.sigma_trans_per_m * factor,
            sigma_rot_per_rad=self.sigma_rot_per_rad * factor,
            sigma_rot_per_m=self.sigma_rot_per_m * factor,
            sigma_xy_min_m=self.sigma_xy_min_m,
            sigma_theta_min_rad=self.sigma_theta_min_rad,
        )


def odometry_covariance(increment: FloatArray, noise: OdometryNoiseConfig) -> FloatArray:
    """``Q_u``, the covariance of one odometry increment in the tangent space; shape (..., 3, 3).

    Parameters
    ----------
    increment : ndarray, shape (..., 3)
        Odometry increments ``(u_x, u_y, u_θ)``.
    noise : OdometryNoiseConfig
        Noise per metre / per radian.
    """
    u = np.asarray(increment, dtype=float)
    d = np.hypot(u[..., 0], u[..., 1])
    var_xy = noise.sigma_trans_per_m**2 * d + noise.sigma_xy_min_m**2
    var_th = (
        noise.sigma_rot_per_rad**2 * np.abs(u[..., 2])
        + noise.sigma_rot_per_m**2 * d
        + noise.sigma_theta_min_rad**2
    )
    Q = np.zeros((*u.shape[:-1], 3, 3))
    Q[..., 0, 0] = var_xy
    Q[..., 1, 1] = var_xy
    Q[..., 2, 2] = var_th
    return Q


def predict_pose(
    pose_world_laser: FloatArray, increment: FloatArray, Q_u: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Propagate a pose by an odometry increment, with the state Jacobian and process noise.

    Parameters
    ----------
    pose_world_laser : ndarray, shape (3,)
        Pose at ``k-1``.
    increment : ndarray, shape (3,)
        Odometry increment ``u_k`` (laser frame at ``k-1``).
    Q_u : ndarray, shape (3, 3)
        Covariance of the increment in the tangent space of the new pose.

    Returns
    -------
    pose_new : ndarray, shape (3,)
        ``pose_{k-1} · u_k`` (θ wrapped).
    F : ndarray, shape (3, 3)
        ``∂pose_k/∂pose_{k-1}`` for the additive ``(x, y, θ)`` error.
    Q : ndarray, shape (3, 3)
        Process noise for the additive error, ``J(θ_k) Q_u J(θ_k)ᵀ``.
    """
    pose = np.asarray(pose_world_laser, dtype=float)
    u = np.asarray(increment, dtype=float)
    pose_new = pose_compose(pose, u)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    F = np.eye(3)
    F[0, 2] = -s * u[0] - c * u[1]
    F[1, 2] = c * u[0] - s * u[1]
    J = tangent_to_state_jacobian(pose_new[2])
    Q = J @ np.asarray(Q_u, dtype=float) @ J.T
    return pose_new, F, Q
