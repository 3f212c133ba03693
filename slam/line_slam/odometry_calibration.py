"""The odometry's persistent error (scale, turn gain, heading drift), estimated during the run.

The motion model is a random walk: it describes errors that are independent from step to step.
An odometry whose wheels or gyro are miscalibrated errs the same way on every step, and over a
long stretch its error outgrows the model (``scripts/odometry_bias.py``).  Where a keyframe's
lines pin its pose down, the registration measured the odometry's error on that step, ``ν``
(:func:`slam.line_slam.odometry_noise.odometry_error`).  A calibration ``θ`` (translation scale,
turn gain, heading drift per metre, :class:`slam.models.motion.OdometryCalibration`) explains it
to first order as

``ν ≈ A(δ) θ + ε``,   ``ε ~ N(0, Q(δ) + P_L)``,

with ``A`` the calibration's Jacobian at the raw step ``δ``, ``Q`` the motion noise and ``P_L``
the lines' covariance.  ``θ`` is the weighted least-squares solution over the samples, with a
zero-mean Gaussian prior (``prior_sigmas``), refitted every ``update_every`` keyframes once
``min_samples`` are in: a first fit, then the samples whose squared Mahalanobis residual
exceeds χ²₃'s 99.99 % quantile (21.1: a wheel slip the scan matcher let through) left out,
and a second fit; later steps are calibrated before the front end and the graph use them.
A sample is measured against the calibrated prediction; it is referred back to the raw step by
adding ``A(δ) θ_applied``.  Steps whose covariance the log states (laser odometry) are not
calibrated.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.models.motion import OdometryCalibration

__all__ = ["OdometryCalibrator"]

FloatArray = NDArray[np.float64]

#: χ² (3 dof) at 99.99 %: a sample beyond it under the first fit is left out of the second.
_OUTLIER_CHI2 = 21.1


class OdometryCalibrator:
    """Collects the registrations' odometry errors and fits the calibration (module docstring).

    Parameters
    ----------
    prior_sigmas : tuple of float
        Standard deviations of the zero-mean prior of (scale, turn gain, heading drift rad/m).
    min_samples, update_every : int
        The first fit needs ``min_samples`` samples; refitted every ``update_every`` keyframes.
    """

    def __init__(
        self,
        prior_sigmas: tuple[float, float, float] = (0.05, 0.05, 0.05),
        min_samples: int = 30,
        update_every: int = 25,
    ) -> None:
        self.calibration = OdometryCalibration()
        self._info = np.diag(1.0 / np.square(np.asarray(prior_sigmas, dtype=float)))
        self._prior_info = self._info.copy()
        self._samples: list[tuple[FloatArray, FloatArray, FloatArray]] = []
        self.n_samples = 0
        self.min_samples = min_samples
        self.update_every = update_every
        self._since = 0
        self.fits = 0

    def apply(self, delta: FloatArray) -> FloatArray:
        """The step calibrated with the current estimate."""
        return np.asarray(self.calibration.apply(delta), dtype=float)

    def add(self, raw_delta: FloatArray, nu: FloatArray, cov: FloatArray) -> None:
        """One sample: the error ``nu`` of the calibrated step, covariance ``cov`` (Q + P_L)."""
        A = self.calibration.jacobian(raw_delta)
        theta = np.array(
            [
                self.calibration.scale,
                self.calibration.turn_gain,
                self.calibration.heading_drift_rad_per_m,
            ]
        )
        nu_raw = np.asarray(nu, dtype=float) + A @ theta
        W = np.linalg.inv(0.5 * (cov + cov.T))
        self._samples.append((A, np.asarray(W, np.float64), np.asarray(nu_raw, np.float64)))
        self.n_samples += 1

    def keyframe(self) -> bool:
        """Count a keyframe; refit when due.  Returns whether the calibration changed."""
        self._since += 1
        if self.n_samples < self.min_samples or self._since < self.update_every:
            return False
        self._since = 0
        theta, info = self._fit(np.ones(len(self._samples), bool))
        # gross outliers (slips) under the first fit left out of the second
        keep = np.array(
            [
                float((nu - A @ theta) @ W @ (nu - A @ theta)) <= _OUTLIER_CHI2
                for A, W, nu in self._samples
            ]
        )
        theta, info = self._fit(keep)
        self._info = info
        self.calibration = OdometryCalibration(float(theta[0]), float(theta[1]), float(theta[2]))
        self.fits += 1
        return True

    def _fit(self, keep: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
        """Weighted least squares with the prior over the samples ``keep``: (θ, information)."""
        info = self._prior_info.copy()
        vec = np.zeros(3)
        for (A, W, nu), k in zip(self._samples, keep, strict=True):
            if k:
                info += A.T @ W @ A
                vec += A.T @ W @ nu
        return np.asarray(np.linalg.solve(info, vec), dtype=np.float64), info

    def summary(self) -> dict[str, float | int]:
        """``summary.json`` ``odometry_calibration``: the estimate and its standard deviations."""
        sd = np.sqrt(np.diag(np.linalg.inv(self._info)))
        out: dict[str, float | int] = {"samples": self.n_samples, "fits": self.fits}
        out.update(self.calibration.as_dict())
        out.update(
            {
                "sd_scale": float(sd[0]),
                "sd_turn_gain": float(sd[1]),
                "sd_heading_drift_rad_per_m": float(sd[2]),
            }
        )
        return out
