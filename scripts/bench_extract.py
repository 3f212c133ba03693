"""Line extraction throughput on a log: batch and single-scan APIs, and the C++ reference.

Usage::

    python scripts/bench_extract.py [--log intel] [--scans N] [--batch 64] [--rounds 3]
        [--grouping hough split_merge] [--thresholds default matched] [--reference]

What is timed
-------------
The log is resolved by ``slam.io.catalog.resolve_log`` (``$LINESLAM_DATA``, else
``<repo>/../shared/datasets``) and read once into memory (not timed).  Every measurement runs
over the **same scans** (the whole log, or its first ``--scans``):

* ``batch``: ``extract_lines_batch`` on consecutive chunks of ``--batch`` scans, all
  :class:`~linefit.Line` objects built;
* ``single``: ``extract_lines`` called once per scan (the README's single-scan API);
* ``C++ ref`` (``--reference``): kam3k/laser_line_extraction's harness ``bench_O3`` (built from
  ``../shared/reference/laser_line_extraction/`` with its ``build.sh`` into ``--build-dir``,
  outside the repository; needs the apt packages ``libeigen3-dev libboost-dev``) on the whole
  log: one ``setRangeData`` + ``extractLines`` per scan, its own process-CPU clock around the
  loop (parsing excluded).  It always runs the whole log with its README thresholds: use
  ``--thresholds matched`` and no ``--scans`` for a like-for-like comparison.

Throughput is scans per second of **process CPU time** (``time.process_time`` here,
``CLOCK_PROCESS_CPUTIME_ID`` in the harness), so other jobs on a shared machine slow the wall
clock but not the figure much; wall-clock scans/s are printed as well.  The measurements are
interleaved: each of ``--rounds`` rounds runs every configuration once (and the reference
once), in the same order, and the ratios to the reference are taken round by round; the table
shows the median over rounds and the range of the ratio.  A first untimed pass compiles the
extraction kernels (numba) and warms the caches.

Threshold sets: ``default`` is :class:`~linefit.LineFitConfig` as is; ``matched`` uses the
reference's thresholds where lineslam has the same rule (at least 9 points, at least 0.5 m
long, readings at or above 81 m are "no return").
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import statistics
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from linefit import LineFitConfig, extract_lines, extract_lines_batch
from slam.io.carmen import iter_scans
from slam.io.catalog import resolve_log

REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO.parent / "shared" / "reference" / "laser_line_extraction"
THRESHOLDS = {
    "default": {},
    "matched": {"min_points": 9, "min_length_m": 0.5, "max_range_m": 81.0},
}


def load(log: Path, max_scans: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ranges ``(n, beams)``, shared bearings and per-scan max range of the log's scans."""
    ranges, bearings, max_range = [], None, []
    for k, scan in enumerate(iter_scans(log)):
        if max_scans is not None and k >= max_scans:
            break
        ranges.append(scan.ranges)
        max_range.append(scan.max_range_m)
        if bearings is None:
            bearings = scan.bearings
    assert bearings is not None
    if any(r.shape[0] != bearings.shape[0] for r in ranges):
        raise SystemExit("scans of different widths: this benchmark expects one beam layout")
    return np.stack(ranges), bearings, np.asarray(max_range)


