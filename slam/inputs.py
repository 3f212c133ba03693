"""A log as the estimators read it: format, scanner geometry, laser mounting, odometry, frame.

Main entry points::

    log = open_log("run.bag", config.scanner)   # a CARMEN file, a bag, or a catalogue name
    log.policy                                   # InputPolicy: laser odometry, mounting, frame
    log.n_scans                                  # for progress bars (None if not cheap to know)
    for scan in log.scans(max_scans=None): ...   # geometry and range limits applied
    log.describe()                               # summary.json's "input" block

Every estimator and runner (the factor graph, the EKF, the map builder, the comparisons,
``lineslam extract``) reads a log through :func:`open_log`, so that all of them see the same
scans and motion and report the same frame.  The settings are the ``[scanner]`` table of the
run configuration (:class:`ScannerConfig`); the command line sets the same keys.

Formats
-------
A ROS 1 ``.bag`` file or a ROS 2 bag folder (:mod:`slam.io.rosbag`), else a CARMEN log
(:mod:`slam.io.carmen`).  A name that is not a file is looked up in the dataset catalogue.

Log anomalies
-------------
A CARMEN log is checked while it is read (:mod:`slam.io.anomalies`: time going backwards,
repeated time stamps, odometry jumps, a last line cut short, unknown messages):
``log.scans(stats=CarmenStats(...))`` counts them in ``stats.anomalies`` over the part of the
log read, ``strict=True`` makes the first one an error.  A bag is not checked: its messages
are typed and time-stamped by the recorder, and its ``stats`` stay empty.

Geometry and range limits (first match wins)
--------------------------------------------
1. What ``[scanner]`` states (``first_angle_deg``, ``step_deg`` or ``fov_deg``, ``beams``,
   ``min_range_m``, ``max_range_m``); parts not stated come from below.
2. The dataset catalogue, for its own logs, recognised by content (size and SHA-256, not the
   file name: :func:`slam.io.catalog.manifest_for_path`).
3. What the log states: ``ROBOTLASER1``/``RAWLASER`` fields, a bag's ``angle_min``,
   ``angle_increment``, ``range_min``, ``range_max``; for ``FLASER``/``RLASER`` lines its
   ``PARAM`` lines (``laser_front_laser_resolution``, ``laser_front_laser_fov``,
   ``robot_front_laser_max``; :class:`slam.io.carmen.LogParams`).
4. For ``FLASER``/``RLASER`` lines, which carry only ranges: CARMEN's rule
   (:func:`slam.io.laser.guess_laser_geometry`), with an :class:`InputWarning` that says so.

Readings below ``min_range_m`` become NaN (not measurements); readings at or above the range
limit are "no return" (:attr:`slam.types.Scan.max_range_m`).

Laser mounting ``pose_base_laser`` (first match wins)
----------------------------------------------------
1. ``[scanner] pose_base_laser`` when stated (or ``mount_source = "config"``: it, else zero).
2. The catalogue's recorded mounting, for its own logs (``datasets/catalog.toml``).
3. The log's ``PARAM`` lines (``robot_frontlaser_offset``, ``robot_frontlaser_side_offset``,
   ``robot_frontlaser_angular_offset``; ``rear`` for ``RLASER``): the laser odometry is the
   logged laser pose where that pose already holds the stated mounting, else the odometry
   pose composed with it (an :class:`InputWarning` when the logged poses hold another offset).
4. The log's poses: a CARMEN log whose laser lines state both the laser pose and the odometry
   pose (``FLASER x y θ`` and ``odom_x odom_y odom_θ``; ``ROBOTLASER1`` laser and robot pose)
   gives ``pose_odom_base⁻¹ ∘ pose_odom_laser``, which must be the same for every scan (within
   :data:`MOUNT_TOLERANCE_M` and :data:`MOUNT_TOLERANCE_RAD`; otherwise an
   :class:`InputWarning` and no mounting); a bag gives its ``/tf_static`` chain from the base
   frame to the scan's frame.
5. None known: the laser odometry is the base's, and the trajectory is reported for the laser.

Laser odometry and output frame
-------------------------------
``laser_odometry = "auto"`` takes the logged laser pose where the mounting came from the log
itself, and ``base odometry ∘ mounting`` where it was stated, catalogued (and not applied in
the log's laser poses) or read from tf.  Poses are estimated for the laser and reported in
the frame ``output_frame`` names: ``"base"``, the robot base (``pose_world_base =
pose_world_laser ∘ pose_base_laser⁻¹``; the laser when no mounting is known), ``"laser"``, or
``"auto"`` (the default): for a catalogued log the frame of its reference relations (the
catalogue's ``relations_frame``, so that ``trajectory.tum`` and the relations compare like with
like), for any other log the base.  ``summary.json``'s ``"frame"`` says which.  ``odometry_sign =
"velocity"`` repairs CARMEN odometry that logs reversing as forward motion
(:func:`slam.io.carmen.velocity_signed_scans`).

Logs without odometry
---------------------
A laser-only recording has no odometry, or odometry that never moves; read as it is, every
scan would sit at the first pose.  With ``[scanner] odometry_source = "auto"`` (the default)
the scans are held back while the log's odometry has not moved and are registered meanwhile
(:class:`slam.frontend.laser_odometry.LaserOdometry`, scan matching alone).  Once the odometry
moves, every scan passes as logged (a robot that stood still at the start); where the logged
laser poses stand still while the odometry poses move, the laser odometry is the odometry
pose composed with the mounting (an :class:`InputWarning`; ``laser_odometry`` ``"base"``).
Once the scans have moved :data:`STILL_ODOMETRY_M` or :data:`STILL_ODOMETRY_RAD` from the
first scan without it, and the first scan no longer registers the current one where it was
(their overlap at the identity, :func:`slam.frontend.scan_match.overlap_at`, below the laser
odometry's ``min_overlap``: the scans themselves show the motion, not only the chained
matches, which along a corridor with no visible end follow their constant-velocity
prediction), the odometry is taken for absent: an :class:`InputWarning` says so and every scan
gets the laser odometry's pose (from the first scan's logged pose) and the covariance of its
step from the previous scan (:attr:`Scan.odometry_step_cov`; scans with the log's odometry
have none).
``"scan_matching"`` always uses the laser odometry, ``"log"`` never.  The laser odometry's
settings are the ``[scanner.scan_odometry]`` table
(:class:`~slam.frontend.laser_odometry.LaserOdometryConfig`); its points carry the run's
sensor noise (``[linefit.noise]``) and its matcher the run's scan-matcher settings
(``[slam.frontend.scan_matching]``, its own ``min_overlap``), when the log is opened with
them (:func:`open_log`; :func:`slam.config.open_run_log` does).  ``summary.json``'s
``"input"`` block has ``odometry_source`` (``"log"`` or ``"scan_matching"``) and, for the
latter, ``laser_odometry_scans`` (matched, unmatched, and of the matched those registered by
the search over every heading: rescued).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from linefit.config import SensorNoiseConfig
from slam.errors import ConfigError, InputError, LogFormatError
from slam.frontend.laser_odometry import LaserOdometry, LaserOdometryConfig
from slam.frontend.odometry_delay import (
    MAX_DELAY_SCANS,
    OdometryDelay,
    estimate_odometry_delay,
    median_interval,
    shift_odometry,
)
from slam.frontend.scan_match import ScanMatchConfig, ScanPoints, overlap_at
from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_inverse
from slam.lines.merge import chi2_ppf
from slam.types import Scan
from slam.validate import require

if TYPE_CHECKING:
    from slam.io.carmen import CarmenStats
    from slam.io.catalog import DatasetManifest, ResolvedLog

__all__ = [
    "MOUNT_TOLERANCE_M",
    "MOUNT_TOLERANCE_RAD",
    "InputPolicy",
    "InputSettings",
    "InputWarning",
    "LogInput",
    "MountEstimate",
    "ScannerConfig",
    "derive_mount",
    "open_log",
    "policy_for_log",
    "read_log_scans",
]

FloatArray = NDArray[np.float64]

MOUNT_TOLERANCE_M = 0.01
"""Largest spread (m) of ``pose_odom_base⁻¹ ∘ pose_odom_laser`` over a log for a mounting."""
MOUNT_TOLERANCE_RAD = math.radians(0.5)
"""Largest spread (rad) of its heading for a mounting."""


STILL_ODOMETRY_M = 0.5
"""How far (m) the scans must move from the first scan, the log's odometry not moving, before
``odometry_source = "auto"`` takes the odometry for absent."""
STILL_ODOMETRY_RAD = 0.5
"""The same in rotation (rad)."""

DELAY_CHI2_99 = chi2_ppf(0.99, 1)
"""χ²₁'s 99 % point: an estimated odometry delay is applied when its likelihood ratio against
no delay exceeds it."""

_INTERVAL_SCANS = 200
"""Scans read for the usual interval between them where a delay is stated (not estimated)."""


class InputWarning(UserWarning):
    """Something about the input was assumed rather than stated (the message says what)."""


@dataclass(frozen=True)
class ScannerConfig:
    """The ``[scanner]`` table: the log's scanner, odometry and mounting, and the reported frame.

    ``None`` (a key left out of ``config.toml``) means "not stated": the value comes from the
    catalogue or the log (module docstring).

    Attributes
    ----------
    first_angle_deg : float, optional
        Bearing of beam 0 in the laser frame (deg); default with ``fov_deg``: ``−fov/2``.
    step_deg : float, optional
        Angle between beams (deg); negative for beams in clockwise order (a scanner mounted
        upside down: ``first_angle_deg = 90``, ``step_deg = -1`` for CARMEN's 180 beams).
    fov_deg : float, optional
        Angle from the first to the last beam (deg); the step is ``fov / (n − 1)``.  Give
        ``step_deg`` or ``fov_deg``, not both.
    beams : int, optional
        Beams per scan; a scan with another count is an error.
    min_range_m : float, optional
        Readings below this (m) are not measurements.
    max_range_m : float, optional
        Readings at or above this (m) are "no return".
    pose_base_laser : tuple of 3 floats, optional
        The laser's pose on the robot base ``(x m, y m, θ rad)``; stated, it overrides the
        catalogue and the log.
    mount_source : {"auto", "config"}
        ``"auto"``: module docstring; ``"config"``: ``pose_base_laser`` (zero if not stated)
        and nothing else.
    laser_odometry : {"auto", "logged", "base"}
        ``"logged"``: the logged laser pose, else base odometry ∘ mounting; ``"base"``: always
        base odometry ∘ mounting; ``"auto"``: module docstring.
    output_frame : {"auto", "base", "laser"}
        Frame of the reported trajectory (``"base"`` needs a known mounting); ``"auto"``: a
        catalogued log's relations frame, else ``"base"`` (module docstring).
    odometry_sign : {"velocity", "logged"}
        CARMEN odometry as logged, or with reversing repaired from the logged speed.
    scan_topic, odom_topic : str, optional
        Bag topics (needed when a bag has several of a type).
    odometry : {"auto", "topic", "tf"}
        Bags: the odometry topic, or the ``/tf`` transforms to the base frame.
    base_frame : str, optional
        Bags: the robot's base frame (default: the odometry's ``child_frame_id``).
    odometry_source : {"auto", "log", "scan_matching"}
        Where the motion comes from: the log's odometry (``"log"``), the scans alone
        (``"scan_matching"``: :class:`slam.frontend.laser_odometry.LaserOdometry`), or
        ``"auto"``: the log's, unless it has none or it never moves while the scans do
        (module docstring, "Logs without odometry").
    scan_odometry : LaserOdometryConfig
        The ``[scanner.scan_odometry]`` table: how the laser odometry chains its scan matches
        when the motion comes from the scans.
    odometry_delay : {"off", "estimated"}
        ``"off"`` (default): the poses as logged; ``"estimated"``: how many scans late the
        log's odometry is against its scans is estimated from the scans' own rotation at the
        turns, and every scan's odometry pose is read that many scans later
        (:mod:`slam.frontend.odometry_delay`).  Not for motion from the scans.
    odometry_delay_scans : float, optional
        A stated delay (scans; negative: the odometry is early) used instead of the estimate.
    """

    first_angle_deg: float | None = None
    step_deg: float | None = None
    fov_deg: float | None = None
    beams: int | None = None
    min_range_m: float | None = None
    max_range_m: float | None = None
    pose_base_laser: tuple[float, float, float] | None = None
    mount_source: Literal["auto", "config"] = "auto"
    laser_odometry: Literal["auto", "logged", "base"] = "auto"
    output_frame: Literal["auto", "base", "laser"] = "auto"
    odometry_sign: Literal["velocity", "logged"] = "velocity"
    scan_topic: str | None = None
    odom_topic: str | None = None
    odometry: Literal["auto", "topic", "tf"] = "auto"
    base_frame: str | None = None
    odometry_source: Literal["auto", "log", "scan_matching"] = "auto"
    scan_odometry: LaserOdometryConfig = field(default_factory=LaserOdometryConfig)
    odometry_delay: Literal["off", "estimated"] = "off"
    odometry_delay_scans: float | None = None

    def __post_init__(self) -> None:
        require(
            self.odometry_delay in ("estimated", "off"),
            "odometry_delay must be off or estimated",
        )
        require(
            self.odometry_delay_scans is None
            or (
                math.isfinite(self.odometry_delay_scans)
                and abs(self.odometry_delay_scans) <= MAX_DELAY_SCANS
            ),
            f"odometry_delay_scans must be a number of scans within ±{MAX_DELAY_SCANS:g}",
        )
        for name in ("first_angle_deg", "step_deg", "fov_deg", "min_range_m", "max_range_m"):
            value = getattr(self, name)
            require(value is None or math.isfinite(value), f"{name} must be a finite number")
        require(
            self.step_deg is None or self.step_deg != 0.0,
            "step_deg must not be 0 (negative: beams in clockwise order)",
        )
        require(self.fov_deg is None or self.fov_deg > 0.0, "fov_deg must be > 0")
        require(
            self.step_deg is None or self.fov_deg is None,
            "give step_deg or fov_deg, not both",
        )
        require(self.beams is None or self.beams >= 2, "beams must be >= 2")
        require(self.min_range_m is None or self.min_range_m >= 0.0, "min_range_m must be >= 0")
        require(self.max_range_m is None or self.max_range_m > 0.0, "max_range_m must be > 0")
        require(
            self.min_range_m is None
            or self.max_range_m is None
            or self.min_range_m < self.max_range_m,
            "min_range_m must be below max_range_m",
        )
        if self.pose_base_laser is not None:
            require(
                len(self.pose_base_laser) == 3
                and all(math.isfinite(v) for v in self.pose_base_laser),
                "pose_base_laser must be three finite numbers (x m, y m, theta rad)",
            )
        require(self.mount_source in ("auto", "config"), "mount_source must be auto or config")
        require(
            self.laser_odometry in ("auto", "logged", "base"),
            "laser_odometry must be auto, logged or base",
        )
        require(
            self.output_frame in ("auto", "base", "laser"),
            "output_frame must be auto, base or laser",
        )
        require(
            self.odometry_sign in ("velocity", "logged"),
            "odometry_sign must be velocity or logged",
        )
        require(self.odometry in ("auto", "topic", "tf"), "odometry must be auto, topic or tf")
        require(
            self.odometry_source in ("auto", "log", "scan_matching"),
            "odometry_source must be auto, log or scan_matching",
        )
        require(
            isinstance(self.scan_odometry, LaserOdometryConfig),
            "scan_odometry must be a LaserOdometryConfig ([scanner.scan_odometry] table)",
        )

    @property
    def states_geometry(self) -> bool:
        """Whether any beam-geometry key is stated."""
        return any(
            v is not None for v in (self.first_angle_deg, self.step_deg, self.fov_deg, self.beams)
        )


OLD_SLAM_KEYS: dict[str, Any] = {
    "pose_base_laser": (0.0, 0.0, 0.0),
    "mount_source": "catalog",
    "laser_odometry": "logged",
    "output_frame": "laser",
    "odometry_sign": "velocity",
}
"""The input keys an older ``config.toml`` has in ``[slam]``, with their old defaults."""


def migrate_slam_keys(data: dict[str, Any]) -> dict[str, Any]:
    """Move an older ``config.toml``'s input keys from ``[slam]`` to ``[scanner]``.

    A key whose value is the old default is dropped (the ``[scanner]`` default applies); any
    other value moves with its meaning (``mount_source = "config"`` stays ``"config"``; a
    non-zero ``pose_base_laser`` becomes the stated mounting).  A key given in both tables is
    an error.  Returns a new dict; ``data`` is not changed.
    """
    slam = data.get("slam")
    if not isinstance(slam, dict) or not any(k in slam for k in OLD_SLAM_KEYS):
        return data
    out = dict(data)
    slam = dict(slam)
    scanner = dict(out.get("scanner", {}))
    for key, old_default in OLD_SLAM_KEYS.items():
        if key not in slam:
            continue
        value = slam.pop(key)
        if key in scanner:
            raise ConfigError(f"{key} is given in [slam] (older files) and in [scanner]: keep one")
        same = (
            list(value) == list(old_default)
            if isinstance(old_default, tuple)
            else value == old_default
        )
        if not same:
            scanner[key] = value
    out["slam"] = slam
    out["scanner"] = scanner
    return out


class InputSettings(Protocol):
    """Where a policy's settings come from (e.g. a resolved :class:`ScannerConfig`)."""

    @property
    def pose_base_laser(self) -> Any:
        """Laser pose on the robot base (m, m, rad)."""

    @property
    def laser_odometry(self) -> str:
        """``"logged"`` or ``"base"``."""

    @property
    def output_frame(self) -> str:
        """``"laser"`` or ``"base"``."""

    @property
    def odometry_sign(self) -> str:
        """``"velocity"`` or ``"logged"``."""


