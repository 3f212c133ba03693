"""The public entry points: :func:`extract_lines` for a scan, :func:`fit_line` and
:func:`fit_scan_line` for a given set of points.

Pipeline of :func:`extract_lines`
---------------------------------
1. Readings that are not measurements of a surface (NaN, ±inf, ``≤ 0``, ``≥`` max range) are
   dropped; they never enter a fit.
2. Eq. 8 covariances of the remaining points (:mod:`linefit.noise`).
3. Grouping into candidate lines: Hough transform (:mod:`linefit.hough`) or split-and-merge
   (:mod:`linefit.split_merge`).
4. For all candidates at once (:mod:`linefit.fit`): the ML fit, then each point's normal
   residual is tested against its own covariance (``δ_R²/P_R > outlier_chi2``: rejected; in
   each round only points within a factor 4 of their line's worst are rejected, so one bad
   point cannot mask the others), each line is cut into segments at gaps and range jumps and
   pieces with fewer than ``min_segment_points`` points are dropped
   (:mod:`linefit.segments`); refit until nothing changes (at most ``max_refits`` rounds).
5. Optionally (``merge_collinear``) lines whose ``(r, α)`` pass a χ² test are joined into one
   line with several segments and refitted.
6. Lines with fewer than ``min_points`` points or shorter than ``min_length_m`` are dropped;
   covariances (:mod:`linefit.covariance`) and segment ends; normal form; sorted by their
   first beam index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.config import LineFitConfig
from linefit.covariance import LineCovariances, line_covariances
from linefit.errors import DegenerateGeometryError, InputError
from linefit.fit import GroupFit, PointSet, fit_groups, nearest_representative, tls_groups
from linefit.grouping import Grouping
from linefit.hough import hough_groups
from linefit.line import Line, wrap_angle
from linefit.noise import SigmaRangeFn, point_covariance_entries, range_sigma
from linefit.segments import segment_ids
from linefit.split_merge import split_merge_groups

__all__ = ["extract_lines", "fit_line", "fit_scan_line", "scan_points"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


# ---------------------------------------------------------------------------------------------
# input checks
# ---------------------------------------------------------------------------------------------
def _as_vector(values: ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be an array of numbers ({exc})") from exc
    if arr.ndim != 1:
        raise InputError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def _check_scan(ranges: ArrayLike, bearings: ArrayLike) -> tuple[FloatArray, FloatArray]:
    d = _as_vector(ranges, "ranges")
    phi = _as_vector(bearings, "bearings")
    if d.shape != phi.shape:
        raise InputError(f"ranges ({d.shape[0]}) and bearings ({phi.shape[0]}) differ in length")
    if not np.all(np.isfinite(phi)):
        raise InputError("bearings must be finite")
    if phi.shape[0] >= 2:
        step = np.diff(np.unwrap(phi))
        if not (np.all(step > 0.0) or np.all(step < 0.0)):
            raise InputError("bearings must be strictly increasing or strictly decreasing")
    return d, phi


def valid_readings(
    ranges: FloatArray, max_range_m: float | None, config: LineFitConfig
) -> NDArray[np.bool_]:
    """True for readings that are measurements of a surface (finite, > 0, < max range)."""
    limit = np.inf
    for value in (max_range_m, config.max_range_m):
        if value is not None:
            limit = min(limit, float(value))
    with np.errstate(invalid="ignore"):
        return np.isfinite(ranges) & (ranges > 0.0) & (ranges < limit)


def scan_points(
    ranges: FloatArray,
    bearings: FloatArray,
    beams: IntArray,
    config: LineFitConfig,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> PointSet:
    """Cartesian points of (valid) readings with their Eq. 8 covariances."""
    noise = config.noise
    q11, q12, q22 = point_covariance_entries(ranges, bearings, noise, sigma_range_fn)
    sigma = range_sigma(ranges, noise, sigma_range_fn)
    if sigma_range_fn is None:
        dvar = 2.0 * sigma * noise.sigma_range_per_m
    else:  # numerical derivative of the user's σ_d(d)²
        h = 1e-6 * np.maximum(ranges, 1.0)
        hi = range_sigma(ranges + h, noise, sigma_range_fn) ** 2
        lo = range_sigma(ranges - h, noise, sigma_range_fn) ** 2
        dvar = (hi - lo) / (2.0 * h)
    return PointSet(
        x=ranges * np.cos(bearings),
        y=ranges * np.sin(bearings),
        q11=q11,
        q12=q12,
        q22=q22,
        beam=beams,
        var_range=sigma * sigma,
        var_perp=(ranges * noise.sigma_bearing_rad) ** 2,
        dvar_range=dvar,
    )


# ---------------------------------------------------------------------------------------------
# batched fit / reject / segment loop
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Fitted:
    pidx: IntArray
    gidx: IntArray
    n_groups: int
    fit: GroupFit
    cov: LineCovariances
    order: IntArray
    seg: IntArray


def _compact(pidx: IntArray, gidx: IntArray, keep_group: NDArray[np.bool_]) -> tuple:
    """Drop groups (and their memberships) and renumber the rest 0..G'-1."""
    new_id = np.cumsum(keep_group) - 1
    keep = keep_group[gidx]
    return pidx[keep], new_id[gidx[keep]], int(keep_group.sum())


