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

from slam.geometry import (
    adjoint_pose2,
    pose_between,
    pose_compose,
    pose_inverse,
    pose_log,
    right_jacobian_pose2,
)

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
