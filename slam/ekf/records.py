"""What the EKF reports: one :class:`ScanReport` per call, the per-scan records, the result.

:class:`ScanRecords` keeps the pose and covariance of every processed scan and assembles the
:class:`slam.result.SlamResult` (the result type of both estimators) with the final map.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.inputs import InputPolicy
from slam.result import SlamResult

__all__ = ["ScanRecords", "ScanReport"]

FloatArray = NDArray[np.float64]


class ScanReport:
    """What one :meth:`EkfSlam.add_scan` call did.

    Attributes
    ----------
    index : int
        Scan index.
    n_lines, n_matched, n_new, n_ambiguous, n_invalid : int
        Lines given / matched to landmarks / starting new landmarks / dropped as ambiguous /
        skipped for a bad covariance.
    updated : bool
        False when the update policy skipped this scan's lines.
    skipped : bool
        True when the filter had stopped before this scan (no pose for it).
    runtime_s : float
        Time spent on the scan.
    """

    def __init__(self, index: int) -> None:
        self.index = index
        self.n_lines = 0
        self.n_matched = 0
        self.n_new = 0
        self.n_ambiguous = 0
        self.n_invalid = 0
        self.updated = False
        self.skipped = False
        self.runtime_s = 0.0

    def __repr__(self) -> str:
        return (
            f"ScanReport(index={self.index}, lines={self.n_lines}, matched={self.n_matched}, "
            f"new={self.n_new}, ambiguous={self.n_ambiguous}, invalid={self.n_invalid})"
        )


class ScanRecords:
    """Pose, covariance and bookkeeping of every scan the filter processed, in order."""

    def __init__(self) -> None:
        self._t: list[float] = []
        self._poses: list[FloatArray] = []
        self._covs: list[FloatArray] = []
        self._is_update: list[bool] = []
        self._runtime: list[float] = []
        self._n_landmarks: list[int] = []

    def __len__(self) -> int:
        return len(self._t)

    def append(
        self,
        timestamp: float,
        pose_world_laser: FloatArray,
        covariance: FloatArray,
        is_update: bool,
        runtime_s: float,
        n_landmarks: int,
    ) -> None:
        """Record one scan.

        Its laser pose ``(3,)``, tangent-space covariance ``(3, 3)``, whether its lines updated
        the filter, the time spent on it (s) and the number of landmarks after it.
        """
        self._t.append(float(timestamp))
        self._poses.append(pose_world_laser)
        self._covs.append(covariance)
        self._is_update.append(bool(is_update))
        self._runtime.append(float(runtime_s))
        self._n_landmarks.append(int(n_landmarks))

    def result(
        self,
        landmarks_r_alpha: FloatArray,
        landmark_covariances: FloatArray,
        landmark_segments: list[FloatArray],
        landmark_n_observations: Sequence[int],
        stats: dict[str, Any],
        policy: InputPolicy,
        state_dim: int,
    ) -> SlamResult:
        """The result with the map ``(M, 2)`` in normal form, its covariances and segments.

        Poses and covariances are reported in the policy's output frame
        (:meth:`slam.inputs.InputPolicy.report`); the updates are the keyframes; ``stats`` is
        copied with ``backend = "ekf"`` and ``runtime_s`` (``total``, ``per_scan_mean``,
        ``per_scan_max`` of the per-scan times) added.  The filter does not estimate the
        variances of the segments' ends: zeros.
        """
        is_update = np.asarray(self._is_update, dtype=bool)
        runtime = np.asarray(self._runtime, dtype=float)
        poses, pose_cov = policy.report(
            np.asarray(self._poses, dtype=float).reshape(-1, 3),
            np.asarray(self._covs, dtype=float).reshape(-1, 3, 3),
        )
        assert pose_cov is not None
        out_stats: dict[str, Any] = {
            **stats,
            "backend": "ekf",
            "runtime_s": {
                "total": float(np.sum(runtime)),
                "per_scan_mean": float(np.mean(runtime)) if runtime.size else 0.0,
                "per_scan_max": float(np.max(runtime)) if runtime.size else 0.0,
            },
        }
        return SlamResult(
            timestamps=np.asarray(self._t, dtype=float),
            poses_world_laser=poses,
            pose_covariances=pose_cov,
            is_keyframe=is_update,
            keyframe_of_scan=(np.cumsum(is_update) - 1).astype(np.int64),
            landmark_ids=np.arange(landmarks_r_alpha.shape[0], dtype=np.int64),
            landmarks_r_alpha=landmarks_r_alpha,
            landmark_covariances=landmark_covariances,
            landmark_segments=landmark_segments,
            landmark_segments_var=[np.zeros((seg.shape[0], 2)) for seg in landmark_segments],
            landmark_n_observations=np.asarray(landmark_n_observations, dtype=np.int64),
            scan_runtime_s=runtime,
            n_landmarks=np.asarray(self._n_landmarks, dtype=np.int64),
            stats=out_stats,
            frame=policy.output_frame,
            state_dim=int(state_dim),
        )
