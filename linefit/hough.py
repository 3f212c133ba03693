"""Grouping by the Hough transform (Sec. IV).

Each scan point ``(x, y)`` votes for every discretised line through it: for each normal angle
``β_j = j·Δβ ∈ [0, π)`` the signed distance ``ℛ = x cos β_j + y sin β_j = d cos(β_j − φ)``
(Eq. 28) falls in one of the bins ``[−ℛ_max, ℛ_max]`` of width ``Δℛ``, with ``ℛ_max`` the largest
valid range of the scan.  The votes of all points are accumulated at once (one ``bincount``
over the ``n × n_β`` cell indices), and the cell index of each vote is kept, so the points of
any cell are recoverable (paper: "when a cell is incremented, the coordinate of the associated
scan point is stored").

Peaks are then taken one after another:

1. the cell with the most votes of still unassigned points (stop below ``hough_min_votes``);
2. its points, together with the unassigned points within ``hough_gather_m`` of the cell's
   line (points of one wall straddle neighbouring ``ℛ`` bins), form a candidate;
3. a total-least-squares line through the candidate replaces the coarse cell line, and the
   unassigned points within ``hough_gather_m`` of it become the group (this recovers the
   parts of a long wall that the ``Δβ`` discretisation put in other cells); its angle is the
   grouping's estimate that starts the ML fit;
4. the group's points are removed: their votes are subtracted from the accumulator.

Defaults (1°, 5 cm, 5 votes, 5 cm) suit indoor scans with 0.25-1° beam spacing; the ML fit,
the per-point χ² gate and the segment rules of :mod:`linefit.segments` then decide the final
support of each line, so the Hough step only needs to be roughly right.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.grouping import Grouping

__all__ = ["hough_accumulator", "hough_groups"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def hough_accumulator(
    x: FloatArray, y: FloatArray, angle_step_rad: float, range_step_m: float
) -> tuple[NDArray[np.int64], IntArray, FloatArray, FloatArray, float]:
    """Vote all points into the ``(β, ℛ)`` accumulator.

    Parameters
    ----------
    x, y
        Point coordinates (m), shape ``(n,)``.
    angle_step_rad, range_step_m
        Cell size ``Δβ`` (rad) and ``Δℛ`` (m).

    Returns
    -------
    acc : ndarray of int64, shape (n_β · n_ℛ,)
        Vote counts, cell ``j·n_ℛ + i`` for angle bin ``j`` and distance bin ``i``.
    cells : ndarray of int, shape (n, n_β)
        The cell each point voted for at each angle.
    rho : ndarray, shape (n, n_β)
        The exact ``ℛ`` of each vote (m).
    betas : ndarray, shape (n_β,)
        The angle bins ``β_j`` (rad).
    r_max : float
        ``ℛ_max`` (m); distance bin ``i`` covers ``[−ℛ_max + i·Δℛ, −ℛ_max + (i+1)·Δℛ)``.
    """
    n_beta = max(1, round(np.pi / angle_step_rad))
    betas = np.arange(n_beta) * (np.pi / n_beta)
    r_max = float(np.sqrt(np.max(x * x + y * y))) + range_step_m
    n_rho = int(np.ceil(2.0 * r_max / range_step_m))
    rho = np.multiply.outer(x, np.cos(betas))
    rho += np.multiply.outer(y, np.sin(betas))
    bins = ((rho + r_max) * (1.0 / range_step_m)).astype(np.intp)
    np.clip(bins, 0, n_rho - 1, out=bins)
    bins += np.arange(n_beta, dtype=np.intp) * n_rho
    acc = np.bincount(bins.ravel(), minlength=n_beta * n_rho)
    return acc, bins, rho, betas, r_max


def hough_groups(
    x: FloatArray,
    y: FloatArray,
    *,
    angle_step_rad: float,
    range_step_m: float,
    min_votes: int,
    gather_m: float,
    max_peaks: int,
) -> Grouping:
    """Group the points of one scan into candidate lines by Hough peaks.

    Parameters
    ----------
    x, y
        Valid scan points (m), shape ``(n,)``.
    angle_step_rad, range_step_m
        Accumulator resolution ``Δβ``, ``Δℛ``.
    min_votes
        Smallest peak accepted (number of unassigned points in the cell).
    gather_m
        Distance (m) from the peak's line, then from the refined line, within which
        unassigned points join the group.
    max_peaks
        Cap on the number of peaks examined.

    Returns
    -------
    Grouping
        One candidate per accepted peak, with its refined normal angle.
    """
    n = x.shape[0]
    if n < max(2, min_votes):
        return Grouping.empty()
    acc, cells, rho, betas, r_max = hough_accumulator(x, y, angle_step_rad, range_step_m)
    n_rho = acc.shape[0] // betas.shape[0]
    alive = np.ones(n, dtype=bool)
    members: list[IntArray] = []
    alphas: list[float] = []
    for _ in range(max_peaks):
        c = int(acc.argmax())
        if acc[c] < min_votes:
            break
        j, i = divmod(c, n_rho)
        rho_c = (i + 0.5) * range_step_m - r_max
        cand = np.flatnonzero(alive & (np.abs(rho[:, j] - rho_c) <= max(gather_m, range_step_m)))
        alpha = float(betas[j])
        if cand.shape[0] >= 2:
            # refine: total least squares through the candidate, then recruit along it
            cx, cy = x[cand], y[cand]
            mx, my = cx.mean(), cy.mean()
            dx, dy = cx - mx, cy - my
            cxx, cyy, cxy = dx @ dx, dy @ dy, dx @ dy
            a_tls = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
            ca, sa = np.cos(a_tls), np.sin(a_tls)
            dist = np.abs((x - mx) * ca + (y - my) * sa)
            grp = np.flatnonzero(alive & (dist <= gather_m))
            if grp.shape[0] >= min_votes:
                cand = grp
                alpha = float(a_tls)
        alive[cand] = False
        np.subtract.at(acc, cells[cand].ravel(), 1)
        members.append(cand)
        alphas.append(alpha)
    return Grouping.from_lists(members, alphas)
