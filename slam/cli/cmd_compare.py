"""``lineslam compare LOG --out DIR``: estimator variants on the same data, one report.

``LOG`` is a log (path or registered dataset name) or ``sim:WORLD[:LOOPS[:SEED]]`` for the
line-level simulator with ground truth.  Each variant runs as a task (serially, on
``--workers`` local processes, or on a Dask cluster with ``--dask ADDRESS``) and gets its own
folder (``trajectory.tum``, ``map.json``, ``summary.json``); the comparison writes
``report.json``, ``report.md`` and figures (trajectories over the map, error over time, run
time per scan, NEES over time with χ² bounds for simulated data).
"""

from __future__ import annotations

from typing import Annotated

import typer

from slam.cli._app import app
from slam.cli.common import (
    ConfigOpt,
    DaskOpt,
    OutDirOpt,
    QuietOpt,
    SeedOpt,
    SigmaDOpt,
    SigmaPhiOpt,
    build_config,
    check_out_dir,
    results_dir,
    task_progress,
)

__all__ = ["compare"]


@app.command()
def compare(
    log: Annotated[
        str, typer.Argument(help="Log path, dataset name, or sim:WORLD[:LOOPS[:SEED]].")
    ],
    out: OutDirOpt,
    variants: Annotated[
        str | None,
        typer.Option(
            "--variants",
            help="Comma-separated NAME=ESTIMATOR\\[/unweighted] or estimator names; "
            "default: every available variant.",
        ),
    ] = None,
    workers: Annotated[
        int,
        typer.Option("--workers", help="Local worker processes (0: one per CPU core; 1: serial)."),
    ] = 0,
    dask: DaskOpt = None,
    time_budget: Annotated[
        float | None,
        typer.Option(
            "--time-budget",
            help="Seconds each variant may run before it stops taking scans (default: only "
            "graph-batch on logs, 150 s).",
        ),
    ] = None,
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="Draw figures.")] = True,
    max_scans: Annotated[
        int | None, typer.Option("--max-scans", help="Use only the first scans of the log.")
    ] = None,
    config: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
) -> None:
    """Compare graph SLAM, EKF-SLAM, odometry and front-end variants on one log."""
    from dataclasses import replace

    from slam.errors import ConfigError
    from slam.experiments.compare import run_compare
    from slam.experiments.report import write_report
    from slam.experiments.variants import default_variants, parse_source, parse_variants
    from slam.io.catalog import resolve_log

    run_config = build_config(config, sigma_d, sigma_phi, seed)
    data = parse_source(log, seed=run_config.seed)
    if workers <= 0:
        import os

        workers = os.cpu_count() or 1
    if variants:
        selected = parse_variants(variants)
    else:
        selected = default_variants(simulated=data.kind == "sim")
    if time_budget is not None:
        if not time_budget > 0.0:
            raise ConfigError(f"--time-budget must be > 0, got {time_budget}")
        selected = tuple(replace(v, time_budget_s=time_budget) for v in selected)
    check_out_dir(out)
    inputs = [resolve_log(data.name).log] if data.kind == "log" else []
    with (
        results_dir(out, run_config, inputs, reuse=(".cache",)) as work,
        task_progress(len(selected), "variants", "variant", quiet) as progress,
    ):
        report = run_compare(
            data,
            selected,
            run_config,
            workers,
            dask,
            progress,
            cache_dir=work / ".cache",
            max_scans=max_scans,
        )
        write_report(report, work, figures=figures)
    if not quiet:
        typer.echo(report.markdown_table())
