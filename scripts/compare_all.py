"""Every log in the catalogue, the demo log and the simulated worlds → one results table.

Runs the comparison of ``lineslam compare`` (the Python API, :mod:`slam.experiments.compare`)
on each source with every estimator's one default configuration (``RunConfig()``: the same
for all logs, no per-log tuning) and writes one markdown table: relations error where the log
has relations, ATE where ground truth is known, run time; graph vs EKF vs odometry.  Each
source's own report (figures, every variant's folder) is written below ``--out``.  A source
whose comparison was already run (``lineslam compare``) can be taken from its ``report.json``
with ``--report SOURCE=DIR``.

Usage::

    python scripts/compare_all.py [--out results/compare_all] [--workers 2] [--dask ADDR]
        [--sources intel aces fr079 datasets/sim/demo/log.clf sim:corridor_loop:1:0 ...]
        [--variants graph-isam2,ekf,odometry] [--report intel=results/intel-compare]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path
from typing import Any

from slam.config import RunConfig
from slam.errors import LineslamError
from slam.experiments.compare import run_compare
from slam.experiments.report import write_report
from slam.experiments.variants import Variant, parse_source
from slam.io.catalog import load_catalog

REPO = Path(__file__).resolve().parents[1]
SIM_SOURCES = ["sim:corridor_loop:1:0", "sim:grid2x2:1:0"]
DEMO = REPO / "datasets" / "sim" / "demo" / "log.clf"
DEFAULT_VARIANTS = "graph-isam2,ekf,odometry"
"""Graph (iSAM2, the default back-end) vs EKF (its default: JCBB) vs odometry."""


def fmt(v: Any, digits: int) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return f"{v:.{digits}f}"


def table(rows: list[dict[str, Any]]) -> str:
    out = [
        "| source | estimator | scans | relations trans. (m) | relations rot. (deg) | "
        "ATE (m) | landmarks | time/scan (ms) | total (s) | note |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        note = ""
        if r.get("stopped_at_scan") is not None:
            note = f"stopped at scan {r['stopped_at_scan']}"
        rel = "–"
        if r.get("rel_trans_mean_m") is not None:
            rel = f"{fmt(r['rel_trans_mean_m'], 3)} ± {fmt(r.get('rel_trans_std_m'), 3)}"
        rot = "–"
        if r.get("rel_rot_mean_deg") is not None:
            rot = f"{fmt(r['rel_rot_mean_deg'], 2)} ± {fmt(r.get('rel_rot_std_deg'), 2)}"
        out.append(
            f"| {r['source']} | {r['variant']} | {r.get('scans_processed', '–')}/"
            f"{r.get('scans', '–')} | {rel} | {rot} | {fmt(r.get('ate_rmse_m'), 3)} | "
            f"{r.get('landmarks', '–')} | {fmt(r.get('runtime_per_scan_ms_mean'), 1)} | "
            f"{fmt(r.get('runtime_s'), 1)} | {note} |"
        )
    return "\n".join(out)


def main() -> None:
    catalogue = sorted(load_catalog())
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/compare_all"))
    ap.add_argument(
        "--sources", nargs="+", default=[*catalogue, str(DEMO), *SIM_SOURCES], help="sources"
    )
    ap.add_argument("--variants", default=DEFAULT_VARIANTS, help="comma-separated estimators")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--dask", default=None)
    ap.add_argument(
        "--report",
        action="append",
        default=[],
        metavar="SOURCE=DIR",
        help="take SOURCE's rows from DIR/report.json (a finished lineslam compare)",
    )
    args = ap.parse_args()
    done = dict(item.split("=", 1) for item in args.report)
    wanted = [v.strip() for v in args.variants.split(",") if v.strip()]
    rows: list[dict[str, Any]] = []
    t_all = time.perf_counter()
    for source in args.sources:
        if source in done:
            doc = json.loads((Path(done[source]) / "report.json").read_text())
            for row in doc["variants"]:
                if row["variant"] in wanted:
                    rows.append({"source": doc["source"], **row})
            print(f"{source}: rows from {done[source]}/report.json")
            continue
        try:
            data = parse_source(source)
            variants = tuple(Variant(v, v) for v in wanted)
            report = run_compare(
                data,
                variants,
                RunConfig(),
                args.workers,
                args.dask,
                cache_dir=args.out / ".cache" / data.label.replace(":", "_"),
            )
        except LineslamError as exc:
            print(f"{source}: skipped ({exc})")
            continue
        write_report(report, args.out / data.label.replace(":", "_"))
        rows += [{"source": data.label, **row} for row in report.rows()]
        print(f"{source}: done in {report.wall_time_s:.1f} s")
    text = table(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.md").write_text(text + "\n")
    (args.out / "results.json").write_text(json.dumps(rows, indent=1, default=str))
    print(text)
    print(f"total {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
