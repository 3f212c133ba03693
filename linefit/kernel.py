"""The compiled extraction path: the whole pipeline of :mod:`linefit.extract`, scan by scan (numba).

:func:`extract_kernel` runs steps 3-7 of :func:`linefit.extract_lines` (grouping, fit,
rejection, segments, Hough recovery, collinear merge, covariances, normal form, order) for every
scan of a batch, one scan after the other, and returns flat arrays that
:func:`linefit.batch.extract_lines_batch` turns into :class:`~linefit.line.Line` objects.  Steps
1-2 (valid readings, points and their Eq. 8 covariances) stay in numpy, vectorised over the
batch.  Each function here is the scalar-loop form of the numpy function named in its
docstring, with the same formulas in the same order of operations and the same discrete rules
(ties, order of lines), so both paths give the same lines; sums are accumulated left to right
where numpy may sum pairwise, so values agree to rounding (``tests/test_kernel.py`` compares
the two on constructed and real scans).  The numpy modules remain the reference
implementation (:func:`linefit.batch.extract_lines_batch_numpy`).

A scan's result does not depend on the other scans of its batch: everything, the Hough
accumulator's extent included, is computed per scan.

Why compiled: the numpy path amortises numpy's per-call overhead over a batch, but the
pipeline is hundreds of small array operations per batch and per scan a few dozen points per
line; a single scan pays that overhead in full (``docs/benchmarks.md``).
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.config import LineFitConfig

__all__ = ["DENSE_CELLS", "FPARAMS", "IPARAMS", "extract_kernel", "kernel_params"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

jit = njit(cache=True, error_model="numpy", nogil=True)

#: Rows of the point array ``pt`` given to :func:`extract_kernel`.
X, Y, Q11, Q12, Q22, VR, VP, DV, SIG, D, PHI = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10

#: Names of the entries of the float parameter vector, in order.
FPARAMS = (
    "alpha_tolerance_rad",
    "outlier_chi2",
    "breakpoint_lambda_rad",
    "breakpoint_sigma",
    "hough_range_step_m",
    "hough_gather_m",
    "split_threshold_m",
    "split_threshold_sigma",
    "merge_chi2",
    "min_length_m",
)
(
    F_TOL,
    F_CHI2,
    F_LAMBDA,
    F_BSIG,
    F_RSTEP,
    F_GATHER,
    F_SPLIT_M,
    F_SPLIT_SIG,
    F_MERGE_CHI2,
    F_MIN_LEN,
) = range(10)

#: Names of the entries of the integer parameter vector, in order.
IPARAMS = (
    "max_iterations",
    "min_points",
    "max_refits",
    "min_segment_points",
    "max_missing_beams",
    "hough_min_votes",
    "hough_max_peaks",
    "hough",
    "hough_recover",
    "merge_collinear",
    "weighted",
    "prop2",
    "beam_model",
)
(
    I_MAXIT,
    I_MINPTS,
    I_MAXREF,
    I_MINSEG,
    I_MAXMISS,
    I_MINVOTES,
    I_MAXPEAKS,
    I_HOUGH,
    I_RECOVER,
    I_MERGE,
    I_WEIGHTED,
    I_PROP2,
    I_BEAM,
) = range(13)

#: Rows of the member arena ``ar``: u_R, u_S and endpoint variance of each stored member.
A_UR, A_US, A_EV = 0, 1, 2

#: Rows of the float scratch ``wk`` of the line being refined: centred points, u_R, u_S, P_R,
#: P_S, P_RS, their weights, and a spare row.
W_CX, W_CY, W_UR, W_US, W_PR, W_PS, W_PRS, W_WR, W_WS, W_TMP = range(10)

#: Rows of the integer scratch ``iw``: members of the line being refined, their order by
#: ``u_S``, segment numbers, segment sizes, drop flags.
R_MEM, R_ORDER, R_SEG, R_COUNT, R_DROP = 0, 1, 2, 3, 4

FLOOR = 1e-20  # linefit.fit.VARIANCE_FLOOR_M2
SUPPRESSED = -1073741824  # np.iinfo(np.int32).min // 2, as linefit.hough


@jit
def _wrap(a: float) -> float:
    """:func:`linefit.line.wrap_angle` of one angle."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


# --------------------------------------------------------------------------------------------
# the ML fit of one line (linefit.fit.fit_groups)
# --------------------------------------------------------------------------------------------
@jit
def _fit(pt, iw, L, alpha0, ip, fp, wk, res):
    """Fit one line to the points ``iw[R_MEM, :L]``; per-member results in the rows of ``wk``.

    ``res`` receives ``r, alpha, s`` (signed, the representative nearest ``alpha0``).  Returns
    True when the line converged with finite ``r`` and ``alpha`` (else the caller drops it).
    """
    weighted = ip[I_WEIGHTED] != 0
    mx = 0.0
    my = 0.0
    for k in range(L):
        mx += pt[X, iw[R_MEM, k]]
        my += pt[Y, iw[R_MEM, k]]
    mx /= L
    my /= L
    for k in range(L):
        wk[W_CX, k] = pt[X, iw[R_MEM, k]] - mx
        wk[W_CY, k] = pt[Y, iw[R_MEM, k]] - my
    alpha = alpha0
    active = True
    if not weighted:
        # tls_groups (unit weights, plain sums) and nearest_representative
        tx = 0.0
        ty = 0.0
        for k in range(L):
            tx += pt[X, iw[R_MEM, k]]
            ty += pt[Y, iw[R_MEM, k]]
        tx /= L
        ty /= L
        cxx = 0.0
        cyy = 0.0
        cxy = 0.0
        for k in range(L):
            dx = pt[X, iw[R_MEM, k]] - tx
            dy = pt[Y, iw[R_MEM, k]] - ty
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        a_t = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
        r_t = tx * np.cos(a_t) + ty * np.sin(a_t)
        if r_t < 0.0:
            a_t = a_t + np.pi
        a_t = _wrap(a_t)
        diff = _wrap(a_t - alpha0)
        if abs(diff) > 0.5 * np.pi:
            diff = _wrap(diff + np.pi)
        alpha = alpha0 + diff
        active = False
    else:
        prop2 = ip[I_PROP2] != 0
        tol = fp[F_TOL]
        last_step = 0.0
        fresh = False
        for _ in range(ip[I_MAXIT]):
            ca = np.cos(alpha)
            sa = np.sin(alpha)
            cos2 = ca * ca - sa * sa
            sin2 = ca * sa + sa * ca
            W = 0.0
            s_wr = 0.0
            s_ws = 0.0
            s_wrs = 0.0
            s_wss = 0.0
            s_p0 = 0.0
            s_p1 = 0.0
            for k in range(L):
                p = iw[R_MEM, k]
                q11 = pt[Q11, p]
                q22 = pt[Q22, p]
                qt = q11 + q22
                qh = 0.5 * qt
                qd = 0.5 * (q11 - q22)
                u_r = wk[W_CX, k] * ca + wk[W_CY, k] * sa
                u_s = wk[W_CY, k] * ca - wk[W_CX, k] * sa
                p_r = qh + (qd * cos2 + pt[Q12, p] * sin2)
                if p_r < FLOOR:
                    p_r = FLOOR
                w = 1.0 / p_r
                wu_r = w * u_r
                wu_s = w * u_s
                W += w
                s_wr += wu_r
                s_ws += wu_s
                s_wrs += wu_r * u_s
                s_wss += wu_s * u_s
                if prop2:
                    p_s = qt - p_r
                    if p_s < FLOOR:
                        p_s = FLOOR
                    s_p0 += 1.0 / p_s
                    s_p1 += (1.0 / p_s) * u_s
            centre = s_ws / W
            num = s_wrs - s_wr * centre
            if prop2:
                s_p = s_p1 / s_p0
                den = s_wss - 2.0 * s_p * s_ws + s_p * s_p * W
            else:
                den = s_wss - centre * s_ws
            step = -num / den
            if not np.isfinite(step):
                step = 0.0
            alpha += step
            conv = abs(step) < tol
            if not prop2:
                rho = step / last_step
                jump = fresh and (not conv) and rho > 0.0 and rho < 0.95
                if jump:
                    extra = step * rho / (1.0 - rho)
                    extra = min(max(extra, -0.1), 0.1)
                    alpha += extra
                fresh = not jump
                last_step = step
            if conv:
                active = False
                break
    # final frame in sensor coordinates
    ca = np.cos(alpha)
    sa = np.sin(alpha)
    cc = ca * ca
    ss = sa * sa
    sc = sa * ca
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for k in range(L):
        p = iw[R_MEM, k]
        x = pt[X, p]
        y = pt[Y, p]
        q11 = pt[Q11, p]
        q12 = pt[Q12, p]
        q22 = pt[Q22, p]
        wk[W_UR, k] = x * ca + y * sa
        wk[W_US, k] = y * ca - x * sa
        p_r = q11 * cc + 2.0 * q12 * sc + q22 * ss
        if p_r < FLOOR:
            p_r = FLOOR
        p_s = (q11 + q22) - p_r
        if p_s < FLOOR:
            p_s = FLOOR
        wk[W_PR, k] = p_r
        wk[W_PS, k] = p_s
        wk[W_PRS, k] = (q22 - q11) * sc + q12 * (cc - ss)
        if weighted:
            wk[W_WR, k] = 1.0 / p_r
            wk[W_WS, k] = 1.0 / p_s
        else:
            wk[W_WR, k] = 1.0
            wk[W_WS, k] = 1.0
        s0 += wk[W_WR, k]
        s1 += wk[W_WR, k] * (wk[W_CX, k] * ca + wk[W_CY, k] * sa)
        s2 += wk[W_WS, k]
        s3 += wk[W_WS, k] * (wk[W_CY, k] * ca - wk[W_CX, k] * sa)
    r = s1 / s0 + mx * ca + my * sa
    s = s3 / s2 + my * ca - mx * sa
    res[0] = r
    res[1] = alpha
    res[2] = s
    return (not active) and np.isfinite(r) and np.isfinite(alpha)


