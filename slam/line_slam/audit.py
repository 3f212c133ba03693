"""Merge audits: undo a merge (fusion or loop closure) that the estimate does not explain.

After a merge the optimum of a wrong one sits on one side and the other side's measurements
are all off; so both sides of a merged landmark (the factors that came with the dropped
landmark, and the kept landmark's others) must have a median whitened squared residual below
``fusion.audit_max_median_chi2`` (χ²₂ 99 %: 9.21).  An undone pair is vetoed: fusion never
merges it again.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.graph.factors import line_factor_residuals
from slam.graph.odometry import between_costs
from slam.graph.problem import LineGraph, MergeRecord
from slam.graph.robust import RobustKernel, robust_cost
from slam.line_slam.config import FusionConfig
from slam.line_slam.landmarks import LandmarkBook

__all__ = ["MergeAudit", "residual_chi2"]

FloatArray = NDArray[np.float64]


def residual_chi2(
    graph: LineGraph, from_pose: int = 0, kernel: RobustKernel = "none", k: float = 1.0
) -> tuple[float, float, FloatArray]:
    """Squared whitened residuals of the graph at its estimate.

    Returns the χ² total over the line factors of poses from ``from_pose`` on and the
    odometry factors ending there; the same total in the cost the solver minimises, each line
    factor adding ``2 ρ(‖e‖)`` of the robust ``kernel`` (``k`` in standard deviations,
    :mod:`slam.graph.robust`; χ² units; the odometry factors are never robustified) instead
    of ``‖e‖²``; and each of those line factors' own χ² (2 dof).
    """
    g = graph
    line = np.zeros(0)
    f = np.flatnonzero(g.factor_pose >= from_pose)
    if f.size:
        lm = g.factor_landmark[f]
        ew = line_factor_residuals(
            g.poses[g.factor_pose[f]],
            g.landmarks[lm],
            g.anchors[lm],
            g.factor_z[f],
            g.factor_sqrt_info[f],
        )
        line = np.sum(ew**2, axis=1)
    odo = 0.0
    e = np.flatnonzero(g.odometry_second >= from_pose)
    if e.size:
        odo = 2.0 * float(
            np.sum(
                between_costs(
                    g.poses[g.odometry_first[e]],
                    g.poses[g.odometry_second[e]],
                    g.odometry_measured[e],
                    g.odometry_sqrt_info[e],
                )
            )
        )
    robust = float(np.sum(2.0 * robust_cost(kernel, np.sqrt(line), k))) if line.size else 0.0
    return float(line.sum()) + odo, robust + odo, line


class MergeAudit:
    """Checks merges against the current estimate and undoes the unexplained ones.

    Attributes
    ----------
    vetoed : set of (int, int)
        Pairs ``(min, max)`` of landmarks whose merge was undone.
    counters : dict
        The run's counters; ``merges_undone`` is counted here.
    """

    def __init__(self, book: LandmarkBook, config: FusionConfig, counters: dict[str, int]) -> None:
        self.book = book
        self.config = config
        self.counters = counters
        self.vetoed: set[tuple[int, int]] = set()

    def chi2(self, rec: MergeRecord) -> float | None:
        """The larger of a merge's two sides' median whitened squared residuals.

        None when the merge is no longer checkable (undone, superseded, or one side empty).
        """
        g = self.book.graph
        if rec.undo or not g.landmark_alive[rec.keep] or g.landmark_alive[rec.drop]:
            return None
        if not np.all(g.factor_landmark[rec.factors] == rec.keep):
            return None
        f_keep = np.flatnonzero(g.factor_landmark == rec.keep)
        other = np.setdiff1d(f_keep, rec.factors)
        if other.size == 0 or rec.factors.size == 0:
            return None
        lm = g.factor_landmark[f_keep]
        ew = line_factor_residuals(
            g.poses[g.factor_pose[f_keep]],
            g.landmarks[lm],
            g.anchors[lm],
            g.factor_z[f_keep],
            g.factor_sqrt_info[f_keep],
        )
        c2 = np.sum(ew**2, axis=1)
        side = np.isin(f_keep, rec.factors)
        return float(max(np.median(c2[side]), np.median(c2[~side])))

    def consistent(self, rec: MergeRecord) -> bool | None:
        """Whether a merge is explained by the current estimate (None: no longer checkable)."""
        worst = self.chi2(rec)
        if worst is None:
            return None
        return worst <= self.config.audit_max_median_chi2

    def audit(self, records: list[MergeRecord]) -> int:
        """Undo the merges among ``records`` that the estimate does not explain.

        Returns how many were undone; an undone pair is vetoed.
        """
        g = self.book.graph
        undone = []
        for rec in records:
            if self.consistent(rec) is False:
                g.unmerge(rec)
                undone.append(rec)
                self.vetoed.add((min(rec.keep, rec.drop), max(rec.keep, rec.drop)))
        if undone:
            self.book.recompute_info(
                np.array(sorted({r.keep for r in undone} | {r.drop for r in undone}))
            )
            self.book.refresh_extents()
            self.counters["merges_undone"] += len(undone)
        return len(undone)
