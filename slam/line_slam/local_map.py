"""The local map: the landmarks offered to a keyframe's registration.

Graph and tentative landmarks within ``association.max_range_m`` of the predicted pose whose
drift relative to the robot is small: the drift since a landmark was last seen is the sum of the
front end's step covariances since (:mod:`slam.line_slam.drift`), and landmarks whose
translation drift exceeds ``frontend.max_drift_xy_m`` are left to loop closing.  Each
landmark's covariance relative to the robot is its covariance relative to the poses that saw
it, plus the drift since (:func:`slam.models.anchored.drift_covariance`), plus a floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.association import candidate_landmarks
from slam.line_slam.config import SlamConfig
from slam.line_slam.drift import DriftAccumulator
from slam.line_slam.landmarks import LandmarkBook, anchored_endpoints
from slam.lines.lineset import LineSet
from slam.models.anchored import anchored_jacobian, drift_covariance, r_alpha_from_anchored

__all__ = ["GRAPH", "TENTATIVE", "LocalMap", "build_local_map"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

GRAPH = 0
"""``LocalMap.kind`` of a graph landmark."""
TENTATIVE = 1
"""``LocalMap.kind`` of a tentative landmark."""


@dataclass(frozen=True, eq=False)
class LocalMap:
    """Landmarks offered to the registration.

    Attributes
    ----------
    kind : ndarray of int, shape (k,)
        :data:`GRAPH` or :data:`TENTATIVE`.
    index : ndarray of int, shape (k,)
        Graph landmark index or tentative id.
    lines : LineSet
        ``(r, α)`` in the world, covariance relative to the robot, extents' end points.
    rho_phi, anchors, extents : ndarray, shape (k, 2)
        Anchored values, anchors and extents along the line.
    side : ndarray, shape (k,)
        Side of the wall they were seen from.
    """

    kind: IntArray
    index: IntArray
    lines: LineSet
    rho_phi: FloatArray
    anchors: FloatArray
    extents: FloatArray
    side: FloatArray

    @classmethod
    def empty(cls) -> LocalMap:
        """No landmarks."""
        z2 = np.zeros((0, 2))
        return cls(
            np.zeros(0, np.intp), np.zeros(0, np.intp), LineSet.empty(), z2, z2, z2, np.zeros(0)
        )

    def __len__(self) -> int:
        return int(self.kind.size)


def build_local_map(
    book: LandmarkBook, drift: DriftAccumulator, x_pred: FloatArray, config: SlamConfig
) -> LocalMap:
    """Graph and tentative landmarks near ``x_pred`` with small drift (module docstring)."""
    g = book.graph
    fc = config.frontend
    p = x_pred[:2]
    kinds: list[IntArray] = []
    idx: list[IntArray] = []
    ra: list[FloatArray] = []
    cov: list[FloatArray] = []
    ends: list[FloatArray] = []
    vals: list[FloatArray] = []
    anch: list[FloatArray] = []
    exts: list[FloatArray] = []
    sides: list[FloatArray] = []
    if g.n_landmarks:
        cand = candidate_landmarks(
            x_pred,
            g.landmarks_r_alpha,
            book.extents,
            config.association.max_range_m,
            alive=g.landmark_alive,
            anchors=g.anchors,
        )
        if cand.size:
            sxy, sth = drift.since(book.last_keyframe[cand])
            near = sxy <= fc.max_drift_xy_m
            cand, sxy, sth = cand[near], sxy[near], sth[near]
        if cand.size:
            v = g.landmarks[cand]
            c = g.anchors[cand]
            P = book.covariance(cand) + drift_covariance(v, c, p, sxy, sth)
            J = anchored_jacobian(v, c)
            kinds.append(np.full(cand.size, GRAPH, dtype=np.intp))
            idx.append(cand)
            ra.append(r_alpha_from_anchored(v, c))
            cov.append(J @ P @ np.swapaxes(J, -1, -2))
            ends.append(anchored_endpoints(v, c, book.extents[cand]))
            vals.append(v)
            anch.append(c)
            exts.append(book.extents[cand])
            sides.append(book.side[cand])
    tp = book.tentative
    if len(tp):
        t_ra = r_alpha_from_anchored(tp.rho_phi, tp.anchors)
        near_t = candidate_landmarks(
            x_pred, t_ra, tp.extents, config.association.max_range_m, anchors=tp.anchors
        )
        if near_t.size:
            v = tp.rho_phi[near_t]
            c = tp.anchors[near_t]
            sxy, sth = drift.since(tp.last_kf[near_t])
            P = tp.cov[near_t] + drift_covariance(v, c, p, sxy, sth)
            P[:, 0, 0] += fc.landmark_sigma_r_m**2
            P[:, 1, 1] += fc.landmark_sigma_alpha_rad**2
            J = anchored_jacobian(v, c)
            kinds.append(np.full(near_t.size, TENTATIVE, dtype=np.intp))
            idx.append(tp.ids[near_t])
            ra.append(t_ra[near_t])
            cov.append(J @ P @ np.swapaxes(J, -1, -2))
            ends.append(anchored_endpoints(v, c, tp.extents[near_t]))
            vals.append(v)
            anch.append(c)
            exts.append(tp.extents[near_t])
            sides.append(tp.side[near_t])
    if not kinds:
        return LocalMap.empty()
    kind = np.concatenate(kinds)
    lines = LineSet(
        np.concatenate(ra), np.concatenate(cov), np.concatenate(ends), np.arange(kind.size)
    )
    return LocalMap(
        kind,
        np.concatenate(idx),
        lines,
        np.concatenate(vals),
        np.concatenate(anch),
        np.concatenate(exts),
        np.concatenate(sides),
    )
