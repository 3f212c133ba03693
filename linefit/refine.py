"""Fit, outlier rejection and segmentation of candidate lines, all lines of a batch together.

Step 4 of the pipeline (:mod:`linefit.extract`): the ML fit, then each point's normal residual
is tested against its own covariance, studentised by its leverage
(``δ_R²/(P_R (1 − h)) > outlier_chi2``: rejected; in each round only points within a factor 3
(in residual) of their line's worst are rejected, so one bad point cannot mask the others),
and the lines that lost points are refitted, at most ``max_refits`` rounds; then each line is
cut into segments at gaps and range jumps, pieces with fewer than ``min_segment_points``
points leave it, and it is refitted.  Lines that are not changed by a step are never refitted.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.config import LineFitConfig
from linefit.covariance import line_covariances
from linefit.fit import GroupFit, PointSet, fit_groups
from linefit.fitted import Fitted, Groups, fit_cat, fit_take
from linefit.segments import segment_ids

__all__ = ["fit_kept", "leverage", "refine", "refit_changed"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def refit_changed(
    pts: PointSet,
    grp: Groups,
    fit: GroupFit,
    changed: NDArray[np.bool_],
    keep_m: NDArray[np.bool_],
    cfg: LineFitConfig,
) -> tuple[Groups, GroupFit | None, NDArray[np.bool_]]:
    """Refit only the lines ``changed`` (with the members ``keep_m``); the others stay as they are.

    Returns the groups (unchanged ones first), their fits, and which of them were refitted.
    """
    stay = ~changed
    grp_u = grp.subset(stay)
    fit_u = fit_take(fit, stay, stay[grp.gidx])
    grp_c = grp.subset(changed, keep_m)
    grp_c.alpha0 = fit.alpha[changed]  # restart from the current fit
    fit_c = fit_kept(pts, grp_c, cfg) if grp_c.n else None
    if fit_c is None:
        return grp_u, (fit_u if grp_u.n else None), np.zeros(grp_u.n, dtype=bool)
    refitted = np.concatenate([np.zeros(grp_u.n, dtype=bool), np.ones(grp_c.n, dtype=bool)])
    return Groups.cat(grp_u, grp_c), fit_cat(fit_u, fit_c), refitted


def _fit_batch(pts: PointSet, grp: Groups, cfg: LineFitConfig) -> GroupFit:
    """The ML fit (Props. 1-2) of every group of ``grp``, started from ``grp.alpha0``."""
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


def leverage(fit: GroupFit, gidx: IntArray, G: int) -> FloatArray:
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
    pts: PointSet, sigma_range: FloatArray, grp: Groups, fit: GroupFit, cfg: LineFitConfig
) -> tuple[IntArray, IntArray]:
    """Segment ids of the memberships of ``grp`` (:func:`linefit.segments.segment_ids`)."""
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


def fit_kept(pts: PointSet, grp: Groups, cfg: LineFitConfig) -> GroupFit | None:
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
        fit = fit_take(fit, ok, ok[grp.gidx])
        grp.keep_groups(ok)
        return fit
    return None


def refine(
    pts: PointSet, sigma_range: FloatArray, grp: Groups, cfg: LineFitConfig
) -> Fitted | None:
    """Fit, reject outliers, cut into segments and refit all candidate lines together.

    After the first fit only the lines that lost points are refitted.
    """
    fit = fit_kept(pts, grp, cfg)
    if fit is None:
        return None
    todo = np.ones(grp.n, dtype=bool)  # lines whose points may still be rejected
    for _ in range(cfg.max_refits + 1):
        # per-point χ² gate on the normal residual, studentised by the point's leverage
        G, gidx = grp.n, grp.gidx
        chi2 = (fit.u_r - fit.r[gidx]) ** 2 / (fit.p_r * (1.0 - leverage(fit, gidx, G)))
        worst = np.zeros(G)
        np.maximum.at(worst, gidx, chi2)
        reject = (chi2 > cfg.outlier_chi2) & (chi2 >= worst[gidx] / 9.0) & todo[gidx]
        if not reject.any():
            break
        changed = np.zeros(G, dtype=bool)
        changed[gidx[reject]] = True
        grp, fit_new, todo = refit_changed(pts, grp, fit, changed, ~reject, cfg)
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
        grp, fit_new, _ = refit_changed(pts, grp, fit, changed, keep, cfg)
        if fit_new is None:
            return None
        fit = fit_new
        order, seg = _segments(pts, sigma_range, grp, fit, cfg)
    cov = line_covariances(fit, pts, grp.pidx, grp.gidx, grp.n, cfg.noise.bearing_error)
    return Fitted(grp.pidx, grp.gidx, grp.n, grp.gscan, fit, cov, order, seg)
