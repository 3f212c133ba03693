"""Tentative landmarks: lines seen too few times to be trusted with a graph variable.

A line that matches no landmark does not enter the factor graph at once.  It becomes a
*tentative* landmark here, with its observation buffered; later keyframes associate with it like
with any landmark (the front end offers tentative landmarks to the registration too).  Once it
has been observed in ``min_observations`` keyframes it is **promoted**: the caller creates the
graph landmark and adds all buffered observations as line factors (nothing is lost, it only
arrives late).  A tentative landmark not seen again for ``max_age_keyframes`` keyframes
**expires** with its observations: people walking by, a chair seen once, lines fitted across a
depth jump, reflections.  See ``docs/real-logs.md``.

Values are kept in the anchored chart (:mod:`slam.models.anchored`): ``(ρ, φ)`` at the anchor
of the first observation (its segment's mid-point), with the information-weighted fusion of the
observations (each moved into the world with the pose estimate of its keyframe at the time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.geometry import pose_compose
from slam.models.anchored import align_representative, observe_anchored

__all__ = ["Observation", "TentativePool"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class Observation:
    """One buffered line measurement (what a line factor needs)."""

    pose: int
    z: FloatArray
    R: FloatArray
    endpoints: FloatArray
    endpoint_var: FloatArray
    pieces: FloatArray
    pieces_var: FloatArray
    R_fit: FloatArray
    """The fit's covariance without model error (``R`` is this plus the model error)."""


