"""ROS 1 and ROS 2 bags: ``sensor_msgs/LaserScan`` and ``nav_msgs/Odometry`` (optional extra).

Main entry points::

    iter_rosbag_scans(path, *, scan_topic=None, odom_topic=None) -> Iterator[Scan]
    read_rosbag_odometry(path, *, topic=None) -> Trajectory

Needs the ``rosbags`` package (``pip install 'lineslam[ros]'``); nothing of ROS itself.  A ROS 1
``.bag`` file or a ROS 2 bag folder (sqlite3 or mcap) is read through
``rosbags.highlevel.AnyReader``.

Scans
-----
``timestamp`` = ``header.stamp`` (s); ``bearings`` = ``angle_min + i·angle_increment``;
``ranges`` as recorded (NaN and ±inf kept, as REP 117 uses them; :meth:`Scan.valid_mask`
excludes them); ``max_range_m`` = ``range_max``.  ``pose_odom_base`` is the odometry pose
interpolated at the scan's stamp (linear in x, y and the unwrapped yaw) when an odometry topic
exists and the stamp lies within its span, else ``None``.  The laser's mounting (tf) is not
read: ``pose_odom_laser`` is ``None``.  Scans come in bag (receive-time) order.

If a bag has several topics of a type, name the one to read (``scan_topic=``/``odom_topic=``);
the error lists them.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import InputError, LogFormatError
from slam.io.trajectory import Trajectory
from slam.types import Scan

__all__ = ["iter_rosbag_scans", "read_rosbag_odometry"]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"


def _rosbags() -> Any:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - the test extra installs rosbags
        raise InputError(
            "reading ROS bags needs the optional 'rosbags' package: pip install 'lineslam[ros]'"
        ) from None
    return AnyReader, get_typestore(Stores.LATEST)


def _open(path: str | Path) -> Any:
    any_reader, typestore = _rosbags()
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or bag folder", str(path))
    try:
        reader = any_reader([path], default_typestore=typestore)
        reader.open()
    except Exception as exc:  # rosbags raises several reader-specific errors
        raise LogFormatError(
            f"not a readable ROS bag ({type(exc).__name__}: {exc})", str(path)
        ) from None
    return reader


def _pick(reader: Any, msgtype: str, topic: str | None, path: str) -> list[Any]:
    conns = [c for c in reader.connections if c.msgtype == msgtype]
    if topic is not None:
        chosen = [c for c in conns if c.topic == topic]
        if not chosen:
            have = sorted({c.topic for c in conns}) or ["none"]
            raise InputError(f"no {msgtype} topic {topic!r} (have: {', '.join(have)})", path)
        return chosen
    topics = sorted({c.topic for c in conns})
    if len(topics) > 1:
        raise InputError(f"several {msgtype} topics ({', '.join(topics)}): name one", path)
    return conns


def _stamp(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _yaw(q: Any) -> float:
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _read_odometry(reader: Any, conns: list[Any], path: str) -> Trajectory | None:
    if not conns:
        return None
    stamps: list[float] = []
    poses: list[tuple[float, float, float]] = []
    for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
        try:
            msg = reader.deserialize(raw, conn.msgtype)
            pose = msg.pose.pose
            stamps.append(_stamp(msg.header))
            poses.append((float(pose.position.x), float(pose.position.y), _yaw(pose.orientation)))
        except Exception as exc:
            raise LogFormatError(
                f"{conn.topic}: odometry message {k} cannot be read ({exc})", path
            ) from None
    if not stamps:
        return None
    try:
        return Trajectory(np.asarray(stamps), np.asarray(poses))
    except InputError as exc:
        raise LogFormatError(f"odometry: {exc.reason}", path) from None


def read_rosbag_odometry(path: str | Path, *, topic: str | None = None) -> Trajectory:
    """All ``nav_msgs/Odometry`` poses ``(x, y, yaw)`` of a bag, at their header stamps."""
    reader = _open(path)
    try:
        odometry = _read_odometry(reader, _pick(reader, ODOMETRY, topic, str(path)), str(path))
    finally:
        reader.close()
    if odometry is None:
        raise InputError("no nav_msgs/Odometry messages in the bag", str(path))
    return odometry


def _interpolator(odometry: Trajectory | None) -> Any:
    if odometry is None:
        return lambda t: None
    order = np.argsort(odometry.timestamps, kind="stable")
    t = odometry.timestamps[order]
    xy = odometry.poses[order, :2]
    yaw = np.unwrap(odometry.poses[order, 2])

    def pose_at(stamp: float) -> NDArray[np.float64] | None:
        if stamp < t[0] or stamp > t[-1]:
            return None
        theta = float(np.interp(stamp, t, yaw))
        theta = float(np.arctan2(np.sin(theta), np.cos(theta)))
        return np.array([np.interp(stamp, t, xy[:, 0]), np.interp(stamp, t, xy[:, 1]), theta])

    return pose_at


def iter_rosbag_scans(
    path: str | Path, *, scan_topic: str | None = None, odom_topic: str | None = None
) -> Iterator[Scan]:
    """Yield the ``LaserScan`` messages of a bag as :class:`~slam.types.Scan` (module docstring)."""
    where = str(path)
    reader = _open(path)
    try:
        scan_conns = _pick(reader, LASER_SCAN, scan_topic, where)
        if not scan_conns:
            raise InputError("no sensor_msgs/LaserScan messages in the bag", where)
        odometry = _read_odometry(reader, _pick(reader, ODOMETRY, odom_topic, where), where)
        pose_at = _interpolator(odometry)
        for k, (conn, _, raw) in enumerate(reader.messages(connections=scan_conns)):
            try:
                msg = reader.deserialize(raw, conn.msgtype)
                ranges = np.asarray(msg.ranges, dtype=np.float64)
                n = ranges.shape[0]
                first, step = float(msg.angle_min), float(msg.angle_increment)
                stamp = _stamp(msg.header)
                max_range = float(msg.range_max)
            except Exception as exc:
                raise LogFormatError(
                    f"{conn.topic}: scan message {k} cannot be read ({exc})", where
                ) from None
            if not (np.isfinite(first) and np.isfinite(step) and step != 0.0):
                raise LogFormatError(f"{conn.topic}: scan {k} has angle_increment {step}", where)
            if not max_range > 0.0:
                max_range = float("inf")
            yield Scan(
                index=k,
                timestamp=stamp,
                ranges=ranges,
                bearings=first + step * np.arange(n, dtype=np.float64),
                max_range_m=max_range,
                pose_odom_base=pose_at(stamp),
                pose_odom_laser=None,
                source=f"{where}:{conn.topic}#{k}",
            )
    finally:
        reader.close()
