"""Which frame a log's relations relate: a run scored with its poses moved along the laser axis.

Usage::

    python scripts/relations_frame.py RESULTS_DIR --log fr079 [--offsets -0.04 0 0.04 0.08]

``RESULTS_DIR`` is a ``lineslam slam`` results folder (``trajectory.tum``, ``summary.json``,
``graph.g2o``); ``--log`` the dataset name or log it ran on (its relations file; ``--relations
FILE`` for a log outside the catalogue).  For every offset ``x`` (m) the trajectory's poses are
moved to ``pose ∘ (x, 0, 0)`` — a frame ``x`` ahead of the reported one along its own axis,
which for a laser mounted straight ahead is the axis from the base to the laser — and scored
with the Kümmerle relations metric (mean absolute translation and rotation), over all
relations and over those whose two scans are both keyframes (whose poses come from the lines,
not from odometry carried on from a keyframe).  Rotations do not change with ``x``; the
translation error is least near the frame the relations relate.  The frame the run reports and
the mounting it used are printed, so the laser frame's offset is known: ``+mount_x`` when the
run reports the base.

``--lever-arm`` also fits where the relations' frame sits in the run's reported frame from the
relations shorter than ``--short`` seconds: ``relation ≈ M⁻¹ · (the run's relative pose) · M``
with ``M = (x, y, 0)``, the lever arm that moves a frame sideways on every turn
(:func:`slam.evaluation.odometry_bias.fit_odometry_calibration`, ``parameters="mounting"``,
the run's trajectory in place of the odometry), with its spread over bootstrap resamples of
those relations (``--seed``).  Straight relations carry no information on it, turns do.  Near
zero: the relations relate the frame the run reports (the laser's, as its scans see it);
``scripts/odometry_bias.py NAME --mounting`` gives the same fit for the raw odometry.

    python scripts/relations_frame.py results/fr079 --log fr079 --lever-arm

Nothing is written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slam.errors import EvaluationError
from slam.evaluation.odometry_bias import relations_frame_offset
from slam.evaluation.relations_metric import relations_metric, relations_within
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_compose
from slam.io.catalog import resolve_log
from slam.io.g2o import read_line_graph_g2o
from slam.io.relations import Relations, read_relations
from slam.io.trajectory import Trajectory
from slam.io.tum import read_tum

#: Bootstrap resamples of the lever arm's spread.
RESAMPLES = 50


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="lineslam slam results folder")
    ap.add_argument("--log", required=True, help="dataset name or CARMEN log of the run")
    ap.add_argument("--relations", type=Path, help="relations file (default: the dataset's)")
    ap.add_argument(
        "--offsets",
        type=float,
        nargs="+",
        default=[-0.04, -0.02, 0.0, 0.02, 0.04, 0.06, 0.08, 0.10],
        help="offsets x (m) along the reported frame's axis",
    )
    ap.add_argument(
        "--lever-arm",
        action="store_true",
        help="also fit where the relations' frame sits in the reported frame (module doc)",
    )
    ap.add_argument("--short", type=float, default=10.0, help="s: relations the fit uses")
    ap.add_argument("--seed", type=int, default=0, help="seed of the bootstrap resamples")
    args = ap.parse_args()

    rel_path = args.relations or resolve_log(args.log).relations
    if rel_path is None:
        ap.error(f"{args.log}: no relations file; give --relations")
    run = read_tum(args.results / "trajectory.tum")
    summary = json.loads((args.results / "summary.json").read_text())
    relations = relations_within(read_relations(rel_path), run.timestamps)
    keyframes = read_line_graph_g2o(args.results / "graph.g2o").timestamps
    if keyframes is None:
        ap.error(f"{args.results / 'graph.g2o'} does not state its keyframes' time stamps")
    _, kf1 = match_timestamps(relations.t1, keyframes, 1e-5)
    _, kf2 = match_timestamps(relations.t2, keyframes, 1e-5)
    between_keyframes = relations.subset(kf1 & kf2)
    mount = (summary.get("input") or {}).get("pose_base_laser")
    print(
        f"{args.results}: frame {summary.get('frame')!r}, mounting (base -> laser) {mount}; "
        f"{len(relations)} relations, {len(between_keyframes)} between two keyframes"
    )
    header = ("offset x (m)", "all: trans (m)", "rot (deg)", "keyframes: trans (m)")
    print(f"{header[0]:>13}  {header[1]:>15}  {header[2]:>9}  {header[3]:>20}")
    for x in args.offsets:
        moved = pose_compose(run.poses, np.broadcast_to(np.array([x, 0.0, 0.0]), run.poses.shape))
        trajectory = Trajectory(run.timestamps, moved)
        every = relations_metric(trajectory, relations)
        kf = relations_metric(trajectory, between_keyframes)
        print(
            f"{x:>+13.3f}  {every.abs_trans_m.mean:>15.4f}  {every.abs_rot_deg.mean:>9.3f}  "
            f"{kf.abs_trans_m.mean:>20.4f}"
        )
    if args.lever_arm:
        _lever_arm(run, relations, args.short, args.seed)


def _lever_arm(run: Trajectory, relations: Relations, short_s: float, seed: int) -> None:
    """Print the relations' frame in the run's frame, fitted to the short relations."""
    try:
        off = relations_frame_offset(
            run.timestamps, run.poses, relations.t1, relations.t2, relations.poses,
            short_s=short_s, resamples=RESAMPLES, seed=seed,
        )  # fmt: skip
    except EvaluationError as exc:
        print(f"lever arm: {exc}")
        return
    print(
        f"lever arm from the {off.relations} relations shorter than {short_s:g} s: the "
        f"relations' frame at x {off.x_m:+.4f} m (sd {off.sd_x_m:.4f}), y {off.y_m:+.4f} m "
        f"(sd {off.sd_y_m:.4f}) in the reported frame ({RESAMPLES} bootstrap resamples, "
        f"seed {seed})"
    )


if __name__ == "__main__":
    main()
