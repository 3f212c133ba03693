"""Figures of a line-SLAM result (matplotlib; imported only where a picture is drawn).

:func:`plot_slam_result` draws the estimated trajectory (and the odometry, when the result
keeps it) over the line map, each map line with its visible segments, optionally over the raw
laser points placed by the estimated poses, and saves
``trajectory_map.png`` into a folder.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from slam.plotting.figure import plt, save_figure
from slam.plotting.shapes import add_segments

__all__ = ["plot_slam_result", "raw_points_world"]


def raw_points_world(
    scans: Iterable[Any], poses_world_laser: np.ndarray, keep: np.ndarray, max_points: int = 400_000
) -> np.ndarray:
    """The valid readings of the scans where ``keep`` is true, in the world frame.

    ``scans`` are the log's scans in order (``Scan`` objects), ``poses_world_laser`` one
    estimated laser pose per scan.  At most about ``max_points`` points are returned (every
    k-th kept scan), enough to show the walls behind the line map.
    """
    poses = np.asarray(poses_world_laser, dtype=float)
    keep = np.asarray(keep, dtype=bool)
    step = max(1, int(np.ceil(keep.sum() * 200 / max_points)))
    wanted = set(np.flatnonzero(keep)[::step].tolist())
    chunks = []
    for n, scan in enumerate(scans):
        if n >= poses.shape[0]:
            break
        if n not in wanted:
            continue
        ok = scan.valid_mask()
        x = scan.ranges[ok] * np.cos(scan.bearings[ok])
        y = scan.ranges[ok] * np.sin(scan.bearings[ok])
        px, py, th = poses[n]
        c, s_ = np.cos(th), np.sin(th)
        chunks.append(np.column_stack([px + c * x - s_ * y, py + s_ * x + c * y]))
    return np.concatenate(chunks) if chunks else np.zeros((0, 2))


def plot_slam_result(
    result: Any, out_dir: Path, title: str = "", points_world: np.ndarray | None = None
) -> Path:
    """Trajectory and line map of a :class:`slam.result.SlamResult`; returns the PNG's path.

    Parameters
    ----------
    result : SlamResult
        Needs ``poses_world_laser``, ``landmark_segments`` and ``is_keyframe``.
    out_dir : Path
        Folder (created) for ``trajectory_map.png``.
    title : str
        Figure title.
    points_world : ndarray, shape (n, 2), optional
        Raw laser points in the world frame (:func:`raw_points_world`), drawn under the map.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9, 9))
    if points_world is not None and len(points_world):
        ax.plot(points_world[:, 0], points_world[:, 1], ",", color="0.6", alpha=0.5)
    segs = [s for pieces in result.landmark_segments for s in pieces]
    if segs:
        add_segments(ax, segs, colors="k", linewidths=1.2, label="map")
    p = np.asarray(result.poses_world_laser)
    ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=0.8, label="trajectory (laser)")
    kf = np.asarray(result.is_keyframe, dtype=bool)
    ax.plot(p[kf, 0], p[kf, 1], ".", color="tab:blue", ms=2)
    odo = result.stats.get("odometry_poses") if isinstance(result.stats, dict) else None
    if odo is not None:
        o = np.asarray(odo)
        ax.plot(o[:, 0], o[:, 1], "-", color="tab:red", lw=0.6, alpha=0.6, label="odometry")
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    n_lines = len(result.landmark_segments)
    ax.set_title(f"{title}  ({len(p)} scans, {int(kf.sum())} keyframes, {n_lines} map lines)")
    ax.legend(loc="best")
    return save_figure(
        fig, out_dir / "trajectory_map.png", dpi=150, tight_layout=False, bbox_inches="tight"
    )
