"""``lineslam map LOG --out DIR``: line map merged across poses with the log's own poses."""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, Any

import typer

from slam.cli._app import app
from slam.cli.common import (
    ConfigOpt,
    LogArg,
    MaxScansOpt,
    OutDirOpt,
    QuietOpt,
    SeedOpt,
    SigmaDOpt,
    SigmaPhiOpt,
    StrictOpt,
    build_config,
    check_max_scans,
    check_out_dir,
    warn_log_anomalies,
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

__all__ = ["map_command"]


@app.command("map")
def map_command(
    log: LogArg,
    out: OutDirOpt,
    config_path: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
    strict: StrictOpt = False,
    pose_sigma_xy: Annotated[
        float | None,
        typer.Option("--pose-sigma-xy", help="σ (m) of each scan pose's x and y in the map."),
    ] = None,
    pose_sigma_theta: Annotated[
        float | None,
        typer.Option("--pose-sigma-theta", help="σ (rad) of each scan pose's heading."),
    ] = None,
    gate: Annotated[
        float | None,
        typer.Option("--gate", help="χ² merge gate probability (default 0.9973 = 3σ)."),
    ] = None,
    max_gap: Annotated[
        float | None,
        typer.Option("--max-gap", help="Largest gap (m) between merged collinear pieces."),
    ] = None,
    max_scans: MaxScansOpt = None,
    plot: Annotated[bool, typer.Option("--plot/--no-plot", help="Draw the figures.")] = True,
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
    """Fit lines to every scan and merge them across poses (paper Sec. V).

    Writes map.json, summary.json, config.toml and figures into --out.
    """
    from tqdm import tqdm

    from slam.config import open_run_log
    from slam.diagnostics import tally_warnings
    from slam.mapping import run_map

    config = build_config(config_path, sigma_d, sigma_phi, seed)
    config = with_scanner_options(
        config,
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
    overrides: dict[str, Any] = {
        "pose_sigma_xy_m": pose_sigma_xy,
        "pose_sigma_theta_rad": pose_sigma_theta,
        "gate_probability": gate,
        "max_gap_m": max_gap,
    }
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if overrides:
        config = replace(config, map=replace(config.map, **overrides))
    check_max_scans(max_scans)
    check_out_dir(out)
    with tally_warnings() as tally:
        source = open_run_log(log, config, max_scans=max_scans)
        with tqdm(desc="map", unit="scan", disable=quiet, total=source.total(max_scans)) as bar:
            summary = run_map(
                source,
                out,
                config,
                plot=plot,
                max_scans=max_scans,
                progress=bar.update,
                tally=tally,
                strict=strict,
            )
    echo_warnings(tally)
    warn_log_anomalies(summary["log"], summary.get("log_anomalies"))
    if not quiet:
        typer.echo(
            f"{summary['scans']} scans, {summary['points']} points -> {summary['lines_fit']} lines"
            f" -> {summary['lines_merged']} merged ({summary['segments_merged']} segments),"
            f" compression {100 * summary['compression']:.1f} %; wrote {out}"
        )
