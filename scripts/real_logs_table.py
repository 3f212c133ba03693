"""The README's real-log table: odometry only vs lineslam on every catalogued log with relations.

For each log: the Kümmerle et al. relations error (mean absolute translation ± std, mean
absolute rotation) of the logged odometry, of the odometry the estimators read (repaired where
the log hides reversing, ``SlamConfig.odometry_sign``) and of ``lineslam slam`` with the default
configuration (one run per back-end asked for), its wall-clock and CPU time, and the loop
closures accepted / judged.  Prints a Markdown table.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/real_logs_table.py
    .venv/bin/python scripts/real_logs_table.py --logs aces --backend isam2 --backend batch
    .venv/bin/python scripts/real_logs_table.py --backend batch --config batch10.toml

``--config`` starts from a TOML run configuration (as ``lineslam slam --config``) instead of
the defaults, e.g. ``[slam.solver] batch_interval = 10`` for a faster batch back-end.

Runs one log after another (the times are only comparable on an otherwise idle machine).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Literal, cast

from slam.config import RunConfig
from slam.evaluation import relations_metric
from slam.evaluation.relations_metric import RelationsMetric
from slam.io.carmen import scan_trajectory
from slam.io.catalog import load_catalog, resolve_log
from slam.io.relations import read_relations
from slam.io.tum import read_tum
from slam.runner import run_slam

TARGETS_M = {"intel": 0.08, "aces": 0.08, "fr079": 0.10}


def _fmt(metric: RelationsMetric) -> tuple[str, str]:
    t, r = metric.abs_trans_m, metric.abs_rot_deg
    return f"{t.mean:.4f} ± {t.std:.4f}", f"{r.mean:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=None, help="default: every catalogued log")
    parser.add_argument("--backend", action="append", choices=("isam2", "batch"))
    parser.add_argument("--config", type=Path, default=None, help="TOML run configuration")
    args = parser.parse_args()
    base = RunConfig() if args.config is None else RunConfig.from_toml(args.config)
    backends = args.backend or ["isam2"]
    names = args.logs or [n for n, d in load_catalog().items() if d.relations]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            resolved = resolve_log(name)
            if resolved.relations is None:
                raise SystemExit(f"{name}: no relations file")
            relations = read_relations(resolved.relations)
            for backend in backends:
                config = base
                kind = cast(Literal["batch", "isam2"], backend)
                config = replace(config, slam=replace(config.slam, backend=kind))
                out = Path(tmp) / f"{name}-{backend}"
                wall, cpu = time.perf_counter(), time.process_time()
                summary = run_slam(name, out, config)
                wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
                ours = relations_metric(read_tum(out / "trajectory.tum"), relations)
                # the logged odometry in the frame the run wrote (laser or base)
                odo_traj = scan_trajectory(resolved.log, frame=summary["frame"])
                odo = relations_metric(odo_traj, relations)
                read = scan_trajectory(
                    resolved.log, frame=summary["frame"], odometry_sign=config.scanner.odometry_sign
                )
                odo_read = relations_metric(read, relations)
                target = TARGETS_M.get(name)
                ok = "" if target is None else (" ✓" if ours.abs_trans_m.mean <= target else " ✗")
                rows.append(
                    (
                        f"{name} ({summary['scans']:,} scans)",
                        backend,
                        *_fmt(odo),
                        _fmt(odo_read)[0],
                        *_fmt(ours),
                        "" if target is None else f"≤ {target:.2f}{ok}",
                        f"{wall:.0f} / {cpu:.0f}",
                        f"{summary['loop_closures']} / {summary['loop_closure_candidates']}",
                    )
                )
                print(f"{name} {backend}: {rows[-1]}", flush=True)
    print()
    print(
        "| log | back-end | odometry as logged (m) | odometry rot. (deg) | odometry read (m)"
        " | lineslam (m) | lineslam rot. (deg) | target (m) | wall / CPU (s)"
        " | closures accepted / judged |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
