"""The RS frame of a candidate line (Eqs. 9-16), vectorised.

For a line with normal angle ``α`` the RS frame is the sensor frame rotated by ``α``: ``R`` along
the normal ``n = (cos α, sin α)`` and ``S`` along the tangent ``t = (−sin α, cos α)``.  A point
``u = (x, y) = d·(cos φ, sin φ)`` has

* ``u_R = u·n = d·cos(α − φ)`` (Eq. 9),
* ``u_S = u·t = d·sin(φ − α)`` (Eq. 10 with the sign of reading note 1: the printed
  ``sin(α − φ)`` makes Prop. 2 diverge; this sign is the one under which Eqs. 24 and 30 hold),

and, for a point covariance ``Q``, the variances of its normal and tangential components

* ``P_R = nᵀ Q n`` (Eq. 14) and ``P_S = tᵀ Q t`` (Eq. 15),

plus the cross term ``P_RS = nᵀ Q t`` that the paper drops in Eq. 16 (it does not enter the fit,
but it does enter the covariance of ``S`` and of the endpoints, see :mod:`linefit.covariance`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["rs_coordinates", "rs_variances"]

FloatArray = NDArray[np.float64]


def rs_coordinates(x: ArrayLike, y: ArrayLike, alpha: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """RS-frame coordinates ``(u_R, u_S)`` of points ``(x, y)`` for line angle(s) ``alpha``.

    Parameters
    ----------
    x, y
        Point coordinates (m) in the sensor frame, broadcastable with ``alpha``.
    alpha
        Normal angle(s) of the line (rad).

    Returns
    -------
    u_r, u_s : ndarray
        Coordinates along the normal and along the tangent ``(−sin α, cos α)`` (m).
    """
    ca = np.cos(alpha)
    sa = np.sin(alpha)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return x * ca + y * sa, y * ca - x * sa


def rs_variances(
    q11: ArrayLike, q12: ArrayLike, q22: ArrayLike, alpha: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Variances of a point's normal and tangential components (Eqs. 14-15) and their covariance.

    Parameters
    ----------
    q11, q12, q22
        Entries of the point covariance ``Q = [[q11, q12], [q12, q22]]`` (m²).
    alpha
        Normal angle(s) of the line (rad), broadcastable with the ``q``.

    Returns
    -------
    p_r, p_s, p_rs : ndarray
        ``nᵀQn`` (Eq. 14), ``tᵀQt`` (Eq. 15) and ``nᵀQt`` (m²).
    """
    ca = np.cos(alpha)
    sa = np.sin(alpha)
    q11 = np.asarray(q11, dtype=float)
    q12 = np.asarray(q12, dtype=float)
    q22 = np.asarray(q22, dtype=float)
    cc, ss, sc = ca * ca, sa * sa, sa * ca
    p_r = q11 * cc + 2.0 * q12 * sc + q22 * ss
    p_s = q11 * ss - 2.0 * q12 * sc + q22 * cc
    p_rs = (q22 - q11) * sc + q12 * (cc - ss)
    return p_r, p_s, p_rs