def _fit_batch(
    pts: PointSet, pidx: IntArray, gidx: IntArray, n_groups: int, alpha0: FloatArray, cfg
) -> GroupFit:
    return fit_groups(
        pts,
        pidx,
        gidx,
        n_groups,
        alpha0,
        weighted=cfg.weighted,
        max_iterations=cfg.max_iterations,
        tolerance_rad=cfg.alpha_tolerance_rad,
        alpha_step=cfg.alpha_update,
    )


def _leverage(fit: GroupFit, gidx: IntArray, G: int) -> FloatArray:
    """Leverage ``h_k`` of each membership in its line's weighted fit (capped below 1).

    ``var(δ_R,k) = P_R,k (1 − h_k)`` at the estimate, with
    ``h_k = w_k (1/W + (u_S,k − c)²/A)`` (notation of :mod:`linefit.covariance`).
    """
    w = fit.w_r
    W = np.bincount(gidx, weights=w, minlength=G)
    c = np.bincount(gidx, weights=w * fit.u_s, minlength=G) / W
    du = fit.u_s - c[gidx]
    A = np.bincount(gidx, weights=w * du * du, minlength=G)
    h = w * (1.0 / W[gidx] + du * du / A[gidx])
    return np.minimum(h, 0.95)


def _refine(pts: PointSet, sigma_range: FloatArray, grouping: Grouping, cfg: LineFitConfig):
    """Fit, reject, cut into segments and refit all candidate lines together."""
    pidx, gidx, G, alpha0 = grouping.pidx, grouping.gidx, grouping.n_groups, grouping.alpha0
    min_pts = max(2, cfg.min_points)
    for round_ in range(cfg.max_refits + 1):
        if G == 0:
            return None
        counts = np.bincount(gidx, minlength=G)
        keep_g = counts >= min_pts
        if not keep_g.all():
            alpha0 = alpha0[keep_g]
            pidx, gidx, G = _compact(pidx, gidx, keep_g)
            if G == 0:
                return None
        fit = _fit_batch(pts, pidx, gidx, G, alpha0, cfg)
        ok = fit.converged & np.isfinite(fit.r) & np.isfinite(fit.alpha)
        if not ok.all():
            alpha0 = fit.alpha[ok]
            pidx, gidx, G = _compact(pidx, gidx, ok)
            continue
        # per-point χ² gate on the normal residual, studentised by the point's leverage
        chi2 = (fit.u_r - fit.r[gidx]) ** 2 / (fit.p_r * (1.0 - _leverage(fit, gidx, G)))
        worst = np.zeros(G)
        np.maximum.at(worst, gidx, chi2)
        reject = (chi2 > cfg.outlier_chi2) & (chi2 >= 0.25 * worst[gidx])
        # segments of the surviving memberships; drop pieces that are too small
        keep = ~reject
        order, seg = segment_ids(
            pts.x[pidx[keep]],
            pts.y[pidx[keep]],
            pts.beam[pidx[keep]],
            sigma_range[pidx[keep]],
            gidx[keep],
            fit.u_s[keep],
            max_missing_beams=cfg.max_missing_beams,
            lambda_rad=cfg.breakpoint_lambda_rad,
            sigma_factor=cfg.breakpoint_sigma,
        )
        seg_size = np.bincount(seg)
        small = seg_size[seg] < cfg.min_segment_points
        if small.any():
            kept_idx = np.flatnonzero(keep)
            keep[kept_idx[order[small]]] = False
        last = round_ == cfg.max_refits
        if keep.all() or last:
            if not keep.all():
                pidx, gidx = pidx[keep], gidx[keep]
                counts = np.bincount(gidx, minlength=G)
                keep_g = counts >= min_pts
                alpha0 = fit.alpha[keep_g]
                pidx, gidx, G = _compact(pidx, gidx, keep_g)
                if G == 0:
                    return None
                fit = _fit_batch(pts, pidx, gidx, G, alpha0, cfg)
                order, seg = segment_ids(
                    pts.x[pidx],
                    pts.y[pidx],
                    pts.beam[pidx],
                    sigma_range[pidx],
                    gidx,
                    fit.u_s,
                    max_missing_beams=cfg.max_missing_beams,
                    lambda_rad=cfg.breakpoint_lambda_rad,
                    sigma_factor=cfg.breakpoint_sigma,
                )
            cov = line_covariances(fit, pts, pidx, gidx, G, cfg.noise.bearing_error)
            return _Fitted(pidx, gidx, G, fit, cov, order, seg)
        pidx, gidx = pidx[keep], gidx[keep]
        alpha0 = fit.alpha
    return None  # pragma: no cover - the loop always returns


