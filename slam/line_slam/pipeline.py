"""``LineSlam``: factor-graph line SLAM fed one scan at a time.

Per scan (:meth:`LineSlam.add_scan`, or :meth:`LineSlam.add_scans` for a batch whose keyframes'
lines are extracted at once):

1. **Odometry.**  The laser's odometry pose (``Scan.pose_odom_laser``, else
   ``Scan.pose_odom_base ∘ config.pose_base_laser``; always the latter with
   ``laser_odometry = "base"``) gives the motion ``δ`` since the last keyframe.
2. **Keyframes.**  The scan becomes a pose variable when ``δ`` exceeds ``keyframes.min_distance_m``
   or ``keyframes.min_angle_rad`` (the first scan always does).  Other scans hang from the
   keyframes around them (:meth:`result`).
3. **Lines.**  Lines with too few points or too short are dropped; every other line's
   covariance gets the model-error floor (``line_model_sigma_*``).
4. **Front end** (:mod:`slam.frontend.registration`).  The lines are registered against the
   local map (graph and tentative landmarks near the prediction ``x̂ = x_k ∘ δ`` whose drift
   relative to the robot is small) with the odometry prediction as prior.  The registered pose
   is the keyframe's initial estimate, and the registration's pairs are the data association.
5. **Landmarks.**  Lines paired with a graph landmark become line factors.  Lines paired with a
   tentative landmark are buffered there (:mod:`slam.frontend.tentative`); a tentative landmark
   seen in ``tentative.min_observations`` keyframes is promoted to a graph landmark with all
   its observations.  Lines compatible with nothing start tentative landmarks; lines
   compatible with some landmark but not paired are dropped (``lines_ambiguous``).
6. **Back-end update** (iSAM2 or periodic batch, :mod:`slam.graph.backend`).
7. **Landmark fusion** every ``fusion.interval_keyframes`` keyframes among the landmarks near
   the robot (:meth:`_fusion_round`), and **loop closing** every
   ``loop_closure.interval_keyframes`` (:meth:`_loop_closure`,
   :mod:`slam.frontend.loop_closure`).

Graceful degradation (each with a :class:`SlamWarning`, counted in the statistics): a keyframe
without usable lines rests on odometry; a keyframe whose matched lines are all parallel (a
corridor) gets no information along them, which the odometry factor supplies; a keyframe where
nothing matches near the prediction (lost association) starts new landmarks and continues on
odometry.  The odometry chain and the prior on the first pose keep the graph well posed in every
case.

:meth:`LineSlam.optimize` runs a last fusion round and converges the back-end;
:meth:`LineSlam.result` returns a :class:`~slam.result.SlamResult`.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.config import LineFitConfig
from linefit.line import Line, wrap_angle
from slam.association import candidate_landmarks, landmarks_compatible
from slam.frontend.registration import register_lines
from slam.frontend.tentative import Observation, TentativePool
from slam.geometry import (
    adjoint_pose2,
    pose_between,
    pose_compose,
    pose_exp,
    pose_inverse,
    pose_log,
)
from slam.graph.backend import BatchBackend, Isam2Backend, make_backend
from slam.graph.batch import BatchSolver
from slam.graph.factors import line_factor_residuals
from slam.graph.problem import GrowableArray, LineGraph
from slam.inputs import InputPolicy
from slam.line_slam.config import SlamConfig
from slam.lines.lineset import LineSet
from slam.models.anchored import (
    anchored_jacobian,
    drift_covariance,
    landmarks_normal_form,
    model_error_covariance,
    observe_anchored,
    r_alpha_from_anchored,
)
from slam.result import SlamResult
from slam.types import Scan

__all__ = ["LineSlam", "ScanReport", "SlamWarning"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

PARALLEL_TOLERANCE_RAD = np.deg2rad(5.0)
"""Matched lines whose normals all lie within this of each other (mod π) count as parallel."""

ANGLE_WEIGHT_M_PER_RAD = 0.5
"""Turning 1 rad counts as this much path when non-keyframe poses are interpolated."""


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
        Landmarks (graph and tentative) offered to the registration.
    matched : int
        Lines paired with a landmark (graph or tentative).
    new_landmarks : int
        Lines that started a (tentative) landmark.
    ambiguous : int
        Lines dropped as ambiguous.
    merged : int
        Landmark fusions performed after this scan.
    loop_closures : int
        Loop closures accepted after this scan.
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
    loop_closures: int = 0
    warnings: tuple[str, ...] = ()


WARN_NO_LINES = "keyframe without usable lines: its pose rests on odometry alone"
WARN_PARALLEL = (
    "all matched lines are parallel (e.g. a corridor): the position along them rests on odometry"
)
WARN_LOST = (
    "no line matched the map near the predicted pose (lost association): "
    "continuing on odometry, new landmarks started"
)


@dataclass(frozen=True, eq=False)
class _Lines:
    """Usable lines of one keyframe, as arrays."""

    z: FloatArray
    R: FloatArray
    endpoints: FloatArray
    endpoint_var: FloatArray
    pieces: list[FloatArray]
    pieces_var: list[FloatArray]

    def __len__(self) -> int:
        return int(self.z.shape[0])

    def observation(self, pose: int, k: int) -> Observation:
        return Observation(
            pose,
            self.z[k],
            self.R[k],
            self.endpoints[k],
            self.endpoint_var[k],
            self.pieces[k],
            self.pieces_var[k],
        )


@dataclass(frozen=True, eq=False)
class _LocalMap:
    """Landmarks offered to the registration: ``kind`` 0 graph, 1 tentative; ``index`` id."""

    kind: IntArray
    index: IntArray
    lines: LineSet
    rho_phi: FloatArray
    anchors: FloatArray
    extents: FloatArray
    side: FloatArray

    @classmethod
    def empty(cls) -> _LocalMap:
        z2 = np.zeros((0, 2))
        return cls(
            np.zeros(0, np.intp), np.zeros(0, np.intp), LineSet.empty(), z2, z2, z2, np.zeros(0)
        )


class LineSlam:
    """Factor-graph line SLAM (see the module docstring).

    Parameters
    ----------
    config : SlamConfig, optional
    linefit_config : LineFitConfig, optional
        Used when :meth:`add_scan` extracts the lines itself.
    policy : InputPolicy, optional
        How the scans' odometry is read and which frame is reported (:mod:`slam.inputs`);
        default: the settings in ``config``.

    Examples
    --------
    >>> slam = LineSlam(SlamConfig(backend="isam2"))          # doctest: +SKIP
    >>> for scan in scans:                                    # doctest: +SKIP
    ...     slam.add_scan(scan)
    >>> slam.optimize()                                       # doctest: +SKIP
    >>> result = slam.result()                                # doctest: +SKIP
    """

    def __init__(
        self,
        config: SlamConfig | None = None,
        linefit_config: LineFitConfig | None = None,
        policy: InputPolicy | None = None,
    ) -> None:
        self.config = config or SlamConfig()
        self.policy = policy if policy is not None else InputPolicy.of(self.config)
        self.linefit_config = linefit_config or LineFitConfig()
        self.graph = LineGraph()
        self.backend: BatchBackend | Isam2Backend = make_backend(
            self.config.backend, self.config.solver, self.config.isam2
        )
        self.tentative = TentativePool()
        # loop-closure candidates are judged by batch solves outside the back-end
        self._judge = BatchSolver(
            replace(
                self.config.solver,
                relative_tolerance=self.config.loop_closure.judge_relative_tolerance,
            )
        )
        self._extents = np.zeros((0, 2))
        # per graph landmark (front-end bookkeeping)
        self._lm_info = GrowableArray((2, 2))
        self._lm_last_kf = GrowableArray((), dtype=np.intp)
        self._lm_side = GrowableArray(())
        # per keyframe
        self._kf_path = GrowableArray(())
        self._kf_delta = GrowableArray((3,))
        self._kf_scan = GrowableArray((), dtype=np.intp)
        # per scan
        self._timestamps: list[float] = []
        self._scan_kf: list[int] = []
        self._scan_offset: list[FloatArray] = []
        self._scan_progress: list[float] = []
        self._scan_is_kf: list[bool] = []
        self._scan_runtime: list[float] = []
        self._scan_n_landmarks: list[int] = []
        self._last_kf_odom: FloatArray | None = None
        self._last_odom: FloatArray | None = None
        self._progress = 0.0
        self._path = 0.0
        self._kf_since_fusion = 0
        self._kf_since_closure = 0
        self._closure_log: list[dict[str, Any]] = []
        # judged and rejected loop-closure hypotheses: (keyframe, correction, paired lines)
        self._rejected: list[tuple[int, FloatArray, int]] = []
        # hypotheses the marginals' gate turned away: (keyframe, correction)
        self._gated: list[tuple[int, FloatArray]] = []
        self._to_audit: list[Any] = []
        # pairs of landmarks whose merge an audit undid: never merged again by fusion
        self._vetoed: set[tuple[int, int]] = set()
        self.counters: dict[str, int] = {
            "points": 0,
            "lines_fit": 0,
            "lines_used": 0,
            "lines_matched": 0,
            "lines_new": 0,
            "lines_ambiguous": 0,
            "lines_rejected": 0,
            "landmarks_merged": 0,
            "merges_undone": 0,
            "tentative_started": 0,
            "tentative_promoted": 0,
            "tentative_expired": 0,
            "registrations_failed": 0,
            "relocalisations": 0,
            "relocalisations_used": 0,
            "loop_closure_attempts": 0,
            "loop_closure_candidates": 0,
            "loop_closures": 0,
            "loop_closures_undone": 0,
            "loop_closures_repeated": 0,
            "loop_closures_gated": 0,
            "loop_closure_gate_overrides": 0,
            "keyframes_without_lines": 0,
            "keyframes_parallel_lines": 0,
            "keyframes_lost_association": 0,
        }
        self.time_s: dict[str, float] = {
            "extract": 0.0,
            "frontend": 0.0,
            "associate": 0.0,
            "backend": 0.0,
            "fusion": 0.0,
            "loop_closure": 0.0,
            "judge": 0.0,
            "optimize": 0.0,
            "covariances": 0.0,
        }

    # -- inputs ------------------------------------------------------------------------------
    def _odometry(self, scan: Scan) -> FloatArray:
        return self.policy.pose_odom_laser(scan)

    def _is_keyframe(self, delta: FloatArray) -> bool:
        k = self.config.keyframes
        return bool(
            np.hypot(delta[0], delta[1]) >= k.min_distance_m or abs(delta[2]) >= k.min_angle_rad
        )

    def _extract(self, scan: Scan) -> list[Line]:
        from linefit import extract_lines

        t0 = time.perf_counter()
        lines = extract_lines(
            scan.ranges, scan.bearings, self.linefit_config, max_range_m=scan.max_range_m
        )
        self.time_s["extract"] += time.perf_counter() - t0
        return list(lines)

    def _usable(self, lines: Sequence[Line]) -> _Lines:
        """Arrays of the usable lines of a scan, model error added to their covariances."""
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
            return _Lines(np.zeros((0, 2)), empty, empty, np.zeros((0, 2)), [], [])
        z_arr, R_arr, ep_arr = np.array(z), np.array(R), np.array(ep)
        if cfg.line_model_sigma_r_m > 0.0 or cfg.line_model_sigma_alpha_rad > 0.0:
            R_arr = R_arr + model_error_covariance(
                z_arr, ep_arr, cfg.line_model_sigma_r_m, cfg.line_model_sigma_alpha_rad
            )
        return _Lines(z_arr, R_arr, ep_arr, np.array(ev), pieces, pieces_var)

    # -- the main step -----------------------------------------------------------------------
    def add_scans(self, scans: Sequence[Scan]) -> list[ScanReport]:
        """Process several scans.

        The lines of those that become keyframes are extracted in one vectorised call
        (:func:`linefit.extract_lines_batch`, the fast path).
        """
        from linefit import extract_lines_batch

        last = self._last_kf_odom
        want: list[int] = []
        for n, scan in enumerate(scans):
            odom = self._odometry(scan)
            if last is None or self._is_keyframe(pose_between(last, odom)):
                want.append(n)
                last = odom
        lines: dict[int, list[Line]] = {}
        t0 = time.perf_counter()
        # one batch per beam layout
        groups: dict[tuple[int, float, float, float], list[int]] = {}
        for n in want:
            s = scans[n]
            key = (s.n_beams, float(s.bearings[0]), float(s.bearings[-1]), float(s.max_range_m))
            groups.setdefault(key, []).append(n)
        for members in groups.values():
            ranges = np.stack([scans[n].ranges for n in members])
            out = extract_lines_batch(
                ranges,
                scans[members[0]].bearings,
                self.linefit_config,
                max_range_m=scans[members[0]].max_range_m,
            )
            for n, ls in zip(members, out, strict=True):
                lines[n] = list(ls)
        self.time_s["extract"] += time.perf_counter() - t0
        return [self.add_scan(s, lines.get(n, [])) for n, s in enumerate(scans)]

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
        if self._last_odom is not None:
            step = pose_between(self._last_odom, odom)
            inc = float(np.hypot(step[0], step[1]))
            self._path += inc
            self._progress += inc + ANGLE_WEIGHT_M_PER_RAD * abs(float(step[2]))
        self._last_odom = odom
        if self._last_kf_odom is None:
            delta = np.zeros(3)
            first = True
        else:
            delta = pose_between(self._last_kf_odom, odom)
            first = False
        is_kf = first or self._is_keyframe(delta)
        if not is_kf:
            kf = self.graph.n_poses - 1
            self._record(scan, kf, delta, self._progress, False, t_start)
            return ScanReport(scan_no, False, kf)
        if lines is None:
            lines = self._extract(scan)
        self.counters["lines_fit"] += len(lines)
        self.counters["points"] += int(np.count_nonzero(scan.valid_mask()))
        self._kf_delta.append(delta)
        self._kf_path.append(self._path)
        self._kf_scan.append(scan_no)
        self._progress = 0.0
        report = self._keyframe(scan_no, odom, delta, first, lines)
        self._last_kf_odom = odom
        self._record(scan, report.pose_index, np.zeros(3), 0.0, True, t_start)
        return report

    def _record(
        self,
        scan: Scan,
        kf: int,
        offset: FloatArray,
        progress: float,
        is_kf: bool,
        t_start: float,
    ) -> None:
        self._timestamps.append(float(scan.timestamp))
        self._scan_kf.append(kf)
        self._scan_offset.append(np.asarray(offset, dtype=float))
        self._scan_progress.append(progress)
        self._scan_is_kf.append(is_kf)
        self._scan_n_landmarks.append(int(np.count_nonzero(self.graph.landmark_alive)))
        self._scan_runtime.append(time.perf_counter() - t_start)

    # -- local map ---------------------------------------------------------------------------
    def _drift_sigmas(self, last_kf: IntArray) -> tuple[FloatArray, FloatArray]:
        """Drift ``(σ_xy, σ_θ)`` relative to landmarks last seen at keyframes ``last_kf``."""
        fc = self.config.frontend
        d = self._path - self._kf_path.data[np.asarray(last_kf, dtype=np.intp)]
        return fc.drift_xy_per_m * d, fc.drift_theta_per_m * d

    def _landmark_cov(self, lms: IntArray) -> FloatArray:
        """Covariance (anchored chart) of graph landmarks relative to the poses that saw them."""
        fc = self.config.frontend
        info = self._lm_info.data[lms]
        det = info[:, 0, 0] * info[:, 1, 1] - info[:, 0, 1] * info[:, 1, 0]
        ok = det > 1e-300
        P = np.zeros_like(info)
        P[ok] = np.linalg.inv(info[ok])
        P[~ok] = np.diag([1.0, 0.1])
        P[:, 0, 0] += fc.landmark_sigma_r_m**2
        P[:, 1, 1] += fc.landmark_sigma_alpha_rad**2
        return P

    def _endpoints(
        self, rho_phi: FloatArray, anchors: FloatArray, extents: FloatArray
    ) -> FloatArray:
        """World end points ``(k, 2, 2)`` of anchored lines' extents."""
        phi = rho_phi[:, 1]
        n = np.stack([np.cos(phi), np.sin(phi)], -1)
        t = np.stack([-n[:, 1], n[:, 0]], -1)
        foot = anchors + rho_phi[:, 0:1] * n
        return foot[:, None, :] + extents[:, :, None] * t[:, None, :]

    def _local_map(self, x_pred: FloatArray) -> _LocalMap:
        """Graph and tentative landmarks near ``x_pred`` with small drift (module docstring)."""
        cfg = self.config
        g = self.graph
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
                self._extents,
                cfg.association.max_range_m,
                alive=g.landmark_alive,
                anchors=g.anchors,
            )
            if cand.size:
                sxy, sth = self._drift_sigmas(self._lm_last_kf.data[cand])
                near = sxy <= cfg.frontend.max_drift_xy_m
                cand, sxy, sth = cand[near], sxy[near], sth[near]
            if cand.size:
                v = g.landmarks[cand]
                c = g.anchors[cand]
                P = self._landmark_cov(cand) + drift_covariance(v, c, p, sxy, sth)
                J = anchored_jacobian(v, c)
                kinds.append(np.zeros(cand.size, dtype=np.intp))
                idx.append(cand)
                ra.append(r_alpha_from_anchored(v, c))
                cov.append(J @ P @ np.swapaxes(J, -1, -2))
                ends.append(self._endpoints(v, c, self._extents[cand]))
                vals.append(v)
                anch.append(c)
                exts.append(self._extents[cand])
                sides.append(self._lm_side.data[cand])
        tp = self.tentative
        if len(tp):
            t_ra = r_alpha_from_anchored(tp.rho_phi, tp.anchors)
            near_t = candidate_landmarks(
                x_pred, t_ra, tp.extents, cfg.association.max_range_m, anchors=tp.anchors
            )
            if near_t.size:
                v = tp.rho_phi[near_t]
                c = tp.anchors[near_t]
                sxy, sth = self._drift_sigmas(tp.last_kf[near_t])
                P = tp.cov[near_t] + drift_covariance(v, c, p, sxy, sth)
                P[:, 0, 0] += cfg.frontend.landmark_sigma_r_m**2
                P[:, 1, 1] += cfg.frontend.landmark_sigma_alpha_rad**2
                J = anchored_jacobian(v, c)
                kinds.append(np.ones(near_t.size, dtype=np.intp))
                idx.append(tp.ids[near_t])
                ra.append(t_ra[near_t])
                cov.append(J @ P @ np.swapaxes(J, -1, -2))
                ends.append(self._endpoints(v, c, tp.extents[near_t]))
                vals.append(v)
                anch.append(c)
                exts.append(tp.extents[near_t])
                sides.append(tp.side[near_t])
        if not kinds:
            return _LocalMap.empty()
        kind = np.concatenate(kinds)
        index = np.concatenate(idx)
        lines = LineSet(
            np.concatenate(ra), np.concatenate(cov), np.concatenate(ends), np.arange(kind.size)
        )
        return _LocalMap(
            kind,
            index,
            lines,
            np.concatenate(vals),
            np.concatenate(anch),
            np.concatenate(exts),
            np.concatenate(sides),
        )

    # -- one keyframe ------------------------------------------------------------------------
    def _keyframe(
        self, scan_no: int, odom: FloatArray, delta: FloatArray, first: bool, lines: Sequence[Line]
    ) -> ScanReport:
        cfg = self.config
        g = self.graph
        obs = self._usable(lines)
        K = len(obs)
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
        # front end: registration against the local map = initial guess + association
        t0 = time.perf_counter()
        x0 = x_pred
        matches = np.full(K, -1, dtype=np.int64)
        n_compat = np.zeros(K, dtype=np.int64)
        local = _LocalMap.empty()
        reg_cov: FloatArray | None = None
        if K and not first:
            local = self._local_map(x_pred)
            if len(local.lines):
                fc = cfg.frontend
                P0 = Q + np.diag(
                    [fc.prior_sigma_xy_m**2, fc.prior_sigma_xy_m**2, fc.prior_sigma_theta_rad**2]
                )
                scan_set = LineSet(obs.z, obs.R, obs.endpoints, np.arange(K))
                reg = register_lines(scan_set, local.lines, x_pred, P0, fc.registration)
                rc = fc.relocalisation
                if (
                    rc.enabled
                    and reg.n_matches < K
                    and reg.n_matches < rc.min_matched_fraction * K
                    and len(local.lines) >= rc.min_matches
                ):
                    reg = self._relocalise(scan_set, obs, local, x_pred, P0, reg)
                matches, n_compat = reg.matches, reg.n_compatible
                if reg.matched:
                    x0 = reg.pose_world_laser
                    reg_cov = reg.cov
                else:
                    self.counters["registrations_failed"] += 1
        self.time_s["frontend"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        # the pose and its odometry
        i = g.add_pose(x0)
        if first:
            g.set_prior(x0, cfg.prior_cov)
        else:
            g.add_odometry(prev, i, delta, Q)
            if cfg.frontend.pose_factor == "inflated" and reg_cov is not None:
                self._add_registration_factor(prev, i, x0, reg_cov)
        matched = matches >= 0
        kind = np.full(K, -1, dtype=np.intp)
        target = np.full(K, -1, dtype=np.intp)
        kind[matched] = local.kind[matches[matched]]
        target[matched] = local.index[matches[matched]]
        to_graph = np.flatnonzero(matched & (kind == 0))
        to_tent = np.flatnonzero(matched & (kind == 1))
        new = np.flatnonzero(~matched & (n_compat == 0))
        ambiguous = int(np.count_nonzero(~matched & (n_compat > 0)))
        factors = self._add_factors(i, target[to_graph], obs, to_graph, x0)
        # tentative landmarks: observe, start, promote, expire
        tp = self.tentative
        if to_tent.size:
            tp.observe(target[to_tent], i, x0, [obs.observation(i, int(k)) for k in to_tent])
        if new.size:
            tp.add(i, x0, [obs.observation(i, int(k)) for k in new])
            self.counters["tentative_started"] += int(new.size)
        promoted = self._promote(tp.ready(cfg.tentative.min_observations))
        factors = np.concatenate([factors, promoted])
        expired = tp.expired(i, cfg.tentative.max_age_keyframes)
        tp.remove(expired)
        self.counters["tentative_expired"] += int(expired.size)
        self.counters["lines_matched"] += int(matched.sum())
        self.counters["lines_new"] += int(new.size)
        self.counters["lines_ambiguous"] += ambiguous
        self.time_s["associate"] += time.perf_counter() - t0
        # degradations
        if K == 0:
            self.counters["keyframes_without_lines"] += 1
            warned.append(WARN_NO_LINES)
        elif not first and len(local.lines) and not np.any(matched):
            self.counters["keyframes_lost_association"] += 1
            warned.append(WARN_LOST)
        elif np.count_nonzero(matched) >= 1 and _all_parallel(obs.z[matched, 1]):
            self.counters["keyframes_parallel_lines"] += 1
            warned.append(WARN_PARALLEL)
        for msg in warned:
            warnings.warn(msg, SlamWarning, stacklevel=3)
        # back-end
        t0 = time.perf_counter()
        self.backend.update(g)
        self.time_s["backend"] += time.perf_counter() - t0
        self._update_extents(factors)
        # fusion and loop closing
        merged = 0
        self._kf_since_fusion += 1
        if cfg.fusion.enabled and self._kf_since_fusion >= cfg.fusion.interval_keyframes:
            merged = self._fusion_round(x0)
            self._kf_since_fusion = 0
        closures = 0
        self._kf_since_closure += 1
        lcc = cfg.loop_closure
        if lcc.enabled and self._kf_since_closure >= lcc.interval_keyframes:
            self._kf_since_closure = 0
            closures = self._loop_closure(i)
        return ScanReport(
            scan=scan_no,
            keyframe=True,
            pose_index=i,
            lines=K,
            candidates=len(local.lines),
            matched=int(matched.sum()),
            new_landmarks=int(new.size),
            ambiguous=ambiguous,
            merged=merged,
            loop_closures=closures,
            warnings=tuple(warned),
        )

    def _relocalise(
        self,
        scan_set: LineSet,
        obs: _Lines,
        local: _LocalMap,
        x_pred: FloatArray,
        P0: FloatArray,
        reg: Any,
    ) -> Any:
        """Search the scan's lines in the local map around ``x_pred``; register again.

        The registration restarts from the correction found; the better of the two
        registrations (more pairs) is returned.
        """
        from slam.frontend.loop_closure import LoopLines, search_loop_closure

        rc = self.config.frontend.relocalisation
        z = obs.z
        a_w = np.asarray(wrap_angle(z[:, 1] + x_pred[2]))
        r_w = z[:, 0] + x_pred[0] * np.cos(a_w) + x_pred[1] * np.sin(a_w)
        ends = scan_set.endpoints_in(x_pred)
        scan_ll = LoopLines(a_w, r_w, ends)
        map_ll = LoopLines.from_anchored(local.rho_phi, local.anchors, local.extents, local.side)
        found = search_loop_closure(
            scan_ll, map_ll, x_pred[:2], rc.window_xy_m, rc.window_theta_rad, rc, window_prior=True
        ).closure
        self.counters["relocalisations"] += 1
        if found is None:
            return reg
        t = found.correction
        x_new = np.array([x_pred[0] + t[0], x_pred[1] + t[1], float(wrap_angle(x_pred[2] + t[2]))])
        fc = self.config.frontend
        P1 = np.diag([fc.prior_sigma_xy_m**2, fc.prior_sigma_xy_m**2, fc.prior_sigma_theta_rad**2])
        reg2 = register_lines(scan_set, local.lines, x_new, P1 + 0.1 * P0, fc.registration)
        if reg2.n_matches > reg.n_matches:
            self.counters["relocalisations_used"] += 1
            return reg2
        return reg

    def _add_registration_factor(
        self, prev: int, i: int, x_reg: FloatArray, reg_cov: FloatArray
    ) -> None:
        """Relative-pose factor ``prev → i`` from the registration (inflated covariance).

        The registration's covariance is that of the absolute pose given the local map; as a
        relative pose from the previous keyframe (whose estimate the local map is tied to) it
        is used as is, times ``pose_factor_inflation`` (double counting with the line factors).
        """
        g = self.graph
        rel = pose_between(g.poses[prev], x_reg)
        cov = self.config.frontend.pose_factor_inflation * np.asarray(reg_cov)
        g.add_odometry(prev, i, rel, 0.5 * (cov + cov.T))

    def _add_factors(
        self, pose: int, lms: IntArray, obs: _Lines, rows: IntArray, x0: FloatArray
    ) -> IntArray:
        """Line factors from ``pose`` to graph landmarks ``lms`` for the lines ``rows``."""
        g = self.graph
        if rows.size == 0:
            return np.zeros(0, dtype=np.intp)
        factors = g.add_line_factors(
            pose,
            lms,
            obs.z[rows],
            obs.R[rows],
            obs.endpoints[rows],
            obs.endpoint_var[rows],
            pieces=[obs.pieces[k] for k in rows],
            pieces_var=[obs.pieces_var[k] for k in rows],
        )
        self._note_observations(lms, obs.z[rows], obs.R[rows], x0, pose)
        return factors

    def _note_observations(
        self, lms: IntArray, z: FloatArray, R: FloatArray, pose_world_laser: FloatArray, kf: int
    ) -> None:
        """Front-end bookkeeping of observations of graph landmarks (information, last seen)."""
        g = self.graph
        _, P = observe_anchored(z, R, pose_world_laser, g.anchors[lms])
        np.add.at(self._lm_info.data, lms, np.linalg.inv(P))
        self._lm_last_kf.data[lms] = np.maximum(self._lm_last_kf.data[lms], kf)

    def _new_graph_landmarks(
        self,
        rho_phi: FloatArray,
        anchors: FloatArray,
        info: FloatArray,
        last_kf: IntArray,
        side: FloatArray,
    ) -> IntArray:
        g = self.graph
        ids = g.add_landmarks(r_alpha_from_anchored(rho_phi, anchors), anchors)
        self._lm_info.append(info)
        self._lm_last_kf.append(last_kf)
        self._lm_side.append(side)
        self._extents = np.vstack([self._extents, np.full((ids.size, 2), np.nan)])
        return ids

    def _promote(self, tids: IntArray) -> IntArray:
        """Tentative landmarks ``tids`` become graph landmarks with all their observations."""
        tp = self.tentative
        if tids.size == 0:
            return np.zeros(0, dtype=np.intp)
        g = self.graph
        rows = tp.rows(tids)
        ids = self._new_graph_landmarks(
            tp.rho_phi[rows],
            tp.anchors[rows],
            np.asarray(np.linalg.inv(tp.cov[rows]), dtype=float),
            tp.last_kf[rows],
            tp.side[rows],
        )
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
        tp.remove(tids)
        self.counters["tentative_promoted"] += int(tids.size)
        return np.concatenate(out) if out else np.zeros(0, dtype=np.intp)

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

    # -- fusion ------------------------------------------------------------------------------
    def _merge(self, keep: int, drop: int) -> None:
        """Merge graph landmark ``drop`` into ``keep`` (front-end bookkeeping follows)."""
        g = self.graph
        # the dropped landmark's information, moved to the kept anchor (same line, so only the
        # chart's lever arm changes): P_keep_chart = T P_drop Tᵀ
        Jd = anchored_jacobian(g.landmarks[drop], g.anchors[drop])
        Jk = anchored_jacobian(g.landmarks[keep], g.anchors[keep])
        T = np.linalg.solve(Jk, Jd)
        Ti = np.linalg.inv(T)
        self._lm_info.data[keep] += Ti.T @ self._lm_info.data[drop] @ Ti
        self._lm_last_kf.data[keep] = max(self._lm_last_kf.data[keep], self._lm_last_kf.data[drop])
        g.merge_landmarks(keep, drop)

    def _merge_consistent(self, rec: Any) -> bool | None:
        """Whether a merge is explained by the current estimate (None: no longer checkable).

        Both sides of the merged landmark (the factors that came with the dropped landmark and
        the kept landmark's others) must have a median whitened squared residual below
        ``audit_max_median_chi2``: after a wrong merge the optimum sits on one side and the
        other side's measurements are all off.
        """
        worst = self._merge_chi2(rec)
        if worst is None:
            return None
        return worst <= self.config.fusion.audit_max_median_chi2

    def _merge_chi2(self, rec: Any) -> float | None:
        """The larger of a merge's two sides' median whitened squared residuals.

        None when no longer checkable; see :meth:`_merge_consistent`.
        """
        g = self.graph
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

    def _audit(self, records: list[Any]) -> int:
        """Undo the merges among ``records`` that the estimate does not explain.

        Returns how many were undone; an undone pair is never merged again by fusion.
        """
        g = self.graph
        undone = []
        for rec in records:
            if self._merge_consistent(rec) is False:
                g.unmerge(rec)
                undone.append(rec)
                self._vetoed.add((min(rec.keep, rec.drop), max(rec.keep, rec.drop)))
        if undone:
            self._recompute_info(
                np.array(sorted({r.keep for r in undone} | {r.drop for r in undone}))
            )
            self._extents = g.landmark_extents()
            self.counters["merges_undone"] += len(undone)
        return len(undone)

    def _fusion_round(self, x_now: FloatArray, everywhere: bool = False) -> int:
        """Merge pairs of graph landmarks that are one wall (near the robot, or everywhere).

        Candidates: landmarks seen since the last round against alive landmarks within
        ``association.max_range_m`` of the robot (all alive ones with ``everywhere``), geometric
        pre-filter of :func:`slam.line_slam.fusion.fusion_candidates`, then the Eq. 34-35 test with
        the landmarks' covariances relative to the poses that saw them plus the drift between
        their last sightings (no joint marginal needed: both are measured relative to nearby
        poses).
        """
        from slam.line_slam.fusion import fusion_candidates

        t0 = time.perf_counter()
        cfg = self.config
        g = self.graph
        if self._to_audit:
            self._audit(self._to_audit)
            self._to_audit = []
        n_log = len(g.merge_log)
        alive = g.landmark_alive & np.isfinite(self._extents).all(axis=1)
        if everywhere:
            subset = np.flatnonzero(alive)
            others = subset
        else:
            recent_from = g.n_poses - cfg.fusion.interval_keyframes
            subset = np.flatnonzero(alive & (self._lm_last_kf.data >= recent_from))
            others = candidate_landmarks(
                x_now,
                g.landmarks_r_alpha,
                self._extents,
                cfg.association.max_range_m,
                alive=alive,
                anchors=g.anchors,
            )
        pairs = fusion_candidates(g, self._extents, subset, cfg.fusion, others=others)
        merged = 0
        if pairs:
            a = np.array([p[0] for p in pairs])
            b = np.array([p[1] for p in pairs])
            la = g.landmarks_r_alpha
            # drift between their last sightings
            last = self._lm_last_kf.data
            gap = np.abs(self._kf_path.data[last[a]] - self._kf_path.data[last[b]])
            if not everywhere:
                # far apart in path: loop closing's job (submap verification), not fusion's
                near = gap <= cfg.fusion.max_path_gap_m
                a, b, gap = a[near], b[near], gap[near]
            Pa = self._landmark_cov(a)
            Pb = self._landmark_cov(b)
            fc = cfg.frontend
            # the drift rotates b about the robot where it last saw b
            seen_from = g.poses[last[b], :2]
            Pb = Pb + drift_covariance(
                g.landmarks[b],
                g.anchors[b],
                seen_from,
                fc.drift_xy_per_m * gap,
                fc.drift_theta_per_m * gap,
            )
            Ja = anchored_jacobian(g.landmarks[a], g.anchors[a])
            Jb = anchored_jacobian(g.landmarks[b], g.anchors[b])
            Pa = Ja @ Pa @ np.swapaxes(Ja, -1, -2)
            Pb = Jb @ Pb @ np.swapaxes(Jb, -1, -2)
            tested = []
            for k in range(a.size):
                if (int(a[k]), int(b[k])) in self._vetoed:
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
            for _, ia, ib in tested:
                keep, drop = (ia, ib) if counts[ia] >= counts[ib] else (ib, ia)
                if ia in dropped or ib in dropped or drop in kept:
                    continue
                self._merge(keep, drop)
                kept.add(keep)
                dropped.add(drop)
                merged += 1
        if merged:
            self.counters["landmarks_merged"] += merged
            self._extents = g.landmark_extents()
            self._to_audit = list(g.merge_log[n_log:])
        self.time_s["fusion"] += time.perf_counter() - t0
        return merged

    # -- loop closing ------------------------------------------------------------------------
    def _loop_closure(self, pose: int) -> int:
        """Search the old map for the local submap; merge verified pairs; undo if unexplained.

        Returns 1 when a closure was accepted, else 0.
        """
        from slam.frontend.loop_closure import search_loop_closure

        t0 = time.perf_counter()
        cfg = self.config
        lcc = cfg.loop_closure
        g = self.graph
        try:
            alive = g.landmark_alive & np.isfinite(self._extents).all(axis=1)
            last = self._lm_last_kf.data
            local = np.flatnonzero(alive & (last > pose - lcc.local_keyframes))
            if local.size < lcc.min_matches:
                return 0
            x = g.poses[pose]
            sxy, _ = self._drift_sigmas(last)
            old_mask = (
                alive & (sxy > cfg.frontend.max_drift_xy_m) & (last <= pose - lcc.local_keyframes)
            )
            d_old = self._path - self._kf_path.data[last]
            win_xy = np.clip(lcc.window_xy_per_m * d_old, lcc.min_window_xy_m, lcc.max_window_xy_m)
            win_th = np.clip(
                lcc.window_theta_per_m * d_old, lcc.min_window_theta_rad, lcc.max_window_theta_rad
            )
            reach = cfg.association.max_range_m + win_xy
            near = candidate_landmarks(
                x,
                g.landmarks_r_alpha,
                self._extents,
                float(reach.max(initial=0.0)),
                alive=old_mask,
                anchors=g.anchors,
            )
            if near.size < lcc.min_matches:
                return 0
            # the window: what the oldest candidate allows (capped); a hypothesis must also lie
            # within what the old lines it pairs allow (window_of_pairs)
            wxy = float(np.max(win_xy[near]))
            wth = float(np.max(win_th[near]))
            self.counters["loop_closure_attempts"] += 1
            search = search_loop_closure(
                self._loop_lines(local),
                self._loop_lines(near),
                x[:2],
                wxy,
                wth,
                lcc,
                old_windows=(win_xy[near], win_th[near]) if lcc.window_of_pairs else None,
            )
            found = search.closure
            if found is None:
                self._closure_log.append(
                    {
                        "keyframe": int(pose),
                        "local": int(local.size),
                        "old": int(near.size),
                        "window": [wxy, wth],
                        "accepted": False,
                        "reason": search.reason,
                    }
                )
                return 0
            repeated = self._repeated_rejection(found, pose)
            if repeated is not None:
                self._closure_log.append(
                    {
                        "keyframe": int(pose),
                        "pairs": len(found.pairs),
                        "correction": [float(v) for v in found.correction],
                        "accepted": False,
                        "reason": f"repeats the hypothesis rejected at keyframe {repeated}",
                    }
                )
                self.counters["loop_closures_repeated"] += 1
                return 0
            # the marginals' gate: a correction the back-end's uncertainty cannot explain is
            # not worth a judgement (max_correction_chi2)
            old_last = self._lm_last_kf.data[near[[j for _, j in found.pairs]]]
            k_old = int(np.median(old_last))
            corr_eff = self._effective_correction(found, near)
            chi2_t = self._correction_chi2(k_old, pose, corr_eff)
            if chi2_t > lcc.max_correction_chi2 and not self._gate_overridden(corr_eff, pose):
                self._closure_log.append(
                    {
                        "keyframe": int(pose),
                        "pairs": len(found.pairs),
                        "correction": [float(v) for v in found.correction],
                        "correction_chi2": chi2_t,
                        "accepted": False,
                        "reason": "correction beyond the marginals' gate",
                        **self._closure_where(pose, k_old),
                    }
                )
                self.counters["loop_closures_gated"] += 1
                return 0
            self.counters["loop_closure_candidates"] += 1
            return self._apply_closure(local, near, found, pose, chi2_t)
        finally:
            self.time_s["loop_closure"] += time.perf_counter() - t0

    def _gate_overridden(self, correction: FloatArray, pose: int) -> bool:
        """Whether the gate lets a correction through after turning it away repeatedly.

        ``LoopClosureConfig.gate_override_after``; a correction not let through is recorded as
        gated.
        """
        from slam.frontend.loop_closure import same_correction

        lcc = self.config.loop_closure
        self._gated = [g for g in self._gated if g[0] > pose - lcc.local_keyframes]
        if lcc.gate_override_after > 0:
            seen = sum(same_correction(correction, c, lcc) for _, c in self._gated)
            if seen >= lcc.gate_override_after:
                self.counters["loop_closure_gate_overrides"] += 1
                return True
        self._gated.append((int(pose), np.asarray(correction, dtype=float)))
        return False

    def _repeated_rejection(self, found: Any, pose: int) -> int | None:
        """The keyframe of a recent rejected hypothesis that ``found`` repeats, if any.

        See ``LoopClosureConfig.skip_repeated_rejections``.
        """
        lcc = self.config.loop_closure
        self._rejected = [r for r in self._rejected if r[0] > pose - lcc.local_keyframes]
        if not lcc.skip_repeated_rejections:
            return None
        from slam.frontend.loop_closure import same_correction

        corr = np.asarray(found.correction, dtype=float)
        for kf, rejected, n_pairs in self._rejected:
            if same_correction(corr, rejected, lcc) and len(found.pairs) <= n_pairs:
                return kf
        return None

    def _loop_lines(self, lms: IntArray) -> Any:
        from slam.frontend.loop_closure import LoopLines

        g = self.graph
        v = g.landmarks[lms]
        c = g.anchors[lms]
        return LoopLines.from_anchored(v, c, self._extents[lms], self._lm_side.data[lms])

    def _effective_correction(self, found: Any, old: IntArray) -> FloatArray:
        """The hypothesis' correction; along a corridor without its arbitrary along-component."""
        corr = np.asarray(found.correction, dtype=float).copy()
        if found.single_direction:
            a = self._loop_lines(old[[found.pairs[0][1]]]).alpha[0]
            n = np.array([np.cos(a), np.sin(a)])
            corr[:2] = (corr[:2] @ n) * n
        return corr

    def _closure_where(self, pose: int, k_old: int) -> dict[str, Any]:
        """Where a loop-closure candidate was: the two keyframes, their scans and poses."""
        g = self.graph
        return {
            "scan": int(self._kf_scan.data[pose]),
            "old_keyframe": k_old,
            "old_scan": int(self._kf_scan.data[k_old]),
            "pose_before": [float(v) for v in g.poses[pose]],
            "old_pose_before": [float(v) for v in g.poses[k_old]],
        }

    def _apply_closure(
        self,
        local: IntArray,
        old: IntArray,
        found: Any,
        pose: int,
        chi2_t: float = float("nan"),
    ) -> int:
        """Spread the correction, merge the verified pairs, judge; keep only if explained.

        The candidate is judged by a batch solve in our own loop
        (:class:`slam.graph.batch.BatchSolver`, ``judge_iterations`` at most) of the loop (the
        poses since ``local_keyframes`` before the old landmarks were last seen, the earlier
        ones held; the whole graph with ``judge_loop_only = False``) without touching
        the back-end: a rejected closure is rolled back (merges and estimate) and the back-end
        never sees it; an accepted one with a large correction restarts the back-end from the
        judged estimate, a small one reaches it incrementally (``large_correction_*``).
        """
        g = self.graph
        lcc = self.config.loop_closure
        saved = (g.poses.copy(), g.landmarks.copy())
        old_last = self._lm_last_kf.data[old[[j for _, j in found.pairs]]]
        k_old = int(np.median(old_last))
        where = self._closure_where(pose, k_old)
        corr = self._effective_correction(found, old)
        big = bool(
            np.hypot(corr[0], corr[1]) > lcc.large_correction_m
            or abs(corr[2]) > lcc.large_correction_rad
        )
        if big:
            self._spread_correction(corr, g.poses[pose, :2].copy(), k_old, pose)
        n_log = len(g.merge_log)
        info_saved = (self._lm_info.data.copy(), self._lm_last_kf.data.copy())
        done: set[int] = set()
        for i, j in found.pairs:
            keep, drop = int(old[j]), int(local[i])
            if drop in done or not (g.landmark_alive[keep] and g.landmark_alive[drop]):
                continue
            self._merge(keep, drop)
            done.add(drop)
        if not done:
            g.poses[:] = saved[0]
            g.landmarks[:] = saved[1]
            return 0
        # the map before the loop is the reference: held, only the loop is solved
        free_from = max(int(old_last.min()) - lcc.local_keyframes, 0) if lcc.judge_loop_only else 0
        t0 = time.perf_counter()
        records = list(g.merge_log[n_log:])

        def hopeless(iterations: int, poses: FloatArray, landmarks: FloatArray) -> bool:
            """At most one pair explained after ``judge_hopeless_after`` linearisations."""
            if iterations != lcc.judge_hopeless_after:
                return False
            kept = (g.poses.copy(), g.landmarks.copy())
            g.poses[:], g.landmarks[:] = poses, landmarks
            good = sum(self._merge_consistent(r) is True for r in records)
            g.poses[:], g.landmarks[:] = kept
            return good <= 1

        judged = self._judge.solve(g, lcc.judge_iterations, free_from=free_from, stop=hopeless)
        self.time_s["judge"] += time.perf_counter() - t0
        chi2 = [c for c in (self._merge_chi2(r) for r in records) if c is not None]
        good = sum(c <= self.config.fusion.audit_max_median_chi2 for c in chi2)
        worst = max(chi2, default=0.0)
        entry: dict[str, Any] = {
            "keyframe": int(pose),
            "pairs": len(done),
            "consistent_pairs": good,
            "worst_pair_chi2": worst,
            "correction": [float(v) for v in found.correction],
            "single_direction": bool(found.single_direction),
            "score": float(found.score),
            "runner_up": float(found.runner_up),
            "judge_iterations": judged.iterations,
            "judge_stop": judged.reason,
            "judge_free_from": free_from,
            "correction_chi2": chi2_t,
            **where,
        }
        if (
            good >= max(lcc.min_matches - 1, 2)
            and good >= lcc.min_consistent_fraction * len(records)
            and worst <= lcc.judge_max_pair_chi2
        ):
            # explained (up to a few wrong pairs, which are undone)
            self._audit(records)
            self._converge(reset=big)
            entry["accepted"] = True
            entry["backend_restarted"] = big
            self._closure_log.append(entry)
            self.counters["loop_closures"] += 1
            return 1
        # not explained: the back-end never saw it; roll the merges and the estimate back
        g.revert_merges(n_log)
        self._lm_info.data[:] = info_saved[0]
        self._lm_last_kf.data[:] = info_saved[1]
        g.poses[:] = saved[0]
        g.landmarks[:] = saved[1]
        self._extents = g.landmark_extents()
        entry["accepted"] = False
        self._closure_log.append(entry)
        self.counters["loop_closures_undone"] += 1
        self._rejected.append(
            (int(pose), np.asarray(found.correction, dtype=float), len(found.pairs))
        )
        return 0

    def _correction_chi2(self, k_old: int, pose: int, correction: FloatArray) -> float:
        """The correction's squared Mahalanobis distance under the back-end's marginals.

        :func:`slam.frontend.loop_closure.correction_chi2` with the joint covariance of the
        keyframe where the paired old lines were last seen and the current one.
        """
        from slam.frontend.loop_closure import correction_chi2

        g = self.graph
        P = self.backend.joint_pose_covariance(g, np.array([k_old, pose], dtype=np.intp))
        return correction_chi2(g.poses[k_old], g.poses[pose], P, correction)

    def _converge(self, reset: bool) -> None:
        """Bring the back-end to the graph, converge, and refresh the extents.

        With ``reset`` iSAM2 is rebuilt from the graph's estimate (after a large change of it).
        """
        g = self.graph
        t0 = time.perf_counter()
        if reset:
            self.backend.reset(g)
        else:
            self.backend.update(g)
        self.backend.optimize(g, self.config.loop_closure.max_updates)
        self._extents = g.landmark_extents()
        self.time_s["backend"] += time.perf_counter() - t0

    def _spread_correction(
        self, correction: FloatArray, center: FloatArray, k_old: int, pose: int
    ) -> None:
        """Move the estimate towards a loop closure before optimising (a good starting point).

        The local submap (the last ``local_keyframes`` keyframes) moves by the whole correction
        ``T`` (``p → R(dθ)(p − c) + c + t``), poses since ``k_old`` (when the old landmarks were
        last seen) by the fraction ``f`` of the path driven since then, ``T_f = (f t, f dθ)``;
        landmarks move with the fraction of their last sighting.
        """
        g = self.graph
        lcc = self.config.loop_closure
        path = self._kf_path.data
        start = max(pose - lcc.local_keyframes, 0)
        span = max(path[start] - path[k_old], 1e-9)

        def fraction(kf: IntArray) -> FloatArray:
            return np.clip((path[kf] - path[k_old]) / span, 0.0, 1.0)

        tx, ty, dth = (float(v) for v in correction)
        f = fraction(np.arange(g.n_poses))
        ang = f * dth
        cs, sn = np.cos(ang), np.sin(ang)
        d = g.poses[:, :2] - center
        g.poses[:, 0] = cs * d[:, 0] - sn * d[:, 1] + center[0] + f * tx
        g.poses[:, 1] = sn * d[:, 0] + cs * d[:, 1] + center[1] + f * ty
        g.poses[:, 2] = np.asarray(wrap_angle(g.poses[:, 2] + ang))
        alive = np.flatnonzero(g.landmark_alive)
        fl = fraction(self._lm_last_kf.data[alive])
        la = g.landmarks_r_alpha[alive]
        a_new = la[:, 1] + fl * dth
        n_old = np.stack([np.cos(la[:, 1]), np.sin(la[:, 1])], -1)
        n_new = np.stack([np.cos(a_new), np.sin(a_new)], -1)
        r_new = la[:, 0] - n_old @ center + n_new @ center + n_new @ np.array([tx, ty]) * fl
        g.set_landmarks_r_alpha(alive, np.column_stack([r_new, a_new]))

    def _recompute_info(self, lms: IntArray) -> None:
        """Front-end information of ``lms`` from their factors (after undoing merges)."""
        g = self.graph
        for j in lms:
            f = np.flatnonzero(g.factor_landmark == j)
            if f.size == 0:
                continue
            poses = g.poses[g.factor_pose[f]]
            _, P = observe_anchored(
                g.factor_z[f], g.factor_cov[f], poses, np.broadcast_to(g.anchors[j], (f.size, 2))
            )
            self._lm_info.data[j] = np.linalg.inv(P).sum(axis=0)
            self._lm_last_kf.data[j] = int(g.factor_pose[f].max())

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
            if self._fusion_round(self.graph.poses[-1], everywhere=True) == 0:
                break
            self.backend.update(self.graph)
        if self._to_audit:
            # the last round's merges, checked at the converged estimate
            stats = self.backend.optimize(self.graph)
            if self._audit(self._to_audit):
                self.backend.update(self.graph)
                stats = self.backend.optimize(self.graph)
            self._to_audit = []
            self._extents = self.graph.landmark_extents()
        self.time_s["optimize"] += time.perf_counter() - t0
        return stats

    def _scan_poses(self) -> tuple[FloatArray, IntArray, FloatArray]:
        """Pose of every scan: keyframes as estimated, others interpolated between keyframes.

        A scan between keyframes ``k`` and ``k+1`` is ``x_k ∘ δ_s ∘ Exp(f·Log(C))`` with ``δ_s``
        its odometry since ``k``, ``C = δ_{k+1}⁻¹ (x_k⁻¹ x_{k+1})`` the correction the estimate
        made to the odometry between the two keyframes and ``f`` the fraction of that stretch
        already driven (path, turning weighted by :data:`ANGLE_WEIGHT_M_PER_RAD`).  After the
        last keyframe: ``x_k ∘ δ_s``.
        """
        g = self.graph
        n = len(self._timestamps)
        kf = np.asarray(self._scan_kf, dtype=np.intp)
        offsets = np.array(self._scan_offset).reshape(n, 3)
        if n == 0:
            return np.zeros((0, 3)), kf, offsets
        poses = pose_compose(g.poses[kf], offsets)
        nxt = kf + 1
        has_next = (nxt < g.n_poses) & ~np.asarray(self._scan_is_kf, dtype=bool)
        if np.any(has_next):
            k = kf[has_next]
            d_next = self._kf_delta.data[k + 1]
            est = pose_between(g.poses[k], g.poses[k + 1])
            corr = pose_log(pose_between(d_next, est))
            total = np.hypot(d_next[:, 0], d_next[:, 1]) + ANGLE_WEIGHT_M_PER_RAD * np.abs(
                d_next[:, 2]
            )
            prog = np.asarray(self._scan_progress, dtype=float)[has_next]
            f = np.clip(prog / np.maximum(total, 1e-9), 0.0, 1.0)
            poses[has_next] = pose_compose(poses[has_next], pose_exp(f[:, None] * corr))
        poses[:, 2] = np.asarray(wrap_angle(poses[:, 2]))
        return poses, kf, offsets

    def result(self) -> SlamResult:
        """The current estimate of every scan's pose and the map, with covariances."""
        g = self.graph
        t0 = time.perf_counter()
        n = len(self._timestamps)
        poses, kf, offsets = self._scan_poses()
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
        frame = self.policy.output_frame
        poses, cov_out = self.policy.report(poses, cov)
        assert cov_out is not None
        cov = cov_out
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
        stats["loop_closures_log"] = list(self._closure_log)
        stats["runtime_s"] = {
            "total": float(np.sum(self._scan_runtime)) + self.time_s["optimize"],
            **{k: float(v) for k, v in self.time_s.items()},
        }
        return SlamResult(
            timestamps=np.asarray(self._timestamps, dtype=float),
            poses_world_laser=poses,
            pose_covariances=cov,
            is_keyframe=np.asarray(self._scan_is_kf, dtype=bool),
            keyframe_of_scan=kf.astype(np.int64),
            landmark_ids=ids.astype(np.int64),
            landmarks_r_alpha=la_nf,
            landmark_covariances=lcov_nf,
            landmark_segments=segs,
            landmark_segments_var=seg_var,
            landmark_n_observations=counts[ids],
            scan_runtime_s=np.asarray(self._scan_runtime, dtype=float),
            n_landmarks=np.asarray(self._scan_n_landmarks, dtype=np.int64),
            stats=stats,
            frame=frame,
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
