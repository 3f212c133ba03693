"""The result of a grouping step: which points support which candidate line."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Grouping", "tls_line"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class Grouping:
    """Candidate lines as memberships.

    Attributes
    ----------
    pidx : ndarray of int, shape (m,)
        Point index (into the scan's valid points) of each membership.
    gidx : ndarray of int, shape (m,)
        Candidate line of each membership, ``0..n_groups-1``.
    n_groups : int
        Number of candidate lines.
    alpha0 : ndarray, shape (n_groups,)
        The grouping's estimate of each line's normal angle (rad), the start of the ML fit.
    """

    pidx: IntArray
    gidx: IntArray
    n_groups: int
    alpha0: FloatArray

    @classmethod
    def empty(cls) -> Grouping:
        """No candidate lines."""
        z = np.zeros(0, dtype=np.intp)
        return cls(z, z.copy(), 0, np.zeros(0))

    @classmethod
    def from_lists(cls, members: list[IntArray], alphas: list[float]) -> Grouping:
        """Build from one index array per candidate line."""
        if not members:
            return cls.empty()
        pidx = np.concatenate(members).astype(np.intp)
        sizes = np.array([m.shape[0] for m in members])
        gidx = np.repeat(np.arange(len(members), dtype=np.intp), sizes)
        return cls(pidx, gidx, len(members), np.asarray(alphas, dtype=float))


def tls_line(x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Unweighted total-least-squares line ``(r, α)`` of a few points, ``r ≥ 0``.

    Parameters
    ----------
    x, y
        Coordinates (m), at least two distinct points.

    Returns
    -------
    r, alpha : float
        Distance (m) and normal angle (rad) of the line.
    """
    mx = float(np.mean(x))
    my = float(np.mean(y))
    dx = x - mx
    dy = y - my
    cxx = float(dx @ dx)
    cyy = float(dy @ dy)
    cxy = float(dx @ dy)
    alpha = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy) + 0.5 * np.pi
    r = mx * np.cos(alpha) + my * np.sin(alpha)
    if r < 0.0:
        r = -r
        alpha += np.pi
    alpha = float(np.pi - np.mod(np.pi - alpha, 2.0 * np.pi))
    return float(r), alpha
