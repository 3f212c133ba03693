"""Grouping by split-and-merge (iterative end-point fit), the alternative to the Hough transform.

1. **Clusters.**  The valid points, in beam order, are cut at breakpoints (range jumps and
   gaps, :func:`linefit.segments.breakpoint_mask`).
2. **Split.**  Each piece is tested against the chord through its first and last point; if
   the point farthest from the chord (relative to its threshold
   ``max(split_threshold_m, split_threshold_sigma · σ_d)``) exceeds it, the piece is split
   there (the split point goes to both halves: it is the corner).  All pieces of the scan
   are tested together, level by level.
3. **Merge.**  Neighbouring pieces of one cluster are merged when every point of the union is
   within its threshold of the union's total-least-squares line (repeated until nothing
   merges).

The pieces become candidate lines, each with its total-least-squares angle as the starting
estimate of the ML fit.  Collinear pieces separated by gaps are joined later, after the fit,
with a χ² test (:func:`linefit.extract.extract_lines`, ``merge_collinear``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.grouping import Grouping
from linefit.segments import breakpoint_mask

__all__ = ["split_merge_groups"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def _expand(starts: IntArray, ends: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Indices of all ranges ``[starts[k], ends[k]]`` concatenated, with range id and offsets."""
    lengths = ends - starts + 1
    offsets = np.cumsum(lengths) - lengths
    total = int(lengths.sum())
    seg = np.repeat(np.arange(starts.shape[0], dtype=np.intp), lengths)
    idx = np.arange(total, dtype=np.intp) - offsets[seg] + starts[seg]
    return idx, seg, offsets


def _chord_split(
    x: FloatArray, y: FloatArray, thr: FloatArray, starts: IntArray, ends: IntArray
) -> tuple[IntArray, IntArray]:
    """Split ranges at the point farthest from their chord until none exceeds its threshold."""
    done_s: list[IntArray] = []
    done_e: list[IntArray] = []
    while starts.shape[0]:
        idx, seg, offsets = _expand(starts, ends)
        xs, ys = x[starts], y[starts]
        ex, ey = x[ends] - xs, y[ends] - ys
        norm = np.hypot(ex, ey)
        norm = np.where(norm > 0.0, norm, 1.0)
        dist = np.abs((x[idx] - xs[seg]) * ey[seg] - (y[idx] - ys[seg]) * ex[seg]) / norm[seg]
        score = dist / thr[idx]
        seg_max = np.maximum.reduceat(score, offsets)
        pos = np.arange(idx.shape[0], dtype=np.intp)
        first = np.minimum.reduceat(np.where(score == seg_max[seg], pos, idx.shape[0]), offsets)
        split = (seg_max > 1.0) & (ends - starts >= 2)
        done_s.append(starts[~split])
        done_e.append(ends[~split])
        k = idx[first[split]]
        starts = np.concatenate([starts[split], k])
        ends = np.concatenate([k, ends[split]])
    s_all = np.concatenate(done_s) if done_s else np.zeros(0, dtype=np.intp)
    e_all = np.concatenate(done_e) if done_e else np.zeros(0, dtype=np.intp)
    order = np.argsort(s_all, kind="stable")
    return s_all[order], e_all[order]


def _tls_max_score(
    x: FloatArray, y: FloatArray, thr: FloatArray, starts: IntArray, ends: IntArray
) -> tuple[FloatArray, FloatArray]:
    """Largest ``distance / threshold`` of each range to its own TLS line, and the line angle."""
    idx, seg, offsets = _expand(starts, ends)
    k = starts.shape[0]
    cnt = (ends - starts + 1).astype(float)
    px, py = x[idx], y[idx]
    mx = np.bincount(seg, weights=px, minlength=k) / cnt
    my = np.bincount(seg, weights=py, minlength=k) / cnt
    dx = px - mx[seg]
    dy = py - my[seg]
    cxx = np.bincount(seg, weights=dx * dx, minlength=k)
    cyy = np.bincount(seg, weights=dy * dy, minlength=k)
    cxy = np.bincount(seg, weights=dx * dy, minlength=k)
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
    dist = np.abs(dx * np.cos(alpha)[seg] + dy * np.sin(alpha)[seg])
    return np.maximum.reduceat(dist / thr[idx], offsets), alpha


