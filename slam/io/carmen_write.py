"""Writing CARMEN logs (``.clf``): ``FLASER`` or ``ROBOTLASER1`` scans with ``ODOM`` lines.

Main entry point::

    write_carmen(path, scans, *, message="auto", range_decimals=4) -> CarmenWriteStats

Lines written (one message per line, as read by :mod:`slam.io.carmen`)::

    ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp
    FLASER n r1 … rn x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp
    ROBOTLASER1 laser_type start_angle fov angular_resolution max_range accuracy remission_mode
        n r1 … rn 0 laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
        forward_safety_dist side_safety_dist turn_axis ipc_timestamp hostname logger_timestamp

* ``x y theta`` of ``FLASER`` (and ``laser_x …`` of ``ROBOTLASER1``) is ``Scan.pose_odom_laser``,
  ``odom_x …`` (``robot_x …``) is ``Scan.pose_odom_base``; a scan with only one of them writes it
  in both places.  ``ODOM`` is written before each scan (same time stamp) from
  ``pose_odom_base``, with ``tv``/``rv`` the forward and yaw velocities from the previous
  odometry pose (0 for the first); ``accel`` is 0.
* Time stamps: ``ipc_timestamp`` and ``logger_timestamp`` are both the scan's time stamp,
  written with 6 decimals (µs, as the public logs); poses with 6 decimals (µm, µrad); ranges
  with ``range_decimals``.
* ``FLASER`` carries no beam angles: a reader takes CARMEN's ``carmen_laser_guess_fov`` rule
  (first beam −90°; 180 beams → 1° steps, 360 → 0.5°, otherwise π/(n−1)) and a range limit of
  80 m.  ``message="auto"`` therefore writes ``FLASER`` only when the scans' bearings follow
  that rule and their ``max_range_m`` is 80 m, and ``ROBOTLASER1`` (which carries start angle,
  resolution and maximum range) otherwise.  A ``FLASER`` log of 180, 181, 360 or 361 beams
  also states that layout as CARMEN's logger does, in ``PARAM`` lines before its first
  message (``laser_front_laser_fov 180``, ``laser_front_laser_resolution`` 1 or 0.5,
  ``robot_front_laser_max 80``; the same bearings to the last bit).  ``laser_type``,
  ``accuracy``, ``remission_mode``, the safety distances and ``turn_axis`` are written 0,
  with no remissions.
* A reading of ``+inf`` (no return) is written as the scan's ``max_range_m``; NaN or negative
  readings, ragged beam counts under ``FLASER``, bearings that are not evenly spaced, or a scan
  without any pose are errors naming the scan.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TextIO

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, InputError
from slam.types import Scan

__all__ = ["FLASER_MAX_RANGE_M", "CarmenWriteStats", "flaser_bearings", "write_carmen"]

FloatArray = NDArray[np.float64]

#: Range limit a CARMEN reader assumes for ``FLASER`` lines (no manifest): see module docstring.
FLASER_MAX_RANGE_M = 80.0

_BEARING_TOL_RAD = 1e-9
_HEADER = (
    "CARMEN Logfile",
    "file format is one message per line",
    "message_name [message contents] ipc_timestamp ipc_hostname logger_timestamp",
    "ODOM x y theta tv rv accel",
    "FLASER num_readings [range_readings] x y theta odom_x odom_y odom_theta",
    "ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range "
    "accuracy remission_mode num_readings [range_readings] num_remissions [remissions] "
    "laser_pose_x laser_pose_y laser_pose_theta robot_pose_x robot_pose_y robot_pose_theta "
    "laser_tv laser_rv forward_safety_dist side_safty_dist turn_axis",
)


@dataclass(frozen=True)
class CarmenWriteStats:
    """What :func:`write_carmen` wrote.

    Attributes
    ----------
    scans : int
        Laser lines written.
    odometry : int
        ``ODOM`` lines written.
    message : str
        ``"FLASER"`` or ``"ROBOTLASER1"``.
    """

    scans: int
    odometry: int
    message: str


def flaser_bearings(n_beams: int) -> FloatArray:
    """Bearings (rad) a CARMEN reader assigns to a ``FLASER`` line of ``n_beams`` readings."""
    if n_beams in (180, 360):
        step = math.pi / n_beams
    elif n_beams > 1:
        step = math.pi / (n_beams - 1)
    else:
        step = math.pi
    return -math.pi / 2.0 + step * np.arange(n_beams, dtype=np.float64)


def _flaser_params(n_beams: int, max_range_m: float) -> list[tuple[str, str]]:
    """The ``PARAM`` lines stating a ``FLASER`` layout of CARMEN's rule (module docstring)."""
    resolution = {180: "1", 181: "1", 360: "0.5", 361: "0.5"}.get(n_beams)
    if resolution is None or max_range_m != FLASER_MAX_RANGE_M:
        return []
    return [
        ("laser_front_laser_fov", "180"),
        ("laser_front_laser_resolution", resolution),
        ("robot_front_laser_max", f"{FLASER_MAX_RANGE_M:g}"),
    ]


