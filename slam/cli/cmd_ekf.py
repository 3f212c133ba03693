"""``lineslam ekf LOG --out DIR``: EKF-SLAM baseline on a log.

Parses the options and runs :func:`slam.runner.run_ekf`: the log (path or registered dataset
name) is read with the same input policy as ``lineslam slam`` (the catalogue's laser mounting
included), each scan's lines are extracted with the configured line fit, and the folder gets
the same files as ``lineslam slam``: ``trajectory.tum``, ``trajectory_covariance.txt``,
``map.json``, ``summary.json`` and ``config.toml``.  When a guard stops the filter
(``ekf.max_landmarks``, ``ekf.max_runtime_s``), the trajectory covers the scans processed and
``summary.json`` says at which scan and why.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, Literal

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

__all__ = ["ekf"]


@app.command()
def ekf(
    log: LogArg,
    out: OutDirOpt,
    association: Annotated[
        str | None, typer.Option("--association", help="nn or jcbb (default: config).")
    ] = None,
    max_scans: MaxScansOpt = None,
    config: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
    strict: StrictOpt = False,
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
    """EKF-SLAM baseline: trajectory.tum, map.json, summary.json."""
    from tqdm import tqdm

    from slam.config import open_run_log
    from slam.diagnostics import tally_warnings
    from slam.errors import ConfigError
    from slam.runner import run_ekf

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
    if association is not None:
        if association not in ("nn", "jcbb"):
            raise ConfigError(f"--association must be nn or jcbb, got {association!r}")
        method: Literal["nn", "jcbb"] = "nn" if association == "nn" else "jcbb"
        ekf_cfg = run_config.ekf
        ekf_cfg = replace(ekf_cfg, association=replace(ekf_cfg.association, method=method))
        run_config = replace(run_config, ekf=ekf_cfg)
    check_max_scans(max_scans)
    check_out_dir(out)
    with tally_warnings() as tally:
        source = open_run_log(log, run_config, max_scans=max_scans)
        with tqdm(desc="ekf", unit="scan", disable=quiet, total=source.total(max_scans)) as bar:
            summary = run_ekf(
                source,
                out,
                run_config,
                max_scans=max_scans,
                progress=bar.update,
                tally=tally,
                strict=strict,
            )
    echo_warnings(tally)
    warn_log_anomalies(summary["log"], summary.get("log_anomalies"))
    if not quiet:
        rt = summary.get("runtime_s", {})
        msg = (
            f"{summary['scans']} scans ({summary['keyframes']} updates), "
            f"{summary['landmarks']} landmarks ({summary['lines_merged']} in the map), "
            f"{rt.get('estimate', float('nan')):.1f} s filtering; wrote {out}"
        )
        if "stop_reason" in summary:
            msg += f"; stopped: {summary['stop_reason']}"
        typer.echo(msg)
