"""Visible extents of line landmarks in the world frame (for overlap gating and ``map.json``).

The overlap test itself is the graph's (:func:`slam.association.overlap_mask`).

A landmark is an infinite line; what the robot saw of it are pieces along it.  Each piece is
stored as its two world end points; to use them with the current estimate ``(r, α)`` of the
line they are projected on its tangent ``t(α) = (−sin α, cos α)``.  Pieces closer than
``gap_m`` along the line are merged (:func:`slam.lines.unite_segments`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.lines import unite_segments

__all__ = ["LandmarkExtents", "tangent_coordinates"]

FloatArray = NDArray[np.float64]


def tangent_coordinates(points_world: FloatArray, alpha: float | FloatArray) -> FloatArray:
    """Coordinates ``p · t(α)`` along line tangents (points ``(..., 2)``, angles ``(...)``)."""
    a = np.asarray(alpha, dtype=float)
    p = np.asarray(points_world, dtype=float)
    return -p[..., 0] * np.sin(a) + p[..., 1] * np.cos(a)


def _points_on_line(s: FloatArray, r: float, alpha: float) -> FloatArray:
    n = np.array([np.cos(alpha), np.sin(alpha)])
    t = np.array([-np.sin(alpha), np.cos(alpha)])
    return r * n + np.asarray(s, dtype=float)[..., None] * t


class LandmarkExtents:
    """The seen pieces of every landmark, in the world frame.

    Parameters
    ----------
    gap_m : float
        Pieces separated by less than this along the line are merged into one.
    """

    def __init__(self, gap_m: float):
        self.gap_m = float(gap_m)
        self._pieces: list[FloatArray] = []
        self._extreme = np.zeros((0, 2, 2))

    def __len__(self) -> int:
        return len(self._pieces)

    def append(self, ends_world: FloatArray) -> None:
        """Add a new landmark seen as the segment ``ends_world`` ``(2, 2)``."""
        ends = np.asarray(ends_world, dtype=float).reshape(1, 2, 2)
        self._pieces.append(ends.copy())
        self._extreme = np.concatenate([self._extreme, ends], axis=0)

    def pieces(self, j: int) -> FloatArray:
        """The stored pieces of landmark ``j`` as world end points, shape (k, 2, 2)."""
        return self._pieces[j].copy()

    def delete(self, j: int) -> None:
        """Forget landmark ``j`` (indices above it shift down by one)."""
        del self._pieces[j]
        self._extreme = np.delete(self._extreme, j, axis=0)

    def extend(self, j: int, r_alpha: FloatArray, ends_world: FloatArray) -> None:
        """Add the segment ``ends_world`` (2, 2) to landmark ``j`` whose line is ``r_alpha``."""
        self.absorb(j, r_alpha, np.asarray(ends_world, dtype=float).reshape(1, 2, 2))

    def absorb(self, j: int, r_alpha: FloatArray, pieces_world: FloatArray) -> None:
        """Add several pieces ``(k, 2, 2)`` to landmark ``j`` and merge along its line."""
        r, alpha = float(r_alpha[0]), float(r_alpha[1])
        allp = np.concatenate([self._pieces[j], pieces_world], axis=0)
        s = tangent_coordinates(allp, alpha)  # (k, 2)
        s_m, _ = unite_segments(s, np.zeros_like(s), self.gap_m)
        pieces = _points_on_line(s_m, r, alpha)  # (k, 2, 2)
        self._pieces[j] = pieces
        self._extreme[j] = _points_on_line(np.array([s_m[0, 0], s_m[-1, 1]]), r, alpha)

    def intervals(self, alpha: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Extreme extent ``(lo, hi)`` of each landmark along its tangent, shapes (M,)."""
        s = tangent_coordinates(self._extreme, np.asarray(alpha)[:, None])
        return s.min(axis=1), s.max(axis=1)

    def segments(self, j: int, r_alpha: FloatArray) -> FloatArray:
        """The pieces of landmark ``j`` as end points on the line ``r_alpha``; shape (k, 2, 2)."""
        r, alpha = float(r_alpha[0]), float(r_alpha[1])
        s = tangent_coordinates(self._pieces[j], alpha)
        s = np.sort(s, axis=1)
        return _points_on_line(s, r, alpha)
