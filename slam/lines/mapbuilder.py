"""Building a line map across poses (paper Sec. V): transform, gate, fuse, best pair first.

:class:`MapBuilder` is fed the lines of one scan at a time with the scan's pose in the world
(and its covariance) and keeps a :class:`LineMap` of world lines.

Merge policy
------------
1. **Within the scan** (``merge_within_scan``): collinear pieces of one scan are merged first in
   the sensor frame, without pose uncertainty (the pieces share the pose, so its error cancels).
2. **Into the world**: the scan's lines go to the world frame by Eq. 31 with the pose covariance
   (:func:`slam.lines.transform.transform_line`, right perturbation), each line stored with
   its normal pointing away from the sensor that saw it.
3. **Candidates**: every new line against every map line, vectorised: a bounding-box test
   (extents grown by ``max_gap_m``) selects candidate pairs, then the χ² test on ``(r, α)``
   (Eqs. 34-35) at the configured probability, the side test (``same_side``) and the gap test
   (the visible extents, projected on one line, are at most ``max_gap_m`` apart).
4. **Best pair first**: all pairs that pass go to a priority queue ordered by ``D²``; the most
   compatible pair is fused (Eqs. 36-37, :func:`slam.lines.merge.fuse`), the fused line keeps the
   older id, and it is tested again against every line of the map (it has moved and shrunk its
   covariance, so old decisions about it are void).  Stale queue entries are skipped.  This
   repeats until no pair passes, so merging within the map (two map lines bridged by a new one)
   happens too.  Choosing the best pair first, and re-testing after every fusion, makes the
   result depend little on the order of the lines and of the scans (a test builds a sequence
   forwards and backwards).
5. **Segments**: the ends of both lines are projected onto the fused line; segments overlapping
   or closer than ``segment_gap_m`` are united, others kept (a multi-segment line); each end
   keeps its variance.

Pose errors of different scans are treated as independent and the lines of one scan as
independent of each other, as in the paper; a fixed pose covariance per scan is the uncertainty
of the log's pose *relative to the map around it*, not the drift of odometry since the start.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam.errors import InputError
from slam.lines.checks import check_covariance
from slam.lines.config import MapConfig
from slam.lines.merge import (
    chi2_gate,
    extent_gap,
    fuse_pair_unchecked,
    mahalanobis2_unchecked,
    to_normal_form,
    unite_segments,
)
from slam.lines.transform import segment_shift, transform_line

__all__ = ["LineMap", "MapBuilder", "MapLine", "MergeStats"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class MapLine:
    """One line of the map, world frame, normal form.

    Attributes
    ----------
    id : int
        Stable identifier (the id of the oldest observation merged into it).
    r, alpha : float
        ``{p : p·(cos α, sin α) = r}``, ``r ≥ 0``, ``α ∈ (−π, π]``.
    s : float
        Weighted centroid of all supporting points along the tangent ``(−sin α, cos α)``.
    cov : ndarray, shape (3, 3)
        Covariance of ``(r, α, s)``.
    segments : ndarray, shape (k, 2, 2)
        Visible pieces ``[[x1, y1], [x2, y2]]`` (m), ordered along the tangent.
    segments_var : ndarray, shape (k, 2)
        Variances (m²) of the end positions along the line.
    n_observations : int
        Number of scan lines merged into this one.
    """

    id: int
    r: float
    alpha: float
    s: float
    cov: FloatArray
    segments: FloatArray
    segments_var: FloatArray
    n_observations: int

    @property
    def cov_r_alpha(self) -> FloatArray:
        """2×2 marginal covariance of ``(r, α)`` (what ``map.json`` stores)."""
        return np.asarray(self.cov[:2, :2])

    @property
    def length(self) -> float:
        """Total visible length (m), gaps excluded."""
        return float(np.sum(np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=-1)))


@dataclass(frozen=True)
class LineMap:
    """A line map: world-frame :class:`MapLine` objects."""

    lines: tuple[MapLine, ...] = ()
    frame: str = "world"

    def __len__(self) -> int:
        return len(self.lines)

    @property
    def n_segments(self) -> int:
        """Number of visible segments over all lines."""
        return int(sum(ln.segments.shape[0] for ln in self.lines))

    def r_alpha(self) -> FloatArray:
        """``(K, 2)`` array of ``(r, α)``."""
        return np.array([[ln.r, ln.alpha] for ln in self.lines]).reshape(-1, 2)


@dataclass
class MergeStats:
    """Counters of a :class:`MapBuilder` (cumulative)."""

    scans: int = 0
    lines_in: int = 0
    candidate_pairs_tested: int = 0
    pairs_in_gate: int = 0
    fusions: int = 0


@dataclass
class _Store:
    """Lines with segments as growable arrays plus the best-pair-first merge loop."""

    gate: float
    max_gap_m: float
    segment_gap_m: float
    same_side: bool
    stats: MergeStats
    prefilter: bool = True
    x: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    P: FloatArray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    ext: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    bbox: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    nobs: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    active: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    version: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    segs: list[FloatArray] = field(default_factory=list)
    segvars: list[FloatArray] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.x.shape[0])

    # -- geometry of extents -----------------------------------------------------------------
    @staticmethod
    def _ends_world(x: FloatArray, ext: FloatArray) -> FloatArray:
        """World endpoints ``(..., 2, 2)`` of extents ``(..., 2)`` on lines ``(..., 3)``."""
        n = np.stack([np.cos(x[..., 1]), np.sin(x[..., 1])], -1)
        t = np.stack([-np.sin(x[..., 1]), np.cos(x[..., 1])], -1)
        return x[..., None, 0:1] * n[..., None, :] + ext[..., :, None] * t[..., None, :]

    def _set_geometry(self, idx: NDArray[np.intp]) -> None:
        ext = np.array([[s[0, 0], s[-1, 1]] for s in (self.segs[i] for i in idx)]).reshape(-1, 2)
        self.ext[idx] = ext
        ends = self._ends_world(self.x[idx], ext)
        self.bbox[idx] = np.column_stack([ends.min(axis=1), ends.max(axis=1)])

    # -- storage -------------------------------------------------------------------------------
    def append(
        self,
        x: FloatArray,
        P: FloatArray,
        segs: Sequence[FloatArray],
        segvars: Sequence[FloatArray],
        nobs: NDArray[np.int64],
        ids: NDArray[np.int64],
    ) -> NDArray[np.intp]:
        n0, k = len(self), x.shape[0]
        self.x = np.concatenate([self.x, x])
        self.P = np.concatenate([self.P, P])
        self.ext = np.concatenate([self.ext, np.zeros((k, 2))])
        self.bbox = np.concatenate([self.bbox, np.zeros((k, 4))])
        self.nobs = np.concatenate([self.nobs, nobs])
        self.ids = np.concatenate([self.ids, ids])
        self.active = np.concatenate([self.active, np.ones(k, bool)])
        self.version = np.concatenate([self.version, np.zeros(k, np.int64)])
        for s, v in zip(segs, segvars, strict=True):
            su, vu = unite_segments(s, v, self.segment_gap_m)
            self.segs.append(su)
            self.segvars.append(vu)
        idx = np.arange(n0, n0 + k)
        self._set_geometry(idx)
        return idx

    def compact(self, force: bool = False) -> None:
        """Drop fused-away entries (when they are more than a quarter of the store, or forced)."""
        keep = np.flatnonzero(self.active)
        dead = len(self) - keep.size
        if dead == 0 or (not force and dead < max(64, len(self) // 4)):
            return
        for name in ("x", "P", "ext", "bbox", "nobs", "ids", "active", "version"):
            setattr(self, name, getattr(self, name)[keep])
        self.segs = [self.segs[i] for i in keep]
        self.segvars = [self.segvars[i] for i in keep]

    # -- gating --------------------------------------------------------------------------------
    def _pairs(
        self, rows: NDArray[np.intp], exclude_new_before: bool = False
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
        """All compatible pairs ``(rows[k], j)`` with ``j`` active, vectorised over rows × map.

        Candidates come from the bounding boxes (grown by ``max_gap_m``), then the χ² test,
        the side test and the gap test.  With ``exclude_new_before``, a pair of two rows is
        reported once (row order) and never with itself.

        Returns
        -------
        i, j : ndarray of int
            Pair members (``i`` from ``rows``).
        d2 : ndarray
            Their ``D²``.
        """
        cols = np.flatnonzero(self.active)
        empty = (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0))
        if rows.size == 0 or cols.size == 0:
            return empty
        g = self.max_gap_m
        if self.prefilter:
            # first against the union box of all rows (one pass over the map), then row by row
            ub = self.bbox[rows]
            lo, hi = ub[:, :2].min(axis=0) - g, ub[:, 2:].max(axis=0) + g
            bb = self.bbox[cols]
            cols = cols[
                (bb[:, 0] <= hi[0])
                & (bb[:, 2] >= lo[0])
                & (bb[:, 1] <= hi[1])
                & (bb[:, 3] >= lo[1])
            ]
            if cols.size == 0:
                return empty
            br, bc = self.bbox[rows][:, None, :], self.bbox[cols][None, :, :]
            near = (
                (bc[..., 0] <= br[..., 2] + g)
                & (bc[..., 2] >= br[..., 0] - g)
                & (bc[..., 1] <= br[..., 3] + g)
                & (bc[..., 3] >= br[..., 1] - g)
            )
        else:
            near = np.ones((rows.size, cols.size), bool)
        # never a line with itself; pairs of two rows only once
        pos = np.full(len(self), -1)
        pos[rows] = np.arange(rows.size)
        col_pos = pos[cols]
        if exclude_new_before:
            near &= (col_pos[None, :] < 0) | (col_pos[None, :] > np.arange(rows.size)[:, None])
        else:
            near &= cols[None, :] != rows[:, None]
        ri, ci = np.nonzero(near)
        if ri.size == 0:
            return empty
        ii, jj = rows[ri], cols[ci]
        self.stats.candidate_pairs_tested += int(ii.size)
        d2 = mahalanobis2_unchecked(self.x[ii], self.P[ii], self.x[jj], self.P[jj], self.same_side)
        ok = d2 <= self.gate
        ii, jj, d2 = ii[ok], jj[ok], d2[ok]
        if ii.size and np.isfinite(g):
            # extents of j projected on line i's tangent
            ends = self._ends_world(self.x[jj], self.ext[jj])  # (p, 2, 2)
            a_i = self.x[ii, 1]
            t_i = np.stack([-np.sin(a_i), np.cos(a_i)], -1)
            proj = np.einsum("pkd,pd->pk", ends, t_i)
            proj_ext = np.stack([proj.min(axis=1), proj.max(axis=1)], -1)
            close = extent_gap(self.ext[ii], proj_ext) <= g
            ii, jj, d2 = ii[close], jj[close], d2[close]
        self.stats.pairs_in_gate += int(ii.size)
        return ii, jj, d2

    # -- fusion --------------------------------------------------------------------------------
    def _fuse(self, keep: int, drop: int) -> None:
        xk, xd = self.x[keep], self.x[drop]
        x, P = fuse_pair_unchecked(xk, self.P[keep], xd, self.P[drop])
        t = np.array([-np.sin(x[1]), np.cos(x[1])])
        segs, vars_ = [], []
        for xo, so, vo in (
            (xk, self.segs[keep], self.segvars[keep]),
            (xd, self.segs[drop], self.segvars[drop]),
        ):
            proj = self._ends_world(np.broadcast_to(xo, (so.shape[0], 3)), so) @ t  # (k, 2)
            order = np.argsort(proj, axis=1)
            segs.append(np.take_along_axis(proj, order, axis=1))
            vars_.append(np.take_along_axis(vo, order, axis=1))
        su, vu = unite_segments(np.concatenate(segs), np.concatenate(vars_), self.segment_gap_m)
        self.x[keep], self.P[keep] = x, P
        self.segs[keep], self.segvars[keep] = su, vu
        self.nobs[keep] += self.nobs[drop]
        self.ids[keep] = min(self.ids[keep], self.ids[drop])
        self.active[drop] = False
        self.version[keep] += 1
        self._set_geometry(np.array([keep]))
        self.stats.fusions += 1

    def merge(self, new: NDArray[np.intp]) -> None:
        """Best-pair-first merging of the lines ``new`` into everything active."""
        ii, jj, d2 = self._pairs(np.asarray(new, dtype=np.intp), exclude_new_before=True)
        v = self.version
        heap = list(
            zip(d2.tolist(), ii.tolist(), jj.tolist(), v[ii].tolist(), v[jj].tolist(), strict=True)
        )
        heapq.heapify(heap)
        while heap:
            _, i, j, vi, vj = heapq.heappop(heap)
            if not (self.active[i] and self.active[j]):
                continue
            if self.version[i] != vi or self.version[j] != vj:
                continue
            keep, drop = (i, j) if self.ids[i] <= self.ids[j] else (j, i)
            self._fuse(keep, drop)
            _, kj, kd = self._pairs(np.array([keep], dtype=np.intp))
            vk = int(self.version[keep])
            for o, dd in zip(kj.tolist(), kd.tolist(), strict=True):
                heapq.heappush(heap, (dd, keep, o, vk, int(self.version[o])))


def _lines_to_arrays(
    lines: Sequence[Line],
) -> tuple[FloatArray, FloatArray, list[FloatArray], list[FloatArray], NDArray[np.int64]]:
    if len(lines) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3, 3)), [], [], np.zeros(0, np.int64)
    x = np.array([[ln.r, ln.alpha, ln.s] for ln in lines], dtype=float)
    if not np.isfinite(x).all():
        raise InputError("MapBuilder: a line has NaN or inf parameters")
    P = check_covariance(np.stack([ln.cov for ln in lines]), 3, "line covariance")
    segs = [np.asarray(ln.segments_s, float).reshape(-1, 2) for ln in lines]
    vars_ = [np.asarray(ln.segments_var, float).reshape(-1, 2) for ln in lines]
    for s in segs:
        if s.shape[0] == 0 or not np.isfinite(s).all() or np.any(s[:, 1] < s[:, 0]):
            raise InputError("MapBuilder: a line has no segments or malformed segments_s")
    return x, P, segs, vars_, np.ones(len(lines), np.int64)


class MapBuilder:
    """Merge the lines of successive scans into a world line map (paper Sec. V).

    Parameters
    ----------
    config : MapConfig, optional
        Gate, gap rules and the default pose covariance.
    spatial_prefilter : bool
        Select candidate pairs by bounding boxes before the χ² test (default).  False tests
        every pair (for benchmarks; same result unless two lines pass the χ² and gap tests
        while their boxes are farther apart than ``max_gap_m`` across their normals).

    Examples
    --------
    >>> builder = MapBuilder()
    >>> for lines, pose in scans:                       # doctest: +SKIP
    ...     builder.add_scan(lines, pose)               # pose_world_laser, default covariance
    >>> line_map = builder.line_map()                   # doctest: +SKIP
    """

    def __init__(self, config: MapConfig | None = None, spatial_prefilter: bool = True) -> None:
        self.config = config or MapConfig()
        self._prefilter = spatial_prefilter
        self.stats = MergeStats()
        self._gate = chi2_gate(self.config.gate_probability)
        self._store = self._new_store()
        self._next_id = 0

    def _new_store(self) -> _Store:
        c = self.config
        return _Store(
            self._gate, c.max_gap_m, c.segment_gap_m, c.same_side, self.stats, self._prefilter
        )

    def __len__(self) -> int:
        return int(np.count_nonzero(self._store.active))

    def add_scan(
        self,
        lines: Sequence[Line],
        pose_world_laser: FloatArray | Sequence[float],
        pose_cov: FloatArray | None = None,
    ) -> int:
        """Merge the lines of one scan (sensor frame) into the map.

        Parameters
        ----------
        lines : sequence of linefit.Line
            The scan's lines, laser frame.
        pose_world_laser : array_like, shape (3,)
            Pose of the laser in the world.
        pose_cov : ndarray, shape (3, 3), optional
            Its covariance (right perturbation); default ``config.pose_cov``.

        Returns
        -------
        int
            Number of map lines after the scan.
        """
        x, P, segs, vars_, nobs = _lines_to_arrays(lines)
        return self.add_line_arrays(x, P, segs, vars_, pose_world_laser, pose_cov, nobs)

    def add_line_arrays(
        self,
        lines_laser: FloatArray,
        covs_laser: FloatArray,
        segments_s: Sequence[FloatArray],
        segments_var: Sequence[FloatArray],
        pose_world_laser: FloatArray | Sequence[float],
        pose_cov: FloatArray | None = None,
        n_observations: NDArray[np.int64] | None = None,
    ) -> int:
        """Same as :meth:`add_scan` with the lines as arrays ``(n, 3)``, ``(n, 3, 3)``."""
        pose = np.asarray(pose_world_laser, dtype=float).reshape(-1)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise InputError(f"pose_world_laser must be 3 finite numbers, got {pose!r}")
        Ppose = self.config.pose_cov if pose_cov is None else check_covariance(pose_cov, 3)
        n = lines_laser.shape[0]
        self.stats.scans += 1
        self.stats.lines_in += n
        if n == 0:
            return len(self)
        nobs = np.ones(n, np.int64) if n_observations is None else np.asarray(n_observations)
        x, P = np.asarray(lines_laser, float), check_covariance(covs_laser, 3)
        segs, vars_ = list(segments_s), list(segments_var)
        if self.config.merge_within_scan and n > 1:
            local = self._new_store()
            local.same_side = False  # one sensor: representatives are already aligned
            local.merge(local.append(x, P, segs, vars_, nobs, np.arange(n, dtype=np.int64)))
            local.compact(force=True)
            x, P, segs, vars_, nobs = local.x, local.P, local.segs, local.segvars, local.nobs
        xw, Pw = transform_line(x, P, pose, Ppose, normal_form=False)
        shift, extra, _ = segment_shift(x, P, pose, Ppose)
        sw = [seg + sh for seg, sh in zip(segs, shift.tolist(), strict=True)]
        vw = [var + ex for var, ex in zip(vars_, extra.tolist(), strict=True)]
        ids = np.arange(self._next_id, self._next_id + xw.shape[0], dtype=np.int64)
        self._next_id += xw.shape[0]
        store = self._store
        store.merge(store.append(xw, Pw, sw, vw, nobs, ids))
        store.compact()
        return len(self)

    def line_map(self) -> LineMap:
        """The current map (normal form, segments as world points)."""
        st = self._store
        out = []
        active = np.flatnonzero(st.active)
        for i in active[np.argsort(st.ids[active])]:
            x, P = to_normal_form(st.x[i], st.P[i])
            ends = st._ends_world(np.broadcast_to(st.x[i], (st.segs[i].shape[0], 3)), st.segs[i])
            var = st.segvars[i]
            if st.x[i, 0] < 0.0:
                # the tangent reversed: keep segments ordered along the new tangent
                ends = ends[::-1, ::-1]
                var = var[::-1, ::-1]
            out.append(
                MapLine(
                    id=int(st.ids[i]),
                    r=float(x[0]),
                    alpha=float(x[1]),
                    s=float(x[2]),
                    cov=np.asarray(P),
                    segments=np.ascontiguousarray(ends),
                    segments_var=np.ascontiguousarray(var),
                    n_observations=int(st.nobs[i]),
                )
            )
        return LineMap(tuple(out))

    # ------------------------------------------------------------------------------------------
    def world_lines(self) -> tuple[FloatArray, FloatArray]:
        """Current map lines as arrays ``(K, 3)`` and ``(K, 3, 3)`` (normal form)."""
        st = self._store
        x, P = to_normal_form(st.x[st.active], st.P[st.active])
        return x, P
