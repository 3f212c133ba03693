"""``lineslam extract LOG --out FILE.jsonl``: the weighted-fit lines of every scan of a log.

Output (``../shared/INTERFACES.md``): one JSON object per scan, in log order,
``{"scan": i, "t": timestamp, "lines": [{"r", "alpha", "s", "cov", "endpoints", "n_points",
"segments", "segments_var"}, ...]}`` in the sensor (laser) frame.  ``cov`` is the full 3×3
covariance of ``(r, alpha, s)``; its ``s`` row and column are not zero (see docs/linefit.md).
``segments`` (the visible pieces, ``[[x1, y1], [x2, y2]]`` each) and ``segments_var`` (variances
of their ends along the line, m²) are extra fields.

Because ``--out`` is a file here, the configuration used is written beside it as
``FILE.config.toml`` (``out.jsonl`` → ``out.config.toml``), reloadable with ``--config``.
``--plot DIR`` draws paper-style figures (Fig. 3) of a few scans spread over the log.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import nullcontext
from dataclasses import replace
from itertools import islice
from pathlib import Path
from typing import Annotated, Literal

import typer

from linefit import Line
from slam import interrupts
from slam.cli._app import app
from slam.cli.common import (
    ConfigOpt,
    QuietOpt,
    SeedOpt,
    SigmaDOpt,
    SigmaPhiOpt,
    StrictOpt,
    build_config,
    out_path,
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
from slam.config import RunConfig
from slam.errors import InputError
from slam.extraction import extract_lines_of_scans
from slam.inputs import LogInput
from slam.io.atomic import check_output_file, staged_files, staged_into
from slam.io.carmen import CarmenStats
from slam.types import Scan

__all__ = ["config_path_for", "extract", "scan_record"]

BATCH_SCANS = 64


def config_path_for(out: Path) -> Path:
    """Where the configuration of ``--out FILE.jsonl`` goes: ``FILE.config.toml``."""
    return (
        out.with_name(out.stem + ".config.toml")
        if out.suffix
        else out.with_name(out.name + ".config.toml")
    )


def scan_record(scan: Scan, lines: list[Line]) -> dict[str, object]:
    """The INTERFACES.md JSON object of one scan."""
    return {
        "scan": int(scan.index),
        "t": float(scan.timestamp),
        "lines": [ln.to_json_dict() for ln in lines],
    }


def _batches(scans: Iterator[Scan], size: int) -> Iterator[list[Scan]]:
    while True:
        chunk = list(islice(scans, size))
        if not chunk:
            return
        yield chunk


@app.command("extract")
def extract(
    log: Annotated[
        str,
        typer.Argument(
            help="CARMEN log, ROS 1 .bag, ROS 2 bag folder, or a dataset name (intel, aces, fr079)."
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out", parser=out_path, help="Output FILE.jsonl (one JSON object per scan)."
        ),
    ],
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Directory for paper-style figures of some scans.")
    ] = None,
    plot_every: Annotated[
        int,
        typer.Option("--plot-every", help="Plot every N-th scan (default: about 12 figures)."),
    ] = 0,
    grouping: Annotated[
        Literal["hough", "split_merge"] | None,
        typer.Option("--grouping", help="Override the grouping of the configuration."),
    ] = None,
    limit: Annotated[
        int | None, typer.Option("--limit", help="Only the first N scans.", min=1)
    ] = None,
    config_file: ConfigOpt = None,
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
    """Fit lines to every scan of LOG (Pfister et al. 2003, Secs. II-IV) and write FILE.jsonl.

    FILE.jsonl and FILE.config.toml are written under temporary names beside them and renamed
    into place when every scan is done: a failed or interrupted run leaves earlier files as
    they were.
    """
    from slam.config import open_run_log
    from slam.diagnostics import tally_warnings

    config = build_config(config_file, sigma_d, sigma_phi, seed)
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
    if grouping is not None:
        config = replace(config, linefit=replace(config.linefit, grouping=grouping))
    check_output_file(out)
    with tally_warnings() as tally:
        source = open_run_log(log, config, max_scans=limit)
        n_scans, n_lines, stats = _extract(
            source, out, config, plot, plot_every, limit, quiet, strict
        )
    echo_warnings(tally)
    warn_log_anomalies(source.log, stats.anomalies.to_dict())
    if not quiet:
        per_scan = n_lines / max(n_scans, 1)
        typer.echo(
            f"{n_scans} scans, {n_lines} lines ({per_scan:.2f} per scan) -> {out}; "
            f"configuration: {config_path_for(out)}"
        )


def _extract(
    source: LogInput,
    out: Path,
    config: RunConfig,
    plot: Path | None,
    plot_every: int,
    limit: int | None,
    quiet: bool,
    strict: bool,
) -> tuple[int, int, CarmenStats]:
    """Write ``out`` and its configuration (and figures under ``plot``); return the counts."""
    total = source.total(limit)
    every = plot_every if plot_every > 0 else max(1, (total or 1200) // 12)
    stats = CarmenStats(path=str(source.log))

    from tqdm import tqdm

    n_scans = n_lines = 0
    with (
        staged_files([out, config_path_for(out)], inputs=[source.log]) as (lines_tmp, cfg_tmp),
        staged_into(plot, inputs=[source.log]) if plot is not None else nullcontext() as figs,
    ):
        config.to_toml(cfg_tmp)
        scans: Iterator[Scan] = source.scans(limit, need_odometry=False, stats=stats, strict=strict)
        with (
            lines_tmp.open("w", encoding="utf-8") as handle,
            tqdm(total=total, unit="scan", desc="extract", disable=quiet) as bar,
        ):
            for chunk in _batches(scans, BATCH_SCANS):
                interrupts.check()  # between chunks (slam.interrupts)
                results = extract_lines_of_scans(chunk, config.linefit)
                for scan, lines in zip(chunk, results, strict=True):
                    handle.write(json.dumps(scan_record(scan, lines)) + "\n")
                    n_lines += len(lines)
                    if figs is not None and scan.index % every == 0:
                        from slam.plotting.scan import save_scan_figure

                        save_scan_figure(
                            figs / f"scan_{scan.index:06d}.png",
                            scan.ranges,
                            scan.bearings,
                            lines,
                            config.linefit,
                            max_range_m=scan.max_range_m,
                            title=f"{source.name} scan {scan.index}: {len(lines)} lines",
                        )
                n_scans += len(chunk)
                bar.update(len(chunk))
        if n_scans == 0:
            odometry = f" ({stats.odometry} ODOM messages)" if stats.odometry else ""
            raise InputError(f"the log contains no laser scans{odometry}", str(source.log))
    return n_scans, n_lines, stats
