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
) -> None:
    """EKF-SLAM baseline: trajectory.tum, map.json, summary.json."""
    from tqdm import tqdm

    from slam.errors import ConfigError
    from slam.runner import run_ekf

    run_config = build_config(config, sigma_d, sigma_phi, seed)
    if association is not None:
        if association not in ("nn", "jcbb"):
            raise ConfigError(f"--association must be nn or jcbb, got {association!r}")
        method: Literal["nn", "jcbb"] = "nn" if association == "nn" else "jcbb"
        ekf_cfg = run_config.ekf
        ekf_cfg = replace(ekf_cfg, association=replace(ekf_cfg.association, method=method))
        run_config = replace(run_config, ekf=ekf_cfg)
    check_max_scans(max_scans)
    check_out_dir(out)
    with tqdm(desc="ekf", unit="scan", disable=quiet, total=max_scans) as bar:
        summary = run_ekf(
            log, out, run_config, max_scans=max_scans, progress=bar.update, strict=strict
        )
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