class TentativePool:
    """Tentative landmarks (see the module docstring); ids are never reused."""

    def __init__(self) -> None:
        self.rho_phi = np.zeros((0, 2))
        self.anchors = np.zeros((0, 2))
        self.cov = np.zeros((0, 2, 2))
        self.extents = np.zeros((0, 2))
        self.side = np.zeros(0)
        self.first_kf = np.zeros(0, dtype=np.intp)
        self.last_kf = np.zeros(0, dtype=np.intp)
        self.n_obs = np.zeros(0, dtype=np.intp)
        self.ids = np.zeros(0, dtype=np.intp)
        self._obs: dict[int, list[Observation]] = {}
        self._next = 0

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def observations(self, tid: int) -> list[Observation]:
        """Buffered observations of tentative landmark ``tid``."""
        return self._obs[tid]

    def rows(self, tids: IntArray) -> IntArray:
        """Rows of the arrays holding ``tids``."""
        return np.searchsorted(self.ids, np.asarray(tids, dtype=np.intp))

    def add(
        self,
        kf: int,
        pose_world_laser: FloatArray,
        observations: list[Observation],
    ) -> IntArray:
        """Start one tentative landmark per observation (seen from ``pose_world_laser``)."""
        k = len(observations)
        if k == 0:
            return np.zeros(0, dtype=np.intp)
        z = np.array([o.z for o in observations])
        R = np.array([o.R for o in observations])
        ep = np.array([o.endpoints for o in observations])
        mid = ep.mean(axis=1)
        anchors = pose_compose(pose_world_laser, np.column_stack([mid, np.zeros(k)]))[:, :2]
        v, P = observe_anchored(z, R, pose_world_laser, anchors)
        # the sensor sees the line from its negative side: side = sign((p − c)·n) < 0 → +1
        p = np.asarray(pose_world_laser, dtype=float)[:2]
        n = np.stack([np.cos(v[:, 1]), np.sin(v[:, 1])], -1)
        side = np.where(np.sum((p - anchors) * n, axis=1) - v[:, 0] <= 0.0, 1.0, -1.0)
        ext = self._extent_of(v, anchors, pose_world_laser, ep)
        ids = np.arange(self._next, self._next + k, dtype=np.intp)
        self._next += k
        self.rho_phi = np.vstack([self.rho_phi, v])
        self.anchors = np.vstack([self.anchors, anchors])
        self.cov = np.concatenate([self.cov, P])
        self.extents = np.vstack([self.extents, ext])
        self.side = np.concatenate([self.side, side])
        self.first_kf = np.concatenate([self.first_kf, np.full(k, kf, dtype=np.intp)])
        self.last_kf = np.concatenate([self.last_kf, np.full(k, kf, dtype=np.intp)])
        self.n_obs = np.concatenate([self.n_obs, np.ones(k, dtype=np.intp)])
        self.ids = np.concatenate([self.ids, ids])
        for tid, obs in zip(ids, observations, strict=True):
            self._obs[int(tid)] = [obs]
        return ids

    @staticmethod
    def _extent_of(
        v: FloatArray, anchors: FloatArray, pose: FloatArray, endpoints_laser: FloatArray
    ) -> FloatArray:
        """``(s_lo, s_hi)`` of measured segments along the lines, from the anchors."""
        k = v.shape[0]
        pts = np.concatenate([endpoints_laser, np.zeros((k, 2, 1))], axis=-1)
        w = pose_compose(np.broadcast_to(np.asarray(pose, dtype=float), pts.shape), pts)[..., :2]
        t = np.stack([-np.sin(v[:, 1]), np.cos(v[:, 1])], -1)
        s = np.einsum("kpd,kd->kp", w - anchors[:, None, :], t)
        return np.column_stack([s.min(axis=1), s.max(axis=1)])

    def observe(
        self,
        tids: IntArray,
        kf: int,
        pose_world_laser: FloatArray,
        observations: list[Observation],
    ) -> None:
        """Fuse new observations (one per id, seen from ``pose_world_laser``) into ``tids``."""
        tids = np.asarray(tids, dtype=np.intp)
        if tids.size == 0:
            return
        rows = self.rows(tids)
        z = np.array([o.z for o in observations])
        R = np.array([o.R for o in observations])
        ep = np.array([o.endpoints for o in observations])
        anchors = self.anchors[rows]
        v_obs, P_obs = observe_anchored(z, R, pose_world_laser, anchors)
        v_obs, P_aligned = align_representative(self.rho_phi[rows], v_obs, P_obs)
        assert P_aligned is not None
        P_obs = P_aligned
        I_old = np.linalg.inv(self.cov[rows])
        I_obs = np.linalg.inv(P_obs)
        P_new = np.linalg.inv(I_old + I_obs)
        v_new = np.einsum(
            "kij,kj->ki",
            P_new,
            np.einsum("kij,kj->ki", I_old, self.rho_phi[rows])
            + np.einsum("kij,kj->ki", I_obs, v_obs),
        )
        self.rho_phi[rows] = v_new
        self.cov[rows] = 0.5 * (P_new + np.swapaxes(P_new, -1, -2))
        ext = self._extent_of(v_new, anchors, pose_world_laser, ep)
        self.extents[rows, 0] = np.minimum(self.extents[rows, 0], ext[:, 0])
        self.extents[rows, 1] = np.maximum(self.extents[rows, 1], ext[:, 1])
        self.last_kf[rows] = np.maximum(self.last_kf[rows], kf)
        for tid, obs in zip(tids, observations, strict=True):
            buf = self._obs[int(tid)]
            if buf[-1].pose != kf:
                self.n_obs[self.rows(np.array([tid]))[0]] += 1
            buf.append(obs)

    def remove(self, tids: IntArray) -> None:
        """Forget ``tids`` (promoted or expired)."""
        tids = np.asarray(tids, dtype=np.intp)
        if tids.size == 0:
            return
        keep = ~np.isin(self.ids, tids)
        for name in (
            "rho_phi",
            "anchors",
            "cov",
            "extents",
            "side",
            "first_kf",
            "last_kf",
            "n_obs",
            "ids",
        ):
            setattr(self, name, getattr(self, name)[keep])
        for tid in tids:
            self._obs.pop(int(tid), None)

    def expired(self, kf: int, max_age_keyframes: int) -> IntArray:
        """Ids not observed during the last ``max_age_keyframes`` keyframes."""
        return self.ids[self.last_kf < kf - max_age_keyframes]

    def ready(self, min_observations: int) -> IntArray:
        """Ids observed in at least ``min_observations`` keyframes."""
        return self.ids[self.n_obs >= min_observations]
