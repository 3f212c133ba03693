"""TUM trajectories: ``timestamp x y z qx qy qz qw``, one pose per line.

Main entry points (stable, used across the project)::

    write_tum(path, timestamps, poses, *, decimals=6, header=None) -> None
    read_tum(path) -> Trajectory            # .timestamps (n,), .poses (n, 3) = (x, y, yaw)
    read_ground_truth(path) -> Trajectory   # read_tum, one pose per time stamp

Planar poses ``(x, y, θ)`` are written with ``z = 0`` and the yaw quaternion
``(0, 0, sin θ/2, cos θ/2)``; time stamps with ``decimals`` (≥ 6) digits after the point, so a
CARMEN ``ipc_timestamp`` (µs) is written exactly as in the log.  This is the format of evo and
of the TUM RGB-D benchmark tools.

Reading accepts ``#`` comment lines, ignores ``z`` and takes the yaw of the quaternion
(``atan2(2(qw qz + qx qy), 1 − 2(qy² + qz²))``); a quaternion whose norm is not 1 (±1e-3), or a
pose that is tilted out of the plane by more than 1e-3 rad, is an error naming the line.
:func:`read_ground_truth` also refuses a time stamp given two different poses (naming both
lines): which of them a relation or a scan is scored against would be arbitrary.  A run's own
trajectory may repeat a time stamp (a log that repeats one) and is read with :func:`read_tum`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from linefit.line import wrap_angle
from slam.errors import InputError, LogFormatError
from slam.io._table import read_numeric_table
from slam.io.trajectory import Trajectory

__all__ = ["read_ground_truth", "read_tum", "write_tum"]

_QUATERNION_TOL = 1e-3
_TILT_TOL_RAD = 1e-3


def write_tum(
    path: str | Path,
    timestamps: ArrayLike,
    poses: ArrayLike,
    *,
    decimals: int = 6,
    header: str | None = None,
) -> None:
    """Write planar poses as a TUM trajectory.

    Parameters
    ----------
    path
        Output file (parent folders must exist).
    timestamps : array_like, shape (n,)
        Time stamps (s), e.g. each scan's ``ipc_timestamp``.
    poses : array_like, shape (n, 3)
        ``(x, y, θ)`` (m, m, rad).
    decimals
        Digits after the point of the time stamps (at least 6: µs).
    header
        Optional comment written as ``# ...`` lines before the poses.
    """
    if decimals < 6:
        raise InputError(f"decimals must be >= 6 (µs time stamps), got {decimals}")
    trajectory = Trajectory.from_arrays(timestamps, poses)
    theta = np.asarray(wrap_angle(trajectory.poses[:, 2]))
    n = len(trajectory)
    table = np.column_stack(
        [
            trajectory.timestamps,
            trajectory.poses[:, 0],
            trajectory.poses[:, 1],
            np.zeros(n),
            np.zeros(n),
            np.zeros(n),
            np.sin(theta / 2.0),
            np.cos(theta / 2.0),
        ]
    )
    fmt = [f"%.{decimals}f"] + ["%.9f"] * 7
    comments = "" if header is None else "# " + "\n# ".join(header.splitlines()) + "\n"
    with Path(path).open("w", encoding="utf-8") as handle:
        handle.write(comments)
        np.savetxt(handle, table, fmt=fmt, delimiter=" ")


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM trajectory as planar poses (see the module docstring for the checks)."""
    return _read_tum(path)[0]


def read_ground_truth(path: str | Path) -> Trajectory:
    """:func:`read_tum`, and a time stamp given twice must carry the same pose.

    Raises
    ------
    LogFormatError
        As :func:`read_tum`; or a time stamp on two lines with different poses (both named).
    """
    trajectory, lines = _read_tum(path)
    t = trajectory.timestamps
    order = np.argsort(t, kind="stable")
    repeated = np.flatnonzero(np.diff(t[order]) == 0.0)
    for k in repeated:
        i, j = int(order[k]), int(order[k + 1])
        d = trajectory.poses[j] - trajectory.poses[i]
        d[2] = float(wrap_angle(d[2]))
        if np.any(np.abs(d) > 1e-9):
            raise LogFormatError(
                f"time stamp {float(t[i])!r} is given two poses, here and at line {int(lines[i])}",
                str(path),
                int(lines[j]),
            )
    return trajectory


def _read_tum(path: str | Path) -> tuple[Trajectory, np.ndarray]:
    values, lines = read_numeric_table(path, 8, "TUM pose (timestamp x y z qx qy qz qw)")
    qx, qy, qz, qw = values[:, 4], values[:, 5], values[:, 6], values[:, 7]
    norm = np.sqrt(qx**2 + qy**2 + qz**2 + qw**2)
    bad = np.abs(norm - 1.0) > _QUATERNION_TOL
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise LogFormatError(f"quaternion norm {norm[i]:.6f} is not 1", str(path), int(lines[i]))
    qx, qy, qz, qw = (q / norm for q in (qx, qy, qz, qw))
    # Tilt of the body z axis: its z component is 1 - 2(qx² + qy²) = cos(tilt).
    cos_tilt = np.clip(1.0 - 2.0 * (qx**2 + qy**2), -1.0, 1.0)
    tilted = np.arccos(cos_tilt) > _TILT_TOL_RAD
    if tilted.any():
        i = int(np.flatnonzero(tilted)[0])
        raise LogFormatError("pose is not planar (roll/pitch > 1e-3 rad)", str(path), int(lines[i]))
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy**2 + qz**2))
    poses = np.column_stack([values[:, 1], values[:, 2], yaw])
    return Trajectory(values[:, 0].copy(), poses), lines
