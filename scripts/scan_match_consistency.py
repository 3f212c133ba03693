"""Is the scan matcher's covariance honest on real scans?  Chained matches against the relations.

Every scan of a log is matched against the one before it (:func:`slam.frontend.scan_match.
match_scans`, the run configuration's ``[slam.frontend.scan_matching]``, the configured motion
model as the odometry's prior, the odometry the estimators read); a match that is not accepted
leaves the odometry step with its prior covariance, and one that contradicts the odometry
(:attr:`~slam.frontend.scan_match.ScanMatch.contradicted`) centres the step with
:func:`~slam.frontend.scan_match.contradicted_covariance`, as the pipeline does.  The matches
are chained
(:func:`slam.lines.transform.compose_chain`, independent steps) and, for every relation
shorter than ``--max-gap-s`` seconds, the chain's relative pose between the relation's two
scans is compared with the relation in the frame a run reports for the log (the
catalogue's ``relations_frame``: the laser's for the catalogued logs; the base, through the
log's laser mounting, where the run reports the base):

* the mean absolute translation and rotation errors of the chain and of the odometry alone;
* the chain's NEES ``eᵀ C⁻¹ e`` (``e = Log(relation⁻¹ · chain)``, ``C`` its chained covariance):
  mean and median, against 3 and 2.37 for an honest covariance (the relations' own scatter is
  part of ``e``: see ``lineslam evaluate``'s "relations' own").

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/scan_match_consistency.py fr079
    .venv/bin/python scripts/scan_match_consistency.py aces --max-scans 3000 --config my.toml

``--lever-arm``: where the relations' frame sits in the chain's frame, the laser's as its
scans see it, fitted to the turns of the relations shorter than ``--max-gap-s``
(:func:`slam.evaluation.odometry_bias.relations_frame_offset`; the same fit to the raw
odometry is ``scripts/odometry_bias.py --mounting``, to a run ``scripts/relations_frame.py
--lever-arm``).  The matches start from the odometry as the prior, so a lever arm the
odometry leaves out pulls them partway towards it.

Nothing is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tqdm import tqdm

from slam.config import RunConfig
from slam.evaluation.odometry_bias import relations_frame_offset
from slam.evaluation.timestamps import match_timestamps
from slam.frontend.scan_match import contradicted_covariance, match_scans, scan_points
from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_inverse, pose_log
from slam.inputs import open_log
from slam.io.relations import read_relations
from slam.lines.transform import compose_chain


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="dataset name or log file")
    parser.add_argument("--relations", type=Path, default=None, help="default: the catalogue's")
    parser.add_argument("--max-gap-s", type=float, default=10.0)
    parser.add_argument("--max-scans", type=int, default=None)
    parser.add_argument("--config", type=Path, default=None, help="TOML run configuration")
    parser.add_argument(
        "--lever-arm",
        action="store_true",
        help="also fit where the relations' frame sits in the chain's (module docstring)",
    )
    args = parser.parse_args()
    config = RunConfig() if args.config is None else RunConfig.from_toml(args.config)
    source = open_log(args.log, config.scanner, max_scans=args.max_scans)
    relations_path = args.relations or source.relations
    if relations_path is None:
        parser.error(f"{args.log}: no relations file known; give --relations FILE")
    sm = config.slam.frontend.scan_matching
    motion = config.slam.motion
    noise = config.linefit.noise
    stamps, steps, covs, odo_steps = [], [], [], []
    prev = prev_points = None
    prev_odom = np.zeros(3)
    n_used = n_slips = n_contradicted = 0
    for scan in tqdm(source.scans(args.max_scans), desc="matching", unit="scan"):
        points = scan_points(scan.ranges, scan.bearings, scan.max_range_m, noise, sm)
        odom = source.policy.pose_odom_laser(scan)  # the laser's, as the estimators read it
        if prev is not None and prev_points is not None:
            delta = pose_between(prev_odom, odom)
            Q = motion.covariance(delta)
            m = match_scans(prev_points, points, delta, Q, sm)
            n_used += int(m.accepted)
            n_slips += int(m.slip)
            n_contradicted += int(m.contradicted)
            if m.accepted:
                steps.append(m.delta)
                covs.append(m.cov)
            elif m.contradicted:
                steps.append(m.delta)
                covs.append(contradicted_covariance(Q, sm, delta, m.delta, body=True))
            else:
                steps.append(delta)
                covs.append(Q)
            odo_steps.append(delta)
        stamps.append(scan.timestamp)
        prev, prev_points, prev_odom = scan, points, odom
    t = np.asarray(stamps)
    steps_a, covs_a, odo_a = np.asarray(steps), np.asarray(covs), np.asarray(odo_steps)
    rel = read_relations(relations_path)
    i1, ok1 = match_timestamps(rel.t1, t, 1e-5)
    i2, ok2 = match_timestamps(rel.t2, t, 1e-5)
    keep = ok1 & ok2 & (rel.t2 - rel.t1 < args.max_gap_s) & (rel.t2 > rel.t1) & (i2 > i1)
    err_m, err_rad, odo_m, odo_rad, nees = [], [], [], [], []
    # laser-frame relative poses in the reported frame: mount ∘ δ ∘ mount⁻¹ for the base
    mount = source.policy.mount if source.policy.output_frame == "base" else np.zeros(3)
    for k in np.flatnonzero(keep):
        a, b = int(i1[k]), int(i2[k])
        poses, pcov = compose_chain(steps_a[a:b], covs_a[a:b])
        chain, C = poses[-1], pcov[-1]
        odo = compose_chain(odo_a[a:b])[0][-1]
        to_base = pose_compose(mount, pose_compose(chain, pose_inverse(mount)))
        odo_base = pose_compose(mount, pose_compose(odo, pose_inverse(mount)))
        Ad = adjoint_pose2(mount)
        C_base = Ad @ C @ Ad.T
        e = pose_log(pose_between(rel.poses[k], to_base))
        eo = pose_log(pose_between(rel.poses[k], odo_base))
        err_m.append(float(np.hypot(e[0], e[1])))
        err_rad.append(abs(float(e[2])))
        odo_m.append(float(np.hypot(eo[0], eo[1])))
        odo_rad.append(abs(float(eo[2])))
        nees.append(float(e @ np.linalg.solve(C_base, e)))
    n = len(nees)
    print(
        f"{source.name}: {len(stamps)} scans, {n_used} of {len(steps)} matches used, "
        f"{n_slips} slips, {n_contradicted} not used that contradict the odometry"
    )
    print(f"relations shorter than {args.max_gap_s:g} s: {n}")
    if n == 0:
        return
    print(
        f"chained matches: {np.mean(err_m):.4f} m, {np.degrees(np.mean(err_rad)):.3f} deg; "
        f"odometry: {np.mean(odo_m):.4f} m, {np.degrees(np.mean(odo_rad)):.3f} deg"
    )
    print(
        f"NEES of the chained matches: mean {np.mean(nees):.2f} (3 if honest), "
        f"median {np.median(nees):.2f} (2.37), inside the 95 % ellipsoid "
        f"{np.mean(np.asarray(nees) <= 7.815):.3f}"
    )
    if args.lever_arm:
        chain_poses = compose_chain(steps_a)[0]  # the laser's, from the first scan
        off = relations_frame_offset(
            t, chain_poses, rel.t1, rel.t2, rel.poses, short_s=args.max_gap_s
        )
        print(
            f"lever arm from the {off.relations} relations shorter than {args.max_gap_s:g} s: "
            f"the relations' frame at x {off.x_m:+.4f} m (sd {off.sd_x_m:.4f}), "
            f"y {off.y_m:+.4f} m (sd {off.sd_y_m:.4f}) in the chain's (the laser's) frame"
        )


if __name__ == "__main__":
    main()
