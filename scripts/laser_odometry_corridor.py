"""Does the laser odometry keep its speed along a corridor whose walls show nothing along it?

Usage::

    python scripts/laser_odometry_corridor.py
    python scripts/laser_odometry_corridor.py --range-offset-m 0.01 --seeds 0 1 2

A simulated corridor 1.8 m wide: two door recesses (0.9 m wide, 0.3 m deep) on each side near
the start, from which the speed can be read, then 60 m of plain wall.  A 180-beam scanner (1°
steps) drives along its middle at ``--step-m`` per scan (5 scans/s); its ranges carry 5 mm of
Gaussian noise, plus ``--range-offset-m`` on every reading (a scanner that reads long) and,
with ``--range-step-m``, are written in steps of that size; readings beyond ``--view-m`` are
no-return, so the corridor's far end is never seen.  The laser odometry
(:class:`slam.frontend.laser_odometry.LaserOdometry`, the defaults) runs over the scans.

Printed per seed: the error along the corridor after the recesses (scan 30) and at the end,
and the distance the laser odometry travelled over the last 50 scans as a fraction of the true
one (1: it kept the speed; 0: it stopped).  Nothing is written.
"""

from __future__ import annotations

import argparse

import numpy as np

from slam.frontend.laser_odometry import LaserOdometry
from slam.sim.raycast import cast_scan
from slam.sim.world import World, WorldBuilder
from slam.types import Scan

HALF_WIDTH_M = 0.9
BEARINGS = np.deg2rad(np.arange(-89.5, 90.0, 1.0))
NO_RETURN_M = 30.0


def corridor() -> World:
    """The corridor: recesses at 0.5-1.4 m and 2.5-3.4 m on both sides, plain to 60 m."""
    b = WorldBuilder()
    for side in (-1.0, 1.0):
        y = HALF_WIDTH_M * side
        corners = [(-5.0, y)]
        for x0 in (0.5, 2.5):
            corners += [(x0, y), (x0, y + 0.3 * side), (x0 + 0.9, y + 0.3 * side), (x0 + 0.9, y)]
        corners.append((60.0, y))
        b.polyline(corners)
    return b.build("corridor")


def run(seed: int, args: argparse.Namespace, world: World) -> tuple[float, float, float]:
    """(error along at scan 30, error along at the end, travelled fraction over the last 50)."""
    rng = np.random.default_rng(seed)
    truth = np.array([[args.step_m * i, 0.0, 0.0] for i in range(args.scans)])
    laser = LaserOdometry()
    poses = []
    for i, pose in enumerate(truth):
        r = cast_scan(pose, BEARINGS, world, NO_RETURN_M)[0]
        r = r + args.range_offset_m + 0.005 * rng.standard_normal(BEARINGS.size)
        if args.range_step_m > 0.0:
            r = np.round(r / args.range_step_m) * args.range_step_m
        r = np.where(r < args.view_m, r, NO_RETURN_M)
        poses.append(laser.add(Scan(i, 0.2 * i, r, BEARINGS, max_range_m=NO_RETURN_M)))
    est = np.array(poses)
    last = min(50, args.scans - 1)
    travelled = (est[-1, 0] - est[-1 - last, 0]) / (truth[-1, 0] - truth[-1 - last, 0])
    return float(est[30, 0] - truth[30, 0]), float(est[-1, 0] - truth[-1, 0]), float(travelled)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--scans", type=int, default=90, help="scans (at least 31)")
    ap.add_argument("--step-m", type=float, default=0.15, help="motion per scan (m)")
    ap.add_argument("--range-offset-m", type=float, default=0.0, help="added to every range")
    ap.add_argument("--range-step-m", type=float, default=0.0, help="ranges written in steps")
    ap.add_argument("--view-m", type=float, default=8.0, help="readings beyond: no return")
    args = ap.parse_args()
    if args.scans < 31:
        ap.error("--scans must be at least 31")
    world = corridor()
    print(
        f"corridor {2 * HALF_WIDTH_M:.1f} m wide, {args.scans} scans {args.step_m} m apart, "
        f"range offset {args.range_offset_m} m, range step {args.range_step_m} m, "
        f"view {args.view_m} m"
    )
    for seed in args.seeds:
        at_30, at_end, travelled = run(seed, args, world)
        print(
            f"  seed {seed}: error along at scan 30 {at_30:+.3f} m, at the end {at_end:+.3f} m;"
            f" travelled over the last 50 scans {travelled:.2f} of the true distance"
        )


if __name__ == "__main__":
    main()
