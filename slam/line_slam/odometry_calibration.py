"""The odometry's persistent error and the laser's unstated mounting, estimated during the run.

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

A laser mounted away from the point whose motion the odometry reports, where the log does not
say so, errs the same way too: every turn ``θ`` moves the laser by ``(R(θ) − I) m`` that the
odometry does not show.  :class:`MountingEstimator` estimates ``m`` from the graph's own
estimate of every keyframe step (``[slam] odometry_calibration = "mounting"``, the default).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.special import gammaincinv

from slam.geometry import pose_between, pose_log
from slam.graph.problem import GrowableArray
from slam.models.motion import OdometryCalibration, mounting_jacobian

__all__ = [
    "SIGNIFICANCE",
    "MountingEstimator",
    "OdometryAndMountingCalibrator",
    "OdometryCalibrator",
]

FloatArray = NDArray[np.float64]

#: χ² (3 dof) at 99.99 %: a sample beyond it under the first fit is left out of the second.
_OUTLIER_CHI2 = 21.1

#: The mounting is applied when its χ² against none (its own covariance) exceeds this quantile.
SIGNIFICANCE = 0.99

#: A step informs the mounting only if it turned by more than this many standard deviations of
#: its heading's error.
_TURN_SIGMAS = 3.0


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
        # per sample: the calibration's Jacobian at the raw step (3×5), the weight (Q + P_L)⁻¹
        # and the error of the raw step
        self._A = GrowableArray((3, 5))
        self._W = GrowableArray((3, 3))
        self._nu = GrowableArray((3,))
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
        applied = np.array(list(self.calibration.as_dict().values()))
        # the error of the raw step, less the mounting (if any) as now estimated
        nu_raw = np.asarray(nu, dtype=float) + A @ applied
        self._A.append(A[None])
        self._W.append(np.linalg.inv(0.5 * (cov + cov.T))[None])
        self._nu.append(nu_raw[None])

    @property
    def n_samples(self) -> int:
        """Registrations' samples kept."""
        return len(self._nu)

    def keyframe(self) -> bool:
        """Count a keyframe; refit when due.  Returns whether the calibration changed."""
        self._since += 1
        if self.n_samples < self.min_samples or self._since < self.update_every:
            return False
        self._since = 0
        A, W, target = self._A.data[:, :, :3], self._W.data, self._target()
        theta, info = self._fit(A, W, target)
        # gross outliers (slips) under the first fit left out of the second
        r = target - A @ theta
        keep = np.einsum("ni,nij,nj->n", r, W, r) <= _OUTLIER_CHI2
        theta, info = self._fit(A[keep], W[keep], target[keep])
        self._info = info
        self.calibration = replace(
            self.calibration,
            scale=float(theta[0]),
            turn_gain=float(theta[1]),
            heading_drift_rad_per_m=float(theta[2]),
        )
        self.fits += 1
        return True

    def set_mounting(self, mount_x_m: float, mount_y_m: float) -> None:
        """The laser's mounting, estimated elsewhere: applied with the three biases.

        The samples' errors are referred to the steps seen from this mounting from the next fit
        on (:class:`OdometryAndMountingCalibrator`).
        """
        self.calibration = replace(self.calibration, mount_x_m=mount_x_m, mount_y_m=mount_y_m)

    def _target(self) -> FloatArray:
        """The samples' errors of the raw steps seen from the current mounting, ``(n, 3)``."""
        c = self.calibration
        mount = np.array([c.mount_x_m, c.mount_y_m])
        return np.asarray(self._nu.data - self._A.data[:, :, 3:] @ mount, dtype=np.float64)

    def _fit(self, A: FloatArray, W: FloatArray, nu: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Weighted least squares with the prior: (θ, information).

        ``A`` the samples' Jacobians ``(n, 3, 3)``, ``W`` their weights, ``nu`` their errors.
        """
        WA = W @ A
        info = self._prior_info + np.einsum("nik,nil->kl", A, WA)
        vec = np.einsum("nik,ni->k", WA, nu)
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


def _significant(m: FloatArray, info: FloatArray) -> bool:
    """Whether a mounting fit tells itself from none: ``mᵀ C⁻¹ m`` beyond χ²₂'s quantile."""
    return bool(m @ info @ m > 2.0 * float(gammaincinv(1.0, SIGNIFICANCE)))


def _fit_report(m: FloatArray, info: FloatArray) -> dict[str, float]:
    """A mounting fit and its standard deviations, by name (``summary.json``)."""
    sd = np.sqrt(np.diag(np.linalg.inv(info)))
    return {
        "fit_mount_x_m": float(m[0]),
        "sd_mount_x_m": float(sd[0]),
        "fit_mount_y_m": float(m[1]),
        "sd_mount_y_m": float(sd[1]),
    }


class MountingEstimator:
    """The laser's unstated mounting, from the graph's own estimate of every keyframe step.

    Each keyframe step whose factor is the (calibrated) odometry is kept with the step the
    graph was given, the mounting it was calibrated with and its covariance ``Q``.  At each
    refit every such step is compared with the graph's current estimate of it
    (``x_{i-1}⁻¹ x_i``, smoothed by all the lines seen since): ``ν = Log(used⁻¹ · estimate)``,
    referred back to the raw step by the mounting applied when it was given, and regressed on
    the mounting's Jacobian at the estimated turn, ``I − R(θ)ᵀ``
    (:func:`~slam.models.motion.mounting_jacobian`): weighted least squares (weights ``Q⁻¹``)
    with a zero-mean prior, a first fit, then the steps whose squared Mahalanobis residual
    exceeds χ²₃'s 99.99 % quantile left out and a second fit.  Only turns beyond three
    standard deviations of their heading (``Q``) inform it: below that the regressor is mostly
    noise.  The fit is applied only where the steps tell it from none, ``mᵀ C⁻¹ m`` beyond
    χ²₂'s 99 % quantile (``C`` its covariance; :data:`SIGNIFICANCE`); the later steps of
    keyframes and of the scans between them are then calibrated.

    Unlike the registrations' samples of :class:`OdometryCalibrator` this uses every step,
    not only those whose registration pinned the keyframe down, which on a turn depends on the
    very error measured.  The graph's estimate of a step is the odometry fused with the lines,
    so ``ν`` holds only part of the odometry's error and a fit falls short of the mounting;
    refitted as the calibration is applied, it tends to where the graph and the calibrated
    odometry agree.

    Parameters
    ----------
    prior_sigma_m : float
        Standard deviation of the zero-mean prior of each of ``(x, y)`` (m).
    min_samples, update_every : int
        The first fit needs ``min_samples`` turning steps; refitted every ``update_every``
        keyframes.
    """

    parameters = "mounting"

    def __init__(
        self, prior_sigma_m: float = 0.3, min_samples: int = 30, update_every: int = 25
    ) -> None:
        self.calibration = OdometryCalibration()
        self._prior_info = np.eye(2) / prior_sigma_m**2
        self._info = self._prior_info.copy()
        self._ends = GrowableArray((2,), dtype=np.intp)
        self._used = GrowableArray((3,))
        self._mount_used = GrowableArray((2,))
        self._Q = GrowableArray((3, 3))
        self.min_samples = min_samples
        self.update_every = update_every
        self._since = 0
        self.fits = 0
        self.n_turns = 0
        self.estimate = np.zeros(2)
        self.significant = False

    @property
    def n_samples(self) -> int:
        """Keyframe steps kept."""
        return len(self._ends)

    def apply(self, delta: FloatArray) -> FloatArray:
        """The step calibrated with the current estimate."""
        return np.asarray(self.calibration.apply(delta), dtype=float)

    def add_step(self, first: int, second: int, used_delta: FloatArray, Q: FloatArray) -> None:
        """The odometry factor between poses ``first`` and ``second``.

        ``used_delta``: the step it was given (calibrated with the current mounting); ``Q``
        its covariance.
        """
        self._ends.append(np.array([[first, second]]))
        self._used.append(np.asarray(used_delta, dtype=float)[None])
        c = self.calibration
        self._mount_used.append(np.array([[c.mount_x_m, c.mount_y_m]]))
        self._Q.append(np.asarray(Q, dtype=float)[None])

    def keyframe(self, poses: FloatArray) -> bool:
        """Count a keyframe; refit from ``poses`` (the graph's estimate) when due.

        Returns whether the calibration changed.
        """
        self._since += 1
        if self._since < self.update_every or self.n_samples == 0:
            return False
        fitted = self._fit(poses)
        if fitted is None:
            return False
        self._since = 0
        m, info, self.n_turns = fitted
        self._info, self.estimate = info, m
        self.significant = _significant(m, info)
        self.fits += 1
        new = OdometryCalibration(
            mount_x_m=float(m[0]) if self.significant else 0.0,
            mount_y_m=float(m[1]) if self.significant else 0.0,
        )
        changed = new != self.calibration
        self.calibration = new
        return changed

    def check(self, poses: FloatArray) -> dict[str, float | int | bool] | None:
        """The fit to ``poses`` (e.g. the final estimate), not applied; None without enough turns.

        The mounting is the total since the raw steps (``fit_mount_x_m``, ``fit_mount_y_m``),
        with ``sd_mount_*``, ``turning_samples`` and ``significant``.
        """
        fitted = self._fit(poses) if self.n_samples else None
        if fitted is None:
            return None
        m, info, n = fitted
        return {**_fit_report(m, info), "turning_samples": n, "significant": _significant(m, info)}

    def _fit(self, poses: FloatArray) -> tuple[FloatArray, FloatArray, int] | None:
        """The mounting fitted to the steps as ``poses`` estimate them: (m, information, turns).

        None with fewer than ``min_samples`` turns.
        """
        ends, Q = self._ends.data, self._Q.data
        estimate = pose_between(poses[ends[:, 0]], poses[ends[:, 1]])
        turning = np.abs(estimate[:, 2]) > _TURN_SIGMAS * np.sqrt(Q[:, 2, 2])
        n_turns = int(np.count_nonzero(turning))
        if n_turns < self.min_samples:
            return None
        estimate, Q = estimate[turning], Q[turning]
        nu = pose_log(pose_between(self._used.data[turning], estimate))
        A = mounting_jacobian(estimate[:, 2])
        nu = nu + np.einsum("nij,nj->ni", A, self._mount_used.data[turning])
        W = np.linalg.inv(0.5 * (Q + np.swapaxes(Q, 1, 2)))
        WA = W @ A

        def fit(keep: NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
            info = self._prior_info + np.einsum("nik,nil->kl", A[keep], WA[keep])
            vec = np.einsum("nik,ni->k", WA[keep], nu[keep])
            return np.asarray(np.linalg.solve(info, vec), dtype=np.float64), info

        m, info = fit(np.ones(nu.shape[0], bool))
        r = nu - np.einsum("nij,j->ni", A, m)
        m, info = fit(np.einsum("ni,nij,nj->n", r, W, r) <= _OUTLIER_CHI2)
        return m, info, n_turns

    def summary(self) -> dict[str, float | int | str | bool]:
        """``summary.json`` ``odometry_calibration``: the mounting applied and the last fit.

        ``mount_x_m``, ``mount_y_m`` as applied (zero until a fit is significant), the other
        parameters of :class:`~slam.models.motion.OdometryCalibration` (zero),
        ``significant``, ``fit_mount_*`` and ``sd_mount_*`` (the last fit and its standard
        deviations), ``samples`` (keyframe steps kept) and ``turning_samples`` (those that
        informed the last fit).
        """
        out: dict[str, float | int | str | bool] = {
            "parameters": self.parameters,
            "samples": self.n_samples,
            "turning_samples": self.n_turns,
            "fits": self.fits,
            "significant": self.significant,
        }
        out.update(self.calibration.as_dict())
        out.update(_fit_report(self.estimate, self._info))
        return out


class OdometryAndMountingCalibrator:
    """The odometry's persistent error and the laser's unstated mounting, estimated together.

    The three biases (scale, turn gain, heading drift) from the registrations' samples
    (:class:`OdometryCalibrator`) and the mounting from the graph's estimate of every keyframe
    step (:class:`MountingEstimator`), each as its own estimator does, applied together
    (``[slam] odometry_calibration = "estimated"``).  The registrations' samples are referred to
    the steps seen from the mounting as currently estimated, so the biases are fitted to what
    the mounting leaves; the graph's steps are compared with the steps as given, the biases of
    their time taken out, so the mounting is fitted to what the biases leave.  The two act on
    different parts of a step (the mounting only moves a turning step's translation across
    ``(R(θ) − I) m``; the biases scale its length, its turn, and add heading per metre).
    """

    parameters = "scale, turn gain, heading drift and mounting"

    def __init__(self) -> None:
        self.bias = OdometryCalibrator()
        self.mounting = MountingEstimator()

    @property
    def calibration(self) -> OdometryCalibration:
        """The five parameters as applied now."""
        return self.bias.calibration

    def apply(self, delta: FloatArray) -> FloatArray:
        """The step calibrated with the current estimate."""
        return self.bias.apply(delta)

    def add(self, raw_delta: FloatArray, nu: FloatArray, cov: FloatArray) -> None:
        """A registration's sample (:meth:`OdometryCalibrator.add`)."""
        self.bias.add(raw_delta, nu, cov)

    def add_step(self, first: int, second: int, used_delta: FloatArray, Q: FloatArray) -> None:
        """A keyframe step's odometry factor (:meth:`MountingEstimator.add_step`)."""
        self.mounting.add_step(first, second, used_delta, Q)

    def keyframe(self, poses: FloatArray) -> bool:
        """Count a keyframe; refit either part when due.  Returns whether anything changed."""
        changed = self.bias.keyframe()
        if self.mounting.keyframe(poses):
            c = self.mounting.calibration
            self.bias.set_mounting(c.mount_x_m, c.mount_y_m)
            changed = True
        return changed

    def check(self, poses: FloatArray) -> dict[str, float | int | bool] | None:
        """The mounting's fit to ``poses``, not applied (:meth:`MountingEstimator.check`)."""
        return self.mounting.check(poses)

    def summary(self) -> dict[str, float | int | str | bool]:
        """``summary.json`` ``odometry_calibration``: both parts.

        The five parameters as applied, the biases' standard deviations and samples
        (``samples``, ``fits``), and the mounting's last fit (``significant``,
        ``fit_mount_*``, ``sd_mount_*``, ``steps``, ``turning_samples``, ``mounting_fits``).
        """
        mounting = self.mounting.summary()
        out: dict[str, float | int | str | bool] = {"parameters": self.parameters}
        out.update(self.bias.summary())
        out.update(
            {
                "steps": mounting["samples"],
                "turning_samples": mounting["turning_samples"],
                "mounting_fits": mounting["fits"],
                "significant": mounting["significant"],
            }
        )
        out.update({k: v for k, v in mounting.items() if k.startswith(("fit_", "sd_"))})
        return out
