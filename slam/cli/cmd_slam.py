"""``lineslam slam LOG --out DIR``: factor-graph line SLAM (batch LM or iSAM2)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from slam.cli._app import app
from slam.cli.common import (
    ConfigOpt,
    QuietOpt,
    SeedOpt,
    SigmaDOpt,
    SigmaPhiOpt,
    build_config,
    prepare_out_dir,
)

__all__ = ["slam_command"]


@app.command("slam")
def slam_command(
    log: Annotated[str, typer.Argument(help="Log file, or a dataset name (intel, aces, fr079).")],
    out: Annotated[Path, typer.Option("--out", help="Results folder (created).")],
    backend: Annotated[
        str | None,
        typer.Option("--backend", help="batch (periodic Levenberg-Marquardt) or isam2."),
    ] = None,
    config_path: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
    max_scans: Annotated[
        int | None, typer.Option("--max-scans", help="Use only the first N scans.")
    ] = None,
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
    if max_scans is not None and max_scans < 1:
        raise typer.BadParameter("--max-scans must be >= 1")
    prepare_out_dir(out, config)
    with tqdm(
        desc=f"slam ({config.slam.backend})", unit="scan", disable=quiet, total=max_scans
    ) as bar:
        summary = run_slam(log, out, config, max_scans=max_scans, progress=bar.update, plot=plot)
    if not quiet:
        rt = summary.get("runtime_s", {})
        typer.echo(
            f"{summary['scans']} scans ({summary['keyframes']} keyframes), "
            f"{summary['lines_fit']} lines -> {summary['landmarks']} map lines, "
            f"{rt.get('total', float('nan')):.1f} s; wrote {out}"
        )
