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
the graph (``scripts/bench_graph.py``).  The linearisation takes its sines and cosines from numpy
and does the rest in one compiled loop over the factors (:func:`_linearize_kernel`), with the
same floating-point operations as the numpy functions it stands for
(:func:`slam.models.anchored.r_alpha_from_anchored`, :func:`slam.geometry.predict_line_measurement`,
:func:`slam.geometry.line_residual`, :func:`slam.models.anchored.anchored_jacobian`, the whitening
products): the same numbers, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.errors import ConfigError, DegenerateGeometryError, InputError
from slam.geometry import wrap_angle_compiled
from slam.graph.robust import RobustKernel, robust_cost

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


def _rows(
    poses_world_laser: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
) -> tuple[tuple[int, ...], FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The factors' common shape and their inputs broadcast to it, one row per factor.

    Returns the shape and ``(F, 3)`` poses, ``(F, 2)`` landmarks, anchors and measurements,
    ``(F, 2, 2)`` whitening matrices.
    """
    P = np.asarray(poses_world_laser, dtype=float)
    V = np.asarray(landmarks, dtype=float)
    C = np.asarray(anchors, dtype=float)
    Z = np.asarray(z, dtype=float)
    S = np.asarray(sqrt_info, dtype=float)
    shape = np.broadcast_shapes(
        P.shape[:-1], V.shape[:-1], C.shape[:-1], Z.shape[:-1], S.shape[:-2]
    )
    n = math.prod(shape)
    return (
        shape,
        np.broadcast_to(P, (*shape, 3)).reshape(n, 3),
        np.broadcast_to(V, (*shape, 2)).reshape(n, 2),
        np.broadcast_to(C, (*shape, 2)).reshape(n, 2),
        np.broadcast_to(Z, (*shape, 2)).reshape(n, 2),
        np.broadcast_to(S, (*shape, 2, 2)).reshape(n, 2, 2),
    )


def _angles(pose: FloatArray, v: FloatArray, jacobians: bool) -> tuple[FloatArray, FloatArray]:
    """Sines and cosines of the factors' angles, by numpy, for the compiled kernels.

    Rows ``cos φ, sin φ, cos α_w, sin α_w`` (``α_w`` the wrapped ``φ``) and, with
    ``jacobians``, ``cos α_s, sin α_s``; and ``α_s = α_w − θ``.
    """
    phi = v[:, 1]
    a_w = np.asarray(wrap_angle(phi))
    a_s = a_w - pose[:, 2]
    trig = np.empty((6 if jacobians else 4, pose.shape[0]))
    np.cos(phi, out=trig[0])
    np.sin(phi, out=trig[1])
    np.cos(a_w, out=trig[2])
    np.sin(a_w, out=trig[3])
    if jacobians:
        np.cos(a_s, out=trig[4])
        np.sin(a_s, out=trig[5])
    return trig, a_s


def line_factor_residuals(
    poses_world_laser: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
) -> FloatArray:
    """Whitened residuals ``W e`` of line factors, shape ``(F, 2)`` (inputs row-aligned)."""
    shape, pose, v, c, zm, W = _rows(poses_world_laser, landmarks, anchors, z, sqrt_info)
    trig, a_s = _angles(pose, v, jacobians=False)
    ew = np.empty((pose.shape[0], 2))
    _residual_kernel(pose, v, c, zm, W, trig, a_s, ew)
    return ew.reshape(*shape, 2)


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


#: Robust kernels by the code :func:`_linearize_kernel` takes.
_KERNEL_CODE = {"none": 0, "huber": 1, "cauchy": 2}


@njit(cache=True, nogil=True)
def _residual(
    x: float,
    y: float,
    rho: float,
    c0: float,
    c1: float,
    trig: FloatArray,
    a_s: float,
    z: FloatArray,
    f: int,
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Residual ``e`` of factor ``f`` and its representative's sign (see the kernels).

    The operations of :func:`slam.models.anchored.r_alpha_from_anchored`,
    :func:`slam.geometry.predict_line_measurement` and :func:`slam.geometry.line_residual`.
    """
    r_w = c0 * trig[0, f] + c1 * trig[1, f] + rho
    z0 = r_w - x * trig[2, f] - y * trig[3, f]
    z1 = wrap_angle_compiled(a_s)
    d_alpha = wrap_angle_compiled(z1 - z[f, 1])
    flip = abs(d_alpha) > math.pi / 2.0
    sign = -1.0 if flip else 1.0
    e1 = wrap_angle_compiled(d_alpha + math.pi) if flip else wrap_angle_compiled(d_alpha)
    e0 = sign * z0 - z[f, 0]
    return e0, e1, sign


@njit(cache=True, nogil=True)
def _residual_kernel(
    poses: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
    trig: FloatArray,
    a_s: FloatArray,
    ew: FloatArray,
) -> None:  # pragma: no cover - compiled
    """The arithmetic of :func:`line_factor_residuals` after its sines and cosines.

    ``trig`` holds the rows ``cos φ, sin φ, cos α_w, sin α_w`` (:func:`_angles`); ``ew`` (``W e``)
    is written per factor, summed as ``einsum`` sums it.
    """
    for f in range(poses.shape[0]):
        e0, e1, _ = _residual(
            poses[f, 0],
            poses[f, 1],
            landmarks[f, 0],
            anchors[f, 0],
            anchors[f, 1],
            trig,
            a_s[f],
            z,
            f,
        )
        ew[f, 0] = 0.0 + sqrt_info[f, 0, 0] * e0 + sqrt_info[f, 0, 1] * e1
        ew[f, 1] = 0.0 + sqrt_info[f, 1, 0] * e0 + sqrt_info[f, 1, 1] * e1


@njit(cache=True, nogil=True)
def _linearize_kernel(
    poses: FloatArray,
    landmarks: FloatArray,
    anchors: FloatArray,
    z: FloatArray,
    sqrt_info: FloatArray,
    trig: FloatArray,
    a_s: FloatArray,
    kernel: int,
    k: float,
    A_pose: FloatArray,
    A_landmark: FloatArray,
    b: FloatArray,
    ew: FloatArray,
    weights: FloatArray,
) -> None:  # pragma: no cover - compiled
    """The arithmetic of :func:`linearize_line_factors` after its sines and cosines.

    ``trig`` holds the rows ``cos φ, sin φ, cos α_w, sin α_w, cos α_s, sin α_s`` (``α_w`` the
    wrapped ``φ``, ``α_s = α_w − θ``, given in ``a_s``; :func:`_angles`); ``kernel`` is a code of
    ``_KERNEL_CODE``.  Outputs ``A_pose``, ``A_landmark``, ``b``, ``ew`` (``W e``) and
    ``weights`` are written per factor.  Every entry is the sequence of IEEE operations the
    numpy functions perform: products ``W M`` of 2×2 by 2×n matrices as
    ``(0 + W_i0 M_0j) + W_i1 M_1j`` (numpy's ``matmul`` fuses the second product into a
    multiply-add, which rounds the same because every ``M_1j`` here is 0, 1 or −1), ``W e`` as
    ``einsum`` sums it, ``‖W e‖`` as ``np.linalg.norm``, the kernels' weights as
    :func:`slam.graph.robust.robust_weights`.
    """
    for f in range(poses.shape[0]):
        x, y = poses[f, 0], poses[f, 1]
        c0, c1 = anchors[f, 0], anchors[f, 1]
        cphi, sphi = trig[0, f], trig[1, f]
        caw, saw = trig[2, f], trig[3, f]
        cas, sas = trig[4, f], trig[5, f]
        e0, e1, sign = _residual(x, y, landmarks[f, 0], c0, c1, trig, a_s[f], z, f)
        # measurement Jacobians, the r row times the sign; landmark one through the chart
        hp00 = -cas * sign
        hp01 = -sas * sign
        hp02 = 0.0 * sign
        h_lm = x * saw - y * caw
        s_c = -c0 * sphi + c1 * cphi
        m00 = (0.0 + 1.0 * 1.0 + h_lm * 0.0) * sign
        m01 = (0.0 + 1.0 * s_c + h_lm * 1.0) * sign
        m10 = 0.0 + 0.0 * 1.0 + 1.0 * 0.0
        m11 = 0.0 + 0.0 * s_c + 1.0 * 1.0
        w00, w01 = sqrt_info[f, 0, 0], sqrt_info[f, 0, 1]
        w10, w11 = sqrt_info[f, 1, 0], sqrt_info[f, 1, 1]
        ew0 = 0.0 + w00 * e0 + w01 * e1
        ew1 = 0.0 + w10 * e0 + w11 * e1
        u = math.sqrt(ew0 * ew0 + ew1 * ew1)
        if kernel == 0:
            w = 1.0
        elif kernel == 1:
            w = 1.0 if u <= k else k / max(u, 1e-300)
        else:
            q = u / k
            w = 1.0 / (1.0 + q * q)
        sw = math.sqrt(w)
        A_pose[f, 0, 0] = (0.0 + w00 * hp00 + w01 * 0.0) * sw
        A_pose[f, 0, 1] = (0.0 + w00 * hp01 + w01 * 0.0) * sw
        A_pose[f, 0, 2] = (0.0 + w00 * hp02 + w01 * -1.0) * sw
        A_pose[f, 1, 0] = (0.0 + w10 * hp00 + w11 * 0.0) * sw
        A_pose[f, 1, 1] = (0.0 + w10 * hp01 + w11 * 0.0) * sw
        A_pose[f, 1, 2] = (0.0 + w10 * hp02 + w11 * -1.0) * sw
        A_landmark[f, 0, 0] = (0.0 + w00 * m00 + w01 * m10) * sw
        A_landmark[f, 0, 1] = (0.0 + w00 * m01 + w01 * m11) * sw
        A_landmark[f, 1, 0] = (0.0 + w10 * m00 + w11 * m10) * sw
        A_landmark[f, 1, 1] = (0.0 + w10 * m01 + w11 * m11) * sw
        b[f, 0] = -ew0 * sw
        b[f, 1] = -ew1 * sw
        ew[f, 0] = ew0
        ew[f, 1] = ew1
        weights[f] = w


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
    if kernel not in _KERNEL_CODE:
        raise ConfigError(f"unknown robust kernel {kernel!r}")
    shape, pose, v, c, zm, W = _rows(poses_world_laser, landmarks, anchors, z, sqrt_info)
    trig, a_s = _angles(pose, v, jacobians=True)
    n = pose.shape[0]
    A_pose = np.empty((n, 2, 3))
    A_landmark = np.empty((n, 2, 2))
    b = np.empty((n, 2))
    ew = np.empty((n, 2))
    w = np.empty(n)
    _linearize_kernel(
        pose, v, c, zm, W, trig, a_s, _KERNEL_CODE[kernel], float(k), A_pose, A_landmark, b, ew, w
    )
    return LineLinearization(
        A_pose=A_pose.reshape(*shape, 2, 3),
        A_landmark=A_landmark.reshape(*shape, 2, 2),
        b=b.reshape(*shape, 2),
        whitened_residual=ew.reshape(*shape, 2),
        weights=w.reshape(shape),
    )