# --------------------------------------------------------------------------------------------
# breakpoints and segments (linefit.segments)
# --------------------------------------------------------------------------------------------
@jit
def _is_break(pt, beam, a, b, ip, fp):
    """:func:`linefit.segments.breakpoint_mask` between the points ``a`` and ``b`` (symmetric)."""
    missing = abs(beam[b] - beam[a]) - 1
    if missing > ip[I_MAXMISS]:
        return True
    xa = pt[X, a]
    ya = pt[Y, a]
    xb = pt[X, b]
    yb = pt[Y, b]
    dphi = abs(pt[PHI, b] - pt[PHI, a])
    dphi = min(dphi, 2.0 * np.pi - dphi)
    d_near = min(pt[D, a], pt[D, b])
    gap = np.hypot(xb - xa, yb - ya)
    lam = fp[F_LAMBDA]
    sin_margin = np.sin(max(lam - dphi, 0.0))
    limit = d_near * np.sin(dphi) / sin_margin
    limit = limit + fp[F_BSIG] * max(pt[SIG, a], pt[SIG, b])
    return dphi >= lam or not (gap <= limit)


@jit
def _lt(a, b):
    """``a < b`` in numpy's sort order (NaN last)."""
    return a < b or (b != b and a == a)


@jit
def _argsort_stable(v, row, L, iw):
    """Stable argsort of ``v[row, :L]`` into ``iw[R_ORDER, :L]`` (``np.argsort``, stable).

    Insertion sort, run from the end whose order the data already has (the members of a line
    are in beam order, so ``u_S`` is nearly sorted one way or the other): linear time for the
    usual input.
    """
    if L == 0:
        return
    if _lt(v[row, L - 1], v[row, 0]):
        # nearly descending: insert k = L-1, ..., 0 into the sorted tail iw[R_ORDER, k + 1 : L]
        for k in range(L - 1, -1, -1):
            x = v[row, k]
            i = k
            while i + 1 < L and _lt(v[row, iw[R_ORDER, i + 1]], x):
                iw[R_ORDER, i] = iw[R_ORDER, i + 1]
                i += 1
            iw[R_ORDER, i] = k
    else:
        for k in range(L):
            x = v[row, k]
            i = k
            while i > 0 and _lt(x, v[row, iw[R_ORDER, i - 1]]):
                iw[R_ORDER, i] = iw[R_ORDER, i - 1]
                i -= 1
            iw[R_ORDER, i] = k


@jit
def _segment_sizes(pt, beam, L, ip, fp, iw, wk):
    """Order the members ``iw[R_MEM, :L]`` by ``u_S`` and number their segments.

    The order (stable, by ``wk[W_US]``) goes to ``iw[R_ORDER]``, the segment numbers to
    ``iw[R_SEG]``.

    Returns the number of segments (:func:`linefit.segments.segment_ids` for one line).
    """
    _argsort_stable(wk, W_US, L, iw)
    n_seg = 0
    for k in range(L):
        a = iw[R_MEM, iw[R_ORDER, k - 1]] if k > 0 else 0
        if k > 0 and _is_break(pt, beam, a, iw[R_MEM, iw[R_ORDER, k]], ip, fp):
            n_seg += 1
        iw[R_SEG, k] = n_seg
    return n_seg + 1 if L else 0


