"""Simulated worlds: sets of wall segments with ids, and their ``world.json`` files.

A :class:`World` is an immutable set of line segments in the world frame (metres), each with an
integer id (reported per beam by the ray caster) and a label (``"wall"``, ``"door"``,
``"desk"``, ...), plus optionally the waypoints of a default robot path through it.

``world.json``::

    {"format": "lineslam-world", "version": 1, "name": "loop", "frame": "world",
     "description": "...",
     "segments": [{"id": 0, "label": "wall", "p1": [0.0, 0.0], "p2": [30.0, 0.0]}, ...],
     "waypoints": [[1.0, 1.0], [29.0, 1.0], ...]}

``waypoints`` may be missing (then a trajectory must be given another way).  Reading checks
everything and raises :class:`~slam.errors.InputError` naming the file: not JSON, missing keys,
non-finite or zero-length segments, coordinates beyond ±1e6 m, duplicate ids.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError

__all__ = ["World", "WorldBuilder", "read_world", "write_world"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

WORLD_FORMAT = "lineslam-world"
WORLD_VERSION = 1
#: Largest coordinate magnitude accepted (m).
MAX_COORDINATE_M = 1e6


@dataclass(frozen=True, eq=False)
class World:
    """Wall segments in the world frame.

    Attributes
    ----------
    segments : ndarray, shape (n, 2, 2)
        ``segments[k] = [[x1, y1], [x2, y2]]`` (m).
    ids : ndarray of int, shape (n,)
        Unique, non-negative segment ids (the ray caster reports them; ``-1`` means no hit).
    labels : tuple of str, length n
        What each segment is (``"wall"``, ``"door"``, ``"desk"``, ``"pillar"``, ...).
    name : str
        Short name (``"hallway"``, ``"lab"``, ``"loop"``, or a file's stem).
    waypoints : ndarray, shape (k, 2), or None
        Default robot path (a polyline, corners are rounded by the trajectory generator).
    description : str
        One line for humans.
    """

    segments: FloatArray
    ids: IntArray
    labels: tuple[str, ...]
    name: str = "world"
    waypoints: FloatArray | None = None
    description: str = ""

    def __post_init__(self) -> None:
        seg = np.array(self.segments, dtype=np.float64)  # a private, read-only copy
        if seg.ndim != 3 or seg.shape[1:] != (2, 2):
            raise InputError(f"world segments must have shape (n, 2, 2), got {seg.shape}")
        n = seg.shape[0]
        if n == 0:
            raise InputError("a world needs at least one segment")
        if not np.isfinite(seg).all():
            raise InputError("world segments contain NaN or infinite coordinates")
        if np.abs(seg).max() > MAX_COORDINATE_M:
            raise InputError(f"world coordinates beyond ±{MAX_COORDINATE_M:g} m")
        lengths = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
        if (lengths <= 1e-9).any():
            k = int(np.flatnonzero(lengths <= 1e-9)[0])
            raise InputError(f"world segment {k} has zero length")
        ids = np.array(self.ids)
        if ids.shape != (n,) or not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"world ids must be {n} integers, got shape {ids.shape}")
        ids = ids.astype(np.int64)
        if (ids < 0).any():
            raise InputError("world segment ids must be >= 0 (-1 means 'no hit')")
        if np.unique(ids).shape[0] != n:
            raise InputError("world segment ids must be unique")
        if len(self.labels) != n:
            raise InputError(f"world needs {n} labels, got {len(self.labels)}")
        wp = self.waypoints
        if wp is not None:
            wp = np.array(wp, dtype=np.float64)
            if wp.ndim != 2 or wp.shape[1] != 2 or wp.shape[0] < 2:
                raise InputError(f"waypoints must have shape (k >= 2, 2), got {wp.shape}")
            if not np.isfinite(wp).all() or np.abs(wp).max() > MAX_COORDINATE_M:
                raise InputError(f"waypoints must be finite and within ±{MAX_COORDINATE_M:g} m")
            wp.flags.writeable = False
        seg.flags.writeable = False
        ids.flags.writeable = False
        object.__setattr__(self, "segments", seg)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "labels", tuple(str(s) for s in self.labels))
        object.__setattr__(self, "waypoints", wp)

    def __len__(self) -> int:
        return int(self.segments.shape[0])

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of all segments (m)."""
        pts = self.segments.reshape(-1, 2)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def segment_by_id(self, segment_id: int) -> FloatArray:
        """The ``(2, 2)`` end points of the segment with id ``segment_id``."""
        hits = np.flatnonzero(self.ids == segment_id)
        if hits.shape[0] == 0:
            raise KeyError(segment_id)
        return self.segments[int(hits[0])]

    def to_dict(self) -> dict[str, Any]:
        """The ``world.json`` document as a ``dict``."""
        out: dict[str, Any] = {
            "format": WORLD_FORMAT,
            "version": WORLD_VERSION,
            "name": self.name,
            "frame": "world",
            "description": self.description,
            "segments": [
                {
                    "id": int(i),
                    "label": label,
                    "p1": [float(s[0, 0]), float(s[0, 1])],
                    "p2": [float(s[1, 0]), float(s[1, 1])],
                }
                for i, label, s in zip(self.ids, self.labels, self.segments, strict=True)
            ],
        }
        if self.waypoints is not None:
            out["waypoints"] = [[float(x), float(y)] for x, y in self.waypoints]
        return out

    @classmethod
    def from_dict(cls, data: Any, source: str = "world") -> World:
        """Build a world from a ``world.json`` document; errors name ``source``."""
        if not isinstance(data, dict):
            raise InputError("not a world document (expected a JSON object)", source)
        fmt = data.get("format", WORLD_FORMAT)
        if fmt != WORLD_FORMAT:
            raise InputError(f"not a lineslam world (format {fmt!r})", source)
        raw = data.get("segments")
        if not isinstance(raw, list) or not raw:
            raise InputError("'segments' must be a non-empty list", source)
        segments = np.empty((len(raw), 2, 2))
        ids = np.empty(len(raw), dtype=np.int64)
        labels: list[str] = []
        for k, item in enumerate(raw):
            try:
                if not isinstance(item, dict):
                    raise TypeError("not an object")
                seg_id = item.get("id", k)
                if isinstance(seg_id, bool) or not isinstance(seg_id, int):
                    raise TypeError(f"id {seg_id!r} is not an integer")
                segments[k] = [_point(item["p1"]), _point(item["p2"])]
                ids[k] = seg_id
                labels.append(str(item.get("label", "wall")))
            except (KeyError, TypeError, ValueError) as exc:
                raise InputError(f"segment {k}: {exc}", source) from None
        waypoints = None
        if data.get("waypoints") is not None:
            try:
                waypoints = np.array([_point(p) for p in data["waypoints"]], dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise InputError(f"waypoints: {exc}", source) from None
        try:
            return cls(
                segments=segments,
                ids=ids,
                labels=tuple(labels),
                name=str(data.get("name", Path(source).stem)),
                waypoints=waypoints,
                description=str(data.get("description", "")),
            )
        except InputError as exc:
            raise InputError(exc.reason, source) from None


def _point(value: Any) -> tuple[float, float]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ValueError(f"a point must be [x, y], got {value!r}")
    x, y = (float(v) for v in value)
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"point {value!r} is not finite")
    return x, y


def write_world(world: World, path: str | Path) -> None:
    """Write ``world`` as ``world.json`` (see the module docstring)."""
    Path(path).write_text(json.dumps(world.to_dict(), indent=1) + "\n", encoding="utf-8")


def read_world(path: str | Path) -> World:
    """Read a ``world.json`` file written by :func:`write_world` (or by hand)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("world file not found", str(path)) from None
    except UnicodeDecodeError:
        raise InputError("not a text file (expected world JSON)", str(path)) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a world JSON file", str(path)) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON ({exc.msg})", str(path), exc.lineno) from None
    return World.from_dict(data, source=str(path))


@dataclass
class WorldBuilder:
    """Collects segments with consecutive ids; used to write the named worlds.

    Examples
    --------
    >>> b = WorldBuilder()
    >>> b.polyline([(0, 0), (4, 0), (4, 3)])
    >>> b.box(1.0, 1.0, 0.5, 0.5, label="box")
    >>> world = b.build("example")
    >>> len(world)
    6
    """

    segments: list[tuple[tuple[float, float], tuple[float, float]]] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)

    def segment(self, p1: ArrayLike, p2: ArrayLike, label: str = "wall") -> None:
        """Add one segment ``p1 → p2``."""
        a = np.asarray(p1, dtype=np.float64)
        b = np.asarray(p2, dtype=np.float64)
        self.segments.append(((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))))
        self.labels.append(label)

    def polyline(
        self, points: Sequence[Sequence[float]], label: str = "wall", closed: bool = False
    ) -> None:
        """Add the segments joining consecutive ``points`` (and last → first if ``closed``)."""
        pts = [tuple(p) for p in points]
        if closed:
            pts.append(pts[0])
        for a, b in itertools.pairwise(pts):
            self.segment(a, b, label)

    def box(self, x: float, y: float, width: float, height: float, label: str = "box") -> None:
        """Add an axis-aligned rectangle with lower-left corner ``(x, y)``."""
        self.polyline(
            [(x, y), (x + width, y), (x + width, y + height), (x, y + height)],
            label=label,
            closed=True,
        )

    def rotated_box(
        self, cx: float, cy: float, width: float, height: float, angle_rad: float, label: str
    ) -> None:
        """Add a rectangle centred on ``(cx, cy)`` rotated by ``angle_rad``."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        corners = [(-width / 2, -height / 2), (width / 2, -height / 2)]
        corners += [(width / 2, height / 2), (-width / 2, height / 2)]
        pts = [(cx + c * u - s * v, cy + s * u + c * v) for u, v in corners]
        self.polyline(pts, label=label, closed=True)

    def polygon(self, cx: float, cy: float, radius: float, n_sides: int, label: str) -> None:
        """Add a regular polygon (e.g. a round pillar) around ``(cx, cy)``."""
        angles = np.arange(n_sides) * 2.0 * math.pi / n_sides
        pts = [(cx + radius * math.cos(a), cy + radius * math.sin(a)) for a in angles]
        self.polyline(pts, label=label, closed=True)

    def build(
        self,
        name: str,
        waypoints: ArrayLike | None = None,
        description: str = "",
    ) -> World:
        """The :class:`World` of the segments added so far (ids ``0..n-1`` in order)."""
        return World(
            segments=np.array(self.segments, dtype=np.float64),
            ids=np.arange(len(self.segments), dtype=np.int64),
            labels=tuple(self.labels),
            name=name,
            waypoints=None if waypoints is None else np.asarray(waypoints, dtype=np.float64),
            description=description,
        )
