"""Breakpoints between neighbouring points, and the visible segments of a fitted line.

Breakpoints (range jumps and gaps)
----------------------------------
Two points ``i, j`` that are neighbours (in beam order for a scan, along the line for a fitted
line) belong to the same surface only if

* at most ``max_missing_beams`` beams lie between them (a gap of more beams is a door, an
  opening or an occluder: the surface is not visible there), and
* they are closer than the adaptive breakpoint distance of Borges & Aldon (2004),
  ``d_near · sin Δφ / sin(λ − Δφ) + k_σ · σ_d`` with ``d_near`` the smaller of the two ranges,
  ``Δφ`` their bearing difference and ``λ`` the most grazing angle between beam and surface
  still accepted (``breakpoint_lambda_rad``; walls seen at more than ``90° − λ`` incidence are
  broken up).  This is the exact spacing of two hits on a surface seen at grazing angle ``λ``
  (law of sines), plus the range noise.  A range jump between adjacent beams is a breakpoint of
  this kind.

Segments
--------
The supporting points of a fitted line, sorted by ``u_S``, are cut at breakpoints; pieces with
fewer than ``min_segment_points`` points are dropped from the line (they are collinear with it
by accident, e.g. clutter across a room).  Each remaining piece is one row of
:attr:`linefit.Line.segments_s`: ``(u_S of the first point, u_S of the last point)``, with the
endpoint variances of :mod:`linefit.covariance`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["breakpoint_mask", "segment_ids"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def breakpoint_mask(
    x: FloatArray,
    y: FloatArray,
    beam: IntArray,
    sigma_range: FloatArray,
    *,
    max_missing_beams: int,
    lambda_rad: float,
    sigma_factor: float,
) -> NDArray[np.bool_]:
    """True between neighbours ``(k, k+1)`` that do not belong to the same surface.

    Parameters
    ----------
    x, y
        Coordinates (m) of the points in neighbour order, shape ``(n,)``.
    beam
        Beam index of each point, shape ``(n,)``.
    sigma_range
        Range standard deviation ``σ_d`` of each point (m), shape ``(n,)``.
    max_missing_beams
        Largest number of beams allowed between two neighbours.
    lambda_rad
        Most grazing beam-to-surface angle accepted (rad), in ``(0, π/2]``.
    sigma_factor
        Multiple of ``σ_d`` added to the breakpoint distance.

    Returns
    -------
    ndarray of bool, shape (n - 1,)
    """
    if x.shape[0] < 2:
        return np.zeros(0, dtype=bool)
    d = np.hypot(x, y)
    phi = np.arctan2(y, x)
    dphi = np.abs(np.diff(phi))
    dphi = np.minimum(dphi, 2.0 * np.pi - dphi)
    d_near = np.minimum(d[:-1], d[1:])
    gap = np.hypot(np.diff(x), np.diff(y))
    missing = np.abs(np.diff(beam)) - 1
    sin_margin = np.sin(np.maximum(lambda_rad - dphi, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        limit = d_near * np.sin(dphi) / sin_margin
    limit = limit + sigma_factor * np.maximum(sigma_range[:-1], sigma_range[1:])
    too_far = (dphi >= lambda_rad) | ~(gap <= limit)
    return (missing > max_missing_beams) | too_far


def segment_ids(
    x: FloatArray,
    y: FloatArray,
    beam: IntArray,
    sigma_range: FloatArray,
    gidx: IntArray,
    u_s: FloatArray,
    *,
    max_missing_beams: int,
    lambda_rad: float,
    sigma_factor: float,
) -> tuple[IntArray, IntArray]:
    """Cut every line's memberships into segments.

    Parameters
    ----------
    x, y, beam, sigma_range
        Per-membership point coordinates (m), beam index and ``σ_d`` (m), shape ``(m,)``.
    gidx
        Group (line) of each membership.
    u_s
        Position of each membership along its line (m).
    max_missing_beams, lambda_rad, sigma_factor
        Breakpoint parameters (see :func:`breakpoint_mask`).

    Returns
    -------
    order : ndarray of int, shape (m,)
        Memberships sorted by line, then by ``u_S``.
    seg : ndarray of int, shape (m,)
        Segment number (0, 1, ... over all lines, in ``order``) of each sorted membership.
    """
    order = np.lexsort((u_s, gidx))
    if order.shape[0] == 0:
        return order, np.zeros(0, dtype=np.intp)
    g = gidx[order]
    brk = breakpoint_mask(
        x[order],
        y[order],
        beam[order],
        sigma_range[order],
        max_missing_beams=max_missing_beams,
        lambda_rad=lambda_rad,
        sigma_factor=sigma_factor,
    )
    new_seg = np.empty(order.shape[0], dtype=bool)
    new_seg[0] = True
    new_seg[1:] = brk | (g[1:] != g[:-1])
    seg = np.cumsum(new_seg) - 1
    return order, seg
