"""Monte-Carlo helpers: fit many noisy observations of one wall at once (vectorised)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from linefit import LineFitConfig
from linefit.covariance import LineCovariances, line_covariances
from linefit.fit import GroupFit, fit_groups
from linefit.noise import point_covariance_entries
from linefit.readings import scan_points
from linefit.rsframe import rs_variances


@dataclass
class Trials:
    fit: GroupFit
    cov: LineCovariances
    n_trials: int
    n_points: int
    errors: np.ndarray  # (T, 3): (R, α, S) estimate minus truth
    end_errors: np.ndarray  # (T, 2): first / last point's s minus its truth
    end_var: np.ndarray  # (T, 2): predicted variances of those


def fit_trials(obs: dict, r: float, alpha: float, config: LineFitConfig) -> Trials:
    """Fit each trial (row) of ``obs`` (from ``_synthetic.wall_scan``) as one line."""
    ranges, bearings = obs["ranges"], obs["bearings"]
    n_trials, n = ranges.shape
    beams = np.tile(np.arange(n), n_trials)
    pts = scan_points(ranges.ravel(), bearings.ravel(), beams, config)
    pidx = np.arange(n_trials * n)
    gidx = np.repeat(np.arange(n_trials), n)
    fit = fit_groups(
        pts,
        pidx,
        gidx,
        n_trials,
        np.full(n_trials, alpha),
        weighted=config.weighted,
        max_iterations=config.max_iterations,
        tolerance_rad=config.alpha_tolerance_rad,
        alpha_step=config.alpha_update,
    )
    assert fit.converged.all()
    cov = line_covariances(fit, pts, pidx, gidx, n_trials, config.noise.bearing_error)
    # truth of S: the same weighted mean of the true along-wall positions, weights at the truth
    if config.weighted:
        q = point_covariance_entries(obs["ranges_true"], obs["bearings_true"], config.noise)
        _, p_s, _ = rs_variances(*q, alpha)
        v = (1.0 / p_s) / np.sum(1.0 / p_s)
    else:
        v = np.full(n, 1.0 / n)
    s_true = float(v @ obs["s_true"])
    errors = np.stack([fit.r - r, fit.alpha - alpha, fit.s - s_true], axis=1)
    u_s = fit.u_s.reshape(n_trials, n)
    ev = cov.end_var.reshape(n_trials, n)
    end_errors = np.stack([u_s[:, 0] - obs["s_true"][0], u_s[:, -1] - obs["s_true"][-1]], 1)
    return Trials(fit, cov, n_trials, n, errors, end_errors, ev[:, [0, -1]])


def nees_bounds(dof: int, n: int, level: float = 0.99) -> tuple[float, float]:
    """Interval of the mean of ``n`` χ²_dof values at ``level`` (normal approximation)."""
    z = stats.norm.ppf(0.5 + level / 2.0)
    half = z * np.sqrt(2.0 * dof / n)
    return dof - half, dof + half


def mean_nees(errors: np.ndarray, covs: np.ndarray) -> float:
    """Mean of ``eᵀ P⁻¹ e`` over trials (errors ``(T, k)``, covariances ``(T, k, k)``)."""
    sol = np.linalg.solve(covs, errors[..., None])[..., 0]
    return float(np.mean(np.sum(errors * sol, axis=1)))
