"""``LineSlam``: factor-graph line SLAM fed one scan at a time.

Per scan (:meth:`LineSlam.add_scan`):

1. **Odometry.**  The laser's odometry pose (``Scan.pose_odom_laser``, else
   ``Scan.pose_odom_base ∘ config.pose_base_laser``) gives the motion ``δ`` since the last
   keyframe.
2. **Keyframes.**  The scan becomes a pose variable when ``δ`` exceeds ``keyframes.min_distance_m``
   or ``keyframes.min_angle_rad`` (the first scan always does).  Other scans hang from the last
   keyframe with their odometry offset (their lines are not used).
3. **Prediction.**  ``x̂ = x_k ∘ δ`` with covariance ``Ad(δ⁻¹) P_k Ad(δ⁻¹)ᵀ + Q(δ)``; the
   joint covariance with the candidate landmarks comes from the back-end and is carried along.
4. **Association** (:mod:`slam.association`): candidates near ``x̂`` (their extents within
   ``max_range_m``), χ² gate + segment overlap, nearest neighbour or JCBB.  Matched lines become
   line factors; lines compatible with no landmark start new landmarks (initialised by Eq. 30 at
   ``x̂``, anchored at their segment's mid-point); lines compatible with some landmark but left
   out of the chosen hypothesis are dropped (``lines_ambiguous``) rather than duplicating a wall.
5. **Back-end update** (iSAM2 or periodic batch, :mod:`slam.graph.backend`).
6. **Landmark fusion** every ``fusion.interval_keyframes`` keyframes (:mod:`slam.graph.fusion`).

Graceful degradation (each with a :class:`SlamWarning`, counted in the statistics): a keyframe
without usable lines rests on odometry; a keyframe whose matched lines are all parallel (a
corridor) gets no information along them, which the odometry factor supplies; a keyframe where
nothing matches near the prediction (lost association) starts new landmarks and continues on
odometry.  The odometry chain and the prior on the first pose keep the graph well posed in every
case.

:meth:`LineSlam.optimize` runs a last fusion round and converges the back-end;
:meth:`LineSlam.result` returns a :class:`~slam.graph.result.SlamResult`.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.config import LineFitConfig
from linefit.line import Line
from slam.association import associate, build_problem, candidate_landmarks, overlap_mask
from slam.errors import InputError
from slam.geometry import line_to_parent, pose_between, pose_compose, pose_inverse
from slam.graph.backend import BatchBackend, Isam2Backend, make_backend
from slam.graph.config import SlamConfig
from slam.graph.fusion import fuse_landmarks, fusion_candidates
from slam.graph.landmark import anchored_jacobian, landmarks_normal_form
from slam.graph.odometry import adjoint_pose2
from slam.graph.problem import LineGraph
from slam.graph.result import SlamResult
from slam.types import Scan

__all__ = ["LineSlam", "ScanReport", "SlamWarning"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

PARALLEL_TOLERANCE_RAD = np.deg2rad(5.0)
"""Matched lines whose normals all lie within this of each other (mod π) count as parallel."""


class SlamWarning(UserWarning):
    """The estimate is degraded but the run continues (no lines, parallel lines, lost match)."""


@dataclass(frozen=True)
class ScanReport:
    """What :meth:`LineSlam.add_scan` did with one scan.

    Attributes
    ----------
    scan : int
        Position of the scan in the stream (0-based).
    keyframe : bool
        Whether it became a pose variable.
    pose_index : int
        The pose variable it hangs from.
    lines : int
        Usable lines (keyframes only).
    candidates : int
        Landmarks considered for association.
    matched, new_landmarks, ambiguous : int
        Lines matched, lines that started landmarks, lines dropped as ambiguous.
    merged : int
        Landmark fusions performed after this scan.
    warnings : tuple of str
        Degradations (see the module docstring).
    """

    scan: int
    keyframe: bool
    pose_index: int
    lines: int = 0
    candidates: int = 0
    matched: int = 0
    new_landmarks: int = 0
    ambiguous: int = 0
    merged: int = 0
    warnings: tuple[str, ...] = ()


WARN_NO_LINES = "keyframe without usable lines: its pose rests on odometry alone"
WARN_PARALLEL = (
    "all matched lines are parallel (e.g. a corridor): the position along them rests on odometry"
)
WARN_LOST = (
    "no line matched the map near the predicted pose (lost association): "
    "continuing on odometry, new landmarks started"
)


class LineSlam:
    """Factor-graph line SLAM (see the module docstring).

    Parameters
    ----------
    config : SlamConfig, optional
    linefit_config : LineFitConfig, optional
        Used when :meth:`add_scan` extracts the lines itself.

    Examples
    --------
    >>> slam = LineSlam(SlamConfig(backend="isam2"))          # doctest: +SKIP
    >>> for scan in scans:                                    # doctest: +SKIP
    ...     slam.add_scan(scan)
    >>> slam.optimize()                                       # doctest: +SKIP
    >>> result = slam.result()                                # doctest: +SKIP
    """

    def __init__(
        self, config: SlamConfig | None = None, linefit_config: LineFitConfig | None = None
    ) -> None:
        self.config = config or SlamConfig()
        self.linefit_config = linefit_config or LineFitConfig()
        self.graph = LineGraph()
        self.backend: BatchBackend | Isam2Backend = make_backend(self.config)
        self._extents = np.zeros((0, 2))
        self._timestamps: list[float] = []
        self._scan_kf: list[int] = []
        self._scan_offset: list[FloatArray] = []
        self._scan_is_kf: list[bool] = []
        self._scan_runtime: list[float] = []
        self._scan_n_landmarks: list[int] = []
        self._last_kf_odom: FloatArray | None = None
        self._kf_since_fusion = 0
        self._base_laser = np.asarray(self.config.pose_base_laser, dtype=float)
        self.counters: dict[str, int] = {
            "points": 0,
            "lines_fit": 0,
            "lines_used": 0,
            "lines_matched": 0,
            "lines_new": 0,
            "lines_ambiguous": 0,
            "lines_rejected": 0,
            "landmarks_merged": 0,
            "keyframes_without_lines": 0,
            "keyframes_parallel_lines": 0,
            "keyframes_lost_association": 0,
            "jcbb_incomplete": 0,
        }
        self.time_s: dict[str, float] = {
            "extract": 0.0,
            "associate": 0.0,
            "backend": 0.0,
            "fusion": 0.0,
            "optimize": 0.0,
            "covariances": 0.0,
        }

    # -- inputs ------------------------------------------------------------------------------
    def _odometry(self, scan: Scan) -> FloatArray:
        if scan.pose_odom_laser is not None:
            pose = np.asarray(scan.pose_odom_laser, dtype=float).reshape(3)
        elif scan.pose_odom_base is not None:
            pose = pose_compose(np.asarray(scan.pose_odom_base, dtype=float), self._base_laser)
        else:
            raise InputError(
                f"scan {scan.index} has no odometry (pose_odom_laser / pose_odom_base)",
                scan.source or None,
            )
        if not np.isfinite(pose).all():
            raise InputError(f"scan {scan.index}: odometry is not finite", scan.source or None)
        return pose

    def _extract(self, scan: Scan) -> list[Line]:
        from linefit import extract_lines

        t0 = time.perf_counter()
        lines = extract_lines(
            scan.ranges, scan.bearings, self.linefit_config, max_range_m=scan.max_range_m
        )
        self.time_s["extract"] += time.perf_counter() - t0
        return list(lines)

    def _usable(
        self, lines: Sequence[Line]
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, list[FloatArray], list[FloatArray]]:
        """Arrays of the usable lines of a scan.

        Returns ``z (K,2)``, ``R (K,2,2)``, end points ``(K,2,2)``, end variances ``(K,2)``, and
        each line's visible pieces ``(p,2,2)`` with their end variances ``(p,2)``.
        """
        cfg = self.config
        z, R, ep, ev = [], [], [], []
        pieces: list[FloatArray] = []
        pieces_var: list[FloatArray] = []
        for ln in lines:
            cov = np.asarray(ln.cov, dtype=float)[:2, :2]
            ok = (
                ln.n_points >= cfg.min_line_points
                and ln.length >= cfg.min_line_length_m
                and np.isfinite(cov).all()
                and np.isfinite([ln.r, ln.alpha]).all()
                and cov[0, 0] > 0.0
                and cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0] > 0.0
            )
            if not ok:
                self.counters["lines_rejected"] += 1
                continue
            z.append([ln.r, ln.alpha])
            R.append(0.5 * (cov + cov.T))
            ep.append(ln.endpoints)
            ev.append([ln.segments_var[0, 0], ln.segments_var[-1, 1]])
            pieces.append(ln.point_at(ln.segments_s))
            pieces_var.append(np.asarray(ln.segments_var, dtype=float))
        if not z:
            empty = np.zeros((0, 2, 2))
            return np.zeros((0, 2)), empty, empty, np.zeros((0, 2)), [], []
        return np.array(z), np.array(R), np.array(ep), np.array(ev), pieces, pieces_var

    # -- the main step -----------------------------------------------------------------------
    def add_scan(self, scan: Scan, lines: Sequence[Line] | None = None) -> ScanReport:
        """Process one scan.

        Parameters
        ----------
        scan : Scan
            Needs odometry (``pose_odom_laser`` or ``pose_odom_base``).
        lines : sequence of Line, optional
            Lines already extracted from this scan (laser frame); extracted here when None
            (only for keyframes).

        Returns
        -------
        ScanReport

        Raises
        ------
        InputError
            The scan has no (finite) odometry.
        """
        t_start = time.perf_counter()
        odom = self._odometry(scan)
        scan_no = len(self._timestamps)
        if self._last_kf_odom is None:
            delta = np.zeros(3)
            first = True
        else:
            delta = pose_between(self._last_kf_odom, odom)
            first = False
        kcfg = self.config.keyframes
        is_kf = first or (
            np.hypot(delta[0], delta[1]) >= kcfg.min_distance_m
            or abs(delta[2]) >= kcfg.min_angle_rad
        )
        if not is_kf:
            kf = self.graph.n_poses - 1
            self._record(scan, kf, delta, False, t_start)
            return ScanReport(scan_no, False, kf)
        if lines is None:
            lines = self._extract(scan)
        self.counters["lines_fit"] += len(lines)
        self.counters["points"] += int(np.count_nonzero(scan.valid_mask()))
        report = self._keyframe(scan_no, odom, delta, first, lines)
        self._last_kf_odom = odom
        self._record(scan, report.pose_index, np.zeros(3), True, t_start)
        return report

    def _record(self, scan: Scan, kf: int, offset: FloatArray, is_kf: bool, t_start: float) -> None:
        self._timestamps.append(float(scan.timestamp))
        self._scan_kf.append(kf)
        self._scan_offset.append(np.asarray(offset, dtype=float))
        self._scan_is_kf.append(is_kf)
        self._scan_n_landmarks.append(int(np.count_nonzero(self.graph.landmark_alive)))
        self._scan_runtime.append(time.perf_counter() - t_start)

    def _keyframe(
        self, scan_no: int, odom: FloatArray, delta: FloatArray, first: bool, lines: Sequence[Line]
    ) -> ScanReport:
        cfg = self.config
        g = self.graph
        z, R, ep, ev, pieces, pieces_var = self._usable(lines)
        K = z.shape[0]
        self.counters["lines_used"] += K
        warned: list[str] = []
        # prediction
        if first:
            x_pred = odom.copy()
            prev = -1
        else:
            prev = g.n_poses - 1
            x_pred = pose_compose(g.poses[prev], delta)
        Q = cfg.motion.covariance(delta)
        # association
        t0 = time.perf_counter()
        cand = np.zeros(0, dtype=np.intp)
        assignment = np.full(K, -1, dtype=np.intp)
        n_compat = np.zeros(K, dtype=np.intp)
        if K and not first and g.n_landmarks:
            la = g.landmarks_r_alpha
            cand = candidate_landmarks(
                x_pred,
                la,
                self._extents,
                cfg.association.max_range_m,
                alive=g.landmark_alive,
                anchors=g.anchors,
                max_candidates=cfg.association.max_candidates,
            )
            if cand.size:
                # thin the candidates by segment overlap (needs only the pose covariance)
                P_pose = self._predicted_covariance(prev, cand[:0], delta, Q)
                near = overlap_mask(
                    ep,
                    x_pred,
                    P_pose,
                    la[cand],
                    self._extents[cand],
                    cfg.association,
                    g.anchors[cand],
                ).any(axis=0)
                cand = cand[near]
            if cand.size:
                P = self._predicted_covariance(prev, cand, delta, Q)
                problem = build_problem(
                    z,
                    R,
                    ep,
                    x_pred,
                    P,
                    la[cand],
                    self._extents[cand],
                    cfg.association,
                    anchors=g.anchors[cand],
                )
                res = associate(problem, cfg.association)
                assignment, n_compat = res.assignment, res.n_compatible
                if not res.complete:
                    self.counters["jcbb_incomplete"] += 1
        self.time_s["associate"] += time.perf_counter() - t0
        # the pose and its odometry
        if first:
            i = g.add_pose(x_pred)
            g.set_prior(x_pred, cfg.prior_cov)
        else:
            i = g.add_pose(x_pred)
            g.add_odometry(prev, i, delta, Q)
        matched = assignment >= 0
        new = (~matched) & (n_compat == 0)
        ambiguous = (~matched) & (n_compat > 0)
        lm_idx = np.full(K, -1, dtype=np.intp)
        lm_idx[matched] = cand[assignment[matched]]
        if np.any(new):
            zn = np.column_stack([z[new], np.zeros(int(new.sum()))])
            la_new = line_to_parent(zn, x_pred, normal_form=False)[0][:, :2]
            mid = ep[new].mean(axis=1)
            anchors = pose_compose(x_pred, np.column_stack([mid, np.zeros(mid.shape[0])]))[:, :2]
            lm_idx[new] = g.add_landmarks(la_new, anchors)
            self._extents = np.vstack([self._extents, np.full((int(new.sum()), 2), np.nan)])
        use = matched | new
        used = np.flatnonzero(use)
        factors = g.add_line_factors(
            i,
            lm_idx[use],
            z[use],
            R[use],
            ep[use],
            ev[use],
            pieces=[pieces[k] for k in used],
            pieces_var=[pieces_var[k] for k in used],
        )
        self.counters["lines_matched"] += int(matched.sum())
        self.counters["lines_new"] += int(new.sum())
        self.counters["lines_ambiguous"] += int(ambiguous.sum())
        # degradations
        if K == 0:
            self.counters["keyframes_without_lines"] += 1
            warned.append(WARN_NO_LINES)
        elif not first and cand.size and not np.any(matched):
            self.counters["keyframes_lost_association"] += 1
            warned.append(WARN_LOST)
        elif np.count_nonzero(matched) >= 1 and _all_parallel(z[matched, 1]):
            self.counters["keyframes_parallel_lines"] += 1
            warned.append(WARN_PARALLEL)
        for msg in warned:
            warnings.warn(msg, SlamWarning, stacklevel=3)
        # back-end
        t0 = time.perf_counter()
        self.backend.update(g)
        self.time_s["backend"] += time.perf_counter() - t0
        self._update_extents(factors)
        # fusion
        merged = 0
        self._kf_since_fusion += 1
        fcfg = cfg.fusion
        if fcfg.enabled and self._kf_since_fusion >= fcfg.interval_keyframes:
            recent_from = g.n_poses - self._kf_since_fusion
            recent = np.unique(g.factor_landmark[g.factor_pose >= recent_from])
            merged = self._fusion_round(recent)
            self._kf_since_fusion = 0
        return ScanReport(
            scan=scan_no,
            keyframe=True,
            pose_index=i,
            lines=K,
            candidates=int(cand.size),
            matched=int(matched.sum()),
            new_landmarks=int(new.sum()),
            ambiguous=int(ambiguous.sum()),
            merged=merged,
            warnings=tuple(warned),
        )

    def _predicted_covariance(
        self, prev: int, cand: IntArray, delta: FloatArray, Q: FloatArray
    ) -> FloatArray:
        """Joint covariance of ``x̂ = x_prev ∘ δ`` and the candidates, landmarks in ``(r, α)``."""
        g = self.graph
        P = self.backend.joint_covariance(g, prev, cand)
        C = cand.shape[0]
        T = np.eye(3 + 2 * C)
        T[:3, :3] = adjoint_pose2(pose_inverse(delta))
        J = anchored_jacobian(g.landmarks[cand], g.anchors[cand])
        for c in range(C):
            T[3 + 2 * c : 5 + 2 * c, 3 + 2 * c : 5 + 2 * c] = J[c]
        P = T @ P @ T.T
        P[:3, :3] += Q
        return 0.5 * (P + P.T)

    def _update_extents(self, new_factors: IntArray) -> None:
        g = self.graph
        if self.backend.estimate_moved or self._extents.shape[0] != g.n_landmarks:
            self._extents = g.landmark_extents()
            return
        if new_factors.size == 0:
            return
        s = g.factor_extents(new_factors)
        lm = g.factor_landmark[new_factors]
        lo = np.where(np.isnan(self._extents[:, 0]), np.inf, self._extents[:, 0])
        hi = np.where(np.isnan(self._extents[:, 1]), -np.inf, self._extents[:, 1])
        np.minimum.at(lo, lm, s[:, 0])
        np.maximum.at(hi, lm, s[:, 1])
        seen = np.isfinite(lo)
        self._extents[seen, 0] = lo[seen]
        self._extents[seen, 1] = hi[seen]

    def _fusion_round(self, subset: IntArray) -> int:
        t0 = time.perf_counter()
        g = self.graph
        pairs = fusion_candidates(g, self._extents, subset, self.config.fusion)
        merged = fuse_landmarks(
            g,
            pairs,
            lambda idx: self.backend.joint_covariance(g, None, idx),
            self.config.fusion,
        )
        if merged:
            self.counters["landmarks_merged"] += len(merged)
            self._extents = g.landmark_extents()
        self.time_s["fusion"] += time.perf_counter() - t0
        return len(merged)

    # -- finishing ---------------------------------------------------------------------------
    def optimize(self) -> dict[str, Any]:
        """Final fusion over the whole map and convergence of the back-end.

        Returns the back-end's statistics of the last solve.
        """
        t0 = time.perf_counter()
        stats: dict[str, Any] = {}
        if self.graph.n_poses == 0:
            return stats
        for _ in range(3):
            stats = self.backend.optimize(self.graph)
            self._extents = self.graph.landmark_extents()
            if not self.config.fusion.enabled:
                break
            alive = np.flatnonzero(self.graph.landmark_alive)
            if self._fusion_round(alive) == 0:
                break
            self.backend.update(self.graph)
        self.time_s["optimize"] += time.perf_counter() - t0
        return stats

    def result(self) -> SlamResult:
        """The current estimate of every scan's pose and the map, with covariances."""
        g = self.graph
        t0 = time.perf_counter()
        n = len(self._timestamps)
        kf = np.asarray(self._scan_kf, dtype=np.int64)
        offsets = np.array(self._scan_offset).reshape(n, 3)
        poses = pose_compose(g.poses[kf], offsets) if n else np.zeros((0, 3))
        cov = np.full((n, 3, 3), np.nan)
        kf_cov = None
        if self.config.pose_covariances == "keyframes" and g.n_poses:
            kf_cov = self.backend.pose_covariances(g, np.arange(g.n_poses))
            F = adjoint_pose2(pose_inverse(offsets))
            cov = F @ kf_cov[kf] @ np.swapaxes(F, 1, 2) + np.where(
                np.asarray(self._scan_is_kf)[:, None, None],
                0.0,
                self.config.motion.covariance(offsets),
            )
        counts = g.observation_counts()
        ids = np.flatnonzero(g.landmark_alive & (counts >= self.config.map_min_observations))
        la = g.landmarks_r_alpha[ids]
        lcov = self.backend.landmark_covariances(g, ids) if ids.size else np.zeros((0, 2, 2))
        J = anchored_jacobian(g.landmarks[ids], g.anchors[ids])
        lcov = J @ lcov @ np.swapaxes(J, 1, 2)
        la_nf, lcov_nf = landmarks_normal_form(la, lcov)
        assert lcov_nf is not None
        segs, seg_var = self._segments(ids, la_nf, kf_cov)
        self.time_s["covariances"] += time.perf_counter() - t0
        stats: dict[str, Any] = dict(self.counters)
        stats["backend"] = self.backend.stats()
        stats["runtime_s"] = {
            "total": float(np.sum(self._scan_runtime)) + self.time_s["optimize"],
            **{k: float(v) for k, v in self.time_s.items()},
        }
        return SlamResult(
            timestamps=np.asarray(self._timestamps, dtype=float),
            poses_world_laser=poses,
            pose_covariances=cov,
            is_keyframe=np.asarray(self._scan_is_kf, dtype=bool),
            keyframe_of_scan=kf,
            landmark_ids=ids.astype(np.int64),
            landmarks_r_alpha=la_nf,
            landmark_covariances=lcov_nf,
            landmark_segments=segs,
            landmark_segments_var=seg_var,
            landmark_n_observations=counts[ids],
            scan_runtime_s=np.asarray(self._scan_runtime, dtype=float),
            n_landmarks=np.asarray(self._scan_n_landmarks, dtype=np.int64),
            stats=stats,
        )

    def _segments(
        self, ids: IntArray, la_nf: FloatArray, kf_cov: FloatArray | None
    ) -> tuple[list[FloatArray], list[FloatArray]]:
        """Visible pieces of each map line: its observations' intervals, united."""
        from slam.lines import unite_segments

        g = self.graph
        if g.n_line_factors == 0 or ids.size == 0:
            return [np.zeros((0, 2, 2)) for _ in ids], [np.zeros((0, 2)) for _ in ids]
        pf = g.piece_factor
        fp = g.factor_pose[pf]
        ends = np.concatenate([g.piece_ends, np.zeros((pf.shape[0], 2, 1))], axis=-1)
        pts = pose_compose(np.broadcast_to(g.poses[fp][:, None, :], ends.shape), ends)[..., :2]
        pos = np.full(g.n_landmarks, -1)
        pos[ids] = np.arange(ids.size)
        row = pos[g.factor_landmark[pf]]
        keep = row >= 0
        a = la_nf[row[keep], 1]
        r = la_nf[row[keep], 0]
        t = np.stack([-np.sin(a), np.cos(a)], -1)
        nrm = np.stack([np.cos(a), np.sin(a)], -1)
        s = np.einsum("fkd,fd->fk", pts[keep], t)
        lo, hi = s.min(axis=1), s.max(axis=1)
        var = g.piece_var[keep]
        if kf_cov is not None:
            th = g.poses[fp[keep], 2]
            c, sn = np.cos(th), np.sin(th)
            Rw = np.stack([np.stack([c, -sn], -1), np.stack([sn, c], -1)], -2)
            Pw = Rw @ kf_cov[fp[keep], :2, :2] @ np.swapaxes(Rw, 1, 2)
            var = var + np.einsum("fi,fij,fj->f", t, Pw, t)[:, None]
        order = np.argsort(row[keep], kind="stable")
        rows = row[keep][order]
        bounds = np.searchsorted(rows, np.arange(ids.size + 1))
        seg_out, var_out = [], []
        for k in range(ids.size):
            sel = order[bounds[k] : bounds[k + 1]]
            united, uvar = unite_segments(
                np.column_stack([lo[sel], hi[sel]]), var[sel], self.config.map_segment_gap_m
            )
            foot = r[sel[0]] * nrm[sel[0]]
            ends = foot[None, None, :] + united[:, :, None] * t[sel[0]][None, None, :]
            seg_out.append(ends)
            var_out.append(uvar)
        return seg_out, var_out


def _all_parallel(alpha: FloatArray) -> bool:
    """Whether all normals ``alpha`` are within :data:`PARALLEL_TOLERANCE_RAD` (mod π)."""
    a = np.asarray(alpha, dtype=float)
    if a.size == 0:
        return False
    d = np.abs(np.sin(a[:, None] - a[None, :]))
    return bool(np.max(d) < np.sin(PARALLEL_TOLERANCE_RAD))
