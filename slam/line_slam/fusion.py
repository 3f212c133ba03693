"""Landmark fusion: merging graph landmarks that turn out to be one wall.

Every ``fusion.interval_keyframes`` keyframes (and over the whole map at
:meth:`LineSlam.optimize`) the landmarks seen since the last round are tested against the alive
landmarks near the robot.

1. **Candidates** (:func:`fusion_candidates`, a vectorised pre-filter over pairs): normals that
   differ by less than ``max_angle_rad`` modulo π, the mid-point of one's extent within
   ``max_distance_m`` of the other line, extents along the line that overlap or leave a gap of
   at most ``max_gap_m``.  During the run, pairs whose last sightings are further apart in drift
   (:mod:`slam.line_slam.drift`) than ``frontend.max_drift_xy_m`` are left to loop closing.
2. **Test**: the paper's merge test (Eqs. 34-35, :func:`slam.association.landmarks_compatible`)
   on the two landmarks' covariances relative to the poses that saw them, the second one
   widened by the drift between their last sightings (no joint marginal is needed: both are
   measured relative to nearby poses).
3. **Merge**, best first (smallest ``D²``): the landmark with more observations is kept and the
   other's factors are rewired to it (:meth:`LandmarkBook.merge`); a landmark may absorb several
   others in one round but is never absorbed after absorbing.  Pairs whose merge an audit undid
   (:mod:`slam.line_slam.audit`) are never merged again.  The round's merges are audited at the
   next round, once the estimate has absorbed them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.association import candidate_landmarks, landmarks_compatible
from slam.graph.problem import LineGraph, MergeRecord
from slam.line_slam.audit import MergeAudit
from slam.line_slam.clock import StageClock
from slam.line_slam.config import FusionConfig, SlamConfig
from slam.line_slam.drift import DriftAccumulator
from slam.line_slam.keyframes import EveryKeyframes
from slam.line_slam.landmarks import LandmarkBook
from slam.models.anchored import anchored_jacobian, drift_covariance

__all__ = ["LandmarkFusion", "fusion_candidates"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def fusion_candidates(
    graph: LineGraph,
    extents: FloatArray,
    subset: IntArray,
    config: FusionConfig,
    others: IntArray | None = None,
) -> list[tuple[int, int]]:
    """Pairs of landmarks that pass the geometric pre-filter of the module docstring.

    One landmark of each pair is in ``subset`` (e.g. the recently observed ones), the other is
    any alive landmark (or any in ``others``, e.g. those near the robot); pairs are returned as
    sorted ``(a, b)`` with ``a < b``.
    """
    alive = np.flatnonzero(graph.landmark_alive & np.isfinite(extents).all(axis=1))
    if others is not None:
        alive = np.intersect1d(alive, np.union1d(np.asarray(others, dtype=np.intp), subset))
    sub = np.intersect1d(np.asarray(subset, dtype=np.intp), alive)
    if sub.size == 0 or alive.size < 2:
        return []
    la = graph.landmarks_r_alpha
    c = graph.anchors
    # mid-points of the extents in the world
    t = np.stack([-np.sin(la[:, 1]), np.cos(la[:, 1])], -1)
    n = np.stack([np.cos(la[:, 1]), np.sin(la[:, 1])], -1)
    foot = c + (la[:, 0] - np.sum(c * n, axis=1))[:, None] * n  # anchor projected on the line
    mid = foot + (0.5 * (extents[:, 0] + extents[:, 1]))[:, None] * t
    A, B = sub[:, None], alive[None, :]
    d_alpha = np.abs(np.asarray(wrap_angle(la[A, 1] - la[B, 1])))
    d_alpha = np.minimum(d_alpha, np.pi - d_alpha)
    # distance of each one's mid-point from the other line (both ways)
    dist_ab = np.abs(np.sum(mid[A] * n[B], axis=-1) - la[B, 0])
    dist_ba = np.abs(np.sum(mid[B] * n[A], axis=-1) - la[A, 0])
    # extents of both along a's tangent, from a's anchor
    half_b = 0.5 * (extents[B, 1] - extents[B, 0])
    s_mid_b = np.sum((mid[B] - c[A]) * t[A], axis=-1)
    proj = np.abs(np.sum(t[A] * t[B], axis=-1))
    lo_b, hi_b = s_mid_b - proj * half_b, s_mid_b + proj * half_b
    gap = np.maximum(extents[A, 0], lo_b) - np.minimum(extents[A, 1], hi_b)
    ok = (d_alpha <= config.max_angle_rad) & (np.maximum(dist_ab, dist_ba) <= config.max_distance_m)
    ok &= gap <= config.max_gap_m
    ok &= A != B
    ia, ib = np.nonzero(ok)
    pairs = {
        (int(min(sub[i], alive[j])), int(max(sub[i], alive[j])))
        for i, j in zip(ia, ib, strict=True)
    }
    return sorted(pairs)


class LandmarkFusion:
    """Fusion rounds over the landmark book (module docstring).

    Parameters
    ----------
    book, drift, audit
        The run's landmark book, drift accumulator and merge audit.
    config : SlamConfig
        ``fusion``, ``association.max_range_m`` and the front end's drift model.
    counters : dict
        The run's counters (``landmarks_merged``).
    clock : StageClock
        Times the rounds (``fusion``).
    """

    def __init__(
        self,
        book: LandmarkBook,
        drift: DriftAccumulator,
        audit: MergeAudit,
        config: SlamConfig,
        counters: dict[str, int],
        clock: StageClock,
    ) -> None:
        self.book = book
        self.drift = drift
        self.audit = audit
        self.config = config
        self.counters = counters
        self.clock = clock
        self.pending_audit: list[MergeRecord] = []
        """The last round's merges, audited at the next round (or at the end)."""
        self._every = EveryKeyframes()

    def due(self) -> bool:
        """Count a keyframe; whether a round is due (every ``fusion.interval_keyframes``)."""
        return self._every.tick(self.config.fusion.enabled, self.config.fusion.interval_keyframes)

    def round(self, x_now: FloatArray, everywhere: bool = False) -> int:
        """One fusion round near ``x_now`` (over all alive landmarks with ``everywhere``).

        Returns the number of merges.
        """
        with self.clock("fusion"):
            return self._round(x_now, everywhere)

    def _round(self, x_now: FloatArray, everywhere: bool) -> int:
        cfg = self.config
        book = self.book
        g = book.graph
        if self.pending_audit:
            self.audit.audit(self.pending_audit)
            self.pending_audit = []
        n_log = len(g.merge_log)
        alive = book.alive_with_extent()
        if everywhere:
            subset = np.flatnonzero(alive)
            others = subset
        else:
            recent_from = g.n_poses - cfg.fusion.interval_keyframes
            subset = np.flatnonzero(alive & (book.last_keyframe >= recent_from))
            others = candidate_landmarks(
                x_now,
                g.landmarks_r_alpha,
                book.extents,
                cfg.association.max_range_m,
                alive=alive,
                anchors=g.anchors,
            )
        pairs = fusion_candidates(g, book.extents, subset, cfg.fusion, others=others)
        merged = 0
        if pairs:
            merged = self._test_and_merge(pairs, everywhere)
        if merged:
            self.counters["landmarks_merged"] += merged
            book.refresh_extents()
            self.pending_audit = list(g.merge_log[n_log:])
        return merged

    def _test_and_merge(self, pairs: list[tuple[int, int]], everywhere: bool) -> int:
        cfg = self.config
        book = self.book
        g = book.graph
        a = np.array([p[0] for p in pairs])
        b = np.array([p[1] for p in pairs])
        la = g.landmarks_r_alpha
        # drift between their last sightings
        last = book.last_keyframe
        sxy, sth = self.drift.between(last[a], last[b])
        if not everywhere:
            # far apart in drift: loop closing's job (submap verification), not fusion's
            near = sxy <= cfg.frontend.max_drift_xy_m
            a, b, sxy, sth = a[near], b[near], sxy[near], sth[near]
        Pa = book.covariance(a)
        Pb = book.covariance(b)
        # the drift rotates b about the robot where it last saw b
        seen_from = g.poses[last[b], :2]
        Pb = Pb + drift_covariance(
            g.landmarks[b],
            g.anchors[b],
            seen_from,
            sxy,
            sth,
        )
        Ja = anchored_jacobian(g.landmarks[a], g.anchors[a])
        Jb = anchored_jacobian(g.landmarks[b], g.anchors[b])
        Pa = Ja @ Pa @ np.swapaxes(Ja, -1, -2)
        Pb = Jb @ Pb @ np.swapaxes(Jb, -1, -2)
        tested = []
        for k in range(a.size):
            if (int(a[k]), int(b[k])) in self.audit.vetoed:
                continue
            P = np.zeros((4, 4))
            P[:2, :2] = Pa[k]
            P[2:, 2:] = Pb[k]
            ok, d2 = landmarks_compatible(la[a[k]], la[b[k]], P, cfg.fusion.gate_probability)
            if ok:
                tested.append((d2, int(a[k]), int(b[k])))
        tested.sort()
        counts = g.observation_counts()
        kept: set[int] = set()
        dropped: set[int] = set()
        merged = 0
        for _, ia, ib in tested:
            keep, drop = (ia, ib) if counts[ia] >= counts[ib] else (ib, ia)
            if ia in dropped or ib in dropped or drop in kept:
                continue
            book.merge(keep, drop)
            kept.add(keep)
            dropped.add(drop)
            merged += 1
        return merged
