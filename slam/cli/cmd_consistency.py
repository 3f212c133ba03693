"""``lineslam consistency``: Monte-Carlo NEES of the estimators on a simulated world.

Runs ``--runs`` seeded simulations (line-level simulator, :mod:`slam.experiments.linesim`)
through each estimator, serially, on ``--workers`` local processes, or on a Dask cluster
(``--dask ADDRESS``) — the same numbers either way.  Writes ``config.toml``,
``consistency.json`` (per estimator: ANEES over time and per loop, its heading part per loop,
bounds, fraction inside, RMSE, run time) and the figures ``nees.png`` (with ``--loops`` ≥ 2
the mean per loop drawn over the curves), ``nees_heading.png`` (the heading part, 1 dof) and
``error.png``.  ``--odometry-scale``, ``--line-range-sigma`` and
``--line-point-spacing`` set the simulator's noise (the estimators are told the same models).
"""

from __future__ import annotations

import json
from typing import Annotated

import typer

from slam import interrupts
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

__all__ = ["consistency"]


@app.command()
def consistency(
    out: OutDirOpt,
    world: Annotated[
        str, typer.Option("--world", help="Simulated world: corridor_loop or gridNxM.")
    ] = "corridor_loop",
    loops: Annotated[float, typer.Option("--loops", help="Repetitions of the route.")] = 1.0,
    runs: Annotated[int, typer.Option("--runs", help="Seeded runs per estimator.")] = 50,
    estimators: Annotated[
        str,
        typer.Option(
            "--estimators",
            help="Comma-separated estimator names: ekf, ekf-nn, ekf-jcbb, ekf-fej, ekf-oc, "
            "graph-isam2, graph-batch, odometry.",
        ),
    ] = "ekf,graph-isam2,graph-batch,odometry",
    odometry_scale: Annotated[
        float,
        typer.Option(
            "--odometry-scale",
            help="Odometry noise of the simulator (and of the estimators' model) times this.",
        ),
    ] = 1.0,
    line_range_sigma: Annotated[
        float | None,
        typer.Option(
            "--line-range-sigma",
            help="Range noise (m) of the points behind each simulated line fit (default 0.01).",
        ),
    ] = None,
    line_point_spacing: Annotated[
        float | None,
        typer.Option(
            "--line-point-spacing",
            help="Spacing (m) of those points along the wall (default 0.05).",
        ),
    ] = None,
    workers: Annotated[
        int, typer.Option("--workers", help="Local worker processes (1: serial).")
    ] = 1,
    dask: DaskOpt = None,
    config: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
) -> None:
    """Monte-Carlo consistency (pose NEES over time with chi-square bounds)."""
    from dataclasses import replace

    from slam.experiments.consistency import ConsistencyConfig, run_consistency
    from slam.experiments.linesim import LineSimConfig

    run_config = build_config(config, sigma_d, sigma_phi, seed)
    sim = LineSimConfig()
    sim = replace(sim, odometry=sim.odometry.scaled(odometry_scale))
    if line_range_sigma is not None:
        sim = replace(sim, sigma_range_m=line_range_sigma)
    if line_point_spacing is not None:
        sim = replace(sim, point_spacing_m=line_point_spacing)
    study = ConsistencyConfig(
        world=world,
        loops=loops,
        n_runs=runs,
        estimators=tuple(e.strip() for e in estimators.split(",") if e.strip()),
        seed=run_config.seed,
        linesim=sim,
    )
    check_out_dir(out)
    with results_dir(out, run_config) as work:
        with task_progress(runs, "runs", "run", quiet) as progress:
            result = run_consistency(study, run_config, workers, dask, progress)
        (work / "consistency.json").write_text(json.dumps(result.to_dict(), indent=1))
        interrupts.check()  # between the steps of the end (slam.interrupts)
        from slam.plotting.compare import plot_errors_over_time, plot_nees_over_time

        interrupts.check()

        plot_nees_over_time(
            {k: v.anees for k, v in result.estimators.items()},
            next(iter(result.estimators.values())).bounds,
            work / "nees.png",
            n_runs=runs,
            title=f"Pose NEES over time, {world} x{loops:g}, {runs} runs",
            segments=result.n_loops,
        )
        interrupts.check()
        plot_nees_over_time(
            {k: v.anees_heading for k, v in result.estimators.items()},
            next(iter(result.estimators.values())).heading_bounds,
            work / "nees_heading.png",
            dof=1,
            n_runs=runs,
            title=f"Heading NEES over time, {world} x{loops:g}, {runs} runs",
            segments=result.n_loops,
            ylabel="average heading NEES",
        )
        interrupts.check()
        plot_errors_over_time(
            {k: v.pos_rmse_over_time for k, v in result.estimators.items()},
            work / "error.png",
            ylabel="position RMSE over runs (m)",
            title=f"Position error over time, {world} x{loops:g}",
        )
    if not quiet:
        typer.echo(result.table())
