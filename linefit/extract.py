"""The public entry points of line extraction and fitting.

:func:`extract_lines` for a scan (defined here), :func:`extract_lines_batch` for many scans at
once (:mod:`linefit.batch`), :func:`fit_line` and :func:`fit_scan_line` for a given set of
points (:mod:`linefit.one_line`).

Steps 1-2 below run in numpy for all the scans of a batch at once; steps 3-7 run in a compiled
kernel (:mod:`linefit.kernel`), scan by scan, so :func:`extract_lines` costs about as much per
scan as a batch.  The modules named below are the reference implementation of those steps in
numpy (:func:`linefit.batch.extract_lines_batch_numpy`), which the kernel reproduces to rounding
(``tests/test_kernel.py``); ``scripts/bench_extract.py`` measures both APIs.

Pipeline of :func:`extract_lines`
---------------------------------
1. Readings that are not measurements of a surface (NaN, ±inf, ``≤ 0``, ``≥`` max range) are
   dropped; they never enter a fit (:mod:`linefit.readings`).
2. Eq. 8 covariances of the remaining points (:mod:`linefit.noise`, :mod:`linefit.readings`).
3. Grouping into candidate lines: Hough transform (:mod:`linefit.hough`) or split-and-merge
   (:mod:`linefit.split_merge`).
4. For all candidates at once (:mod:`linefit.refine`): the ML fit (:mod:`linefit.fit`), then
   each point's normal residual is tested against its own covariance, studentised by its
   leverage (``δ_R²/(P_R (1 − h)) > outlier_chi2``: rejected; in each round only points within
   a factor 3 (in residual) of their line's worst are rejected, so one bad point cannot mask
   the others), and refit, at most ``max_refits`` rounds; then each line is cut into segments
   at gaps and range jumps (:mod:`linefit.segments`), pieces with fewer than
   ``min_segment_points`` points leave it, and it is refitted.
5. Hough only (``hough_recover``): the points no line kept are grouped by split-and-merge and
   those candidates go through step 4 too.
6. Optionally (``merge_collinear``) lines of one scan whose ``(r, α)`` pass a χ² test are
   joined into one line with several segments and refitted (step 4;
   :mod:`linefit.collinear`).
7. Lines with fewer than ``min_points`` points or shorter than ``min_length_m`` are dropped;
   covariances (:mod:`linefit.covariance`) and segment ends; normal form; sorted by their
   first beam index (:mod:`linefit.assemble`).

Lines that are not changed by a later step are never refitted, and the kernel computes
everything per scan, so a scan's result does not depend on the other scans of its batch, to the
last bit (tested).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from linefit.batch import extract_lines_batch
from linefit.config import LineFitConfig
from linefit.errors import InputError
from linefit.line import Line
from linefit.noise import SigmaRangeFn
from linefit.one_line import fit_line, fit_scan_line
from linefit.readings import as_vector, scan_points, valid_readings

__all__ = [
    "extract_lines",
    "extract_lines_batch",
    "fit_line",
    "fit_scan_line",
    "scan_points",
    "valid_readings",
]


def extract_lines(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    max_range_m: float | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> list[Line]:
    """Extract the weighted-fit lines of one range scan.

    Parameters
    ----------
    ranges
        Measured ranges ``d`` (m), shape ``(n,)``.  NaN, ±inf, zero, negative and max-range
        readings are allowed and ignored.
    bearings
        Beam angles ``φ`` (rad) in the sensor frame, shape ``(n,)``, finite and strictly
        monotonic (increasing or decreasing, possibly wrapping past ±π).
    config
        Extraction settings (default :class:`LineFitConfig`).
    max_range_m
        The scan's maximum range: readings at or above it are "no return" (CARMEN logs give
        it per scan).  Combined with ``config.max_range_m`` (the smaller applies).
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)`` replacing the configured range noise.

    Returns
    -------
    list of Line
        In normal form (``r ≥ 0``, ``α ∈ (−π, π]``), sorted by the first beam index of their
        supporting points.  Empty when the scan holds no line (e.g. all readings invalid or
        fewer than ``min_points`` valid readings).

    Raises
    ------
    InputError
        Mismatched or non-1-D arrays, non-numeric values, non-finite or non-monotonic
        bearings, bearings sweeping more than a full turn (degrees given for radians),
        readings beyond any laser's reach (over 1e5 m) when nothing limits the range, a
        ``sigma_range_fn`` value that is not finite, ``> 0`` and at most 1e5 m
        (:func:`linefit.noise.range_sigma`).
    ConfigError
        ``config`` is not a :class:`LineFitConfig`.

    Examples
    --------
    >>> import numpy as np
    >>> phi = np.radians(np.arange(-30.0, 31.0))
    >>> d = 2.0 / np.cos(phi)            # a wall 2 m ahead, normal along x
    >>> [round(l.r, 3) for l in extract_lines(d, phi)]
    [2.0]
    """
    d = as_vector(ranges, "ranges")
    phi = as_vector(bearings, "bearings")
    if d.shape != phi.shape:
        raise InputError(f"ranges ({d.shape[0]}) and bearings ({phi.shape[0]}) differ in length")
    if max_range_m is not None and not np.ndim(max_range_m) == 0:
        raise InputError("max_range_m must be a number")
    return extract_lines_batch(
        d[None, :], phi, config, max_range_m=max_range_m, sigma_range_fn=sigma_range_fn
    )[0]