def _is_flaser_compatible(scan: Scan) -> bool:
    if scan.max_range_m != FLASER_MAX_RANGE_M:
        return False
    expected = flaser_bearings(scan.n_beams)
    return bool(np.abs(np.asarray(scan.bearings) - expected).max() <= _BEARING_TOL_RAD)


def _where(scan: Scan) -> str:
    return scan.source or f"scan {scan.index}"


def _ranges(scan: Scan) -> FloatArray:
    r = np.asarray(scan.ranges, dtype=np.float64)
    if r.ndim != 1 or r.shape[0] < 1:
        raise InputError(f"{_where(scan)}: ranges must be a non-empty 1-D array")
    if np.isnan(r).any() or (r < 0).any():
        raise InputError(f"{_where(scan)}: NaN or negative range cannot be written")
    if np.isinf(r).any():
        if not math.isfinite(scan.max_range_m):
            raise InputError(f"{_where(scan)}: infinite range and no finite max_range_m")
        r = np.where(np.isinf(r), scan.max_range_m, r)
    return r


def _poses(scan: Scan) -> tuple[FloatArray, FloatArray]:
    base, laser = scan.pose_odom_base, scan.pose_odom_laser
    if base is None and laser is None:
        raise InputError(f"{_where(scan)}: a scan without an odometry pose cannot be written")
    base_a = np.asarray(base if base is not None else laser, dtype=np.float64)
    laser_a = np.asarray(laser if laser is not None else base, dtype=np.float64)
    if not (np.isfinite(base_a).all() and np.isfinite(laser_a).all()):
        raise InputError(f"{_where(scan)}: non-finite odometry pose")
    return base_a, laser_a


def _geometry(scan: Scan) -> tuple[float, float]:
    """``(start_angle, resolution)`` of evenly spaced bearings."""
    b = np.asarray(scan.bearings, dtype=np.float64)
    if b.shape != (scan.n_beams,):
        raise InputError(f"{_where(scan)}: {b.shape[0]} bearings for {scan.n_beams} ranges")
    if b.shape[0] == 1:
        return float(b[0]), 0.0
    step = (b[-1] - b[0]) / (b.shape[0] - 1)
    if not step > 0 or np.abs(np.diff(b) - step).max() > _BEARING_TOL_RAD:
        raise InputError(f"{_where(scan)}: bearings are not evenly spaced and increasing")
    return float(b[0]), float(step)


class _Velocity:
    """Forward and yaw velocity from consecutive odometry poses (0 for the first)."""

    def __init__(self) -> None:
        self.previous: tuple[float, FloatArray] | None = None

    def __call__(self, timestamp: float, pose: FloatArray) -> tuple[float, float]:
        tv = rv = 0.0
        if self.previous is not None:
            t0, p0 = self.previous
            dt = timestamp - t0
            if dt > 0:
                c, s = math.cos(p0[2]), math.sin(p0[2])
                forward = c * (pose[0] - p0[0]) + s * (pose[1] - p0[1])
                dtheta = math.remainder(float(pose[2] - p0[2]), 2.0 * math.pi)
                tv, rv = forward / dt, dtheta / dt
        self.previous = (timestamp, pose)
        return tv, rv


