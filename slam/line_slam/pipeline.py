"""``LineSlam``: factor-graph line SLAM fed one scan at a time.

Per scan (:meth:`LineSlam.add_scan`, or :meth:`LineSlam.add_scans` for a batch whose keyframes'
lines are extracted at once), the steps below; each is a collaborator in its own module.

1. **Odometry and keyframes** (:mod:`~slam.line_slam.keyframes`).  The input policy
   (:mod:`slam.inputs`) gives the laser's odometry; the scan becomes a keyframe (a pose
   variable) when the motion since the last keyframe exceeds ``keyframes.min_distance_m`` or
   ``keyframes.min_angle_rad``.  Other scans are recorded and placed at the end.

For each keyframe:

2. **Usable lines** (:mod:`~slam.line_slam.observations`): too few points, too short, or a
   degenerate covariance: dropped; the model-error floor is added to the others.
3. **Prediction**: ``x̂ = x_k ∘ δ`` with the motion noise ``Q(δ)`` (:mod:`slam.models.motion`).
   With ``frontend.scan_matching.enabled`` the keyframe's points are first matched against the
   previous keyframe's with ``(δ, Q)`` as the prior (:mod:`slam.frontend.scan_match`), and an
   accepted match replaces ``δ`` in ``x̂`` (``Q`` is kept; the match is no graph factor).  A
   match that finds the odometry's heading slipped (``scan_matching.slip_probability``)
   replaces the keyframe's odometry factor (the match's posterior under the slip component:
   the points' rotation, the translation moved with it), and the step is left out of the
   odometry-noise estimate.  A match not used (too little overlap) whose best solution is
   still a slip (``contradicted``) centres the step too, spread along the slip as far as the
   odometry's heading (:func:`~slam.frontend.scan_match.contradicted_covariance`): the points
   refute the odometry's heading but are not trusted as a measurement of it.
4. **Front end** (:mod:`~slam.line_slam.local_map`, :mod:`~slam.line_slam.front_end`): the
   lines are registered against the local map around ``x̂``; the registered pose is the
   keyframe's initial estimate and the registration's pairs are the data association.
5. **Pose**: a pose variable with its odometry factor (and, with ``frontend.pose_factor =
   "inflated"``, the registration as a relative-pose factor).
6. **Association** (:mod:`~slam.line_slam.associate`): line factors, tentative landmarks.
7. **Degradations** (:mod:`~slam.line_slam.report`): a :class:`SlamWarning` when the keyframe
   rests on odometry.
8. **Back-end update** (iSAM2 or periodic batch, :mod:`slam.graph.backend`).
9. **Landmark fusion** every ``fusion.interval_keyframes`` keyframes
   (:mod:`~slam.line_slam.fusion`, merges audited by :mod:`~slam.line_slam.audit`).
10. **Loop closing** every ``loop_closure.interval_keyframes`` keyframes
    (:mod:`~slam.line_slam.loop_closer`).

The map's state has one owner, the :class:`~slam.line_slam.landmarks.LandmarkBook`.
:meth:`LineSlam.optimize` runs a last fusion round over the whole map and converges the
back-end; :meth:`LineSlam.result` assembles a :class:`~slam.result.SlamResult`
(:mod:`~slam.line_slam.assembly`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import deque
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import bdtrc

from linefit.config import LineFitConfig
from linefit.line import Line
from slam import interrupts
from slam.errors import EstimationError, EvaluationError
from slam.extraction import extract_lines_of_scans, extract_scan_lines
from slam.frontend.scan_match import (
    ScanMatch,
    ScanPoints,
    contradicted_covariance,
    match_scans,
    refine_scan,
    scale_points_information,
    scan_points,
    scan_view,
)
from slam.geometry import pose_between, pose_compose, pose_log
from slam.graph.backend import BatchBackend, Isam2Backend, make_backend
from slam.graph.problem import LineGraph
from slam.inputs import InputPolicy
from slam.line_slam.assembly import assemble_result
from slam.line_slam.associate import associate_lines
from slam.line_slam.audit import MergeAudit
from slam.line_slam.clock import StageClock
from slam.line_slam.config import SlamConfig
from slam.line_slam.drift import DriftAccumulator
from slam.line_slam.front_end import add_registration_factor, register_keyframe
from slam.line_slam.fusion import LandmarkFusion
from slam.line_slam.keyframes import KeyframeTrack, OdometryStep
from slam.line_slam.landmarks import LandmarkBook
from slam.line_slam.line_noise import LineModelErrorEstimator, LineReweighting
from slam.line_slam.local_map import LocalMap, build_local_map
from slam.line_slam.loop_closer import LoopCloser
from slam.line_slam.observations import usable_lines
from slam.line_slam.odometry_calibration import (
    MountingEstimator,
    OdometryAndMountingCalibrator,
)
from slam.line_slam.odometry_noise import MotionNoiseEstimator, odometry_error
from slam.line_slam.passes import (
    PassError,
    estimate_pass_error,
    find_passes,
    fitted_pairs,
    with_pass_links,
)
from slam.line_slam.range_noise import RangeNoiseCheck
from slam.line_slam.report import (
    COUNTERS,
    MIRRORED_P_VALUE,
    ScanReport,
    SlamWarning,
    degradation,
    warn_mirrored,
)
from slam.result import SlamResult
from slam.types import Scan, check_lines, check_scan
from slam.validate import check_config

PASS_PAIRS = 300
"""Most pairs of passes the pass error is estimated from (each costs two solves)."""

MAX_STRETCH_SCANS = 256
"""Most scans between two keyframes whose points are kept, should the next keyframe's match
find a slip (:meth:`LineSlam._research_stretch`): a memory bound (a few MB), reached only
where the robot stands still for a while, which makes no keyframe."""

FloatArray = NDArray[np.float64]


class _StretchScan(NamedTuple):
    """A scan matched since the last keyframe, kept for a search after a slip."""

    scan_no: int
    points: ScanPoints
    delta: FloatArray  # the odometry's offset from the keyframe
    Q: FloatArray  # its covariance, the refinement's prior
    accepted: bool
    searched: bool


__all__ = ["COUNTERS", "LineSlam", "ScanReport", "SlamWarning"]


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

    Attributes
    ----------
    graph : LineGraph
        The factor graph (poses, landmarks, factors).
    backend : BatchBackend or Isam2Backend
        The online estimator.
    track, book, audit, fusion, loop_closer
        The steps' collaborators (keyframe track, landmark book, merge audit, landmark
        fusion, loop closer).
    counters : dict of str to int
        What happened so far (:data:`COUNTERS`).
    clock : StageClock
        Time per stage.

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
        self.config = check_config(config, SlamConfig, "config")
        self.linefit_config = check_config(linefit_config, LineFitConfig, "linefit_config")
        policy = None if policy is None else check_config(policy, InputPolicy, "policy")
        self.policy = policy if policy is not None else InputPolicy.of(self.config)
        cfg = self.config
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.clock = StageClock()
        self.graph = LineGraph()
        self.backend: BatchBackend | Isam2Backend = make_backend(cfg.backend, cfg.solver, cfg.isam2)
        self.track = KeyframeTrack(cfg.keyframes)
        self.drift = DriftAccumulator(cfg.frontend.drift_xy_per_m, cfg.frontend.drift_theta_per_m)
        self.odometry_noise = MotionNoiseEstimator(cfg.motion)
        # used with odometry_calibration other than "off": the laser's mounting from the
        # graph's estimate of the steps, and with "estimated" the three biases from the
        # registrations as well
        self.odometry_calibrator: OdometryAndMountingCalibrator | MountingEstimator = (
            OdometryAndMountingCalibrator()
            if cfg.odometry_calibration == "estimated"
            else MountingEstimator()
        )
        # the keyframe steps, for the mounting they imply at the end (never applied with
        # odometry_calibration = "off")
        self.mounting_steps = self.odometry_calibrator
        self._points: ScanPoints | None = None  # the previous keyframe's, for scan matching
        # the latest scans matched since that keyframe
        self._stretch: deque[_StretchScan] = deque(maxlen=MAX_STRETCH_SCANS)
        self.range_noise = RangeNoiseCheck(self.linefit_config.noise.sigma_range_m)
        self._warned_mirrored = False
        self.line_noise = LineModelErrorEstimator(
            cfg.line_model_sigma_r_m, cfg.line_model_sigma_alpha_rad
        )
        self.line_weights = LineReweighting(self.line_noise, cfg.line_model_error == "estimated")
        self.pass_error: PassError | None = None  # with line_pass_error = "estimated"
        self.covariance_graph = self.graph  # the graph the covariances come from (result())
        self.book = LandmarkBook(self.graph, cfg.frontend)
        self.audit = MergeAudit(self.book, cfg.fusion, self.counters)
        self.fusion = LandmarkFusion(
            self.book, self.drift, self.audit, cfg, self.counters, self.clock
        )
        self.loop_closer = LoopCloser(
            self.book,
            self.track,
            self.drift,
            self.audit,
            self.backend,
            cfg,
            self.counters,
            self.clock,
        )

    @property
    def time_s(self) -> dict[str, float]:
        """Seconds spent per stage (:data:`slam.line_slam.clock.STAGES`)."""
        return self.clock.time_s

    # -- scans -------------------------------------------------------------------------------
    def add_scans(self, scans: Sequence[Scan]) -> list[ScanReport]:
        """Process several scans.

        The lines of those that become keyframes are extracted together
        (:func:`slam.extraction.extract_lines_of_scans`, the vectorised fast path).  A signal
        (:mod:`slam.interrupts`) stops it between two scans (:class:`~slam.interrupts.Interrupted`).
        """
        scans = [check_scan(s, f"scans[{k}]") for k, s in enumerate(scans)]
        odometry = [self.policy.pose_odom_laser(s) for s in scans]
        keyframes = [n for n, kf in enumerate(self.track.keyframe_mask(odometry)) if kf]
        with self.clock("extract"):
            extracted = extract_lines_of_scans([scans[n] for n in keyframes], self.linefit_config)
        lines = dict(zip(keyframes, extracted, strict=True))
        reports = []
        for n, s in enumerate(scans):
            interrupts.check()
            reports.append(self.add_scan(s, lines.get(n, [])))
        return reports

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
            ``scan`` is not a :class:`Scan`, ``lines`` not a sequence of :class:`Line`, or
            the scan has no (finite) odometry.
        """
        check_scan(scan)
        if lines is not None:
            lines = check_lines(lines, scan)
        t_start = time.perf_counter()
        step = self.track.step(self.policy.pose_odom_laser(scan), scan.odometry_step_cov)
        scan_no = self.track.n_scans
        if not step.keyframe:
            kf = self.graph.n_poses - 1
            offset, offset_cov = self._between_keyframes(scan, step, scan_no)
            self._record(scan, kf, offset, False, t_start, offset_cov)
            return ScanReport(scan_no, False, kf)
        if lines is None:
            with self.clock("extract"):
                lines = extract_scan_lines(scan, self.linefit_config)
        self.counters["lines_fit"] += len(lines)
        self.counters["points"] += int(np.count_nonzero(scan.valid_mask()))
        self.track.begin_keyframe(step, scan_no)
        points = None
        if self.config.frontend.scan_matching.enabled:
            with self.clock("frontend"):
                points = self._scan_points(scan)
            self.range_noise.add(points)
        report = self._keyframe(scan_no, step, lines, points)
        self.track.end_keyframe(step)
        self._record(scan, report.pose_index, np.zeros(3), True, t_start)
        return report

    def _between_keyframes(
        self, scan: Scan, step: OdometryStep, scan_no: int
    ) -> tuple[FloatArray, FloatArray | None]:
        """A scan that is not a keyframe: its offset from the keyframe, and its covariance.

        The odometry's offset (covariance None: the motion model's), or with
        ``scan_matching.between_keyframes`` the scan's points matched against the keyframe's
        from it (:func:`refine_scan`) where the match is accepted.  A refinement not accepted
        (too little overlap: the odometry may have slipped beyond its reach) is followed by
        the search a keyframe's match makes (:func:`match_scans`).  The scan's points are
        kept until the next keyframe: where that keyframe's match finds that the odometry
        slipped, the scans not yet searched are (:meth:`_research_stretch`).
        """
        smc = self.config.frontend.scan_matching
        if self.config.odometry_calibration != "off" and not step.first and step.cov is None:
            # the odometry's calibration, as estimated so far (as for a keyframe's step)
            step = replace(step, delta=self.odometry_calibrator.apply(step.delta))
        if not (smc.enabled and smc.between_keyframes) or self._points is None:
            return step.delta, None
        with self.clock("frontend"):
            points = self._scan_points(scan, with_normals=False)  # matched, never a reference
            Q = self._step_covariance(step)
            match = refine_scan(self._points, points, step.delta, Q, smc)
            searched = not match.accepted
            if searched:
                match = match_scans(self._points, points, step.delta, Q, smc)
                self.counters["scan_matches_between_searched"] += 1
        self._stretch.append(_StretchScan(scan_no, points, step.delta, Q, match.accepted, searched))
        if not match.accepted:
            self.counters["scan_matches_between_rejected"] += 1
            return step.delta, None
        self.counters["scan_matches_between"] += 1
        return match.delta, self._between_covariance(match.cov, Q)

    def _between_covariance(self, cov: FloatArray, Q: FloatArray) -> FloatArray:
        """A between scan's match covariance, its points' part scaled as the run's scatter."""
        # the points scatter as the run has measured, not as the noise model says
        ratio = self.range_noise.sigma_ratio
        factor = 1.0 if ratio is None else ratio**2
        return scale_points_information(cov, Q, factor)

    def _research_stretch(self) -> None:
        """Match the scans since the last keyframe again, with the search (:func:`match_scans`).

        Called when the new keyframe's match finds that the odometry slipped since the last
        keyframe: the odometry's offsets of the scans in between, from which
        :func:`refine_scan` started, were then off by part of the slip, and a refinement
        from them can settle on a rotation tens of degrees from the scan's.  Each not searched
        already is matched as a keyframe is (the rotations searched, the slip in the prior);
        an accepted match replaces its recorded offset (a rejected one leaves it as it was).
        The latest :data:`MAX_STRETCH_SCANS` scans are kept for this (a robot standing still
        makes no keyframe; earlier scans of such a stretch keep their refined offsets).
        """
        assert self._points is not None
        smc = self.config.frontend.scan_matching
        for s in self._stretch:
            if s.searched:
                continue
            match = match_scans(self._points, s.points, s.delta, s.Q, smc)
            self.counters["scan_matches_between_searched"] += 1
            if not match.accepted:
                continue
            if not s.accepted:
                self.counters["scan_matches_between_rejected"] -= 1
                self.counters["scan_matches_between"] += 1
            self.track.scan_offset[s.scan_no] = np.asarray(match.delta, dtype=float)
            self.track.scan_offset_cov[s.scan_no] = self._between_covariance(match.cov, s.Q)

    def _step_covariance(self, step: OdometryStep) -> FloatArray:
        """The covariance of the odometry's motion since the last keyframe.

        The odometry's own where it states one (the laser odometry's matches, composed by
        the keyframe track: large along a corridor whose walls show nothing along it, where
        its steps are the constant-velocity prediction's), else the motion model's.
        """
        if step.cov is not None:
            return step.cov
        return self.odometry_noise.model.covariance(step.delta)

    def _check_turn(self, turn_odom: float, Q: FloatArray, match: ScanMatch) -> None:
        """Count a turn the odometry is sure of (beyond 3σ) against the match's rotation.

        Scans whose beams run clockwise while the geometry says anticlockwise (a scanner
        mounted upside down) turn against the odometry at nearly every turn; a one-sided sign
        test (:data:`~slam.line_slam.report.MIRRORED_P_VALUE`) then warns once.
        """
        if not (match.accepted or match.contradicted):
            return
        if abs(turn_odom) <= 3.0 * math.sqrt(max(float(Q[2, 2]), 0.0)):
            return
        self.counters["scan_match_turns"] += 1
        self.counters["scan_match_turns_against"] += int(turn_odom * float(match.delta[2]) < 0.0)
        n, k = self.counters["scan_match_turns"], self.counters["scan_match_turns_against"]
        if not self._warned_mirrored and 2 * k > n:
            # P(at least k of n against), scipy.stats.binom.sf(k - 1, n, 0.5) from scipy.special
            p_value = float(bdtrc(k - 1, n, 0.5))
            if p_value < MIRRORED_P_VALUE:
                self._warned_mirrored = True
                warnings.warn(warn_mirrored(n, k), SlamWarning, stacklevel=4)

    def _scan_points(self, scan: Scan, with_normals: bool = True) -> ScanPoints:
        """The scan matcher's points of ``scan`` (:func:`scan_points`)."""
        return scan_points(
            scan.ranges,
            scan.bearings,
            scan.max_range_m,
            self.linefit_config.noise,
            self.config.frontend.scan_matching,
            with_normals=with_normals,
        )

    def _record(
        self,
        scan: Scan,
        kf: int,
        offset: FloatArray,
        keyframe: bool,
        t_start: float,
        offset_cov: FloatArray | None = None,
    ) -> None:
        self.track.record_scan(
            scan.timestamp,
            kf,
            offset,
            keyframe,
            int(np.count_nonzero(self.graph.landmark_alive)),
            time.perf_counter() - t_start,
            offset_cov,
        )

    # -- one keyframe ------------------------------------------------------------------------
    def _keyframe(
        self,
        scan_no: int,
        step: OdometryStep,
        lines: Sequence[Line],
        points: ScanPoints | None = None,
    ) -> ScanReport:
        cfg = self.config
        g = self.graph
        raw_delta = step.delta
        calibrate = cfg.odometry_calibration != "off" and not step.first and step.cov is None
        if calibrate:
            # the odometry's persistent error, as estimated so far, taken out of the step
            step = replace(step, delta=self.odometry_calibrator.apply(step.delta))
        # 2. usable lines
        obs, rejected = usable_lines(lines, cfg, self.line_noise.sigmas)
        K = len(obs)
        self.counters["lines_rejected"] += rejected
        self.counters["lines_used"] += K
        # 3. prediction
        prev = -1 if step.first else g.n_poses - 1
        x_pred = (
            step.pose_odom_laser.copy() if step.first else pose_compose(g.poses[prev], step.delta)
        )
        Q = self._step_covariance(step)
        x_odo = x_pred
        slip: ScanMatch | None = None
        step_delta = step.delta  # the step's odometry factor: the odometry, or what replaces it
        contradicted = False
        # 4. front end: the scan's points matched against the previous keyframe's with the
        # odometry as the prior (a slip the points see is corrected before the lines are
        # paired); then the lines registered against the local map = initial guess +
        # association.  The match moves the prediction (its covariance stays the odometry's);
        # it enters the graph only where it finds a slip, as that step's odometry factor (5.);
        # a match not used that finds a slip centres the step, spread as far as the odometry
        with self.clock("frontend"):
            if points is not None and self._points is not None and not step.first:
                match = match_scans(self._points, points, step.delta, Q, cfg.frontend.scan_matching)
                self.counters["scan_matches"] += 1
                self._check_turn(step.delta[2], Q, match)
                if match.accepted:
                    x_pred = pose_compose(g.poses[prev], match.delta)
                    if match.slip:
                        slip = match
                        self.counters["scan_match_slips"] += 1
                        self._research_stretch()
                else:
                    self.counters["scan_matches_rejected"] += 1
                    if match.contradicted:
                        # the points say the odometry's heading slipped, with too little
                        # overlap to be trusted as a measurement: the step is centred where
                        # they put it, spread along the slip as far as the odometry's heading
                        Q = contradicted_covariance(
                            Q, cfg.frontend.scan_matching, step.delta, match.delta, body=True
                        )
                        step_delta = match.delta
                        x_pred = pose_compose(g.poses[prev], match.delta)
                        contradicted = True
                        self.counters["scan_match_contradictions"] += 1
            # the reference of the next keyframe's match and of the scans before it: what it
            # could see, worked out once
            self._points = None if points is None else replace(points, view=scan_view(points))
            self._stretch.clear()
            local = LocalMap.empty()
            if K and not step.first:
                local = build_local_map(self.book, self.drift, x_pred, cfg)
            reg = register_keyframe(obs, local, x_pred, Q, cfg.frontend)
        self.counters["relocalisations"] += int(reg.relocalised)
        self.counters["relocalisations_used"] += int(reg.relocalisation_used)
        self.counters["registrations_failed"] += int(reg.failed)
        self.counters["registrations_rejected"] += int(reg.rejected)
        # the step's uncertainty (drift) and what it says about the odometry's noise
        self.drift.add_step(
            np.zeros((3, 3)) if step.first else (Q if reg.cov is None else reg.cov),
            self.track.path_m,
            None if step.first else pose_between(g.poses[prev], reg.pose_world_laser),
        )
        if reg.cov is not None and slip is None and not contradicted:
            # the odometry's own error, as the registration sees it
            c_odo = (
                reg.correction
                if x_pred is x_odo
                else pose_log(pose_between(x_odo, reg.pose_world_laser))
            )
            measured = odometry_error(c_odo, reg.prior_cov, reg.cov)
            if measured is not None:
                nu, P_L = measured
                self.odometry_noise.add_error(step.delta, nu, P_L)
                if calibrate and isinstance(
                    self.odometry_calibrator, OdometryAndMountingCalibrator
                ):
                    self.odometry_calibrator.add(raw_delta, nu, Q + P_L)
        self.odometry_noise.keyframe()
        if cfg.odometry_calibration != "off":
            self.odometry_calibrator.keyframe(g.poses)
        with self.clock("associate"):
            # 5. the pose and its odometry
            i = g.add_pose(reg.pose_world_laser)
            if step.first:
                g.set_prior(reg.pose_world_laser, cfg.prior_cov)
            else:
                if slip is None:
                    g.add_odometry(prev, i, step_delta, Q)
                    if step_delta is step.delta and step.cov is None:
                        self.mounting_steps.add_step(prev, i, step_delta, Q)
                else:
                    # the odometry's heading slipped: the step's factor is the match (the
                    # points' rotation, the translation moved with the slip)
                    g.add_odometry(prev, i, slip.delta, slip.cov)
                if cfg.frontend.pose_factor == "inflated" and reg.cov is not None:
                    add_registration_factor(g, prev, i, reg, cfg.frontend.pose_factor_inflation)
            # 6. association: line factors and tentative landmarks
            assoc = associate_lines(self.book, i, obs, reg, local, cfg.tentative, self.counters)
        # 7. degradations
        warned: tuple[str, ...] = ()
        degraded = degradation(K, step.first, len(local.lines), obs.z[assoc.matched, 1])
        if degraded is not None:
            self.counters[degraded[0]] += 1
            warned = (degraded[1],)
            warnings.warn(degraded[1], SlamWarning, stacklevel=3)
        # 8. back-end
        with self.clock("backend"):
            self.backend.update(g)
        self.book.update_extents(assoc.factors, self.backend.estimate_moved)
        if self.line_weights.keyframe(g, self.book.fit_cov):
            self.backend.reset(g)  # the line factors re-weighted with the model error estimated
        # 9. fusion and 10. loop closing
        merged = self.fusion.round(reg.pose_world_laser) if self.fusion.due() else 0
        closures = self.loop_closer.attempt(i) if self.loop_closer.due() else 0
        return ScanReport(
            scan=scan_no,
            keyframe=True,
            pose_index=i,
            lines=K,
            candidates=len(local.lines),
            matched=int(assoc.matched.sum()),
            new_landmarks=int(assoc.new.size),
            ambiguous=assoc.ambiguous,
            merged=merged,
            loop_closures=closures,
            warnings=warned,
        )

    # -- finishing ---------------------------------------------------------------------------
    def optimize(self) -> dict[str, Any]:
        """Final fusion over the whole map and convergence of the back-end.

        Returns the back-end's statistics of the last solve.  A signal
        (:mod:`slam.interrupts`) stops it between two solves (and within a batch solve, between
        its iterations).
        """
        t0 = time.perf_counter()
        stats: dict[str, Any] = {}
        g = self.graph
        if g.n_poses == 0:
            return stats
        # a loop-closure hypothesis still awaiting confirmation is judged now
        self.loop_closer.judge_pending()
        if self.line_weights.estimate(g, self.book.fit_cov):
            self.backend.reset(g)
        for _ in range(3):
            interrupts.check()
            stats = self.backend.optimize(g)
            interrupts.check()
            self.book.refresh_extents()
            if not self.config.fusion.enabled:
                break
            if self.fusion.round(g.poses[-1], everywhere=True) == 0:
                break
            self.backend.update(g)
        if self.fusion.pending_audit:
            # the last round's merges, checked at the converged estimate
            interrupts.check()
            stats = self.backend.optimize(g)
            interrupts.check()
            if self.audit.audit(self.fusion.pending_audit):
                self.backend.update(g)
                interrupts.check()
                stats = self.backend.optimize(g)
            self.fusion.pending_audit = []
            self.book.refresh_extents()
        self.clock.time_s["optimize"] += time.perf_counter() - t0
        return stats

    def _pass_model(self) -> tuple[PassError, LineGraph]:
        """The pass error estimated at the estimate, and the graph the covariances come from.

        :mod:`slam.line_slam.passes`: from at most :data:`PASS_PAIRS` pairs of passes; where
        the error is not zero, a copy of the graph with each pass of a multi-pass wall linked
        to it, else the graph itself.
        """
        cfg = self.config
        g = self.graph
        keyframe = np.asarray(self.track.scan_is_keyframe, dtype=bool)
        stamps = np.asarray(self.track.timestamps, dtype=float)[keyframe]
        kernel = (cfg.solver.robust_kernel, cfg.solver.robust_k)
        passes = find_passes(g, stamps, kernel, cfg.line_pass_gap_s)
        pairs = fitted_pairs(g, passes, kernel, max_pairs=PASS_PAIRS)
        error = estimate_pass_error(passes, pairs)
        linked, n_linked = with_pass_links(g, passes, error)
        return replace(error, linked_passes=n_linked), linked

    def write_graph_g2o(self, path: str | Path, result: SlamResult | None = None) -> Path:
        """Write the factor graph as ``graph.g2o`` (:func:`slam.io.g2o.write_line_graph_g2o`).

        With the run's ``result`` the file also says which scan each keyframe is and how
        every other scan hangs from its keyframe (odometry offset, the final motion model), so
        that the run's covariances can be recomputed from it (:mod:`slam.graph.relative`).
        """
        from slam.io.g2o import write_line_graph_g2o

        solver = self.config.solver
        return write_line_graph_g2o(
            path,
            self.covariance_graph,
            result,
            scan_offsets=np.array(self.track.scan_offset).reshape(-1, 3),
            scan_offset_covariances=np.array(self.track.scan_offset_cov).reshape(-1, 3, 3),
            motion_noise=self.odometry_noise.model,
            robust_kernel=(solver.robust_kernel, solver.robust_k),
        )

    def result(self) -> SlamResult:
        """The current estimate of every scan's pose and the map, with covariances."""
        stats: dict[str, Any] = {}
        with self.clock("covariances"):
            covariances = None
            self.covariance_graph = self.graph
            pass_skipped = None
            if self.config.line_pass_error == "estimated":
                try:
                    self.pass_error, self.covariance_graph = self._pass_model()
                except (EstimationError, EvaluationError) as exc:
                    # the back-end's covariances stand; summary.json says why
                    pass_skipped = f"not estimated: {exc}"
                if self.covariance_graph is not self.graph:
                    covariances = (BatchBackend(self.config.solver), self.covariance_graph)
            args = (self.track, self.config, self.policy, stats, self.odometry_noise.model)
            try:
                result = assemble_result(self.graph, self.backend, *args, covariances)
            except EstimationError as exc:
                if covariances is None:
                    raise
                # the linked graph's marginals failed: the back-end's covariances stand
                pass_skipped = f"covariances of the linked graph: {exc}"
                self.pass_error, self.covariance_graph = None, self.graph
                result = assemble_result(self.graph, self.backend, *args)
        time_s = self.clock.time_s
        stats.update(self.counters)
        stats["backend"] = self.backend.stats()
        stats["loop_closures_log"] = [a.as_log() for a in self.loop_closer.attempts]
        stats["odometry_noise"] = self.odometry_noise.summary()
        if self.config.odometry_calibration != "off":
            stats["odometry_calibration"] = self.odometry_calibrator.summary()
        stats["laser_mounting_fit"] = self.mounting_steps.check(self.graph.poses)
        stats["range_noise"] = self.range_noise.summary()
        warning = self.range_noise.warning()
        if warning is not None:
            warnings.warn(warning, SlamWarning, stacklevel=2)
        if self.config.line_model_error == "estimated":
            stats["line_model_error"] = self.line_noise.summary()
        if self.pass_error is not None:
            stats["line_pass_error"] = self.pass_error.to_dict()
        elif pass_skipped is not None:
            stats["line_pass_error"] = {"skipped": pass_skipped}
        stats["drift_scale"] = {"xy": self.drift.scale_xy, "theta": self.drift.scale_theta}
        stats["loop_closure_graph_scale"] = self.loop_closer.graph_report()
        stats["runtime_s"] = {
            "total": float(np.sum(self.track.scan_runtime_s)) + time_s["optimize"],
            **{k: float(v) for k, v in time_s.items()},
        }
        return result
