"""The public entry points of line extraction and fitting.

:func:`extract_lines` for a scan, :func:`extract_lines_batch` for many scans at once,
:func:`fit_line` and :func:`fit_scan_line` for a given set of points.

Every step works on all the scans of a batch together (the points, candidate lines and
segments of all scans are flat arrays with a scan id); :func:`extract_lines` is a batch of one.
Batches amortise numpy's per-call overhead: ``scripts/bench_extract.py`` measures both.

Pipeline of :func:`extract_lines`
---------------------------------
1. Readings that are not measurements of a surface (NaN, ±inf, ``≤ 0``, ``≥`` max range) are
   dropped; they never enter a fit.
2. Eq. 8 covariances of the remaining points (:mod:`linefit.noise`).
3. Grouping into candidate lines: Hough transform (:mod:`linefit.hough`) or split-and-merge
   (:mod:`linefit.split_merge`).
4. For all candidates at once (:mod:`linefit.fit`): the ML fit, then each point's normal
   residual is tested against its own covariance, studentised by its leverage
   (``δ_R²/(P_R (1 − h)) > outlier_chi2``: rejected; in each round only points within a factor
   3 (in residual) of their line's worst are rejected, so one bad point cannot mask the
   others), and refit, at most ``max_refits`` rounds; then each line is cut into segments at
   gaps and range jumps, pieces with fewer than ``min_segment_points`` points leave it, and it
   is refitted (:mod:`linefit.segments`).
5. Hough only (``hough_recover``): the points no line kept are grouped by split-and-merge and
   those candidates go through step 4 too.
6. Optionally (``merge_collinear``) lines of one scan whose ``(r, α)`` pass a χ² test are
   joined into one line with several segments and refitted (step 4).
7. Lines with fewer than ``min_points`` points or shorter than ``min_length_m`` are dropped;
   covariances (:mod:`linefit.covariance`) and segment ends; normal form; sorted by their
   first beam index.

Lines that are not changed by a later step are never refitted, so a scan's result does not
depend on the other scans of its batch (tested).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.config import LineFitConfig
from linefit.covariance import LineCovariances, line_covariances
from linefit.errors import DegenerateGeometryError, InputError
from linefit.fit import GroupFit, PointSet, fit_groups, nearest_representative, tls_groups
from linefit.hough import hough_groups
from linefit.line import Line, wrap_angle
from linefit.noise import SigmaRangeFn, point_covariance_entries, range_sigma
from linefit.segments import segment_ids
from linefit.split_merge import split_merge_groups

__all__ = [
    "extract_lines",
    "extract_lines_batch",
    "fit_line",
    "fit_scan_line",
    "scan_points",
    "valid_readings",
]

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


def _check_batch(
    ranges: ArrayLike, bearings: ArrayLike, max_range_m: ArrayLike | None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    try:
        d = np.asarray(ranges, dtype=float)
        phi = np.asarray(bearings, dtype=float)
        mr = np.asarray(np.inf if max_range_m is None else max_range_m, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"ranges, bearings and max_range_m must be numeric ({exc})") from exc
    if d.ndim != 2:
        raise InputError(f"ranges must have shape (n_scans, n_beams), got {d.shape}")
    if phi.ndim == 1:
        phi = np.broadcast_to(phi, d.shape)
    if phi.shape != d.shape:
        raise InputError(
            f"bearings must have shape ({d.shape[1]},) or {d.shape}, got {np.shape(bearings)}"
        )
    if not np.all(np.isfinite(phi)):
        raise InputError("bearings must be finite")
    if d.shape[1] >= 2:
        step = phi[:, 1:] - phi[:, :-1]
        step = np.pi - np.mod(np.pi - step, 2.0 * np.pi)  # wrap to (−π, π]
        mono = np.all(step > 0.0, axis=1) | np.all(step < 0.0, axis=1)
        if not mono.all():
            bad = int(np.flatnonzero(~mono)[0])
            raise InputError(
                f"bearings must be strictly increasing or strictly decreasing (scan {bad})"
            )
    if mr.ndim == 0:
        mr = np.full(d.shape[0], float(mr))
    if mr.shape != (d.shape[0],):
        raise InputError(f"max_range_m must be a number or have shape ({d.shape[0]},)")
    if np.any(np.isnan(mr) | (mr <= 0.0)):
        raise InputError("max_range_m must be positive")
    return d, phi, mr


def valid_readings(
    ranges: FloatArray, max_range_m: FloatArray | float | None, config: LineFitConfig
) -> NDArray[np.bool_]:
    """True for readings that are measurements of a surface (finite, > 0, < max range).

    ``max_range_m`` is a number or one value per scan (the rows of a 2-D ``ranges``); the
    smaller of it and ``config.max_range_m`` applies.
    """
    limit = np.asarray(np.inf if max_range_m is None else max_range_m, dtype=float)
    if config.max_range_m is not None:
        limit = np.minimum(limit, config.max_range_m)
    if ranges.ndim == 2 and limit.ndim == 1:
        limit = limit[:, None]
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
    """Fitted lines: memberships (``gidx`` ascending), fits, covariances and segments.

    ``order`` sorts the memberships by (line, u_S); ``seg`` numbers the segments along
    ``order`` (non-decreasing, lines in ascending order).
    """

    pidx: IntArray
    gidx: IntArray
    n_groups: int
    gscan: IntArray
    fit: GroupFit
    cov: LineCovariances
    order: IntArray
    seg: IntArray

    def select(self, keep_g: NDArray[np.bool_]) -> _Fitted:
        """Only the lines ``keep_g`` (renumbered in order)."""
        new_g = np.cumsum(keep_g) - 1
        keep_m = keep_g[self.gidx]
        new_m = np.cumsum(keep_m) - 1
        f, c = self.fit, self.cov
        kept_sorted = keep_m[self.order]
        _, seg = np.unique(self.seg[kept_sorted], return_inverse=True)
        fit = _fit_take(f, keep_g, keep_m)
        cov = LineCovariances(c.cov[keep_g], c.end_var[keep_m], c.gain_alpha[keep_m])
        return _Fitted(
            self.pidx[keep_m],
            new_g[self.gidx[keep_m]],
            int(keep_g.sum()),
            self.gscan[keep_g],
            fit,
            cov,
            new_m[self.order[kept_sorted]],
            seg.reshape(-1).astype(np.intp),
        )

    @staticmethod
    def concat(a: _Fitted, b: _Fitted) -> _Fitted:
        """The lines of ``a`` followed by those of ``b``."""
        fit = _fit_cat(a.fit, b.fit)
        cov = LineCovariances(
            np.concatenate([a.cov.cov, b.cov.cov]),
            np.concatenate([a.cov.end_var, b.cov.end_var]),
            np.concatenate([a.cov.gain_alpha, b.cov.gain_alpha]),
        )
        n_seg_a = int(a.seg[-1]) + 1 if a.seg.shape[0] else 0
        return _Fitted(
            np.concatenate([a.pidx, b.pidx]),
            np.concatenate([a.gidx, b.gidx + a.n_groups]),
            a.n_groups + b.n_groups,
            np.concatenate([a.gscan, b.gscan]),
            fit,
            cov,
            np.concatenate([a.order, b.order + a.pidx.shape[0]]),
            np.concatenate([a.seg, b.seg + n_seg_a]),
        )


_PER_LINE = ("r", "alpha", "s", "converged", "iterations")
_PER_MEMBER = ("u_r", "u_s", "p_r", "p_s", "p_rs", "w_r", "w_s")


@dataclass
class _Groups:
    """Memberships (sorted by group) with per-group start angle and scan."""

    pidx: IntArray
    gidx: IntArray
    n: int
    alpha0: FloatArray
    gscan: IntArray

    def keep_groups(self, keep_g: NDArray[np.bool_]) -> None:
        new_id = np.cumsum(keep_g) - 1
        keep = keep_g[self.gidx]
        self.pidx = self.pidx[keep]
        self.gidx = new_id[self.gidx[keep]]
        self.n = int(keep_g.sum())
        self.alpha0 = self.alpha0[keep_g]
        self.gscan = self.gscan[keep_g]

    def keep_members(self, keep: NDArray[np.bool_]) -> None:
        self.pidx = self.pidx[keep]
        self.gidx = self.gidx[keep]

    def subset(self, keep_g: NDArray[np.bool_], keep_m: NDArray[np.bool_] | None = None) -> _Groups:
        """A copy with only the groups ``keep_g`` (and, if given, only the members ``keep_m``)."""
        out = _Groups(self.pidx, self.gidx, self.n, self.alpha0, self.gscan)
        if keep_m is not None:
            out.keep_members(keep_m)
        out.keep_groups(keep_g)
        return out

    @staticmethod
    def cat(a: _Groups, b: _Groups) -> _Groups:
        """The groups of ``a`` followed by those of ``b``."""
        return _Groups(
            np.concatenate([a.pidx, b.pidx]),
            np.concatenate([a.gidx, b.gidx + a.n]),
            a.n + b.n,
            np.concatenate([a.alpha0, b.alpha0]),
            np.concatenate([a.gscan, b.gscan]),
        )


def _fit_take(fit: GroupFit, keep_g: NDArray[np.bool_], keep_m: NDArray[np.bool_]) -> GroupFit:
    """The fits of the lines ``keep_g`` (whose memberships are ``keep_m``)."""
    return GroupFit(
        **{k: getattr(fit, k)[keep_g] for k in _PER_LINE},
        **{k: getattr(fit, k)[keep_m] for k in _PER_MEMBER},
        weighted=fit.weighted,
    )


def _fit_cat(a: GroupFit, b: GroupFit) -> GroupFit:
    """The fits of ``a`` followed by those of ``b``."""
    return GroupFit(
        **{k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in _PER_LINE},
        **{k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in _PER_MEMBER},
        weighted=a.weighted,
    )


def _refit_changed(
    pts: PointSet,
    grp: _Groups,
    fit: GroupFit,
    changed: NDArray[np.bool_],
    keep_m: NDArray[np.bool_],
    cfg: LineFitConfig,
) -> tuple[_Groups, GroupFit | None, NDArray[np.bool_]]:
    """Refit only the lines ``changed`` (with the members ``keep_m``); the others stay as they are.

    Returns the groups (unchanged ones first), their fits, and which of them were refitted.
    """
    stay = ~changed
    grp_u = grp.subset(stay)
    fit_u = _fit_take(fit, stay, stay[grp.gidx])
    grp_c = grp.subset(changed, keep_m)
    grp_c.alpha0 = fit.alpha[changed]  # restart from the current fit
    fit_c = _fit_kept(pts, grp_c, cfg) if grp_c.n else None
    if fit_c is None:
        return grp_u, (fit_u if grp_u.n else None), np.zeros(grp_u.n, dtype=bool)
    refitted = np.concatenate([np.zeros(grp_u.n, dtype=bool), np.ones(grp_c.n, dtype=bool)])
    return _Groups.cat(grp_u, grp_c), _fit_cat(fit_u, fit_c), refitted


def _fit_batch(pts: PointSet, grp: _Groups, cfg: LineFitConfig) -> GroupFit:
    return fit_groups(
        pts,
        grp.pidx,
        grp.gidx,
        grp.n,
        grp.alpha0,
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


def _segments(
    pts: PointSet, sigma_range: FloatArray, grp: _Groups, fit: GroupFit, cfg: LineFitConfig
) -> tuple[IntArray, IntArray]:
    return segment_ids(
        pts.x[grp.pidx],
        pts.y[grp.pidx],
        pts.beam[grp.pidx],
        sigma_range[grp.pidx],
        grp.gidx,
        fit.u_s,
        max_missing_beams=cfg.max_missing_beams,
        lambda_rad=cfg.breakpoint_lambda_rad,
        sigma_factor=cfg.breakpoint_sigma,
    )


def _fit_kept(pts: PointSet, grp: _Groups, cfg: LineFitConfig) -> GroupFit | None:
    """Drop lines with too few points or that do not converge, and fit the rest."""
    min_pts = max(2, cfg.min_points)
    while grp.n:
        keep_g = np.bincount(grp.gidx, minlength=grp.n) >= min_pts
        if not keep_g.all():
            grp.keep_groups(keep_g)
            if grp.n == 0:
                break
        fit = _fit_batch(pts, grp, cfg)
        ok = fit.converged & np.isfinite(fit.r) & np.isfinite(fit.alpha)
        if ok.all():
            return fit
        if not ok.any():
            break
        # lines are fitted independently: drop the failures, keep the others' fits
        fit = _fit_take(fit, ok, ok[grp.gidx])
        grp.keep_groups(ok)
        return fit
    return None


def _refine(
    pts: PointSet, sigma_range: FloatArray, grp: _Groups, cfg: LineFitConfig
) -> _Fitted | None:
    """Fit, reject outliers, cut into segments and refit all candidate lines together.

    After the first fit only the lines that lost points are refitted.
    """
    fit = _fit_kept(pts, grp, cfg)
    if fit is None:
        return None
    todo = np.ones(grp.n, dtype=bool)  # lines whose points may still be rejected
    for _ in range(cfg.max_refits + 1):
        # per-point χ² gate on the normal residual, studentised by the point's leverage
        G, gidx = grp.n, grp.gidx
        chi2 = (fit.u_r - fit.r[gidx]) ** 2 / (fit.p_r * (1.0 - _leverage(fit, gidx, G)))
        worst = np.zeros(G)
        np.maximum.at(worst, gidx, chi2)
        reject = (chi2 > cfg.outlier_chi2) & (chi2 >= worst[gidx] / 9.0) & todo[gidx]
        if not reject.any():
            break
        changed = np.zeros(G, dtype=bool)
        changed[gidx[reject]] = True
        grp, fit_new, todo = _refit_changed(pts, grp, fit, changed, ~reject, cfg)
        if fit_new is None:
            return None
        fit = fit_new
    # segments; pieces with too few points leave the line
    order, seg = _segments(pts, sigma_range, grp, fit, cfg)
    small = np.bincount(seg)[seg] < cfg.min_segment_points
    if small.any():
        keep = np.ones(grp.pidx.shape[0], dtype=bool)
        keep[order[small]] = False
        changed = np.zeros(grp.n, dtype=bool)
        changed[grp.gidx[~keep]] = True
        grp, fit_new, _ = _refit_changed(pts, grp, fit, changed, keep, cfg)
        if fit_new is None:
            return None
        fit = fit_new
        order, seg = _segments(pts, sigma_range, grp, fit, cfg)
    cov = line_covariances(fit, pts, grp.pidx, grp.gidx, grp.n, cfg.noise.bearing_error)
    return _Fitted(grp.pidx, grp.gidx, grp.n, grp.gscan, fit, cov, order, seg)


def _merge_collinear(
    pts: PointSet, sigma_range: FloatArray, fitted: _Fitted, cfg: LineFitConfig
) -> _Fitted:
    """Join lines of one scan whose (r, α) pass the χ² test into multi-segment lines."""
    G = fitted.n_groups
    if G < 2:
        return fitted
    perm = np.argsort(fitted.gscan, kind="stable")  # lines by scan
    gscan = fitted.gscan[perm]
    first_g = np.searchsorted(gscan, gscan, side="left")
    per_scan = np.searchsorted(gscan, gscan, side="right") - first_g
    k_max = int(per_scan.max())
    if k_max < 2:
        return fitted
    # all pairs (i < j) of lines within each scan
    ti, tj = np.triu_indices(k_max, 1)
    starts = np.unique(first_g)
    sizes = np.searchsorted(gscan, gscan[starts], side="right") - starts
    ok = tj[None, :] < sizes[:, None]
    i = perm[(starts[:, None] + ti[None, :])[ok]]
    j = perm[(starts[:, None] + tj[None, :])[ok]]
    r, alpha = fitted.fit.r, fitted.fit.alpha
    flip = r < 0.0
    rn = np.abs(r)
    an = np.asarray(wrap_angle(np.where(flip, alpha + np.pi, alpha)))
    P = fitted.cov.cov[:, :2, :2]
    p_ra = np.where(flip, -P[:, 0, 1], P[:, 0, 1])
    dr = rn[i] - rn[j]
    da = np.asarray(wrap_angle(an[i] - an[j]))
    s00 = P[i, 0, 0] + P[j, 0, 0]
    s11 = P[i, 1, 1] + P[j, 1, 1]
    s01 = p_ra[i] + p_ra[j]
    det = s00 * s11 - s01 * s01
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (s11 * dr * dr - 2.0 * s01 * dr * da + s00 * da * da) / det
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
    joined = np.bincount(roots, minlength=G)[roots] > 1
    if not joined.any():
        return fitted
    # only the joined lines are refitted (from the angle of the set's first line)
    _, new_g = np.unique(roots[joined], return_inverse=True)
    new_g = new_g.reshape(-1)
    n_new = int(new_g.max()) + 1
    g_of = np.full(G, -1, dtype=np.intp)
    g_of[joined] = new_g
    members = joined[fitted.gidx]
    gidx = g_of[fitted.gidx[members]]
    pidx = fitted.pidx[members]
    # a point shared by two joined lines counts once; memberships sorted by new line
    key = gidx.astype(np.int64) * (len(pts) + 1) + pidx
    _, first = np.unique(key, return_index=True)
    joined_ids = np.flatnonzero(joined)
    _, first_of_set = np.unique(new_g, return_index=True)
    grp = _Groups(
        pidx=pidx[first],
        gidx=gidx[first],
        n=n_new,
        alpha0=alpha[joined_ids[first_of_set]],
        gscan=fitted.gscan[joined_ids[first_of_set]],
    )
    refined = _refine(pts, sigma_range, grp, cfg)
    rest = fitted.select(~joined)
    return rest if refined is None else _Fitted.concat(rest, refined)


# ---------------------------------------------------------------------------------------------
# Line objects
# ---------------------------------------------------------------------------------------------
def _lines_from_fit(
    pts: PointSet, fitted: _Fitted, cfg: LineFitConfig, n_scans: int
) -> list[list[Line]]:
    fit, G = fitted.fit, fitted.n_groups
    order, seg = fitted.order, fitted.seg
    pidx, gidx = fitted.pidx, fitted.gidx
    n_seg = int(seg[-1]) + 1 if seg.shape[0] else 0
    seg_ids = np.arange(n_seg)
    first = np.searchsorted(seg, seg_ids, side="left")
    last = np.searchsorted(seg, seg_ids, side="right") - 1
    seg_group = gidx[order[first]]
    s_start = fit.u_s[order[first]]
    s_end = fit.u_s[order[last]]
    v_start = fitted.cov.end_var[order[first]]
    v_end = fitted.cov.end_var[order[last]]
    length = np.bincount(seg_group, weights=s_end - s_start, minlength=G)
    counts = np.bincount(gidx, minlength=G)
    beams = pts.beam[pidx]
    # memberships by (group, beam): each line's beam indices are one sorted slice
    mem_order = np.lexsort((beams, gidx))
    mem_bounds = np.searchsorted(gidx[mem_order], np.arange(G + 1))
    sorted_beams = beams[mem_order]
    first_beam = sorted_beams[np.minimum(mem_bounds[:-1], max(0, sorted_beams.shape[0] - 1))]
    seg_bounds = np.searchsorted(seg_group, np.arange(G + 1))  # segments are sorted by line
    keep = (counts >= cfg.min_points) & (length >= cfg.min_length_m)
    keep &= np.all(np.isfinite(fitted.cov.cov.reshape(G, 9)), axis=1)
    # normal form, vectorised
    flip = fit.r < 0.0
    r_n = np.abs(fit.r)
    a_n = np.asarray(wrap_angle(np.where(flip, fit.alpha + np.pi, fit.alpha)), dtype=float)
    s_n = np.where(flip, -fit.s, fit.s)
    sign = np.where(flip[:, None], np.array([-1.0, 1.0, -1.0]), 1.0)
    cov_n = fitted.cov.cov * sign[:, :, None] * sign[:, None, :]
    segs_all = np.stack([s_start, s_end], axis=1)
    vars_all = np.stack([v_start, v_end], axis=1)
    out: list[list[Line]] = [[] for _ in range(n_scans)]
    sel = np.flatnonzero(keep)
    sel = sel[np.lexsort((first_beam[sel], fitted.gscan[sel]))]
    # per line: python scalars and array slices, then the trusted constructor
    r_l, a_l, s_l = r_n.tolist(), a_n.tolist(), s_n.tolist()
    flip_l, scan_l = flip.tolist(), fitted.gscan.tolist()
    sb, mb = seg_bounds.tolist(), mem_bounds.tolist()
    for g in sel.tolist():
        segs = segs_all[sb[g] : sb[g + 1]]
        svar = vars_all[sb[g] : sb[g + 1]]
        if flip_l[g]:
            segs = -segs[::-1, ::-1]
            svar = svar[::-1, ::-1]
        idx = sorted_beams[mb[g] : mb[g + 1]]
        out[scan_l[g]].append(
            Line._trusted(r_l[g], a_l[g], s_l[g], cov_n[g], segs, svar, mb[g + 1] - mb[g], idx)
        )
    return out


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------
def extract_lines_batch(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    max_range_m: ArrayLike | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> list[list[Line]]:
    """Extract the lines of many scans at once (same result as one :func:`extract_lines` each).

    Parameters
    ----------
    ranges
        Ranges (m), shape ``(n_scans, n_beams)``; NaN, ±inf, zero, negative and max-range
        readings are allowed and ignored (pad scans of different lengths with NaN).
    bearings
        Beam angles (rad), shape ``(n_beams,)`` (shared) or ``(n_scans, n_beams)``; finite and
        strictly monotonic per scan.
    config
        Extraction settings (default :class:`LineFitConfig`).
    max_range_m
        Maximum range of the scans: one number or one per scan.
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)``.

    Returns
    -------
    list of list of Line
        The lines of each scan (see :func:`extract_lines`).
    """
    cfg = config if config is not None else LineFitConfig()
    d, phi, mr = _check_batch(ranges, bearings, max_range_m)
    n_scans, n_beams = d.shape
    valid = valid_readings(d, mr, cfg)
    # scans with too few valid readings hold no line
    valid &= (valid.sum(axis=1) >= max(2, cfg.min_points))[:, None]
    flat = np.flatnonzero(valid.ravel())
    if flat.shape[0] == 0:
        return [[] for _ in range(n_scans)]
    scan_of = flat // n_beams
    beam_of = flat % n_beams
    pts = scan_points(d.ravel()[flat], phi.ravel()[flat], beam_of, cfg, sigma_range_fn)
    assert pts.var_range is not None
    sigma_range = np.sqrt(pts.var_range)

    def split_merge_of(sub: IntArray) -> _Groups:
        """Split-and-merge candidates among the valid points ``sub`` (sorted)."""
        grouping = split_merge_groups(
            pts.x[sub],
            pts.y[sub],
            pts.beam[sub],
            sigma_range[sub],
            scan_of[sub],
            split_threshold_m=cfg.split_threshold_m,
            split_threshold_sigma=cfg.split_threshold_sigma,
            max_missing_beams=cfg.max_missing_beams,
            lambda_rad=cfg.breakpoint_lambda_rad,
            sigma_factor=cfg.breakpoint_sigma,
            min_points=cfg.min_segment_points,
        )
        first = np.searchsorted(grouping.gidx, np.arange(grouping.n_groups))
        return _Groups(
            sub[grouping.pidx],
            grouping.gidx,
            grouping.n_groups,
            grouping.alpha0,
            scan_of[sub[grouping.pidx[first]]] if grouping.n_groups else np.zeros(0, np.intp),
        )

    all_points = np.arange(flat.shape[0], dtype=np.intp)
    if cfg.grouping == "hough":
        to_valid = np.full(d.size, -1, dtype=np.intp)
        to_valid[flat] = all_points
        x2 = np.zeros(d.shape)
        y2 = np.zeros(d.shape)
        x2.ravel()[flat] = pts.x
        y2.ravel()[flat] = pts.y
        grouping, gscan = hough_groups(
            x2,
            y2,
            valid,
            angle_step_rad=cfg.hough_angle_step_rad,
            range_step_m=cfg.hough_range_step_m,
            min_votes=cfg.hough_min_votes,
            gather_m=cfg.hough_gather_m,
            max_peaks=cfg.hough_max_peaks,
        )
        grp = _Groups(
            to_valid[grouping.pidx], grouping.gidx, grouping.n_groups, grouping.alpha0, gscan
        )
        fitted = _refine(pts, sigma_range, grp, cfg)
        if cfg.hough_recover:
            # points no Hough line kept (a coarse peak can absorb, and then lose, the points
            # of a small face): split-and-merge pieces among them, refitted with the lines
            used = np.zeros(flat.shape[0], dtype=bool)
            if fitted is not None:
                used[fitted.pidx] = True
            extra = split_merge_of(all_points[~used])
            if extra.n:
                new = _refine(pts, sigma_range, extra, cfg)
                if fitted is None:
                    fitted = new
                elif new is not None:
                    fitted = _Fitted.concat(fitted, new)
    else:
        fitted = _refine(pts, sigma_range, split_merge_of(all_points), cfg)
    if fitted is None:
        return [[] for _ in range(n_scans)]
    if cfg.merge_collinear:
        fitted = _merge_collinear(pts, sigma_range, fitted, cfg)
    return _lines_from_fit(pts, fitted, cfg, n_scans)


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
    d = _as_vector(ranges, "ranges")
    phi = _as_vector(bearings, "bearings")
    if d.shape != phi.shape:
        raise InputError(f"ranges ({d.shape[0]}) and bearings ({phi.shape[0]}) differ in length")
    if max_range_m is not None and not np.ndim(max_range_m) == 0:
        raise InputError("max_range_m must be a number")
    return extract_lines_batch(
        d[None, :], phi, config, max_range_m=max_range_m, sigma_range_fn=sigma_range_fn
    )[0]


def _single_line(
    pts: PointSet, alpha0: float | None, weighted: bool, cfg: LineFitConfig, bearing_error: str
) -> Line:
    n = len(pts)
    pidx = np.arange(n, dtype=np.intp)
    gidx = np.zeros(n, dtype=np.intp)
    _, a_tls, ratio = tls_groups(pts, pidx, gidx, 1)
    if not np.isfinite(ratio[0]):
        raise DegenerateGeometryError("the points coincide: they do not determine a line")
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
    fitted = _Fitted(pidx, gidx, 1, np.zeros(1, dtype=np.intp), fit, cov, order, seg)
    relaxed = LineFitConfig(noise=cfg.noise, min_points=2, min_length_m=0.0)
    return _lines_from_fit(pts, fitted, relaxed, 1)[0][0]


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
