"""The lines' model error, estimated from the residuals of repeated observations of the walls.

A fitted line's covariance (the paper's Props. 1-3) knows only the per-beam noise (Eq. 8).  Real
walls are not the fit's straight lines — they bend, beams have a footprint, ranges are biased by
the surface — so every measured line gets a model error: an offset ``σ_o`` along its normal
and an angle ``σ_a`` about its mid-point (:func:`slam.models.anchored.model_error_covariance`).
Simulated walls have none; real walls have what their residuals show.

Every graph landmark seen many times is an estimate of one wall; the residuals of its line
factors at the current estimate, taken at each segment's mid-point (offset along the normal
there, and angle), are the fit's error plus the model error.  For each component separately,
``σ²`` is Huber's scale estimate ("Proposal 2", Huber 1964): the mean of
``min(e² / (fit variance + σ²), c)`` equals its value for a χ²₁ variable, with ``c`` the
χ²₁ quantile :data:`WINSOR_PROBABILITY`.  It is the variance the line factors must carry for
their covariances to describe the residuals' spread (a second moment, so the heavier-than-
Gaussian tails of real walls count), while a wrong association (a residual of metres) counts
no more than ``c``.  For Gaussian residuals it is the variance itself (simulated walls:
about zero).  Factors of landmarks with fewer than ``min_observations`` factors are left out
(their residuals are shrunk by the landmark's own fit to them).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.special import gammainc, gammaincinv

from slam.graph.factors import line_factor_residuals
from slam.graph.problem import LineGraph
from slam.line_slam.keyframes import EveryKeyframes
from slam.lines.merge import chi2_ppf
from slam.models.anchored import model_error_covariance

__all__ = ["LineModelErrorEstimator", "LineReweighting", "midpoint_residuals"]

FIRST_ESTIMATE_KEYFRAMES = 20
"""Keyframes before the first estimate of the lines' model error."""

ESTIMATE_INTERVAL_KEYFRAMES = 50
"""Keyframes between two later estimates."""

REWEIGHT_CHANGE = 0.2
"""Relative change of the estimated model error that re-weights the line factors."""

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

WINSOR_PROBABILITY = 0.99
"""Residual ratios ``e² / (fit variance + σ²)`` beyond this χ²₁ quantile count as the quantile."""

_WINSOR_C = chi2_ppf(WINSOR_PROBABILITY, 1)
# E[min(X, c)] for X ~ χ²₁: E[X; X < c] = P(χ²₃ < c), plus c · P(X > c)
_WINSOR_MEAN = float(
    gammainc(1.5, _WINSOR_C / 2) + _WINSOR_C * (1.0 - gammainc(0.5, _WINSOR_C / 2))
)


