"""Maximum-likelihood line fit (Props. 1-2), vectorised over all the lines of a scan.

The fit works on *memberships*: ``point_idx[j]`` is a point (index into the point arrays) and
``group_idx[j]`` the line it supports; a point may support more than one line.  Every step is
a handful of numpy operations over all memberships at once, with per-line sums by
``np.bincount`` over the group ids, so a scan's lines are iterated together.

Weighted fit (the paper)
------------------------
For the current ``α̂`` of each line:

* Prop. 1: ``R = Σ(u_R/P_R)/Σ(1/P_R)`` and ``S = Σ(u_S/P_S)/Σ(1/P_S)`` (Eqs. 21-23);
* Prop. 2: ``δα = −Σ(δ_R δ_S/P_R) / Σ(δ_S²/P_R)`` (Eq. 24), with ``δ_R = u_R − R``,
  ``δ_S = u_S − S`` and the sign of ``u_S`` of reading note 1 (``u_S = d·sin(φ − α)``).

The iteration stops when every line's ``|δα|`` is below ``tolerance_rad`` (or after
``max_iterations``; lines that have not converged are flagged).  Its fixed point is the minimiser
of ``Σ (u_R − R)²/P_R`` with the weights ``1/P_R`` evaluated at the solution itself, i.e. the
weighted total-least-squares line with self-consistent Eq. 14 weights.  For fixed weights that
minimiser is closed-form (the smallest eigenvector of the weighted scatter matrix);
:func:`fit_alpha_numerical` instead maximises the normal part of the log-likelihood Eq. 20 over
``α`` with scipy and re-evaluates the weights until they stop changing, which is what the tests
compare Prop. 2 against.

The ``δ_S`` of Eq. 24 is measured from the ``P_S``-weighted ``S`` of Prop. 1; any other origin
gives the same numerator (``Σ δ_R/P_R = 0``) and hence the same fixed point.  Measuring from the
``P_R``-weighted centre (``alpha_step="gauss_newton"``, the default) turns the step into the exact
Gauss-Newton step for the current weights; the paper's choice (``"prop2"``) makes it shorter
when the two centres differ, e.g. 16-23 instead of 3-5 iterations to 1e-12 rad for a wall seen
off to one side, 66-100 for a wall spanning 1-20 m.  What remains linear is the re-weighting
(the weights depend on ``α``); with ``"gauss_newton"`` that tail is shortened by Aitken
extrapolation.  Both reach the same optimum (``tests/test_fit.py``).

Unweighted fit
--------------
``weighted=False`` gives plain total least squares: the line through the centroid along the
principal direction of the points (closed form, no iteration), ``S`` the plain mean of ``u_S``.
Its covariance is propagated for that estimator (sandwich form, :mod:`linefit.covariance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle

__all__ = [
    "GroupFit",
    "PointSet",
    "fit_alpha_numerical",
    "fit_groups",
    "nearest_representative",
    "tls_groups",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# Floor on the variances of a point's normal/tangential component (m²).  Only reached with
# sigma_bearing_rad = 0 at exact normal or grazing incidence, where a variance would be 0.
VARIANCE_FLOOR_M2 = 1e-20


@dataclass(frozen=True, eq=False)
class PointSet:
    """Points of one scan with their covariances, as flat arrays (all shape ``(n,)``).

    Attributes
    ----------
    x, y : ndarray
        Cartesian coordinates (m) in the sensor frame.
    q11, q12, q22 : ndarray
        Entries of each point's covariance ``Q`` (m²), e.g. Eq. 8.
    var_range, var_perp : ndarray or None
        For scan points: ``σ_d²`` and ``d²σ_φ²`` (m²), the along-beam and across-beam parts of
        Eq. 8.  Given, they let :mod:`linefit.covariance` use the ``"beam"`` bearing-error
        model for ``S`` and the endpoints, and account for the dependence of the ``S`` weights
        on the measured range and bearing; None for arbitrary points with given (constant)
        covariances.
    dvar_range : ndarray or None
        For scan points: ``d(σ_d²)/dd`` (m), zero for a constant ``σ_d``.
    beam : ndarray of int
        Beam index of each point in its scan (used for gaps and for :attr:`Line.indices`).
    """

    x: FloatArray
    y: FloatArray
    q11: FloatArray
    q12: FloatArray
    q22: FloatArray
    beam: IntArray
    var_range: FloatArray | None = None
    var_perp: FloatArray | None = None
    dvar_range: FloatArray | None = None

    def __len__(self) -> int:
        return int(self.x.shape[0])


@dataclass(frozen=True, eq=False)
class GroupFit:
    """Result of fitting ``G`` lines at once.

    Per line (shape ``(G,)``): ``r`` (signed), ``alpha``, ``s``, ``converged``, ``iterations``.
    Per membership (shape ``(m,)``), evaluated at the final estimate: ``u_r``, ``u_s``, ``p_r``,
    ``p_s``, ``p_rs`` (Eq. 14, Eq. 15 and the cross term, m²), ``w_r`` and ``w_s`` (the weights
    used for ``R, α`` and for ``S``).
    """

    r: FloatArray
    alpha: FloatArray
    s: FloatArray
    converged: NDArray[np.bool_]
    iterations: IntArray
    u_r: FloatArray
    u_s: FloatArray
    p_r: FloatArray
    p_s: FloatArray
    p_rs: FloatArray
    w_r: FloatArray
    w_s: FloatArray
    weighted: bool


def nearest_representative(alpha: FloatArray, reference: FloatArray) -> FloatArray:
    """``alpha`` or ``alpha + π`` (the same infinite line), whichever is nearer ``reference``.

    The result is unwrapped around ``reference`` (it may leave ``(−π, π]``).
    """
    diff = np.asarray(wrap_angle(np.asarray(alpha) - np.asarray(reference)), dtype=float)
    diff = np.where(np.abs(diff) > 0.5 * np.pi, np.asarray(wrap_angle(diff + np.pi)), diff)
    return np.asarray(reference, dtype=float) + diff


def tls_groups(
    pts: PointSet, pidx: IntArray, gidx: IntArray, n_groups: int, weights: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closed-form (weighted) total-least-squares lines of many groups at once.

    Minimises ``Σ w_k (u_k·n − R)²`` per group for fixed weights: the line passes through the
    weighted centroid, its normal is the eigenvector of the smallest eigenvalue of the weighted
    scatter matrix.

    Parameters
    ----------
    pts
        The points.
    pidx, gidx
        Memberships: point index and group id (shape ``(m,)``).
    n_groups
        Number of groups ``G``.
    weights
        Per-membership weights; None for unweighted.

    Returns
    -------
    r, alpha : ndarray, shape (G,)
        The lines with ``α`` chosen so that ``r ≥ 0``.
    min_eig_ratio : ndarray, shape (G,)
        Smallest over largest eigenvalue of the scatter matrix (0 for a perfect line; NaN
        when the group's points coincide).
    """
    x = pts.x[pidx]
    y = pts.y[pidx]
    w = np.ones_like(x) if weights is None else weights
    wsum = np.bincount(gidx, weights=w, minlength=n_groups)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = np.bincount(gidx, weights=w * x, minlength=n_groups) / wsum
        my = np.bincount(gidx, weights=w * y, minlength=n_groups) / wsum
    dx = x - mx[gidx]
    dy = y - my[gidx]
    cxx = np.bincount(gidx, weights=w * dx * dx, minlength=n_groups)
    cyy = np.bincount(gidx, weights=w * dy * dy, minlength=n_groups)
    cxy = np.bincount(gidx, weights=w * dx * dy, minlength=n_groups)
    # direction of largest spread; the normal is perpendicular to it
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
    r = mx * np.cos(alpha) + my * np.sin(alpha)
    flip = r < 0.0
    r = np.where(flip, -r, r)
    alpha = np.asarray(wrap_angle(np.where(flip, alpha + np.pi, alpha)), dtype=float)
    half_tr = 0.5 * (cxx + cyy)
    disc = np.sqrt(np.maximum(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = (half_tr - disc) / (half_tr + disc)
    return r, alpha, ratio


def fit_groups(
    pts: PointSet,
    pidx: IntArray,
    gidx: IntArray,
    n_groups: int,
    alpha0: FloatArray,
    *,
    weighted: bool = True,
    max_iterations: int = 20,
    tolerance_rad: float = 1e-10,
    alpha_step: str = "gauss_newton",
) -> GroupFit:
    """Fit ``G`` lines at once (Props. 1-2 when weighted, total least squares otherwise).

    Parameters
    ----------
    pts
        The points of the scan.
    pidx, gidx
        Memberships (shape ``(m,)``): point index and group id in ``0..G-1``, sorted by group.
        Every group needs at least two memberships.
    n_groups
        ``G``.
    alpha0
        Initial normal angles (rad), shape ``(G,)``, e.g. from the grouping step.
    weighted
        Paper's ML fit (True) or plain total least squares (False; ``alpha0`` only picks the
        representative).
    max_iterations
        Cap on Prop. 2 iterations.
    tolerance_rad
        A line has converged when its last ``|δα|`` is below this; the iteration stops when
        all have.
    alpha_step
        ``"gauss_newton"`` or ``"prop2"`` (see the module docstring).

    Returns
    -------
    GroupFit
        Lines with signed ``r`` (the representative closest to ``alpha0``) and the per-membership
        quantities the covariance needs.
    """
    G = n_groups
    m = pidx.shape[0]
    # memberships are sorted by group: every per-line sum is one reduceat over the rows
    starts = np.flatnonzero(np.concatenate([[True], gidx[1:] != gidx[:-1]]))
    if starts.shape[0] != G or (m and (gidx[0] != 0 or gidx[-1] != G - 1)):
        raise ValueError("memberships must be sorted by group and every group non-empty")
    counts = np.diff(np.append(starts, m)).astype(float)
    x_all = pts.x[pidx]
    y_all = pts.y[pidx]
    # centre each group on its centroid (no cancellation in the sums below)
    mx = np.add.reduceat(x_all, starts) / counts
    my = np.add.reduceat(y_all, starts) / counts
    x = x_all - mx[gidx]
    y = y_all - my[gidx]
    q11 = pts.q11[pidx]
    q12 = pts.q12[pidx]
    q22 = pts.q22[pidx]
    q_tr = q11 + q22
    q_half = 0.5 * q_tr
    q_diff = 0.5 * (q11 - q22)

    alpha = np.asarray(alpha0, dtype=float).copy()
    iterations = np.zeros(G, dtype=np.intp)
    active = np.ones(G, dtype=bool)
    if not weighted:
        _, a_tls, _ = tls_groups(pts, pidx, gidx, G)
        alpha = nearest_representative(a_tls, alpha)
        active[:] = False  # closed form: nothing to iterate
    else:
        prop2 = alpha_step == "prop2"
        # working set: the lines still iterating (compacted when many have converged)
        groups = np.arange(G)
        last_step = np.zeros(G)
        fresh = np.zeros(G, dtype=bool)  # the previous step was a plain one
        gw, sw = gidx, starts
        # complex form: u_R + i u_S = (x + i y)·e^{−iα},
        # P_R = q_half + Re((q_diff − i q12)·e^{2iα})
        zw = x + 1j * y
        qzw = q_diff - 1j * q12
        qh, qt = q_half, q_tr
        for _ in range(max_iterations):
            act_w = active[groups]
            if act_w.sum() < 0.6 * groups.shape[0]:
                keep = act_w[gw]
                groups = groups[act_w]
                local = np.cumsum(act_w) - 1
                gw = local[gw[keep]]
                zw, qzw, qh, qt = zw[keep], qzw[keep], qh[keep], qt[keep]
                sw = np.flatnonzero(np.concatenate([[True], gw[1:] != gw[:-1]]))
                act_w = np.ones(groups.shape[0], dtype=bool)
            rot = np.exp(-1j * alpha[groups])
            u = zw * rot[gw]
            u_r, u_s = u.real, u.imag
            p_r = qh + (qzw * (rot * rot).conj()[gw]).real
            np.maximum(p_r, VARIANCE_FLOOR_M2, out=p_r)
            rows = np.empty((7 if prop2 else 5, zw.shape[0]))
            w = np.divide(1.0, p_r, out=rows[0])
            np.multiply(w, u_r, out=rows[1])
            np.multiply(w, u_s, out=rows[2])
            np.multiply(rows[1], u_s, out=rows[3])
            np.multiply(rows[2], u_s, out=rows[4])
            if prop2:
                p_s = np.maximum(qt - p_r, VARIANCE_FLOOR_M2)
                np.divide(1.0, p_s, out=rows[5])
                np.multiply(rows[5], u_s, out=rows[6])
            sums = np.add.reduceat(rows, sw, axis=1)
            W, s_wr, s_ws, s_wrs, s_wss = sums[0], sums[1], sums[2], sums[3], sums[4]
            centre = s_ws / W  # P_R-weighted centre of u_S
            num = s_wrs - s_wr * centre  # Σ w δ_R u_S  (Σ w δ_R = 0)
            if prop2:
                s_p = sums[6] / sums[5]  # Prop. 1's P_S-weighted S
                den = s_wss - 2.0 * s_p * s_ws + s_p * s_p * W
            else:
                den = s_wss - centre * s_ws
            with np.errstate(invalid="ignore", divide="ignore"):
                step = -num / den
            # converged lines are frozen, so a line's result does not depend on the others
            step = np.where(act_w & np.isfinite(step), step, 0.0)
            alpha[groups] += step
            iterations[groups] += act_w
            conv = np.abs(step) < tolerance_rad
            if not prop2:
                # Aitken extrapolation of the linear tail that re-weighting leaves (a line whose
                # weights change quickly with α, e.g. a few points at mixed incidence): after
                # two plain steps in a ratio 0 < ρ < 0.95, jump by step·ρ/(1 − ρ).  The fixed
                # point, and the convergence test on a plain step, are unchanged.
                prev = last_step[groups]
                with np.errstate(invalid="ignore", divide="ignore"):
                    rho = step / prev
                    jump = fresh[groups] & ~conv & (rho > 0.0) & (rho < 0.95)
                    extra = np.clip(step * rho / (1.0 - rho), -0.1, 0.1)
                alpha[groups] += np.where(jump, extra, 0.0)
                fresh[groups] = ~jump
                last_step[groups] = step
            active[groups] = act_w & ~conv
            if not active.any():
                break
    converged = ~active

    # final frame in sensor coordinates
    ca_g, sa_g = np.cos(alpha), np.sin(alpha)
    ca, sa = ca_g[gidx], sa_g[gidx]
    u_r = x_all * ca + y_all * sa
    u_s = y_all * ca - x_all * sa
    cc = ca * ca
    ss = sa * sa
    sc = sa * ca
    p_r = np.maximum(q11 * cc + 2.0 * q12 * sc + q22 * ss, VARIANCE_FLOOR_M2)
    p_s = np.maximum(q_tr - p_r, VARIANCE_FLOOR_M2)
    p_rs = (q22 - q11) * sc + q12 * (cc - ss)
    if weighted:
        w_r = 1.0 / p_r
        w_s = 1.0 / p_s
    else:
        w_r = np.ones(m)
        w_s = np.ones(m)
    # R and S from Prop. 1, computed in centred coordinates
    u_r_c = x * ca + y * sa
    u_s_c = y * ca - x * sa
    sums = np.add.reduceat(np.stack([w_r, w_r * u_r_c, w_s, w_s * u_s_c]), starts, axis=1)
    r = sums[1] / sums[0] + mx * ca_g + my * sa_g
    s = sums[3] / sums[2] + my * ca_g - mx * sa_g
    return GroupFit(
        r=r,
        alpha=alpha,
        s=s,
        converged=converged,
        iterations=iterations,
        u_r=u_r,
        u_s=u_s,
        p_r=p_r,
        p_s=p_s,
        p_rs=p_rs,
        w_r=w_r,
        w_s=w_s,
        weighted=weighted,
    )


def fit_alpha_numerical(
    pts: PointSet,
    alpha0: float,
    *,
    tolerance_rad: float = 1e-13,
    max_reweights: int = 50,
    half_width_rad: float = 0.05,
) -> float:
    """Maximise the normal part of the log-likelihood (Eq. 20) over ``α`` with scipy.

    For fixed weights ``1/P_R`` (Eq. 14 at the current ``α̂``) the terms of Eq. 20 that depend
    on the line's ``(R, α)`` are ``−½ Σ (u_R − R)²/P_R``; with ``R`` from Prop. 1 this is a
    function of ``α`` alone, maximised here with :func:`scipy.optimize.minimize_scalar`
    (bounded Brent, ``α̂ ± half_width_rad``).  The weights are then re-evaluated at the new
    ``α̂`` and the maximisation repeated until ``α̂`` moves by less than ``tolerance_rad``.
    (The ``δ_S`` terms of Eq. 20 only determine ``S``: the paper's decoupling of the R and S
    directions, Sec. III.)

    Parameters
    ----------
    pts
        All the points of one line.
    alpha0
        Starting normal angle (rad).
    tolerance_rad
        Stop when the re-weighted optimum moves by less than this.
    max_reweights
        Cap on re-weighting rounds.
    half_width_rad
        Half-width of the bracket searched around the current estimate.

    Returns
    -------
    float
        The maximising ``α`` (rad), same representative as ``alpha0``.
    """
    from scipy.optimize import minimize_scalar

    x = pts.x
    y = pts.y
    alpha = float(alpha0)
    for _ in range(max_reweights):
        ca, sa = np.cos(alpha), np.sin(alpha)
        cc, ss, sc = ca * ca, sa * sa, sa * ca
        w = 1.0 / np.maximum(pts.q11 * cc + 2 * pts.q12 * sc + pts.q22 * ss, VARIANCE_FLOOR_M2)
        w = w / w.sum()
        mx, my = float(w @ x), float(w @ y)
        dx, dy = x - mx, y - my

        def neg_loglik(
            delta: float,
            dx: FloatArray = dx,
            dy: FloatArray = dy,
            w: FloatArray = w,
            alpha: float = alpha,
        ) -> float:
            a = alpha + delta
            resid = dx * np.cos(a) + dy * np.sin(a)  # u_R − R with R from Prop. 1
            return 0.5 * float(w @ (resid * resid))

        res = minimize_scalar(
            neg_loglik,
            bounds=(-half_width_rad, half_width_rad),
            method="bounded",
            options={"xatol": 1e-15, "maxiter": 500},
        )
        alpha_new = alpha + float(res.x)
        moved = abs(alpha_new - alpha)
        alpha = alpha_new
        if moved < tolerance_rad:
            break
    return alpha
