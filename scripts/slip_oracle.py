"""Were the scan matcher's slips and contradictions right?  Each one against a reference run.

``lineslam slam`` matches each keyframe's points against the previous keyframe's with the
odometry as the prior (``slam.frontend.scan_match``).  A match whose best solution lies in the
prior's slip component is a *slip* when the matcher accepts it (it replaces the step's
odometry factor) and *contradicted* when it does not (too little overlap; it centres the step,
spread as far as the odometry's heading: ``contradicted_spread``).  This script runs the
pipeline on LOG, records the heading step of every such keyframe (odometry, match) and
compares both with the reference's heading step between the same two scans, found by time
stamp (so a reference run of the unmodified log serves its decimated variants too).

    python scripts/slip_oracle.py LOG --reference other/trajectory.tum [--config FILE]

Prints how many matches lie within ``--right`` rad of the reference (default 0.05), how many
are closer to it than the odometry, and one line per contradicted match (with ``--slips``, per
slip too).  The reference's own
errors are part of the numbers.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import numpy as np

import slam.line_slam.pipeline as pipeline
from slam.config import RunConfig
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import pose_between
from slam.inputs import open_log
from slam.io.tum import read_tum
from slam.runner import run_slam


def trace(log: str, config: RunConfig, out: Path) -> list[dict[str, Any]]:
    """Run the pipeline on ``log``; each keyframe's slip or contradicted match, as dicts."""
    rows: list[dict[str, Any]] = []
    state: dict[str, Any] = {"match": None, "t": None, "t_prev": None}
    match_scans = pipeline.match_scans
    keyframe = pipeline.LineSlam._keyframe
    add_scan = pipeline.LineSlam.add_scan

    def traced_match(*args: Any, **kwargs: Any) -> Any:
        state["match"] = match_scans(*args, **kwargs)
        return state["match"]

    def traced_keyframe(self: Any, scan_no: int, step: Any, *args: Any, **kwargs: Any) -> Any:
        state["match"] = None
        report = keyframe(self, scan_no, step, *args, **kwargs)
        m = state["match"]
        if m is not None and (m.slip or m.contradicted) and state["t_prev"] is not None:
            rows.append(
                {
                    "scan": scan_no,
                    "t_from": state["t_prev"],
                    "t_to": state["t"],
                    "contradicted": bool(m.contradicted),
                    "overlap": float(m.overlap),
                    "odometry_rad": float(step.delta[2]),
                    "match_rad": float(m.delta[2]),
                }
            )
        state["t_prev"] = state["t"]
        return report

    def traced_add_scan(self: Any, scan: Any, *args: Any, **kwargs: Any) -> Any:
        state["t"] = float(scan.timestamp)
        return add_scan(self, scan, *args, **kwargs)

    pipeline.match_scans = traced_match  # type: ignore[assignment]
    pipeline.LineSlam._keyframe = traced_keyframe  # type: ignore[method-assign]
    pipeline.LineSlam.add_scan = traced_add_scan  # type: ignore[method-assign]
    try:
        run_slam(open_log(log, config.scanner), out, config)
    finally:
        pipeline.match_scans = match_scans
        pipeline.LineSlam._keyframe = keyframe  # type: ignore[method-assign]
        pipeline.LineSlam.add_scan = add_scan  # type: ignore[method-assign]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="log file or dataset name")
    parser.add_argument("--reference", type=Path, required=True, help="TUM trajectory")
    parser.add_argument("--config", type=Path, help="run configuration (TOML)")
    parser.add_argument("--right", type=float, default=0.05, help="rad (default 0.05)")
    parser.add_argument("--slips", action="store_true", help="one line per slip too (kind 'slip')")
    args = parser.parse_args()
    config = RunConfig.from_toml(args.config) if args.config else RunConfig()
    ref = read_tum(args.reference)

    with tempfile.TemporaryDirectory() as tmp:
        rows = trace(args.log, config, Path(tmp) / "run")
    # the reference's pose nearest in time to each end of each step
    i_from = match_timestamps(np.array([r["t_from"] for r in rows]), ref.timestamps, np.inf)[0]
    i_to = match_timestamps(np.array([r["t_to"] for r in rows]), ref.timestamps, np.inf)[0]
    for r, a, b in zip(rows, i_from, i_to, strict=True):
        r["reference_rad"] = float(pose_between(ref.poses[a], ref.poses[b])[2])
    for kind, flag in (("slips", False), ("contradicted", True)):
        rr = [r for r in rows if r["contradicted"] == flag]
        e_match = np.array([abs(r["match_rad"] - r["reference_rad"]) for r in rr])
        e_odo = np.array([abs(r["odometry_rad"] - r["reference_rad"]) for r in rr])
        print(
            f"{kind}: {len(rr)}, within {args.right:g} rad of the reference "
            f"{int(np.sum(e_match < args.right))}, closer to it than the odometry "
            f"{int(np.sum(e_match < e_odo))}"
        )
    print(
        f"{'scan':>6} {'kind':>12} {'overlap':>8} {'odometry':>9} {'match':>8} "
        f"{'reference':>10}  (rad)"
    )
    for r in rows:
        if r["contradicted"] or args.slips:
            kind = "contradicted" if r["contradicted"] else "slip"
            print(
                f"{r['scan']:6d} {kind:>12} {r['overlap']:8.2f} {r['odometry_rad']:9.3f} "
                f"{r['match_rad']:8.3f} {r['reference_rad']:10.3f}"
            )


if __name__ == "__main__":
    sys.exit(main())
