"""Benchmark of map building (paper Sec. V) on the first 1,000 Intel scans.

Fits every scan once (timed separately), then builds the map from the same lines twice, side by
side in one run: with the vectorised bounding-box prefilter (default) and testing every pair
(``spatial_prefilter=False``).  Prints time per scan, candidate pairs tested and the ratios.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/bench_map.py [--scans 1000]
"""

from __future__ import annotations

import argparse
import time
from itertools import islice

import numpy as np

from slam.config import RunConfig
from slam.io.carmen import iter_scans
from slam.io.catalog import resolve_log
from slam.lines.config import MapConfig
from slam.lines.mapbuilder import MapBuilder
from slam.mapping import fit_scan, scan_pose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", default="intel")
    parser.add_argument("--scans", type=int, default=1000)
    parser.add_argument(
        "--stress",
        action="store_true",
        help="also a synthetic worst case: 1,000 scans of 15 random lines over 50 m × 50 m "
        "(almost nothing merges, the map grows to ~13,000 lines)",
    )
    args = parser.parse_args()
    config = RunConfig()
    log = resolve_log(args.log).log

    t0 = time.perf_counter()
    scans = list(islice(iter_scans(log), args.scans))
    t_read = time.perf_counter() - t0
    t0 = time.perf_counter()
    fitted = []
    n_points = 0
    for scan in scans:
        pose = scan_pose(scan)
        if pose is None:
            continue
        lines, pts = fit_scan(scan, config)
        n_points += pts
        fitted.append((lines, pose))
    t_fit = time.perf_counter() - t0
    n_lines = sum(len(lines) for lines, _ in fitted)

    results = {}
    for name, prefilter in (("bbox prefilter", True), ("all pairs", False)):
        builder = MapBuilder(config.map, spatial_prefilter=prefilter)
        t0 = time.perf_counter()
        for lines, pose in fitted:
            builder.add_scan(lines, pose)
        dt = time.perf_counter() - t0
        results[name] = (dt, builder)

    n = len(fitted)
    print(f"log {log}: {n} scans, {n_points} points, {n_lines} fitted lines")
    print(f"read   {t_read:8.3f} s  ({1e3 * t_read / n:.3f} ms/scan)")
    print(f"fit    {t_fit:8.3f} s  ({1e3 * t_fit / n:.3f} ms/scan)")
    print(
        f"{'merge':<16}{'total s':>9}{'ms/scan':>9}{'pairs tested':>14}{'in gate':>9}"
        f"{'fusions':>9}{'lines':>7}{'segments':>10}"
    )
    for name, (dt, b) in results.items():
        st = b.stats
        m = b.line_map()
        print(
            f"{name:<16}{dt:9.3f}{1e3 * dt / n:9.3f}{st.candidate_pairs_tested:14d}"
            f"{st.pairs_in_gate:9d}{st.fusions:9d}{len(m):7d}{m.n_segments:10d}"
        )
    (d1, b1), (d2, b2) = results["bbox prefilter"], results["all pairs"]
    print(
        f"ratio all-pairs / prefilter: time {d2 / d1:.2f}x, pairs tested "
        f"{b2.stats.candidate_pairs_tested / max(b1.stats.candidate_pairs_tested, 1):.1f}x"
    )
    print(f"map building (fit + merge) of {n} scans: {t_fit + d1:.2f} s (target < 10 s)")
    if args.stress:
        stress()


def stress() -> None:
    """Random lines spread over a large area: the map grows, candidate search dominates."""
    rng = np.random.default_rng(0)
    batches = []
    for _ in range(1000):
        n = 15
        x = np.column_stack(
            [rng.uniform(0.5, 8, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(-1, 1, n)]
        )
        P = np.broadcast_to(np.diag([1e-5, 1e-6, 1e-4]), (n, 3, 3)).copy()
        segs = [np.array([[s - 1, s + 1]]) for s in x[:, 2]]
        var = [np.full((1, 2), 1e-4) for _ in range(n)]
        pose = np.array([rng.uniform(0, 50), rng.uniform(0, 50), rng.uniform(-3, 3)])
        batches.append((x, P, segs, var, pose))
    print("\nstress: 1,000 scans x 15 random lines over 50 m x 50 m")
    times = {}
    for name, prefilter in (("bbox prefilter", True), ("all pairs", False)):
        b = MapBuilder(MapConfig(), spatial_prefilter=prefilter)
        t0 = time.perf_counter()
        for x, P, segs, var, pose in batches:
            b.add_line_arrays(x, P, segs, var, pose)
        times[name] = time.perf_counter() - t0
        print(
            f"{name:<16}{times[name]:9.3f} s  {b.stats.candidate_pairs_tested:12d} pairs  "
            f"{len(b):6d} lines"
        )
    print(f"ratio all-pairs / prefilter: time {times['all pairs'] / times['bbox prefilter']:.1f}x")


if __name__ == "__main__":
    main()