@dataclass(frozen=True)
class InputPolicy:
    """How scans' odometry is read and which frame poses are reported in.

    Attributes
    ----------
    pose_base_laser : tuple of 3 floats
        Laser pose on the robot base ``(x_m, y_m, theta_rad)``.
    laser_odometry : {"logged", "base"}
        ``"logged"``: the logged laser pose, else base odometry ∘ mounting; ``"base"``: always
        base odometry ∘ mounting.
    output_frame : {"laser", "base"}
        Frame of the reported trajectory.
    odometry_sign : {"velocity", "logged"}
        How a CARMEN log's odometry is read (:func:`slam.io.carmen.iter_log_scans`).
    """

    pose_base_laser: tuple[float, float, float] = (0.0, 0.0, 0.0)
    laser_odometry: Literal["logged", "base"] = "logged"
    output_frame: Literal["laser", "base"] = "laser"
    odometry_sign: Literal["velocity", "logged"] = "velocity"

    def __post_init__(self) -> None:
        if len(self.pose_base_laser) != 3 or not all(
            math.isfinite(v) for v in self.pose_base_laser
        ):
            raise ConfigError("pose_base_laser must be three finite numbers (x, y, theta)")
        if self.laser_odometry not in ("logged", "base"):
            raise ConfigError(f"laser_odometry must be logged or base: {self.laser_odometry!r}")
        if self.output_frame not in ("laser", "base"):
            raise ConfigError(f"output_frame must be laser or base: {self.output_frame!r}")
        if self.odometry_sign not in ("velocity", "logged"):
            raise ConfigError(f"odometry_sign must be velocity or logged: {self.odometry_sign!r}")

    @classmethod
    def of(cls, settings: Any) -> InputPolicy:
        """The policy of an object holding the settings; missing or unresolved ones default.

        Unresolved values of a :class:`ScannerConfig` (``pose_base_laser = None``,
        ``laser_odometry = "auto"``) take the policy's defaults, ``output_frame = "auto"`` the
        base (as for a log the catalogue does not know); :func:`open_log` resolves them for a
        log.
        """
        default = cls()
        mount = getattr(settings, "pose_base_laser", None)
        laser_odometry = getattr(settings, "laser_odometry", default.laser_odometry)
        frame = getattr(settings, "output_frame", default.output_frame)
        return cls(
            default.pose_base_laser if mount is None else tuple(float(v) for v in mount),  # type: ignore[arg-type]
            default.laser_odometry if laser_odometry == "auto" else laser_odometry,
            "base" if frame == "auto" else frame,
            getattr(settings, "odometry_sign", default.odometry_sign),
        )

    @property
    def mount(self) -> FloatArray:
        """``pose_base_laser`` as an array ``(3,)``."""
        return np.asarray(self.pose_base_laser, dtype=float)

    def pose_odom_laser(self, scan: Scan) -> FloatArray:
        """The laser's odometry pose of ``scan`` ``(3,)``.

        Raises
        ------
        InputError
            The scan has no odometry, or it is not finite (names the scan and its file).
        """
        use_base = self.laser_odometry == "base" or scan.pose_odom_laser is None
        if not use_base:
            pose = np.asarray(scan.pose_odom_laser, dtype=float).reshape(3)
        elif scan.pose_odom_base is not None:
            pose = pose_compose(np.asarray(scan.pose_odom_base, dtype=float), self.mount)
        else:
            raise InputError(
                f"scan {scan.index} has no odometry (pose_odom_laser / pose_odom_base)",
                scan.source or None,
            )
        if not np.isfinite(pose).all():
            raise InputError(f"scan {scan.index}: odometry is not finite", scan.source or None)
        return pose

    def with_laser_odometry(self, scans: Iterable[Scan]) -> Iterator[Scan]:
        """``scans`` with ``pose_odom_laser`` set to :meth:`pose_odom_laser` (the policy's).

        For consumers that read ``Scan.pose_odom_laser`` directly; scans without any odometry
        pass unchanged.
        """
        for s in scans:
            if s.pose_odom_laser is None and s.pose_odom_base is None:
                yield s
            elif self.laser_odometry == "base" or s.pose_odom_laser is None:
                yield replace(s, pose_odom_laser=self.pose_odom_laser(s))
            else:
                yield s

    def report(
        self, poses_world_laser: FloatArray, covariances: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray | None]:
        """Poses ``(n, 3)`` and covariances ``(n, 3, 3)`` in the output frame.

        For ``"base"``: ``pose_world_base = pose_world_laser ∘ pose_base_laser⁻¹``; a right
        perturbation of the laser pose is ``Ad(pose_base_laser)`` times the base's, so the
        covariance becomes ``Ad P Adᵀ``.  For ``"laser"`` the inputs are returned unchanged.
        """
        poses = np.asarray(poses_world_laser, dtype=float)
        if self.output_frame != "base" or poses.shape[0] == 0 or not self.mount.any():
            return poses, covariances  # a zero mounting: the laser's poses are the base's
        poses = pose_compose(poses, np.broadcast_to(pose_inverse(self.mount), poses.shape))
        if covariances is not None:
            F = adjoint_pose2(self.mount)
            covariances = F @ covariances @ F.T
        return poses, covariances


