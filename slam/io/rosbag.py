"""ROS 1 and ROS 2 bags: ``sensor_msgs/LaserScan``, odometry (a topic or tf) and the mounting.

Main entry points::

    bag = RosbagLog(path, scan_topic=None, odom_topic=None, odometry="auto", base_frame=None)
    bag.scan_count            # from the bag's index, without reading the messages
    bag.mount()               # MountInfo (pose_base_laser from /tf_static) or None
    bag.scans()               # Iterator[Scan], odometry attached
    iter_rosbag_scans(path, *, scan_topic=None, odom_topic=None) -> Iterator[Scan]
    read_rosbag_odometry(path, *, topic=None) -> Trajectory
    is_rosbag(path) -> bool   # a ROS 1 .bag file or a ROS 2 bag folder

Needs the ``rosbags`` package (``pip install 'lineslam[ros]'``); nothing of ROS itself.  A ROS 1
``.bag`` file or a ROS 2 bag folder (sqlite3 or mcap) is read through
``rosbags.highlevel.AnyReader``.

Scans
-----
``timestamp`` = ``header.stamp`` (s); ``bearings`` = ``angle_min + i·angle_increment`` (the
geometry the message states); ``ranges`` as recorded (NaN and ±inf kept, as REP 117 uses
them; :meth:`Scan.valid_mask` excludes them); ``max_range_m`` = ``range_max``.  Scans come in
bag (receive-time) order.

Odometry
--------
``odometry="topic"``: a ``nav_msgs/Odometry`` topic (``odom_topic``, or the only one);
``"tf"``: the dynamic ``/tf`` transforms whose child is the base frame (the hop
``odom → base``); ``"auto"``: the topic if the bag has one, else tf, else none.  The base
odometry pose of a scan (``Scan.pose_odom_base``) is interpolated at its stamp (linear in
x, y and the unwrapped yaw); a scan up to :data:`MAX_ODOMETRY_GAP_S` outside the odometry's
span takes the nearest end's pose, a scan further out has none.  ``Scan.pose_odom_laser``
is ``None``: the laser's odometry is the base's composed with the mounting
(:class:`slam.inputs.InputPolicy`).

Mounting
--------
:meth:`RosbagLog.mount` composes the ``/tf_static`` transforms from the base frame to the
scan's ``header.frame_id`` (any number of hops) into ``pose_base_laser = (x, y, yaw)``.  The
base frame is ``base_frame`` if given, else the odometry's ``child_frame_id`` (or the tf
child), else the root of the laser's static tf tree.  Roll and pitch are dropped (a planar
scanner); a scanner mounted upside down (|roll| or |pitch| > 1°) is an error, as its bearings
would run the other way.

If a bag has several topics of a type, name the one to read (``scan_topic=``/``odom_topic=``);
the error lists them.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, InputError, LogFormatError
from slam.geometry import pose_compose
from slam.io.carmen import pose_beyond_bound
from slam.io.trajectory import Trajectory
from slam.types import Scan

__all__ = [
    "MAX_ODOMETRY_GAP_S",
    "MountInfo",
    "RosbagLog",
    "is_rosbag",
    "iter_rosbag_scans",
    "read_rosbag_odometry",
]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"

MAX_ODOMETRY_GAP_S = 1.0
"""A scan this close (s) outside the odometry's time span takes the nearest end's pose."""

_ROS1_MAGIC = b"#ROSBAG V2.0"


def is_rosbag(path: str | Path) -> bool:
    """True for a ROS 1 bag file (by its magic line) or a ROS 2 bag folder (``metadata.yaml``)."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    if p.is_file():
        with p.open("rb") as handle:
            return handle.read(len(_ROS1_MAGIC)) == _ROS1_MAGIC
    return False


@dataclass(frozen=True)
class MountInfo:
    """The laser's pose on the robot base, as the bag's static tf states it.

    Attributes
    ----------
    pose_base_laser : tuple of 3 floats
        ``(x m, y m, yaw rad)`` of the scan frame in the base frame.
    base_frame, laser_frame : str
        The two frames.
    hops : int
        Static transforms composed.
    """

    pose_base_laser: tuple[float, float, float]
    base_frame: str
    laser_frame: str
    hops: int


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


def _roll_pitch(q: Any) -> tuple[float, float]:
    roll = math.atan2(2.0 * (q.w * q.x + q.y * q.z), 1.0 - 2.0 * (q.x * q.x + q.y * q.y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (q.w * q.y - q.z * q.x))))
    return roll, pitch


def _read_odometry(reader: Any, conns: list[Any], path: str) -> tuple[Trajectory | None, str]:
    """Poses of the odometry topic and its ``child_frame_id`` (``""`` if none)."""
    if not conns:
        return None, ""
    stamps: list[float] = []
    poses: list[tuple[float, float, float]] = []
    child = ""
    for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
        try:
            msg = reader.deserialize(raw, conn.msgtype)
            pose = msg.pose.pose
            stamps.append(_stamp(msg.header))
            poses.append((float(pose.position.x), float(pose.position.y), _yaw(pose.orientation)))
            child = child or str(msg.child_frame_id)
        except Exception as exc:
            raise LogFormatError(
                f"{conn.topic}: odometry message {k} cannot be read ({exc})", path
            ) from None
        _check_pose(poses[-1], f"{conn.topic}: odometry message {k}", path)
    if not stamps:
        return None, child
    try:
        return Trajectory(np.asarray(stamps), np.asarray(poses)), child
    except InputError as exc:
        raise LogFormatError(f"odometry: {exc.reason}", path) from None


