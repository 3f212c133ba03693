"""Laser odometry: the motion of a log without wheel odometry, from its scans alone.

A log that records no odometry, or odometry that never moves (a hand-held or laser-only
recording), gives the estimators nothing to predict a keyframe from: every scan would sit at
the first pose.  :class:`LaserOdometry` makes the odometry from the scans instead.  Each scan's
points (:func:`slam.frontend.scan_match.scan_points`, the paper's per-point noise, Eq. 8) are
registered against a reference scan's by the dense scan matcher
(:func:`slam.frontend.scan_match.match_scans`: point to line, Cauchy weights, a search over
rotations), with a constant-velocity prediction as the prior: the last step repeated, spread
by ``sigma_xy_m`` and ``sigma_theta_rad`` per scan, or with the matcher's slip probability a
slip of it (a sudden turn, a gap in the log).  The reference is kept while the scan stays
within ``reference_distance_m`` and ``reference_angle_rad`` of it (fewer matches chained, so
less drift), then the current scan becomes the reference.  A match the matcher does not accept
(too little overlap: a gap in the log, a turn faster than the prediction allows) is searched
again over every heading (:func:`slam.frontend.scan_match.match_any_heading`: the rotation's
prior flat, the translation's spread grown with the time since the last scan); its best
solution is used when the matcher accepts it and its posterior probability among the distinct
solutions found is at least ``any_heading_probability`` (``rescued``: a corridor seen both
ways is not).  Otherwise the scan stays at the prediction (``unmatched``).

The poses are the laser's, in the frame of the first scan; the estimators then treat them
as any logged odometry (their motion noise, the scan matcher between keyframes, the line
registration).  :mod:`slam.inputs` decides when a log needs them
(``[scanner] odometry_source``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from linefit.config import SensorNoiseConfig
from slam.frontend.scan_match import (
    ScanMatchConfig,
    ScanPoints,
    match_any_heading,
    match_scans,
    scan_points,
)
from slam.geometry import pose_between, pose_compose
from slam.types import Scan
from slam.validate import positive, require

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
        A scan further than this from the reference scan (m, rad) becomes the next reference.
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
    """

    sigma_xy_m: float = 0.1
    sigma_theta_rad: float = 0.1
    reference_distance_m: float = 0.2
    reference_angle_rad: float = 0.15
    min_overlap: float = 0.3
    any_heading_probability: float = 0.99

    def __post_init__(self) -> None:
        for name in (
            "sigma_xy_m",
            "sigma_theta_rad",
            "reference_distance_m",
            "reference_angle_rad",
        ):
            positive(name, getattr(self, name))
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
        The scan matcher's settings, with the config's ``min_overlap``.  Its slip mixture
        (``slip_probability``) stays: the constant-velocity prediction fails as wheel odometry
        slips, at a sudden turn or across a gap in the log, and the mixture lets the points
        decide there (on the ``*-no-odometry`` rows, one run each: Intel 0.059 m against
        0.227 m without it, ACES 1.13 against 1.16 m, fr079 0.043 m either way).

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
        )
        self.matched = 0
        self.unmatched = 0
        self.rescued = 0
        sxy, sth = self.config.sigma_xy_m, self.config.sigma_theta_rad
        self._Q = np.diag([sxy**2, sxy**2, sth**2])  # the prediction's spread per scan
        self._reference: ScanPoints | None = None
        self._pose_reference = np.zeros(3)
        self._pose = np.zeros(3)
        self._step = np.zeros(3)  # the last step, the constant-velocity prediction
        self._time: float | None = None  # the last scan's time stamp (s)
        self._intervals: deque[float] = deque(maxlen=50)  # the last scans' intervals (s)

    @property
    def pose_odom_laser(self) -> FloatArray:
        """The last scan's laser pose, in the first scan's frame ``(x, y, θ)``."""
        return self._pose.copy()

    def add(self, scan: Scan) -> FloatArray:
        """Register ``scan``; return its laser pose ``(3,)`` in the first scan's frame."""
        cfg = self.config
        points = scan_points(
            scan.ranges, scan.bearings, scan.max_range_m, self.noise, self.matching
        )
        if self._reference is None:
            self._reference = points
            return self._pose.copy()
        dt = self._interval(scan.timestamp)
        predicted = pose_compose(self._pose, self._step)
        delta0 = pose_between(self._pose_reference, predicted)
        match = match_scans(self._reference, points, delta0, self._Q, self.matching)
        rescued = False
        elapsed = 1.0  # the time since the last scan in usual intervals (at least 1)
        if not match.accepted and cfg.any_heading_probability < 1.0:
            if dt is not None:
                usual = float(np.median(self._intervals)) if self._intervals else dt
                elapsed = max(dt / usual, 1.0)
            match, probability = match_any_heading(
                self._reference, points, delta0, cfg.sigma_xy_m * elapsed, self.matching
            )
            rescued = match.accepted and probability >= cfg.any_heading_probability
            if rescued:
                self.rescued += 1
            else:
                match = replace(match, accepted=False)
        if dt is not None:
            self._intervals.append(dt)
        if match.accepted:
            pose = pose_compose(self._pose_reference, match.delta)
            self.matched += 1
        else:
            pose = predicted
            self.unmatched += 1
        self._step = pose_between(self._pose, pose)
        if rescued:
            self._step /= elapsed  # a gap's motion, spread over its usual intervals
        self._pose = pose
        away = pose_between(self._pose_reference, pose)
        if (
            not match.accepted
            or np.hypot(away[0], away[1]) > cfg.reference_distance_m
            or abs(away[2]) > cfg.reference_angle_rad
        ):
            self._reference = points
            self._pose_reference = pose.copy()
        return pose.copy()

    def _interval(self, timestamp: float) -> float | None:
        """The time since the last scan (s); None without two valid, increasing time stamps."""
        last, self._time = self._time, float(timestamp)
        if last is None or not np.isfinite(self._time) or not np.isfinite(last):
            return None
        dt = self._time - last
        return dt if dt > 0.0 else None
