"""The result of an estimator run (:class:`~slam.line_slam.LineSlam` or :class:`~slam.ekf.EkfSlam`).

One type for both estimators, and one writer of its files (``../shared/INTERFACES.md``):
``trajectory.tum`` (one pose per scan, time stamps as in the log) with
``trajectory_covariance.txt`` holding the pose covariances (:func:`slam.io.write_trajectory`),
``map.json`` (world lines in normal form with their 2×2 marginal covariance and visible
segments; :func:`slam.lines.mapio.write_map_json`) and ``summary.json``
(:func:`slam.io.write_summary`).  :meth:`SlamResult.to_json_dict` /
:meth:`SlamResult.from_json_dict` round-trip everything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import InputError
from slam.io.results import to_jsonable

__all__ = ["SlamResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SlamResult:
    """What an estimator run produced (all scans, the final estimate).

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
        Scan time stamps as in the log.
    poses_world_laser : ndarray, shape (N, 3)
        Pose of every scan in the frame ``frame`` (m, m, rad).  Graph: keyframes as optimised,
        other scans their keyframe's pose composed with the odometry since.  EKF: the filtered
        estimate at the scan's time (pose ``k`` uses scans ``≤ k`` only).
    pose_covariances : ndarray, shape (N, 3, 3)
        Their covariances in the right tangent space (as GTSAM's ``Pose2`` marginals);
        non-keyframes add the motion noise of their odometry offset; NaN when not computed.
    is_keyframe : ndarray of bool, shape (N,)
        Graph: scans with a pose variable.  EKF: scans whose lines updated the filter (the
        same rule on the odometry since the last one, :func:`slam.models.moved_enough`).
    keyframe_of_scan : ndarray of int, shape (N,)
        Index of the keyframe each scan hangs from (``0`` for the first keyframe).
    landmark_ids : ndarray of int, shape (M,)
        Identifier of each map line (graph: landmark variable index, fused landmarks are
        absent; EKF: index in the filter state).
    landmarks_r_alpha : ndarray, shape (M, 2)
        World lines in normal form (``r ≥ 0``, ``α ∈ (−π, π]``).
    landmark_covariances : ndarray, shape (M, 2, 2)
        Their marginal covariances on ``(r, α)``.
    landmark_segments : list of ndarray, each (k, 2, 2)
        Visible pieces of each line (world end points, m), ordered along the tangent.
    landmark_segments_var : list of ndarray, each (k, 2)
        Approximate variances (m²) of the pieces' ends along the line (zeros where the
        estimator does not estimate them, as the EKF).
    landmark_n_observations : ndarray of int, shape (M,)
        Line measurements on each landmark.
    scan_runtime_s : ndarray, shape (N,)
        Wall-clock time spent on each scan (s).
    n_landmarks : ndarray of int, shape (N,)
        Landmarks alive after each scan.
    stats : dict
        Counters and timings (see :meth:`summary_dict`).
    frame : {"laser", "base"}
        Frame whose poses ``poses_world_laser`` holds (the input policy's output frame).
    state_dim : int or None
        Size of a filter's state ``3 + 2M`` at the end (EKF); None for the graph.
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
    state_dim: int | None = None

    @property
    def n_scans(self) -> int:
        """Number of scans."""
        return int(self.timestamps.shape[0])

    # -- files -------------------------------------------------------------------------------
    def _in_map(self, min_observations: int) -> NDArray[np.intp]:
        """Indices of the landmarks with at least ``min_observations`` measurements."""
        return np.flatnonzero(self.landmark_n_observations >= min_observations)

    def line_map(self, min_observations: int = 1) -> Any:
        """The map as a :class:`slam.lines.mapbuilder.LineMap` (for ``map.json``).

        Only landmarks with at least ``min_observations`` measurements are in it.
        """
        from slam.lines.mapbuilder import LineMap, MapLine

        out = []
        for k in self._in_map(min_observations):
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

    def summary_dict(self, min_observations: int = 1) -> dict[str, Any]:
        """``summary.json``: the INTERFACES.md fields plus the run's counters.

        ``lines_merged``, ``segments`` and ``compression`` (a segment counting as two points)
        are of the map written with ``min_observations``; ``landmarks`` counts all of them.
        """
        points = int(self.stats.get("points", 0))
        in_map = self._in_map(min_observations)
        n_map = int(in_map.shape[0])
        n_seg = int(sum(self.landmark_segments[k].shape[0] for k in in_map))
        out: dict[str, Any] = {
            "scans": self.n_scans,
            "points": points,
            "lines_fit": int(self.stats.get("lines_fit", 0)),
            "lines_merged": n_map,
            "compression": (1.0 - 2.0 * n_seg / points) if points > 0 else None,
            "runtime_s": self.stats.get("runtime_s", {}),
            "frame": self.frame,
            "keyframes": int(np.count_nonzero(self.is_keyframe)),
            "landmarks": int(self.landmark_ids.shape[0]),
            "segments": n_seg,
        }
        if self.state_dim is not None:
            out["state_dim"] = int(self.state_dim)
        out.update({k: v for k, v in self.stats.items() if k not in out})
        result: dict[str, Any] = to_jsonable(out)
        return result

    def write_files(self, out_dir: str | Path, min_observations: int = 1) -> Path:
        """Write ``trajectory.tum`` (+ ``trajectory_covariance.txt``) and ``map.json``.

        The covariances are written when all are finite.  Returns the folder (created if
        needed).  ``summary.json`` is left to the caller (:meth:`write`, or a runner that adds
        its timings, :func:`slam.io.write_summary`).
        """
        from slam.io.results import write_trajectory
        from slam.lines.mapio import write_map_json

        if self.frame not in ("laser", "base"):
            raise InputError(f"frame must be 'laser' or 'base', got {self.frame!r}")
        cov = self.pose_covariances
        out = write_trajectory(
            out_dir,
            self.timestamps,
            self.poses_world_laser,
            cov if np.isfinite(cov).all() else None,
        )
        write_map_json(out / "map.json", self.line_map(min_observations))
        return out

    def write(self, out_dir: str | Path, min_observations: int = 1) -> Path:
        """Write the results folder: :meth:`write_files` and ``summary.json``."""
        from slam.io.results import write_summary

        out = self.write_files(out_dir, min_observations)
        write_summary(out, self.summary_dict(min_observations))
        return out

    # -- serialisation -----------------------------------------------------------------------
    def to_json_dict(self) -> dict[str, Any]:
        """Everything as JSON-compatible lists (NaN becomes ``None``)."""
        return {
            "timestamps": self.timestamps.tolist(),
            "poses_world_laser": self.poses_world_laser.tolist(),
            "pose_covariances": to_jsonable(self.pose_covariances),
            "is_keyframe": self.is_keyframe.tolist(),
            "keyframe_of_scan": self.keyframe_of_scan.tolist(),
            "landmark_ids": self.landmark_ids.tolist(),
            "landmarks_r_alpha": self.landmarks_r_alpha.tolist(),
            "landmark_covariances": to_jsonable(self.landmark_covariances),
            "landmark_segments": [s.tolist() for s in self.landmark_segments],
            "landmark_segments_var": [v.tolist() for v in self.landmark_segments_var],
            "landmark_n_observations": self.landmark_n_observations.tolist(),
            "scan_runtime_s": self.scan_runtime_s.tolist(),
            "n_landmarks": self.n_landmarks.tolist(),
            "stats": to_jsonable(self.stats),
            "frame": self.frame,
            "state_dim": self.state_dim,
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
        state_dim = doc.get("state_dim")
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
            state_dim=None if state_dim is None else int(state_dim),
        )