# -- the mounting from a log's own poses -----------------------------------------------------


@dataclass(frozen=True)
class MountEstimate:
    """``pose_odom_base⁻¹ ∘ pose_odom_laser`` over the scans that state both poses.

    Attributes
    ----------
    pose_base_laser : tuple of 3 floats or None
        The median offset, or ``None`` if no scan states both poses.
    n_scans : int
        Scans that state both.
    spread_m, spread_rad : float
        Largest deviation from the median (position m, heading rad).
    """

    pose_base_laser: tuple[float, float, float] | None
    n_scans: int
    spread_m: float
    spread_rad: float

    @property
    def consistent(self) -> bool:
        """The offset is the same over the log (within the module's tolerances)."""
        return (
            self.pose_base_laser is not None
            and self.spread_m <= MOUNT_TOLERANCE_M
            and self.spread_rad <= MOUNT_TOLERANCE_RAD
        )


def derive_mount(scans: Iterable[Scan]) -> MountEstimate:
    """The laser mounting that the scans' logged laser and base poses imply (module docstring)."""
    acc = _MountAccumulator()
    for scan in scans:
        acc.add(scan)
    return acc.result()


class _MountAccumulator:
    """:func:`derive_mount` fed one scan at a time (keeps only the offsets)."""

    def __init__(self) -> None:
        self._offsets: list[FloatArray] = []

    def add(self, scan: Scan) -> None:
        if scan.pose_odom_base is not None and scan.pose_odom_laser is not None:
            base = np.asarray(scan.pose_odom_base, dtype=float)
            self._offsets.append(pose_between(base, np.asarray(scan.pose_odom_laser, float)))

    def result(self) -> MountEstimate:
        if not self._offsets:
            return MountEstimate(None, 0, math.nan, math.nan)
        d = np.vstack(self._offsets)
        med = np.median(d, axis=0)
        dtheta = np.abs(np.angle(np.exp(1j * (d[:, 2] - med[2]))))
        spread_m = float(np.max(np.hypot(d[:, 0] - med[0], d[:, 1] - med[1])))
        # offsets at rounding level are no mounting: keep them exactly zero
        med = np.where(np.abs(med) < 1e-9, 0.0, med)
        mount = (float(med[0]), float(med[1]), float(med[2]))
        return MountEstimate(mount, d.shape[0], spread_m, float(np.max(dtheta)))


