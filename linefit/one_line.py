"""Fitting one line to given points (:func:`fit_line`) or readings (:func:`fit_scan_line`).

The ML fit of Props. 1-2 and the covariance of :mod:`linefit.covariance` for one set of points,
without grouping, outlier rejection or segmentation.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from linefit.assemble import lines_from_fit
from linefit.config import LineFitConfig
from linefit.covariance import line_covariances
from linefit.errors import DegenerateGeometryError, InputError
from linefit.fit import PointSet, fit_groups, nearest_representative, tls_groups
from linefit.fitted import Fitted
from linefit.line import Line, wrap_angle
from linefit.noise import SigmaRangeFn
from linefit.readings import as_vector, scan_points

__all__ = ["fit_line", "fit_scan_line", "single_line"]


def single_line(
    pts: PointSet, alpha0: float | None, weighted: bool, cfg: LineFitConfig, bearing_error: str
) -> Line:
    """The ML fit of one line to all of ``pts`` (no grouping, no rejection, one segment).

    Parameters
    ----------
    pts
        The points with their covariances.
    alpha0
        Starting normal angle (rad); ``None``: the total-least-squares line.
    weighted
        ML fit (True) or unweighted total least squares (False).
    cfg
        Noise model and iteration settings.
    bearing_error
        Covariance model of ``S`` and the ends (``LineFitConfig.noise.bearing_error``).

    Returns
    -------
    Line
        In normal form, one segment spanning the extreme points.

    Raises
    ------
    DegenerateGeometryError
        Coincident points, no convergence, or a non-finite covariance.
    """
    n = len(pts)
    pidx = np.arange(n, dtype=np.intp)
    gidx = np.zeros(n, dtype=np.intp)
    _, a_tls, ratio = tls_groups(pts, pidx, gidx, 1)
    if not np.isfinite(ratio[0]):
        raise DegenerateGeometryError("the points coincide: they do not determine a line")
    start = a_tls if alpha0 is None else nearest_representative(a_tls, np.array([alpha0]))
    fit = fit_groups(
        pts,
        pidx,
        gidx,
        1,
        np.asarray(start, dtype=float),
        weighted=weighted,
        max_iterations=cfg.max_iterations,
        tolerance_rad=cfg.alpha_tolerance_rad,
        alpha_step=cfg.alpha_update,
    )
    if not (fit.converged[0] and np.isfinite(fit.alpha[0])):
        raise DegenerateGeometryError("the α iteration did not converge for these points")
    cov = line_covariances(fit, pts, pidx, gidx, 1, bearing_error)
    if not np.all(np.isfinite(cov.cov)):
        raise DegenerateGeometryError("the line covariance is not finite for these points")
    order = np.argsort(fit.u_s, kind="stable")
    seg = np.zeros(n, dtype=np.intp)
    fitted = Fitted(pidx, gidx, 1, np.zeros(1, dtype=np.intp), fit, cov, order, seg)
    relaxed = LineFitConfig(noise=cfg.noise, min_points=2, min_length_m=0.0)
    return lines_from_fit(pts, fitted, relaxed, 1)[0][0]


def fit_line(
    points_xy: ArrayLike,
    covariances: ArrayLike,
    *,
    alpha0: float | None = None,
    weighted: bool = True,
    config: LineFitConfig | None = None,
) -> Line:
    """Fit one line to arbitrary points with given covariances (no grouping, no rejection).

    This is the ML fit of Props. 1-2 with the covariance of :mod:`linefit.covariance`, for
    points from anywhere (e.g. the points of two lines moved into a common frame, to check that
    fusing lines equals fitting their points).  The covariances are taken as the covariances of
    the points about their true positions (the ``"reading"`` model for ``S`` and the ends).

    Parameters
    ----------
    points_xy
        Points (m), shape ``(n, 2)``, ``n ≥ 2``.
    covariances
        Their covariances (m²), shape ``(n, 2, 2)``, symmetric positive definite.
    alpha0
        Starting normal angle (rad); default: the total-least-squares line.  It also picks
        the representative before the result is put in normal form.
    weighted
        ML fit (True) or unweighted total least squares (False).
    config
        Iteration settings (``max_iterations``, ``alpha_tolerance_rad``, ``alpha_update``).

    Returns
    -------
    Line
        In normal form, one segment spanning the extreme points, ``indices`` = ``0..n-1``.

    Raises
    ------
    InputError
        Wrong shapes, non-finite values, covariances that are not symmetric positive definite.
    DegenerateGeometryError
        Fewer than two distinct points, or points that do not determine a line.
    """
    cfg = config if config is not None else LineFitConfig()
    try:
        p = np.asarray(points_xy, dtype=float)
        C = np.asarray(covariances, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"points and covariances must be numeric arrays ({exc})") from exc
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"points_xy must have shape (n, 2), got {p.shape}")
    if C.shape != (p.shape[0], 2, 2):
        raise InputError(f"covariances must have shape ({p.shape[0]}, 2, 2), got {C.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(C))):
        raise InputError("points and covariances must be finite")
    if p.shape[0] < 2:
        raise DegenerateGeometryError(f"a line needs at least two points, got {p.shape[0]}")
    q11, q12, q22 = C[:, 0, 0], 0.5 * (C[:, 0, 1] + C[:, 1, 0]), C[:, 1, 1]
    spd = (q11 > 0.0) & (q22 > 0.0) & (q11 * q22 - q12 * q12 > 0.0)
    if not np.allclose(C[:, 0, 1], C[:, 1, 0], rtol=1e-9, atol=1e-18) or not spd.all():
        raise InputError("covariances must be symmetric positive definite")
    pts = PointSet(
        x=p[:, 0].copy(),
        y=p[:, 1].copy(),
        q11=q11.copy(),
        q12=q12.copy(),
        q22=q22.copy(),
        beam=np.arange(p.shape[0], dtype=np.intp),
    )
    return single_line(pts, alpha0, weighted, cfg, "reading")


def fit_scan_line(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    alpha0: float | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> Line:
    """Fit one line to all the given readings (Eq. 8 noise, no grouping, no rejection).

    Parameters
    ----------
    ranges, bearings
        The readings of one line (m, rad), shape ``(n,)``; all must be valid measurements.
    config
        Noise model and fit settings (``weighted``, iterations, ``noise.bearing_error``).
    alpha0
        Starting normal angle (rad); default the total-least-squares line.
    sigma_range_fn
        Optional vectorised ``σ_d(d)``.

    Returns
    -------
    Line
        In normal form, one segment, ``indices`` = positions in the given arrays.

    Raises
    ------
    InputError
        Mismatched shapes or invalid readings (NaN, inf, ``≤ 0``).
    DegenerateGeometryError
        Fewer than two points, or points on a ray through the sensor (a range sensor cannot
        observe such a line: every beam would be parallel to it).
    """
    cfg = config if config is not None else LineFitConfig()
    d = as_vector(ranges, "ranges")
    phi = as_vector(bearings, "bearings")
    if d.shape != phi.shape:
        raise InputError(f"ranges ({d.shape[0]}) and bearings ({phi.shape[0]}) differ in length")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(phi)) and np.all(d > 0.0)):
        raise InputError("fit_scan_line needs valid readings: finite ranges > 0, finite bearings")
    if d.shape[0] < 2:
        raise DegenerateGeometryError(f"a line needs at least two points, got {d.shape[0]}")
    pts = scan_points(d, phi, np.arange(d.shape[0], dtype=np.intp), cfg, sigma_range_fn)
    ray = DegenerateGeometryError(
        "the points lie on a line through the sensor: a range sensor cannot observe it"
    )
    # bearings all equal modulo π: the points are on one line through the sensor origin
    spread = np.asarray(wrap_angle(2.0 * (phi - phi[0])))
    if np.all(np.abs(spread) < 1e-9):
        raise ray
    line = single_line(pts, alpha0, cfg.weighted, cfg, cfg.noise.bearing_error)
    if line.r <= 1e-9 * max(1.0, float(np.max(d))):
        raise ray
    return line
