"""Absolute trajectory error after SE(2) alignment (Umeyama/Horn without scale, in 2-D).

The estimate is moved onto the ground truth by the rigid motion ``T = (R(φ), t)`` that
minimises ``Σ |R p_est + t − p_gt|²`` over the poses matched by time stamp; in 2-D the
optimum is closed-form: with centred positions ``a_i`` (estimate) and ``b_i`` (truth),
``φ = atan2(Σ a_i × b_i, Σ a_i · b_i)`` and ``t = b̄ − R ā`` (Horn 1987; Umeyama 1991 with
the scale fixed to 1).  ATE is the statistics of ``|R p_est + t − p_gt|`` (evo's ``ape``
with ``--align``); the heading error ``θ_est + φ − θ_gt`` is reported alongside.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import EvaluationError
from slam.evaluation.stats import ErrorStats
from slam.evaluation.timestamps import associate
from slam.geometry import pose_compose, wrap_angle
from slam.io.trajectory import Trajectory

__all__ = ["AteResult", "align_se2", "ate"]

FloatArray = NDArray[np.float64]


def align_se2(positions_est: FloatArray, positions_ref: FloatArray) -> FloatArray:
    """The pose ``T = (x, y, φ)`` with ``T · p_est ≈ p_ref`` in least squares (no scale).

    Parameters
    ----------
    positions_est, positions_ref : ndarray, shape (n, 2)
        Corresponding positions; at least two distinct ones.
    """
    a = np.asarray(positions_est, dtype=np.float64)
    b = np.asarray(positions_ref, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 2:
        raise EvaluationError(f"need two (n, 2) position arrays, got {a.shape} and {b.shape}")
    mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
    ac, bc = a - mean_a, b - mean_b
    dot = float(np.sum(ac * bc))
    cross = float(np.sum(ac[:, 0] * bc[:, 1] - ac[:, 1] * bc[:, 0]))
    if np.hypot(dot, cross) <= 1e-12 * max(1.0, float(np.sum(ac**2))):
        raise EvaluationError("alignment is undetermined: the positions do not spread out")
    phi = np.arctan2(cross, dot)
    c, s = np.cos(phi), np.sin(phi)
    t = mean_b - np.array([c * mean_a[0] - s * mean_a[1], s * mean_a[0] + c * mean_a[1]])
    return np.array([t[0], t[1], phi])


@dataclass(frozen=True)
class AteResult:
    """Absolute trajectory error.

    Attributes
    ----------
    translation_m : ErrorStats
        ``|R p_est + t − p_gt|`` (m); ``translation_m.rmse`` is "the ATE".
    rotation_deg : ErrorStats
        ``|θ_est + φ − θ_gt|`` (deg).
    alignment : tuple of float
        ``(x, y, φ)`` applied to the estimate (identity if ``aligned`` is False).
    aligned : bool
    n_unmatched : int
        Estimated poses without a ground-truth pose of the same stamp.
    index_estimate, index_reference : ndarray of int, shape (m,)
        The matched poses: estimated pose ``index_estimate[i]`` and ground-truth pose
        ``index_reference[i]`` share a time stamp.
    translation_errors_m : ndarray, shape (m,)
        ``|R p_est + t − p_gt|`` (m) of each matched pose, the samples of ``translation_m``.
    """

    translation_m: ErrorStats
    rotation_deg: ErrorStats
    alignment: tuple[float, float, float]
    aligned: bool
    n_unmatched: int
    index_estimate: NDArray[np.int64] = field(repr=False, compare=False)
    index_reference: NDArray[np.int64] = field(repr=False, compare=False)
    translation_errors_m: FloatArray = field(repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy (per-pose errors left out)."""
        return {
            "rmse_m": self.translation_m.rmse,
            "translation_m": self.translation_m.to_dict(),
            "rotation_deg": self.rotation_deg.to_dict(),
            "alignment": list(self.alignment),
            "aligned": self.aligned,
            "n_unmatched": self.n_unmatched,
        }


def ate(
    estimate: Trajectory,
    ground_truth: Trajectory,
    *,
    align: bool = True,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> AteResult:
    """ATE of ``estimate`` against ``ground_truth`` (poses matched by time stamp)."""
    i_est, i_ref, n_unmatched = associate(
        estimate,
        ground_truth,
        tolerance_s=tolerance_s,
        max_unmatched_fraction=max_unmatched_fraction,
    )
    est = estimate.poses[i_est]
    ref = ground_truth.poses[i_ref]
    transform = align_se2(est[:, :2], ref[:, :2]) if align else np.zeros(3)
    moved = pose_compose(transform, est)
    trans = np.hypot(moved[:, 0] - ref[:, 0], moved[:, 1] - ref[:, 1])
    rot = np.degrees(np.abs(wrap_angle(moved[:, 2] - ref[:, 2])))
    return AteResult(
        translation_m=ErrorStats.of(trans),
        rotation_deg=ErrorStats.of(rot),
        alignment=(float(transform[0]), float(transform[1]), float(transform[2])),
        aligned=align,
        n_unmatched=n_unmatched,
        index_estimate=i_est,
        index_reference=i_ref,
        translation_errors_m=trans,
    )
