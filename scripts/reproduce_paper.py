"""Reproduce the paper's Section VI table: points → lines → merged lines → compression.

Simulated sequences with the paper's sensor (σ_d = 5 mm, σ_φ = 1e-4 rad, 720 points per scan) in a
hallway with door recesses and in a laboratory, for 1, 2, 8 and 10 poses, printed beside the
paper's numbers; then the same table on the first scans of each real log (odometry poses).

The simulated poses are the odometry of the simulator; each scan's pose covariance is the
odometry covariance compounded from the first pose (`compose_chain`), i.e. the paper's P^ij
with i = the first pose.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/reproduce_paper.py [--seed 0]
"""

from __future__ import annotations

import argparse
from itertools import islice

import numpy as np

from slam.config import RunConfig
from slam.lines.mapbuilder import MapBuilder
from slam.mapping import (
    build_map,
    compression,
    fit_scan,
    scan_pose,
    simulate_paper_sequence,
    write_map_results,
)

# (data, points, lines, merged, compression %) from Sec. VI (reading notes)
PAPER = {
    ("hallway", 1): (720, 9, None, 97.0),
    ("hallway", 2): (1440, 20, 14, 98.0),
    ("hallway", 8): (5760, 93, 29, 98.9),
    ("laboratory", 10): (7200, 141, 60, 98.9),
}


def row(name: str, points: int, lines: int, merged: int, segments: int, ref: str = "") -> str:
    return (
        f"| {name} | {points} | {lines} | {merged} ({segments}) | "
        f"{100 * compression(points, lines):.1f} % | {100 * compression(points, merged):.1f} % | "
        f"{100 * compression(points, segments):.1f} % | {ref} |"
    )


HEADER = (
    "| data | points | lines | merged lines (segments) | compression fit | "
    "compression merged (line = 2 pts) | (segment = 2 pts) | paper |\n"
    "|---|---|---|---|---|---|---|---|"
)


def sim_rows(config: RunConfig, seed: int, figures: str | None, pose_cov: str) -> list[str]:
    from pathlib import Path

    out = []
    for world, label in (("hallway", "hallway"), ("lab", "laboratory")):
        for n in (1, 2, 8, 10):
            rng = np.random.default_rng([seed, n, len(world)])
            scans, covs = simulate_paper_sequence(world, n, rng, pose_cov)
            run = build_map(scans, config, pose_covs=covs, collect_figures=figures is not None)
            s = run.summary
            paper = PAPER.get((label, n))
            ref = ""
            if paper is not None:
                p, l, m, c = paper
                ref = f"{p} → {l} → {'–' if m is None else m}, {c} %"
            out.append(
                row(
                    f"{n} pose(s), {label} (sim)",
                    s["points"],
                    s["lines_fit"],
                    s["lines_merged"],
                    s["segments_merged"],
                    ref,
                )
            )
            if figures is not None and (world, n) in (("hallway", 8), ("lab", 10), ("hallway", 2)):
                folder = Path(figures) / f"sim_{world}_{n}"
                folder.mkdir(parents=True, exist_ok=True)
                write_map_results(folder, run, title=f"simulated {label}, {n} poses")
    return out


def real_log_rows(config: RunConfig, counts: tuple[int, ...]) -> list[str]:
    from slam.io.carmen import iter_scans
    from slam.io.catalog import resolve_log

    out = []
    for name in ("intel", "aces", "fr079"):
        try:
            log = resolve_log(name).log
        except Exception as exc:  # a missing dataset is reported, not fatal
            out.append(f"| {name} | missing: {exc} |")
            continue
        scans = list(islice(iter_scans(log), max(counts)))
        fitted = [(fit_scan(s, config), scan_pose(s)) for s in scans]
        for n in counts:
            b = MapBuilder(config.map)
            pts = lines = 0
            for (ls, p), pose in fitted[:n]:
                if pose is None:
                    continue
                b.add_scan(ls, pose)
                pts += p
                lines += len(ls)
            m = b.line_map()
            out.append(row(f"{name}, first {n} scans", pts, lines, len(m), m.n_segments))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--figures", default=None, help="folder for the paper-style figures")
    parser.add_argument("--no-real", action="store_true", help="skip the real logs")
    parser.add_argument(
        "--pose-cov",
        choices=("step", "chain"),
        default="step",
        help="each scan's pose covariance: the odometry step from the previous scan (default) "
        "or odometry compounded from the first scan (the paper's P^1j)",
    )
    args = parser.parse_args()
    config = RunConfig(seed=args.seed)

    print("Paper (Sec. VI):\n")
    print("| data | points | lines | merged | compression |\n|---|---|---|---|---|")
    for (world, n), (p, l, m, c) in PAPER.items():
        print(f"| {n} pose(s), {world} | {p} | {l} | {'–' if m is None else m} | {c} % |")
    what = {
        "step": "the odometry step from the previous scan",
        "chain": "the odometry compounded from the first scan",
    }[args.pose_cov]
    print("\nlineslam, simulated (σ_d 5 mm, σ_φ 1e-4 rad, 720 beams; odometry poses, each with")
    print(f"the covariance of {what}; seed {args.seed}):\n")
    print(HEADER)
    for line in sim_rows(config, args.seed, args.figures, args.pose_cov):
        print(line)
    if not args.no_real:
        print("\nReal logs (odometry poses, default [map] pose covariance):\n")
        print(HEADER)
        for line in real_log_rows(config, (1, 2, 8, 10, 100)):
            print(line)


if __name__ == "__main__":
    main()
