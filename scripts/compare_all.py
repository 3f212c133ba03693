"""Every log in the catalogue and the simulated worlds → one results table (markdown).

Runs ``lineslam compare`` (the Python API) on each source and prints one table: relations
error where the log has relations, ATE where ground truth is known, run time; graph vs EKF vs
odometry.  The table is what the README keeps.

Usage: python scripts/compare_all.py [--out results/compare_all] [--workers 2] [--dask ADDR]
       [--sources sim:corridor_loop sim:grid2x2 intel aces fr079] [--variants ekf,odometry]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from slam.config import RunConfig
from slam.errors import LineslamError
from slam.experiments.compare import (
    Variant,
    default_variants,
    parse_source,
    run_compare,
    write_report,
)

DEFAULT_SOURCES = ["sim:corridor_loop:1:0", "sim:grid2x2:1:0", "intel", "aces", "fr079"]


def fmt(v, digits):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return f"{v:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/compare_all"))
    ap.add_argument("--sources", nargs="+", default=DEFAULT_SOURCES)
    ap.add_argument("--variants", default=None, help="comma-separated estimator names")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--dask", default=None)
    args = ap.parse_args()
    rows = []
    for source in args.sources:
        try:
            data = parse_source(source)
            if args.variants:
                variants = tuple(Variant(v, v) for v in args.variants.split(","))
            else:
                variants = default_variants(simulated=data.kind == "sim")
            report = run_compare(data, variants, RunConfig(), args.workers, args.dask)
        except LineslamError as exc:
            print(f"{source}: skipped ({exc})")
            continue
        write_report(report, args.out / data.label.replace(":", "_"))
        for row in report.rows():
            rows.append({"source": data.label, **row})
        print(f"{source}: done in {report.wall_time_s:.1f} s")
    table = [
        "| source | variant | relations trans. (m) | relations rot. (deg) | ATE (m) | "
        "time/scan (ms) | total (s) | note |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        note = f"stopped at scan {r['stopped_at_scan']}" if r.get("stopped_at_scan") else ""
        table.append(
            f"| {r['source']} | {r['variant']} | {fmt(r.get('rel_trans_mean_m'), 3)} | "
            f"{fmt(r.get('rel_rot_mean_deg'), 2)} | {fmt(r.get('ate_rmse_m'), 3)} | "
            f"{fmt(r.get('runtime_per_scan_ms_mean'), 2)} | {fmt(r.get('runtime_s'), 1)} | "
            f"{note} |"
        )
    text = "\n".join(table)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.md").write_text(text + "\n")
    (args.out / "results.json").write_text(json.dumps(rows, indent=1, default=str))
    print(text)


if __name__ == "__main__":
    main()