# --------------------------------------------------------------------------------------------
# covariance of one line (linefit.covariance.line_covariances)
# --------------------------------------------------------------------------------------------
@jit
def _covariance(pt, iw, L, wk, s_fit, ip, lcov, li):
    """The ``(R, α, S)`` covariance into ``lcov[li]``; the members' endpoint variances.

    The endpoint variances go to ``wk[W_TMP]``.
    """
    weighted = ip[I_WEIGHTED] != 0
    beam_model = ip[I_BEAM] != 0
    W = 0.0
    cw = 0.0
    WS = 0.0
    for k in range(L):
        W += wk[W_WR, k]
        cw += wk[W_WR, k] * wk[W_US, k]
        WS += wk[W_WS, k]
    c = cw / W
    A = 0.0
    for k in range(L):
        du = wk[W_US, k] - c
        A += wk[W_WR, k] * du * du
    c_s = 0.0
    c_s_w = 0.0
    for k in range(L):
        c_s += (wk[W_WS, k] / WS) * wk[W_UR, k]
        if weighted:
            kappa = (wk[W_US, k] - s_fit) / WS
            c_s_w += 2.0 * wk[W_PRS, k] * wk[W_WS, k] * wk[W_WS, k] * kappa
    c_s = -c_s
    if weighted:
        c_s = c_s + c_s_w
    if weighted:
        P_aa = 1.0 / A
        P_ra = c / A
        P_rr = 1.0 / W + c * c / A
    else:
        P_rr = 0.0
        P_ra = 0.0
        P_aa = 0.0
        for k in range(L):
            gain_a = -wk[W_WR, k] * (wk[W_US, k] - c) / A
            gain_r = wk[W_WR, k] / W + c * gain_a
            P_rr += gain_r * gain_r * wk[W_PR, k]
            P_ra += gain_r * gain_a * wk[W_PR, k]
            P_aa += gain_a * gain_a * wk[W_PR, k]
    P_rs = 0.0
    P_as = 0.0
    P_ss = 0.0
    for k in range(L):
        p = iw[R_MEM, k]
        u_r = wk[W_UR, k]
        u_s = wk[W_US, k]
        gain_a = -wk[W_WR, k] * (u_s - c) / A
        gain_r = wk[W_WR, k] / W + c * gain_a
        d2 = u_r * u_r + u_s * u_s
        cos_t = u_r / np.sqrt(d2)
        sin_t = u_s / np.sqrt(d2)
        var_range = pt[VR, p]
        var_perp = pt[VP, p]
        if beam_model:
            var_eff = var_range + var_perp * (u_s * u_s) / (u_r * u_r)
            q_tt = var_eff * sin_t * sin_t
            q_nt = var_eff * sin_t * cos_t
        else:
            q_tt = wk[W_PS, k]
            q_nt = wk[W_PRS, k]
        v = wk[W_WS, k] / WS
        a_s = 0.0
        b_s = v
        if weighted:
            kappa = (u_s - s_fit) / WS
            d = np.sqrt(d2)
            dps_dd = pt[DV, p] * sin_t * sin_t + 2.0 * var_perp / d * cos_t * cos_t
            dps_dphi = 2.0 * (var_range - var_perp) * sin_t * cos_t
            k_d = -kappa * dps_dd * wk[W_WS, k] * wk[W_WS, k]
            k_phi = -kappa * dps_dphi * wk[W_WS, k] * wk[W_WS, k] / d
            a_s = k_d * cos_t - k_phi * sin_t
            b_s = v + k_d * sin_t + k_phi * cos_t
        a_s = a_s + c_s * gain_a
        P_rs += gain_r * (a_s * wk[W_PR, k] + b_s * q_nt)
        P_as += gain_a * (a_s * wk[W_PR, k] + b_s * q_nt)
        P_ss += a_s * a_s * wk[W_PR, k] + b_s * b_s * q_tt + 2.0 * a_s * b_s * q_nt
        wk[W_TMP, k] = q_tt + u_r * u_r * P_aa - 2.0 * u_r * gain_a * q_nt
    lcov[li, 0, 0] = P_rr
    lcov[li, 0, 1] = P_ra
    lcov[li, 1, 0] = P_ra
    lcov[li, 1, 1] = P_aa
    lcov[li, 0, 2] = P_rs
    lcov[li, 2, 0] = P_rs
    lcov[li, 1, 2] = P_as
    lcov[li, 2, 1] = P_as
    lcov[li, 2, 2] = P_ss


# --------------------------------------------------------------------------------------------
# fit, rejection and segments of one candidate line (linefit.refine.refine)
# --------------------------------------------------------------------------------------------
@jit
def _refine_line(
    pt, beam, gm, g0, L0, alpha0, ip, fp, wk, iw, res, lr, lcov, lm, li, ar, ai, ao, top
):
    """Refine the candidate ``gm[g0 : g0 + L0]`` into line slot ``li``; its members go to ``top``.

    Returns ``(status, n_refits, seg_changed, new_top)``: status 1 when the line survived.
    ``n_refits`` is the number of reject-and-refit rounds it went through and ``seg_changed``
    whether small segments were removed (the caller reproduces the numpy path's order of lines
    from these).
    """
    min_pts = max(2, ip[I_MINPTS])
    L = L0
    for k in range(L):
        iw[R_MEM, k] = gm[g0 + k]
    n_refits = 0
    if min_pts > L:
        return 0, n_refits, False, top
    if not _fit(pt, iw, L, alpha0, ip, fp, wk, res):
        return 0, n_refits, False, top
    chi2_max = fp[F_CHI2]
    for _ in range(ip[I_MAXREF] + 1):
        # leverage (linefit.refine.leverage) and the studentised χ² of each member
        W = 0.0
        cw = 0.0
        for k in range(L):
            W += wk[W_WR, k]
            cw += wk[W_WR, k] * wk[W_US, k]
        c = cw / W
        A = 0.0
        for k in range(L):
            du = wk[W_US, k] - c
            A += wk[W_WR, k] * du * du
        worst = 0.0
        for k in range(L):
            du = wk[W_US, k] - c
            h = wk[W_WR, k] * (1.0 / W + du * du / A)
            h = min(h, 0.95)
            e = wk[W_UR, k] - res[0]
            chi2 = e * e / (wk[W_PR, k] * (1.0 - h))
            wk[W_TMP, k] = chi2
            if chi2 > worst or np.isnan(chi2):
                worst = chi2
        n_keep = 0
        for k in range(L):
            reject = wk[W_TMP, k] > chi2_max and wk[W_TMP, k] >= worst / 9.0
            if not reject:
                iw[R_MEM, n_keep] = iw[R_MEM, k]
                n_keep += 1
        if n_keep == L:
            break
        L = n_keep
        n_refits += 1
        if min_pts > L:
            return 0, n_refits, False, top
        if not _fit(pt, iw, L, res[1], ip, fp, wk, res):
            return 0, n_refits, False, top
    # segments; pieces with too few points leave the line
    n_seg = _segment_sizes(pt, beam, L, ip, fp, iw, wk)
    seg_changed = False
    if n_seg:
        for g in range(n_seg):
            iw[R_COUNT, g] = 0
        for k in range(L):
            iw[R_COUNT, iw[R_SEG, k]] += 1
        for k in range(L):
            iw[R_DROP, k] = 0
        any_small = False
        for k in range(L):
            if iw[R_COUNT, iw[R_SEG, k]] < ip[I_MINSEG]:
                iw[R_DROP, iw[R_ORDER, k]] = 1
                any_small = True
        if any_small:
            seg_changed = True
            n_keep = 0
            for k in range(L):
                if iw[R_DROP, k] == 0:
                    iw[R_MEM, n_keep] = iw[R_MEM, k]
                    n_keep += 1
            L = n_keep
            if min_pts > L:
                return 0, n_refits, True, top
            if not _fit(pt, iw, L, res[1], ip, fp, wk, res):
                return 0, n_refits, True, top
            n_seg = _segment_sizes(pt, beam, L, ip, fp, iw, wk)
    # store the line: slot li, its members at arena[top : top + L] with their order by u_S
    # and segment numbers
    for k in range(L):
        ai[top + k] = iw[R_MEM, k]
        ar[A_UR, top + k] = wk[W_UR, k]
        ar[A_US, top + k] = wk[W_US, k]
        ao[0, top + k] = iw[R_ORDER, k]
        ao[1, top + k] = iw[R_SEG, k]
    lr[li, 0] = res[0]
    lr[li, 1] = res[1]
    lr[li, 2] = res[2]
    lm[li, 0] = top
    lm[li, 1] = L
    lm[li, 2] = n_seg
    _covariance(pt, iw, L, wk, res[2], ip, lcov, li)
    for k in range(L):
        ar[A_EV, top + k] = wk[W_TMP, k]
    return 1, n_refits, seg_changed, top + L


