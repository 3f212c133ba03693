"""The input policy: how a log's odometry becomes the laser's motion, and which frame is reported.

Every estimator and runner (the factor graph, the EKF, the map builder, the comparisons) reads
its odometry and reports its poses through one :class:`InputPolicy`, so that all of them see
the same motion and write the same frame.

* **Laser odometry.**  The laser's odometry pose is the scan's logged laser pose
  (``Scan.pose_odom_laser``), else the base's odometry composed with the mounting
  (``Scan.pose_odom_base ∘ pose_base_laser``); with ``laser_odometry = "base"`` always the
  latter (logs whose laser poses lack the mounting).
* **Output frame.**  Poses are estimated for the laser; with ``output_frame = "base"`` they are
  reported for the robot base, ``pose_world_base = pose_world_laser ∘ pose_base_laser⁻¹``, their
  covariances carried along by the adjoint of the mounting.
* **Odometry sign.**  ``odometry_sign = "velocity"`` reads a CARMEN log with the increments that
  the logged speed says went backwards negated (:func:`slam.io.carmen.iter_log_scans`).
* **Catalogued logs.**  :func:`policy_for_log` applies the mounting recorded in the dataset
  catalogue to a catalogued log whose laser poses lack it.

The settings live in the ``[slam]`` table of the run configuration (``pose_base_laser``,
``mount_source``, ``laser_odometry``, ``output_frame``, ``odometry_sign``); any object with those
attributes builds a policy (:meth:`InputPolicy.of`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, InputError
from slam.geometry import adjoint_pose2, pose_compose, pose_inverse
from slam.types import Scan

if TYPE_CHECKING:
    from slam.io.carmen import CarmenStats

__all__ = ["InputPolicy", "InputSettings", "policy_for_log", "read_log_scans"]

FloatArray = NDArray[np.float64]


class InputSettings(Protocol):
    """Where the policy's settings come from (e.g. :class:`slam.line_slam.SlamConfig`)."""

    @property
    def pose_base_laser(self) -> tuple[float, float, float]:
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

    @property
    def mount_source(self) -> str:
        """``"catalog"`` or ``"config"``."""


@dataclass(frozen=True)
class InputPolicy:
    """How scans' odometry is read and which frame poses are reported in (module docstring).

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
    def of(cls, settings: InputSettings) -> InputPolicy:
        """The policy of a configuration holding the settings (e.g. ``RunConfig.slam``)."""
        return cls(
            tuple(float(v) for v in settings.pose_base_laser),  # type: ignore[arg-type]
            settings.laser_odometry,  # type: ignore[arg-type]
            settings.output_frame,  # type: ignore[arg-type]
            settings.odometry_sign,  # type: ignore[arg-type]
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
        if self.output_frame != "base" or poses.shape[0] == 0:
            return poses, covariances
        poses = pose_compose(poses, np.broadcast_to(pose_inverse(self.mount), poses.shape))
        if covariances is not None:
            F = adjoint_pose2(self.mount)
            covariances = F @ covariances @ F.T
        return poses, covariances


def policy_for_log(policy: InputPolicy, log: str | Path, mount_source: str) -> InputPolicy:
    """The policy with the laser mounting of a catalogued log applied.

    With ``mount_source == "catalog"`` and a log whose catalogue entry records a mounting that
    the log's laser poses do not contain (``mount_applied_in_log = false``), the laser odometry
    becomes ``base odometry ∘ mounting`` and the trajectory is reported for the base (the frame
    of the poses as logged, which the relations refer to).  Otherwise ``policy`` is returned
    unchanged.
    """
    from slam.io.catalog import resolve_log

    if mount_source != "catalog":
        return policy
    manifest = resolve_log(log).manifest
    if manifest is None or manifest.laser is None:
        return policy
    laser = manifest.laser
    mount = (laser.mount_x_m, laser.mount_y_m, math.radians(laser.mount_theta_deg))
    if laser.mount_applied_in_log or not any(mount):
        return policy
    return replace(policy, pose_base_laser=mount, laser_odometry="base", output_frame="base")


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
