"""The keyframe track: odometry in, keyframe decisions, path driven, and the record of every scan.

A scan becomes a keyframe (a pose variable) when the odometry since the last keyframe exceeds
``keyframes.min_distance_m`` or ``keyframes.min_angle_rad`` (the first scan always does).
Other scans hang from the keyframe before them: their odometry offset from it and how far
along the stretch to the next keyframe they are (path, turning weighted by
:data:`ANGLE_WEIGHT_M_PER_RAD`) are recorded here, so that the result can place them
(:mod:`slam.line_slam.assembly`).  The path driven since the start, at every keyframe, is what
the front end's drift model and the loop closer measure drift by.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.geometry import chain_covariance, pose_between
from slam.graph.problem import GrowableArray
from slam.line_slam.config import KeyframeConfig
from slam.models.motion import moved_enough

__all__ = ["ANGLE_WEIGHT_M_PER_RAD", "EveryKeyframes", "KeyframeTrack", "OdometryStep"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

ANGLE_WEIGHT_M_PER_RAD = 0.5
"""Turning 1 rad counts as this much path when non-keyframe poses are interpolated."""


@dataclass(frozen=True)
class OdometryStep:
    """One scan's odometry, seen from the last keyframe.

    Attributes
    ----------
    pose_odom_laser : ndarray, shape (3,)
        The laser's odometry pose.
    delta : ndarray, shape (3,)
        Motion since the last keyframe (laser frame of that keyframe); zero for the first scan.
    first : bool
        The first scan of the run.
    keyframe : bool
        Whether the scan becomes a keyframe.
    cov : ndarray, shape (3, 3) or None
        Covariance of ``delta`` (its frame, right perturbation) where every scan since the
        last keyframe stated its odometry step's (:attr:`slam.types.Scan.odometry_step_cov`);
        None: the motion model's.
    """

    pose_odom_laser: FloatArray
    delta: FloatArray
    first: bool
    keyframe: bool
    cov: FloatArray | None = None


class KeyframeTrack:
    """Keyframe decisions and the per-keyframe and per-scan records (module docstring)."""

    def __init__(self, config: KeyframeConfig) -> None:
        self.config = config
        self._last_kf_odom: FloatArray | None = None
        self._last_odom: FloatArray | None = None
        self._cov: FloatArray | None = np.zeros((3, 3))  # of the motion since the keyframe
        self._progress = 0.0
        self.path_m = 0.0
        """Odometry path driven since the first scan (m)."""
        # per keyframe
        self._kf_path = GrowableArray(())
        self._kf_delta = GrowableArray((3,))
        self._kf_scan = GrowableArray((), dtype=np.intp)
        # per scan
        self.timestamps: list[float] = []
        self.scan_keyframe: list[int] = []
        self.scan_offset: list[FloatArray] = []
        #: covariance of a scan's offset where it was matched against its keyframe (else NaN:
        #: the offset is the odometry's, its noise the motion model's)
        self.scan_offset_cov: list[FloatArray] = []
        self.scan_progress: list[float] = []
        self.scan_is_keyframe: list[bool] = []
        self.scan_runtime_s: list[float] = []
        self.scan_n_landmarks: list[int] = []

    # -- decisions ---------------------------------------------------------------------------
    def is_keyframe(self, delta: FloatArray) -> bool:
        """Whether a motion ``delta`` since the last keyframe makes a keyframe."""
        return moved_enough(delta, self.config.min_distance_m, self.config.min_angle_rad)

    def keyframe_mask(self, poses_odom_laser: Sequence[FloatArray]) -> list[bool]:
        """Which of the next scans (their odometry poses) will become keyframes."""
        last = self._last_kf_odom
        out = []
        for odom in poses_odom_laser:
            kf = last is None or self.is_keyframe(pose_between(last, odom))
            out.append(kf)
            if kf:
                last = odom
        return out

    def step(self, pose_odom_laser: FloatArray, step_cov: FloatArray | None = None) -> OdometryStep:
        """Advance the path by one scan's odometry and decide whether it is a keyframe.

        ``step_cov`` ``(3, 3)``: the covariance of the odometry's step from the previous scan
        (its frame), where the odometry states one; the steps' covariances since the last
        keyframe are composed into :attr:`OdometryStep.cov`.
        """
        odom = pose_odom_laser
        if self._last_odom is not None:
            step = pose_between(self._last_odom, odom)
            inc = float(np.hypot(step[0], step[1]))
            self.path_m += inc
            self._progress += inc + ANGLE_WEIGHT_M_PER_RAD * abs(float(step[2]))
            self._cov = chain_covariance(self._cov, step, step_cov)
        self._last_odom = odom
        if self._last_kf_odom is None:
            return OdometryStep(odom, np.zeros(3), True, True)
        delta = pose_between(self._last_kf_odom, odom)
        cov = None if self._cov is None else self._cov.copy()
        return OdometryStep(odom, delta, False, self.is_keyframe(delta), cov)

    # -- records -----------------------------------------------------------------------------
    def begin_keyframe(self, step: OdometryStep, scan_no: int) -> None:
        """Record a new keyframe (its motion, the path so far, its scan)."""
        self._kf_delta.append(step.delta)
        self._kf_path.append(self.path_m)
        self._kf_scan.append(scan_no)
        self._progress = 0.0

    def end_keyframe(self, step: OdometryStep) -> None:
        """The keyframe is in the graph: later motion is measured from it."""
        self._last_kf_odom = step.pose_odom_laser
        self._cov = np.zeros((3, 3))

    def record_scan(
        self,
        timestamp: float,
        keyframe: int,
        offset: FloatArray,
        keyframe_scan: bool,
        n_landmarks: int,
        runtime_s: float,
        offset_cov: FloatArray | None = None,
    ) -> None:
        """Record one scan: its keyframe, offset from it and progress towards the next.

        The offset is the odometry's, or with ``offset_cov`` (3×3) the scan's match against the
        keyframe.
        """
        self.timestamps.append(float(timestamp))
        self.scan_keyframe.append(keyframe)
        self.scan_offset.append(np.asarray(offset, dtype=float))
        self.scan_offset_cov.append(
            np.full((3, 3), np.nan) if offset_cov is None else np.asarray(offset_cov, dtype=float)
        )
        self.scan_progress.append(0.0 if keyframe_scan else self._progress)
        self.scan_is_keyframe.append(keyframe_scan)
        self.scan_n_landmarks.append(n_landmarks)
        self.scan_runtime_s.append(runtime_s)

    # -- views -------------------------------------------------------------------------------
    @property
    def n_scans(self) -> int:
        """Scans recorded."""
        return len(self.timestamps)

    @property
    def keyframe_path_m(self) -> FloatArray:
        """Path driven (m) at each keyframe, ``(n_keyframes,)``."""
        return self._kf_path.data

    @property
    def scan_matched(self) -> NDArray[np.bool_]:
        """Whether each scan's offset is its match against the keyframe (``(n,)``)."""
        cov = np.asarray(self.scan_offset_cov, dtype=float).reshape(-1, 9)
        return np.asarray(np.all(np.isfinite(cov), axis=1))

    @property
    def keyframe_delta(self) -> FloatArray:
        """Odometry motion from the previous keyframe to each keyframe, ``(n_keyframes, 3)``."""
        return self._kf_delta.data

    @property
    def keyframe_scan(self) -> IntArray:
        """Scan number of each keyframe, ``(n_keyframes,)``."""
        return self._kf_scan.data

    def path_since(self, keyframes: IntArray) -> FloatArray:
        """Path driven (m) since each of ``keyframes``."""
        return self.path_m - self._kf_path.data[np.asarray(keyframes, dtype=np.intp)]


class EveryKeyframes:
    """A step due every ``interval`` keyframes (fusion rounds, loop-closure attempts)."""

    def __init__(self) -> None:
        self._since = 0

    def tick(self, enabled: bool, interval: int) -> bool:
        """Count a keyframe; whether the step is due (the count restarts when it is)."""
        self._since += 1
        if enabled and self._since >= interval:
            self._since = 0
            return True
        return False
