"""Odometry and prior factors on ``Pose2``, linearised in numpy (GTSAM's exact semantics).

``BetweenFactorPose2(i, j, u, Σ)``: ``e = Log(u⁻¹ · x_i⁻¹ · x_j)``, cost ``½‖W e‖²``,
``WᵀW = Σ⁻¹``.  For right perturbations ``x·Exp(ξ)``:

``∂e/∂ξ_j = J_r⁻¹(e)``,   ``∂e/∂ξ_i = −J_r⁻¹(e) · Ad(x_j⁻¹ x_i)``,

with ``J_r`` the right Jacobian of SE(2)'s ``Exp`` (GTSAM's ``Pose2::ExpmapDerivative``) and
``Ad(T) = [[cos θ, −sin θ, y], [sin θ, cos θ, −x], [0, 0, 1]]``.
``PriorFactorPose2(0, p, Σ)``: ``e = Log(p⁻¹ x)``, ``∂e/∂ξ = J_r⁻¹(e)``.
Tested against ``gtsam.BetweenFactorPose2.linearize`` entry by entry.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.geometry import pose_between, pose_compose, pose_inverse, pose_log

__all__ = [
    "adjoint_pose2",
    "between_costs",
    "linearize_between",
    "linearize_prior",
    "right_jacobian_pose2",
    "sqrt_information",
]

FloatArray = NDArray[np.float64]


def sqrt_information(cov: FloatArray) -> FloatArray:
    """Upper-triangular ``W`` with ``WᵀW = cov⁻¹`` (GTSAM's Gaussian whitening), ``(..., n, n)``."""
    info = np.linalg.inv(np.asarray(cov, dtype=float))
    info = 0.5 * (info + np.swapaxes(info, -1, -2))
    L = np.linalg.cholesky(info)  # info = L Lᵀ, so W = Lᵀ
    return np.swapaxes(L, -1, -2)


def adjoint_pose2(pose: FloatArray) -> FloatArray:
    """SE(2) adjoint of poses ``(..., 3)``: ``(..., 3, 3)``."""
    p = np.asarray(pose, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    Ad = np.zeros((*p.shape[:-1], 3, 3))
    Ad[..., 0, 0] = c
    Ad[..., 0, 1] = -s
    Ad[..., 1, 0] = s
    Ad[..., 1, 1] = c
    Ad[..., 0, 2] = p[..., 1]
    Ad[..., 1, 2] = -p[..., 0]
    Ad[..., 2, 2] = 1.0
    return Ad


def right_jacobian_pose2(xi: FloatArray) -> FloatArray:
    """Right Jacobian ``J_r(ξ)`` of SE(2)'s exponential (Solà et al. 2018, Eq. 163), vectorised."""
    x = np.asarray(xi, dtype=float)
    v1, v2, w = x[..., 0], x[..., 1], x[..., 2]
    small = np.abs(w) < 1e-4
    ws = np.where(small, 1.0, w)
    s, c = np.sin(w), np.cos(w)
    a = np.where(small, 1.0 - w**2 / 6.0, s / ws)
    b = np.where(small, w / 2.0 - w**3 / 24.0, (1.0 - c) / ws)
    j02 = np.where(small, -v2 / 2.0 + v1 * w / 6.0, (w * v1 - v2 + v2 * c - v1 * s) / ws**2)
    j12 = np.where(small, v1 / 2.0 + v2 * w / 6.0, (v1 + w * v2 - v1 * c - v2 * s) / ws**2)
    J = np.zeros((*x.shape[:-1], 3, 3))
    J[..., 0, 0] = a
    J[..., 0, 1] = b
    J[..., 1, 0] = -b
    J[..., 1, 1] = a
    J[..., 0, 2] = j02
    J[..., 1, 2] = j12
    J[..., 2, 2] = 1.0
    return J


def _between_error(pose_i: FloatArray, pose_j: FloatArray, measured: FloatArray) -> FloatArray:
    return pose_log(pose_compose(pose_inverse(measured), pose_between(pose_i, pose_j)))


def between_costs(
    pose_i: FloatArray, pose_j: FloatArray, measured: FloatArray, sqrt_info: FloatArray
) -> FloatArray:
    """``½‖W e‖²`` of odometry factors, ``(E,)``."""
    ew = np.einsum("eij,ej->ei", sqrt_info, _between_error(pose_i, pose_j, measured))
    return 0.5 * np.sum(ew**2, axis=-1)


def linearize_between(
    pose_i: FloatArray, pose_j: FloatArray, measured: FloatArray, sqrt_info: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Whitened ``(A_i, A_j, b)`` of odometry factors: ``(E,3,3)``, ``(E,3,3)``, ``(E,3)``."""
    e = _between_error(pose_i, pose_j, measured)
    Jinv = np.linalg.inv(right_jacobian_pose2(e))
    Ad = adjoint_pose2(pose_between(pose_j, pose_i))
    A_i = -sqrt_info @ Jinv @ Ad
    A_j = sqrt_info @ Jinv
    b = -np.einsum("eij,ej->ei", sqrt_info, e)
    return A_i, A_j, b


def linearize_prior(
    pose: FloatArray, prior: FloatArray, sqrt_info: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Whitened ``(A, b)`` and cost ``½‖W e‖²`` of a prior ``e = Log(prior⁻¹ x)``."""
    e = pose_log(pose_between(prior, pose))
    A = sqrt_info @ np.linalg.inv(right_jacobian_pose2(e))
    ew = sqrt_info @ e
    return A, -ew, float(0.5 * ew @ ew)
