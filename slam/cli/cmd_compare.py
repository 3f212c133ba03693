"""``lineslam compare LOG --out DIR``: estimator variants on the same data, one report.

``LOG`` is a log (a CARMEN file, a ROS bag, or a registered dataset name) or
``sim:WORLD[:LOOPS[:SEED]]`` for the line-level simulator with ground truth (the world names
of ``lineslam simulate``).  A log is evaluated against ``--relations FILE`` and/or
``--ground-truth FILE.tum``, else the catalogue's relations, else ``relations.txt`` and
``ground_truth.tum`` beside the log; with none of these the report has no accuracy columns and
a warning says so.  Each variant runs as a task (serially, on
``--workers`` local processes, or on a Dask cluster with ``--dask ADDRESS``) and gets its own
folder (``trajectory.tum``, ``map.json``, ``summary.json``); the comparison writes
``report.json``, ``report.md`` and figures (trajectories over the map, error over time, run
time per scan, NEES over time with χ² bounds for simulated data).
"""

from __future__ import annotations

from pathlib import Path
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
from slam.cli.scanner_opts import (
    BaseFrameOpt,
    BeamsOpt,
    FirstAngleOpt,
    FovOpt,
    FrameOpt,
    MaxRangeOpt,
    MinRangeOpt,
    MountOpt,
    OdometryOpt,
    OdomTopicOpt,
    ScanTopicOpt,
    StepOpt,
    echo_warnings,
    with_scanner_options,
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
            help="Comma-separated NAME=ESTIMATOR\\[/unweighted] or estimator names (ekf, ekf-nn, "
            "ekf-jcbb, ekf-fej, ekf-oc, graph-isam2, graph-batch, odometry); default: every "
            "available variant.",
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
    relations: Annotated[
        str | None,
        typer.Option(
            "--relations",
            help="Relations file (t1 t2 x y z roll pitch yaw) to evaluate against, or a dataset "
            "name.",
        ),
    ] = None,
    ground_truth: Annotated[
        Path | None, typer.Option("--ground-truth", help="Ground-truth TUM trajectory.")
    ] = None,
    first_angle: FirstAngleOpt = None,
    step: StepOpt = None,
    fov: FovOpt = None,
    beams: BeamsOpt = None,
    min_range: MinRangeOpt = None,
    max_range: MaxRangeOpt = None,
    mount: MountOpt = None,
    frame: FrameOpt = None,
    scan_topic: ScanTopicOpt = None,
    odom_topic: OdomTopicOpt = None,
    odometry: OdometryOpt = None,
    base_frame: BaseFrameOpt = None,
) -> None:
    """Compare graph SLAM, EKF-SLAM, odometry and front-end variants on one log."""
    from dataclasses import replace

    from slam.cli.cmd_evaluate import relations_path
    from slam.diagnostics import tally_warnings
    from slam.errors import ConfigError
    from slam.experiments.compare import run_compare
    from slam.experiments.report import write_report
    from slam.experiments.variants import default_variants, parse_source, parse_variants
    from slam.io.catalog import resolve_log

    run_config = build_config(config, sigma_d, sigma_phi, seed)
    run_config = with_scanner_options(
        run_config,
        first_angle=first_angle,
        step=step,
        fov=fov,
        beams=beams,
        min_range=min_range,
        max_range=max_range,
        mount=mount,
        frame=frame,
        scan_topic=scan_topic,
        odom_topic=odom_topic,
        odometry=odometry,
        base_frame=base_frame,
    )
    check_out_dir(out)
    rel_file = relations_path(relations) if relations is not None else None
    data = parse_source(log, seed=run_config.seed, relations=rel_file, ground_truth=ground_truth)
    if data.kind == "log" and rel_file is None and ground_truth is None:
        _warn_if_no_reference(log)
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
    inputs: list[Path] = []
    if data.kind == "log":
        from slam.io.rosbag import is_rosbag

        inputs = [Path(data.name) if is_rosbag(data.name) else resolve_log(data.name).log]
    with (
        tally_warnings() as tally,
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
    echo_warnings(tally)
    if not quiet:
        typer.echo(report.markdown_table())


def _warn_if_no_reference(log: str) -> None:
    """Say so when a log has nothing to be evaluated against (no accuracy columns)."""
    from slam.errors import LineslamError
    from slam.io.catalog import resolve_log
    from slam.io.rosbag import is_rosbag

    folder = Path(log).parent
    if (folder / "relations.txt").is_file() or (folder / "ground_truth.tum").is_file():
        return
    if not is_rosbag(log):
        try:
            if resolve_log(log).relations is not None:
                return
        except LineslamError:
            return  # the run reports the bad LOG itself
    typer.echo(
        f"lineslam: warning: {log}: no relations or ground truth (not a catalogued log, no "
        "relations.txt beside it): the report has no accuracy columns; give --relations FILE "
        "or --ground-truth FILE.tum",
        err=True,
    )
