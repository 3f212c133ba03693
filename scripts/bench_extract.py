"""Line extraction throughput on the whole Intel log, both groupings, measured side by side.

Usage::

    python scripts/bench_extract.py [--log intel] [--batch 64] [--single 2000] [--sigma-d 0.005]

The log is resolved by ``slam.io.catalog.resolve_log`` (``$LINESLAM_DATA``, else
``<repo>/../shared/datasets``) and read once into memory (the reading time is printed but not
counted).  For each grouping the whole log is extracted with ``extract_lines_batch`` in chunks
of ``--batch`` scans, and the first ``--single`` scans with ``extract_lines`` one scan at a
time (the single-scan API).  Printed per run: scans/s (wall clock), scans/s of process CPU time
(shows how much the machine was shared), lines per scan, microseconds per fitted line.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from linefit import LineFitConfig, SensorNoiseConfig, extract_lines, extract_lines_batch
from slam.io.carmen import iter_scans
from slam.io.catalog import resolve_log


def load(log: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    resolved = resolve_log(log)
    t0 = time.perf_counter()
    ranges, bearings, max_range = [], None, []
    for scan in iter_scans(resolved.log):
        ranges.append(scan.ranges)
        max_range.append(scan.max_range_m)
        if bearings is None:
            bearings = scan.bearings
    assert bearings is not None
    width = max(r.shape[0] for r in ranges)
    out = np.full((len(ranges), width), np.nan)
    for k, r in enumerate(ranges):
        out[k, : r.shape[0]] = r
    if any(r.shape[0] != width for r in ranges):
        raise SystemExit("scans of different widths: this benchmark expects one beam layout")
    return out, bearings, np.asarray(max_range), time.perf_counter() - t0


def run(fn, n_scans: int) -> tuple[float, float, int]:
    t0, c0 = time.perf_counter(), time.process_time()
    n_lines = fn()
    return time.perf_counter() - t0, time.process_time() - c0, n_lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default="intel", help="dataset name or path (default intel)")
    ap.add_argument("--batch", type=int, default=64, help="scans per extract_lines_batch call")
    ap.add_argument("--single", type=int, default=2000, help="scans timed one by one")
    ap.add_argument("--sigma-d", type=float, default=0.005, help="range noise σ_d (m)")
    args = ap.parse_args()

    ranges, bearings, max_range, t_read = load(args.log)
    n = ranges.shape[0]
    print(f"{args.log}: {n} scans of {ranges.shape[1]} beams, read in {t_read:.2f} s")
    print(f"sigma_d = {args.sigma_d} m, batch = {args.batch}, single-scan runs on {args.single}")
    header = (
        f"{'grouping':<12} {'mode':<10} {'scans':>6} {'time s':>7} {'scans/s':>8} "
        f"{'cpu scans/s':>11} {'lines/scan':>10} {'us/line':>8}"
    )
    print(header)
    print("-" * len(header))
    for grouping in ("hough", "split_merge"):
        cfg = LineFitConfig(grouping=grouping, noise=SensorNoiseConfig(sigma_range_m=args.sigma_d))

        def batch(cfg: LineFitConfig = cfg) -> int:
            total = 0
            for k in range(0, n, args.batch):
                out = extract_lines_batch(
                    ranges[k : k + args.batch],
                    bearings,
                    cfg,
                    max_range_m=max_range[k : k + args.batch],
                )
                total += sum(len(lines) for lines in out)
            return total

        m = min(args.single, n)

        def single(cfg: LineFitConfig = cfg, m: int = m) -> int:
            return sum(
                len(extract_lines(ranges[k], bearings, cfg, max_range_m=float(max_range[k])))
                for k in range(m)
            )

        for mode, fn, count in ((f"batch {args.batch}", batch, n), ("single", single, m)):
            wall, cpu, lines = run(fn, count)
            print(
                f"{grouping:<12} {mode:<10} {count:>6} {wall:>7.2f} {count / wall:>8.0f} "
                f"{count / cpu:>11.0f} {lines / count:>10.2f} {wall / max(lines, 1) * 1e6:>8.1f}"
            )


if __name__ == "__main__":
    main()
