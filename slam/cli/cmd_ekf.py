"""``lineslam ekf LOG --out DIR``: EKF-SLAM baseline on a log.

Reads the log (path or registered dataset name), extracts each scan's lines with the
configured line fit, runs :class:`slam.ekf.EkfSlam` and writes the same files as
``lineslam slam``: ``trajectory.tum``, ``map.json``, ``summary.json`` and ``config.toml``.
When a guard stops the filter (``ekf.max_landmarks``, ``ekf.max_runtime_s``), the trajectory
covers the scans processed and ``summary.json`` says at which scan and why.
"""

from __future__ import annotations

from typing import Annotated, Literal

import typer

from slam.cli._app import app
from slam.cli.common import (
    ConfigOpt,
    OutDirOpt,
    QuietOpt,
    SeedOpt,
    SigmaDOpt,
    SigmaPhiOpt,
    build_config,
    prepare_out_dir,
)

__all__ = ["ekf"]


@app.command()
def ekf(
    log: Annotated[str, typer.Argument(help="Log file or registered dataset name.")],
    out: OutDirOpt,
    association: Annotated[
        str | None, typer.Option("--association", help="nn or jcbb (default: config).")
    ] = None,
    max_scans: Annotated[
        int | None, typer.Option("--max-scans", help="Process only the first scans.")
    ] = None,
    config: ConfigOpt = None,
    sigma_d: SigmaDOpt = None,
    sigma_phi: SigmaPhiOpt = None,
    seed: SeedOpt = None,
    quiet: QuietOpt = False,
) -> None:
    """EKF-SLAM baseline: trajectory.tum, map.json, summary.json."""
    import time
    from dataclasses import replace

    from slam.ekf import EkfSlam
    from slam.ekf.threads import blas_threads
    from slam.errors import ConfigError
    from slam.experiments.logdata import load_log

    run_config = build_config(config, sigma_d, sigma_phi, seed)
    if association is not None:
        if association not in ("nn", "jcbb"):
            raise ConfigError(f"--association must be nn or jcbb, got {association!r}")
        method: Literal["nn", "jcbb"] = "nn" if association == "nn" else "jcbb"
        ekf_cfg = run_config.ekf
        ekf_cfg = replace(ekf_cfg, association=replace(ekf_cfg.association, method=method))
        run_config = replace(run_config, ekf=ekf_cfg)
    prepare_out_dir(out, run_config)
    bar = None
    if not quiet:
        from tqdm import tqdm

        bar = tqdm(desc="extract", unit="scan")

    def extracted(n: int) -> None:
        if bar is not None:
            bar.update(n - bar.n)

    t0 = time.perf_counter()
    data = load_log(
        log, run_config.linefit, max_scans, extracted, odometry_sign=run_config.slam.odometry_sign
    )
    if bar is not None:
        bar.close()
        bar = tqdm(total=len(data.scans), desc="ekf", unit="scan")
    filt = EkfSlam(run_config.ekf, run_config.linefit)
    with blas_threads(run_config.ekf.blas_threads):
        for scan, lines in zip(data.scans, data.lines, strict=True):
            if filt.stopped:
                break
            filt.add_scan(scan, lines)
            if bar is not None:
                bar.update(1)
                if filt.n_landmarks and bar.n % 50 == 0:
                    bar.set_postfix(landmarks=filt.n_landmarks)
    if bar is not None:
        bar.close()
    result = filt.result()
    result.stats["runtime_s"] = {
        "extraction": data.extraction_s,
        "wall": time.perf_counter() - t0,
    }
    result.write(out, run_config.ekf.min_landmark_observations)
    if not quiet:
        msg = (
            f"{result.n_scans} scans, {result.landmarks_r_alpha.shape[0]} landmarks, "
            f"{sum(result.scan_runtime_s):.1f} s filtering"
        )
        if filt.stopped:
            msg += f"; stopped: {filt.stop_reason}"
        typer.echo(msg)
