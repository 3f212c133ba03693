"""Reproduce the paper's Section VI table: points → lines → merged lines → compression.

Simulated sequences with the paper's sensor (σ_d = 5 mm, σ_φ = 1e-4 rad, 720 points per scan) in a
hallway with door recesses and in a laboratory, for 1, 2, 8 and 10 poses, printed beside the
paper's numbers; then the same table on the first scans of each real log (odometry poses).

The simulated poses are the odometry of the simulator; each scan's pose covariance is the
odometry covariance compounded from the first pose (`compose_chain`), i.e. the paper's P^ij
with i = the first pose.

    LINESLAM_DATA=/work/shared/datasets .venv/bin/python scripts/reproduce_paper.py [--seed 0]
"""

from __future__ import annotations

import argparse
from itertools import islice

import numpy as np

from slam.config import RunConfig
from slam.lines.mapbuilder import MapBuilder
from slam.lines.transform import compose_chain
from slam.mapping import build_map, compression, fit_scan, scan_pose, write_map_results
from slam.types import Scan

# (data, points, lines, merged, compression %) from Sec. VI (reading notes)
PAPER = {
    ("hallway", 1): (720, 9, None, 97.0),
    ("hallway", 2): (1440, 20, 14, 98.0),
    ("hallway", 8): (5760, 93, 29, 98.9),
    ("laboratory", 10): (7200, 141, 60, 98.9),
}


def row(name: str, points: int, lines: int, merged: int, segments: int) -> str:
    return (
        f"| {name} | {points} | {lines} | {merged} ({segments}) | "
        f"{100 * compression(points, lines):.1f} % | {100 * compression(points, merged):.1f} % | "
        f"{100 * compression(points, segments):.1f} % |"
    )


HEADER = (
    "| data | points | lines | merged lines (segments) | compression fit | "
    "compression merged (line = 2 pts) | (segment = 2 pts) |\n|---|---|---|---|---|---|---|"
)


SIGMA_D, SIGMA_PHI = 0.005, 1e-4
N_BEAMS = 720  # the paper's 720 points per scan: 0.25° over 180°
SPACING_M = {"hallway": 3.5, "lab": 2.4}  # distance between the poses along the path


def sim_sequence(world_name: str, n_poses: int, rng: np.random.Generator):
    """``n_poses`` scans along the world's path with the paper's sensor, odometry poses.

    Returns the scans (``pose_odom_laser`` = odometry) and each pose's covariance relative to
    the first pose (odometry compounded with :func:`compose_chain`: the paper's ``P^1j``).
    """
    from slam.sim import (
        cast_scan,
        get_world,
        motion_noise_covariance,
        noisy_motions,
        relative_motions,
        trajectory_from_waypoints,
    )
    from slam.sim.config import OdometryNoiseConfig, TrajectoryConfig

    world = get_world(world_name)
    traj = trajectory_from_waypoints(world.waypoints, TrajectoryConfig(scan_spacing_m=0.05))
    path = traj.poses_world_base
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path[:, :2], axis=0).T))])
    targets = 1.0 + SPACING_M[world_name] * np.arange(n_poses)
    truth = path[np.searchsorted(arc, targets)]
    odo = OdometryNoiseConfig()
    motions = relative_motions(truth)
    est, covs = compose_chain(
        noisy_motions(motions, odo, rng), motion_noise_covariance(motions, odo), truth[0]
    )
    bearings = -np.pi / 2 + np.arange(N_BEAMS) * (np.pi / N_BEAMS)
    scans = []
    for k, pose in enumerate(truth):
        # the paper's noise model: the ray is cast at Φ + ε_φ, reported at Φ; range + ε_d
        ranges, _ = cast_scan(pose, bearings + rng.normal(0, SIGMA_PHI, N_BEAMS), world, 80.0)
        ranges = np.where(np.isfinite(ranges), ranges + rng.normal(0, SIGMA_D, N_BEAMS), 80.0)
        scans.append(Scan(k, float(k), ranges, bearings, max_range_m=80.0, pose_odom_laser=est[k]))
    return scans, list(covs)


def sim_rows(config: RunConfig, seed: int, figures: str | None) -> list[str]:
    from pathlib import Path

    out = []
    for world, label in (("hallway", "hallway"), ("lab", "laboratory")):
        for n in (1, 2, 8, 10):
            rng = np.random.default_rng([seed, n, len(world)])
            scans, covs = sim_sequence(world, n, rng)
            run = build_map(scans, config, pose_covs=covs, collect_figures=figures is not None)
            s = run.summary
            paper = PAPER.get((label, n))
            ref = ""
            if paper is not None:
                p, l, m, c = paper
                ref = f" paper: {p} → {l} → {'–' if m is None else m}, {c} %"
            out.append(
                row(
                    f"{n} pose(s), {label} (sim)",
                    s["points"],
                    s["lines_fit"],
                    s["lines_merged"],
                    s["segments_merged"],
                )
                + ref
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
    args = parser.parse_args()
    config = RunConfig(seed=args.seed)

    print("Paper (Sec. VI):\n")
    print("| data | points | lines | merged | compression |\n|---|---|---|---|---|")
    for (world, n), (p, l, m, c) in PAPER.items():
        print(f"| {n} pose(s), {world} | {p} | {l} | {'–' if m is None else m} | {c} % |")
    print("\nlineslam, simulated (σ_d 5 mm, σ_φ 1e-4 rad, 720 beams; odometry poses with")
    print("the compounded odometry covariance from the first pose):\n")
    print(HEADER)
    for line in sim_rows(config, args.seed, args.figures):
        print(line)
    if not args.no_real:
        print("\nReal logs (odometry poses, default [map] pose covariance):\n")
        print(HEADER)
        for line in real_log_rows(config, (1, 2, 8, 10)):
            print(line)


if __name__ == "__main__":
    main()