def _check_pose(pose: tuple[float, float, float], what: str, where: str) -> None:
    """A pose beyond the readers' bound (:func:`slam.io.carmen.pose_beyond_bound`) is corrupt."""
    reason = pose_beyond_bound(pose)
    if reason is not None:
        raise LogFormatError(f"{what}: pose {reason}", where)


def read_rosbag_odometry(path: str | Path, *, topic: str | None = None) -> Trajectory:
    """All ``nav_msgs/Odometry`` poses ``(x, y, yaw)`` of a bag, at their header stamps."""
    reader = _open(path)
    try:
        odometry, _ = _read_odometry(reader, _pick(reader, ODOMETRY, topic, str(path)), str(path))
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
        if stamp < t[0] - MAX_ODOMETRY_GAP_S or stamp > t[-1] + MAX_ODOMETRY_GAP_S:
            return None
        theta = float(np.interp(stamp, t, yaw))
        theta = float(np.arctan2(np.sin(theta), np.cos(theta)))
        return np.array([np.interp(stamp, t, xy[:, 0]), np.interp(stamp, t, xy[:, 1]), theta])

    return pose_at


def _transforms(reader: Any, conns: list[Any]) -> Iterator[tuple[float, Any]]:
    for conn, _, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        for tr in msg.transforms:
            yield _stamp(tr.header), tr


def _planar(tr: Any, where: str) -> tuple[float, float, float]:
    q = tr.transform.rotation
    roll, pitch = _roll_pitch(q)
    if abs(roll) > math.radians(1.0) or abs(pitch) > math.radians(1.0):
        raise InputError(
            f"tf {tr.header.frame_id} -> {tr.child_frame_id} is tilted (roll "
            f"{math.degrees(roll):.1f}°, pitch {math.degrees(pitch):.1f}°): a planar scanner "
            "mounted level is needed",
            where,
        )
    t = tr.transform.translation
    return float(t.x), float(t.y), _yaw(q)