# -- opening a log ---------------------------------------------------------------------------


@dataclass
class _Geometry:
    """What the run used: filled from the first scan read."""

    first_angle_deg: float | None = None
    step_deg: float | None = None
    beams: int | None = None
    max_range_m: float | None = None
    min_range_m: float | None = None
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "first_angle_deg": self.first_angle_deg,
            "step_deg": self.step_deg,
            "beams": self.beams,
            "min_range_m": self.min_range_m,
            "max_range_m": self.max_range_m,
            "source": self.source,
        }


@dataclass
class LogInput:
    """An opened log (see :func:`open_log`).

    Attributes
    ----------
    log : Path
        The log file or bag folder.
    name : str
        Dataset name, or the file's stem.
    format : {"carmen", "rosbag"}
    manifest : DatasetManifest or None
        The catalogue entry, for a catalogued log.
    relations : Path or None
        The catalogue's relations file for a catalogued log.
    policy : InputPolicy
        Laser odometry, mounting, output frame, odometry sign (resolved).
    n_scans : int or None
        Laser scans in the log, where known without reading it.
    mount_source : str
        ``"config"``, ``"catalogue"``, ``"param"`` (the log's ``PARAM`` lines), ``"log"`` (its
        poses), ``"tf"`` or ``"none"``.
    details : dict
        More about the input for ``summary.json``.
    noise, matching : SensorNoiseConfig or ScanMatchConfig, optional
        The laser odometry's point noise and scan-matcher settings (:func:`open_log`; None:
        their defaults).
    """

    log: Path
    name: str
    format: str
    manifest: DatasetManifest | None
    relations: Path | None
    policy: InputPolicy
    n_scans: int | None
    mount_source: str
    scanner: ScannerConfig
    details: dict[str, Any] = field(default_factory=dict)
    geometry: _Geometry = field(default_factory=_Geometry)
    _reader: Any = None
    _skipped_without_odometry: int = 0
    _laser_odometry: Any = None
    odometry_source: str = "log"
    noise: SensorNoiseConfig | None = None
    matching: ScanMatchConfig | None = None
    _delay: float | None = None
    _delay_source: str = "off"
    _delay_estimate: OdometryDelay | None = None
    _delay_interval_s: float | None = None

    def total(self, max_scans: int | None = None) -> int | None:
        """Scans a run over at most ``max_scans`` of them will read (None if unknown)."""
        if self.n_scans is None:
            return max_scans
        return self.n_scans if max_scans is None else min(self.n_scans, max_scans)

    def raw_scans(
        self, *, stats: CarmenStats | None = None, strict: bool = False
    ) -> Iterator[Scan]:
        """The scans as the reader gives them, odometry sign applied, nothing else.

        A CARMEN log's reader fills ``stats`` (its counts and log anomalies,
        :mod:`slam.io.anomalies`) while reading; ``strict`` makes the first anomaly an error.
        A bag is read without anomaly checks (``stats`` stays as it is).
        """
        if self.format == "rosbag":
            yield from self._reader.scans()
            return
        from slam.io.carmen import reader_scans

        reader = self._carmen_reader(strict)
        if stats is not None:
            reader.stats = stats
        yield from reader_scans(reader, self.policy.odometry_sign)

    def _carmen_reader(self, strict: bool = False) -> Any:
        from slam.io.carmen import CarmenReader

        return CarmenReader(self.log, geometry=self._reader, strict=strict)

    def scans(
        self,
        max_scans: int | None = None,
        *,
        need_odometry: bool = True,
        stats: CarmenStats | None = None,
        strict: bool = False,
    ) -> Iterator[Scan]:
        """The scans with the stated geometry and range limits applied, in log order.

        A bag's scans outside the odometry's time span (:mod:`slam.io.rosbag`), and a CARMEN
        log's scans without a pose of their own (``RAWLASER``) more than
        :data:`slam.io.carmen.MAX_ODOMETRY_GAP_S` from its ``ODOM`` lines
        (:func:`slam.io.carmen.with_odom_poses`), are left out when ``need_odometry`` (an
        :class:`InputWarning` counts them); the indices stay contiguous.  ``stats`` and
        ``strict``: the log anomalies of a CARMEN log, counted in ``stats.anomalies`` over the
        part of the log read, or an error at the first one (:meth:`raw_scans`; bags are not
        checked).
        """
        if max_scans is not None and max_scans <= 0:
            return
        if self.format == "carmen" and stats is None:
            from slam.io.carmen import CarmenStats

            stats = CarmenStats()
        scans = self._read(max_scans, need_odometry, stats, strict)
        if need_odometry:
            delay = self.odometry_delay_scans()
            if delay:
                scans = shift_odometry(scans, delay, self._delay_interval_s)
        yield from self._motion(scans) if need_odometry else scans

    def odometry_delay_scans(self) -> float:
        """The delay (scans) each scan's odometry is read at: stated, estimated once, or 0.

        Estimated (``[scanner] odometry_delay = "estimated"``) from the log's first turns
        (:func:`slam.frontend.odometry_delay.estimate_odometry_delay`); 0 where the motion
        comes from the scans, the log has too few turns, or the estimate is not significant
        (its likelihood ratio against no delay below χ²₁'s 99 % point).
        """
        if self._delay is not None:
            return self._delay
        scanner = self.scanner
        delay = 0.0
        if scanner.odometry_delay_scans is not None:
            delay = float(scanner.odometry_delay_scans)
            self._delay_source = "config"
            # how long a gap counts (slam.frontend.odometry_delay.scan_slots): the scans' usual
            # interval, from the first of them
            self._delay_interval_s = median_interval(
                s.timestamp for s in self._read(_INTERVAL_SCANS, False, None, False)
            )
        elif scanner.odometry_delay == "estimated" and scanner.odometry_source != "scan_matching":
            stats = None
            if self.format == "carmen":
                from slam.io.carmen import CarmenStats

                stats = CarmenStats()  # as scans() reads it (scans without a pose left out)
            estimate = estimate_odometry_delay(
                self._read(None, True, stats, False), self.noise, self.matching
            )
            self._delay_estimate = estimate
            self._delay_source = "estimated"
            if estimate is not None and estimate.chi2 > DELAY_CHI2_99:
                delay = estimate.scans
                self._delay_interval_s = estimate.interval_s
        else:
            self._delay_source = "off"
        self._delay = delay
        return delay

    def _read(
        self,
        max_scans: int | None,
        need_odometry: bool,
        stats: CarmenStats | None,
        strict: bool,
    ) -> Iterator[Scan]:
        """:meth:`scans` before the odometry source is applied."""
        scanner = self.scanner
        k = 0
        skipped = 0
        for scan in self.raw_scans(stats=stats, strict=strict):
            if need_odometry and scan.pose_odom_base is None and scan.pose_odom_laser is None:
                # a bag's scan outside its odometry's span; a CARMEN scan without a pose in a
                # log whose ODOM lines lie more than MAX_ODOMETRY_GAP_S away from it
                has_odometry = (
                    self._reader.odometry is not None
                    if self.format == "rosbag"
                    else stats is not None and stats.odometry > 0
                )
                if has_odometry:
                    skipped += 1
                    continue
            scan = _apply_scanner(scan, scanner, k)
            if k == 0:
                self._note_geometry(scan)
            k += 1
            yield scan
            if max_scans is not None and k >= max_scans:
                break  # not one message more is read (anomalies cover the part read)
        if skipped:
            self._skipped_without_odometry = skipped
            warnings.warn(
                f"{self.log}: {skipped} scan(s) lie more than 1 s outside the odometry's time "
                "span (no pose of their own) and were left out",
                InputWarning,
                stacklevel=2,
            )

    def _motion(self, scans: Iterator[Scan]) -> Iterator[Scan]:
        """``scans`` with the odometry ``[scanner] odometry_source`` asks for (module docstring).

        ``"auto"`` holds the scans back while the log's odometry has not moved (or is absent)
        and registers them meanwhile (:class:`~slam.frontend.laser_odometry.LaserOdometry`):
        once the odometry moves they pass unchanged (where the logged laser poses stand still
        while the odometry poses move, with the odometry pose composed with the mounting, and
        an :class:`InputWarning`); once the scans have moved
        :data:`STILL_ODOMETRY_M` or :data:`STILL_ODOMETRY_RAD` from the first scan without it,
        the log's odometry is taken for absent (an :class:`InputWarning`) and every scan gets
        the laser odometry's pose.
        """
        mode = self.scanner.odometry_source
        if mode == "log":
            yield from scans
            return
        laser = LaserOdometry(self.scanner.scan_odometry, self.noise, self.matching)
        first_points: ScanPoints | None = None  # the first scan's, for the scans' own motion
        origin: FloatArray | None = None  # the first scan's logged pose (else zero)
        first: FloatArray | None = None  # the first scan's logged pose, if it has one
        held: list[tuple[Scan, FloatArray, FloatArray]] = []
        decided: str | None = mode if mode == "scan_matching" else None
        first_base: FloatArray | None = None  # the first scan's odometry (base) pose
        for scan in scans:
            if decided == "log":
                yield scan
                continue
            if decided == "base":
                yield self._with_base_pose(scan)
                continue
            odom = self._logged_pose(scan)
            if origin is None:
                origin = np.zeros(3) if odom is None else odom
                first = odom
                first_base = scan.pose_odom_base
            if decided is None and _moved(odom, first):
                decided = "log"  # the log's odometry moves: everything as logged
                yield from (s for s, _, _ in held)
                held = []
                yield scan
                continue
            if decided is None and _moved(scan.pose_odom_base, first_base):
                # the logged laser poses stand still while the odometry poses move
                decided = "base"
                warnings.warn(
                    f"{self.log}: the log's laser poses never move while its odometry "
                    f"poses do (by scan {scan.index}): the laser odometry is the "
                    "odometry pose composed with the mounting",
                    InputWarning,
                    stacklevel=2,
                )
                self.policy = replace(self.policy, laser_odometry="base")
                yield from (self._with_base_pose(s) for s, _, _ in held)
                held = []
                yield self._with_base_pose(scan)
                continue
            pose = laser.add(scan)
            cov = laser.step_cov.copy()
            if decided is not None:
                yield self._with_laser_pose(scan, pose, origin, cov)
                continue
            held.append((scan, pose, cov))
            points = laser.last_points
            assert points is not None  # laser.add has just computed them
            if first_points is None:
                first_points = points
            away = math.hypot(pose[0], pose[1])
            moved = away > STILL_ODOMETRY_M or abs(pose[2]) > STILL_ODOMETRY_RAD
            # ... and the scans themselves show it: the first no longer registers this one
            # where it was (not only the chained matches' constant-velocity drift)
            if moved and (
                overlap_at(first_points, points, np.zeros(3), laser.matching)
                < laser.matching.min_overlap
            ):
                decided = "scan_matching"
                warnings.warn(
                    f"{self.log}: the log's odometry "
                    + ("is absent" if first is None else "never moves")
                    + f" while its scans move ({away:.2f} m, {abs(pose[2]):.2f} rad by scan "
                    f"{scan.index}): the motion is made by matching the scans (laser "
                    "odometry, [scanner] odometry_source)",
                    InputWarning,
                    stacklevel=2,
                )
                yield from (self._with_laser_pose(s, p, origin, c) for s, p, c in held)
                held = []
        if decided is None and held:
            # neither the odometry nor the scans moved: the scans as logged, those without
            # odometry at the laser odometry's pose (as still as they are)
            assert origin is not None
            absent = [s.pose_odom_laser is None and s.pose_odom_base is None for s, _, _ in held]
            yield from (
                self._with_laser_pose(s, p, origin, c) if a else s
                for (s, p, c), a in zip(held, absent, strict=True)
            )
            decided = "scan_matching" if any(absent) else "log"
        if decided == "scan_matching":
            self.odometry_source = "scan_matching"
            self._laser_odometry = laser

    def _logged_pose(self, scan: Scan) -> FloatArray | None:
        """The scan's logged laser odometry pose, or None when it has none."""
        if scan.pose_odom_laser is None and scan.pose_odom_base is None:
            return None
        return self.policy.pose_odom_laser(scan)

    def _with_base_pose(self, scan: Scan) -> Scan:
        """``scan`` with its laser odometry from its odometry (base) pose and the mounting."""
        if scan.pose_odom_base is None:
            return scan
        pose = pose_compose(np.asarray(scan.pose_odom_base, dtype=float), self.policy.mount)
        return replace(scan, pose_odom_laser=pose)

    def _with_laser_pose(
        self, scan: Scan, pose: FloatArray, origin: FloatArray, step_cov: FloatArray
    ) -> Scan:
        """``scan`` with the laser odometry's pose (from ``origin``) and step covariance."""
        pose_laser = pose_compose(origin, pose)
        pose_base = pose_compose(pose_laser, pose_inverse(self.policy.mount))
        return replace(
            scan, pose_odom_laser=pose_laser, pose_odom_base=pose_base, odometry_step_cov=step_cov
        )

    def _note_geometry(self, scan: Scan) -> None:
        g = self.geometry
        b = np.asarray(scan.bearings)
        g.first_angle_deg = math.degrees(float(b[0])) if b.size else None
        g.step_deg = math.degrees(float(b[1] - b[0])) if b.size > 1 else None
        g.beams = int(b.size)
        g.max_range_m = float(scan.max_range_m)

    def run_summary(self, n_scans: int, max_scans: int | None) -> dict[str, Any]:
        """What ``summary.json`` says about the input of a run over ``n_scans`` scans.

        ``log`` (the absolute path), ``dataset``, ``scans_in_log`` (where known), ``partial``
        (true when the run stopped before the log's end: fewer scans than the log has, or, the
        count unknown, ``max_scans`` reached; ``lineslam evaluate`` then scores the relations
        inside the run),
        ``max_scans`` and ``input`` (:meth:`describe`).
        """
        # absolute, so that the results folder can be evaluated from any working directory
        out: dict[str, Any] = {"log": os.path.abspath(self.log), "dataset": self.name}
        if self.n_scans is not None:
            out["scans_in_log"] = self.n_scans
            partial = n_scans < self.n_scans
        else:
            partial = max_scans is not None and n_scans >= max_scans
        out["partial"] = bool(partial)
        if max_scans is not None:
            out["max_scans"] = int(max_scans)
        out["input"] = self.describe()
        return out

    def describe(self) -> dict[str, Any]:
        """The ``"input"`` block of ``summary.json``: what was read and what was assumed."""
        out: dict[str, Any] = {
            "log": os.path.abspath(self.log),
            "format": self.format,
            "catalogue": self.manifest.name if self.manifest is not None else None,
            "geometry": self.geometry.to_dict(),
            "pose_base_laser": list(self.policy.pose_base_laser),
            "mount_source": self.mount_source,
            "laser_odometry": self.policy.laser_odometry,
            "odometry_sign": self.policy.odometry_sign,
            "frame": self.policy.output_frame,
            **self.details,
        }
        if self._skipped_without_odometry:
            out["scans_without_odometry_left_out"] = self._skipped_without_odometry
        out["odometry_source"] = self.odometry_source
        if self._delay is not None:
            out["odometry_delay"] = {
                "source": self._delay_source,
                "scans": self._delay,
                "interval_s": self._delay_interval_s,
                "estimate": None
                if self._delay_estimate is None
                else self._delay_estimate.to_dict(),
            }
        if self._laser_odometry is not None:
            out["laser_odometry_scans"] = {
                "matched": int(self._laser_odometry.matched),
                "unmatched": int(self._laser_odometry.unmatched),
                "rescued": int(self._laser_odometry.rescued),
            }
        return out