def _merge_collinear(
    pts: PointSet, sigma_range: FloatArray, fitted: _Fitted, cfg: LineFitConfig
) -> _Fitted:
    """Join lines whose (r, α) pass the χ² test into multi-segment lines, then refit."""
    G = fitted.n_groups
    if G < 2:
        return fitted
    r, alpha = fitted.fit.r, fitted.fit.alpha
    flip = r < 0.0
    rn = np.abs(r)
    an = np.asarray(wrap_angle(np.where(flip, alpha + np.pi, alpha)))
    P = fitted.cov.cov[:, :2, :2].copy()
    P[flip, 0, 1] *= -1.0
    P[flip, 1, 0] *= -1.0
    i, j = np.triu_indices(G, 1)
    dr = rn[i] - rn[j]
    da = np.asarray(wrap_angle(an[i] - an[j]))
    S = P[i] + P[j]
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (S[:, 1, 1] * dr * dr - 2.0 * S[:, 0, 1] * dr * da + S[:, 0, 0] * da * da) / det
    cand = np.flatnonzero(d2 <= cfg.merge_chi2)
    if cand.shape[0] == 0:
        return fitted
    parent = list(range(G))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for k in cand[np.argsort(d2[cand], kind="stable")].tolist():
        a, b = find(int(i[k])), find(int(j[k]))
        if a != b:
            parent[max(a, b)] = min(a, b)
    roots = np.array([find(a) for a in range(G)])
    _, new_g = np.unique(roots, return_inverse=True)
    n_new = int(new_g.max()) + 1
    if n_new == G:
        return fitted
    gidx = new_g[fitted.gidx].astype(np.intp)
    # a point shared by two merged lines (a split-and-merge corner) counts once
    key = gidx.astype(np.int64) * (len(pts) + 1) + fitted.pidx
    _, first = np.unique(key, return_index=True)
    pidx = fitted.pidx[first]
    gidx = gidx[first]
    # representative angle: that of the first line of each merged set, as seen by all
    _, first_of_set = np.unique(new_g, return_index=True)
    alpha0 = alpha[first_of_set]
    refined = _refine(pts, sigma_range, Grouping(pidx, gidx, n_new, alpha0), cfg)
    return refined if refined is not None else fitted


