"""``lineslam slam LOG --out DIR``: factor-graph line SLAM (batch LM or iSAM2)."""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated

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

__all__ = ["slam_command"]


@app.command("slam")
def slam_command(
    log: LogArg,
    out: OutDirOpt,
    backend: Annotated[
        str | None,
        typer.Option("--backend", help="batch (periodic Levenberg-Marquardt) or isam2."),
    ] = None,
    config_path: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
    strict: StrictOpt = False,
    max_scans: MaxScansOpt = None,
    plot: Annotated[
        bool, typer.Option("--plot/--no-plot", help="Draw the trajectory and the line map.")
    ] = False,
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
    """Line-based factor-graph SLAM over a log.

    LOG is a CARMEN log, a ROS 1 .bag, a ROS 2 bag folder or a dataset name.  Writes
    trajectory.tum, trajectory_covariance.txt, map.json, graph.g2o, summary.json and
    config.toml (and figures/ with --plot) into --out.
    """
    from tqdm import tqdm

    from slam.config import open_run_log
    from slam.diagnostics import tally_warnings
    from slam.runner import run_slam

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
    if backend is not None:
        if backend not in ("batch", "isam2"):
            raise typer.BadParameter("--backend must be batch or isam2")
        config = replace(config, slam=replace(config.slam, backend=backend))  # type: ignore[arg-type]
    check_max_scans(max_scans)
    check_out_dir(out)
    with tally_warnings() as tally:
        source = open_run_log(log, config, max_scans=max_scans)
        with tqdm(
            desc=f"slam ({config.slam.backend})",
            unit="scan",
            disable=quiet,
            total=source.total(max_scans),
        ) as bar:
            summary = run_slam(
                source,
                out,
                config,
                max_scans=max_scans,
                progress=bar.update,
                plot=plot,
                tally=tally,
                strict=strict,
            )
    echo_warnings(tally)
    warn_log_anomalies(summary["log"], summary.get("log_anomalies"))
    if not quiet:
        rt = summary.get("runtime_s", {})
        typer.echo(
            f"{summary['scans']} scans ({summary['keyframes']} keyframes), "
            f"{summary['lines_fit']} lines -> {summary['landmarks']} map lines, "
            f"{rt.get('total', float('nan')):.1f} s; wrote {out}"
        )