def midpoint_residuals(
    graph: LineGraph, factors: IntArray, fit_cov: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Residuals of line factors at their segments' mid-points, and the fit's variances.

    Returns ``(e, var)``, each ``(F, 2)``: column 0 the offset along the normal at the mid-point
    (m), column 1 the angle (rad); ``var`` the fit's variances of the same.
    """
    g = graph
    f = np.asarray(factors, dtype=np.intp)
    lm = g.factor_landmark[f]
    # unwhitened residuals: (r, α) predicted minus measured
    eye = np.broadcast_to(np.eye(2), (f.size, 2, 2))
    e = line_factor_residuals(g.poses[g.factor_pose[f]], g.landmarks[lm], g.anchors[lm],
                              g.factor_z[f], eye)  # fmt: skip
    z = g.factor_z[f]
    mid = g.factor_endpoints[f].mean(axis=1)
    a = z[:, 1]
    s_m = -np.sin(a) * mid[:, 0] + np.cos(a) * mid[:, 1]
    # offset at the mid-point: δr − s_m δα
    T = np.zeros((f.size, 2, 2))
    T[:, 0, 0] = 1.0
    T[:, 0, 1] = -s_m
    T[:, 1, 1] = 1.0
    em = np.einsum("fij,fj->fi", T, e)
    C = T @ np.asarray(fit_cov, dtype=float)[f] @ np.swapaxes(T, 1, 2)
    return em, np.stack([C[:, 0, 0], C[:, 1, 1]], axis=-1)


# Var[min(X, c)] for X ~ χ²₁: E[X²; X < c] = 3 P(χ²₅ < c), plus c² · P(X > c), less the mean²
_WINSOR_VAR = float(
    3.0 * gammainc(2.5, _WINSOR_C / 2)
    + _WINSOR_C**2 * (1.0 - gammainc(0.5, _WINSOR_C / 2))
    - _WINSOR_MEAN**2
)


def _winsorized_mean(e2: FloatArray, var: FloatArray, s2: float) -> float:
    return float(np.mean(np.minimum(e2 / (var + s2), _WINSOR_C)))


def excess_is_significant(e2: FloatArray, var: FloatArray, probability: float) -> bool:
    """Whether the residuals ``e²`` exceed their variances ``var`` beyond chance.

    The one-sided test of "no model error" (``σ² = 0``): the mean of ``min(e² / var, c)``
    over ``n`` independent residuals against the ``probability`` quantile of its
    distribution without one, taken as the gamma distribution of the same mean and
    variance (``_WINSOR_MEAN``, ``_WINSOR_VAR / n``; the mean is skewed to the right, which a
    normal approximation would miss).
    """
    e2 = np.asarray(e2, dtype=float)
    n = e2.size
    if n == 0:
        return False
    shape = n * _WINSOR_MEAN**2 / _WINSOR_VAR
    # scipy.stats.gamma.ppf(probability, shape, scale=...), the same function from
    # scipy.special (importing scipy.stats costs about half a second of start-up)
    limit = float(gammaincinv(shape, probability) * (_WINSOR_MEAN / shape))
    return _winsorized_mean(e2, var, 0.0) > limit


def _sigma2_for_moment(e2: FloatArray, var: FloatArray) -> float:
    """``σ² ≥ 0`` with the mean of ``min(e² / (var + σ²), c)`` equal to its χ²₁ value.

    The mean falls as ``σ²`` grows, so bisection finds the one root (``0`` when the fit's
    variances alone already explain the residuals).
    """
    if _winsorized_mean(e2, var, 0.0) <= _WINSOR_MEAN:
        return 0.0
    lo, hi = 0.0, max(float(np.mean(e2)), 1e-12)
    while _winsorized_mean(e2, var, hi) > _WINSOR_MEAN:
        hi *= 4.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _winsorized_mean(e2, var, mid) > _WINSOR_MEAN:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class LineModelErrorEstimator:
    """Estimates ``(σ_o, σ_a)`` from the graph's line factors (module docstring).

    Parameters
    ----------
    sigma_offset_m, sigma_angle_rad : float
        The configured values: used until there are ``min_samples`` residuals.
    min_observations : int
        Only factors of landmarks with at least this many factors count.
    min_samples : int
        Least number of such factors for an estimate.
    """

    def __init__(
        self,
        sigma_offset_m: float,
        sigma_angle_rad: float,
        min_observations: int = 5,
        min_samples: int = 50,
    ) -> None:
        self.sigma_offset_m = sigma_offset_m
        self.sigma_angle_rad = sigma_angle_rad
        self.min_observations = min_observations
        self.min_samples = min_samples
        self.samples = 0
        self.updates = 0

    @property
    def sigmas(self) -> tuple[float, float]:
        """The current ``(σ_o, σ_a)`` (m, rad)."""
        return self.sigma_offset_m, self.sigma_angle_rad

    def update(self, graph: LineGraph, fit_cov: FloatArray) -> bool:
        """Estimate from the graph's current line factors; returns whether it did.

        ``fit_cov`` ``(F, 2, 2)``: each factor's fit covariance (without model error).
        """
        g = graph
        if g.n_line_factors == 0:
            return False
        counts = g.observation_counts()
        f = np.flatnonzero(counts[g.factor_landmark] >= self.min_observations)
        if f.size < self.min_samples:
            return False
        e, var = midpoint_residuals(g, f, fit_cov)
        self.sigma_offset_m = float(np.sqrt(_sigma2_for_moment(e[:, 0] ** 2, var[:, 0])))
        self.sigma_angle_rad = float(np.sqrt(_sigma2_for_moment(e[:, 1] ** 2, var[:, 1])))
        self.samples = int(f.size)
        self.updates += 1
        return True

    def summary(self) -> dict[str, float | int]:
        """The estimate and how it was obtained (for ``summary.json``)."""
        return {
            "sigma_offset_m": self.sigma_offset_m,
            "sigma_angle_rad": self.sigma_angle_rad,
            "samples": self.samples,
            "updates": self.updates,
        }


class LineReweighting:
    """Estimates the model error on schedule and re-weights the graph's line factors with it.

    The factors are re-weighted when either component differs by more than
    :data:`REWEIGHT_CHANGE` (relative) from what they were weighted with: the estimate settles
    within the first few hundred keyframes, while the graph is small.  A back-end holding the
    factors must be restarted after a re-weighting.

    Parameters
    ----------
    estimator : LineModelErrorEstimator
    enabled : bool
        False: nothing is ever estimated (the configured model error is kept).
    """

    def __init__(self, estimator: LineModelErrorEstimator, enabled: bool) -> None:
        self.estimator = estimator
        self.enabled = enabled
        self.weighted_with = estimator.sigmas
        self._due = EveryKeyframes()

    def keyframe(self, graph: LineGraph, fit_cov: FloatArray) -> bool:
        """Count a keyframe; estimate when due.  Returns whether the factors were re-weighted."""
        est = self.estimator
        interval = ESTIMATE_INTERVAL_KEYFRAMES if est.updates else FIRST_ESTIMATE_KEYFRAMES
        return self._due.tick(self.enabled, interval) and self.estimate(graph, fit_cov)

    def estimate(self, graph: LineGraph, fit_cov: FloatArray) -> bool:
        """Estimate now; re-weight when moved.  Returns whether the factors were re-weighted."""
        if not self.enabled or not self.estimator.update(graph, fit_cov):
            return False
        new, old = self.estimator.sigmas, self.weighted_with
        if all(abs(n - o) <= REWEIGHT_CHANGE * max(o, 1e-6) for n, o in zip(new, old, strict=True)):
            return False
        g = graph
        cov = np.asarray(fit_cov) + model_error_covariance(
            g.factor_z, g.factor_endpoints, new[0], new[1]
        )
        g.set_line_factor_covariances(np.arange(g.n_line_factors), cov)
        self.weighted_with = new
        return True
