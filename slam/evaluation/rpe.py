"""Relative pose error over travelled distances (as evo's ``rpe`` with ``--delta_unit m``).

Pairs ``(i, j)`` are chosen on the ground truth's travelled path ``d`` (cumulative distance of
its positions, in the estimate's order): for each start ``i``, ``j`` is the pose whose path
distance from ``i`` is nearest to ``delta_m``, accepted within ``±tolerance·delta_m``
(``all_pairs=True``); or, by default, consecutive non-overlapping pairs starting at pose 0,
each ``j`` the first pose at least ``delta_m`` further along.  The error of a pair is

    E_ij = (Q_i⁻¹ Q_j)⁻¹ · (P_i⁻¹ P_j)

(``Q`` truth, ``P`` estimate); reported: statistics of ``|t(E)|`` (m) and ``|θ(E)|`` (deg).
RPE needs no global alignment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import EvaluationError
from slam.evaluation.stats import ErrorStats
from slam.evaluation.timestamps import associate
from slam.geometry import pose_between, pose_compose, pose_inverse, wrap_angle
from slam.io.trajectory import Trajectory

__all__ = ["RpeResult", "distance_pairs", "rpe", "rpe_errors"]


@dataclass(frozen=True)
class RpeResult:
    """RPE for one distance ``delta_m``."""

    delta_m: float
    all_pairs: bool
    translation_m: ErrorStats
    rotation_deg: ErrorStats

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy."""
        return {
            "delta_m": self.delta_m,
            "all_pairs": self.all_pairs,
            "n_pairs": self.translation_m.n,
            "translation_m": self.translation_m.to_dict(),
            "rotation_deg": self.rotation_deg.to_dict(),
        }


def distance_pairs(
    positions: NDArray[np.float64],
    delta_m: float,
    *,
    all_pairs: bool = False,
    tolerance: float = 0.1,
) -> NDArray[np.int64]:
    """Index pairs ``(i, j)`` about ``delta_m`` of travelled path apart (module docstring)."""
    if not delta_m > 0.0:
        raise EvaluationError(f"delta_m must be > 0, got {delta_m}")
    steps = np.hypot(*np.diff(positions, axis=0).T) if len(positions) > 1 else np.zeros(0)
    d = np.concatenate([[0.0], np.cumsum(steps)])
    n = d.size
    if all_pairs:
        i = np.arange(n)
        hi = np.searchsorted(d, d + delta_m, side="left")
        lo = hi - 1
        hi_c = np.clip(hi, 0, n - 1)
        err_hi = np.where(hi < n, np.abs(d[hi_c] - d - delta_m), np.inf)
        err_lo = np.where(lo > i, np.abs(d[np.clip(lo, 0, n - 1)] - d - delta_m), np.inf)
        j = np.where(err_hi <= err_lo, hi_c, lo)
        ok = (np.minimum(err_hi, err_lo) <= tolerance * delta_m) & (j > i)
        return np.column_stack([i[ok], j[ok]]).astype(np.int64)
    pairs: list[tuple[int, int]] = []
    start = 0
    while True:  # one iteration per pair (path length / delta), not per pose
        end = int(np.searchsorted(d, d[start] + delta_m, side="left"))
        if end >= n:
            break
        pairs.append((start, end))
        start = end
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)


def rpe(
    estimate: Trajectory,
    ground_truth: Trajectory,
    delta_m: float = 1.0,
    *,
    all_pairs: bool = False,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> RpeResult:
    """RPE of ``estimate`` against ``ground_truth`` over ``delta_m`` of travelled path."""
    error = rpe_errors(
        estimate,
        ground_truth,
        delta_m,
        all_pairs=all_pairs,
        tolerance_s=tolerance_s,
        max_unmatched_fraction=max_unmatched_fraction,
    )
    return RpeResult(
        delta_m=float(delta_m),
        all_pairs=all_pairs,
        translation_m=ErrorStats.of(np.hypot(error[:, 0], error[:, 1])),
        rotation_deg=ErrorStats.of(np.degrees(np.abs(wrap_angle(error[:, 2])))),
    )


def rpe_errors(
    estimate: Trajectory,
    ground_truth: Trajectory,
    delta_m: float = 1.0,
    *,
    all_pairs: bool = False,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> NDArray[np.float64]:
    """The relative pose errors ``E_ij`` of :func:`rpe`, one row ``(x, y, θ)`` per pair.

    For statistics :class:`ErrorStats` does not give (percentiles, the worst pairs).
    """
    i_est, i_ref, _ = associate(
        estimate,
        ground_truth,
        tolerance_s=tolerance_s,
        max_unmatched_fraction=max_unmatched_fraction,
    )
    est = estimate.poses[i_est]
    ref = ground_truth.poses[i_ref]
    pairs = distance_pairs(ref[:, :2], delta_m, all_pairs=all_pairs)
    if pairs.shape[0] == 0:
        raise EvaluationError(f"the ground truth travels less than delta = {delta_m} m")
    rel_ref = pose_between(ref[pairs[:, 0]], ref[pairs[:, 1]])
    rel_est = pose_between(est[pairs[:, 0]], est[pairs[:, 1]])
    return np.asarray(pose_compose(pose_inverse(rel_ref), rel_est), dtype=np.float64)