def write_carmen(
    path: str | Path,
    scans: Iterable[Scan],
    *,
    message: Literal["auto", "FLASER", "ROBOTLASER1"] = "auto",
    range_decimals: int = 4,
    odometry: bool = True,
    hostname: str = "lineslam",
    header: Sequence[str] = (),
) -> CarmenWriteStats:
    """Write ``scans`` (in the given order) as a CARMEN log; see the module docstring.

    Parameters
    ----------
    path
        Output file (its folder must exist).
    scans
        The scans; each needs ``pose_odom_base`` and/or ``pose_odom_laser``.  Streamed: the
        iterable is consumed once, one line at a time.
    message
        ``"FLASER"``, ``"ROBOTLASER1"``, or ``"auto"`` (decided on the first scan).
    range_decimals
        Digits after the point of the ranges (1..9).
    odometry
        Also write an ``ODOM`` line before each scan.
    hostname
        The hostname field (no spaces).
    header
        Extra ``#`` comment lines written after CARMEN's own header.

    Returns
    -------
    CarmenWriteStats
    """
    if message not in ("auto", "FLASER", "ROBOTLASER1"):
        raise ConfigError(f"message must be 'auto', 'FLASER' or 'ROBOTLASER1', got {message!r}")
    if not (isinstance(range_decimals, int) and 1 <= range_decimals <= 9):
        raise ConfigError(f"range_decimals must be an integer in 1..9, got {range_decimals!r}")
    if not hostname or any(ch.isspace() for ch in hostname):
        raise ConfigError(f"hostname must be one word, got {hostname!r}")
    n_scans = n_odom = 0
    chosen: str | None = None if message == "auto" else message
    velocity = _Velocity()
    with Path(path).open("w", encoding="utf-8") as out:
        for line in (*_HEADER, *header):
            out.write(f"# {line}\n")
        flaser_n: int | None = None
        fmt_cache: dict[int, str] = {}
        for scan in scans:
            ranges = _ranges(scan)
            base, laser = _poses(scan)
            if chosen is None:
                chosen = "FLASER" if _is_flaser_compatible(scan) else "ROBOTLASER1"
            if not math.isfinite(scan.timestamp):
                raise InputError(f"{_where(scan)}: non-finite time stamp")
            stamp = f"{scan.timestamp:.6f}"
            if n_scans == 0 and chosen == "FLASER":
                for name, value in _flaser_params(ranges.shape[0], scan.max_range_m):
                    out.write(f"PARAM {name} {value} {stamp} {hostname} {stamp}\n")
            tv, rv = velocity(scan.timestamp, base)
            if odometry:
                out.write(
                    f"ODOM {base[0]:.6f} {base[1]:.6f} {base[2]:.6f} {tv:.6f} {rv:.6f} 0 "
                    f"{stamp} {hostname} {stamp}\n"
                )
                n_odom += 1
            n = ranges.shape[0]
            if n not in fmt_cache:
                fmt_cache[n] = " ".join([f"%.{range_decimals}f"] * n)
            readings = fmt_cache[n] % tuple(ranges.tolist())
            if chosen == "FLASER":
                if flaser_n is None:
                    flaser_n = n
                elif n != flaser_n:
                    raise InputError(
                        f"{_where(scan)}: {n} beams after {flaser_n}; FLASER logs need one "
                        "beam count (write ROBOTLASER1)"
                    )
                _write_flaser(out, n, readings, laser, base, stamp, hostname)
            else:
                _write_robotlaser(out, scan, n, readings, laser, base, tv, rv, stamp, hostname)
            n_scans += 1
    return CarmenWriteStats(n_scans, n_odom, chosen or "FLASER")


def _pose_text(pose: FloatArray) -> str:
    return f"{pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f}"


def _write_flaser(
    out: TextIO,
    n: int,
    readings: str,
    laser: FloatArray,
    base: FloatArray,
    stamp: str,
    hostname: str,
) -> None:
    out.write(
        f"FLASER {n} {readings} {_pose_text(laser)} {_pose_text(base)} {stamp} {hostname} {stamp}\n"
    )


def _write_robotlaser(
    out: TextIO,
    scan: Scan,
    n: int,
    readings: str,
    laser: FloatArray,
    base: FloatArray,
    tv: float,
    rv: float,
    stamp: str,
    hostname: str,
) -> None:
    start, step = _geometry(scan)
    if not math.isfinite(scan.max_range_m):
        raise InputError(f"{_where(scan)}: ROBOTLASER1 needs a finite max_range_m")
    fov = step * (n - 1)
    max_range = float(scan.max_range_m)
    out.write(
        f"ROBOTLASER1 0 {start!r} {fov!r} {step!r} {max_range!r} 0 0 {n} {readings} 0 "
        f"{_pose_text(laser)} {_pose_text(base)} {tv:.6f} {rv:.6f} 0 0 0 "
        f"{stamp} {hostname} {stamp}\n"
    )
