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
) -> None:
    """Line-based factor-graph SLAM over a log.

    Writes trajectory.tum, map.json, summary.json and config.toml (and figures/ with --plot)
    into --out.
    """
    from tqdm import tqdm

    from slam.runner import run_slam

    config = build_config(config_path, sigma_d, sigma_phi, seed)
    if backend is not None:
        if backend not in ("batch", "isam2"):
            raise typer.BadParameter("--backend must be batch or isam2")
        config = replace(config, slam=replace(config.slam, backend=backend))  # type: ignore[arg-type]
    check_max_scans(max_scans)
    check_out_dir(out)
    with tqdm(
        desc=f"slam ({config.slam.backend})", unit="scan", disable=quiet, total=max_scans
    ) as bar:
        summary = run_slam(
            log, out, config, max_scans=max_scans, progress=bar.update, plot=plot, strict=strict
        )
    warn_log_anomalies(summary["log"], summary.get("log_anomalies"))
    if not quiet:
        rt = summary.get("runtime_s", {})
        typer.echo(
            f"{summary['scans']} scans ({summary['keyframes']} keyframes), "
            f"{summary['lines_fit']} lines -> {summary['landmarks']} map lines, "
            f"{rt.get('total', float('nan')):.1f} s; wrote {out}"
        )