class RosbagLog:
    """A bag to read scans, odometry and the laser mounting from (module docstring).

    Parameters
    ----------
    path
        A ROS 1 ``.bag`` file or a ROS 2 bag folder.
    scan_topic, odom_topic
        Topics to read; ``None``: the only one of its type.
    odometry : {"auto", "topic", "tf"}
        Where the base's odometry comes from.
    base_frame
        The robot's base frame (tf child of the odometry); ``None``: as the module docstring.

    Raises
    ------
    InputError, LogFormatError
        No such bag, not a bag, no scan topic, an ambiguous or missing topic.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        scan_topic: str | None = None,
        odom_topic: str | None = None,
        odometry: Literal["auto", "topic", "tf"] = "auto",
        base_frame: str | None = None,
    ) -> None:
        if odometry not in ("auto", "topic", "tf"):
            raise ConfigError(f"odometry must be auto, topic or tf, got {odometry!r}")
        self.path = Path(path)
        self.where = str(path)
        self.odometry_mode = odometry
        self._base_frame = base_frame
        reader = _open(path)
        try:
            self._scan_conns = _pick(reader, LASER_SCAN, scan_topic, self.where)
            if not self._scan_conns:
                raise InputError("no sensor_msgs/LaserScan messages in the bag", self.where)
            odom_conns = [c for c in reader.connections if c.msgtype == ODOMETRY]
            if odometry == "tf" and odom_topic is None:
                odom_conns = []
            else:
                odom_conns = _pick(reader, ODOMETRY, odom_topic, self.where)
            if odometry == "topic" and not odom_conns:
                raise InputError(
                    "no nav_msgs/Odometry topic in the bag (--odometry tf?)", self.where
                )
            self.scan_topic = str(self._scan_conns[0].topic)
            self.odom_topic = str(odom_conns[0].topic) if odom_conns else None
            self._tf_topics = sorted({str(c.topic) for c in reader.connections if c.msgtype == TF})
            self.scan_count = int(sum(c.msgcount for c in self._scan_conns))
            self._laser_frame = self._first_scan_frame(reader)
        finally:
            reader.close()
        self._odometry: Trajectory | None = None
        self._odometry_source = ""
        self._odometry_child = ""
        self._loaded = False

    @staticmethod
    def _conns(reader: Any, topics: list[str], msgtype: str) -> list[Any]:
        """The connections of ``reader`` (each reader has its own) on ``topics``."""
        return [c for c in reader.connections if c.topic in topics and c.msgtype == msgtype]

    def _first_scan_frame(self, reader: Any) -> str:
        conns = self._conns(reader, [self.scan_topic], LASER_SCAN)
        for conn, _, raw in reader.messages(connections=conns):
            return str(reader.deserialize(raw, conn.msgtype).header.frame_id)
        return ""

    @property
    def laser_frame(self) -> str:
        """``header.frame_id`` of the first scan."""
        return self._laser_frame

    def _static_parents(self) -> dict[str, tuple[str, Any]]:
        """``child -> (parent, transform)`` of the bag's ``/tf_static`` topics."""
        parents: dict[str, tuple[str, Any]] = {}
        static = [t for t in self._tf_topics if t.endswith("tf_static")]
        if not static:
            return parents
        reader = _open(self.path)
        try:
            for _, tr in _transforms(reader, self._conns(reader, static, TF)):
                parents[str(tr.child_frame_id).lstrip("/")] = (
                    str(tr.header.frame_id).lstrip("/"),
                    tr,
                )
        finally:
            reader.close()
        return parents

    def _load_odometry(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        reader = _open(self.path)
        try:
            if self.odom_topic is not None and self.odometry_mode in ("auto", "topic"):
                conns = self._conns(reader, [self.odom_topic], ODOMETRY)
                self._odometry, self._odometry_child = _read_odometry(reader, conns, self.where)
                self._odometry_source = f"topic {self.odom_topic}"
                if self._odometry is not None:
                    return
            if self.odometry_mode in ("auto", "tf"):
                self._odometry = self._tf_odometry(reader)
        finally:
            reader.close()

    def _tf_odometry(self, reader: Any) -> Trajectory | None:
        dynamic = [t for t in self._tf_topics if not t.endswith("tf_static")]
        base = self._base_frame or self._static_root()
        if not dynamic or not base:
            return None
        stamps: list[float] = []
        poses: list[tuple[float, float, float]] = []
        parent = ""
        for stamp, tr in _transforms(reader, self._conns(reader, dynamic, TF)):
            if str(tr.child_frame_id).lstrip("/") != base:
                continue
            parent = parent or str(tr.header.frame_id).lstrip("/")
            stamps.append(stamp)
            poses.append(_planar(tr, self.where))
            _check_pose(poses[-1], f"/tf {base} at {stamp:.6f} s", self.where)
        if not stamps:
            if self.odometry_mode == "tf":
                raise InputError(f"no /tf transform to the base frame {base!r}", self.where)
            return None
        self._odometry_source = f"tf {parent} -> {base}"
        self._odometry_child = base
        return Trajectory(np.asarray(stamps), np.asarray(poses))

    def _static_root(self) -> str:
        """The root of the laser frame's static tf chain (``""`` if it has none)."""
        parents = self._static_parents()
        frame, seen = self._laser_frame.lstrip("/"), set()
        while frame in parents and frame not in seen:
            seen.add(frame)
            frame = parents[frame][0]
        return frame if seen else ""

    @property
    def odometry(self) -> Trajectory | None:
        """The base's odometry (topic or tf), or ``None`` if the bag has none."""
        self._load_odometry()
        return self._odometry

    @property
    def odometry_source(self) -> str:
        """Where the odometry came from (``"topic /odom"``, ``"tf odom -> base_link"``, ``""``)."""
        self._load_odometry()
        return self._odometry_source

    @property
    def base_frame(self) -> str:
        """The base frame: stated, else the odometry's child, else the static tree's root."""
        if self._base_frame:
            return self._base_frame
        self._load_odometry()
        return self._odometry_child.lstrip("/") or self._static_root()

    def mount(self) -> MountInfo | None:
        """``pose_base_laser`` from ``/tf_static`` (module docstring), or ``None`` if not there."""
        laser = self._laser_frame.lstrip("/")
        base = self.base_frame
        if not laser or not base:
            return None
        if laser == base:
            return MountInfo((0.0, 0.0, 0.0), base, laser, 0)
        parents = self._static_parents()
        chain: list[Any] = []
        frame = laser
        while frame != base:
            if frame not in parents or len(chain) > len(parents):
                return None
            frame, tr = parents[frame]
            chain.append(tr)
        pose = np.zeros(3)
        for tr in reversed(chain):
            pose = pose_compose(pose, np.asarray(_planar(tr, self.where)))
        x, y, yaw = (float(v) for v in pose)
        return MountInfo((x, y, yaw), base, laser, len(chain))

    def scans(self) -> Iterator[Scan]:
        """The scans in bag order, with the base odometry attached (module docstring)."""
        pose_at = _interpolator(self.odometry)
        reader = _open(self.path)
        where = self.where
        try:
            conns = self._conns(reader, [self.scan_topic], LASER_SCAN)
            for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
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
                    raise LogFormatError(
                        f"{conn.topic}: scan {k} has angle_increment {step}", where
                    )
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


def iter_rosbag_scans(
    path: str | Path, *, scan_topic: str | None = None, odom_topic: str | None = None
) -> Iterator[Scan]:
    """Yield the ``LaserScan`` messages of a bag as :class:`~slam.types.Scan` (module docstring).

    Odometry as :class:`RosbagLog` with ``odometry="auto"`` (the topic, else tf).
    """
    yield from RosbagLog(path, scan_topic=scan_topic, odom_topic=odom_topic).scans()
