"""The EKF's pose error convention and its conversion to the project's tangent space.

The filter state holds the laser pose as a plain vector ``(x, y, θ)`` in the world frame and
its covariance is that of the **additive** error ``δ = (δx, δy, δθ)`` (``θ`` wrapped).  The rest
of lineslam (GTSAM, :mod:`slam.geometry`) perturbs poses on the **right**, in the body frame:
``pose ⊕ ξ = pose · Exp(ξ)``, ``ξ = (v_x, v_y, ω)``.

To first order ``pose · Exp(ξ)`` moves the translation by ``Rot(θ)·(v_x, v_y)`` and the angle by
``ω`` (the derivative of ``Exp`` at zero is the identity), so

``δ = J(θ) ξ``  with  ``J(θ) = blockdiag(Rot(θ), 1)``,  ``J(θ)⁻¹ = blockdiag(Rot(θ)ᵀ, 1)``.

Consequences used by the filter:

* a Jacobian w.r.t. ``ξ`` becomes one w.r.t. the state by ``∂h/∂(x, y, θ) = ∂h/∂ξ · J(θ)⁻¹``;
* a covariance in the tangent space maps to the state's by ``P_δ = J Σ_ξ Jᵀ`` and back by
  ``Σ_ξ = J⁻¹ P_δ J⁻ᵀ`` (this is how the filter reports pose covariances, so that they compare
  directly with GTSAM's ``Pose2`` marginals).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "cov_state_to_tangent",
    "cov_tangent_to_state",
    "state_jacobian_from_tangent",
    "tangent_to_state_jacobian",
]

FloatArray = NDArray[np.float64]


def tangent_to_state_jacobian(theta: float | FloatArray) -> FloatArray:
    """``J(θ) = ∂(x, y, θ)/∂ξ`` at ``ξ = 0``: ``blockdiag(Rot(θ), 1)``; shape ``(..., 3, 3)``."""
    th = np.asarray(theta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    J = np.zeros((*th.shape, 3, 3))
    J[..., 0, 0] = c
    J[..., 0, 1] = -s
    J[..., 1, 0] = s
    J[..., 1, 1] = c
    J[..., 2, 2] = 1.0
    return J


def state_jacobian_from_tangent(H_xi: FloatArray, theta: float | FloatArray) -> FloatArray:
    """Convert ``∂h/∂ξ`` (right perturbation) to ``∂h/∂(x, y, θ)``: ``H_ξ · J(θ)⁻¹``.

    Parameters
    ----------
    H_xi : ndarray, shape (..., m, 3)
        Jacobian with respect to the right perturbation ``ξ``.
    theta : float or ndarray, shape (...)
        Heading of the pose at which ``H_xi`` was evaluated.

    Returns
    -------
    ndarray, shape (..., m, 3)
    """
    J_inv = np.swapaxes(tangent_to_state_jacobian(theta), -1, -2)  # Rot is orthonormal
    return np.asarray(H_xi, dtype=float) @ J_inv


def cov_tangent_to_state(cov_xi: FloatArray, theta: float | FloatArray) -> FloatArray:
    """``J Σ_ξ Jᵀ``: a right-perturbation pose covariance as an additive ``(x, y, θ)`` one."""
    J = tangent_to_state_jacobian(theta)
    return J @ np.asarray(cov_xi, dtype=float) @ np.swapaxes(J, -1, -2)


def cov_state_to_tangent(cov_state: FloatArray, theta: float | FloatArray) -> FloatArray:
    """``J⁻¹ P_δ J⁻ᵀ``: an additive ``(x, y, θ)`` covariance in the right-perturbation space."""
    J_inv = np.swapaxes(tangent_to_state_jacobian(theta), -1, -2)
    return J_inv @ np.asarray(cov_state, dtype=float) @ np.swapaxes(J_inv, -1, -2)
