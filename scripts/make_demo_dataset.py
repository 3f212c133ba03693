"""Regenerate the demo dataset ``datasets/sim/demo/`` (the log that ``make demo`` runs on).

Deterministic: the same command gives byte-identical files (checked by the test suite, which
regenerates the log in a temporary folder and compares it with the committed one).

    .venv/bin/python scripts/make_demo_dataset.py [--out datasets/sim/demo]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from slam.geometry import pose_between, pose_compose, pose_inverse
from slam.sim import OdometryNoiseConfig, SimConfig, get_world
from slam.sim.simulate import SimulatedLog, simulate
from slam.sim.write import write_simulation

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "datasets" / "sim" / "demo"

#: The demo: the corridor loop, 180 beams, the paper's laser noise, odometry with 1 % scale error
#: and 0.0015 rad/m heading drift on top of the default random noise; seed 2.
DEMO_CONFIG = SimConfig(
    world="loop",
    seed=2,
    odometry=OdometryNoiseConfig(scale_bias=0.01, heading_drift_rad_per_m=0.0015),
)


def make_demo(out: Path = DEFAULT_OUT) -> SimulatedLog:
    """Simulate the demo log and write it (without ``beam_hits.npy``) to ``out``."""
    log = simulate(get_world(DEMO_CONFIG.world), None, DEMO_CONFIG)
    write_simulation(log, out, beam_hits=False)
    return log


def odometry_relations_error(log: SimulatedLog) -> tuple[float, float]:
    """Mean |translation| (m) and |rotation| (deg) relation error of the odometry alone."""
    i, j = log.relation_pairs.T
    gt, odom = log.poses_world_laser, log.poses_odom_laser
    err = pose_compose(pose_between(odom[i], odom[j]), pose_inverse(pose_between(gt[i], gt[j])))
    return float(np.hypot(err[:, 0], err[:, 1]).mean()), float(np.degrees(np.abs(err[:, 2])).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    log = make_demo(args.out)
    end = float(np.linalg.norm(log.poses_odom_base[-1, :2] - log.poses_world_base[-1, :2]))
    trans, rot = odometry_relations_error(log)
    size = sum(p.stat().st_size for p in args.out.iterdir() if p.is_file())
    print(
        f"{args.out}: {log.n_scans} scans x {log.n_beams} beams, "
        f"{len(log.relation_pairs)} relations, odometry end error {end:.2f} m, "
        f"odometry-only relations error {trans:.3f} m / {rot:.2f} deg, {size / 1e6:.2f} MB"
    )


if __name__ == "__main__":
    main()
