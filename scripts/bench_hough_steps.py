"""Where the time of Hough extraction goes: the compiled kernel's steps, per scan.

Usage::

    python scripts/bench_hough_steps.py [--log intel] [--scans N] [--batch 64] [--rounds 7]
        [--thresholds matched]

What is timed
-------------
The log's scans (read into memory first, not timed) in consecutive batches of ``--batch``, as
``scripts/bench_extract.py``'s ``batch`` case; the inputs of every ``extract_kernel`` call are
recorded once, then each of these runs over all of them, interleaved round by round:

* ``accumulator``: the start of :func:`linefit.kernel._hough` for every scan: float32 points,
  the rows' windows of distance bins, the votes and their count in the dense accumulator;
* ``Hough grouping``: :func:`linefit.kernel._hough` whole (accumulator, then the peak search:
  up to ``hough_max_peaks`` peaks, each a candidate set refined twice);
* ``extract_kernel``: the whole compiled kernel (grouping, ML fits, rejection, segments,
  recovery, collinear merge, covariances, output);
* ``extract_lines_batch``: the whole batch API (the kernel plus the numpy steps 1-2 and the
  :class:`~linefit.Line` objects).

Process CPU time per scan, median over ``--rounds`` rounds (and the range).  The differences
between consecutive rows are the costs of the steps in between.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from bench_extract import THRESHOLDS, cpu_model, load
from numba import njit

import linefit.batch as batch_module
from linefit import LineFitConfig, extract_lines_batch
from linefit import kernel as lk
from slam.io.catalog import resolve_log

_hough = lk._hough
_hough_rows = lk._hough_rows
_hough_votes_dense = lk._hough_votes_dense
_hough_count = lk._hough_count
X, Y, F_RSTEP, I_MINVOTES, I_MAXPEAKS = lk.X, lk.Y, lk.F_RSTEP, lk.I_MINVOTES, lk.I_MAXPEAKS


def _hough_steps(pt, scan_start, ip, fp, cos_b, sin_b, c32, s32, dense_cells, whole):
    """Hough accumulator (``whole`` False) or whole Hough grouping of every scan of a batch.

    The scratch arrays are those of :func:`linefit.kernel.extract_kernel`; returns the number
    of listed cells or of candidate sets (so that no step is optimised away).
    """
    n_scans = scan_start.shape[0] - 1
    nmax = 1
    d2max = 0.0
    for k in range(n_scans):
        nmax = max(nmax, scan_start[k + 1] - scan_start[k])
    for p in range(pt.shape[1]):
        d2max = max(d2max, pt[X, p] * pt[X, p] + pt[Y, p] * pt[Y, p])
    n_beta = cos_b.shape[0]
    n_rho = 2 * (int(np.ceil(np.sqrt(d2max) / fp[F_RSTEP])) + 2)
    capl = ip[I_MAXPEAKS] + 2 * nmax + 16
    capm = 4 * nmax + 64
    vote = np.empty((nmax, n_beta), dtype=np.int32)
    row_off = np.empty(n_beta, dtype=np.int64)
    row_key = np.empty(n_beta, dtype=np.int64)
    acc = np.empty(max(0, min(n_beta * (3 * (n_rho // 2) + 16), dense_cells)), dtype=np.int32)
    cap_cells = n_beta * (nmax // max(1, ip[I_MINVOTES]) + 1) + 1
    cidx = np.empty(cap_cells, dtype=np.int64)
    ckey = np.empty(cap_cells, dtype=np.int64)
    alive = np.empty(nmax, dtype=np.bool_)
    alist = np.empty(nmax, dtype=np.int64)
    grp = np.empty(nmax, dtype=np.bool_)
    x32 = np.empty(nmax, dtype=np.float32)
    y32 = np.empty(nmax, dtype=np.float32)
    gm = np.empty(capm, dtype=np.int64)
    gs = np.empty(capl + 1, dtype=np.int64)
    ga = np.empty(capl)
    total = 0
    for k in range(n_scans):
        a = scan_start[k]
        n = scan_start[k + 1] - a
        if n == 0:
            continue
        pts = pt[:, a : a + n]
        if whole:
            total += _hough(
                pts, n, ip, fp, cos_b, sin_b, c32, s32, x32, y32, vote, row_off, row_key, acc,
                cidx, ckey, alive, alist, grp, gm, gs, ga,
            )  # fmt: skip
        else:
            d2m = 0.0
            for p in range(n):
                d2m = max(d2m, pts[X, p] * pts[X, p] + pts[Y, p] * pts[Y, p])
            half = int(np.ceil(np.sqrt(d2m) / fp[F_RSTEP])) + 1
            for p in range(n):
                x32[p] = np.float32(pts[X, p])
                y32[p] = np.float32(pts[Y, p])
            n_acc = _hough_rows(x32, y32, n, c32, s32, half, 2 * half, row_off, row_key)
            if n_acc > acc.shape[0]:
                continue  # counted by sorting in the kernel: not part of this figure
            _hough_votes_dense(x32, y32, n, c32, s32, row_off, n_acc, acc, vote)
            total += _hough_count(vote, n, n_beta, ip[I_MINVOTES], row_key, acc, cidx, ckey)
    return total


hough_steps: Any = njit(cache=False)(_hough_steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default="intel", help="dataset name or path (default intel)")
    ap.add_argument("--scans", type=int, default=None, help="first N scans (default all)")
    ap.add_argument("--batch", type=int, default=64, help="scans per extract_lines_batch call")
    ap.add_argument("--rounds", type=int, default=7, help="interleaved rounds (default 7)")
    ap.add_argument("--thresholds", choices=sorted(THRESHOLDS), default="matched")
    args = ap.parse_args()

    ranges, bearings, max_range = load(resolve_log(args.log).log, args.scans)
    n = ranges.shape[0]
    cfg = LineFitConfig(grouping="hough", **THRESHOLDS[args.thresholds])  # type: ignore[arg-type]
    chunks = range(0, n, args.batch)

    def run_batch() -> None:
        for k in chunks:
            b = slice(k, k + args.batch)
            extract_lines_batch(ranges[b], bearings, cfg, max_range_m=max_range[b])

    calls: list[tuple[Any, ...]] = []
    kernel: Any = batch_module.extract_kernel

    def record(*a: Any) -> Any:
        calls.append(a)
        return kernel(*a)

    batch_module.extract_kernel = record  # type: ignore[assignment]
    try:
        run_batch()
    finally:
        batch_module.extract_kernel = kernel
    n_points = sum(int(c[0].shape[1]) for c in calls)

    def accumulator() -> None:
        for c in calls:
            hough_steps(c[0], c[2], *c[3:], False)

    def grouping() -> None:
        for c in calls:
            hough_steps(c[0], c[2], *c[3:], True)

    def whole_kernel() -> None:
        for c in calls:
            kernel(*c)

    steps: dict[str, Callable[[], None]] = {
        "accumulator": accumulator,
        "Hough grouping (+ peak search)": grouping,
        "extract_kernel (+ fits ... output)": whole_kernel,
        "extract_lines_batch (+ numpy, Lines)": run_batch,
    }
    print(
        f"log {args.log}: {n} scans, {n_points / n:.0f} valid points per scan, thresholds "
        f"{args.thresholds}, batches of {args.batch}, {args.rounds} interleaved rounds"
    )
    print(f"machine: {cpu_model()}; load average {os.getloadavg()[0]:.2f} at start")
    for step in steps.values():  # compile and warm up (not timed)
        step()
    us: dict[str, list[float]] = {name: [] for name in steps}
    for _ in range(args.rounds):
        for name, step in steps.items():
            c0 = time.process_time()
            step()
            us[name].append((time.process_time() - c0) / n * 1e6)
    print(f"{'step (cumulative)':<38} {'CPU us/scan':>11}  range")
    for name, v in us.items():
        print(f"{name:<38} {statistics.median(v):>11.1f}  {min(v):.1f}-{max(v):.1f}")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
