"""The landmark book: the one owner of the map's state.

It holds the factor graph's landmarks (:class:`slam.graph.problem.LineGraph`: values, anchors,
factors, merges), the front end's bookkeeping per graph landmark (the information of its
observations relative to the poses that saw it, the keyframe it was last seen from, the side
of the wall it was seen from), the landmarks' extents along their lines, and the tentative
landmarks (:class:`slam.frontend.tentative.TentativePool`).

Everything that changes a landmark goes through the book: new line factors
(:meth:`LandmarkBook.observe`), promotion of tentative landmarks (:meth:`LandmarkBook.promote`),
merges (:meth:`LandmarkBook.merge`) and their undoing (:meth:`LandmarkBook.recompute_info`).
:meth:`LandmarkBook.snapshot` and :meth:`LandmarkBook.restore` take the whole estimate and
bookkeeping back to an earlier state (a rejected loop closure).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.frontend.config import FrontendConfig
from slam.frontend.loop_closure import LoopLines
from slam.frontend.tentative import TentativePool
from slam.graph.problem import GrowableArray, LineGraph, unite_factor_extents
from slam.line_slam.observations import ScanLines
from slam.models.anchored import anchored_jacobian, observe_anchored, r_alpha_from_anchored

__all__ = ["BookSnapshot", "LandmarkBook", "anchored_endpoints"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def anchored_endpoints(rho_phi: FloatArray, anchors: FloatArray, extents: FloatArray) -> FloatArray:
    """World end points ``(k, 2, 2)`` of anchored lines' extents."""
    phi = rho_phi[:, 1]
    n = np.stack([np.cos(phi), np.sin(phi)], -1)
    t = np.stack([-n[:, 1], n[:, 0]], -1)
    foot = anchors + rho_phi[:, 0:1] * n
    return foot[:, None, :] + extents[:, :, None] * t[:, None, :]


