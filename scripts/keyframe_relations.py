"""Where a run's relations error sits: between keyframes or between the scans that hang from them.

Usage::

    python scripts/keyframe_relations.py RESULTS_DIR --relations FILE|NAME

``RESULTS_DIR`` is a ``lineslam slam`` results folder (``trajectory.tum`` and ``graph.g2o``,
whose ``LINESLAM_SCAN`` lines give the keyframes' time stamps); ``--relations`` a relations
file or a catalogued name.  Each relation whose two time stamps are scans of the run (within
1e-4 s) is put in one of three groups: both scans keyframes (pose variables of the graph),
neither (scans placed from their keyframe: by the odometry, or by a match with
``between_keyframes``), or one of each.  Printed: each group's count and mean translation
error (the relations metric's), and the whole.  A run whose keyframes are right but whose
scans between keyframes carry the odometry's errors (odometry interpolated at jittered time
stamps, as a bag gives it) shows it here.  Nothing is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from slam.evaluation.relations_metric import relation_errors
from slam.evaluation.timestamps import match_timestamps
from slam.io.catalog import resolve_log
from slam.io.g2o import read_line_graph_g2o
from slam.io.relations import read_relations
from slam.io.tum import read_tum

STAMP_TOL_S = 1e-4


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="results folder of lineslam slam")
    parser.add_argument("--relations", required=True, help="relations file or catalogued name")
    args = parser.parse_args()
    path = Path(args.relations)
    if not path.is_file():
        resolved = resolve_log(args.relations).relations
        if resolved is None:
            parser.error(f"{args.relations}: no relations file")
        path = resolved
    rel = read_relations(path)
    trajectory = read_tum(args.run / "trajectory.tum")
    t = np.asarray(trajectory.timestamps)
    keyframe_t = read_line_graph_g2o(args.run / "graph.g2o").timestamps
    if keyframe_t is None:
        parser.error(f"{args.run / 'graph.g2o'}: no LINESLAM_SCAN time stamps")
    i1, ok1 = match_timestamps(rel.t1, t, STAMP_TOL_S)
    i2, ok2 = match_timestamps(rel.t2, t, STAMP_TOL_S)
    ok = ok1 & ok2
    _, is_keyframe = match_timestamps(t, keyframe_t, STAMP_TOL_S)
    err, _ = relation_errors(trajectory.poses[i1], trajectory.poses[i2], rel)
    k1, k2 = is_keyframe[i1], is_keyframe[i2]
    print(f"{args.run}: {ok.sum()} of {len(rel.t1)} relations with both scans in the run")
    for name, mask in (
        ("both keyframes", k1 & k2),
        ("neither a keyframe", ~k1 & ~k2),
        ("one of each", k1 ^ k2),
        ("all", np.ones_like(k1)),
    ):
        m = ok & mask
        mean = f"{err[m].mean():.4f} m" if m.any() else "-"
        print(f"  {name:<20} {m.sum():>6}  mean translation error {mean}")


if __name__ == "__main__":
    main()
