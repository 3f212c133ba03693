"""Normalised estimation error squared (NEES) of poses, and its χ² bounds.

Interim home until :mod:`slam.evaluation` provides NEES; the convention is the project's:
pose covariances live in the right-perturbation tangent space, so the error of an estimate
``T̂`` with respect to the truth ``T`` is ``ξ = Log(T̂⁻¹ · T)`` and ``NEES = ξᵀ Σ⁻¹ ξ``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from slam.errors import InputError
from slam.geometry import pose_between, pose_log

__all__ = ["anees_bounds", "pose_nees"]

FloatArray = NDArray[np.float64]


def pose_nees(poses_est: FloatArray, covariances: FloatArray, poses_true: FloatArray) -> FloatArray:
    """NEES of each pose; ``nan`` where the covariance is singular.

    Parameters
    ----------
    poses_est : ndarray, shape (..., 3)
    covariances : ndarray, shape (..., 3, 3)
        Right-perturbation tangent-space covariances of the estimates.
    poses_true : ndarray, shape (..., 3)

    Returns
    -------
    ndarray, shape (...)
    """
    est = np.asarray(poses_est, dtype=float)
    cov = np.asarray(covariances, dtype=float)
    truth = np.asarray(poses_true, dtype=float)
    if est.shape != truth.shape or cov.shape != (*est.shape, 3):
        raise InputError(f"pose_nees: shapes {est.shape}, {cov.shape}, {truth.shape} do not match")
    xi = pose_log(pose_between(est, truth))
    out = np.full(est.shape[:-1], np.nan)
    ok = np.linalg.matrix_rank(cov, tol=1e-15) == 3
    if np.any(ok):
        sol = np.linalg.solve(cov[ok], xi[ok][..., None])[..., 0]
        out[ok] = np.sum(xi[ok] * sol, axis=-1)
    return out


def anees_bounds(dof: int, n_runs: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds of the NEES averaged over ``n_runs`` consistent runs (``dof`` each).

    ``n_runs · ANEES ~ χ²_{n_runs · dof}``; returns the ``(1 ± probability)/2`` quantiles
    divided by ``n_runs``.
    """
    lo = chi2.ppf((1.0 - probability) / 2.0, n_runs * dof) / n_runs
    hi = chi2.ppf((1.0 + probability) / 2.0, n_runs * dof) / n_runs
    return float(lo), float(hi)
