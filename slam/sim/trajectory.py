"""Timed robot poses from a waypoint polyline: straights, rounded corners, a fixed scan rate.

The path is made of three kinds of pieces, each with an exact closed-form pose:

* **straight** legs between corners, driven at the cruise speed ``v``;
* **arcs** of radius ``R`` replacing each corner (``R`` = the configured turn radius, reduced
  where the legs are too short to hold the tangent points), driven at ``min(v, ω_max·R)``;
* **turns on the spot** where no arc fits (``R`` would be below 1 mm), at ``ω_max``.

Scans are taken at the fixed period ``scan_spacing_m / speed_m_s`` from the start of the path
to its end; poses are those of the robot base in the world frame, headings along the path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.line import wrap_angle
from slam.errors import InputError
from slam.sim.config import TrajectoryConfig

__all__ = ["SimTrajectory", "path_length", "trajectory_from_waypoints"]

FloatArray = NDArray[np.float64]

_MIN_ARC_RADIUS_M = 1e-3


@dataclass(frozen=True, eq=False)
class SimTrajectory:
    """True poses of the robot base at the scan times.

    Attributes
    ----------
    timestamps : ndarray, shape (n,)
        Scan times (s), strictly increasing, rounded to µs.
    poses_world_base : ndarray, shape (n, 3)
        ``(x, y, θ)`` of the base in the world (m, m, rad).
    """

    timestamps: FloatArray
    poses_world_base: FloatArray

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64)
        p = np.asarray(self.poses_world_base, dtype=np.float64)
        if t.ndim != 1 or t.shape[0] < 1:
            raise InputError(f"timestamps must be a non-empty 1-D array, got shape {t.shape}")
        if p.shape != (t.shape[0], 3):
            raise InputError(f"poses_world_base must have shape ({t.shape[0]}, 3), got {p.shape}")
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            raise InputError("trajectory contains NaN or infinite values")
        if (np.diff(t) <= 0.0).any():
            raise InputError("trajectory timestamps must be strictly increasing")
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "poses_world_base", p)

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])


@dataclass(frozen=True)
class _Piece:
    kind: str  # "line", "arc" or "turn"
    x: float
    y: float
    heading: float
    length: float  # path length (m); 0 for turns
    angle: float  # signed heading change (rad); 0 for lines
    radius: float  # arc radius (m)
    duration: float  # s


def _pieces(waypoints: FloatArray, config: TrajectoryConfig) -> list[_Piece]:
    pts = waypoints
    legs = np.diff(pts, axis=0)
    lengths = np.linalg.norm(legs, axis=1)
    if (lengths <= 1e-9).any():
        k = int(np.flatnonzero(lengths <= 1e-9)[0])
        raise InputError(f"waypoints {k} and {k + 1} coincide")
    dirs = legs / lengths[:, None]
    headings = np.arctan2(dirs[:, 1], dirs[:, 0])
    n_legs = legs.shape[0]
    v, w_max = config.speed_m_s, config.max_turn_rate_rad_s
    # Tangent length used at each interior corner, and the corner's arc (or spot turn).
    cut = np.zeros(n_legs + 1)
    corners: list[tuple[float, float]] = [(0.0, 0.0)] * (n_legs + 1)  # (signed angle, radius)
    for i in range(1, n_legs):
        turn = float(wrap_angle(headings[i] - headings[i - 1]))
        if abs(turn) < 1e-12:
            continue
        if abs(turn) > math.pi - 1e-6:
            raise InputError(f"the path reverses at waypoint {i}; add a waypoint to turn around")
        half_tan = math.tan(abs(turn) / 2.0)
        room_in = lengths[i - 1] * (1.0 if i == 1 else 0.5)
        room_out = lengths[i] * (1.0 if i == n_legs - 1 else 0.5)
        radius = min(config.turn_radius_m, min(room_in, room_out) / half_tan)
        if radius < _MIN_ARC_RADIUS_M:
            radius = 0.0
        cut[i] = radius * half_tan
        corners[i] = (turn, radius)
    pieces: list[_Piece] = []
    for i in range(n_legs):
        # Leg i runs from waypoint i to i + 1, shortened by the tangent lengths at both ends.
        heading = float(headings[i])
        x, y = (float(c) for c in pts[i] + dirs[i] * cut[i])
        length = float(lengths[i] - cut[i] - cut[i + 1])
        if length > 1e-12:
            pieces.append(_Piece("line", x, y, heading, length, 0.0, 0.0, length / v))
        turn, radius = corners[i + 1]
        if turn == 0.0:
            continue
        x, y = (float(c) for c in pts[i + 1] - dirs[i] * cut[i + 1])
        if radius == 0.0:
            pieces.append(_Piece("turn", x, y, heading, 0.0, turn, 0.0, abs(turn) / w_max))
        else:
            arc_len = abs(turn) * radius
            duration = arc_len / min(v, w_max * radius)
            pieces.append(_Piece("arc", x, y, heading, arc_len, turn, radius, duration))
    return pieces


def _pose_on_piece(piece: _Piece, fraction: FloatArray) -> FloatArray:
    """Poses at ``fraction ∈ [0, 1]`` of the way through ``piece``, shape (k, 3)."""
    h = piece.heading
    if piece.kind == "line":
        s = fraction * piece.length
        return np.column_stack(
            [piece.x + s * math.cos(h), piece.y + s * math.sin(h), np.full_like(s, h)]
        )
    phi = fraction * piece.angle  # signed heading change so far
    if piece.kind == "turn":
        return np.column_stack([np.full_like(phi, piece.x), np.full_like(phi, piece.y), h + phi])
    sign = math.copysign(1.0, piece.angle)
    r = piece.radius
    cx = piece.x - sign * r * math.sin(h)
    cy = piece.y + sign * r * math.cos(h)
    return np.column_stack(
        [cx + sign * r * np.sin(h + phi), cy - sign * r * np.cos(h + phi), h + phi]
    )


def path_length(waypoints: ArrayLike) -> float:
    """Length (m) of the waypoint polyline (before corners are rounded)."""
    pts = np.asarray(waypoints, dtype=np.float64)
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def trajectory_from_waypoints(
    waypoints: ArrayLike, config: TrajectoryConfig | None = None
) -> SimTrajectory:
    """Timed base poses along ``waypoints`` (see the module docstring).

    Parameters
    ----------
    waypoints : array_like, shape (k >= 2, 2)
        The path's corners in the world frame (m).
    config : TrajectoryConfig, optional
        Speeds, corner radius, scan spacing, first time stamp.

    Returns
    -------
    SimTrajectory
        Poses at ``start_time_s + k · scan_period_s`` for every ``k`` within the path's
        duration (headings wrapped to ``(−π, π]``).
    """
    config = config or TrajectoryConfig()
    pts = np.asarray(waypoints, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise InputError(f"waypoints must have shape (k >= 2, 2), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError("waypoints contain NaN or infinite coordinates")
    pieces = _pieces(pts, config)
    durations = np.array([p.duration for p in pieces])
    ends = np.cumsum(durations)
    period = config.scan_period_s
    n_scans = math.floor(ends[-1] / period + 1e-9) + 1
    t_rel = np.arange(n_scans) * period
    which = np.minimum(np.searchsorted(ends, t_rel, side="right"), len(pieces) - 1)
    starts = ends - durations
    poses = np.empty((n_scans, 3))
    for k in np.unique(which):
        sel = which == k
        fraction = np.clip((t_rel[sel] - starts[k]) / durations[k], 0.0, 1.0)
        poses[sel] = _pose_on_piece(pieces[int(k)], fraction)
    poses[:, 2] = wrap_angle(poses[:, 2])
    stamps_us = np.round(config.start_time_s * 1e6) + np.round(t_rel * 1e6)
    return SimTrajectory(stamps_us / 1e6, poses)
