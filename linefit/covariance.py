"""Covariance of fitted lines over ``(R, α, S)`` and of their endpoints (vectorised over lines).

Derivation (first order, all sums over the supporting points ``k`` of one line)
-------------------------------------------------------------------------------
Write each point as its true position plus an error, and split the error into its components
along the line's normal and tangent: ``e_k = n·δu_k`` and ``f_k = t·δu_k``, with
``var e_k = P_R,k`` (Eq. 14), ``var f_k = q_tt,k`` and ``cov(e_k, f_k) = q_nt,k`` (see *Bearing
error models* below).

**(R, α).**  The fit minimises ``Σ w_k (u_k·n(α) − R)²`` (``w_k = 1/P_R,k`` for the ML fit,
``w_k = 1`` for total least squares).  Linearising, ``(δR, δα) = Σ_k g_k e_k`` with

``g_k = w_k · M⁻¹ (1, −u_S,k)``,  ``M = Σ w_k [[1, −u_S,k], [−u_S,k, u_S,k²]]``.

With ``W = Σ w_k``, the weighted centre ``c = Σ w_k u_S,k / W`` and ``A = Σ w_k (u_S,k − c)²``:
``g_α,k = w_k (c − u_S,k)/A`` and ``g_R,k = w_k/W + c·g_α,k``.  The covariance is the sandwich
``Σ g_k g_kᵀ P_R,k``; for the ML weights it collapses to ``M⁻¹``:

``P_αα = 1/A``,  ``P_Rα = c/A``,  ``P_RR = 1/W + c²/A``.

The paper's Eqs. 22, 26, 27 are the ``c = 0`` case: ``P_RR = 1/W`` is the variance of ``R``
*given* ``α`` (reading note 8).  For a wall seen off to one side (``c`` several metres) the
printed ``P_RR`` is too small by the factor ``1 + W c²/A`` (15× in note 8's example); the joint
form above is what this module returns (Monte-Carlo NEES in ``tests/test_covariance.py``).

**S.**  ``S = Σ v_k u_S,k`` with ``v_k = w^S_k/Σ w^S`` (``w^S = 1/P_S`` for the ML fit, Eq. 21,
``1`` for total least squares).  ``u_S = u·t(α)`` depends on ``α`` (``∂u_S/∂α = −u_R``) and,
for the ML fit, so do the weights (``∂(1/P_S)/∂α = 2 q^{(8)}_nt / P_S²`` with the Eq. 8 cross
term).  Hence

``δS = Σ v_k f_k + c_S·δα``,  ``c_S = −Σ v_k u_R,k + Σ (∂w^S_k/∂α)(u_S,k − S)/Σ w^S``

(``c_S ≈ −R``), and

``P_SS = c_S² P_αα + Σ v_k² q_tt,k + 2 c_S Σ v_k g_α,k q_nt,k``,
``P_RS = c_S P_Rα + Σ v_k g_R,k q_nt,k``,  ``P_αS = c_S P_αα + Σ v_k g_α,k q_nt,k``.

The cross terms are **not** negligible: ``c_S P_αα`` alone gives ``corr(S, α) ≈ −1`` for a
distant line, and at oblique incidence a point's normal and tangential errors are strongly
correlated (``q_nt``), so ``P_RS`` and ``P_αS`` are of the order of ``sqrt(P_RR P_SS)`` and
``sqrt(P_αα P_SS)``.  INTERFACES.md shows zeros there (the paper's Eq. 25); this module returns
the full matrix.

**Endpoints.**  A segment end is ``u_S`` of its extreme supporting point ``m`` on the fitted line,
``ŝ_m = u_m·t(α̂)``.  Its error is ``f_m − u_R,m δα``, so

``var ŝ_m = q_tt,m + u_R,m² P_αα − 2 u_R,m g_α,m q_nt,m``.

The paper keeps only ``P_S,m`` (Eq. 15), which misses the line's own ``α`` uncertainty (the
``u_R² P_αα`` and cross terms) and, for the ``"beam"`` model, the motion of the hit point along
the wall (reading note 9).

Bearing error models
--------------------
Eq. 8 is the covariance of a measured point about the point *where its beam physically hit*.
Two readings of "true position" give the same ``P_R`` (so the same ``R, α`` and ``P_Rα``
block) but different tangential statistics:

``"reading"``
    The beam hits the wall at a fixed point and the *reported* bearing is off by ``ε_φ``
    (Eqs. 4-5 literally).  ``q_tt = P_S`` (Eq. 15), ``q_nt = nᵀQt``.
``"beam"`` (default)
    The reported bearings are the fixed, nominal beam grid (as in every logged scan: CARMEN
    stores ranges only) and the *physical* beam leaves at ``φ + ε_φ``, so the hit point moves
    along the wall.  Relative to the wall point on the nominal ray (a fixed point, and the only
    one a user can name), the measured point lies on the nominal ray at range error
    ``ε_d + (∂D/∂φ) ε_φ`` with ``∂D/∂φ = D tan θ`` (``θ`` the incidence angle), so its error
    is along the beam with variance ``σ_eff² = σ_d² + D² tan²θ σ_φ²``:
    ``q_tt = σ_eff² sin²θ``, ``q_nt = σ_eff² sinθ cosθ`` (and ``σ_eff² cos²θ = P_R`` exactly,
    as it must).  At grazing incidence the ``D² tan²θ σ_φ²`` term dominates: at 30 m and 75°
    it is 4× σ_d².

Points given with an arbitrary covariance (no beam) use ``"reading"`` (their covariance is
taken as the covariance about their true positions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.fit import GroupFit, PointSet

__all__ = ["LineCovariances", "line_covariances"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class LineCovariances:
    """Covariances of ``G`` lines and the endpoint variance of every membership.

    Attributes
    ----------
    cov : ndarray, shape (G, 3, 3)
        Covariance of ``(R, α, S)`` per line (signed representative of the fit).
    end_var : ndarray, shape (m,)
        Variance (m²) of ``u_S`` of each membership as an end of its line's segment.
    gain_alpha : ndarray, shape (m,)
        ``g_α,k``: sensitivity of ``α̂`` to the normal error of membership ``k``.
    """

    cov: FloatArray
    end_var: FloatArray
    gain_alpha: FloatArray


def line_covariances(
    fit: GroupFit,
    pts: PointSet,
    pidx: IntArray,
    gidx: IntArray,
    n_groups: int,
    bearing_error: str = "beam",
) -> LineCovariances:
    """First-order covariance of every fitted line and the variance of every possible endpoint.

    Parameters
    ----------
    fit
        The result of :func:`linefit.fit.fit_groups` for these memberships.
    pts, pidx, gidx, n_groups
        The points and memberships that were fitted.
    bearing_error
        ``"beam"`` or ``"reading"`` (see the module docstring).  ``"beam"`` needs
        ``pts.var_range`` and ``pts.var_perp``; without them ``"reading"`` is used.

    Returns
    -------
    LineCovariances
    """
    g = gidx
    G = n_groups
    u_r, u_s, p_r = fit.u_r, fit.u_s, fit.p_r
    w = fit.w_r

    def gsum(values: FloatArray) -> FloatArray:
        return np.asarray(np.bincount(g, weights=values, minlength=G), dtype=float)

    # (R, α): δθ = Σ g_k e_k
    W = gsum(w)
    c = gsum(w * u_s) / W
    du = u_s - c[g]
    A = gsum(w * du * du)
    gain_a = -w * du / A[g]
    gain_r = w / W[g] + c[g] * gain_a
    if fit.weighted:
        P_aa = 1.0 / A
        P_ra = c / A
        P_rr = 1.0 / W + c * c / A
    else:
        P_rr = gsum(gain_r * gain_r * p_r)
        P_ra = gsum(gain_r * gain_a * p_r)
        P_aa = gsum(gain_a * gain_a * p_r)

    # tangential error moments of each point
    var_range_all, var_perp_all = pts.var_range, pts.var_perp
    d2 = u_r * u_r + u_s * u_s
    cos_t = u_r / np.sqrt(d2)
    sin_t = u_s / np.sqrt(d2)
    if bearing_error == "beam" and var_range_all is not None and var_perp_all is not None:
        var_eff = var_range_all[pidx] + var_perp_all[pidx] * (u_s * u_s) / (u_r * u_r)
        q_tt = var_eff * sin_t * sin_t
        q_nt = var_eff * sin_t * cos_t
    else:
        q_tt = fit.p_s
        q_nt = fit.p_rs

    # S = Σ v u_S: coefficients (a_S, b_S) on each point's (e, f)
    w_s = fit.w_s
    WS = gsum(w_s)
    v = w_s / WS[g]
    c_s = -gsum(v * u_r)
    a_s = np.zeros_like(u_r)
    b_s = v
    if fit.weighted:
        kappa = (u_s - fit.s[g]) / WS[g]  # ∂S/∂w^S_k
        # through α: ∂(1/P_S)/∂α = 2 P_RS / P_S² (Eq. 8 cross term)
        c_s = c_s + gsum(2.0 * fit.p_rs * w_s * w_s * kappa)
        if var_range_all is not None and var_perp_all is not None:
            # through the point's own measured range and bearing (δd = b·δu, δφ = p·δu / d)
            var_range = var_range_all[pidx]
            var_perp = var_perp_all[pidx]
            dvar_range = pts.dvar_range[pidx] if pts.dvar_range is not None else np.zeros_like(u_r)
            d = np.sqrt(d2)
            dps_dd = dvar_range * sin_t * sin_t + 2.0 * var_perp / d * cos_t * cos_t
            dps_dphi = 2.0 * (var_range - var_perp) * sin_t * cos_t
            k_d = -kappa * dps_dd * w_s * w_s
            k_phi = -kappa * dps_dphi * w_s * w_s / d
            a_s = k_d * cos_t - k_phi * sin_t
            b_s = v + k_d * sin_t + k_phi * cos_t
    a_s = a_s + c_s[g] * gain_a

    P_rs = gsum(gain_r * (a_s * p_r + b_s * q_nt))
    P_as = gsum(gain_a * (a_s * p_r + b_s * q_nt))
    P_ss = gsum(a_s * a_s * p_r + b_s * b_s * q_tt + 2.0 * a_s * b_s * q_nt)

    cov = np.empty((G, 3, 3))
    cov[:, 0, 0] = P_rr
    cov[:, 0, 1] = cov[:, 1, 0] = P_ra
    cov[:, 1, 1] = P_aa
    cov[:, 0, 2] = cov[:, 2, 0] = P_rs
    cov[:, 1, 2] = cov[:, 2, 1] = P_as
    cov[:, 2, 2] = P_ss

    end_var = q_tt + u_r * u_r * P_aa[g] - 2.0 * u_r * gain_a * q_nt
    return LineCovariances(cov=cov, end_var=end_var, gain_alpha=gain_a)
