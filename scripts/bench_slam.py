"""Benchmark of the whole ``lineslam slam`` pipeline on a real log, time per stage.

Runs the pipeline (read, extract, front end, associate, fuse, loop closing, optimise, write)
exactly as ``lineslam slam LOG --out DIR`` does, once per back-end, side by side in one run,
and prints for each the time per stage (from ``summary.json``'s ``runtime_s``), scans per
second and the ratio of the back-ends' totals.  With ``--relations`` the relations error of
each run is printed too, so a speed-up that costs accuracy shows.

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/bench_slam.py intel
    .venv/bin/python scripts/bench_slam.py intel --max-scans 2000 --backend batch
    .venv/bin/python scripts/bench_slam.py intel --backend isam2 --config coarse.toml --relations

With ``--config`` every back-end also runs with that configuration, one run after the other in
the same process, and the totals are printed as ratios to the first run.

Target: the whole Intel log (13,631 scans) in under 120 s on a 2-core machine (Cartographer
reports 179 s for it).
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal, cast

from slam.config import RunConfig
from slam.runner import run_slam

#: Stages in pipeline order; the runner and the back-end may report more (printed after).
STAGES = (
    "read",
    "extract",
    "frontend",
    "associate",
    "fusion",
    "loop_closure",
    "backend",
    "optimize",
    "covariances",
    "write",
    "total",
)


def run_once(
    log: str, backend: str, max_scans: int | None, out: Path, config_path: Path | None = None
) -> dict[str, Any]:
    """Run the pipeline with one back-end (from a TOML configuration if given); its summary."""
    config = RunConfig() if config_path is None else RunConfig.from_toml(config_path)
    kind = cast(Literal["batch", "isam2"], backend)
    config = replace(config, slam=replace(config.slam, backend=kind))
    return run_slam(log, out, config, max_scans=max_scans)


def relations_error(out: Path, log: str) -> tuple[float, float, int] | None:
    """Mean absolute translational (m) and rotational (deg) relations error of the run, and
    the number of relations used (those inside the run, for ``--max-scans``); None without
    a relations file."""
    from slam.evaluation import relations_metric, relations_within
    from slam.io.catalog import resolve_log
    from slam.io.relations import read_relations
    from slam.io.tum import read_tum

    resolved = resolve_log(log)
    if resolved.relations is None:
        return None
    trajectory = read_tum(out / "trajectory.tum")
    relations = relations_within(read_relations(resolved.relations), trajectory.timestamps)
    metric = relations_metric(trajectory, relations)
    return metric.abs_trans_m.mean, metric.abs_rot_deg.mean, metric.n_used


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", nargs="?", default="intel", help="log file or dataset name")
    parser.add_argument("--max-scans", type=int, default=None)
    parser.add_argument(
        "--backend",
        action="append",
        choices=("batch", "isam2"),
        help="back-end(s) to time; default both, side by side",
    )
    parser.add_argument(
        "--relations", action="store_true", help="also print the relations error of each run"
    )
    parser.add_argument(
        "--config",
        type=Path,
        action="append",
        default=[],
        help="also run each back-end with this TOML configuration (side by side with the "
        "defaults; repeatable)",
    )
    args = parser.parse_args()
    # runs: every back-end with the defaults, then with each --config
    runs: list[tuple[str, str, Path | None]] = []
    for backend in args.backend or ["batch", "isam2"]:
        runs.append((backend, backend, None))
        runs += [(f"{backend}:{c.stem}", backend, c) for c in args.config]
    backends = [label for label, _, _ in runs]

    summaries: dict[str, dict[str, Any]] = {}
    errors: dict[str, tuple[float, float, int] | None] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, (label, backend, config_path) in enumerate(runs):
            out = Path(tmp) / f"run{k}"
            summaries[label] = run_once(args.log, backend, args.max_scans, out, config_path)
            errors[label] = relations_error(out, args.log) if args.relations else None

    n_scans = {b: int(s.get("scans", 0)) for b, s in summaries.items()}
    print(f"log {args.log}: {next(iter(n_scans.values()))} scans")
    keys = [k for k in STAGES if any(k in s["runtime_s"] for s in summaries.values())]
    keys += sorted({k for s in summaries.values() for k in s["runtime_s"]} - set(keys))
    width = max(12, *(len(b) + 2 for b in backends))
    print(f"{'stage (s)':<14}" + "".join(f"{b:>{width}}" for b in backends))
    for key in keys:
        times = [summaries[b]["runtime_s"].get(key, float("nan")) for b in backends]
        row = "".join(f"{t:>{width}.2f}" for t in times)
        print(f"{key:<14}{row}")
    rate = "".join(
        f"{n_scans[b] / summaries[b]['runtime_s']['total']:>{width}.1f}" for b in backends
    )
    print(f"{'scans/s':<14}{rate}")
    if args.relations:
        for b in backends:
            e = errors[b]
            if e is not None:
                print(f"relations {b}: {e[0]:.4f} m, {e[1]:.3f} deg (mean abs, {e[2]} used)")
    a = backends[0]
    for b in backends[1:]:
        ratio = summaries[b]["runtime_s"]["total"] / summaries[a]["runtime_s"]["total"]
        print(f"total {b} / {a}: {ratio:.2f}")


if __name__ == "__main__":
    main()
