"""Landmark fusion: find landmarks that are one wall and merge them in the graph.

Two landmarks become candidates when (vectorised pre-filter over pairs) their normals differ by
less than ``max_angle_rad`` modulo π, the mid-point of one's extent lies within
``max_distance_m`` of the other line, and their extents along the line overlap or leave a gap of
at most ``max_gap_m``.  A candidate pair is then tested with the paper's merge test
(Eqs. 34-35) on the two landmarks' **joint** marginal
(:func:`slam.association.landmarks_compatible`): landmarks observed from the same poses are
strongly correlated, and ignoring that would make the test far too strict.  A compatible pair is
merged (:meth:`LineGraph.merge_landmarks`): the landmark with more observations is kept, its
estimate set to the maximum-likelihood fusion of the two (:func:`slam.lines.fuse`, Eqs. 36-37,
as a starting point: the next solve does the exact fusion, since all measurements now constrain
one variable), and the other's factors are rewired to it.  Pairs are taken best first (smallest
``D²``); a landmark may absorb several others in one round but is never absorbed after
absorbing.  A pair that failed the test
is tested again only once its two landmarks together have ``retest_growth`` times the
measurements they had (the joint marginal is the expensive part: one
``jointMarginalCovariance`` per pair; two walls seen together every keyframe would otherwise be
tested every round).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.association import landmarks_compatible
from slam.graph.problem import LineGraph
from slam.line_slam.config import FusionConfig
from slam.models.anchored import anchored_jacobian

__all__ = ["fuse_landmarks", "fusion_candidates"]

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


def fuse_landmarks(
    graph: LineGraph,
    pairs: list[tuple[int, int]],
    joint_covariance: Callable[[IntArray], FloatArray],
    config: FusionConfig,
    rejected: dict[tuple[int, int], int] | None = None,
) -> list[tuple[int, int, float]]:
    """Test ``pairs`` on their joint marginal and merge the compatible ones (best first).

    Parameters
    ----------
    graph : LineGraph
    pairs : list of (int, int)
    joint_covariance : callable
        ``landmarks (2,) -> (4, 4)`` joint marginal covariance in the anchored chart.
    config : FusionConfig
    rejected : dict, optional
        Memo of failed pairs → their total observation count when tested (updated in place).

    Returns
    -------
    list of (kept, dropped, D²)
    """
    from slam.lines import fuse

    if not pairs:
        return []
    la = graph.landmarks_r_alpha
    counts = graph.observation_counts()
    tested = []
    for a, b in pairs:
        n_obs = int(counts[a] + counts[b])
        retest_at = config.retest_growth * rejected.get((a, b), 0) if rejected is not None else 0
        if n_obs < retest_at:
            continue
        idx = np.array([a, b])
        P = joint_covariance(idx)
        T = np.zeros((4, 4))
        T[:2, :2] = anchored_jacobian(graph.landmarks[a], graph.anchors[a])
        T[2:, 2:] = anchored_jacobian(graph.landmarks[b], graph.anchors[b])
        P_ra = T @ P @ T.T
        ok, d2 = landmarks_compatible(la[a], la[b], P_ra, config.gate_probability)
        if ok:
            tested.append((d2, a, b, P_ra))
        elif rejected is not None:
            rejected[(a, b)] = n_obs
    tested.sort(key=lambda item: item[0])
    kept: set[int] = set()
    dropped: set[int] = set()
    merged = []
    for d2, a, b, P_ra in tested:
        keep, drop = (a, b) if counts[a] >= counts[b] else (b, a)
        # each tested pair was tested against the kept landmark's estimate before this round's
        # merges: a landmark may absorb several others, but is never absorbed after absorbing
        if a in dropped or b in dropped or drop in kept:
            continue
        ik, id_ = (0, 2) if keep == a else (2, 0)
        fused, _ = fuse(
            la[keep],
            P_ra[ik : ik + 2, ik : ik + 2],
            la[drop],
            P_ra[id_ : id_ + 2, id_ : id_ + 2],
            normal_form=False,
        )
        # the kept estimate moves only for its first merge in the round (the others were tested
        # against the estimate before any merge); the next solve does the exact fusion
        graph.merge_landmarks(keep, drop, fused if keep not in kept else None)
        kept.add(keep)
        dropped.add(drop)
        merged.append((keep, drop, float(d2)))
    return merged
