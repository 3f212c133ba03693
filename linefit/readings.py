"""Readings of a scan: input checks, which readings are measurements, their points.

A reading is a measurement of a surface when its range is finite, ``> 0`` and below the
maximum range (:func:`valid_readings`); the others never enter a fit.  :func:`scan_points`
turns valid readings into Cartesian points with their Eq. 8 covariances (:mod:`linefit.noise`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.config import LineFitConfig
from linefit.errors import InputError
from linefit.fit import PointSet
from linefit.noise import SigmaRangeFn, point_covariance_entries, range_sigma

__all__ = ["as_vector", "check_batch", "check_real", "scan_points", "valid_readings"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def check_real(values: ArrayLike, name: str) -> None:
    """Refuse complex ``values`` (numpy would drop the imaginary part with only a warning).

    Raises
    ------
    InputError
        ``"{name} must be real numbers, got complex values"``.
    """
    if np.iscomplexobj(values):
        raise InputError(f"{name} must be real numbers, got complex values")


def as_vector(values: ArrayLike, name: str) -> FloatArray:
    """``values`` as a 1-D float array.

    Parameters
    ----------
    values
        Array-like of numbers.
    name
        The argument's name, for the error message.

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    InputError
        Non-numeric or complex values, or not one-dimensional.
    """
    check_real(values, name)
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be an array of numbers ({exc})") from exc
    if arr.ndim != 1:
        raise InputError(f"{name} must be one-dimensional, got shape {arr.shape}")
    return arr


def check_batch(
    ranges: ArrayLike, bearings: ArrayLike, max_range_m: ArrayLike | None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Check and normalise the arrays of a batch of scans.

    Parameters
    ----------
    ranges
        Ranges (m), shape ``(n_scans, n_beams)``.
    bearings
        Beam angles (rad), shape ``(n_beams,)`` or ``(n_scans, n_beams)``.
    max_range_m
        Maximum range (m): ``None`` (no limit), one number or one per scan.

    Returns
    -------
    ranges : ndarray, shape (n_scans, n_beams)
    bearings : ndarray, shape (n_scans, n_beams)
        Broadcast to one row per scan.
    max_range_m : ndarray, shape (n_scans,)

    Raises
    ------
    InputError
        Non-numeric values, wrong shapes, non-finite or non-monotonic bearings (per scan;
        wrapping past ±π is allowed), bearings sweeping more than a full turn (degrees given
        for radians), non-positive maximum range, complex values.
    """
    check_real(ranges, "ranges")
    check_real(bearings, "bearings")
    if max_range_m is not None:
        check_real(max_range_m, "max_range_m")
    try:
        d = np.asarray(ranges, dtype=float)
        phi = np.asarray(bearings, dtype=float)
        mr = np.asarray(np.inf if max_range_m is None else max_range_m, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"ranges, bearings and max_range_m must be numeric ({exc})") from exc
    if d.ndim != 2:
        raise InputError(f"ranges must have shape (n_scans, n_beams), got {d.shape}")
    if phi.ndim == 1:
        phi = np.broadcast_to(phi, d.shape)
    if phi.shape != d.shape:
        raise InputError(
            f"bearings must have shape ({d.shape[1]},) or {d.shape}, got {np.shape(bearings)}"
        )
    if not np.all(np.isfinite(phi)):
        raise InputError("bearings must be finite")
    if d.shape[1] >= 2:
        step = phi[:, 1:] - phi[:, :-1]
        step = np.pi - np.mod(np.pi - step, 2.0 * np.pi)  # wrap to (−π, π]
        mono = np.all(step > 0.0, axis=1) | np.all(step < 0.0, axis=1)
        if not mono.all():
            bad = int(np.flatnonzero(~mono)[0])
            raise InputError(
                f"bearings must be strictly increasing or strictly decreasing (scan {bad})"
            )
        sweep = np.abs(step.sum(axis=1))
        if np.any(sweep > 2.0 * np.pi + 1e-9):
            bad = int(np.flatnonzero(sweep > 2.0 * np.pi + 1e-9)[0])
            raise InputError(
                f"bearings sweep {float(sweep[bad]):.4g} rad in scan {bad}, more than a full "
                f"turn: degrees given for radians?"
            )
    if mr.ndim == 0:
        mr = np.full(d.shape[0], float(mr))
    if mr.shape != (d.shape[0],):
        raise InputError(f"max_range_m must be a number or have shape ({d.shape[0]},)")
    if np.any(np.isnan(mr) | (mr <= 0.0)):
        raise InputError("max_range_m must be positive")
    return d, phi, mr


