"""Range-sensor noise model of the paper's Section II (Eq. 8), vectorised over a whole scan.

A reading ``(d, φ)`` is the point ``u = d·(cos φ, sin φ)``.  With independent zero-mean Gaussian
range noise ``ε_d`` (std ``σ_d``) and bearing noise ``ε_φ`` (std ``σ_φ``), to first order in
``ε_φ`` the point's covariance is (Eq. 8)

``Q = σ_d² · b bᵀ + d² σ_φ² · p pᵀ``

with the beam direction ``b = (cos φ, sin φ)`` and its perpendicular ``p = (−sin φ, cos φ)``
(written out this is exactly the paper's Eq. 8 with the measured ``d, φ`` in place of the true
``D, Φ``, as the paper recommends).

``σ_d`` may depend on the range: ``σ_d(d) = sigma_range_m + sigma_range_per_m · d`` from the
configuration, or any vectorised callable ``sigma_range_fn(d) -> σ_d`` passed directly (its
values must be finite, ``> 0`` and at most :data:`MAX_SIGMA_RANGE_M`, else :class:`InputError`).

The three distinct entries ``(Q11, Q12, Q22)`` are what the fitting code uses (flat arrays,
no 2×2 matrices in the inner loops); :func:`point_covariances` returns the ``(n, 2, 2)`` stack.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.config import SensorNoiseConfig
from linefit.errors import InputError

__all__ = [
    "MAX_SIGMA_RANGE_M",
    "SigmaRangeFn",
    "point_covariance_entries",
    "point_covariances",
    "range_sigma",
]

FloatArray = NDArray[np.float64]
SigmaRangeFn = Callable[[FloatArray], FloatArray]

MAX_SIGMA_RANGE_M = 1.0e5
"""Largest ``σ_d`` (m) a ``sigma_range_fn`` may return: any laser's reach, the bound of
:data:`linefit.readings.MAX_READING_M`.  A reading whose standard deviation exceeds it measures
no surface at all, so a larger value is a bug or a sentinel, never a standard deviation
(``1e200`` squared overflows: numpy warned and the scan silently had no line); up to it,
``σ_d² ≤ 1e10 m²`` and the fit's products stay far from overflow."""


def range_sigma(
    ranges: ArrayLike,
    noise: SensorNoiseConfig | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> FloatArray:
    """Range standard deviation ``σ_d(d)`` (m) for each reading.

    Parameters
    ----------
    ranges
        Ranges ``d`` (m), any shape.
    noise
        Noise configuration (default: the paper's SICK LMS-200 values).  Used when
        ``sigma_range_fn`` is None: ``σ_d = sigma_range_m + sigma_range_per_m · d``.
    sigma_range_fn
        Optional vectorised ``σ_d(d)``; overrides the configured range noise.

    Returns
    -------
    ndarray
        ``σ_d`` for each reading, same shape as ``ranges``.

    Raises
    ------
    InputError
        If ``sigma_range_fn`` returns a wrong shape, or a value that is not finite, ``> 0`` and
        at most :data:`MAX_SIGMA_RANGE_M` (the message names the first such value and its
        range).
    """
    d = np.asarray(ranges, dtype=float)
    if sigma_range_fn is None:
        cfg = noise if noise is not None else SensorNoiseConfig()
        if cfg.sigma_range_per_m == 0.0:
            return np.full(d.shape, cfg.sigma_range_m)
        return cfg.sigma_range_m + cfg.sigma_range_per_m * np.abs(d)
    raw = np.asarray(sigma_range_fn(d), dtype=float)
    if raw.shape != d.shape and raw.size != 1:
        raise InputError(f"sigma_range_fn returned shape {raw.shape} for ranges of shape {d.shape}")
    sigma = np.broadcast_to(raw.reshape(-1)[0] if raw.shape != d.shape else raw, d.shape)
    ok = (sigma > 0.0) & (sigma <= MAX_SIGMA_RANGE_M)  # False for NaN and inf
    if not ok.all():
        i = int(np.flatnonzero(~ok.ravel())[0])
        value, at = float(sigma.reshape(-1)[i]), float(d.reshape(-1)[i])
        raise InputError(
            f"sigma_range_fn returned {value:g} m for range {at:g} m: a range standard "
            f"deviation must be finite, > 0 and at most {MAX_SIGMA_RANGE_M:g} m"
        )
    return sigma


def point_covariance_entries(
    ranges: ArrayLike,
    bearings: ArrayLike,
    noise: SensorNoiseConfig | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Entries ``(Q11, Q12, Q22)`` of the Eq. 8 point covariances, vectorised.

    Parameters
    ----------
    ranges, bearings
        Readings ``d`` (m) and ``φ`` (rad), same shape.
    noise
        Noise configuration (default: ``σ_d`` = 5 mm, ``σ_φ`` = 1e-4 rad).
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)`` (see :func:`range_sigma`).

    Returns
    -------
    q11, q12, q22 : ndarray
        ``Q = [[q11, q12], [q12, q22]]`` (m²) for each reading, same shape as the inputs.
    """
    d = np.asarray(ranges, dtype=float)
    phi = np.asarray(bearings, dtype=float)
    if d.shape != phi.shape:
        raise InputError(f"ranges {d.shape} and bearings {phi.shape} differ in shape")
    cfg = noise if noise is not None else SensorNoiseConfig()
    var_d = range_sigma(d, cfg, sigma_range_fn) ** 2
    var_t = (d * cfg.sigma_bearing_rad) ** 2
    c = np.cos(phi)
    s = np.sin(phi)
    q11 = var_d * c * c + var_t * s * s
    q22 = var_d * s * s + var_t * c * c
    q12 = (var_d - var_t) * s * c
    return q11, q12, q22


def point_covariances(
    ranges: ArrayLike,
    bearings: ArrayLike,
    noise: SensorNoiseConfig | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> FloatArray:
    """Eq. 8 covariances ``Q_k`` of the Cartesian scan points, shape ``(n, 2, 2)``.

    Parameters
    ----------
    ranges, bearings
        Readings ``d`` (m) and ``φ`` (rad), shape ``(n,)``.
    noise
        Noise configuration (default: ``σ_d`` = 5 mm, ``σ_φ`` = 1e-4 rad).
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)``.

    Returns
    -------
    ndarray, shape (n, 2, 2)
        ``Q_k`` in m², in the sensor frame.

    Examples
    --------
    >>> import numpy as np
    >>> Q = point_covariances(np.array([2.0]), np.array([0.0]))
    >>> np.allclose(Q[0], np.diag([0.005**2, (2.0 * 1e-4) ** 2]))
    True
    """
    q11, q12, q22 = point_covariance_entries(ranges, bearings, noise, sigma_range_fn)
    out = np.empty(q11.shape + (2, 2))
    out[..., 0, 0] = q11
    out[..., 0, 1] = q12
    out[..., 1, 0] = q12
    out[..., 1, 1] = q22
    return out