# --------------------------------------------------------------------------------------------
# split-and-merge grouping of some points of one scan (linefit.split_merge)
# --------------------------------------------------------------------------------------------
@jit
def _thr(pt, p, fp):
    """Split threshold of point ``p``: ``max(split_threshold_m, split_threshold_sigma · σ_d)``."""
    return max(fp[F_SPLIT_M], fp[F_SPLIT_SIG] * pt[SIG, p])


@jit
def _tls(pt, sub, s, e):
    """Mean-centred TLS line of ``sub[s..e]``: ``(mx, my, alpha)`` (as ``_tls_max_score``)."""
    cnt = float(e - s + 1)
    mx = 0.0
    my = 0.0
    for k in range(s, e + 1):
        mx += pt[X, sub[k]]
        my += pt[Y, sub[k]]
    mx = mx / cnt
    my = my / cnt
    cxx = 0.0
    cyy = 0.0
    cxy = 0.0
    for k in range(s, e + 1):
        dx = pt[X, sub[k]] - mx
        dy = pt[Y, sub[k]] - my
        cxx += dx * dx
        cyy += dy * dy
        cxy += dx * dy
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
    return mx, my, alpha


@jit
def _tls_max_score(pt, sub, s, e, fp):
    """Largest ``distance / threshold`` of ``sub[s..e]`` to its own TLS line, and its angle."""
    mx, my, alpha = _tls(pt, sub, s, e)
    ca = np.cos(alpha)
    sa = np.sin(alpha)
    best = -np.inf
    for k in range(s, e + 1):
        p = sub[k]
        d = abs((pt[X, p] - mx) * ca + (pt[Y, p] - my) * sa) / _thr(pt, p, fp)
        if d > best or np.isnan(d):
            best = d
    return best, alpha


@jit
def _split_merge(pt, beam, sub, n, ip, fp, starts, ends, alphas, stk, flag):
    """Split-and-merge pieces of the points ``sub[:n]`` (one scan, beam order).

    Pieces are ``sub[starts[g] .. ends[g]]`` with start angles ``alphas[g]``; returns their
    number (:func:`linefit.split_merge.split_merge_groups` for one scan).
    """
    if n < max(2, ip[I_MINSEG]):
        return 0
    # clusters between breakpoints, at least two points each, onto the stack
    n_stk = 0
    c0 = 0
    for k in range(n):
        last = k == n - 1
        if last or _is_break(pt, beam, sub[k], sub[k + 1], ip, fp):
            if k - c0 + 1 >= 2:
                stk[n_stk, 0] = c0
                stk[n_stk, 1] = k
                n_stk += 1
            c0 = k + 1
    # chord split (depth first; the pieces are sorted by start afterwards)
    m = 0
    while n_stk:
        n_stk -= 1
        s = stk[n_stk, 0]
        e = stk[n_stk, 1]
        xs = pt[X, sub[s]]
        ys = pt[Y, sub[s]]
        ex = pt[X, sub[e]] - xs
        ey = pt[Y, sub[e]] - ys
        norm = np.hypot(ex, ey)
        if not norm > 0.0:
            norm = 1.0
        seg_max = -np.inf
        first = s
        for k in range(s, e + 1):
            p = sub[k]
            dist = abs((pt[X, p] - xs) * ey - (pt[Y, p] - ys) * ex) / norm
            score = dist / _thr(pt, p, fp)
            if score > seg_max:
                seg_max = score
                first = k
        if seg_max > 1.0 and e - s >= 2:
            stk[n_stk, 0] = first
            stk[n_stk, 1] = e
            stk[n_stk + 1, 0] = s
            stk[n_stk + 1, 1] = first
            n_stk += 2
        else:
            starts[m] = s
            ends[m] = e
            m += 1
    o = np.argsort(starts[:m])
    tmp_s = starts[:m][o]
    tmp_e = ends[:m][o]
    starts[:m] = tmp_s
    ends[:m] = tmp_e
    # merge neighbouring pieces of one cluster while the union stays a line
    while m >= 2:
        any_ok = False
        for a in range(m - 1):
            flag[a] = 0
            if ends[a] == starts[a + 1]:
                score, _ = _tls_max_score(pt, sub, starts[a], ends[a + 1], fp)
                if score <= 1.0:
                    flag[a] = 1
                    any_ok = True
        if not any_ok:
            break
        last = -2
        w = 0
        a = 0
        while a < m:
            if a < m - 1 and flag[a] == 1 and a > last + 1:
                last = a
                starts[w] = starts[a]
                ends[w] = ends[a + 1]
                w += 1
                a += 2
            else:
                starts[w] = starts[a]
                ends[w] = ends[a]
                w += 1
                a += 1
        m = w
    # corners shared by two pieces go to the piece whose line they are on
    for a in range(m - 1):
        flag[a] = 0
        if (
            ends[a] == starts[a + 1]
            and ends[a] - starts[a] >= 2
            and ends[a + 1] - starts[a + 1] >= 2
        ):
            k = ends[a]
            p = sub[k]
            mx, my, al = _tls(pt, sub, starts[a], k - 1)
            dl = abs((pt[X, p] - mx) * np.cos(al) + (pt[Y, p] - my) * np.sin(al))
            mx, my, al = _tls(pt, sub, k + 1, ends[a + 1])
            dr = abs((pt[X, p] - mx) * np.cos(al) + (pt[Y, p] - my) * np.sin(al))
            flag[a] = 1 if dl <= dr else 2
    for a in range(m - 1):
        if flag[a] == 1:
            starts[a + 1] += 1
        elif flag[a] == 2:
            ends[a] -= 1
    # pieces with enough points, and their angles
    w = 0
    for a in range(m):
        if ends[a] - starts[a] + 1 >= ip[I_MINSEG]:
            starts[w] = starts[a]
            ends[w] = ends[a]
            _, alphas[w] = _tls_max_score(pt, sub, starts[a], ends[a], fp)
            w += 1
    return w


# --------------------------------------------------------------------------------------------
# Hough grouping of one scan (linefit.hough.hough_groups)
# --------------------------------------------------------------------------------------------
#: Largest dense Hough accumulator (cells, int32) of a scan: beyond it :func:`extract_kernel`
#: counts that scan's votes by sorting (same result); read at each call (tests lower it).
DENSE_CELLS = 1 << 22


@jit
def _hough_rows(x32, y32, n, c32, s32, half, n_rho, row_off, row_key):
    """Distance-bin window of every angle row; returns the number of dense cells needed.

    Row ``j`` of the dense accumulator holds the bins ``[lo_j, hi_j]`` (a bound from the
    points' bounding box, widened beyond any float32 rounding); a vote for bin ``b`` of row
    ``j`` goes to cell ``b + row_off[j]``, whose argmax key ``j · n_ℛ + (b + half)`` is the cell
    number ``+ row_key[j]``.
    """
    xmin = np.inf
    xmax = -np.inf
    ymin = np.inf
    ymax = -np.inf
    for p in range(n):
        xv = np.float64(x32[p])
        yv = np.float64(y32[p])
        xmin = min(xmin, xv)
        xmax = max(xmax, xv)
        ymin = min(ymin, yv)
        ymax = max(ymax, yv)
    total = 0
    for j in range(c32.shape[0]):
        c = np.float64(c32[j])
        s = np.float64(s32[j])
        a = c * xmin
        b = c * xmax
        lo = min(a, b)
        hi = max(a, b)
        a = s * ymin
        b = s * ymax
        lo += min(a, b)
        hi += max(a, b)
        margin = 2.0 + (abs(lo) + abs(hi)) * 1e-6
        b_lo = int(np.floor(lo - margin))
        b_hi = int(np.floor(hi + margin))
        row_off[j] = total - b_lo
        row_key[j] = j * n_rho + half - row_off[j]
        total += b_hi - b_lo + 1
    return total


