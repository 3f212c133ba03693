"""Figures of a line-SLAM result (matplotlib; imported only where a picture is drawn).

:func:`plot_slam_result` draws the estimated trajectory (and the odometry, when the result
keeps it) over the line map, each map line with its visible segments, and saves
``trajectory_map.png`` into a folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

__all__ = ["plot_slam_result"]


def plot_slam_result(result: Any, out_dir: Path, title: str = "") -> Path:
    """Trajectory and line map of a :class:`slam.graph.SlamResult`; returns the PNG's path.

    Parameters
    ----------
    result : SlamResult
        Needs ``poses_world_laser``, ``landmark_segments`` and ``is_keyframe``.
    out_dir : Path
        Folder (created) for ``trajectory_map.png``.
    title : str
        Figure title.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9, 9))
    segs = [s for pieces in result.landmark_segments for s in pieces]
    if segs:
        ax.add_collection(LineCollection(list(segs), colors="k", linewidths=1.2, label="map"))
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
    path = out_dir / "trajectory_map.png"
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
    return path
