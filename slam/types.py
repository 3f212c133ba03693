"""Plain data types passed between the layers of ``slam``.

Naming: a pose ``pose_a_b`` is the pose of frame ``b`` expressed in frame ``a`` (it maps points
from ``b`` to ``a``), stored as ``(x, y, theta)`` in metres and radians.  Frames: ``world`` (the
map), ``odom`` (the odometry's own drifting frame), ``base`` (the robot), ``laser`` (the
scanner).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.errors import InputError
from linefit.line import Line

__all__ = ["Scan", "check_lines", "check_scan"]

FloatArray = NDArray[np.float64]


def _vector(value: Any, what: str, fail: Any) -> FloatArray:
    """``value`` as a 1-D float array (float arrays pass through unchanged)."""
    if not (isinstance(value, np.ndarray) and value.dtype.kind == "f"):
        try:
            value = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise fail(f"{what} must be an array of numbers") from None
    if value.ndim != 1:
        raise fail(f"{what} must be one-dimensional, got shape {value.shape}")
    return value


def _good_pose(value: Any) -> bool:
    return value is None or (
        type(value) is np.ndarray and value.shape == (3,) and value.dtype.kind == "f"
    )


def _good_cov(value: Any) -> bool:
    return value is None or (
        type(value) is np.ndarray
        and value.shape == (3, 3)
        and value.dtype.kind == "f"
        and bool(np.all(np.isfinite(value)))
    )


def _cov(value: Any, what: str, fail: Any) -> FloatArray | None:
    if value is None:
        return None
    try:
        value = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise fail(f"{what} must be a 3x3 covariance") from None
    if value.shape != (3, 3):
        raise fail(f"{what} must have shape (3, 3), got {value.shape}")
    if not np.all(np.isfinite(value)):
        raise fail(f"{what} must be finite")
    return value


def _pose(value: Any, what: str, fail: Any) -> FloatArray | None:
    if value is None:
        return None
    if not (isinstance(value, np.ndarray) and value.dtype.kind == "f"):
        try:
            value = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise fail(f"{what} must be three numbers (x, y, theta)") from None
    if value.shape != (3,):
        raise fail(f"{what} must have shape (3,) (x, y, theta), got {value.shape}")
    return value


@dataclass(frozen=True, eq=False)
class Scan:
    """One laser scan with the odometry that came with it.

    Lists are accepted for the arrays (converted to float arrays); wrong types, shapes, a
    non-finite time stamp or a non-positive range limit raise :class:`InputError` naming the
    field (and the scan's ``source``).

    Attributes
    ----------
    index : int
        0-based position among the log's laser scans, in file order (never re-sorted: Intel's
        timestamps go backwards now and then).
    timestamp : float
        Time stamp (s) exactly as in the log (CARMEN: the ``ipc_timestamp`` field).
    ranges : ndarray, shape (n,)
        Measured ranges (m), as logged (max-range, zero and non-finite readings included).
    bearings : ndarray, shape (n,)
        Beam angles (rad) in the laser frame.
    max_range_m : float
        Readings ``>= max_range_m`` are "no return" and are not measurements of a surface.
    pose_odom_base : ndarray, shape (3,) or None
        Odometry pose of the robot base at this scan ``(x, y, theta)``, if the log has one.
    pose_odom_laser : ndarray, shape (3,) or None
        Pose of the laser in the odometry frame as logged (CARMEN ``FLASER x y theta``,
        ``ROBOTLASER1 laser_x laser_y laser_theta``), if the log has one.
    source : str
        Where the scan came from, for messages (``"path:line"``).
    odometry_step_cov : ndarray, shape (3, 3) or None
        Covariance of the odometry's step from the previous scan to this one (in the previous
        laser pose's frame, right perturbation), where the odometry states one (the laser
        odometry's matches); None: the estimator's motion model gives it.
    """

    index: int
    timestamp: float
    ranges: FloatArray
    bearings: FloatArray
    max_range_m: float = np.inf
    pose_odom_base: FloatArray | None = None
    pose_odom_laser: FloatArray | None = None
    source: str = ""
    odometry_step_cov: FloatArray | None = None

    def __post_init__(self) -> None:
        """Check the fields (lists become float arrays); raise :class:`InputError` naming them."""
        r, b, t = self.ranges, self.bearings, self.timestamp
        if (  # the common case, cheaply: float arrays, a finite float stamp, proper poses
            type(r) is np.ndarray
            and type(b) is np.ndarray
            and r.ndim == 1
            and r.shape == b.shape
            and r.dtype.kind == "f"
            and b.dtype.kind == "f"
            and type(t) is float
            and math.isfinite(t)
            and type(self.index) is int
            and _good_pose(self.pose_odom_base)
            and _good_pose(self.pose_odom_laser)
            and _good_cov(self.odometry_step_cov)
            and isinstance(self.max_range_m, float)
            and self.max_range_m > 0.0
        ):
            return
        self._check_fields()

    def _check_fields(self) -> None:
        where = self.source or None

        def fail(message: str) -> InputError:
            return InputError(f"Scan {self.index!r}: {message}", where)

        if isinstance(self.index, bool) or not isinstance(self.index, numbers.Integral):
            raise fail(f"index must be a whole number, got {type(self.index).__name__}")
        try:
            finite = math.isfinite(self.timestamp)
        except TypeError:
            raise fail(f"timestamp must be a number, got {type(self.timestamp).__name__}") from None
        if not finite:
            raise fail(f"timestamp must be finite, got {float(self.timestamp)}")
        ranges = _vector(self.ranges, "ranges", fail)
        bearings = _vector(self.bearings, "bearings", fail)
        if ranges.shape != bearings.shape:
            raise fail(
                f"ranges ({ranges.shape[0]}) and bearings ({bearings.shape[0]}) differ in length"
            )
        try:
            limit_ok = float(self.max_range_m) > 0.0
        except (TypeError, ValueError):
            raise fail("max_range_m must be a number") from None
        if not limit_ok:
            raise fail(f"max_range_m must be > 0 (inf: no limit), got {self.max_range_m}")
        base = _pose(self.pose_odom_base, "pose_odom_base", fail)
        laser = _pose(self.pose_odom_laser, "pose_odom_laser", fail)
        step_cov = _cov(self.odometry_step_cov, "odometry_step_cov", fail)
        for name, value in (
            ("ranges", ranges),
            ("bearings", bearings),
            ("pose_odom_base", base),
            ("pose_odom_laser", laser),
            ("odometry_step_cov", step_cov),
        ):
            if value is not getattr(self, name):
                object.__setattr__(self, name, value)

    @property
    def n_beams(self) -> int:
        """Number of beams in the scan."""
        return int(self.ranges.shape[0])

    def valid_mask(self) -> NDArray[np.bool_]:
        """True for readings that are measurements of a surface (finite, > 0, < max range)."""
        r = self.ranges
        return np.isfinite(r) & (r > 0.0) & (r < self.max_range_m)

    def points_xy(self) -> FloatArray:
        """Cartesian points ``(n, 2)`` in the laser frame for all beams (invalid ones too)."""
        return np.stack(
            [self.ranges * np.cos(self.bearings), self.ranges * np.sin(self.bearings)], 1
        )


def check_scan(scan: object, name: str = "scan") -> Scan:
    """``scan`` if it is a :class:`~slam.types.Scan`, else :class:`InputError` naming ``name``.

    A ``Scan`` checks its own fields when it is made (finite time stamp, shapes, ...).
    """
    if not isinstance(scan, Scan):
        raise InputError(f"{name} must be a slam.types.Scan, got {type(scan).__name__}")
    return scan


def check_lines(lines: object, scan: Scan, name: str = "lines") -> list[Line]:
    """``lines`` as a list of :class:`linefit.Line`, else :class:`InputError` naming the scan.

    ``None`` is not accepted here (callers extract the lines themselves then).
    """
    where = scan.source or None
    if isinstance(lines, str | bytes) or not isinstance(lines, Iterable):
        raise InputError(
            f"scan {scan.index}: {name} must be a sequence of linefit.Line, got "
            f"{type(lines).__name__}",
            where,
        )
    out = list(lines)
    for k, line in enumerate(out):
        if not isinstance(line, Line):
            raise InputError(
                f"scan {scan.index}: {name}[{k}] must be a linefit.Line, got {type(line).__name__}",
                where,
            )
    return out
