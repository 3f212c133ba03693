"""Odometry models shared by both estimators.

* :class:`MotionNoiseConfig`: a random walk in distance travelled and angle turned; the graph's
  odometry factors and the EKF's prediction use the same noise.
* :class:`OdometryCalibration`: a persistent error of the odometry (scale, turn gain, heading
  drift per metre), applied to its steps.
* :func:`moved_enough`: the rule on the odometry since the last keyframe that makes a scan a
  keyframe (graph) or an update (EKF).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.validate import nonneg, positive

__all__ = ["MotionNoiseConfig", "OdometryCalibration", "moved_enough"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MotionNoiseConfig:
    """Odometry noise: a random walk in distance travelled and angle turned.

    The covariance of a relative motion ``(dx, dy, dθ)`` (right tangent space, body frame) is
    ``diag(σ_xy², σ_xy², σ_θ²)`` with

    ``σ_xy² = sigma_xy_min_m² + sigma_xy_per_m²·d + sigma_xy_per_rad²·|dθ|``,
    ``σ_θ²  = sigma_theta_min_rad² + sigma_theta_per_m²·d + sigma_theta_per_rad²·|dθ|``,

    ``d = √(dx² + dy²)``.  Variances grow linearly, so chaining steps gives (to first order) the
    same uncertainty as one step over the same path: ``sigma_xy_per_m`` is the standard
    deviation after 1 m (m/√m), ``sigma_theta_per_rad`` after turning 1 rad (rad/√rad), etc.

    Attributes
    ----------
    sigma_xy_per_m : float
        Position noise per axis after 1 m of travel (m/√m).
    sigma_xy_per_rad : float
        Position noise per axis after turning 1 rad (m/√rad).
    sigma_theta_per_m : float
        Heading noise after 1 m of travel (rad/√m).
    sigma_theta_per_rad : float
        Heading noise after turning 1 rad (rad/√rad).  ``scripts/calibrate_odometry.py``
        fits ``sigma_xy_per_m``, ``sigma_theta_per_m`` and this one to a log's short
        relations; the defaults are one setting for all logs.
    sigma_xy_min_m, sigma_theta_min_rad : float
        Floors per step (m, rad), so that a standstill is not a perfect constraint.
    """

    sigma_xy_per_m: float = 0.05
    sigma_xy_per_rad: float = 0.02
    sigma_theta_per_m: float = 0.02
    sigma_theta_per_rad: float = 0.05
    sigma_xy_min_m: float = 0.002
    sigma_theta_min_rad: float = 0.001

    def __post_init__(self) -> None:
        for name in (
            "sigma_xy_per_m",
            "sigma_xy_per_rad",
            "sigma_theta_per_m",
            "sigma_theta_per_rad",
        ):
            nonneg(name, getattr(self, name))
        positive("sigma_xy_min_m", self.sigma_xy_min_m)
        positive("sigma_theta_min_rad", self.sigma_theta_min_rad)

    def scaled(self, factor: float) -> MotionNoiseConfig:
        """The same model with the four growth rates ``sigma_*_per_*`` times ``factor``.

        The floors per step are kept.  Used by experiments with noisier odometry
        (``lineslam consistency --odometry-scale``).
        """
        positive("factor", factor)
        return MotionNoiseConfig(
            sigma_xy_per_m=self.sigma_xy_per_m * factor,
            sigma_xy_per_rad=self.sigma_xy_per_rad * factor,
            sigma_theta_per_m=self.sigma_theta_per_m * factor,
            sigma_theta_per_rad=self.sigma_theta_per_rad * factor,
            sigma_xy_min_m=self.sigma_xy_min_m,
            sigma_theta_min_rad=self.sigma_theta_min_rad,
        )

    def covariance(self, delta: FloatArray) -> FloatArray:
        """Covariance ``(..., 3, 3)`` of relative motions ``delta`` ``(..., 3)``."""
        d = np.asarray(delta, dtype=float)
        dist = np.hypot(d[..., 0], d[..., 1])
        turn = np.abs(d[..., 2])
        var_xy = self.sigma_xy_min_m**2 + self.sigma_xy_per_m**2 * dist
        var_xy = var_xy + self.sigma_xy_per_rad**2 * turn
        var_th = self.sigma_theta_min_rad**2 + self.sigma_theta_per_m**2 * dist
        var_th = var_th + self.sigma_theta_per_rad**2 * turn
        out = np.zeros((*d.shape[:-1], 3, 3))
        out[..., 0, 0] = var_xy
        out[..., 1, 1] = var_xy
        out[..., 2, 2] = var_th
        return out


@dataclass(frozen=True)
class OdometryCalibration:
    """A persistent odometry error, applied to each step ``(dx, dy, dθ)`` of path length ``d``.

    The calibrated step is ``((1 + scale)·dx, (1 + scale)·dy, (1 + turn_gain)·dθ +
    heading_drift_rad_per_m·d)``, then seen from a laser mounted at ``m = (mount_x_m,
    mount_y_m)`` in the frame the odometry reports (an unstated lever arm):
    ``M⁻¹ · step · M`` with ``M`` the translation ``m``, i.e. ``m`` rotated with the step,
    ``t + (R(θ) − I) m``.  A pure turn ``θ`` then moves the laser by ``(R(θ) − I) m``.

    Attributes
    ----------
    scale : float
        Relative translation error (0.01: the true motion is 1 % longer than logged).
    turn_gain : float
        Relative rotation error.
    heading_drift_rad_per_m : float
        Heading change per metre travelled that the odometry does not report (rad/m).
    mount_x_m, mount_y_m : float
        Where the laser is in the frame the odometry reports (m; 0.08: 8 cm ahead of it).
    """

    scale: float = 0.0
    turn_gain: float = 0.0
    heading_drift_rad_per_m: float = 0.0
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0

    def apply(self, steps: FloatArray) -> FloatArray:
        """The calibrated steps, shape ``(..., 3)`` as ``steps``."""
        s = np.array(steps, dtype=float)
        d = np.hypot(s[..., 0], s[..., 1])
        s[..., :2] *= 1.0 + self.scale
        s[..., 2] = s[..., 2] * (1.0 + self.turn_gain) + self.heading_drift_rad_per_m * d
        if self.mount_x_m or self.mount_y_m:
            c, n = np.cos(s[..., 2]) - 1.0, np.sin(s[..., 2])
            s[..., 0] += c * self.mount_x_m - n * self.mount_y_m
            s[..., 1] += n * self.mount_x_m + c * self.mount_y_m
        return s

    def jacobian(self, step: FloatArray) -> FloatArray:
        """``∂ Log(δ⁻¹ · calibrated(δ)) / ∂(scale, turn_gain, heading_drift, mount_x, mount_y)``.

        At zero, shape (3, 5): the error of an uncalibrated step ``δ`` in its end frame (right
        perturbation), to first order in the five parameters.  The mounting's columns are
        ``I − R(dθ)ᵀ``: zero on a straight step, so only turns tell where the laser is.
        """
        dx, dy, dth = (float(v) for v in step)
        c, s = np.cos(dth), np.sin(dth)
        J = np.zeros((3, 5))
        J[:, :3] = [
            [c * dx + s * dy, 0.0, 0.0],
            [-s * dx + c * dy, 0.0, 0.0],
            [0.0, dth, np.hypot(dx, dy)],
        ]
        J[:, 3:] = mounting_jacobian(np.array(dth))
        return J

    def as_dict(self) -> dict[str, float]:
        """The five parameters by name (``summary.json``)."""
        return {
            "scale": self.scale,
            "turn_gain": self.turn_gain,
            "heading_drift_rad_per_m": self.heading_drift_rad_per_m,
            "mount_x_m": self.mount_x_m,
            "mount_y_m": self.mount_y_m,
        }


def mounting_jacobian(dtheta: FloatArray) -> FloatArray:
    """``∂ Log(δ⁻¹ · M⁻¹ δ M) / ∂m`` at ``m = 0`` for steps turning by ``dtheta``: ``I − R(θ)ᵀ``.

    Shape ``(..., 3, 2)`` (the heading row zero): how a laser mounted at ``m`` in the frame
    the odometry reports moves, in the step's end frame, beyond what the step says.
    """
    th = np.asarray(dtheta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    J = np.zeros((*th.shape, 3, 2))
    J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1] = 1.0 - c, -s, s, 1.0 - c
    return J


def moved_enough(delta: FloatArray, min_distance_m: float, min_angle_rad: float) -> bool:
    """Whether a relative motion reaches a keyframe threshold.

    Parameters
    ----------
    delta : ndarray, shape (3,)
        Odometry since the last keyframe ``(dx_m, dy_m, dtheta_rad)``.
    min_distance_m, min_angle_rad : float
        A motion that travels at least ``min_distance_m`` or turns at least ``min_angle_rad``
        reaches the threshold.

    Returns
    -------
    bool
    """
    return bool(np.hypot(delta[0], delta[1]) >= min_distance_m or abs(delta[2]) >= min_angle_rad)