def _moved(pose: FloatArray | None, first: FloatArray | None) -> bool:
    """Whether ``pose`` differs from ``first`` at all (False when either is missing)."""
    return pose is not None and first is not None and bool(np.any(pose != first))


def _apply_scanner(scan: Scan, scanner: ScannerConfig, index: int) -> Scan:
    """``scan`` with the stated geometry and range limits, re-indexed to ``index``."""
    changes: dict[str, Any] = {}
    if scan.index != index:
        changes["index"] = index
    if scanner.states_geometry:
        n = scan.n_beams
        if scanner.beams is not None and n != scanner.beams:
            raise LogFormatError(
                f"scan {scan.index} has {n} beams, [scanner] beams = {scanner.beams}",
                scan.source or None,
            )
        b = np.asarray(scan.bearings)
        if scanner.step_deg is not None:
            step = math.radians(scanner.step_deg)
        elif scanner.fov_deg is not None:
            step = math.radians(scanner.fov_deg) / max(n - 1, 1)
        else:
            step = float(b[1] - b[0]) if n > 1 else 0.0
        if scanner.first_angle_deg is not None:
            first = math.radians(scanner.first_angle_deg)
        elif scanner.fov_deg is not None:
            first = -0.5 * math.radians(scanner.fov_deg)
        else:
            first = float(b[0])
        from slam.io.laser import beam_bearings

        changes["bearings"] = beam_bearings(first, step, n) if step != 0 else b
    if scanner.max_range_m is not None:
        changes["max_range_m"] = float(scanner.max_range_m)
    if scanner.min_range_m:
        r = np.asarray(scan.ranges, dtype=np.float64)
        low = r < scanner.min_range_m
        if low.any():
            r = r.copy()
            r[low] = np.nan
            changes["ranges"] = r
    return replace(scan, **changes) if changes else scan


