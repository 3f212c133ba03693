"""Which loop-closure candidates of a run were right?  Each one against a reference trajectory.

Every candidate that reached the gate or the judgement is in ``summary.json``'s
``loop_closures_log`` with the keyframe where its paired old lines were last seen
(``old_scan``), the current one (``scan``) and both poses before the closure.  The reference's
relative pose between those two scans says where the current pose should be, the old one held;
the candidate's correction says where it would be.  The distance between the two classifies
the candidate: right (< ``--right`` m), wrong (> ``--wrong`` m), or in between (``?``).
A corridor closure (all paired lines parallel) is classified by the component across the
corridor only (its ``corridor_normal``; the component along it is arbitrary and not used):
``right|``, ``?|`` or ``wrong|``; an entry without the normal is ``corridor``.

    .venv/bin/python scripts/closure_oracle.py results/fr079 --reference other/trajectory.tum

The reference is another run of the same log, or of the log a variant was made from (its
poses found by time stamp), e.g. one whose relations error is small; its own errors are part
of the numbers.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between, pose_compose
from slam.io.tum import read_tum


def classify(entry: dict, reference: np.ndarray, right_m: float, wrong_m: float) -> tuple:
    """``(class, needed correction (m), error of the candidate's correction (m))``.

    ``reference`` holds the reference's pose of every scan of the run (``(N, 3)``).
    """
    x_now = np.asarray(entry["pose_before"], dtype=float)
    x_old = np.asarray(entry["old_pose_before"], dtype=float)
    rel = pose_between(reference[entry["old_scan"]], reference[entry["scan"]])
    target = pose_compose(x_old, rel)
    t = np.asarray(entry["correction"], dtype=float)
    need = float(np.hypot(*(target[:2] - x_now[:2])))
    suffix = ""
    if entry.get("single_direction"):
        if "corridor_normal" not in entry:
            return "corridor", need, float("nan")
        n = np.asarray(entry["corridor_normal"], dtype=float)
        err = float(abs((x_now[:2] + (t[:2] @ n) * n - target[:2]) @ n))
        suffix = "|"
    else:
        err = float(np.hypot(*(x_now[:2] + t[:2] - target[:2])))
    cls = "right" if err < right_m else ("wrong" if err > wrong_m else "?")
    return cls + suffix, need, err


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="results folder of lineslam slam")
    parser.add_argument("--reference", type=Path, required=True, help="TUM trajectory")
    parser.add_argument("--right", type=float, default=0.3, help="m (default 0.3)")
    parser.add_argument("--wrong", type=float, default=0.8, help="m (default 0.8)")
    args = parser.parse_args()
    summary = json.loads((args.run / "summary.json").read_text(encoding="utf-8"))
    ours = read_tum(args.run / "trajectory.tum")
    ref = read_tum(args.reference)
    # the reference's pose of each of our scans: the same scans, or (a variant of the log the
    # reference ran on, e.g. every 4th scan) the reference's scan nearest in time
    if ref.timestamps.shape == ours.timestamps.shape and np.allclose(
        ref.timestamps, ours.timestamps, atol=1e-6
    ):
        reference_poses = ref.poses
    else:
        at, found = match_timestamps(ours.timestamps, ref.timestamps, 1e-3)
        if not found.all():
            raise SystemExit(
                f"{args.reference}: has no pose at some scans of {args.run / 'trajectory.tum'} "
                "(a reference must be a run of the same log, or of the log it was made from)"
            )
        reference_poses = ref.poses[at]
    entries = [e for e in summary.get("loop_closures_log", []) if "scan" in e]
    if not entries:
        raise SystemExit(f"{args.run}: no candidate with its keyframes in the log (older run?)")
    print(
        f"{'keyframe':>8} {'old':>6} {'outcome':>8} {'class':>8} {'need (m)':>9} "
        f"{'|T| (m)':>8} {'error (m)':>9} {'pairs':>6} {'worst χ²':>10} {'corr. χ²':>10}"
    )
    tally: Counter[tuple[str, str]] = Counter()
    for e in entries:
        cls, need, err = classify(e, reference_poses, args.right, args.wrong)
        reason = str(e.get("reason", ""))
        if e["accepted"]:
            outcome = "accepted"
        elif "contradicts" in reason:
            outcome = "contra"  # contradicted a recent closure (consistent_with_accepted)
        elif "gate" in reason or "awaiting" in reason:
            outcome = "gated"
        else:
            outcome = "rejected"
        tally[(outcome, cls)] += 1
        t = np.asarray(e["correction"], dtype=float)
        print(
            f"{e['keyframe']:8d} {e['old_keyframe']:6d} {outcome:>8} {cls:>8} {need:9.2f} "
            f"{np.hypot(t[0], t[1]):8.2f} {err:9.2f} {e.get('pairs', 0):6d} "
            f"{e.get('worst_pair_chi2', float('nan')):10.1f} "
            f"{e.get('correction_chi2', float('nan')):10.1f}"
        )
    print()
    for outcome in ("accepted", "rejected", "gated", "contra"):
        row = ", ".join(
            f"{cls} {tally[(outcome, cls)]}"
            for cls in ("right", "?", "wrong", "right|", "?|", "wrong|", "corridor")
            if tally[(outcome, cls)]
        )
        if row:
            print(f"{outcome}: {row}")


if __name__ == "__main__":
    main()