MAX_READING_M = 1.0e5
"""Largest range reading (m) taken as a measurement; beyond any laser's reach."""


def check_reach(ranges: FloatArray, max_range_m: FloatArray, config: LineFitConfig) -> None:
    """Refuse readings beyond :data:`MAX_READING_M` that the range limits would let through.

    Such values (e.g. ``1e300``, a corrupted or sentinel "no return") overflow the fit; a scan
    with a range limit (``max_range_m``, or ``config.max_range_m``) treats them as "no return"
    and is never refused here.

    Raises
    ------
    InputError
        Naming the scan, the reading and its value.
    """
    limit = max_range_m
    if config.max_range_m is not None:
        limit = np.minimum(limit, config.max_range_m)
    open_rows = np.flatnonzero(~(limit <= MAX_READING_M))
    if open_rows.size == 0:
        return
    sub = ranges[open_rows]
    with np.errstate(invalid="ignore"):
        bad = np.isfinite(sub) & (sub > MAX_READING_M)
    if bad.any():
        row, beam = (int(v[0]) for v in np.nonzero(bad))
        raise InputError(
            f"ranges: reading {beam} of scan {int(open_rows[row])} is "
            f"{float(sub[row, beam]):g} m, beyond any laser's reach ({MAX_READING_M:g} m); "
            "give max_range_m (readings at or above it are no returns) or mark no returns "
            "with inf"
        )


def valid_readings(
    ranges: FloatArray, max_range_m: FloatArray | float | None, config: LineFitConfig
) -> NDArray[np.bool_]:
    """True for readings that are measurements of a surface (finite, > 0, < max range).

    ``max_range_m`` is a number or one value per scan (the rows of a 2-D ``ranges``); the
    smaller of it and ``config.max_range_m`` applies.
    """
    limit = np.asarray(np.inf if max_range_m is None else max_range_m, dtype=float)
    if config.max_range_m is not None:
        limit = np.minimum(limit, config.max_range_m)
    if ranges.ndim == 2 and limit.ndim == 1:
        limit = limit[:, None]
    with np.errstate(invalid="ignore"):
        return np.isfinite(ranges) & (ranges > 0.0) & (ranges < limit)


def scan_points(
    ranges: FloatArray,
    bearings: FloatArray,
    beams: IntArray,
    config: LineFitConfig,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> PointSet:
    """Cartesian points of (valid) readings with their Eq. 8 covariances."""
    noise = config.noise
    q11, q12, q22 = point_covariance_entries(ranges, bearings, noise, sigma_range_fn)
    sigma = range_sigma(ranges, noise, sigma_range_fn)
    if sigma_range_fn is None:
        dvar = 2.0 * sigma * noise.sigma_range_per_m
    else:  # numerical derivative of the user's σ_d(d)²
        h = 1e-6 * np.maximum(ranges, 1.0)
        hi = range_sigma(ranges + h, noise, sigma_range_fn) ** 2
        lo = range_sigma(ranges - h, noise, sigma_range_fn) ** 2
        dvar = (hi - lo) / (2.0 * h)
    return PointSet(
        x=ranges * np.cos(bearings),
        y=ranges * np.sin(bearings),
        q11=q11,
        q12=q12,
        q22=q22,
        beam=beams,
        var_range=sigma * sigma,
        var_perp=(ranges * noise.sigma_bearing_rad) ** 2,
        dvar_range=dvar,
    )