def _stated_mount(scanner: ScannerConfig) -> tuple[float, float, float] | None:
    if scanner.pose_base_laser is not None:
        return tuple(float(v) for v in scanner.pose_base_laser)  # type: ignore[return-value]
    if scanner.mount_source == "config":
        return (0.0, 0.0, 0.0)
    return None


def _logged_poses_hold(
    estimate: MountEstimate, param_mount: tuple[float, float, float], where: str, kind: str
) -> bool:
    """Whether a log's laser poses already hold the mounting its ``PARAM`` lines state.

    ``True`` when the offset of the laser pose from the odometry pose is that mounting, for
    every scan (the laser odometry is then the logged laser pose); ``False`` when the two
    poses coincide (the logger did not apply it: the laser odometry is the base's composed with
    the stated mounting).  Otherwise an :class:`InputWarning` (the stated mounting is used with
    the base odometry) and ``False``.
    """
    offset = estimate.pose_base_laser
    if offset is None:
        return False
    stated = np.asarray(param_mount, dtype=float)
    found = np.asarray(offset, dtype=float)
    close = (
        estimate.consistent
        and float(np.hypot(*(found[:2] - stated[:2]))) <= MOUNT_TOLERANCE_M
        and abs(math.remainder(float(found[2] - stated[2]), math.tau)) <= MOUNT_TOLERANCE_RAD
    )
    if close and any(param_mount):
        return True
    zero = (
        estimate.consistent
        and float(np.hypot(found[0], found[1])) <= MOUNT_TOLERANCE_M
        and abs(math.remainder(float(found[2]), math.tau)) <= MOUNT_TOLERANCE_RAD
    )
    if close or zero:
        return False
    warnings.warn(
        f"{where}: its PARAM lines mount the laser at ({stated[0]:g} m, {stated[1]:g} m, "
        f"{math.degrees(stated[2]):g} deg), but the {kind} laser poses differ from the "
        f"odometry poses by ({found[0]:.3f} m, {found[1]:.3f} m, {math.degrees(found[2]):.2f} "
        "deg; the median over the scans): the PARAM mounting is used with the odometry pose "
        "(state another with --mount X,Y,THETA_DEG)",
        InputWarning,
        stacklevel=4,
    )
    return False