@jit
def _hough_votes_dense(x32, y32, n, c32, s32, row_off, n_acc, acc, vote):
    """Clear ``acc[:n_acc]``; ``vote[p, j]`` receives the cell of point ``p`` in angle row ``j``."""
    n_beta = c32.shape[0]
    for f in range(n_acc):
        acc[f] = 0
    for p in range(n):
        xp = x32[p]
        yp = y32[p]
        for j in range(n_beta):
            # float32 as linefit.hough.hough_accumulator: products rounded, then their sum
            v = c32[j] * xp
            v = v + s32[j] * yp
            vote[p, j] = np.int32(np.floor(v)) + row_off[j]


@jit
def _hough_count(vote, n, n_beta, min_votes, row_key, acc, cidx, ckey):
    """Count the votes of ``vote[:n]`` into ``acc``; list the cells reaching ``min_votes``."""
    n_cells = 0
    for p in range(n):
        for j in range(n_beta):
            f = vote[p, j]
            v = acc[f] + 1
            acc[f] = v
            if v == min_votes:
                cidx[n_cells] = f
                ckey[n_cells] = f + row_key[j]
                n_cells += 1
    return n_cells


@jit
def _hough_votes_sorted(x32, y32, n, c32, s32, half, n_rho, min_votes, vote):
    """Sparse form of the votes for an accumulator too large to hold densely.

    The cells (keys ``j · n_ℛ + i``) are counted by sorting; ``vote[p, j]`` receives the index
    of its cell in the returned counts when that cell has ``min_votes`` votes, else the index
    of a spare slot that is never a cell.  Returns ``(counts, cidx, ckey, n_cells)``.
    """
    n_beta = c32.shape[0]
    keys = np.empty(n * n_beta, dtype=np.int64)
    for p in range(n):
        xp = x32[p]
        yp = y32[p]
        for j in range(n_beta):
            v = c32[j] * xp
            v = v + s32[j] * yp
            keys[p * n_beta + j] = j * np.int64(n_rho) + (np.int64(np.floor(v)) + half)
    order = np.argsort(keys, kind="mergesort")
    slot = np.empty(n * n_beta, dtype=np.int64)
    counts = np.zeros(n * n_beta // max(1, min_votes) + 2, dtype=np.int32)
    cidx = np.empty(counts.shape[0], dtype=np.int64)
    ckey = np.empty(counts.shape[0], dtype=np.int64)
    n_cells = 0
    a = 0
    m = n * n_beta
    while a < m:
        b = a
        while b + 1 < m and keys[order[b + 1]] == keys[order[a]]:
            b += 1
        size = b - a + 1
        if size >= min_votes:
            counts[n_cells] = size
            cidx[n_cells] = n_cells
            ckey[n_cells] = keys[order[a]]
            for t in range(a, b + 1):
                slot[order[t]] = n_cells
            n_cells += 1
        else:
            for t in range(a, b + 1):
                slot[order[t]] = -1
        a = b + 1
    spare = n_cells
    for p in range(n):
        for j in range(n_beta):
            s = slot[p * n_beta + j]
            vote[p, j] = s if s >= 0 else spare
    return counts, cidx, ckey, n_cells


@jit
def _hough(
    pt,
    n,
    ip,
    fp,
    cos_b,
    sin_b,
    c32,
    s32,
    x32,
    y32,
    vote,
    row_off,
    row_key,
    acc,
    cidx,
    ckey,
    alive,
    alist,
    grp,
    gm,
    gs,
    ga,
):
    """Hough candidates of the ``n`` points of a scan.

    Group ``g`` is ``gm[gs[g] : gs[g + 1]]`` (point indices, ascending) with start angle
    ``ga[g]``; returns the number of groups.

    The votes are counted in a dense accumulator holding, for each angle row, the window of
    distance bins the scan's points can reach (or, for an accumulator too large, by sorting);
    ``vote[p, j]`` is the accumulator cell of point ``p`` in row ``j``, so removing a group
    subtracts its votes directly.  Only the cells that ever hold ``hough_min_votes`` votes can
    be peaks (votes only decrease): they are listed, and each peak is the one with the most
    votes, then the first in (angle, distance) order, i.e. ``argmax`` over the dense
    ``(β, ℛ)`` accumulator of :mod:`linefit.hough`.  The list drops the cells that fall below
    ``hough_min_votes``.
    """
    n_beta = cos_b.shape[0]
    step = fp[F_RSTEP]
    gather = fp[F_GATHER]
    min_votes = ip[I_MINVOTES]
    d2max = 0.0
    for p in range(n):
        d2 = pt[X, p] * pt[X, p] + pt[Y, p] * pt[Y, p]
        if d2 > d2max:
            d2max = d2
    half = int(np.ceil(np.sqrt(d2max) / step)) + 1
    n_rho = 2 * half
    for p in range(n):
        x32[p] = np.float32(pt[X, p])
        y32[p] = np.float32(pt[Y, p])
    n_acc = _hough_rows(x32, y32, n, c32, s32, half, n_rho, row_off, row_key)
    if n_acc <= acc.shape[0]:
        cnt = acc
        _hough_votes_dense(x32, y32, n, c32, s32, row_off, n_acc, acc, vote)
        n_cells = _hough_count(vote, n, n_beta, min_votes, row_key, acc, cidx, ckey)
        cells = cidx
        keys = ckey
    else:
        cnt, cells, keys, n_cells = _hough_votes_sorted(
            x32, y32, n, c32, s32, half, n_rho, min_votes, vote
        )
    n_alive = n
    for p in range(n):
        alive[p] = True
        alist[p] = p
    tol_peak = max(gather, step)
    n_groups = 0
    gs[0] = 0
    for _ in range(ip[I_MAXPEAKS]):
        # the peak: most votes, then the smallest key; cells below min_votes leave the list
        best = -1
        best_v = 0
        best_k = 0
        w = 0
        for c in range(n_cells):
            f = cells[c]
            v = cnt[f]
            if v < min_votes:
                continue
            k = keys[c]
            cells[w] = f
            keys[w] = k
            if v > best_v or (v == best_v and k < best_k):
                best = f
                best_v = v
                best_k = k
            w += 1
        n_cells = w
        if best < 0:
            break
        j = best_k // n_rho
        rho_c = (best_k - j * n_rho - half + 0.5) * step
        for q in range(n_alive):
            p = alist[q]
            rho = pt[X, p] * cos_b[j] + pt[Y, p] * sin_b[j]
            grp[p] = abs(rho - rho_c) <= tol_peak
        alpha = 0.0
        for _ in range(2):
            m0 = 0.0
            m1 = 0.0
            m2 = 0.0
            m3 = 0.0
            m4 = 0.0
            m5 = 0.0
            for q in range(n_alive):
                p = alist[q]
                if grp[p]:
                    x = pt[X, p]
                    y = pt[Y, p]
                    m0 += 1.0
                    m1 += x
                    m2 += y
                    m3 += x * x
                    m4 += x * y
                    m5 += y * y
            cnt_g = max(m0, 1.0)
            mx = m1 / cnt_g
            my = m2 / cnt_g
            cxx = m3 - cnt_g * mx * mx
            cxy = m4 - cnt_g * mx * my
            cyy = m5 - cnt_g * my * my
            alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
            ca = np.cos(alpha)
            sa = np.sin(alpha)
            off = mx * ca + my * sa
            for q in range(n_alive):
                p = alist[q]
                dist = abs(pt[X, p] * ca + pt[Y, p] * sa - off)
                grp[p] = dist <= gather
        count = 0
        for q in range(n_alive):
            if grp[alist[q]]:
                count += 1
        if count < min_votes:
            cnt[best] = SUPPRESSED
            continue
        # record (points ascending: alist stays sorted) and remove the group's votes
        o = gs[n_groups]
        w = 0
        for q in range(n_alive):
            p = alist[q]
            if grp[p]:
                gm[o] = p
                o += 1
                alive[p] = False
                for jj in range(n_beta):
                    cnt[vote[p, jj]] -= 1
            else:
                alist[w] = p
                w += 1
        n_alive = w
        ga[n_groups] = alpha
        n_groups += 1
        gs[n_groups] = o
    return n_groups


# --------------------------------------------------------------------------------------------
# sets of candidates, collinear merge, one scan
# --------------------------------------------------------------------------------------------
@jit
def _refine_set(pt, beam, gm, gs, ga, n_g, ip, fp, ws, st, ordr, n_ord):
    """Refine the candidates ``g < n_g`` into new line slots; append the survivors to ``ordr``.

    ``st`` holds the counters ``[n_slots, top]``.  The survivors are appended in the order
    the numpy path leaves its lines in (:func:`linefit.refine.refine`: after each round of
    rejections the lines that were refitted move behind the others, and again after the
    segment step), which decides the start angle of a collinear merge.  Returns the new
    length of ``ordr``.
    """
    wk, iw, res, lr, lcov, lm, ar, ai, nref, segch, okf, tmpo, ao = ws
    first = st[0]
    for g in range(n_g):
        li = st[0]
        st[0] += 1
        a = gs[g]
        b = gs[g + 1]
        status, nr, sc, top = _refine_line(
            pt, beam, gm, a, b - a, ga[g], ip, fp, wk, iw, res, lr, lcov, lm, li, ar, ai, ao, st[1]
        )
        st[1] = top
        okf[li] = status
        nref[li] = nr
        segch[li] = 1 if sc else 0
    m = 0
    for li in range(first, st[0]):
        if okf[li] == 1:
            tmpo[m] = li
            m += 1
    for rnd in range(ip[I_MAXREF] + 1):
        w = n_ord
        for k in range(m):
            if nref[tmpo[k]] <= rnd:
                ordr[w] = tmpo[k]
                w += 1
        for k in range(m):
            if nref[tmpo[k]] > rnd:
                ordr[w] = tmpo[k]
                w += 1
        for k in range(m):
            tmpo[k] = ordr[n_ord + k]
    w = n_ord
    for k in range(m):
        if segch[tmpo[k]] == 0:
            ordr[w] = tmpo[k]
            w += 1
    for k in range(m):
        if segch[tmpo[k]] == 1:
            ordr[w] = tmpo[k]
            w += 1
    return n_ord + m


@jit
def _normal(r, alpha):
    """Normal form of a signed line: ``(|r|, α or α + π wrapped, flipped)``."""
    if r < 0.0:
        return -r, _wrap(alpha + np.pi), True
    return r, _wrap(alpha), False


@jit
def _merge_collinear(pt, beam, n, ip, fp, ws, st, ordr, n_ord, parent, mark, gm, gs, ga, tmp_ord):
    """Join collinear lines of the scan (:func:`linefit.collinear.merge_collinear`).

    Returns the new length of ``ordr`` (the lines not joined in their order, then the joined
    ones, refitted).
    """
    lr, lcov, lm, ai = ws[3], ws[4], ws[5], ws[7]
    G = n_ord
    if G < 2:
        return n_ord
    for a in range(G):
        parent[a] = a
    any_pair = False
    chi2 = fp[F_MERGE_CHI2]
    for a in range(G):
        la = ordr[a]
        rn_a, an_a, fl_a = _normal(lr[la, 0], lr[la, 1])
        pra_a = -lcov[la, 0, 1] if fl_a else lcov[la, 0, 1]
        for b in range(a + 1, G):
            lb = ordr[b]
            rn_b, an_b, fl_b = _normal(lr[lb, 0], lr[lb, 1])
            pra_b = -lcov[lb, 0, 1] if fl_b else lcov[lb, 0, 1]
            dr = rn_a - rn_b
            da = _wrap(an_a - an_b)
            s00 = lcov[la, 0, 0] + lcov[lb, 0, 0]
            s11 = lcov[la, 1, 1] + lcov[lb, 1, 1]
            s01 = pra_a + pra_b
            det = s00 * s11 - s01 * s01
            d2 = (s11 * dr * dr - 2.0 * s01 * dr * da + s00 * da * da) / det
            if d2 <= chi2:
                any_pair = True
                ra = a
                while parent[ra] != ra:
                    ra = parent[ra]
                rb = b
                while parent[rb] != rb:
                    rb = parent[rb]
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    if not any_pair:
        return n_ord
    for a in range(G):
        r = a
        while parent[r] != r:
            r = parent[r]
        parent[a] = r
    # the joined sets, by their first line; members deduplicated and sorted
    n_g = 0
    gs[0] = 0
    for root in range(G):
        if parent[root] != root:
            continue
        size = 0
        for a in range(root, G):
            if parent[a] == root:
                size += 1
        if size < 2:
            continue
        for a in range(root, G):
            if parent[a] == root:
                li = ordr[a]
                for k in range(lm[li, 0], lm[li, 0] + lm[li, 1]):
                    mark[ai[k]] = 1
        o = gs[n_g]
        for p in range(n):
            if mark[p] == 1:
                gm[o] = p
                o += 1
                mark[p] = 0
        ga[n_g] = lr[ordr[root], 1]
        n_g += 1
        gs[n_g] = o
    # the lines not joined keep their order; the joined ones follow
    w = 0
    for a in range(G):
        size = 0
        for b in range(G):
            if parent[b] == parent[a]:
                size += 1
        if size == 1:
            tmp_ord[w] = ordr[a]
            w += 1
    for a in range(w):
        ordr[a] = tmp_ord[a]
    return _refine_set(pt, beam, gm, gs, ga, n_g, ip, fp, ws, st, ordr, w)


@jit
def _scan_lines(pt, beam, n, ip, fp, ws, hs, ss, st, ordr):
    """Steps 3-6 of the pipeline for one scan; returns the number of lines in ``ordr``."""
    cos_b, sin_b, c32, s32, x32, y32, vote, row_off, row_key, acc, cidx, ckey = hs[:12]
    alive, alist, grp = hs[12:]
    gm, gs, ga, sub, starts, ends, alphas, stk, flag, parent, mark, tmp_ord = ss
    st[0] = 0
    st[1] = 0
    n_ord = 0
    if ip[I_HOUGH] != 0:
        n_g = _hough(
            pt,
            n,
            ip,
            fp,
            cos_b,
            sin_b,
            c32,
            s32,
            x32,
            y32,
            vote,
            row_off,
            row_key,
            acc,
            cidx,
            ckey,
            alive,
            alist,
            grp,
            gm,
            gs,
            ga,
        )
        n_ord = _refine_set(pt, beam, gm, gs, ga, n_g, ip, fp, ws, st, ordr, n_ord)
        if ip[I_RECOVER] != 0:
            lm, ai = ws[5], ws[7]
            for p in range(n):
                mark[p] = 0
            for k in range(n_ord):
                li = ordr[k]
                for t in range(lm[li, 0], lm[li, 0] + lm[li, 1]):
                    mark[ai[t]] = 1
            m = 0
            for p in range(n):
                if mark[p] == 0:
                    sub[m] = p
                    m += 1
                mark[p] = 0
            n_g = _split_merge(pt, beam, sub, m, ip, fp, starts, ends, alphas, stk, flag)
            n_ord = _refine_pieces(
                pt, beam, sub, starts, ends, alphas, n_g, ip, fp, ws, st, ordr, n_ord, gm, gs, ga
            )
    else:
        for p in range(n):
            sub[p] = p
        n_g = _split_merge(pt, beam, sub, n, ip, fp, starts, ends, alphas, stk, flag)
        n_ord = _refine_pieces(
            pt, beam, sub, starts, ends, alphas, n_g, ip, fp, ws, st, ordr, n_ord, gm, gs, ga
        )
    if ip[I_MERGE] != 0:
        n_ord = _merge_collinear(
            pt, beam, n, ip, fp, ws, st, ordr, n_ord, parent, mark, gm, gs, ga, tmp_ord
        )
    return n_ord


@jit
def _refine_pieces(
    pt, beam, sub, starts, ends, alphas, n_g, ip, fp, ws, st, ordr, n_ord, gm, gs, ga
):
    """:func:`_refine_set` of split-and-merge pieces ``sub[starts[g] .. ends[g]]``."""
    o = 0
    gs[0] = 0
    for g in range(n_g):
        for k in range(starts[g], ends[g] + 1):
            gm[o] = sub[k]
            o += 1
        gs[g + 1] = o
        ga[g] = alphas[g]
    return _refine_set(pt, beam, gm, gs, ga, n_g, ip, fp, ws, st, ordr, n_ord)


# --------------------------------------------------------------------------------------------
# output (linefit.assemble.lines_from_fit) and the batch driver
# --------------------------------------------------------------------------------------------
@jit
def _grow(a, need):
    """``a`` with at least ``need`` rows (doubling), the old rows copied."""
    if a.shape[0] >= need:
        return a
    cap = max(need, 2 * a.shape[0])
    shape = (cap,) + a.shape[1:]
    b = np.empty(shape, dtype=a.dtype)
    b[: a.shape[0]] = a
    return b


@jit
def extract_kernel(pt, beam, scan_start, ip, fp, cos_b, sin_b, c32, s32, dense_cells):
    """Lines of every scan of a batch (steps 3-7 of :func:`linefit.extract_lines`).

    Parameters
    ----------
    pt : ndarray, shape (9, n_points)
        The valid points of all scans (scan by scan, in beam order), rows ``x, y, q11, q12,
        q22, σ_d², d²σ_φ², d(σ_d²)/dd, σ_d`` (:func:`linefit.readings.scan_points`) and
        ``hypot(x, y)``, ``arctan2(y, x)`` (as :func:`linefit.segments.breakpoint_mask`).
    beam : ndarray of int, shape (n_points,)
        Beam index of each point.
    scan_start : ndarray of int, shape (n_scans + 1,)
        Scan ``k``'s points are ``scan_start[k] : scan_start[k + 1]``.
    ip, fp : ndarray
        Integer and float parameters (:data:`IPARAMS`, :data:`FPARAMS`).
    cos_b, sin_b : ndarray
        ``cos β_j``, ``sin β_j`` of the Hough angle bins.
    c32, s32 : ndarray of float32
        ``cos β_j / Δℛ`` and ``sin β_j / Δℛ`` rounded to float32.
    dense_cells : int
        Largest dense Hough accumulator (:data:`DENSE_CELLS`).

    Returns
    -------
    tuple of ndarray
        Per line (in output order: by scan, then first beam): scan, ``(r, α, s)`` in normal
        form, covariance ``(3, 3)``, first segment and number of segments, first index and
        number of points; per segment: ``(s_start, s_end)`` and their variances; per point of
        a line: its beam index.
    """
    n_scans = scan_start.shape[0] - 1
    nmax = 1
    d2max = 0.0
    for k in range(n_scans):
        nmax = max(nmax, scan_start[k + 1] - scan_start[k])
    for p in range(pt.shape[1]):
        d2max = max(d2max, pt[X, p] * pt[X, p] + pt[Y, p] * pt[Y, p])
    n_beta = cos_b.shape[0]
    n_rho = 2 * (int(np.ceil(np.sqrt(d2max) / fp[F_RSTEP])) + 2)
    max_peaks = ip[I_MAXPEAKS]
    capl = max_peaks + 2 * nmax + 16
    capm = 4 * nmax + 64
    # per-line scratch, line slots and the member arena of one scan: a line slot li has its
    # fit in lr[li], its covariance in lcov[li], and in lm[li] the start of its members in the
    # arena, their number and the number of its segments; ao holds, per stored member, the
    # member order by u_S and the segment numbers (as iw[R_ORDER], iw[R_SEG])
    wk = np.empty((10, nmax))
    iw = np.empty((5, nmax), dtype=np.int64)
    res = np.empty(3)
    lr = np.empty((capl, 3))
    lcov = np.empty((capl, 3, 3))
    lm = np.empty((capl, 3), dtype=np.int64)
    ar = np.empty((3, capm))
    ai = np.empty(capm, dtype=np.int64)
    nref = np.empty(capl, dtype=np.int64)
    segch = np.empty(capl, dtype=np.int64)
    okf = np.empty(capl, dtype=np.int64)
    tmpo = np.empty(capl, dtype=np.int64)
    ao = np.empty((2, capm), dtype=np.int64)
    ws = (wk, iw, res, lr, lcov, lm, ar, ai, nref, segch, okf, tmpo, ao)
    # Hough scratch: the dense accumulator holds every row's window of distance bins (at most
    # 2·sqrt(2)·ℛ_max/Δℛ + 10 per row, see _hough_rows); beyond dense_cells a scan's votes are
    # counted by sorting instead
    vote = np.empty((nmax, n_beta), dtype=np.int32)
    row_off = np.empty(n_beta, dtype=np.int64)
    row_key = np.empty(n_beta, dtype=np.int64)
    acc = np.empty(max(0, min(n_beta * (3 * (n_rho // 2) + 16), dense_cells)), dtype=np.int32)
    # a listed cell has at least hough_min_votes points of its angle row: at most n / min_votes
    # per row
    cap_cells = n_beta * (nmax // max(1, ip[I_MINVOTES]) + 1) + 1
    cidx = np.empty(cap_cells, dtype=np.int64)
    ckey = np.empty(cap_cells, dtype=np.int64)
    alive = np.empty(nmax, dtype=np.bool_)
    alist = np.empty(nmax, dtype=np.int64)
    grp = np.empty(nmax, dtype=np.bool_)
    x32 = np.empty(nmax, dtype=np.float32)
    y32 = np.empty(nmax, dtype=np.float32)
    hs = (
        cos_b,
        sin_b,
        c32,
        s32,
        x32,
        y32,
        vote,
        row_off,
        row_key,
        acc,
        cidx,
        ckey,
        alive,
        alist,
        grp,
    )
    # grouping and merge scratch
    gm = np.empty(capm, dtype=np.int64)
    gs = np.empty(capl + 1, dtype=np.int64)
    ga = np.empty(capl)
    sub = np.empty(nmax, dtype=np.int64)
    starts = np.empty(nmax, dtype=np.int64)
    ends = np.empty(nmax, dtype=np.int64)
    alphas = np.empty(nmax)
    stk = np.empty((2 * nmax + 2, 2), dtype=np.int64)
    flag = np.empty(nmax, dtype=np.int64)
    parent = np.empty(capl, dtype=np.int64)
    mark = np.zeros(nmax, dtype=np.int64)
    tmp_ord = np.empty(capl, dtype=np.int64)
    ss = (gm, gs, ga, sub, starts, ends, alphas, stk, flag, parent, mark, tmp_ord)
    st = np.zeros(2, dtype=np.int64)
    ordr = np.empty(capl, dtype=np.int64)
    # output, grown as needed
    o_scan = np.empty(16 * n_scans + 16, dtype=np.int64)
    o_ras = np.empty((o_scan.shape[0], 3))
    o_cov = np.empty((o_scan.shape[0], 3, 3))
    o_lin = np.empty((o_scan.shape[0], 4), dtype=np.int64)
    o_seg = np.empty((o_scan.shape[0], 4))
    o_idx = np.empty(pt.shape[1] + 16, dtype=np.int64)
    n_out = 0
    n_oseg = 0
    n_oidx = 0
    # per-line output scratch
    fb = np.empty(capl, dtype=np.int64)
    keep = np.empty(capl, dtype=np.int64)
    for k in range(n_scans):
        a = scan_start[k]
        b = scan_start[k + 1]
        n = b - a
        if n == 0:
            continue
        pts = pt[:, a:b]
        bm = beam[a:b]
        n_ord = _scan_lines(pts, bm, n, ip, fp, ws, hs, ss, st, ordr)
        # which lines are kept, and their first beams
        n_keep = 0
        for q in range(n_ord):
            li = ordr[q]
            t = lm[li, 0]
            L = lm[li, 1]
            finite = True
            for u in range(3):
                for v in range(3):
                    if not np.isfinite(lcov[li, u, v]):
                        finite = False
            n_seg = lm[li, 2]
            length = 0.0
            q0 = 0
            for g in range(n_seg):
                q1 = q0
                while q1 + 1 < L and ao[1, t + q1 + 1] == g:
                    q1 += 1
                length += ar[A_US, t + ao[0, t + q1]] - ar[A_US, t + ao[0, t + q0]]
                q0 = q1 + 1
            if ip[I_MINPTS] <= L and length >= fp[F_MIN_LEN] and finite:
                first_beam = bm[ai[t]]
                for u in range(t, t + L):
                    first_beam = min(first_beam, bm[ai[u]])
                keep[n_keep] = li
                fb[n_keep] = first_beam
                n_keep += 1
        if n_keep == 0:
            continue
        srt = np.argsort(fb[:n_keep], kind="mergesort")
        o_scan = _grow(o_scan, n_out + n_keep)
        o_ras = _grow(o_ras, n_out + n_keep)
        o_cov = _grow(o_cov, n_out + n_keep)
        o_lin = _grow(o_lin, n_out + n_keep)
        for q in range(n_keep):
            li = keep[srt[q]]
            t = lm[li, 0]
            L = lm[li, 1]
            r_n, a_n, flip = _normal(lr[li, 0], lr[li, 1])
            o_scan[n_out] = k
            o_ras[n_out, 0] = r_n
            o_ras[n_out, 1] = a_n
            o_ras[n_out, 2] = -lr[li, 2] if flip else lr[li, 2]
            for u in range(3):
                for v in range(3):
                    sgn = -1.0 if flip and (u == 2 or u == 0) != (v == 2 or v == 0) else 1.0
                    o_cov[n_out, u, v] = lcov[li, u, v] * sgn
            # segments: ends of each run of the members sorted by u_S
            n_seg = lm[li, 2]
            o_seg = _grow(o_seg, n_oseg + n_seg)
            o_lin[n_out, 0] = n_oseg
            o_lin[n_out, 1] = n_seg
            q0 = 0
            for g in range(n_seg):
                q1 = q0
                while q1 + 1 < L and ao[1, t + q1 + 1] == g:
                    q1 += 1
                m0 = t + ao[0, t + q0]
                m1 = t + ao[0, t + q1]
                row = n_oseg + (n_seg - 1 - g if flip else g)
                if flip:
                    o_seg[row, 0] = -ar[A_US, m1]
                    o_seg[row, 1] = -ar[A_US, m0]
                    o_seg[row, 2] = ar[A_EV, m1]
                    o_seg[row, 3] = ar[A_EV, m0]
                else:
                    o_seg[row, 0] = ar[A_US, m0]
                    o_seg[row, 1] = ar[A_US, m1]
                    o_seg[row, 2] = ar[A_EV, m0]
                    o_seg[row, 3] = ar[A_EV, m1]
                q0 = q1 + 1
            n_oseg += n_seg
            # beam indices, sorted (the members are in point order already, as a rule)
            o_idx = _grow(o_idx, n_oidx + L)
            ascending = True
            for u in range(L):
                o_idx[n_oidx + u] = bm[ai[t + u]]
                if u > 0 and o_idx[n_oidx + u] < o_idx[n_oidx + u - 1]:
                    ascending = False
            if not ascending:
                o_idx[n_oidx : n_oidx + L] = np.sort(o_idx[n_oidx : n_oidx + L])
            o_lin[n_out, 2] = n_oidx
            o_lin[n_out, 3] = L
            n_oidx += L
            n_out += 1
    return (
        o_scan[:n_out],
        o_ras[:n_out],
        o_cov[:n_out],
        o_lin[:n_out],
        o_seg[:n_oseg],
        o_idx[:n_oidx],
    )


@functools.lru_cache(maxsize=32)
def kernel_params(
    cfg: LineFitConfig,
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, NDArray[np.float32], NDArray[np.float32]]:
    """The parameter vectors and Hough bin tables of :func:`extract_kernel` for ``cfg``."""
    ints = {
        "max_iterations": cfg.max_iterations,
        "min_points": cfg.min_points,
        "max_refits": cfg.max_refits,
        "min_segment_points": cfg.min_segment_points,
        "max_missing_beams": cfg.max_missing_beams,
        "hough_min_votes": cfg.hough_min_votes,
        "hough_max_peaks": cfg.hough_max_peaks,
        "hough": int(cfg.grouping == "hough"),
        "hough_recover": int(cfg.hough_recover),
        "merge_collinear": int(cfg.merge_collinear),
        "weighted": int(cfg.weighted),
        "prop2": int(cfg.alpha_update == "prop2"),
        "beam_model": int(cfg.noise.bearing_error == "beam"),
    }
    ip = np.array([ints[name] for name in IPARAMS], dtype=np.int64)
    fp = np.array([float(getattr(cfg, name)) for name in FPARAMS], dtype=float)
    # the Hough angle bins and float32 vote coefficients of linefit.hough.hough_accumulator
    n_beta = max(1, round(np.pi / cfg.hough_angle_step_rad))
    betas = np.arange(n_beta, dtype=float) * (np.pi / n_beta)
    inv = 1.0 / cfg.hough_range_step_m
    c32 = (np.cos(betas) * inv).astype(np.float32)
    s32 = (np.sin(betas) * inv).astype(np.float32)
    return ip, fp, np.cos(betas), np.sin(betas), c32, s32
