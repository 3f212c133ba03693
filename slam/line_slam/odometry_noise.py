"""The odometry's noise, estimated during the run from the front end's registrations.

The motion model (:class:`slam.models.motion.MotionNoiseConfig`) says how uncertain a relative
motion ``δ`` is: ``σ_xy² = a₀ + a₁·d + a₂·|dθ|`` and ``σ_θ² = b₀ + b₁·d + b₂·|dθ|`` with ``d``
the distance and ``|dθ|`` the turn.  The configured values are a prior; each log's odometry is
its own.  Wherever a keyframe's lines pin its pose down in every direction (the registration's
posterior covariance below a quarter of the prediction's in every direction), the registration
measured the odometry's error on that step:

``ν = (I + P_L I_P) c``,   ``E[ν νᵀ] ≈ Q_true(δ) + P_L``,

with ``c = x_reg ⊖ x̂`` the registration's correction of the prediction, ``I_P`` the
prediction's information and ``P_L`` the lines' own covariance.  The squared residuals (minus
the lines' part) are regressed on ``(1, d, |dθ|)`` by weighted, non-negative least squares with
the weights of a χ² variable (``Var(σ² z²) = 2σ⁴``), gross outliers (beyond 4σ under the
current fit: wheel slip, a wrong pairing) left out, and the prior counted as ``prior_weight``
samples.  The estimate is refreshed every ``update_every`` keyframes once
``min_samples`` are in; later predictions and odometry factors use it.

The model describes errors that are independent from step to step.  Whether they are, over
the stretches the registrations measure, :meth:`MotionNoiseEstimator.span_consistency` tells:
over runs of consecutive measured keyframes, the composed error of ``n`` steps (each step's
``ν`` applied after its motion, ``Log((∏ δᵢ)⁻¹ ∏ δᵢ Exp(νᵢ))``) against the model's covariance
of the composed motion (``Σ Jᵢ Q(δᵢ) Jᵢᵀ``, each step's error carried to the end with its
heading's lever arm, plus the last registration's ``P_L`` as for one step): a mean NEES near 3
for every ``n`` says the errors add up as the model says; rising with ``n``, they are
correlated (a bias), falling, anti-correlated.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import product

import numpy as np
from numpy.typing import NDArray

from slam.geometry import compose_covariance, pose_between, pose_compose, pose_exp, pose_log
from slam.models.motion import MotionNoiseConfig

__all__ = ["SPAN_KEYFRAMES", "MotionNoiseEstimator", "odometry_error"]

#: Run lengths (keyframes) that :meth:`MotionNoiseEstimator.span_consistency` reports.
SPAN_KEYFRAMES = (1, 2, 4, 8, 16)

FloatArray = NDArray[np.float64]

_FLOOR_XY = 1e-3**2
_FLOOR_TH = 1e-4**2


@dataclass(frozen=True)
class _Fit:
    xy: FloatArray
    theta: FloatArray


def _params(model: MotionNoiseConfig) -> _Fit:
    return _Fit(
        np.array([model.sigma_xy_min_m**2, model.sigma_xy_per_m**2, model.sigma_xy_per_rad**2]),
        np.array(
            [model.sigma_theta_min_rad**2, model.sigma_theta_per_m**2, model.sigma_theta_per_rad**2]
        ),
    )


def bounded_least_squares(A: FloatArray, b: FloatArray, lower: FloatArray) -> FloatArray:
    """``argmin ‖A p − b‖²`` subject to ``p ≥ lower``, exactly, for a few unknowns.

    The problem is convex, so its minimum is the unconstrained minimum of the face of the box
    on which it lies: every face (each subset of the bounds held, ``2ⁿ`` of them) is solved
    on the normal equations ``AᵀA``, and the feasible solution of least cost is the minimum.
    What ``scipy.optimize.lsq_linear`` computes iteratively (to its tolerance) for the
    three unknowns of the motion model, at a small fraction of its cost.

    Parameters
    ----------
    A : ndarray, shape (m, n)
    b : ndarray, shape (m,)
    lower : ndarray, shape (n,)
        Lower bounds (finite).

    Returns
    -------
    ndarray, shape (n,)
    """
    G = A.T @ A
    g = A.T @ b
    n = lower.size
    best, best_cost = lower.astype(float), np.inf
    for held in product((False, True), repeat=n):
        fixed = np.array(held)
        p = np.where(fixed, lower, 0.0)
        free = ~fixed
        if free.any():
            rhs = g[free] - G[np.ix_(free, fixed)] @ lower[fixed]
            sol, *_ = np.linalg.lstsq(G[np.ix_(free, free)], rhs, rcond=None)
            if np.any(sol < lower[free]):
                continue
            p[free] = sol
        cost = float(p @ G @ p - 2.0 * g @ p)
        if cost < best_cost:
            best, best_cost = p, cost
    return best


def _fit_one(
    A: FloatArray, y: FloatArray, p0: FloatArray, prior_weight: float, floor: float
) -> FloatArray:
    """Weighted non-negative least squares of ``y ≈ A p`` with a prior ``p0`` (module doc)."""
    p = p0.copy()
    keep = np.ones(y.size, dtype=bool)
    for _ in range(3):
        m = np.maximum(A @ p, floor)
        keep = y <= 16.0 * m
        w = 1.0 / (np.sqrt(2.0) * m)
        # the prior as pseudo-samples at the same motions, prior_weight of them in all
        w0 = np.sqrt(prior_weight / max(int(keep.sum()), 1)) * w
        rows = np.vstack([A[keep] * w[keep, None], A[keep] * w0[keep, None]])
        rhs = np.concatenate([y[keep] * w[keep], (A[keep] @ p0) * w0[keep]])
        if rows.shape[0] < 3:
            return p0
        p = bounded_least_squares(rows, rhs, np.array([floor, 0.0, 0.0]))
    return p


def odometry_error(
    correction: FloatArray, prior_cov: FloatArray, posterior_cov: FloatArray
) -> tuple[FloatArray, FloatArray] | None:
    """The odometry's error on a step as a registration measured it, ``(ν, P_L)``, or None.

    None unless the registration pins the pose down in every direction (its posterior below a
    quarter of the prediction's); else ``ν = (I + P_L I_P) c`` and the lines' own covariance
    ``P_L`` (module docstring).
    """
    P0 = np.asarray(prior_cov, dtype=float)
    Pp = np.asarray(posterior_cov, dtype=float)
    L = np.linalg.cholesky(P0)
    Li = np.linalg.inv(L)
    ratio = np.linalg.eigvalsh(Li @ Pp @ Li.T)
    if ratio.max() > 0.25:
        return None
    I_P = np.linalg.inv(P0)
    I_post = np.linalg.inv(Pp)
    P_L = np.linalg.inv(I_post - I_P)
    nu = (np.eye(3) + P_L @ I_P) @ np.asarray(correction, dtype=float)
    return nu, P_L


class MotionNoiseEstimator:
    """Collects registration residuals and fits the motion model (module docstring).

    Parameters
    ----------
    prior : MotionNoiseConfig
        The configured model: the starting point and the prior of the fit.
    prior_weight : float
        How many samples the prior counts as.
    min_samples, update_every : int
        The first fit needs ``min_samples`` samples; the model is refitted every
        ``update_every`` keyframes.
    """

    def __init__(
        self,
        prior: MotionNoiseConfig,
        prior_weight: float = 30.0,
        min_samples: int = 30,
        update_every: int = 25,
    ) -> None:
        self.prior = prior
        self.model = prior
        self.prior_weight = prior_weight
        self.min_samples = min_samples
        self.update_every = update_every
        self._features: list[tuple[float, float, float]] = []
        self._y_xy: list[float] = []
        self._y_th: list[float] = []
        self._since = 0
        self.fits = 0
        # every sample with its keyframe's number, for span_consistency
        self._keyframes = 0
        self._sample_keyframe: list[int] = []
        self._sample_delta: list[FloatArray] = []
        self._sample_nu: list[FloatArray] = []
        self._sample_P_L: list[FloatArray] = []

    @property
    def n_samples(self) -> int:
        """Samples collected."""
        return len(self._y_th)

    def add(
        self,
        delta: FloatArray,
        correction: FloatArray,
        prior_cov: FloatArray,
        posterior_cov: FloatArray,
    ) -> bool:
        """Offer one registration; returns whether it was used as a sample.

        Parameters
        ----------
        delta : ndarray, shape (3,)
            The odometry's motion from the previous keyframe.
        correction : ndarray, shape (3,)
            ``x_reg ⊖ x̂`` (right tangent space).
        prior_cov, posterior_cov : ndarray, shape (3, 3)
            The registration's prior (prediction) and posterior covariances.
        """
        measured = odometry_error(correction, prior_cov, posterior_cov)
        if measured is None:
            return False
        self.add_error(delta, *measured)
        return True

    def add_error(self, delta: FloatArray, nu: FloatArray, P_L: FloatArray) -> None:
        """One sample already measured by :func:`odometry_error`: ``nu`` and ``P_L``."""
        d = float(np.hypot(delta[0], delta[1]))
        turn = abs(float(delta[2]))
        self._sample_keyframe.append(self._keyframes)
        self._sample_delta.append(np.array(delta, dtype=float))
        self._sample_nu.append(np.array(nu, dtype=float))
        self._sample_P_L.append(np.array(P_L, dtype=float))
        self._features.append((1.0, d, turn))
        self._y_xy.append(0.5 * (nu[0] ** 2 + nu[1] ** 2) - 0.5 * (P_L[0, 0] + P_L[1, 1]))
        self._y_th.append(float(nu[2] ** 2 - P_L[2, 2]))

    def keyframe(self) -> bool:
        """Count a keyframe; refit when due.  Returns whether the model changed."""
        self._since += 1
        self._keyframes += 1
        if self.n_samples < self.min_samples or self._since < self.update_every:
            return False
        self._since = 0
        A = np.asarray(self._features, dtype=float)
        p0 = _params(self.prior)
        xy = _fit_one(A, np.asarray(self._y_xy), p0.xy, self.prior_weight, _FLOOR_XY)
        th = _fit_one(A, np.asarray(self._y_th), p0.theta, self.prior_weight, _FLOOR_TH)
        self.model = replace(
            self.prior,
            sigma_xy_min_m=float(np.sqrt(xy[0])),
            sigma_xy_per_m=float(np.sqrt(xy[1])),
            sigma_xy_per_rad=float(np.sqrt(xy[2])),
            sigma_theta_min_rad=float(np.sqrt(th[0])),
            sigma_theta_per_m=float(np.sqrt(th[1])),
            sigma_theta_per_rad=float(np.sqrt(th[2])),
        )
        self.fits += 1
        return True

    def span_consistency(
        self, spans: tuple[int, ...] = SPAN_KEYFRAMES
    ) -> list[dict[str, float | int]]:
        """The samples' NEES over runs of consecutive keyframes, under the current model.

        Each run of consecutive keyframes that all gave a sample is cut into spans of ``n``
        keyframes (from its start, the remainder left out); each span's composed error is
        compared with the model's covariance of its composed motion (module docstring).

        Parameters
        ----------
        spans : tuple of int
            The span lengths ``n`` (keyframes).

        Returns
        -------
        list of dict
            Per ``n`` with at least one span: ``keyframes`` (``n``), ``spans``, ``path_m``
            (their mean path length) and ``nees`` (their mean NEES, 3 dof).
        """
        keyframes = np.asarray(self._sample_keyframe, dtype=int)
        if keyframes.size == 0:
            return []
        delta = np.asarray(self._sample_delta)
        Q = self.model.covariance(delta)
        runs = np.split(np.arange(keyframes.size), np.flatnonzero(np.diff(keyframes) != 1) + 1)
        out: list[dict[str, float | int]] = []
        for n in spans:
            nees: list[float] = []
            path: list[float] = []
            for run in runs:
                for start in range(0, run.size - n + 1, n):
                    steps = run[start : start + n]
                    odometry = np.zeros(3)
                    measured = np.zeros(3)
                    C = np.zeros((3, 3))  # the composed motion's, each step's error at its end
                    for i in steps:
                        odometry = pose_compose(odometry, delta[i])
                        measured = pose_compose(
                            pose_compose(measured, delta[i]), pose_exp(self._sample_nu[i])
                        )
                        C = compose_covariance(C, delta[i], Q[i])
                    e = pose_log(pose_between(odometry, measured))
                    C = C + self._sample_P_L[steps[-1]]
                    try:
                        nees.append(float(e @ np.linalg.solve(C, e)))
                    except np.linalg.LinAlgError:
                        continue
                    path.append(float(np.hypot(delta[steps, 0], delta[steps, 1]).sum()))
            if nees:
                out.append(
                    {
                        "keyframes": n,
                        "spans": len(nees),
                        "path_m": float(np.mean(path)),
                        "nees": float(np.mean(nees)),
                    }
                )
        return out

    def summary(self) -> dict[str, object]:
        """The current model and how it was obtained (for ``summary.json``)."""
        m = self.model
        return {
            "samples": self.n_samples,
            "fits": self.fits,
            "sigma_xy_min_m": m.sigma_xy_min_m,
            "sigma_xy_per_m": m.sigma_xy_per_m,
            "sigma_xy_per_rad": m.sigma_xy_per_rad,
            "sigma_theta_min_rad": m.sigma_theta_min_rad,
            "sigma_theta_per_m": m.sigma_theta_per_m,
            "sigma_theta_per_rad": m.sigma_theta_per_rad,
            "span_nees": self.span_consistency(),
        }