def _policy(
    scanner: ScannerConfig,
    mount: tuple[float, float, float] | None,
    mount_source: str,
    logged_has_mount: bool,
    where: str,
    manifest: DatasetManifest | None = None,
) -> InputPolicy:
    """The resolved policy (module docstring); ``manifest``: the log's catalogue entry."""
    if scanner.laser_odometry != "auto":
        laser_odometry = scanner.laser_odometry
    else:
        laser_odometry = "logged" if logged_has_mount else "base"
    frame: Literal["laser", "base"]
    if scanner.output_frame == "auto":
        frame = manifest.relations_frame if manifest is not None else "base"
    else:
        frame = scanner.output_frame
    if frame == "base" and mount is None:
        warnings.warn(
            f"{where}: the laser's mounting on the robot is not known (not stated, not "
            "catalogued, not derived from the log's poses, not in tf): the trajectory is "
            "reported for the laser (state --mount X,Y,THETA_DEG)",
            InputWarning,
            stacklevel=3,
        )
        frame = "laser"
    return InputPolicy(
        mount if mount is not None else (0.0, 0.0, 0.0),
        laser_odometry,
        frame,
        scanner.odometry_sign,
    )


def open_log(
    log: str | Path,
    scanner: ScannerConfig | None = None,
    *,
    max_scans: int | None = None,
    noise: SensorNoiseConfig | None = None,
    matching: ScanMatchConfig | None = None,
) -> LogInput:
    """Open a log file, bag or catalogue name with the scanner settings (module docstring).

    Parameters
    ----------
    log
        A CARMEN file, a ROS 1 ``.bag`` file, a ROS 2 bag folder, or a catalogue name.
    scanner
        The ``[scanner]`` settings; default :class:`ScannerConfig()`.
    max_scans
        The run reads only the first scans: the mounting is derived from those.
    noise, matching
        The sensor noise of the laser odometry's points and its scan matcher's settings, when
        the motion comes from the scans (default: :class:`~linefit.config.SensorNoiseConfig`
        and :class:`~slam.frontend.scan_match.ScanMatchConfig` defaults; a run passes its own,
        :func:`slam.config.open_run_log`).

    Raises
    ------
    DatasetError, InputError, LogFormatError
        No such log or name; a bag without scans; an unreadable first line.
    """
    from slam.io.catalog import resolve_log
    from slam.io.rosbag import is_rosbag

    scanner = scanner if scanner is not None else ScannerConfig()
    path = Path(log)
    if is_rosbag(path):
        opened = _open_bag(path, scanner)
    else:
        opened = _open_carmen(resolve_log(log), scanner, max_scans)
    opened.noise = noise
    opened.matching = matching
    return opened


def _open_bag(path: Path, scanner: ScannerConfig) -> LogInput:
    from slam.io.catalog import manifest_for_path
    from slam.io.rosbag import RosbagLog

    bag = RosbagLog(
        path,
        scan_topic=scanner.scan_topic,
        odom_topic=scanner.odom_topic,
        odometry=scanner.odometry,
        base_frame=scanner.base_frame,
    )
    manifest = manifest_for_path(path) if path.is_file() else None
    where = str(path)
    stated = _stated_mount(scanner)
    details: dict[str, Any] = {"scan_topic": bag.scan_topic}
    if stated is not None:
        mount: tuple[float, float, float] | None = stated
        source = "config"
    else:
        info = bag.mount()
        mount = info.pose_base_laser if info is not None else None
        source = "tf" if info is not None else "none"
        if info is not None:
            details["tf"] = f"{info.base_frame} -> {info.laser_frame} ({info.hops} static)"
    details["odometry"] = bag.odometry_source or "none"
    if bag.odometry is None:
        fallback = (
            ""
            if scanner.odometry_source == "log"
            else ": the motion is made by matching the scans once they move (laser odometry)"
        )
        warnings.warn(
            f"{where}: no odometry (no nav_msgs/Odometry topic and no /tf to the base frame)"
            + fallback,
            InputWarning,
            stacklevel=3,
        )
    policy = _policy(scanner, mount, source, False, where, manifest)
    geometry = _Geometry(source="config" if scanner.states_geometry else "log")
    return LogInput(
        log=path,
        name=manifest.name if manifest is not None else path.stem,
        format="rosbag",
        manifest=manifest,
        relations=None,
        policy=policy,
        n_scans=bag.scan_count,
        mount_source=source,
        scanner=scanner,
        details=details,
        geometry=geometry,
        _reader=bag,
    )


