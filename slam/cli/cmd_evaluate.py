"""``lineslam evaluate DIR --relations FILE --ground-truth FILE.tum``: metrics of a results DIR."""

from __future__ import annotations

from dataclasses import replace
from functools import partial as bind
from pathlib import Path
from typing import Annotated, Any

import typer

from slam.cli._app import app
from slam.errors import DatasetError, EstimationError, EvaluationError, LineslamError
from slam.evaluation.report import evaluate_results
from slam.io.carmen import scan_trajectory
from slam.io.catalog import resolve_log
from slam.io.relations import read_relations
from slam.io.results import read_results, write_metrics, write_relation_errors
from slam.io.trajectory import Trajectory
from slam.io.tum import read_ground_truth

__all__ = ["evaluate", "relations_path"]


def relations_path(value: str) -> Path:
    """A relations file, or a dataset name whose catalogue entry has one."""
    path = Path(value)
    if path.is_file():
        return path
    try:
        resolved = resolve_log(value)
    except DatasetError:
        raise DatasetError(f"--relations {value!r}: no such file or dataset name") from None
    if resolved.relations is None:
        raise DatasetError(f"--relations {value!r}: the dataset has no relations file")
    return resolved.relations


def _log_odometry(summary: dict[str, Any], frame: str) -> Trajectory | None:
    """The odometry of the CARMEN log the run read (``summary.json``), in the run's frame.

    It is the third measurement of the relations' own scatter
    (:mod:`slam.evaluation.reference_noise`); None (with a warning) when the log is not a
    readable CARMEN file.
    """
    log = summary.get("log")
    source = summary.get("input") or {}
    if not log or source.get("format", "carmen") != "carmen" or frame not in ("base", "laser"):
        return None
    try:
        return scan_trajectory(
            log, frame=frame, odometry_sign=source.get("odometry_sign", "logged")
        )
    except (OSError, LineslamError) as exc:
        typer.echo(f"lineslam: warning: {log}: no relations' scatter: {exc}", err=True)
        return None


WALL_PAIRS = 300
"""Most pairs of passes the walls' between-pass consistency is judged on (seeded draw)."""


def _walls_between_passes(run_cov: Any, graph_file: Path) -> dict[str, Any] | None:
    """:func:`slam.line_slam.passes.pass_consistency` of the run's graph (None: not computed)."""
    from slam.line_slam.passes import pass_consistency

    f = run_cov.graph_file
    try:
        result = pass_consistency(
            run_cov.graph, f.timestamps, f.robust_kernel, max_pairs=WALL_PAIRS
        ).to_dict()
    except (EstimationError, EvaluationError) as exc:
        typer.echo(f"lineslam: warning: {graph_file}: no between-pass consistency: {exc}", err=True)
        return None
    # no pairs: the medians are not numbers
    return {k: (None if isinstance(v, float) and v != v else v) for k, v in result.items()}


@app.command("evaluate")
def evaluate(
    results_dir: Annotated[
        Path, typer.Argument(help="Results folder with trajectory.tum (and summary.json).")
    ],
    relations: Annotated[
        str | None,
        typer.Option(
            "--relations", help="Relations file (t1 t2 x y z roll pitch yaw), or a dataset name."
        ),
    ] = None,
    ground_truth: Annotated[
        Path | None, typer.Option("--ground-truth", help="Ground-truth TUM trajectory.")
    ] = None,
    rpe_delta: Annotated[
        list[float] | None,
        typer.Option("--rpe-delta", help="RPE distance (m); repeat for several. Default 1."),
    ] = None,
    tolerance: Annotated[
        float, typer.Option("--time-tolerance", help="Largest |dt| (s) of a matching stamp.")
    ] = 1e-5,
    max_unmatched: Annotated[
        float,
        typer.Option("--max-unmatched", help="Fail if more than this fraction is unmatched."),
    ] = 0.02,
    partial: Annotated[
        bool | None,
        typer.Option(
            "--partial/--complete",
            help="Score only the relations inside the run (default: as summary.json says; "
            "runs with --max-scans are partial).",
        ),
    ] = None,
    relations_nees: Annotated[
        bool,
        typer.Option(
            "--relations-nees/--no-relations-nees",
            help="With --relations and DIR/graph.g2o: the NEES of every relation against the "
            "covariance of the estimated relative pose (joint marginals recomputed from the "
            "graph).",
        ),
    ] = True,
    per_relation: Annotated[
        bool,
        typer.Option(
            "--per-relation",
            help="With --relations: also write DIR/relation_errors.csv, every relation used "
            "with its time stamps, errors and NEES.",
        ),
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="Do not print the table.")] = False,
) -> None:
    """Evaluate DIR/trajectory.tum; print a table and write DIR/metrics.json."""
    if relations is None and ground_truth is None:
        raise typer.BadParameter("give --relations and/or --ground-truth")
    if per_relation and relations is None:
        raise typer.BadParameter("--per-relation needs --relations")
    results = read_results(results_dir)
    sources: dict[str, str] = {"trajectory": str(results_dir / "trajectory.tum")}
    rel = None
    if relations is not None:
        rel_path = relations_path(relations)
        rel = read_relations(rel_path)
        sources["relations_file"] = str(rel_path)
    covariances = joint = draws = None
    odometry = keyframe_timestamps = None
    walls: dict[str, Any] | None = None
    graph_file = results_dir / "graph.g2o"
    want_relations_nees = rel is not None and relations_nees
    if graph_file.is_file() and (want_relations_nees or ground_truth is not None):
        from slam.graph.relative import RunCovariances

        try:
            run_cov = RunCovariances.from_results(results_dir, results.summary)
        except EvaluationError as exc:  # a graph.g2o of an older lineslam: the rest still runs
            typer.echo(
                f"lineslam: warning: {graph_file}: no relations NEES and no one-run interval "
                f"of the pose NEES: {exc}",
                err=True,
            )
        else:
            sources["graph_file"] = str(graph_file)
            walls = _walls_between_passes(run_cov, graph_file)
            joint = bind(run_cov.joint_scan_covariance, tolerance_s=tolerance)
            if want_relations_nees:
                covariances = bind(run_cov.relative_covariances, tolerance_s=tolerance)
                draws = bind(run_cov.relation_error_draws, tolerance_s=tolerance)
                odometry = _log_odometry(results.summary, results.frame)
                keyframe_timestamps = run_cov.graph_file.timestamps
                if odometry is not None:
                    sources["odometry_log"] = str(results.summary["log"])
    gt = None
    if ground_truth is not None:
        gt = read_ground_truth(ground_truth)
        sources["ground_truth_file"] = str(ground_truth)
    report = evaluate_results(
        results,
        relations=rel,
        ground_truth=gt,
        rpe_deltas_m=tuple(rpe_delta) if rpe_delta else (1.0,),
        tolerance_s=tolerance,
        max_unmatched_fraction=max_unmatched,
        sources=sources,
        partial=partial,
        relative_covariances=covariances,
        odometry=odometry,
        keyframe_timestamps=keyframe_timestamps,
        joint_covariance=joint if ground_truth is not None else None,
        relation_error_draws=draws,
    )
    if walls is not None:
        report = replace(report, walls_between_passes=walls)
    path = write_metrics(results_dir, report.to_dict())  # whole or not at all
    rows = report.relation_rows() if per_relation else None
    rows_path = None if rows is None else write_relation_errors(results_dir, rows)
    if not quiet:
        typer.echo(report.format_table())
        typer.echo(f"wrote {path}")
        if rows_path is not None:
            typer.echo(f"wrote {rows_path}")
