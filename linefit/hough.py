"""Grouping by the Hough transform (Sec. IV), vectorised over points, angles and scans.

Each scan point ``(x, y)`` votes for every discretised line through it: for each normal angle
``β_j = j·Δβ ∈ [0, π)`` the signed distance ``ℛ = x cos β_j + y sin β_j = d cos(β_j − φ)``
(Eq. 28) falls in one of the bins of width ``Δℛ`` covering ``[−ℛ_max, ℛ_max]``, with ``ℛ_max``
the largest valid range in the batch of scans.  All votes of all points of all scans are
accumulated at once (one ``bincount``), and the cell of every vote is kept, so the points of any
cell are recoverable (paper: "when a cell is incremented, the coordinate of the associated scan
point is stored").

Peaks are then taken one after another in every scan (all scans of the batch in lock step):

1. the cell with the most votes of still unassigned points (a scan stops below
   ``hough_min_votes``);
2. its points, together with the unassigned points within ``max(hough_gather_m, Δℛ)`` of the
   cell's line (points of one wall straddle neighbouring ``ℛ`` bins), form a candidate;
3. twice: a total-least-squares line through the current set replaces the coarse cell line, and
   the unassigned points within ``hough_gather_m`` of it become the set (this recovers the parts
   of a long wall that the ``Δβ`` discretisation put in other cells, and drops points that only
   shared the coarse cell); its angle is the grouping's estimate that starts the ML fit;
4. if at least ``hough_min_votes`` points remain, they are the group and are removed (their
   votes are subtracted from the accumulator); otherwise the peak cell is suppressed and its
   points stay free for other lines.

The ML fit, the per-point χ² gate and the segment rules of :mod:`linefit.segments` then decide
the final support of each line, so the Hough step only needs to be roughly right.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.grouping import Grouping

__all__ = ["hough_accumulator", "hough_groups"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


def hough_accumulator(
    x: FloatArray, y: FloatArray, valid: BoolArray, angle_step_rad: float, range_step_m: float
) -> tuple[NDArray[np.int32], IntArray, FloatArray, float]:
    """Vote the valid points of ``N`` scans into one ``(β, ℛ)`` accumulator per scan.

    Parameters
    ----------
    x, y
        Point coordinates (m), shape ``(N, n)`` (any values where not valid).
    valid
        Which points vote, shape ``(N, n)``.
    angle_step_rad, range_step_m
        Cell size ``Δβ`` (rad) and ``Δℛ`` (m).

    Returns
    -------
    acc : ndarray of int32, shape (N, n_β · n_ℛ)
        Vote counts; cell ``j·n_ℛ + i`` for angle bin ``j`` and distance bin ``i``.
    cells : ndarray of int, shape (N, n_β, n)
        The cell each point voted for at each angle, as an index into ``acc.reshape(-1)``
        (scan · n_β · n_ℛ + j · n_ℛ + i; meaningless where not valid).
    betas : ndarray, shape (n_β,)
        The angle bins ``β_j`` (rad).
    r_max : float
        ``ℛ_max`` (m), a multiple of ``Δℛ``; distance bin ``i`` covers
        ``[−ℛ_max + i·Δℛ, −ℛ_max + (i+1)·Δℛ)``.
    """
    n_scans = x.shape[0]
    n_beta = max(1, round(np.pi / angle_step_rad))
    betas = np.arange(n_beta, dtype=float) * (np.pi / n_beta)
    d2 = np.where(valid, x * x + y * y, 0.0)
    # bins anchored at ℛ = 0 (bin edges k·Δℛ), so a scan's cells do not depend on the batch
    half = int(np.ceil(np.sqrt(d2.max()) / range_step_m)) + 1 if d2.size else 1
    r_max = half * range_step_m
    n_rho = 2 * half
    # float32 is ample for bins of centimetres and halves the memory traffic
    # layout (scan, angle, point): the votes of one angle row are adjacent in memory.
    # |ℛ| ≤ range < (half − 1)·Δℛ, so bin + half is in [0, n_ℛ); float32 is ample for bins
    # of centimetres and halves the memory traffic.
    inv = 1.0 / range_step_m
    shifted = (np.cos(betas) * inv).astype(np.float32)[None, :, None] * x.astype(np.float32)[
        :, None, :
    ]
    shifted += (np.sin(betas) * inv).astype(np.float32)[None, :, None] * y.astype(np.float32)[
        :, None, :
    ]
    n_cells = n_beta * n_rho
    # flat cell index: scan · n_cells + angle bin · n_ℛ + distance bin.  The bin is floored
    # before the (batch-dependent) offset ``half`` is added: adding it in float32 first would
    # round a point near a bin edge differently depending on the other scans of the batch.
    np.floor(shifted, out=shifted)
    votes = shifted.astype(np.intp)
    votes += half
    votes += (
        np.arange(n_scans, dtype=np.intp)[:, None, None] * n_cells
        + np.arange(n_beta, dtype=np.intp)[None, :, None] * n_rho
    )
    acc = np.zeros(n_scans * n_cells, dtype=np.int32)
    weight = np.broadcast_to(valid.astype(np.int32)[:, None, :], votes.shape)
    np.add.at(acc, votes.reshape(-1), weight.reshape(-1))  # invalid points add 0
    return acc.reshape(n_scans, n_cells), votes, betas, r_max


def hough_groups(
    x: FloatArray,
    y: FloatArray,
    valid: BoolArray,
    *,
    angle_step_rad: float,
    range_step_m: float,
    min_votes: int,
    gather_m: float,
    max_peaks: int,
) -> tuple[Grouping, IntArray]:
    """Group the points of ``N`` scans into candidate lines by Hough peaks.

    Parameters
    ----------
    x, y
        Scan points (m), shape ``(N, n)``.
    valid
        Which points take part, shape ``(N, n)``.
    angle_step_rad, range_step_m
        Accumulator resolution ``Δβ``, ``Δℛ``.
    min_votes
        Smallest peak accepted (number of unassigned points in the cell).
    gather_m
        Distance (m) from the peak's line, then from the refined line, within which
        unassigned points join the group.
    max_peaks
        Cap on the number of peaks taken per scan.

    Returns
    -------
    grouping : Grouping
        Memberships refer to the flattened ``(N·n)`` point index ``scan·n + beam``.
    group_scan : ndarray of int, shape (n_groups,)
        The scan of each candidate line.
    """
    n_scans, n = x.shape
    if n_scans == 0 or n < 2 or not valid.any():
        return Grouping.empty(), np.zeros(0, dtype=np.intp)
    acc, cells, betas, _ = hough_accumulator(x, y, valid, angle_step_rad, range_step_m)
    cos_b, sin_b = np.cos(betas), np.sin(betas)
    n_rho = acc.shape[1] // betas.shape[0]
    half = n_rho // 2  # r_max = half · Δℛ
    alive = valid.copy()
    tol_peak = max(gather_m, range_step_m)
    out_scan: list[IntArray] = []
    out_point: list[IntArray] = []
    out_group_scan: list[IntArray] = []
    out_alpha: list[FloatArray] = []
    active = np.ones(n_scans, dtype=bool)
    # per point: 1, x, y, x², xy, y² (the TLS sums of any subset are one matrix product)
    moments = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    for _ in range(max_peaks):
        rows = np.flatnonzero(active)
        if rows.shape[0] == 0:
            break
        few = 2 * rows.shape[0] < n_scans  # then copying the active rows is cheaper
        best = acc[rows].argmax(axis=1) if few else acc.argmax(axis=1)[rows]
        votes = acc[rows, best]
        go = votes >= min_votes
        active[rows[~go]] = False
        rows, best = rows[go], best[go]
        if rows.shape[0] == 0:
            break
        j, i = np.divmod(best, n_rho)
        # bin centre from the bin's signed index (not ``… − r_max``, whose rounding would
        # depend on the batch's ``r_max`` and flip points at ``tol_peak`` between batches)
        rho_c = (i - half + 0.5) * range_step_m
        # candidate: unassigned points near the cell's line
        rho_j = x[rows] * cos_b[j][:, None] + y[rows] * sin_b[j][:, None]
        cand = alive[rows] & (np.abs(rho_j - rho_c[:, None]) <= tol_peak)
        # refine twice: total least squares through the current set, recruit along it
        xs, ys, alive_r = x[rows], y[rows], alive[rows]
        moments_r = moments[rows]
        grp = cand
        alpha = betas[j]
        for _ in range(2):
            m = np.matmul(grp[:, None, :].astype(float), moments_r)[:, 0, :]
            cnt = np.maximum(m[:, 0], 1.0)
            mx, my = m[:, 1] / cnt, m[:, 2] / cnt
            cxx = m[:, 3] - cnt * mx * mx
            cxy = m[:, 4] - cnt * mx * my
            cyy = m[:, 5] - cnt * my * my
            alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
            ca, sa = np.cos(alpha), np.sin(alpha)
            dist = np.abs(xs * ca[:, None] + ys * sa[:, None] - (mx * ca + my * sa)[:, None])
            grp = alive_r & (dist <= gather_m)
        ok = grp.sum(axis=1) >= min_votes
        # a peak whose refined line keeps too few points is suppressed, its points stay free
        acc[rows[~ok], best[~ok]] = np.iinfo(np.int32).min // 2
        rows, grp, alpha = rows[ok], grp[ok], alpha[ok]
        if rows.shape[0] == 0:
            continue
        # record and remove
        g_row, g_pt = np.nonzero(grp)
        out_scan.append(rows[g_row])
        out_point.append(g_pt)
        out_group_scan.append(rows)
        out_alpha.append(alpha)
        alive[rows[g_row], g_pt] = False
        flat = cells[rows[g_row], :, g_pt].ravel()
        np.add.at(acc.reshape(-1), flat, np.full(flat.shape[0], -1, dtype=np.int32))
    if not out_group_scan:
        return Grouping.empty(), np.zeros(0, dtype=np.intp)
    # number the groups scan by scan, and sort memberships by group
    group_scan = np.concatenate(out_group_scan)
    alpha_all = np.concatenate(out_alpha)
    sizes = np.array([a.shape[0] for a in out_group_scan])
    iter_offset = np.cumsum(sizes) - sizes
    # group id (in creation order) of each membership: offset of its iteration + rank of its scan
    m_scan = np.concatenate(out_scan)
    m_point = np.concatenate(out_point)
    m_group = np.concatenate(
        [
            off + np.searchsorted(rows_k, s_k)
            for off, rows_k, s_k in zip(iter_offset, out_group_scan, out_scan, strict=True)
        ]
    )
    order_g = np.lexsort((np.arange(group_scan.shape[0]), group_scan))
    new_id = np.empty_like(order_g)
    new_id[order_g] = np.arange(order_g.shape[0])
    gidx = new_id[m_group]
    pidx = m_scan * n + m_point
    order_m = np.lexsort((pidx, gidx))
    return (
        Grouping(pidx[order_m], gidx[order_m], int(group_scan.shape[0]), alpha_all[order_g]),
        group_scan[order_g],
    )
