"""How far the robot may have drifted from what it saw earlier: the front end's own covariances.

Each keyframe adds the uncertainty of its step to a running sum: the registration's posterior
covariance when its lines were registered against the local map, else the odometry's
covariance ``Q``.  That is the random part of the drift; the registrations' errors are also
correlated from step to step (the same walls, the same fitting bias), a systematic part that
grows with the path ``d`` driven between the two keyframes (``frontend.drift_xy_per_m``,
``frontend.drift_theta_per_m``):

``σ_xy²(i, k) = D_xy[k] − D_xy[i] + (κ_xy·d)²``,   ``σ_θ²(i, k) = D_θ[k] − D_θ[i] + (κ_θ·d)²``

(``D_xy`` sums the larger eigenvalue of each step's ``(x, y)`` block, m²; ``D_θ`` its heading
variance, rad²).

For comparing a relative pose with the front end's own chain of steps (the loop closer's
``correction_chi2``), :meth:`DriftAccumulator.relative_cov` gives the whole covariance of the
chain's relative pose instead: the steps' covariances composed along the chain, each heading
error turning the rest of the path about its step (``Σ Ad(T_i) C_i Ad(T_i)ᵀ`` between the two
keyframes, moved to the later one's frame), the systematic heading part as a heading rate
``κ_θ`` per metre carried along the same chain, and ``(κ_xy·d)²`` in each direction.  Over a
loop of tens of metres the lever arms dominate the translation.

The heading part's lever arm (a landmark seen from elsewhere moves when the robot's heading is
off) is added where the drift is used (:func:`slam.models.anchored.drift_covariance`, a rotation
about the robot).  This is what the local map admits landmarks by (``frontend.max_drift_xy_m``),
what fusion compares two landmarks' last sightings with, and what sizes the loop-closure search
window (``loop_closure.window_sigmas`` standard deviations).

The sums are only as honest as the covariances that feed them.  Every accepted loop closure
measures the drift it corrected; :meth:`DriftAccumulator.observe_closure` keeps the normalised
squared corrections, and :attr:`DriftAccumulator.scale` — the median of their ratio to the
predicted variance, relative to the χ² median, never below 1 — widens every later drift.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_inverse
from slam.graph.problem import GrowableArray
from slam.lines.merge import chi2_ppf

__all__ = ["DriftAccumulator"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

_MEDIAN_CHI2_1 = chi2_ppf(0.5, 1)
_MEDIAN_CHI2_2 = chi2_ppf(0.5, 2)


class DriftAccumulator:
    """Running sums of the front end's step variances, per keyframe (module docstring)."""

    def __init__(self, xy_per_m: float = 0.0, theta_per_m: float = 0.0) -> None:
        self.xy_per_m = xy_per_m
        self.theta_per_m = theta_per_m
        self._var_xy = GrowableArray(())
        self._var_th = GrowableArray(())
        self._path = GrowableArray(())
        self._chain = GrowableArray((3,))
        # world-frame sums along the chain: Σ Ad(T_i) C_i Ad(T_i)ᵀ and Σ d_i Ad(T_i) e_θ
        self._lever_cov = GrowableArray((3, 3))
        self._lever_path = GrowableArray((3,))
        self._closures_xy: list[float] = []
        self._closures_th: list[float] = []
        self.scale_xy = 1.0
        """Factor (on the standard deviation) applied to translation drift; ≥ 1."""
        self.scale_theta = 1.0
        """Factor (on the standard deviation) applied to heading drift; ≥ 1."""

    def __len__(self) -> int:
        return len(self._var_xy)

    def add_step(
        self, step_cov: FloatArray, path_m: float, step_pose: FloatArray | None = None
    ) -> None:
        """Add one keyframe: its step's covariance, the path so far (m) and the step itself.

        ``step_cov`` is ``(3, 3)``; ``step_pose`` ``(3,)`` the relative pose from the previous
        keyframe as the front end estimated it (the chain of these is the front end's
        trajectory, free of loop closures).
        """
        C = np.asarray(step_cov, dtype=float)
        xy = C[:2, :2]
        lam = 0.5 * (xy[0, 0] + xy[1, 1]) + np.sqrt(
            0.25 * (xy[0, 0] - xy[1, 1]) ** 2 + xy[0, 1] ** 2
        )
        prev_xy = self._var_xy.data[-1] if len(self._var_xy) else 0.0
        prev_th = self._var_th.data[-1] if len(self._var_th) else 0.0
        self._var_xy.append(prev_xy + max(float(lam), 0.0))
        self._var_th.append(prev_th + max(float(C[2, 2]), 0.0))
        self._path.append(path_m)
        prev = self._chain.data[-1] if len(self._chain) else np.zeros(3)
        step = np.zeros(3) if step_pose is None else np.asarray(step_pose, dtype=float)
        pose = pose_compose(prev, step)
        self._chain.append(pose)
        # the step's covariance is about its end (right perturbation of ``pose``)
        Ad = adjoint_pose2(pose)
        n = len(self._lever_cov)
        prev_cov = self._lever_cov.data[-1] if n else np.zeros((3, 3))
        prev_lever = self._lever_path.data[-1] if n else np.zeros(3)
        step_m = path_m - self._path.data[-2] if n else 0.0
        self._lever_cov.append(prev_cov + Ad @ C @ Ad.T)
        self._lever_path.append(prev_lever + step_m * Ad[:, 2])

    def between(self, a: IntArray | int, b: IntArray | int) -> tuple[FloatArray, FloatArray]:
        """Drift ``(σ_xy, σ_θ)`` (m, rad) between keyframes ``a`` and ``b`` (either order)."""
        vxy, vth = self._var_xy.data, self._var_th.data
        ia = np.asarray(a, dtype=np.intp)
        ib = np.asarray(b, dtype=np.intp)
        d = np.abs(self._path.data[ib] - self._path.data[ia])
        sxy = np.sqrt(np.abs(vxy[ib] - vxy[ia]) + (self.xy_per_m * d) ** 2) * self.scale_xy
        sth = np.sqrt(np.abs(vth[ib] - vth[ia]) + (self.theta_per_m * d) ** 2) * self.scale_theta
        return np.asarray(sxy, dtype=float), np.asarray(sth, dtype=float)

    def relative(self, a: int, b: int) -> FloatArray:
        """Pose of keyframe ``b`` in the frame of keyframe ``a`` along the front end's chain."""
        chain = self._chain.data
        return pose_between(chain[a], chain[b])

    def relative_cov(self, a: int, b: int) -> FloatArray:
        """Covariance ``(3, 3)`` of :meth:`relative` ``(a, b)`` (right perturbation, ``b``'s frame).

        The steps' covariances between the two keyframes composed along the chain with their
        heading's lever arm, the systematic heading rate ``κ_θ`` carried along the same chain,
        and ``(κ_xy·d)²`` in each direction of translation (module docstring); times the
        accumulator's scales (:attr:`scale_xy`, :attr:`scale_theta`).  Either order of ``a``
        and ``b``.
        """
        lo, hi = min(a, b), max(a, b)
        to_b = adjoint_pose2(pose_inverse(self._chain.data[b]))
        C = to_b @ (self._lever_cov.data[hi] - self._lever_cov.data[lo]) @ to_b.T
        v = self.theta_per_m * (to_b @ (self._lever_path.data[hi] - self._lever_path.data[lo]))
        C = C + np.outer(v, v)
        d = abs(float(self._path.data[hi] - self._path.data[lo]))
        C[0, 0] += (self.xy_per_m * d) ** 2
        C[1, 1] += (self.xy_per_m * d) ** 2
        D = np.diag([self.scale_xy, self.scale_xy, self.scale_theta])
        return np.asarray(D @ C @ D, dtype=float)

    def since(self, keyframes: IntArray) -> tuple[FloatArray, FloatArray]:
        """Drift ``(σ_xy, σ_θ)`` from each of ``keyframes`` to the latest keyframe."""
        last = len(self._var_xy) - 1
        return self.between(keyframes, np.full(np.shape(keyframes), last, dtype=np.intp))

    def observe_closure(
        self, correction: FloatArray, sigma_xy: float, sigma_theta: float, single_direction: bool
    ) -> None:
        """Record the drift an accepted loop closure corrected against what was predicted.

        ``correction`` is ``(t_x, t_y, dθ)``; ``sigma_*`` the predicted drift (before scaling).
        Along a corridor (``single_direction``) only the heading is informative.
        """
        t = np.asarray(correction, dtype=float)
        if sigma_theta > 0.0:
            self._closures_th.append(float(t[2] ** 2 / sigma_theta**2))
            self.scale_theta = max(
                1.0, float(np.sqrt(np.median(self._closures_th) / _MEDIAN_CHI2_1))
            )
        if sigma_xy > 0.0 and not single_direction:
            self._closures_xy.append(float((t[0] ** 2 + t[1] ** 2) / sigma_xy**2))
            self.scale_xy = max(1.0, float(np.sqrt(np.median(self._closures_xy) / _MEDIAN_CHI2_2)))
