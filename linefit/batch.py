"""The batch driver: lines of many scans at once (:func:`extract_lines_batch`).

Valid readings and their points (:mod:`linefit.readings`) are computed in numpy for the whole
batch; the rest of :mod:`linefit.extract`'s steps run in the compiled kernel
(:mod:`linefit.kernel`), scan by scan, and the :class:`~linefit.line.Line` objects are built
from its flat arrays.

:func:`extract_lines_batch_numpy` is the reference implementation of the same steps in numpy,
on the points of all the scans of a batch as flat arrays with a scan id: grouping
(:mod:`linefit.hough` or :mod:`linefit.split_merge`), fit, rejection and segments
(:mod:`linefit.refine`), Hough recovery, collinear merge (:mod:`linefit.collinear`) and the
:class:`~linefit.line.Line` objects (:mod:`linefit.assemble`).  Both give the same lines, values
to rounding (``tests/test_kernel.py``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit import kernel
from linefit.assemble import lines_from_fit
from linefit.collinear import merge_collinear
from linefit.config import LineFitConfig
from linefit.errors import ConfigError
from linefit.fitted import Fitted, Groups
from linefit.hough import hough_groups
from linefit.kernel import extract_kernel, kernel_params
from linefit.line import Line
from linefit.noise import SigmaRangeFn
from linefit.readings import check_batch, check_reach, scan_points, valid_readings
from linefit.refine import refine
from linefit.split_merge import split_merge_groups

__all__ = ["extract_lines_batch", "extract_lines_batch_numpy", "kernel_ready", "warm_up"]

IntArray = NDArray[np.intp]


def extract_lines_batch(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    max_range_m: ArrayLike | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> list[list[Line]]:
    """Extract the lines of many scans at once (same result as one :func:`extract_lines` each).

    Parameters
    ----------
    ranges
        Ranges (m), shape ``(n_scans, n_beams)``; NaN, ±inf, zero, negative and max-range
        readings are allowed and ignored (pad scans of different lengths with NaN).
    bearings
        Beam angles (rad), shape ``(n_beams,)`` (shared) or ``(n_scans, n_beams)``; finite and
        strictly monotonic per scan.
    config
        Extraction settings (default :class:`LineFitConfig`).
    max_range_m
        Maximum range of the scans: one number or one per scan.
    sigma_range_fn
        Optional vectorised range-dependent ``σ_d(d)``.

    Returns
    -------
    list of list of Line
        The lines of each scan (see :func:`extract_lines`).  A scan's lines do not depend on
        the other scans of the batch.

    Raises
    ------
    InputError
        Bad arrays (:func:`linefit.readings.check_batch`), readings beyond any laser's reach
        without a range limit (:func:`linefit.readings.check_reach`), or a ``sigma_range_fn``
        value that is no standard deviation (:func:`linefit.noise.range_sigma`).
    ConfigError
        ``config`` is not a :class:`LineFitConfig`.
    """
    if config is not None and not isinstance(config, LineFitConfig):
        raise ConfigError(f"config must be a LineFitConfig, got {type(config).__name__}")
    cfg = config if config is not None else LineFitConfig()
    d, phi, mr = check_batch(ranges, bearings, max_range_m)
    check_reach(d, mr, cfg)
    n_scans, n_beams = d.shape
    valid = valid_readings(d, mr, cfg)
    # scans with too few valid readings hold no line
    valid &= (valid.sum(axis=1) >= max(2, cfg.min_points))[:, None]
    flat = np.flatnonzero(valid.ravel())
    out: list[list[Line]] = [[] for _ in range(n_scans)]
    if flat.shape[0] == 0:
        return out
    beam_of = flat % n_beams
    pts = scan_points(d.ravel()[flat], phi.ravel()[flat], beam_of, cfg, sigma_range_fn)
    assert pts.var_range is not None and pts.var_perp is not None
    assert pts.dvar_range is not None
    pt = np.stack(
        [
            pts.x,
            pts.y,
            pts.q11,
            pts.q12,
            pts.q22,
            pts.var_range,
            pts.var_perp,
            pts.dvar_range,
            np.sqrt(pts.var_range),
            np.hypot(pts.x, pts.y),
            np.arctan2(pts.y, pts.x),
        ]
    )
    scan_start = np.zeros(n_scans + 1, dtype=np.int64)
    np.cumsum(valid.sum(axis=1), out=scan_start[1:])
    scan, ras, cov, lin, seg, idx = extract_kernel(
        pt, beam_of.astype(np.int64), scan_start, *kernel_params(cfg), kernel.DENSE_CELLS
    )
    segs = np.ascontiguousarray(seg[:, :2])
    svar = np.ascontiguousarray(seg[:, 2:])
    for q, (k, (r, alpha, s), (s0, ns, i0, npts)) in enumerate(
        zip(scan.tolist(), ras.tolist(), lin.tolist(), strict=True)
    ):
        out[k].append(
            Line._trusted(
                r,
                alpha,
                s,
                cov[q],
                segs[s0 : s0 + ns],
                svar[s0 : s0 + ns],
                npts,
                idx[i0 : i0 + npts],
            )
        )
    return out


def kernel_ready() -> bool:
    """The compiled kernel is in memory (:func:`warm_up` or an extraction has run)."""
    return bool(extract_kernel.signatures)


def warm_up() -> None:
    """Load the compiled kernel now (from numba's cache, or compile it: about 30 s, once).

    The first :func:`extract_lines_batch` of a process does this anyway; a caller that wants
    it at a chosen moment (e.g. off the main thread, ``slam.extraction``) calls this.  Extracts
    the lines of a small made-up scan, through the same call as every extraction (same
    argument types, so the same compiled code).
    """
    if kernel_ready():
        return
    phi = np.linspace(-np.pi / 2, np.pi / 2, 61)
    d = np.minimum(2.0 / np.maximum(np.cos(phi), 1e-3), 8.0)  # a wall 2 m ahead
    extract_lines_batch(d[None, :], phi, max_range_m=10.0)


def extract_lines_batch_numpy(
    ranges: ArrayLike,
    bearings: ArrayLike,
    config: LineFitConfig | None = None,
    *,
    max_range_m: ArrayLike | None = None,
    sigma_range_fn: SigmaRangeFn | None = None,
) -> list[list[Line]]:
    """:func:`extract_lines_batch` in numpy, vectorised over the batch (the reference path).

    Same parameters and result as :func:`extract_lines_batch` (values to rounding; in the last
    bits they may depend on the other scans of the batch).
    """
    if config is not None and not isinstance(config, LineFitConfig):
        raise ConfigError(f"config must be a LineFitConfig, got {type(config).__name__}")
    cfg = config if config is not None else LineFitConfig()
    d, phi, mr = check_batch(ranges, bearings, max_range_m)
    check_reach(d, mr, cfg)
    n_scans, n_beams = d.shape
    valid = valid_readings(d, mr, cfg)
    # scans with too few valid readings hold no line
    valid &= (valid.sum(axis=1) >= max(2, cfg.min_points))[:, None]
    flat = np.flatnonzero(valid.ravel())
    if flat.shape[0] == 0:
        return [[] for _ in range(n_scans)]
    scan_of = flat // n_beams
    beam_of = flat % n_beams
    pts = scan_points(d.ravel()[flat], phi.ravel()[flat], beam_of, cfg, sigma_range_fn)
    assert pts.var_range is not None
    sigma_range = np.sqrt(pts.var_range)

    def split_merge_of(sub: IntArray) -> Groups:
        """Split-and-merge candidates among the valid points ``sub`` (sorted)."""
        grouping = split_merge_groups(
            pts.x[sub],
            pts.y[sub],
            pts.beam[sub],
            sigma_range[sub],
            scan_of[sub],
            split_threshold_m=cfg.split_threshold_m,
            split_threshold_sigma=cfg.split_threshold_sigma,
            max_missing_beams=cfg.max_missing_beams,
            lambda_rad=cfg.breakpoint_lambda_rad,
            sigma_factor=cfg.breakpoint_sigma,
            min_points=cfg.min_segment_points,
        )
        first = np.searchsorted(grouping.gidx, np.arange(grouping.n_groups))
        return Groups(
            sub[grouping.pidx],
            grouping.gidx,
            grouping.n_groups,
            grouping.alpha0,
            scan_of[sub[grouping.pidx[first]]] if grouping.n_groups else np.zeros(0, np.intp),
        )

    all_points = np.arange(flat.shape[0], dtype=np.intp)
    if cfg.grouping == "hough":
        to_valid = np.full(d.size, -1, dtype=np.intp)
        to_valid[flat] = all_points
        x2 = np.zeros(d.shape)
        y2 = np.zeros(d.shape)
        x2.ravel()[flat] = pts.x
        y2.ravel()[flat] = pts.y
        grouping, gscan = hough_groups(
            x2,
            y2,
            valid,
            angle_step_rad=cfg.hough_angle_step_rad,
            range_step_m=cfg.hough_range_step_m,
            min_votes=cfg.hough_min_votes,
            gather_m=cfg.hough_gather_m,
            max_peaks=cfg.hough_max_peaks,
        )
        grp = Groups(
            to_valid[grouping.pidx], grouping.gidx, grouping.n_groups, grouping.alpha0, gscan
        )
        fitted = refine(pts, sigma_range, grp, cfg)
        if cfg.hough_recover:
            # points no Hough line kept (a coarse peak can absorb, and then lose, the points
            # of a small face): split-and-merge pieces among them, refitted with the lines
            used = np.zeros(flat.shape[0], dtype=bool)
            if fitted is not None:
                used[fitted.pidx] = True
            extra = split_merge_of(all_points[~used])
            if extra.n:
                new = refine(pts, sigma_range, extra, cfg)
                if fitted is None:
                    fitted = new
                elif new is not None:
                    fitted = Fitted.concat(fitted, new)
    else:
        fitted = refine(pts, sigma_range, split_merge_of(all_points), cfg)
    if fitted is None:
        return [[] for _ in range(n_scans)]
    if cfg.merge_collinear:
        fitted = merge_collinear(pts, sigma_range, fitted, cfg)
    return lines_from_fit(pts, fitted, cfg, n_scans)
