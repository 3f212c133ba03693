"""The result of a :class:`~slam.line_slam.LineSlam` run and its files.

Files (``../shared/INTERFACES.md``): ``trajectory.tum`` (one laser pose per scan, time stamps as
in the log; :func:`slam.io.write_results`, with ``trajectory_covariance.txt`` holding the pose
marginals), ``map.json`` (world lines in normal form with their 2×2 marginal covariance and
visible segments; :func:`slam.lines.mapio.write_map_json`) and ``summary.json``.
:meth:`SlamResult.to_json_dict` / :meth:`SlamResult.from_json_dict` round-trip everything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["SlamResult"]

FloatArray = NDArray[np.float64]


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating | float):
        f = float(value)
        return f if np.isfinite(f) else None
    return value


@dataclass(frozen=True, eq=False)
class SlamResult:
    """What a line-SLAM run produced (all scans, the final estimate).

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
        Scan time stamps as in the log.
    poses_world_laser : ndarray, shape (N, 3)
        Laser pose of every scan: keyframes as optimised, other scans their keyframe's pose
        composed with the odometry since.
    pose_covariances : ndarray, shape (N, 3, 3)
        Marginal covariances (right tangent space, as GTSAM's ``Pose2``); non-keyframes add the
        motion noise of their odometry offset; NaN when not computed.
    is_keyframe : ndarray of bool, shape (N,)
    keyframe_of_scan : ndarray of int, shape (N,)
        The pose variable each scan hangs from.
    landmark_ids : ndarray of int, shape (M,)
        Landmark variable index of each map line (fused landmarks are absent).
    landmarks_r_alpha : ndarray, shape (M, 2)
        World lines in normal form (``r ≥ 0``, ``α ∈ (−π, π]``).
    landmark_covariances : ndarray, shape (M, 2, 2)
        Their marginal covariances on ``(r, α)``.
    landmark_segments : list of ndarray, each (k, 2, 2)
        Visible pieces of each line (world end points), ordered along the tangent.
    landmark_segments_var : list of ndarray, each (k, 2)
        Approximate variances (m²) of the pieces' ends along the line.
    landmark_n_observations : ndarray of int, shape (M,)
        Line measurements on each landmark.
    scan_runtime_s : ndarray, shape (N,)
        Wall-clock time of :meth:`LineSlam.add_scan` for each scan.
    n_landmarks : ndarray of int, shape (N,)
        Alive landmarks after each scan.
    stats : dict
        Counters and timings (see :meth:`summary_dict`).
    frame : str
        ``"laser"``: the poses are of the laser.
    """

    timestamps: FloatArray
    poses_world_laser: FloatArray
    pose_covariances: FloatArray
    is_keyframe: NDArray[np.bool_]
    keyframe_of_scan: NDArray[np.int64]
    landmark_ids: NDArray[np.int64]
    landmarks_r_alpha: FloatArray
    landmark_covariances: FloatArray
    landmark_segments: list[FloatArray]
    landmark_segments_var: list[FloatArray]
    landmark_n_observations: NDArray[np.int64]
    scan_runtime_s: FloatArray
    n_landmarks: NDArray[np.int64]
    stats: dict[str, Any] = field(default_factory=dict)
    frame: str = "laser"

    @property
    def n_scans(self) -> int:
        """Number of scans."""
        return int(self.timestamps.shape[0])

    # -- files -------------------------------------------------------------------------------
    def line_map(self, min_observations: int = 1) -> Any:
        """The map as a :class:`slam.lines.mapbuilder.LineMap` (for ``map.json``)."""
        from slam.lines.mapbuilder import LineMap, MapLine

        out = []
        for k in range(self.landmark_ids.shape[0]):
            if self.landmark_n_observations[k] < min_observations:
                continue
            r, a = self.landmarks_r_alpha[k]
            seg = self.landmark_segments[k]
            var = self.landmark_segments_var[k]
            t = np.array([-np.sin(a), np.cos(a)])
            s_ends = seg @ t  # (k, 2)
            lengths = np.abs(s_ends[:, 1] - s_ends[:, 0])
            w = lengths / max(float(lengths.sum()), 1e-300)
            s = float(np.sum(w * s_ends.mean(axis=1)))
            cov = np.zeros((3, 3))
            cov[:2, :2] = self.landmark_covariances[k]
            cov[2, 2] = float(np.mean(var)) if var.size else 0.0
            out.append(
                MapLine(
                    id=int(self.landmark_ids[k]),
                    r=float(r),
                    alpha=float(a),
                    s=s,
                    cov=cov,
                    segments=seg,
                    segments_var=var,
                    n_observations=int(self.landmark_n_observations[k]),
                )
            )
        return LineMap(lines=tuple(out), frame="world")

    def summary_dict(self) -> dict[str, Any]:
        """``summary.json``: the INTERFACES.md fields plus the run's counters."""
        points = int(self.stats.get("points", 0))
        n_map = int(self.landmark_ids.shape[0])
        n_seg = int(sum(s.shape[0] for s in self.landmark_segments))
        out: dict[str, Any] = {
            "scans": self.n_scans,
            "points": points,
            "lines_fit": int(self.stats.get("lines_fit", 0)),
            "lines_merged": n_map,
            "compression": (1.0 - 2.0 * n_seg / points) if points > 0 else None,
            "runtime_s": self.stats.get("runtime_s", {}),
            "frame": self.frame,
            "keyframes": int(np.count_nonzero(self.is_keyframe)),
            "landmarks": n_map,
            "segments": n_seg,
        }
        out.update({k: v for k, v in self.stats.items() if k not in out})
        result: dict[str, Any] = _jsonable(out)
        return result

    def write(self, out_dir: str | Path, min_observations: int = 1) -> Path:
        """Write ``trajectory.tum`` (+ covariances), ``map.json`` and ``summary.json``."""
        from slam.io import write_results
        from slam.lines.mapio import write_map_json

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        cov = self.pose_covariances
        write_results(
            out,
            self.timestamps,
            self.poses_world_laser,
            self.summary_dict(),
            frame=self.frame,
            covariances=cov if np.isfinite(cov).all() else None,
        )
        write_map_json(out / "map.json", self.line_map(min_observations))
        return out

    # -- serialisation -----------------------------------------------------------------------
    def to_json_dict(self) -> dict[str, Any]:
        """Everything as JSON-compatible lists (NaN becomes ``None``)."""
        return {
            "timestamps": self.timestamps.tolist(),
            "poses_world_laser": self.poses_world_laser.tolist(),
            "pose_covariances": _jsonable(self.pose_covariances),
            "is_keyframe": self.is_keyframe.tolist(),
            "keyframe_of_scan": self.keyframe_of_scan.tolist(),
            "landmark_ids": self.landmark_ids.tolist(),
            "landmarks_r_alpha": self.landmarks_r_alpha.tolist(),
            "landmark_covariances": _jsonable(self.landmark_covariances),
            "landmark_segments": [s.tolist() for s in self.landmark_segments],
            "landmark_segments_var": [v.tolist() for v in self.landmark_segments_var],
            "landmark_n_observations": self.landmark_n_observations.tolist(),
            "scan_runtime_s": self.scan_runtime_s.tolist(),
            "n_landmarks": self.n_landmarks.tolist(),
            "stats": _jsonable(self.stats),
            "frame": self.frame,
        }

    @classmethod
    def from_json_dict(cls, doc: dict[str, Any]) -> SlamResult:
        """Inverse of :meth:`to_json_dict`."""

        def arr(key: str, shape: tuple[int, ...], dtype: type = float) -> NDArray[Any]:
            a = np.array(doc[key], dtype=object)
            if dtype is float:
                a = np.where(a == None, np.nan, a)  # noqa: E711 - element-wise None test
            return np.asarray(a, dtype=dtype).reshape(shape)

        n = len(doc["timestamps"])
        m = len(doc["landmark_ids"])
        return cls(
            timestamps=arr("timestamps", (n,)),
            poses_world_laser=arr("poses_world_laser", (n, 3)),
            pose_covariances=arr("pose_covariances", (n, 3, 3)),
            is_keyframe=arr("is_keyframe", (n,), bool),
            keyframe_of_scan=arr("keyframe_of_scan", (n,), np.int64),
            landmark_ids=arr("landmark_ids", (m,), np.int64),
            landmarks_r_alpha=arr("landmarks_r_alpha", (m, 2)),
            landmark_covariances=arr("landmark_covariances", (m, 2, 2)),
            landmark_segments=[
                np.asarray(s, float).reshape(-1, 2, 2) for s in doc["landmark_segments"]
            ],
            landmark_segments_var=[
                np.asarray(v, float).reshape(-1, 2) for v in doc["landmark_segments_var"]
            ],
            landmark_n_observations=arr("landmark_n_observations", (m,), np.int64),
            scan_runtime_s=arr("scan_runtime_s", (n,)),
            n_landmarks=arr("n_landmarks", (n,), np.int64),
            stats=dict(doc.get("stats", {})),
            frame=str(doc.get("frame", "laser")),
        )