def cpu_model() -> str:
    """CPU model and logical CPU count (Linux), for the record."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.machine()
    models = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return f"{models[0] if models else platform.machine()}, {len(models)} logical CPUs"


def build_reference(build_dir: Path) -> Path:
    """Build the C++ harness with the reference's ``build.sh`` (once); the binary's path."""
    binary = build_dir / "bench_O3"
    if not binary.exists():
        script = REFERENCE / "build.sh"
        if not script.exists():
            raise SystemExit(f"no C++ reference at {REFERENCE} (see its README)")
        subprocess.run(["bash", str(script), str(build_dir)], check=True)
    return binary


def run_reference(binary: Path, log: Path, sigma_d: float, sigma_b: float) -> tuple[float, float]:
    """One pass of the harness over the whole log: (CPU scans/s, wall scans/s)."""
    out = subprocess.run(
        [str(binary), str(log), repr(sigma_d), repr(sigma_b), "1", "0"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    m = re.search(r"rep 0: .*?, ([0-9.]+) scans/s .*?cpu ([0-9.]+) scans/s", out)
    if m is None:
        raise SystemExit(f"unexpected output of {binary}:\n{out}")
    return float(m.group(2)), float(m.group(1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default="intel", help="dataset name or path (default intel)")
    ap.add_argument("--scans", type=int, default=None, help="first N scans (default all)")
    ap.add_argument("--batch", type=int, default=64, help="scans per extract_lines_batch call")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    ap.add_argument("--grouping", nargs="+", default=["hough", "split_merge"])
    ap.add_argument("--thresholds", nargs="+", default=["default", "matched"])
    ap.add_argument("--modes", nargs="+", default=["batch", "single"])
    ap.add_argument("--reference", action="store_true", help="also time the C++ reference")
    ap.add_argument(
        "--build-dir",
        type=Path,
        default=Path(os.environ.get("TMPDIR", "/tmp")) / "lineslam-reference",
        help="where the C++ reference is built (outside the repository)",
    )
    args = ap.parse_args()

    resolved = resolve_log(args.log)
    t0 = time.perf_counter()
    ranges, bearings, max_range = load(resolved.log, args.scans)
    n = ranges.shape[0]
    base = LineFitConfig()
    sigma_d, sigma_b = base.noise.sigma_range_m, base.noise.sigma_bearing_rad
    print(
        f"log {resolved.log}: {n} scans of {ranges.shape[1]} beams, read in "
        f"{time.perf_counter() - t0:.2f} s (not timed)"
    )
    print(f"machine: {cpu_model()}; load average {os.getloadavg()[0]:.2f} at start")
    print(
        f"sigma_d = {sigma_d} m, sigma_phi = {sigma_b} rad, batch = {args.batch} scans, "
        f"{args.rounds} interleaved rounds, process CPU time"
    )

    cases: list[tuple[str, Callable[[], int], int]] = []
    configs: list[LineFitConfig] = []
    for thresholds in args.thresholds:
        for grouping in args.grouping:
            cfg = LineFitConfig(grouping=grouping, **THRESHOLDS[thresholds])  # type: ignore[arg-type]
            configs.append(cfg)

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

            def single(cfg: LineFitConfig = cfg) -> int:
                return sum(
                    len(extract_lines(ranges[k], bearings, cfg, max_range_m=float(max_range[k])))
                    for k in range(n)
                )

            for mode, fn in (("batch", batch), ("single", single)):
                if mode in args.modes:
                    cases.append((f"{thresholds:<8} {grouping:<12} {mode:<7}", fn, n))

    binary = build_reference(args.build_dir) if args.reference else None
    for cfg in configs:  # compile and warm up (not timed)
        extract_lines_batch(
            ranges[: args.batch], bearings, cfg, max_range_m=max_range[: args.batch]
        )
        extract_lines(ranges[0], bearings, cfg, max_range_m=float(max_range[0]))

    cpu: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    wall: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    lines: dict[str, int] = {}
    ref_cpu: list[float] = []
    ref_wall: list[float] = []
    for r in range(args.rounds):
        for name, fn, count in cases:
            w0, c0 = time.perf_counter(), time.process_time()
            lines[name] = fn()
            c1, w1 = time.process_time(), time.perf_counter()
            cpu[name].append(count / (c1 - c0))
            wall[name].append(count / (w1 - w0))
        if binary is not None:
            c, w = run_reference(binary, resolved.log, sigma_d, sigma_b)
            ref_cpu.append(c)
            ref_wall.append(w)
        print(f"round {r + 1}/{args.rounds} done", flush=True)

    header = (
        f"{'thresholds grouping     mode':<30} {'scans':>6} {'cpu scans/s':>11} "
        f"{'wall scans/s':>12} {'lines/scan':>10}"
    )
    if binary is not None:
        header += f" {'ratio to C++ (median, range)':>30}"
    print(header)
    print("-" * len(header))
    for name, _, count in cases:
        row = (
            f"{name:<30} {count:>6} {statistics.median(cpu[name]):>11.0f} "
            f"{statistics.median(wall[name]):>12.0f} {lines[name] / count:>10.2f}"
        )
        if binary is not None:
            ratios = [a / b for a, b in zip(cpu[name], ref_cpu, strict=True)]
            row += f" {statistics.median(ratios):>14.2f}x ({min(ratios):.2f}-{max(ratios):.2f})"
        print(row)
    if binary is not None:
        print(
            f"{'C++ reference (README thresh.)':<30} {'all':>6} "
            f"{statistics.median(ref_cpu):>11.0f} {statistics.median(ref_wall):>12.0f}"
            f"    (per round: {', '.join(f'{c:.0f}' for c in ref_cpu)})"
        )
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