def _open_carmen(resolved: ResolvedLog, scanner: ScannerConfig, max_scans: int | None) -> LogInput:
    from slam.io.anomalies import readable
    from slam.io.carmen import CarmenReader, _sniff_laser_type, read_params
    from slam.io.laser import guess_laser_geometry

    where = str(resolved.log)
    manifest = resolved.manifest
    laser_type = _sniff_laser_type(resolved.log)
    old_format = laser_type in ("FLASER", "RLASER")
    reader_geometry = manifest.laser_geometry() if manifest is not None else None
    # the log's own PARAM lines (the catalogue's facts win for its own logs)
    params = read_params(resolved.log) if manifest is None and laser_type else None
    details: dict[str, Any] = {"laser_message": laser_type}
    if params is not None and laser_type:
        stated_params = params.stated(laser_type)
        if stated_params:
            details["params"] = stated_params
    param_geometry = None
    if params is not None and old_format and laser_type:
        param_geometry, problem = params.laser_geometry(laser_type)
        if problem is not None:
            warnings.warn(f"{where}: {problem}", InputWarning, stacklevel=3)
        if param_geometry is not None:
            reader_geometry = param_geometry
    if scanner.states_geometry:
        geometry_source = "config"
    elif manifest is not None:
        geometry_source = "catalogue"
    elif param_geometry is not None:
        geometry_source = "param"
    elif old_format:
        geometry_source = "carmen-rule"
    else:
        geometry_source = "log"
    n_scans = manifest.scans if manifest is not None else None
    stated = _stated_mount(scanner)
    mount: tuple[float, float, float] | None = None
    logged_has_mount = False
    param_mount = params.mount(laser_type) if params is not None and laser_type else None
    if stated is not None:
        mount, source = stated, "config"
    elif manifest is not None:
        facts = manifest.laser
        mount = (facts.mount_x_m, facts.mount_y_m, math.radians(facts.mount_theta_deg))
        source = "catalogue"
        logged_has_mount = facts.mount_applied_in_log or not any(mount)
    elif param_mount is not None:
        mount, source = param_mount, "param"
    else:
        source = "none"
    needs_pass = manifest is None and (stated is None or n_scans is None)
    if needs_pass:
        # one pass: the scan count (progress bars) and, unless stated, the mounting
        reader = CarmenReader(resolved.log, geometry=reader_geometry)
        n = 0
        first_beams = 0
        offsets = _MountAccumulator()
        for scan in islice(reader.scans(), max_scans):
            first_beams = first_beams or scan.n_beams
            n += 1
            offsets.add(scan)
        n_scans = n if max_scans is None else None
        if stated is None:
            estimate = offsets.result()
            if estimate.pose_base_laser is not None:
                details["mount_from_log"] = {
                    "scans": estimate.n_scans,
                    "spread_m": estimate.spread_m,
                    "spread_rad": estimate.spread_rad,
                }
                if param_mount is not None:
                    logged_has_mount = _logged_poses_hold(
                        estimate, param_mount, where, laser_type or ""
                    )
                elif estimate.consistent:
                    mount, source, logged_has_mount = estimate.pose_base_laser, "log", True
                else:
                    warnings.warn(
                        f"{where}: the laser pose and the odometry pose of the log differ by an "
                        f"offset that varies over the log (by {readable(estimate.spread_m)} m, "
                        f"{math.degrees(estimate.spread_rad):.2f} deg): no mounting derived; "
                        "state one with --mount X,Y,THETA_DEG",
                        InputWarning,
                        stacklevel=3,
                    )
                    logged_has_mount = True
        if geometry_source == "carmen-rule" and first_beams:
            guess = guess_laser_geometry(first_beams)
            warnings.warn(
                f"{where}: not a catalogued log and no beam geometry stated: CARMEN's rule for "
                f"{guess.n_beams} beams (first beam at {math.degrees(guess.first_angle_rad):g} "
                f"deg, step {math.degrees(guess.step_rad):.4g} deg); if the scanner differs, "
                "state it (--step DEG or --fov DEG, --first-angle DEG)",
                InputWarning,
                stacklevel=3,
            )
    policy = _policy(scanner, mount, source, logged_has_mount, where, manifest)
    return LogInput(
        log=resolved.log,
        name=resolved.name,
        format="carmen",
        manifest=manifest,
        relations=resolved.relations,
        policy=policy,
        n_scans=n_scans,
        mount_source=source,
        scanner=scanner,
        details=details,
        geometry=_Geometry(source=geometry_source),
        _reader=reader_geometry,
    )


# -- the older entry points -------------------------------------------------------------------


def policy_for_log(policy: InputPolicy, log: str | Path, mount_source: str) -> InputPolicy:
    """The policy with the laser mounting of a catalogued log applied.

    With ``mount_source`` ``"catalog"`` or ``"auto"`` and a log whose catalogue entry records
    a mounting that the log's laser poses do not contain (``mount_applied_in_log = false``),
    the laser odometry becomes ``base odometry ∘ mounting`` and the trajectory is reported in
    the frame of the log's relations (``relations_frame``).  Otherwise ``policy`` is returned
    unchanged.  :func:`open_log` resolves the whole policy of any log.
    """
    from slam.io.catalog import resolve_log

    if mount_source not in ("catalog", "auto"):
        return policy
    manifest = resolve_log(log).manifest
    if manifest is None or manifest.laser is None:
        return policy
    laser = manifest.laser
    mount = (laser.mount_x_m, laser.mount_y_m, math.radians(laser.mount_theta_deg))
    if laser.mount_applied_in_log or not any(mount):
        return policy
    return replace(
        policy,
        pose_base_laser=mount,
        laser_odometry="base",
        output_frame=manifest.relations_frame,
    )


def read_log_scans(
    log: str | Path,
    policy: InputPolicy,
    *,
    stats: CarmenStats | None = None,
    strict: bool = False,
) -> Iterator[Scan]:
    """The scans of a log file (or catalogued name), odometry read by the policy's sign rule.

    ``stats`` is filled while reading (with the log's anomalies); ``strict`` makes the first
    anomaly an error (:func:`slam.io.carmen.iter_log_scans`).
    """
    from slam.io.carmen import iter_log_scans
    from slam.io.catalog import resolve_log

    return iter_log_scans(resolve_log(log).log, policy.odometry_sign, stats=stats, strict=strict)