def _assign_corners(
    x: FloatArray, y: FloatArray, starts: IntArray, ends: IntArray
) -> tuple[IntArray, IntArray]:
    """Give each split point shared by two neighbouring pieces to the one whose line it is on.

    Each piece's total-least-squares line is fitted without the shared point; the point stays
    with the piece it is nearer to.  (A corner hit belongs to one face or the other; kept in
    both, it would bias the shorter piece's line.)
    """
    shared = np.flatnonzero(ends[:-1] == starts[1:])
    # only pieces that keep at least two points without the shared one
    shared = shared[
        (ends[shared] - starts[shared] >= 2) & (ends[shared + 1] - starts[shared + 1] >= 2)
    ]
    if shared.shape[0] == 0:
        return starts, ends
    k = ends[shared]
    left_s, left_e = starts[shared], k - 1
    right_s, right_e = k + 1, ends[shared + 1]
    both_s = np.concatenate([left_s, right_s])
    both_e = np.concatenate([left_e, right_e])
    idx, seg, _ = _expand(both_s, both_e)
    m = both_s.shape[0]
    cnt = (both_e - both_s + 1).astype(float)
    px, py = x[idx], y[idx]
    mx = np.bincount(seg, weights=px, minlength=m) / cnt
    my = np.bincount(seg, weights=py, minlength=m) / cnt
    dx, dy = px - mx[seg], py - my[seg]
    cxx = np.bincount(seg, weights=dx * dx, minlength=m)
    cyy = np.bincount(seg, weights=dy * dy, minlength=m)
    cxy = np.bincount(seg, weights=dx * dy, minlength=m)
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
    kk = np.concatenate([k, k])
    dist = np.abs((x[kk] - mx) * np.cos(alpha) + (y[kk] - my) * np.sin(alpha))
    n = shared.shape[0]
    to_left = dist[:n] <= dist[n:]
    starts = starts.copy()
    ends = ends.copy()
    starts[shared[to_left] + 1] += 1
    ends[shared[~to_left]] -= 1
    return starts, ends


def split_merge_groups(
    x: FloatArray,
    y: FloatArray,
    beam: IntArray,
    sigma_range: FloatArray,
    scan: IntArray | None = None,
    *,
    split_threshold_m: float,
    split_threshold_sigma: float,
    max_missing_beams: int,
    lambda_rad: float,
    sigma_factor: float,
    min_points: int,
) -> Grouping:
    """Group the points of one scan into candidate lines by split-and-merge.

    Parameters
    ----------
    x, y
        Valid scan points (m) in beam order, shape ``(n,)``; several scans may be
        concatenated (``scan``).
    beam
        Their beam indices.
    sigma_range
        Their range standard deviations ``σ_d`` (m).
    scan
        Scan of each point (non-decreasing); pieces never span two scans.  None: one scan.
    split_threshold_m, split_threshold_sigma
        A point splits a piece when farther from its chord than
        ``max(split_threshold_m, split_threshold_sigma · σ_d)``.
    max_missing_beams, lambda_rad, sigma_factor
        Breakpoint parameters (:func:`linefit.segments.breakpoint_mask`).
    min_points
        Pieces with fewer points are not returned.

    Returns
    -------
    Grouping
        One candidate line per piece, memberships sorted by piece (pieces in point order).
    """
    n = x.shape[0]
    if n < max(2, min_points):
        return Grouping.empty()
    thr = np.maximum(split_threshold_m, split_threshold_sigma * sigma_range)
    brk_mask = breakpoint_mask(
        x,
        y,
        beam,
        sigma_range,
        max_missing_beams=max_missing_beams,
        lambda_rad=lambda_rad,
        sigma_factor=sigma_factor,
    )
    if scan is not None:
        brk_mask |= scan[1:] != scan[:-1]
    brk = np.flatnonzero(brk_mask)
    starts = np.concatenate([[0], brk + 1]).astype(np.intp)
    ends = np.concatenate([brk, [n - 1]]).astype(np.intp)
    keep = ends - starts + 1 >= 2
    starts, ends = _chord_split(x, y, thr, starts[keep], ends[keep])

    # merge neighbouring pieces of one cluster while the union stays a line
    while starts.shape[0] >= 2:
        adjacent = np.flatnonzero(ends[:-1] == starts[1:])
        if adjacent.shape[0] == 0:
            break
        score, _ = _tls_max_score(x, y, thr, starts[adjacent], ends[adjacent + 1])
        ok = adjacent[score <= 1.0]
        if ok.shape[0] == 0:
            break
        # take non-overlapping pairs, best first is not needed: left to right is deterministic
        chosen: list[int] = []
        last = -2
        for a in ok.tolist():
            if a > last + 1:
                chosen.append(a)
                last = a
        sel = np.asarray(chosen, dtype=np.intp)
        ends[sel] = ends[sel + 1]
        drop = np.ones(starts.shape[0], dtype=bool)
        drop[sel + 1] = False
        starts, ends = starts[drop], ends[drop]

    starts, ends = _assign_corners(x, y, starts, ends)
    keep = ends - starts + 1 >= min_points
    starts, ends = starts[keep], ends[keep]
    if starts.shape[0] == 0:
        return Grouping.empty()
    _, alpha = _tls_max_score(x, y, thr, starts, ends)
    idx, seg, _ = _expand(starts, ends)
    return Grouping(idx, seg, int(starts.shape[0]), alpha)
