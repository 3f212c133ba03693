"""Validation of covariance inputs shared by :mod:`slam.lines` (one policy, one place).

Policy
------
* A covariance must be finite and of the documented shape, else :class:`InputError`.
* Asymmetry at round-off level (``|P − Pᵀ| ≤ 1e-9·max|P|``) is removed by symmetrising
  ``(P + Pᵀ)/2``; larger asymmetry means the caller passed something that is not a covariance
  and raises :class:`~slam.errors.DegenerateGeometryError` (naming the offending entry).
* Negative variances (a diagonal entry ``< 0``) raise :class:`DegenerateGeometryError`.
  Singular (positive *semi*-definite) covariances are accepted as inputs: a line or pose known
  exactly is legitimate.  Only where an inverse is needed (the sum in the χ² test, the fusion
  gain) does a singular matrix raise, at that point.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.errors import DegenerateGeometryError, InputError

__all__ = ["SYMMETRY_RTOL", "check_covariance", "inv2x2"]

FloatArray = NDArray[np.float64]

SYMMETRY_RTOL = 1e-9
"""Relative asymmetry tolerated (and removed) in a covariance."""


def _index_of_first(mask: NDArray[np.bool_] | np.bool_) -> tuple[int, ...]:
    idx = np.argwhere(np.asarray(mask))
    return tuple(int(i) for i in idx[0]) if idx.size else ()


def check_covariance(P: FloatArray | list[list[float]], dim: int, name: str = "cov") -> FloatArray:
    """Validate covariances of shape ``(..., dim, dim)`` and return them symmetrised.

    Parameters
    ----------
    P : array_like, shape (..., dim, dim)
        Covariance matrices.
    dim : int
        Expected size of each matrix.
    name : str
        Name used in error messages.

    Returns
    -------
    ndarray, shape (..., dim, dim)
        ``(P + Pᵀ)/2`` as float.

    Raises
    ------
    InputError
        Wrong shape or non-finite entries.
    DegenerateGeometryError
        Asymmetric beyond round-off, or a negative variance.
    """
    arr = np.asarray(P, dtype=float)
    if arr.shape[-2:] != (dim, dim):
        raise InputError(f"{name}: expected shape (..., {dim}, {dim}), got {arr.shape}")
    finite = np.isfinite(arr).all(axis=(-2, -1))
    if not finite.all():
        where = _index_of_first(~finite)
        raise InputError(f"{name}{list(where) if where else ''}: covariance has NaN or inf")
    Pt = np.swapaxes(arr, -1, -2)
    scale = np.max(np.abs(arr), axis=(-2, -1))
    asym = np.max(np.abs(arr - Pt), axis=(-2, -1))
    bad = asym > SYMMETRY_RTOL * scale
    if bad.any():
        where = _index_of_first(bad)
        raise DegenerateGeometryError(
            f"{name}{list(where) if where else ''}: covariance is not symmetric "
            f"(max |P - P^T| = {float(np.max(asym)):.3g})"
        )
    diag = np.diagonal(arr, axis1=-2, axis2=-1)
    neg = (diag < 0.0).any(axis=-1)
    if neg.any():
        where = _index_of_first(neg)
        raise DegenerateGeometryError(
            f"{name}{list(where) if where else ''}: covariance has a negative variance"
        )
    return 0.5 * (arr + Pt)


def inv2x2(S: FloatArray, name: str = "covariance") -> FloatArray:
    """Inverse of symmetric positive-definite 2×2 matrices ``(..., 2, 2)`` (closed form).

    Raises
    ------
    DegenerateGeometryError
        If any matrix is not positive definite (relative determinant below 1e-14).
    """
    a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    det = a * d - b * S[..., 1, 0]
    ok = (a > 0.0) & (d > 0.0) & (det > 1e-14 * a * d)
    if not ok.all():
        where = _index_of_first(~ok)
        raise DegenerateGeometryError(
            f"{name}{list(where) if where else ''} is singular or not positive definite; "
            "the chi-square test and the fusion need P1 + P2 invertible"
        )
    inv = np.empty_like(S)
    inv[..., 0, 0] = d / det
    inv[..., 1, 1] = a / det
    inv[..., 0, 1] = -S[..., 0, 1] / det
    inv[..., 1, 0] = -S[..., 1, 0] / det
    return inv
