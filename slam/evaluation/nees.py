"""Normalised estimation error squared (NEES) of poses with covariances and ground truth.

For each pose with covariance ``P`` (3×3, in the right-perturbation tangent space of
:mod:`slam.geometry`, as GTSAM's ``Pose2`` marginals), the error is the tangent vector that
moves the estimate onto the truth, ``ξ = Log(P̂⁻¹ · Q)`` (so ``Q = P̂ ⊕ ξ``), and
``NEES = ξᵀ P⁻¹ ξ``.  A consistent estimator has ``E[NEES] = 3``; the mean over ``N`` poses
is tested against the two-sided χ² interval ``[χ²_{3N}(α/2), χ²_{3N}(1 − α/2)] / N``
(Bar-Shalom, Li & Kirubarajan 2001, §5.4), and the fraction of single poses inside the
``χ²_3`` interval is reported too.  (Successive poses of one trajectory are correlated, so
the interval of the mean is indicative for a single run, exact for independent trials.)

No alignment is applied: the estimate and the truth must share the world frame (the
simulator and the SLAM runner both anchor the first pose).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError
from slam.evaluation.timestamps import associate
from slam.geometry import pose_between, pose_log
from slam.io.trajectory import Trajectory

__all__ = ["NeesResult", "nees_values", "pose_nees"]

FloatArray = NDArray[np.float64]


def nees_values(errors: ArrayLike, covariances: ArrayLike) -> FloatArray:
    """``ξᵀ P⁻¹ ξ`` for errors ``(n, d)`` and covariances ``(n, d, d)`` (Cholesky, checked)."""
    e = np.asarray(errors, dtype=np.float64)
    c = np.asarray(covariances, dtype=np.float64)
    if c.shape != e.shape + e.shape[-1:]:
        raise EvaluationError(f"covariances {c.shape} do not fit errors {e.shape}")
    try:
        L = np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(0.5 * (c + np.swapaxes(c, -1, -2)))
        bad = int(np.flatnonzero(eig.min(axis=-1) <= 0.0)[0]) if (eig <= 0).any() else -1
        raise EvaluationError(
            f"covariance {bad} is not positive definite (eigenvalues {eig[bad].tolist()})"
        ) from None
    z = np.linalg.solve(L, e[..., None])[..., 0]
    return np.sum(z**2, axis=-1)


@dataclass(frozen=True)
class NeesResult:
    """Pose NEES with its χ² consistency bounds."""

    n: int
    dof: int
    mean: float
    lower: float
    upper: float
    confidence: float
    fraction_within: float
    values: FloatArray = field(repr=False)

    @property
    def consistent(self) -> bool:
        """The mean NEES lies inside its χ² interval."""
        return self.lower <= self.mean <= self.upper

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready copy (per-pose values left out)."""
        return {
            "n": self.n,
            "dof": self.dof,
            "mean": self.mean,
            "bounds": [self.lower, self.upper],
            "confidence": self.confidence,
            "consistent": self.consistent,
            "fraction_within_single_bounds": self.fraction_within,
        }


def pose_nees(
    estimate: Trajectory,
    covariances: ArrayLike,
    ground_truth: Trajectory,
    *,
    confidence: float = 0.95,
    tolerance_s: float = 1e-5,
    max_unmatched_fraction: float = 0.02,
) -> NeesResult:
    """NEES of every estimated pose that has a ground-truth pose of the same stamp."""
    cov = np.asarray(covariances, dtype=np.float64)
    if cov.shape != (len(estimate), 3, 3):
        raise EvaluationError(f"need one 3x3 covariance per pose, got shape {cov.shape}")
    i_est, i_ref, _ = associate(
        estimate,
        ground_truth,
        tolerance_s=tolerance_s,
        max_unmatched_fraction=max_unmatched_fraction,
    )
    xi = pose_log(pose_between(estimate.poses[i_est], ground_truth.poses[i_ref]))
    values = nees_values(xi, cov[i_est])
    n, dof = values.size, 3
    alpha = 1.0 - confidence
    from scipy.stats import chi2  # here: importing scipy.stats costs ~1 s at start-up

    lower = float(chi2.ppf(alpha / 2.0, dof * n) / n)
    upper = float(chi2.ppf(1.0 - alpha / 2.0, dof * n) / n)
    single = (values >= chi2.ppf(alpha / 2.0, dof)) & (values <= chi2.ppf(1 - alpha / 2.0, dof))
    return NeesResult(
        n=int(n),
        dof=dof,
        mean=float(values.mean()),
        lower=lower,
        upper=upper,
        confidence=confidence,
        fraction_within=float(single.mean()),
        values=values,
    )
