"""What a log's short relations can tell: a run and the raw odometry against them, side by side.

Usage::

    python scripts/short_relations.py RESULTS_DIR --log aces [--max-gap-s 10] [--coincide-m 0.01]

``RESULTS_DIR`` is a ``lineslam slam`` results folder (``trajectory.tum``, ``summary.json``);
``--log`` the dataset name or CARMEN log it ran on (its relations file and its odometry; give
``--relations FILE`` for a log outside the catalogue).  For every relation shorter than
``--max-gap-s`` seconds whose two time stamps are scans of the run, the translation error
``‖(t_run − t_rel)‖`` of the run and of the odometry (the log's own laser poses, as
``scripts/robustness.py`` scores them) are computed, and split into

* relations the odometry *coincides* with (translation error below ``--coincide-m``): the
  relation and the odometry agree to the last centimetre, so the run can only lose there;
* the others, where the run, the odometry and the relation are three measurements of one
  motion.  Their pairwise mean squared differences give each one's own noise by the
  three-cornered hat (``σ_rel² = (V_run,rel + V_odo,rel − V_run,odo)/2`` and alike, per axis;
  exact if the three errors are independent): how far the relations themselves scatter.

Printed: counts, mean errors of both, the correlation of the run's and the odometry's error
vectors, and the three noise levels.  Nothing is written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slam.evaluation.reference_noise import three_cornered_hat
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between
from slam.io.carmen import scan_trajectory
from slam.io.catalog import resolve_log
from slam.io.relations import read_relations
from slam.io.tum import read_tum


def _relative_xy(poses: np.ndarray, i1: np.ndarray, i2: np.ndarray) -> np.ndarray:
    return np.asarray(pose_between(poses[i1], poses[i2]))[:, :2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="lineslam slam results folder")
    ap.add_argument("--log", required=True, help="dataset name or CARMEN log of the run")
    ap.add_argument("--relations", type=Path, help="relations file (default: the dataset's)")
    ap.add_argument("--max-gap-s", type=float, default=10.0, help="short: |t2 - t1| below this")
    ap.add_argument(
        "--coincide-m", type=float, default=0.01, help="odometry coincides below this (m)"
    )
    args = ap.parse_args()

    resolved = resolve_log(args.log)
    rel_path = args.relations or resolved.relations
    if rel_path is None:
        ap.error(f"{args.log}: no relations file; give --relations")
    relations = read_relations(rel_path)
    run = read_tum(args.results / "trajectory.tum")
    summary = json.loads((args.results / "summary.json").read_text())
    odometry = scan_trajectory(resolved.log, frame="laser")

    short = np.abs(relations.t2 - relations.t1) < args.max_gap_s
    rel = relations.subset(short)
    i1, ok1 = match_timestamps(rel.t1, run.timestamps, 1e-5)
    i2, ok2 = match_timestamps(rel.t2, run.timestamps, 1e-5)
    j1, okj1 = match_timestamps(rel.t1, odometry.timestamps, 1e-5)
    j2, okj2 = match_timestamps(rel.t2, odometry.timestamps, 1e-5)
    used = ok1 & ok2 & okj1 & okj2
    if not used.any():
        ap.error("no short relation has both stamps in the run and in the log")
    truth = rel.poses[used, :2]
    e_run = _relative_xy(run.poses, i1[used], i2[used]) - truth
    e_odo = _relative_xy(odometry.poses, j1[used], j2[used]) - truth
    d_run = np.hypot(e_run[:, 0], e_run[:, 1])
    d_odo = np.hypot(e_odo[:, 0], e_odo[:, 1])
    same = d_odo < args.coincide_m
    other = ~same

    print(f"{args.results} (frame {summary.get('frame', '?')}) against {rel_path}")
    print(f"short relations (< {args.max_gap_s:g} s) used: {int(used.sum())}")
    print(f"  mean translation error  run {d_run.mean():.4f} m   odometry {d_odo.mean():.4f} m")
    print(
        f"  odometry coincides (< {args.coincide_m:g} m): {int(same.sum())}"
        f"   run {d_run[same].mean() if same.any() else float('nan'):.4f} m"
        f"   odometry {d_odo[same].mean() if same.any() else float('nan'):.4f} m"
    )
    if other.sum() < 3:
        return
    er, eo = e_run[other], e_odo[other]
    diff = np.hypot(*(er - eo).T)
    corr = [float(np.corrcoef(er[:, k], eo[:, k])[0, 1]) for k in range(2)]
    print(
        f"  the other {int(other.sum())}: run {d_run[other].mean():.4f} m   odometry "
        f"{d_odo[other].mean():.4f} m   |run - odometry| {diff.mean():.4f} m"
    )
    print(
        f"    correlation of the run's and the odometry's errors: x {corr[0]:.2f}, y {corr[1]:.2f}"
    )
    hat = dict(zip(("relations", "run", "odometry"), three_cornered_hat(er, eo), strict=True))
    print("    three-cornered hat, RMS per axis (x, y) in m (negative variance: shown as 0):")
    for name, v in hat.items():
        s = np.sqrt(np.maximum(v, 0.0))
        print(f"      {name:<10} {s[0]:.4f}  {s[1]:.4f}")


if __name__ == "__main__":
    main()
