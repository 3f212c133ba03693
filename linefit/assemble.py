"""Result assembly: fitted lines of a batch to :class:`~linefit.line.Line` objects per scan."""

from __future__ import annotations

import numpy as np

from linefit.config import LineFitConfig
from linefit.fit import PointSet
from linefit.fitted import Fitted
from linefit.line import Line, wrap_angle

__all__ = ["lines_from_fit"]


def lines_from_fit(
    pts: PointSet, fitted: Fitted, cfg: LineFitConfig, n_scans: int
) -> list[list[Line]]:
    """The :class:`~linefit.line.Line` objects of fitted lines, scan by scan (step 7).

    Lines with fewer than ``cfg.min_points`` points, shorter than ``cfg.min_length_m`` (sum of
    their segments' lengths) or with a non-finite covariance are dropped; the others are put in
    normal form (``r ≥ 0``, ``α ∈ (−π, π]``; where flipped, the signs of ``r`` and ``s`` and of
    their covariance rows and columns change and the segments reverse) and sorted by the first
    beam index of their points.

    Parameters
    ----------
    pts
        The valid points of the batch.
    fitted
        The fitted lines.
    cfg
        Supplies ``min_points`` and ``min_length_m``.
    n_scans
        Number of scans of the batch.

    Returns
    -------
    list of list of Line
        The lines of each scan.
    """
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
