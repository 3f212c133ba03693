"""Where did a run's relations error enter?  The onsets of its error, with the closures near each.

Usage::

    python scripts/error_onsets.py RESULTS_DIR --log intel [--threshold-m 0.2]
    python scripts/error_onsets.py RESULTS_DIR --relations FILE
    python scripts/error_onsets.py RESULTS_DIR --log fr079 --fill   # a decimated variant's run
    python scripts/error_onsets.py RESULTS_DIR --log aces --threshold-deg 20   # by rotation

``RESULTS_DIR`` is a ``lineslam slam`` results folder (``trajectory.tum``, ``summary.json``);
``--log`` the dataset whose relations score it (a variant of a catalogued log made by
``scripts/robustness.py`` keeps its time stamps: give the log it was made from).  Relations
whose two stamps are not both scans of the run (a decimated variant's dropped scans) are left
out and counted; with ``--fill`` a dropped scan instead takes the last kept scan's pose moved
by the log's odometry, as ``scripts/robustness.py`` scores such a run
(:func:`slam.experiments.robustness.fill_dropped_scans`).  Each relation's translation error
is the relations metric's (:func:`slam.evaluation.relations_metric.relation_errors`); a
relation erring by more than ``--threshold-m`` is bad, and
:func:`slam.evaluation.onsets.error_onsets` finds the times that the bad relations span and
the good ones do not: where a wrong step entered the trajectory.  With ``--threshold-deg`` a
relation is bad when its rotation error is above that many degrees instead: a heading error
made where the robot turns on the spot shows in the translation of a relation only once the
robot has driven on, so the translation's onset can lie well after the turn that made it.
Printed for each onset: its interval (seconds from the run's first scan, and the run's scans
in it),
the bad and good relations spanning it, their mean error, and the loop closures the run
accepted within ``--near-s`` seconds of it (keyframe, old keyframe, correction, pairs) — to
be checked with ``scripts/closure_oracle.py``.  Nothing is written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from slam.evaluation.onsets import error_onsets
from slam.evaluation.relations_metric import relation_errors
from slam.evaluation.timestamps import match_timestamps
from slam.experiments.robustness import fill_dropped_scans
from slam.io.carmen import scan_trajectory
from slam.io.catalog import resolve_log
from slam.io.relations import read_relations
from slam.io.tum import read_tum


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="lineslam slam results folder")
    ap.add_argument("--log", help="dataset whose relations score the run")
    ap.add_argument("--relations", type=Path, help="relations file (instead of --log)")
    ap.add_argument("--threshold-m", type=float, default=0.2, help="bad: error above this (m)")
    ap.add_argument(
        "--threshold-deg",
        type=float,
        help="bad: rotation error above this (deg), instead of the translation's threshold",
    )
    ap.add_argument("--min-relations", type=int, default=3, help="bad minus good, at least")
    ap.add_argument("--max-onsets", type=int, default=10)
    ap.add_argument("--near-s", type=float, default=20.0, help="closures this close (s)")
    ap.add_argument(
        "--fill", action="store_true", help="dropped scans carried by the --log's odometry"
    )
    args = ap.parse_args()
    if (args.log is None) == (args.relations is None):
        ap.error("give --log NAME or --relations FILE")
    resolved = resolve_log(args.log) if args.log is not None else None
    rel_path = args.relations if resolved is None else resolved.relations
    if rel_path is None:
        ap.error(f"{args.log}: no relations file; give --relations")
    relations = read_relations(rel_path)
    run = read_tum(args.results / "trajectory.tum")
    summary_path = args.results / "summary.json"
    summary = json.loads(summary_path.read_text(encoding="utf-8")) if summary_path.exists() else {}
    kept = run.timestamps
    if args.fill:
        if resolved is None:
            ap.error("--fill needs --log (its odometry carries the dropped scans)")
        frame = summary.get("frame", "laser")
        run = fill_dropped_scans(run, scan_trajectory(resolved.log, frame=frame))
    i1, ok1 = match_timestamps(relations.t1, run.timestamps, 1e-5)
    i2, ok2 = match_timestamps(relations.t2, run.timestamps, 1e-5)
    used = ok1 & ok2
    if not used.any():
        ap.error("no relation has both stamps in the run")
    rel = relations.subset(used)
    err, rot = relation_errors(run.poses[i1[used]], run.poses[i2[used]], rel)
    if args.threshold_deg is None:
        bad_err, threshold, unit = err, args.threshold_m, "m"
    else:
        bad_err, threshold, unit = np.rad2deg(rot), args.threshold_deg, "deg"
    t0 = float(run.timestamps[0])
    print(
        f"{args.results} against {rel_path}: {int(used.sum())} relations "
        f"({int((~used).sum())} without both scans in the run), mean error {err.mean():.4f} m, "
        f"{np.rad2deg(rot).mean():.3f} deg; "
        f"{int(np.count_nonzero(bad_err > threshold))} above {threshold:g} {unit}"
    )
    onsets = error_onsets(
        rel.t1,
        rel.t2,
        bad_err,
        threshold,
        min_relations=args.min_relations,
        max_onsets=args.max_onsets,
    )
    if not onsets:
        print("no onset: the bad relations span no common time")
        return
    closures = [e for e in summary.get("loop_closures_log", []) if e.get("accepted")]
    n_scans = kept.shape[0]
    mean_head = f"mean ({unit})"
    print(f"{'from (s)':>9} {'until (s)':>9} {'scans':>13} {'bad':>5} {'good':>5} {mean_head:>9}")
    for o in onsets:
        first = int(np.searchsorted(kept, o.from_s))
        last = int(np.searchsorted(kept, o.until_s))
        print(
            f"{o.from_s - t0:9.1f} {o.until_s - t0:9.1f} {first:>6}-{last:<6} {o.bad:5d} "
            f"{o.good:5d} {o.mean_error_m:9.3f}"
        )
        for e in closures:
            scan = int(e.get("scan", -1))
            if not 0 <= scan < n_scans:
                continue
            t = float(kept[scan])
            if o.from_s - args.near_s <= t <= o.until_s + args.near_s:
                corr = ", ".join(f"{v:.2f}" for v in e["correction"])
                print(
                    f"{'':9} closure at keyframe {e['keyframe']} (t {t - t0:.1f} s) onto "
                    f"keyframe {e['old_keyframe']}: correction ({corr}), {e['pairs']} pairs"
                )


if __name__ == "__main__":
    main()