def _bits(a: FloatArray) -> NDArray[np.int64]:
    """The bit patterns of a float array (``−0.0`` differs from ``0.0``, NaN equals itself)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


class _ExtentCache:
    """Each factor's interval along its landmark at the last refresh, and what it was taken at.

    :meth:`extents` recomputes (:meth:`LineGraph.factor_extents`) only the intervals of new
    factors and of factors whose pose, landmark (value or rewiring) changed since, bit for bit;
    an interval depends on nothing else (the factor's end points and its landmark's anchor never
    change), and is computed element by element, so the result is the one a computation of
    every factor gives.  The landmarks' unions are then taken over every factor as
    :meth:`LineGraph.landmark_extents` takes them.
    """

    def __init__(self) -> None:
        self._poses = np.zeros((0, 3), dtype=np.int64)
        self._landmarks = np.zeros((0, 2), dtype=np.int64)
        self._factor_landmark = np.zeros(0, dtype=np.intp)
        self._s = np.zeros((0, 2))

    def extents(self, g: LineGraph) -> FloatArray:
        """:meth:`LineGraph.landmark_extents` of ``g``, from the cached intervals."""
        F, M = g.n_line_factors, g.n_landmarks
        if F == 0:
            return np.full((M, 2), np.nan)
        poses, landmarks = _bits(g.poses), _bits(g.landmarks)
        fl = g.factor_landmark
        n = self._s.shape[0]
        if n > F:  # factors are only ever added; otherwise start afresh
            n = 0
        pose_moved = np.ones(poses.shape[0], dtype=bool)
        k = min(poses.shape[0], self._poses.shape[0])
        pose_moved[:k] = (poses[:k] != self._poses[:k]).any(axis=1)
        lm_moved = np.ones(landmarks.shape[0], dtype=bool)
        k = min(landmarks.shape[0], self._landmarks.shape[0])
        lm_moved[:k] = (landmarks[:k] != self._landmarks[:k]).any(axis=1)
        dirty = np.ones(F, dtype=bool)
        dirty[:n] = (
            pose_moved[g.factor_pose[:n]] | lm_moved[fl[:n]] | (fl[:n] != self._factor_landmark)
        )
        s = np.empty((F, 2))
        s[:n] = self._s[:n]
        idx = np.flatnonzero(dirty)
        if idx.size:
            s[idx] = g.factor_extents(idx)
        self._poses, self._landmarks = poses.copy(), landmarks.copy()
        self._factor_landmark = fl.copy()
        self._s = s
        return unite_factor_extents(s, fl, M)


@dataclass(frozen=True, eq=False)
class BookSnapshot:
    """The estimate and landmark bookkeeping at one moment (:meth:`LandmarkBook.snapshot`)."""

    poses: FloatArray
    landmarks: FloatArray
    n_merges: int
    info: FloatArray
    last_keyframe: IntArray
    extents: FloatArray


class LandmarkBook:
    """Landmark state of a run (module docstring).

    Parameters
    ----------
    graph : LineGraph
        The factor graph (its landmarks are the book's; its poses are read and, by snapshots,
        restored).
    frontend : FrontendConfig
        ``landmark_sigma_r_m`` and ``landmark_sigma_alpha_rad``: the floor added to a landmark's
        covariance relative to the poses that saw it.
    """

    def __init__(self, graph: LineGraph, frontend: FrontendConfig) -> None:
        self.graph = graph
        self.frontend = frontend
        self.tentative = TentativePool()
        self.extents = np.zeros((0, 2))
        """Extent ``(s_min, s_max)`` of each graph landmark along its line (NaN: not yet)."""
        self._info = GrowableArray((2, 2))
        self._last_kf = GrowableArray((), dtype=np.intp)
        self._side = GrowableArray(())
        self._fit_cov = GrowableArray((2, 2))
        self._extent_cache = _ExtentCache()

    # -- views -------------------------------------------------------------------------------
    @property
    def last_keyframe(self) -> IntArray:
        """Keyframe each graph landmark was last seen from, ``(n_landmarks,)``."""
        return self._last_kf.data

    @property
    def side(self) -> FloatArray:
        """Side of the wall each graph landmark was seen from (sign along its normal)."""
        return self._side.data

    @property
    def fit_cov(self) -> FloatArray:
        """Fit covariance (without model error) of each line factor, ``(F, 2, 2)``."""
        return self._fit_cov.data

    @property
    def info(self) -> FloatArray:
        """Information ``(n_landmarks, 2, 2)`` of each landmark's observations (anchored chart)."""
        return self._info.data

    def alive_with_extent(self) -> NDArray[np.bool_]:
        """Alive graph landmarks whose extent is known."""
        return self.graph.landmark_alive & np.isfinite(self.extents).all(axis=1)

    def covariance(self, lms: IntArray) -> FloatArray:
        """Covariance (anchored chart) of graph landmarks relative to the poses that saw them."""
        fc = self.frontend
        info = self._info.data[lms]
        det = info[:, 0, 0] * info[:, 1, 1] - info[:, 0, 1] * info[:, 1, 0]
        ok = det > 1e-300
        P = np.zeros_like(info)
        P[ok] = np.linalg.inv(info[ok])
        P[~ok] = np.diag([1.0, 0.1])
        P[:, 0, 0] += fc.landmark_sigma_r_m**2
        P[:, 1, 1] += fc.landmark_sigma_alpha_rad**2
        return P

    def loop_lines(self, lms: IntArray) -> LoopLines:
        """Graph landmarks ``lms`` in the loop-closure search's representation."""
        g = self.graph
        return LoopLines.from_anchored(
            g.landmarks[lms], g.anchors[lms], self.extents[lms], self._side.data[lms]
        )

    # -- changes -----------------------------------------------------------------------------
    def observe(
        self, pose: int, lms: IntArray, lines: ScanLines, rows: IntArray, x0: FloatArray
    ) -> IntArray:
        """Line factors from ``pose`` to graph landmarks ``lms`` for the lines ``rows``."""
        g = self.graph
        if rows.size == 0:
            return np.zeros(0, dtype=np.intp)
        factors = g.add_line_factors(
            pose,
            lms,
            lines.z[rows],
            lines.R[rows],
            lines.endpoints[rows],
            lines.endpoint_var[rows],
            pieces=[lines.pieces[k] for k in rows],
            pieces_var=[lines.pieces_var[k] for k in rows],
        )
        self._fit_cov.append(lines.R_fit[rows])
        self._note_observations(lms, lines.z[rows], lines.R[rows], x0, pose)
        return factors

    def _note_observations(
        self, lms: IntArray, z: FloatArray, R: FloatArray, pose_world_laser: FloatArray, kf: int
    ) -> None:
        """Front-end bookkeeping of observations of graph landmarks (information, last seen)."""
        _, P = observe_anchored(z, R, pose_world_laser, self.graph.anchors[lms])
        np.add.at(self._info.data, lms, np.linalg.inv(P))
        self._last_kf.data[lms] = np.maximum(self._last_kf.data[lms], kf)

    def promote(self, tids: IntArray) -> IntArray:
        """Tentative landmarks ``tids`` become graph landmarks with all their observations.

        Returns the new line factors.
        """
        tp = self.tentative
        if tids.size == 0:
            return np.zeros(0, dtype=np.intp)
        g = self.graph
        rows = tp.rows(tids)
        rho_phi, anchors = tp.rho_phi[rows], tp.anchors[rows]
        ids = g.add_landmarks(r_alpha_from_anchored(rho_phi, anchors), anchors)
        self._info.append(np.asarray(np.linalg.inv(tp.cov[rows]), dtype=float))
        self._last_kf.append(tp.last_kf[rows])
        self._side.append(tp.side[rows])
        self.extents = np.vstack([self.extents, np.full((ids.size, 2), np.nan)])
        out = []
        for tid, lm in zip(tids, ids, strict=True):
            for o in tp.observations(int(tid)):
                out.append(
                    g.add_line_factors(
                        o.pose,
                        np.array([lm]),
                        o.z[None],
                        o.R[None],
                        o.endpoints[None],
                        o.endpoint_var[None],
                        pieces=[o.pieces],
                        pieces_var=[o.pieces_var],
                    )
                )
                self._fit_cov.append(o.R_fit[None])
        tp.remove(tids)
        return np.concatenate(out) if out else np.zeros(0, dtype=np.intp)

    def merge(self, keep: int, drop: int) -> None:
        """Merge graph landmark ``drop`` into ``keep`` (the bookkeeping follows)."""
        g = self.graph
        # the dropped landmark's information, moved to the kept anchor (same line, so only the
        # chart's lever arm changes): P_keep_chart = T P_drop Tᵀ
        Jd = anchored_jacobian(g.landmarks[drop], g.anchors[drop])
        Jk = anchored_jacobian(g.landmarks[keep], g.anchors[keep])
        T = np.linalg.solve(Jk, Jd)
        Ti = np.linalg.inv(T)
        self._info.data[keep] += Ti.T @ self._info.data[drop] @ Ti
        self._last_kf.data[keep] = max(self._last_kf.data[keep], self._last_kf.data[drop])
        g.merge_landmarks(keep, drop)

    def recompute_info(self, lms: IntArray) -> None:
        """Bookkeeping of ``lms`` recomputed from their factors (after undoing merges)."""
        g = self.graph
        for j in lms:
            f = np.flatnonzero(g.factor_landmark == j)
            if f.size == 0:
                continue
            poses = g.poses[g.factor_pose[f]]
            _, P = observe_anchored(
                g.factor_z[f], g.factor_cov[f], poses, np.broadcast_to(g.anchors[j], (f.size, 2))
            )
            self._info.data[j] = np.linalg.inv(P).sum(axis=0)
            self._last_kf.data[j] = int(g.factor_pose[f].max())

    def refresh_extents(self) -> None:
        """Extents recomputed from every factor at the current estimate.

        Only the factors whose pose or landmark changed are recomputed (the result is the
        same as :meth:`LineGraph.landmark_extents`'s, bit for bit).
        """
        self.extents = self._extent_cache.extents(self.graph)

    def update_extents(self, new_factors: IntArray, estimate_moved: bool) -> None:
        """Extents grown by ``new_factors`` (all recomputed when the estimate moved)."""
        g = self.graph
        if estimate_moved or self.extents.shape[0] != g.n_landmarks:
            self.refresh_extents()
            return
        if new_factors.size == 0:
            return
        s = g.factor_extents(new_factors)
        lm = g.factor_landmark[new_factors]
        lo = np.where(np.isnan(self.extents[:, 0]), np.inf, self.extents[:, 0])
        hi = np.where(np.isnan(self.extents[:, 1]), -np.inf, self.extents[:, 1])
        np.minimum.at(lo, lm, s[:, 0])
        np.maximum.at(hi, lm, s[:, 1])
        seen = np.isfinite(lo)
        self.extents[seen, 0] = lo[seen]
        self.extents[seen, 1] = hi[seen]

    # -- snapshots ---------------------------------------------------------------------------
    def snapshot(self) -> BookSnapshot:
        """The estimate (poses and landmarks), the merges so far and the bookkeeping."""
        g = self.graph
        return BookSnapshot(
            g.poses.copy(),
            g.landmarks.copy(),
            len(g.merge_log),
            self._info.data.copy(),
            self._last_kf.data.copy(),
            self.extents.copy(),
        )

    def restore(self, snap: BookSnapshot) -> None:
        """Back to ``snap``: merges since then undone, estimate and bookkeeping restored."""
        g = self.graph
        g.revert_merges(snap.n_merges)
        self._info.data[:] = snap.info
        self._last_kf.data[:] = snap.last_keyframe
        g.poses[:] = snap.poses
        g.landmarks[:] = snap.landmarks
        self.extents = snap.extents.copy()

    @contextmanager
    def estimate_at(self, poses: FloatArray, landmarks: FloatArray) -> Iterator[None]:
        """Temporarily set the graph's estimate (e.g. to evaluate residuals at another one)."""
        g = self.graph
        kept = (g.poses.copy(), g.landmarks.copy())
        g.poses[:], g.landmarks[:] = poses, landmarks
        try:
            yield
        finally:
            g.poses[:], g.landmarks[:] = kept
