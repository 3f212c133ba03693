"""Estimate a log's odometry noise (random-walk model) from its ground-truth relations.

For every relation ``(t1, t2)`` short enough to reflect the local noise (path length below
``--max-distance`` and turning below ``--max-turn`` by the odometry), the odometry's relative
pose is compared with the relation: ``ξ = Log(relation⁻¹ · odometry⁻¹(t1) · odometry(t2))``.
Least squares on the squared errors then fits the model the estimators use
(``slam.models.motion.MotionNoiseConfig``, used by the graph and the EKF; the
``sigma_xy_per_rad`` term is not fitted and printed as 0):

    E[ξ_x² + ξ_y²] / 2 = σ_t² · Δs,        E[ξ_θ²] = σ_rr² · |Δθ| + σ_rm² · Δs

with ``Δs`` the odometry path length and ``|Δθ|`` the summed absolute turning between the two
scans.  Prints the values as ``[slam.motion]`` and ``[ekf.odometry]`` TOML tables (the same
model); the configuration lineslam uses by default is one for all logs, so these are for
experiments only (``configs/``).

Usage: python scripts/calibrate_odometry.py LOG [--max-distance 2.0] [--max-turn 1.5]
"""

from __future__ import annotations

import argparse

import numpy as np

from slam.geometry import pose_between, pose_log
from slam.io import iter_scans, read_relations, resolve_log


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", help="log file or dataset name (needs its relations)")
    ap.add_argument("--max-distance", type=float, default=2.0, help="m of odometry path")
    ap.add_argument("--max-turn", type=float, default=1.5, help="rad of summed turning")
    args = ap.parse_args()
    log = resolve_log(args.log)
    relations = log.relations
    if relations is None and (log.log.parent / "relations.txt").is_file():
        relations = log.log.parent / "relations.txt"  # a `lineslam simulate` folder
    if relations is None:
        raise SystemExit(f"{args.log}: no relations file known for this log")
    stamps, odom = [], []
    for scan in iter_scans(log.log):
        pose = scan.pose_odom_laser if scan.pose_odom_laser is not None else scan.pose_odom_base
        stamps.append(scan.timestamp)
        odom.append(pose)
    odo = np.asarray(odom, dtype=float)
    index = {t: i for i, t in enumerate(stamps)}
    inc = pose_between(odo[:-1], odo[1:])
    cum_s = np.concatenate([[0.0], np.cumsum(np.hypot(inc[:, 0], inc[:, 1]))])
    cum_r = np.concatenate([[0.0], np.cumsum(np.abs(inc[:, 2]))])
    rel = read_relations(relations)
    rows = []
    for t1, t2, p in zip(rel.t1, rel.t2, rel.poses, strict=True):
        i, j = index.get(float(t1)), index.get(float(t2))
        if i is None or j is None:
            continue
        if j < i:
            i, j, p = j, i, pose_between(p, np.zeros(3))
        xi = pose_log(pose_between(p, pose_between(odo[i], odo[j])))
        rows.append((cum_s[j] - cum_s[i], cum_r[j] - cum_r[i], *xi))
    r = np.asarray(rows)
    short = r[(r[:, 0] < args.max_distance) & (r[:, 1] < args.max_turn)]
    if short.shape[0] < 10:
        raise SystemExit("fewer than 10 short relations: widen --max-distance / --max-turn")
    ds, dr = short[:, 0], short[:, 1]
    (a,) = np.linalg.lstsq(ds[:, None], 0.5 * (short[:, 2] ** 2 + short[:, 3] ** 2), rcond=None)[0]
    b = np.linalg.lstsq(np.column_stack([dr, ds]), short[:, 4] ** 2, rcond=None)[0]
    print(
        f"# {log.name}: {short.shape[0]} of {r.shape[0]} relations used "
        f"(median path {np.median(ds):.2f} m, median turning {np.median(dr):.2f} rad)"
    )
    for table in ("slam.motion", "ekf.odometry"):
        print(f"\n[{table}]")
        print(f"sigma_xy_per_m = {np.sqrt(max(a, 0.0)):.4f}")
        print("sigma_xy_per_rad = 0.0")
        print(f"sigma_theta_per_m = {np.sqrt(max(b[1], 0.0)):.4f}")
        print(f"sigma_theta_per_rad = {np.sqrt(max(b[0], 0.0)):.4f}")


if __name__ == "__main__":
    main()
