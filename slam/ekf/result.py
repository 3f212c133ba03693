"""The EKF's result: trajectory, line map, covariances, run statistics, and its files.

Files (``../shared/INTERFACES.md``): ``trajectory.tum`` (one laser pose per scan, the filtered
estimate at that scan's time), ``map.json`` (world lines in normal form with their 2×2 marginal
covariance and seen segments), ``summary.json``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["EkfResult", "write_tum"]

FloatArray = NDArray[np.float64]


def write_tum(path: Path, timestamps: FloatArray, poses_world_laser: FloatArray) -> None:
    """Write planar poses as TUM lines ``t x y z qx qy qz qw`` (z = 0, yaw quaternion)."""
    th = poses_world_laser[:, 2]
    with Path(path).open("w", encoding="utf-8") as fh:
        for t, (x, y, _), a in zip(timestamps, poses_world_laser, th, strict=True):
            fh.write(
                f"{t:.6f} {x:.9f} {y:.9f} 0.000000000 0.000000000 0.000000000 "
                f"{math.sin(a / 2.0):.12f} {math.cos(a / 2.0):.12f}\n"
            )


@dataclass(frozen=True, eq=False)
class EkfResult:
    """What an EKF-SLAM run produced.

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
        Scan time stamps as in the log.
    poses_world_laser : ndarray, shape (N, 3)
        Filtered laser pose at each scan (not smoothed: pose ``k`` uses scans ``≤ k`` only).
    pose_covariances : ndarray, shape (N, 3, 3)
        Their covariances in the right-perturbation tangent space (as GTSAM's marginals).
    landmarks_r_alpha : ndarray, shape (M, 2)
        Final world lines in normal form (``r ≥ 0``, ``α ∈ (−π, π]``).
    landmark_covariances : ndarray, shape (M, 2, 2)
        Their marginal covariances.
    landmark_segments : list of ndarray, each (k, 2, 2)
        Seen pieces of each line (world end points).
    landmark_n_observations : ndarray of int, shape (M,)
        Measurements fused into each landmark (initialisation included).
    scan_runtime_s : ndarray, shape (N,)
        Wall-clock time spent on each scan (extraction excluded when lines were given).
    n_landmarks : ndarray of int, shape (N,)
        Map size after each scan.
    stats : dict
        Counters (``scans``, ``points``, ``lines_fit``, ``lines_matched``, ``lines_new``,
        ``lines_ambiguous``, ``lines_invalid``, ``landmarks_merged``, ``jcbb_incomplete``,
        ``updates``), and ``stopped_at_scan`` / ``stop_reason`` when the run stopped early.
    state_dim : int
        Final size of the filter state ``3 + 2M``.
    """

    timestamps: FloatArray
    poses_world_laser: FloatArray
    pose_covariances: FloatArray
    landmarks_r_alpha: FloatArray
    landmark_covariances: FloatArray
    landmark_segments: list[FloatArray]
    landmark_n_observations: NDArray[np.int64]
    scan_runtime_s: FloatArray
    n_landmarks: NDArray[np.int64]
    stats: dict[str, Any] = field(default_factory=dict)
    state_dim: int = 3

    @property
    def n_scans(self) -> int:
        """Number of scans in the trajectory."""
        return int(self.timestamps.shape[0])

    def map_dict(self, min_observations: int = 1) -> dict[str, Any]:
        """``map.json`` content: world lines with covariance and segments."""
        lines = []
        for j in range(self.landmarks_r_alpha.shape[0]):
            if self.landmark_n_observations[j] < min_observations:
                continue
            r, a = self.landmarks_r_alpha[j]
            lines.append(
                {
                    "id": j,
                    "r": float(r),
                    "alpha": float(a),
                    "cov": self.landmark_covariances[j].tolist(),
                    "segments": self.landmark_segments[j].tolist(),
                    "n_observations": int(self.landmark_n_observations[j]),
                }
            )
        return {"frame": "world", "lines": lines}

    def summary_dict(self, min_observations: int = 1) -> dict[str, Any]:
        """``summary.json`` content (INTERFACES.md fields plus the EKF's counters)."""
        points = int(self.stats.get("points", 0))
        n_map = int(np.count_nonzero(self.landmark_n_observations >= min_observations))
        compression = 1.0 - 2.0 * n_map / points if points > 0 else float("nan")
        runtime = self.stats.get("runtime_s", {})
        out: dict[str, Any] = {
            "backend": "ekf",
            "scans": self.n_scans,
            "points": points,
            "lines_fit": int(self.stats.get("lines_fit", 0)),
            "lines_merged": n_map,
            "compression": compression,
            "runtime_s": {
                "total": float(np.sum(self.scan_runtime_s)),
                "per_scan_mean": float(np.mean(self.scan_runtime_s)) if self.n_scans else 0.0,
                "per_scan_max": float(np.max(self.scan_runtime_s)) if self.n_scans else 0.0,
                **runtime,
            },
            "frame": "laser",
            "landmarks": int(self.landmarks_r_alpha.shape[0]),
            "state_dim": int(self.state_dim),
        }
        out.update({k: v for k, v in self.stats.items() if k not in ("runtime_s", "points")})
        return out

    def write(self, out_dir: str | Path, min_observations: int = 1) -> None:
        """Write ``trajectory.tum``, ``map.json`` and ``summary.json`` into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_tum(out / "trajectory.tum", self.timestamps, self.poses_world_laser)
        (out / "map.json").write_text(
            json.dumps(self.map_dict(min_observations), indent=1), encoding="utf-8"
        )
        (out / "summary.json").write_text(
            json.dumps(self.summary_dict(min_observations), indent=1), encoding="utf-8"
        )
