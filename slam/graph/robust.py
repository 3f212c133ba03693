"""Robust kernels for iteratively re-weighted least squares (IRLS).

The cost of a factor with whitened residual norm ``u`` is ``ρ(u)``; the Gaussian kernel is
``ρ(u) = u²/2`` (GTSAM's ``0.5‖e‖²``).  Minimising ``Σ ρ(u_f)`` by Gauss-Newton with weights
``w(u) = ρ'(u)/u`` on each factor's whitened Jacobian and residual (both scaled by ``√w``) is
IRLS, the same scheme as GTSAM's ``noiseModel.Robust``:

* ``huber``:  ``ρ = u²/2`` for ``u ≤ k``, ``k·u − k²/2`` beyond; ``w = min(1, k/u)``.
* ``cauchy``: ``ρ = (k²/2)·log(1 + u²/k²)``; ``w = 1 / (1 + u²/k²)``.

``k`` is in standard deviations of the whitened residual (a 2-vector for a line factor).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError

__all__ = ["RobustKernel", "robust_cost", "robust_weights"]

FloatArray = NDArray[np.float64]
RobustKernel = Literal["none", "huber", "cauchy"]


def robust_weights(kernel: RobustKernel, u: FloatArray, k: float) -> FloatArray:
    """IRLS weights ``w(u) = ρ'(u)/u`` for whitened residual norms ``u ≥ 0`` (vectorised)."""
    u = np.asarray(u, dtype=float)
    if kernel == "none":
        return np.ones_like(u)
    if kernel == "huber":
        return np.where(u <= k, 1.0, k / np.maximum(u, 1e-300))
    if kernel == "cauchy":
        return 1.0 / (1.0 + (u / k) ** 2)
    raise ConfigError(f"unknown robust kernel {kernel!r}")


def robust_cost(kernel: RobustKernel, u: FloatArray, k: float) -> FloatArray:
    """``ρ(u)`` for whitened residual norms ``u ≥ 0`` (``u²/2`` without a kernel)."""
    u = np.asarray(u, dtype=float)
    if kernel == "none":
        return 0.5 * u**2
    if kernel == "huber":
        return np.where(u <= k, 0.5 * u**2, k * u - 0.5 * k**2)
    if kernel == "cauchy":
        return 0.5 * k**2 * np.log1p((u / k) ** 2)
    raise ConfigError(f"unknown robust kernel {kernel!r}")