# ---------------------------------------------------------------------------------------------
# Line objects
# ---------------------------------------------------------------------------------------------
def _lines_from_fit(pts: PointSet, fitted: _Fitted, cfg: LineFitConfig) -> list[Line]:
    fit, G = fitted.fit, fitted.n_groups
    order, seg = fitted.order, fitted.seg
    pidx, gidx = fitted.pidx, fitted.gidx
    g_sorted = gidx[order]
    n_seg = int(seg[-1]) + 1 if seg.shape[0] else 0
    seg_ids = np.arange(n_seg)
    first = np.searchsorted(seg, seg_ids, side="left")
    last = np.searchsorted(seg, seg_ids, side="right") - 1
    seg_group = g_sorted[first]
    s_start = fit.u_s[order[first]]
    s_end = fit.u_s[order[last]]
    v_start = fitted.cov.end_var[order[first]]
    v_end = fitted.cov.end_var[order[last]]
    length = np.bincount(seg_group, weights=s_end - s_start, minlength=G)
    counts = np.bincount(gidx, minlength=G)
    beams = pts.beam[pidx]
    first_beam = np.full(G, np.iinfo(np.intp).max)
    np.minimum.at(first_beam, gidx, beams)
    keep = (counts >= cfg.min_points) & (length >= cfg.min_length_m)
    keep &= np.all(np.isfinite(fitted.cov.cov.reshape(G, 9)), axis=1)
    seg_bounds = np.searchsorted(seg_group, np.arange(G + 1))  # segments are sorted by line
    mem_order = np.argsort(gidx, kind="stable")
    mem_bounds = np.searchsorted(gidx[mem_order], np.arange(G + 1))
    lines: list[Line] = []
    for g in np.flatnonzero(keep)[np.argsort(first_beam[keep], kind="stable")].tolist():
        rows = np.arange(seg_bounds[g], seg_bounds[g + 1])
        segs = np.stack([s_start[rows], s_end[rows]], axis=1)
        svar = np.stack([v_start[rows], v_end[rows]], axis=1)
        r, a, s = float(fit.r[g]), float(fit.alpha[g]), float(fit.s[g])
        cov = fitted.cov.cov[g].copy()
        if r < 0.0:
            r, a, s = -r, a + np.pi, -s
            flip = np.array([-1.0, 1.0, -1.0])
            cov = cov * np.outer(flip, flip)
            segs = -segs[::-1, ::-1]
            svar = svar[::-1, ::-1]
        idx = np.unique(beams[mem_order[mem_bounds[g] : mem_bounds[g + 1]]])
        lines.append(
            Line(
                r=r,
                alpha=float(wrap_angle(a)),
                s=s,
                cov=cov,
                segments_s=segs,
                segments_var=svar,
                n_points=int(idx.shape[0]),
                indices=idx,
            )
        )
    return lines


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------
def extract_lines(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    max_range_m: float | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> list[Line]:
    """Extract the weighted-fit lines of one range scan.

    Parameters
    ----------
    ranges
        Measured ranges ``d`` (m), shape ``(n,)``.  NaN, ±inf, zero, negative and max-range
        readings are allowed and ignored.
    bearings
        Beam angles ``φ`` (rad) in the sensor frame, shape ``(n,)``, finite and strictly
        monotonic (increasing or decreasing, possibly wrapping past ±π).
    config
        Extraction settings (default :class:`LineFitConfig`).
    max_range_m
        The scan's maximum range: readings at or above it are "no return" (CARMEN logs give
        it per scan).  Combined with ``config.max_range_m`` (the smaller applies).
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)`` replacing the configured range noise.

    Returns
    -------
    list of Line
        In normal form (``r ≥ 0``, ``α ∈ (−π, π]``), sorted by the first beam index of their
        supporting points.  Empty when the scan holds no line (e.g. all readings invalid or
        fewer than ``min_points`` valid readings).

    Raises
    ------
    InputError
        Mismatched or non-1-D arrays, non-numeric values, non-finite or non-monotonic
        bearings.

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.radians(np.arange(-30.0, 31.0))
    >>> d = 2.0 / np.cos(phi)            # a wall 2 m ahead, normal along x
    >>> [round(l.r, 3) for l in extract_lines(d, phi)]
    [2.0]
    """
    cfg = config if config is not None else LineFitConfig()
    if max_range_m is not None and not (max_range_m > 0.0):
        raise InputError(f"max_range_m must be positive, got {max_range_m!r}")
    d, phi = _check_scan(ranges, bearings)
    valid = valid_readings(d, max_range_m, cfg)
    beams = np.flatnonzero(valid)
    if beams.shape[0] < max(2, cfg.min_points):
        return []
    pts = scan_points(d[valid], phi[valid], beams, cfg, sigma_range_fn)
    sigma_range = np.sqrt(pts.var_range) if pts.var_range is not None else np.zeros(len(pts))
    if cfg.grouping == "hough":
        grouping = hough_groups(
            pts.x,
            pts.y,
            angle_step_rad=cfg.hough_angle_step_rad,
            range_step_m=cfg.hough_range_step_m,
            min_votes=cfg.hough_min_votes,
            gather_m=cfg.hough_gather_m,
            max_peaks=cfg.hough_max_peaks,
        )
    else:
        grouping = split_merge_groups(
            pts.x,
            pts.y,
            pts.beam,
            sigma_range,
            split_threshold_m=cfg.split_threshold_m,
            split_threshold_sigma=cfg.split_threshold_sigma,
            max_missing_beams=cfg.max_missing_beams,
            lambda_rad=cfg.breakpoint_lambda_rad,
            sigma_factor=cfg.breakpoint_sigma,
            min_points=cfg.min_segment_points,
        )
    fitted = _refine(pts, sigma_range, grouping, cfg)
    if fitted is None:
        return []
    if cfg.merge_collinear:
        fitted = _merge_collinear(pts, sigma_range, fitted, cfg)
    return _lines_from_fit(pts, fitted, cfg)


def _single_line(
    pts: PointSet, alpha0: float | None, weighted: bool, cfg: LineFitConfig, bearing_error: str
) -> Line:
    n = len(pts)
    pidx = np.arange(n, dtype=np.intp)
    gidx = np.zeros(n, dtype=np.intp)
    r_tls, a_tls, ratio = tls_groups(pts, pidx, gidx, 1)
    if not np.isfinite(ratio[0]) or ratio[0] > 0.5:
        raise DegenerateGeometryError(
            "the points do not determine a line (they coincide or are not elongated)"
        )
    start = a_tls if alpha0 is None else nearest_representative(a_tls, np.array([alpha0]))
    fit = fit_groups(
        pts,
        pidx,
        gidx,
        1,
        np.asarray(start, dtype=float),
        weighted=weighted,
        max_iterations=cfg.max_iterations,
        tolerance_rad=cfg.alpha_tolerance_rad,
        alpha_step=cfg.alpha_update,
    )
    if not (fit.converged[0] and np.isfinite(fit.alpha[0])):
        raise DegenerateGeometryError("the α iteration did not converge for these points")
    cov = line_covariances(fit, pts, pidx, gidx, 1, bearing_error)
    if not np.all(np.isfinite(cov.cov)):
        raise DegenerateGeometryError("the line covariance is not finite for these points")
    order = np.argsort(fit.u_s, kind="stable")
    seg = np.zeros(n, dtype=np.intp)
    fitted = _Fitted(pidx, gidx, 1, fit, cov, order, seg)
    relaxed = LineFitConfig(noise=cfg.noise, min_points=2, min_length_m=0.0)
    lines = _lines_from_fit(pts, fitted, relaxed)
    return lines[0]


def fit_line(
    points_xy: ArrayLike,
    covariances: ArrayLike,
    *,
    alpha0: float | None = None,
    weighted: bool = True,
    config: LineFitConfig | None = None,
) -> Line:
    """Fit one line to arbitrary points with given covariances (no grouping, no rejection).

    This is the ML fit of Props. 1-2 with the covariance of :mod:`linefit.covariance`, for
    points from anywhere (e.g. the points of two lines moved into a common frame, to check that
    fusing lines equals fitting their points).  The covariances are taken as the covariances of
    the points about their true positions (the ``"reading"`` model for ``S`` and the ends).

    Parameters
    ----------
    points_xy
        Points (m), shape ``(n, 2)``, ``n ≥ 2``.
    covariances
        Their covariances (m²), shape ``(n, 2, 2)``, symmetric positive definite.
    alpha0
        Starting normal angle (rad); default: the total-least-squares line.  It also picks
        the representative before the result is put in normal form.
    weighted
        ML fit (True) or unweighted total least squares (False).
    config
        Iteration settings (``max_iterations``, ``alpha_tolerance_rad``, ``alpha_update``).

    Returns
    -------
    Line
        In normal form, one segment spanning the extreme points, ``indices`` = ``0..n-1``.

    Raises
    ------
    InputError
        Wrong shapes, non-finite values, covariances that are not symmetric positive definite.
    DegenerateGeometryError
        Fewer than two distinct points, or points that do not determine a line.
    """
    cfg = config if config is not None else LineFitConfig()
    try:
        p = np.asarray(points_xy, dtype=float)
        C = np.asarray(covariances, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"points and covariances must be numeric arrays ({exc})") from exc
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"points_xy must have shape (n, 2), got {p.shape}")
    if C.shape != (p.shape[0], 2, 2):
        raise InputError(f"covariances must have shape ({p.shape[0]}, 2, 2), got {C.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(C))):
        raise InputError("points and covariances must be finite")
    if p.shape[0] < 2:
        raise DegenerateGeometryError(f"a line needs at least two points, got {p.shape[0]}")
    q11, q12, q22 = C[:, 0, 0], 0.5 * (C[:, 0, 1] + C[:, 1, 0]), C[:, 1, 1]
    spd = (q11 > 0.0) & (q22 > 0.0) & (q11 * q22 - q12 * q12 > 0.0)
    if not np.allclose(C[:, 0, 1], C[:, 1, 0], rtol=1e-9, atol=1e-18) or not spd.all():
        raise InputError("covariances must be symmetric positive definite")
    pts = PointSet(
        x=p[:, 0].copy(),
        y=p[:, 1].copy(),
        q11=q11.copy(),
        q12=q12.copy(),
        q22=q22.copy(),
        beam=np.arange(p.shape[0], dtype=np.intp),
    )
    return _single_line(pts, alpha0, weighted, cfg, "reading")


def fit_scan_line(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    alpha0: float | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> Line:
    """Fit one line to all the given readings (Eq. 8 noise, no grouping, no rejection).

    Parameters
    ----------
    ranges, bearings
        The readings of one line (m, rad), shape ``(n,)``; all must be valid measurements.
    config
        Noise model and fit settings (``weighted``, iterations, ``noise.bearing_error``).
    alpha0
        Starting normal angle (rad); default the total-least-squares line.
    sigma_range_fn
        Optional vectorised ``σ_d(d)``.

    Returns
    -------
    Line
        In normal form, one segment, ``indices`` = positions in the given arrays.

    Raises
    ------
    InputError
        Mismatched shapes or invalid readings (NaN, inf, ``≤ 0``).
    DegenerateGeometryError
        Fewer than two points, or points on a ray through the sensor (a range sensor cannot
        observe such a line: every beam would be parallel to it).
    """
    cfg = config if config is not None else LineFitConfig()
    d = _as_vector(ranges, "ranges")
    phi = _as_vector(bearings, "bearings")
    if d.shape != phi.shape:
        raise InputError(f"ranges ({d.shape[0]}) and bearings ({phi.shape[0]}) differ in length")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(phi)) and np.all(d > 0.0)):
        raise InputError("fit_scan_line needs valid readings: finite ranges > 0, finite bearings")
    if d.shape[0] < 2:
        raise DegenerateGeometryError(f"a line needs at least two points, got {d.shape[0]}")
    pts = scan_points(d, phi, np.arange(d.shape[0], dtype=np.intp), cfg, sigma_range_fn)
    ray = DegenerateGeometryError(
        "the points lie on a line through the sensor: a range sensor cannot observe it"
    )
    # bearings all equal modulo π: the points are on one line through the sensor origin
    spread = np.asarray(wrap_angle(2.0 * (phi - phi[0])))
    if np.all(np.abs(spread) < 1e-9):
        raise ray
    line = _single_line(pts, alpha0, cfg.weighted, cfg, cfg.noise.bearing_error)
    if line.r <= 1e-9 * max(1.0, float(np.max(d))):
        raise ray
    return line
