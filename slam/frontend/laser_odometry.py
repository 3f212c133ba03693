"""Laser odometry: the motion of a log without wheel odometry, from its scans alone.

A log that records no odometry, or odometry that never moves (a hand-held or laser-only
recording), gives the estimators nothing to predict a keyframe from: every scan would sit at
the first pose.  :class:`LaserOdometry` makes the odometry from the scans instead.  Each scan's
points (:func:`slam.frontend.scan_match.scan_points`, the paper's per-point noise, Eq. 8) are
registered against a local map of recent key scans by the dense scan matcher
(:func:`slam.frontend.scan_match.match_scans`: point to line, Cauchy weights, a search over
rotations), with a constant-velocity prediction as the prior: the last step repeated, spread
by ``sigma_xy_m`` and ``sigma_theta_rad`` per scan, or with the matcher's slip probability a
slip of it (a sudden turn, a gap in the log).  A scan further than ``reference_distance_m`` or
``reference_angle_rad`` from the newest key scan becomes the next key scan; the map
(:class:`slam.frontend.local_map.LocalMap`) holds the key scans within ``map_path_m`` of travel
and ``map_turn_rad`` of turning, merged into the newest one's frame, and each point's line
extends along its wall up to ``normal_length_m`` (the scan matcher's ``normal_length_m``).

Both matter where the walls say little along themselves.  A line through a point's nearest
few neighbours tilts with their noise, and where the ranges are written in steps (ACES's, in
steps of 2.5-5 cm) the steps read as short walls across a corridor, in the same place in
every scan: a scan then matches best where the previous one was, and the laser odometry stalls
and jumps.  Lines a metre long lie along the walls, and a map of several key scans holds the
walls as seen from several places, its steps in different places.  Measured
(``scripts/laser_odometry_check.py``, against default runs of the logs with their odometry;
translation error of relative poses 10 scans apart, RMS): ACES 0.284 m scan to scan, 0.168 m
with both; Intel 0.053 → 0.027 m; fr079 0.054 → 0.053 m; in a simulated corridor with ranges
in 5 cm steps 0.43-0.82 → 0.011-0.012 m (``tests/test_laser_odometry.py``).

A match the matcher does not accept (too little overlap: a gap in the log, a turn faster than
the prediction allows) is searched again over every heading
(:func:`slam.frontend.scan_match.match_any_heading`: the rotation's prior flat, the
translation's spread grown with the time since the last scan); its best solution is used when
the matcher accepts it and its posterior probability among the distinct solutions found is at
least ``any_heading_probability`` (``rescued``: a corridor seen both ways is not).  Otherwise
the scan stays at the prediction (``unmatched``) and starts a new map.

The poses are the laser's, in the frame of the first scan.  Each comes with the covariance
of its step from the previous scan (:attr:`LaserOdometry.step_cov`: the match's posterior,
or the prediction's spread for a scan left at the prediction), which :mod:`slam.inputs` puts
on the scan (:attr:`slam.types.Scan.odometry_step_cov`).  The line SLAM composes these
between keyframes and uses them for the motion between keyframes where wheel odometry gets
its motion model, so that the registration, the graph's odometry factors and the loop
closer's search window follow where the laser odometry can err: where the walls show
nothing along a corridor, a step's covariance along it is the prediction's (0.1 m per scan),
where they fix the scan about a centimetre (over ACES's and Intel's first 1,500 scans the
median standard deviation along a step's weakest direction is 1 cm, and 0.5 % of the steps
have 5 cm or more).  :mod:`slam.inputs` decides when a log needs laser odometry
(``[scanner] odometry_source``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from linefit.config import SensorNoiseConfig
from slam.frontend.local_map import LocalMap
from slam.frontend.scan_match import (
    ScanMatchConfig,
    ScanPoints,
    match_any_heading,
    match_scans,
    scan_points,
)
from slam.geometry import pose_between, pose_compose
from slam.types import Scan
from slam.validate import nonneg, positive, require

__all__ = ["LaserOdometry", "LaserOdometryConfig"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LaserOdometryConfig:
    """How :class:`LaserOdometry` chains its scan matches.

    Attributes
    ----------
    sigma_xy_m, sigma_theta_rad : float
        Spread of the constant-velocity prediction per scan (m, rad): how far the step may
        differ from the previous one.  The matcher's search over rotations
        (``ScanMatchConfig.rotation_window_rad``) reaches beyond it.
    reference_distance_m, reference_angle_rad : float
        A scan further than this from the newest key scan (m, rad) becomes the next key scan.
    min_overlap : float
        The scan matcher's ``min_overlap`` here: a match is used when at least this fraction of
        the scan's visible points lie on the reference's walls.  Lower than between keyframes
        (0.5), because the alternative is not wheel odometry but the blind constant-velocity
        guess: on ACES's first 1,500 scans 20 matches fall below 0.5 and none below 0.3, and
        with 0.3 the heading error over 50 scans is 0.015 against 0.058 rad (against the
        default run's trajectory; measured without the slip mixture).
    any_heading_probability : float
        A scan the matcher does not register against the prediction is searched over every
        heading; the best solution is used when its posterior probability among the distinct
        solutions found is at least this (1: never).
    map_path_m, map_turn_rad : float
        A scan is matched against the local map (:class:`slam.frontend.local_map.LocalMap`):
        the key scans within this travel (m) and turning (rad) of the newest, merged.  0 and
        0: the newest key scan alone.
    normal_length_m : float
        The scan matcher's ``normal_length_m`` here, in place of the run's: each key scan's
        point's line extends along its wall up to this length (m; 0: the line through its
        nearest few points, :class:`~slam.frontend.scan_match.ScanMatchConfig`).
    """

    sigma_xy_m: float = 0.1
    sigma_theta_rad: float = 0.1
    reference_distance_m: float = 0.2
    reference_angle_rad: float = 0.15
    min_overlap: float = 0.3
    any_heading_probability: float = 0.99
    map_path_m: float = 1.0
    map_turn_rad: float = 1.0
    normal_length_m: float = 1.0

    def __post_init__(self) -> None:
        for name in (
            "sigma_xy_m",
            "sigma_theta_rad",
            "reference_distance_m",
            "reference_angle_rad",
        ):
            positive(name, getattr(self, name))
        nonneg("map_path_m", self.map_path_m)
        nonneg("map_turn_rad", self.map_turn_rad)
        nonneg("normal_length_m", self.normal_length_m)
        require(0.0 <= self.min_overlap <= 1.0, "min_overlap must be in [0, 1]")
        require(
            0.0 < self.any_heading_probability <= 1.0,
            "any_heading_probability must be in (0, 1]",
        )


class LaserOdometry:
    """Laser poses from scan matching alone, fed one scan at a time (module docstring).

    Parameters
    ----------
    config : LaserOdometryConfig, optional
    noise : SensorNoiseConfig, optional
        The range-bearing noise of the points (default: the paper's).
    matching : ScanMatchConfig, optional
        The scan matcher's settings, with the config's ``min_overlap`` and
        ``normal_length_m``.  Its slip mixture (``slip_probability``) stays: the
        constant-velocity prediction fails as wheel odometry slips, at a sudden turn or across
        a gap in the log, and the mixture lets the points decide there (on the
        ``*-no-odometry`` rows, one run each, with each scan matched against the previous key
        scan alone: Intel 0.059 m against 0.227 m without it, ACES 1.13 against 1.16 m, fr079
        0.043 m either way).

    Attributes
    ----------
    matched, unmatched : int
        Scans registered against their reference, and scans left at the prediction.
    rescued : int
        Of the matched, those registered by the search over every heading.
    """

    def __init__(
        self,
        config: LaserOdometryConfig | None = None,
        noise: SensorNoiseConfig | None = None,
        matching: ScanMatchConfig | None = None,
    ) -> None:
        self.config = config or LaserOdometryConfig()
        self.noise = noise or SensorNoiseConfig()
        self.matching = replace(
            matching or ScanMatchConfig(),
            min_overlap=self.config.min_overlap,
            normal_length_m=self.config.normal_length_m,
        )
        self.matched = 0
        self.unmatched = 0
        self.rescued = 0
        sxy, sth = self.config.sigma_xy_m, self.config.sigma_theta_rad
        self._Q = np.diag([sxy**2, sxy**2, sth**2])  # the prediction's spread per scan
        self._map = LocalMap(self.config.map_path_m, self.config.map_turn_rad)
        self._pose = np.zeros(3)
        self._step = np.zeros(3)  # the last step, the constant-velocity prediction
        self.step_cov = np.zeros((3, 3))
        """Covariance of the last scan's pose given the one before (its match's posterior, or
        the prediction's spread where it was not matched), ``(3, 3)``."""
        self._last_points: ScanPoints | None = None
        self._time: float | None = None  # the last scan's time stamp (s)
        self._intervals: deque[float] = deque(maxlen=50)  # the last scans' intervals (s)

    @property
    def pose_odom_laser(self) -> FloatArray:
        """The last scan's laser pose, in the first scan's frame ``(x, y, θ)``."""
        return self._pose.copy()

    @property
    def last_points(self) -> ScanPoints | None:
        """The last scan's points as :meth:`add` matched them (None before the first)."""
        return self._last_points

    def add(self, scan: Scan) -> FloatArray:
        """Register ``scan``; return its laser pose ``(3,)`` in the first scan's frame."""
        cfg = self.config
        points = self._last_points = self.points(scan)
        if len(self._map) == 0:
            self._map.add(self._pose, points)
            return self._pose.copy()
        reference = self._map.points
        pose_reference = self._map.pose
        dt = self._interval(scan.timestamp)
        predicted = pose_compose(self._pose, self._step)
        delta0 = pose_between(pose_reference, predicted)
        match = match_scans(reference, points, delta0, self._Q, self.matching)
        rescued = False
        elapsed = 1.0  # the time since the last scan in usual intervals (at least 1)
        if not match.accepted and cfg.any_heading_probability < 1.0:
            if dt is not None:
                usual = float(np.median(self._intervals)) if self._intervals else dt
                elapsed = max(dt / usual, 1.0)
            match, probability = match_any_heading(
                reference, points, delta0, cfg.sigma_xy_m * elapsed, self.matching
            )
            rescued = match.accepted and probability >= cfg.any_heading_probability
            if rescued:
                self.rescued += 1
            else:
                match = replace(match, accepted=False)
        if dt is not None:
            self._intervals.append(dt)
        if match.accepted:
            pose = pose_compose(pose_reference, match.delta)
            self.step_cov = np.asarray(match.cov, dtype=float).copy()
            self.matched += 1
        else:
            pose = predicted
            self.step_cov = self._Q * elapsed**2
            self.unmatched += 1
        self._step = pose_between(self._pose, pose)
        if rescued:
            self._step /= elapsed  # a gap's motion, spread over its usual intervals
        self._pose = pose
        away = pose_between(pose_reference, pose)
        if not match.accepted:
            self._map.reset()  # a scan at the blind prediction starts a new map
        if (
            not match.accepted
            or np.hypot(away[0], away[1]) > cfg.reference_distance_m
            or abs(away[2]) > cfg.reference_angle_rad
        ):
            self._map.add(pose, points)
        return pose.copy()

    def points(self, scan: Scan) -> ScanPoints:
        """``scan``'s points as the laser odometry matches them (its noise and matcher)."""
        return scan_points(scan.ranges, scan.bearings, scan.max_range_m, self.noise, self.matching)

    def _interval(self, timestamp: float) -> float | None:
        """The time since the last scan (s); None without two valid, increasing time stamps."""
        last, self._time = self._time, float(timestamp)
        if last is None or not np.isfinite(self._time) or not np.isfinite(last):
            return None
        dt = self._time - last
        return dt if dt > 0.0 else None
