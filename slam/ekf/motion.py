"""Odometry motion model of the EKF prediction step.

The filter is driven by the odometry **increment** between consecutive scans,
``u_k = pose_odom_laser[k-1]⁻¹ · pose_odom_laser[k]`` (laser frame at ``k-1``), composed on the
right: ``pose_k = pose_{k-1} · u_k · Exp(n_k)`` with ``n_k ~ N(0, Q_u)`` in the tangent space
of the new pose, the same error model as a GTSAM ``BetweenFactorPose2(u_k, Q_u)``.

Noise: the graph back-end's random-walk model, :class:`slam.models.motion.MotionNoiseConfig`
(one class, one set of defaults for both estimators).  With ``d = ‖(u_x, u_y)‖``:

``σ_xy² = σ_xy,min² + σ_xy/m²·d + σ_xy/rad²·|u_θ|``,
``σ_θ² = σ_θ,min² + σ_θ/m²·d + σ_θ/rad²·|u_θ|``,  ``Q_u = diag(σ_xy², σ_xy², σ_θ²)``.

Variances grow linearly with distance and angle, so chained steps give (to first order) the
uncertainty of one step; the floors are per prediction.  :class:`slam.ekf.EkfSlam` predicts
once per update (the graph's keyframe policy: the odometry since the last prediction, as the
graph's odometry factor between keyframes), so the floors count as often as in the graph.

State Jacobians for the additive ``(x, y, θ)`` error of :mod:`slam.ekf.conventions`:
``F = ∂pose_k/∂pose_{k-1} = [[1, 0, −s u_x − c u_y], [0, 1, c u_x − s u_y], [0, 0, 1]]``
(``c, s`` of ``θ_{k-1}``) and ``Q = J(θ_k) Q_u J(θ_k)ᵀ``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slam.ekf.conventions import tangent_to_state_jacobian
from slam.geometry import pose_compose
from slam.models.motion import MotionNoiseConfig

__all__ = [
    "MotionNoiseConfig",
    "first_estimates_propagation_jacobian",
    "odometry_covariance",
    "predict_pose",
]

FloatArray = NDArray[np.float64]


def odometry_covariance(increment: FloatArray, noise: MotionNoiseConfig) -> FloatArray:
    """``Q_u``, the covariance of odometry increments in the tangent space; shape (..., 3, 3).

    Parameters
    ----------
    increment : ndarray, shape (..., 3)
        Odometry increments ``(u_x, u_y, u_θ)``.
    noise : MotionNoiseConfig
        Noise per metre / per radian (the graph back-end's model).
    """
    return noise.covariance(np.asarray(increment, dtype=float))


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


def first_estimates_propagation_jacobian(
    pose_propagated: FloatArray, pose_propagated_before: FloatArray
) -> FloatArray:
    """The FEJ-EKF's ``F`` (Huang, Mourikis & Roumeliotis 2008), shape (3, 3).

    :func:`predict_pose`'s ``F`` is ``[[1, 0, −(y_{k+1} − y_k)], [0, 1, x_{k+1} − x_k], [0, 0,
    1]]`` with ``(x_k, y_k)`` the updated estimate ``x̂_{k|k}``; here ``(x_k, y_k)`` is the
    propagated one, ``x̂_{k|k−1}``, the point at which step ``k``'s measurements were
    linearised, and ``(x_{k+1}, y_{k+1}) = x̂_{k+1|k}``.

    Parameters
    ----------
    pose_propagated : ndarray, shape (3,)
        ``x̂_{k+1|k}``, the pose this prediction produced.
    pose_propagated_before : ndarray, shape (3,)
        ``x̂_{k|k−1}``, the pose the previous prediction produced (the first pose at the start).
    """
    F = np.eye(3)
    F[0, 2] = -(float(pose_propagated[1]) - float(pose_propagated_before[1]))
    F[1, 2] = float(pose_propagated[0]) - float(pose_propagated_before[0])
    return F
