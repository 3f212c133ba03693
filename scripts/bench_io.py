"""Reading a whole CARMEN log into scans, beside a plain numpy.loadtxt baseline (same run).

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/bench_io.py [--log intel]

Prints the time of ``slam.io.iter_scans`` (every FLASER line validated and turned into a
``Scan`` with bearings, poses and range limit; ODOM lines parsed too), the time of
``numpy.loadtxt`` reading only the FLASER lines into one float array (no validation, no
objects), and their ratio.  Best of ``--repeat`` runs each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from slam.io import CarmenStats, iter_scans, resolve_log


def best_of(repeat: int, fn):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def read_lineslam(path: Path):
    stats = CarmenStats()
    n_ranges = sum(scan.n_beams for scan in iter_scans(path, stats=stats))
    return stats.scans, n_ranges


def read_loadtxt(path: Path):
    with path.open() as handle:
        first = next(line for line in handle if line.startswith("FLASER"))
    n_beams = int(first.split()[1])
    with path.open() as handle:
        table = np.loadtxt(
            (line for line in handle if line.startswith("FLASER")),
            usecols=range(1, n_beams + 9),  # n, ranges, 6 pose fields, ipc_timestamp
            dtype=np.float64,
        )
    return table.shape[0], table.shape[0] * n_beams


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", default="intel", help="dataset name or .clf path")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    path = resolve_log(args.log).log
    size_mb = path.stat().st_size / 1e6
    t_ours, (scans, ranges) = best_of(args.repeat, lambda: read_lineslam(path))
    t_base, (scans_b, ranges_b) = best_of(args.repeat, lambda: read_loadtxt(path))
    assert (scans, ranges) == (scans_b, ranges_b), "the two readers disagree"
    print(f"log: {path} ({size_mb:.1f} MB, {scans} scans, {ranges} ranges)")
    print(
        f"slam.io.iter_scans : {t_ours:6.3f} s  {scans / t_ours:9.0f} scans/s  "
        f"{size_mb / t_ours:6.1f} MB/s"
    )
    print(
        f"numpy.loadtxt      : {t_base:6.3f} s  {scans / t_base:9.0f} scans/s  "
        f"{size_mb / t_base:6.1f} MB/s  (FLASER lines only, no validation, no Scan objects)"
    )
    print(f"ratio iter_scans / loadtxt time: {t_ours / t_base:.2f}")
    print(f"budget (issue 4): whole Intel log < 2 s -> {'met' if t_ours < 2.0 else 'NOT met'}")


if __name__ == "__main__":
    main()
