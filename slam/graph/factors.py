"""The line factor, linearised for all factors at once in numpy.

A line factor links a laser pose ``x = pose_world_laser`` and a world line landmark
``v = (ρ, φ)`` with anchor ``c`` (:mod:`slam.models.anchored`; world line
``(r_w, α_w) = (c·n(φ) + ρ, φ)``) to a measured line ``z = (r, α)`` in the laser frame with
covariance ``R`` (the ``(r, α)`` block of :attr:`linefit.Line.cov`).  Its residual is

``e(x, v) = line_residual(h(l, x), z)``,   ``h(l, x) = (r_w − x cos α_w − y sin α_w, α_w − θ)``,

the landmark moved into the laser frame (the inverse of Eq. 30,
:func:`slam.geometry.predict_line_measurement`), compared with ``z`` on the same representative
(:func:`slam.geometry.line_residual`).  Its cost is ``ρ(‖W e‖)`` with ``WᵀW = R⁻¹``, ``W`` the
upper Cholesky factor of the information matrix (the square root GTSAM's
``noiseModel.Gaussian.Covariance`` whitens with), and ``ρ`` the Gaussian or a robust kernel.

Linearisation at ``(x, v)`` for the right perturbation ``x·Exp(ξ)`` and ``v + δ``:

``W e(x·Exp(ξ), v + δ) ≈ W e + (W H_x) ξ + (W H_l J) δ``,  ``J = ∂(r_w, α_w)/∂(ρ, φ)``

so a Gauss-Newton step minimises ``‖A_x ξ + A_l δ − b‖²`` with ``A_x = √w W H_x`` (2×3),
``A_l = √w W H_l J`` (2×2), ``b = −√w W e``: exactly what ``gtsam.JacobianFactor(x, A_x, l, A_l, b,
Unit(2))`` represents.  ``H_x`` and ``H_l`` are the measurement Jacobians with the ``r`` row
multiplied by the representative's sign.

Everything here is vectorised over factors: the cost per factor does not depend on the size of
the graph (``scripts/bench_graph.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.errors import DegenerateGeometryError, InputError
from slam.geometry import line_residual, predict_line_measurement
from slam.graph.robust import RobustKernel, robust_cost, robust_weights
from slam.models.anchored import anchored_jacobian, r_alpha_from_anchored

__all__ = [
    "LineLinearization",
    "line_factor_costs",
    "line_factor_residuals",
    "linearize_line_factors",
    "sqrt_information_2x2",
]

FloatArray = NDArray[np.float64]


def sqrt_information_2x2(cov: FloatArray, what: str = "line covariance") -> FloatArray:
    """Square-root information matrices ``W`` of 2×2 covariances: ``WᵀW = cov⁻¹``.

    ``W`` is the upper-triangular Cholesky factor of the information matrix ``cov⁻¹``, the same
    square root that ``gtsam.noiseModel.Gaussian.Covariance`` whitens with, so the fast path's
    whitened systems equal GTSAM's entry by entry.

    Parameters
    ----------
    cov : ndarray, shape (..., 2, 2)
        Symmetric positive-definite covariances.
    what : str
        Name used in the error message.

    Returns
    -------
    ndarray, shape (..., 2, 2)
        Upper-triangular ``W``.

    Raises
    ------
    DegenerateGeometryError
        A covariance that is not finite and positive definite (the message gives its index).
    """
    P = np.asarray(cov, dtype=float)
    if P.shape[-2:] != (2, 2):
        raise InputError(f"{what}: expected (..., 2, 2), got shape {P.shape}")
    p00, p01, p11 = P[..., 0, 0], 0.5 * (P[..., 0, 1] + P[..., 1, 0]), P[..., 1, 1]
    det = p00 * p11 - p01 * p01
    finite = np.isfinite(P).all(axis=(-2, -1))
    ok = finite & (p00 > 0.0) & (p11 > 0.0) & (det > 1e-12 * np.abs(p00 * p11))
    if not np.all(ok):
        bad = np.argwhere(~np.asarray(ok))
        where = [int(i) for i in bad[0]] if bad.size else []
        raise DegenerateGeometryError(
            f"{what}{where}: not a finite positive-definite covariance "
            f"({np.count_nonzero(~np.asarray(ok))} such)"
        )
    # information I = cov⁻¹ = [[p11, −p01], [−p01, p00]] / det = UᵀU, U upper triangular
    i00, i01, i11 = p11 / det, -p01 / det, p00 / det
    u00 = np.sqrt(i00)
    u01 = i01 / u00
    u11 = np.sqrt(np.maximum(i11 - u01 * u01, 0.0))
    W = np.zeros(P.shape)
    W[..., 0, 0] = u00
    W[..., 0, 1] = u01
    W[..., 1, 1] = u11
    return W


def line_factor_residuals(
    poses_world_laser: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
) -> FloatArray:
    """Whitened residuals ``W e`` of line factors, shape ``(F, 2)`` (inputs row-aligned)."""
    lm = r_alpha_from_anchored(landmarks, anchors)
    z_pred, _, _ = predict_line_measurement(lm, poses_world_laser)
    e, _ = line_residual(z_pred, z)
    return np.einsum("fij,fj->fi", sqrt_info, e)


def line_factor_costs(
    poses_world_laser: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
    kernel: RobustKernel = "none",
    k: float = 1.0,
) -> FloatArray:
    """Cost ``ρ(‖W e‖)`` of each line factor (``‖W e‖²/2`` without a kernel), shape ``(F,)``."""
    ew = line_factor_residuals(poses_world_laser, landmarks, anchors, z, sqrt_info)
    return robust_cost(kernel, np.linalg.norm(ew, axis=-1), k)


@dataclass(frozen=True, eq=False)
class LineLinearization:
    """Whitened linear systems of ``F`` line factors.

    Attributes
    ----------
    A_pose : ndarray, shape (F, 2, 3)
        ``√w W H_x`` (right perturbation of the laser pose).
    A_landmark : ndarray, shape (F, 2, 2)
        ``√w W H_l J`` (anchored landmark chart).
    b : ndarray, shape (F, 2)
        ``−√w W e``.
    whitened_residual : ndarray, shape (F, 2)
        ``W e`` (without the robust weight).
    weights : ndarray, shape (F,)
        IRLS weights ``w`` (ones without a kernel).
    """

    A_pose: FloatArray
    A_landmark: FloatArray
    b: FloatArray
    whitened_residual: FloatArray
    weights: FloatArray


def linearize_line_factors(
    poses_world_laser: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
    kernel: RobustKernel = "none",
    k: float = 1.0,
) -> LineLinearization:
    """Linearise ``F`` line factors at once.

    Parameters
    ----------
    poses_world_laser : ndarray, shape (F, 3)
        Pose of each factor (rows repeat when a pose has several factors).
    landmarks : ndarray, shape (F, 2)
        Landmark of each factor, anchored ``(ρ, φ)``.
    anchors : ndarray, shape (F, 2)
        Anchor point of each factor's landmark.
    z : ndarray, shape (F, 2)
        Measured ``(r, α)`` in the laser frame.
    sqrt_info : ndarray, shape (F, 2, 2)
        Whitening matrices from :func:`sqrt_information_2x2`.
    kernel, k
        Robust kernel and its width (whitened units); weights from the current residuals.

    Returns
    -------
    LineLinearization
    """
    lm = r_alpha_from_anchored(landmarks, anchors)
    z_pred, H_pose, H_lm = predict_line_measurement(lm, poses_world_laser)
    e, sign = line_residual(z_pred, z)
    H_pose = np.array(H_pose)  # broadcast views are read-only
    H_lm = H_lm @ anchored_jacobian(landmarks, anchors)
    H_pose[:, 0, :] *= sign[:, None]
    H_lm[:, 0, :] *= sign[:, None]
    ew = np.einsum("fij,fj->fi", sqrt_info, e)
    w = robust_weights(kernel, np.linalg.norm(ew, axis=-1), k)
    sw = np.sqrt(w)
    WHx = sqrt_info @ H_pose
    WHl = sqrt_info @ H_lm
    return LineLinearization(
        A_pose=WHx * sw[:, None, None],
        A_landmark=WHl * sw[:, None, None],
        b=-ew * sw[:, None],
        whitened_residual=ew,
        weights=w,
    )
