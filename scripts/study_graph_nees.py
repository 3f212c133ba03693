"""Monte-Carlo consistency study of LineSlam on the simulator: pose NEES over seeded runs.

Simulates the ``loop`` world (ray-cast scans, the paper's laser noise, random-walk odometry
without bias), runs LineSlam (lines extracted by linefit) with the matching motion model, and
prints, over the runs, the average pose NEES at spaced scans with the two-sided 95 % χ² band
of an average of ``runs`` χ²₃ samples, and the ATE / relations error against odometry.

    .venv/bin/python scripts/study_graph_nees.py [--runs 20] [--backend isam2] [--scans 200]
"""

from __future__ import annotations

import argparse
import time
import warnings

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import numpy as np
from scipy.stats import chi2

from slam.geometry import pose_between, pose_log
from slam.line_slam import LineSlam, SlamConfig, SlamWarning
from slam.models import MotionNoiseConfig
from slam.sim import OdometryNoiseConfig, SimConfig, get_world
from slam.sim.simulate import simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--backend", choices=["isam2", "batch"], default="isam2")
    parser.add_argument("--scans", type=int, default=200, help="scans per run (from the start)")
    parser.add_argument("--every", type=int, default=20, help="NEES at every N-th scan")
    args = parser.parse_args()
    odo = OdometryNoiseConfig(sigma_trans_per_m=0.02, sigma_rot_per_rad=0.02, sigma_rot_per_m=0.02)
    motion = MotionNoiseConfig(
        sigma_xy_per_m=odo.sigma_trans_per_m,
        sigma_xy_per_rad=0.0,
        sigma_theta_per_m=odo.sigma_rot_per_m,
        sigma_theta_per_rad=odo.sigma_rot_per_rad,
        sigma_xy_min_m=1e-4,
        sigma_theta_min_rad=1e-5,
    )
    world = get_world("loop")
    nees, ate, ate_odo, times = [], [], [], []
    for run in range(args.runs):
        log = simulate(world, None, SimConfig(odometry=odo), seed=1000 + run)
        slam = LineSlam(SlamConfig(backend=args.backend, motion=motion))
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SlamWarning)
            for k, scan in enumerate(log.scans()):
                if k >= args.scans:
                    break
                slam.add_scan(scan)
            slam.optimize()
        res = slam.result()
        times.append(time.perf_counter() - t0)
        n = res.n_scans
        truth = log.poses_world_laser[:n]
        e = pose_log(pose_between(truth, res.poses_world_laser))
        e_odo = pose_log(pose_between(truth, log.poses_odom_laser[:n]))
        nees.append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(res.pose_covariances), e))
        ate.append(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))
        ate_odo.append(np.sqrt(np.mean(np.sum(e_odo[:, :2] ** 2, axis=1))))
        print(f"run {run}: ATE {ate[-1]:.4f} m (odometry {ate_odo[-1]:.3f} m), {times[-1]:.1f} s")
    N = np.array(nees)
    R = N.shape[0]
    lo, hi = chi2.ppf([0.025, 0.975], 3 * R) / R
    print()
    print(f"{R} runs, {N.shape[1]} scans each, backend {args.backend}")
    print(f"average pose NEES over runs (3 dof), 95 % band [{lo:.2f}, {hi:.2f}]:")
    for k in range(0, N.shape[1], args.every):
        mark = "" if lo <= N[:, k].mean() <= hi else "  <- outside"
        print(f"  scan {k:4d}: {N[:, k].mean():6.2f}{mark}")
    inside = np.mean([(lo <= N[:, k].mean() <= hi) for k in range(1, N.shape[1])])
    print(f"fraction of scans inside the band: {inside:.2f}; mean over all: {N[:, 1:].mean():.2f}")
    print(f"ATE mean {np.mean(ate):.4f} m (odometry {np.mean(ate_odo):.3f} m)")
    print(f"time per run {np.mean(times):.1f} s")


if __name__ == "__main__":
    main()
