"""Pairing poses of two trajectories, or relation stamps with poses, by exact time stamp."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, EvaluationError
from slam.io.trajectory import Trajectory

__all__ = ["associate", "check_unmatched_fraction", "match_timestamps"]

FloatArray = NDArray[np.float64]


def match_timestamps(
    query: FloatArray, timestamps: FloatArray, tolerance_s: float
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Index of the time stamp nearest to each query, and whether it is within tolerance.

    Works for time stamps in any order (Intel's go backwards); no interpolation.

    Raises
    ------
    ConfigError
        ``tolerance_s`` is negative or NaN.
    """
    if not tolerance_s >= 0.0:  # NaN too (it would match nothing); inf: the nearest stamp
        raise ConfigError(f"time tolerance must be >= 0 s, got {tolerance_s!r}")
    t = np.asarray(timestamps, dtype=np.float64)
    q = np.asarray(query, dtype=np.float64)
    if t.size == 0:
        return np.zeros(q.shape, np.int64), np.zeros(q.shape, bool)
    order = np.argsort(t, kind="stable")
    sorted_t = t[order]
    pos = np.searchsorted(sorted_t, q)
    lo = np.clip(pos - 1, 0, t.size - 1)
    hi = np.clip(pos, 0, t.size - 1)
    pick_hi = np.abs(sorted_t[hi] - q) < np.abs(sorted_t[lo] - q)
    nearest = np.where(pick_hi, hi, lo)
    found = np.abs(sorted_t[nearest] - q) <= tolerance_s
    return order[nearest].astype(np.int64), found


def check_unmatched_fraction(fraction: float) -> None:
    """Raise :class:`~slam.errors.ConfigError` unless ``0 <= fraction <= 1`` (NaN raises too)."""
    if not 0.0 <= fraction <= 1.0:
        raise ConfigError(f"max_unmatched_fraction must be in [0, 1], got {fraction!r}")


def associate(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Pair each estimated pose with the reference pose of the same time stamp.

    Returns ``(i_estimate, i_reference, n_unmatched)`` in the estimate's order.  Estimated
    poses without a reference pose within ``tolerance_s`` are left out and counted; more than
    ``max_unmatched_fraction`` of them raise :class:`~slam.errors.EvaluationError` (a time
    stamp mistake).
    """
    check_unmatched_fraction(max_unmatched_fraction)
    idx, found = match_timestamps(estimate.timestamps, reference.timestamps, tolerance_s)
    n = len(estimate)
    n_unmatched = int(n - found.sum())
    if n == 0 or n_unmatched > max_unmatched_fraction * n or not found.any():
        raise EvaluationError(
            f"{n_unmatched} of {n} estimated poses have no ground-truth pose with the same time "
            f"stamp (|dt| <= {tolerance_s:g} s; allowed {max_unmatched_fraction:.0%}): a time "
            "stamp mistake, or ground truth of another run?"
        )
    return np.flatnonzero(found).astype(np.int64), idx[found], n_unmatched
