"""Command-line options for a log's scanner, mounting, odometry and output frame.

Each option sets a key of the ``[scanner]`` table (:class:`slam.inputs.ScannerConfig`) over
what ``--config`` loaded; what no option and no file states comes from the catalogue or the
log (:mod:`slam.inputs`).  Commands that read a log (``slam``, ``ekf``, ``map``, ``extract``,
``compare``) declare these parameters and call :func:`with_scanner_options`, then open the
log with :func:`open_run_log` and report the warnings of the run with :func:`echo_warnings`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Annotated, Any

import typer

from slam.config import RunConfig
from slam.diagnostics import WarningTally
from slam.errors import ConfigError

__all__ = [
    "BaseFrameOpt",
    "BeamsOpt",
    "FirstAngleOpt",
    "FovOpt",
    "FrameOpt",
    "MaxRangeOpt",
    "MinRangeOpt",
    "MountOpt",
    "OdomTopicOpt",
    "OdometryOpt",
    "ScanTopicOpt",
    "StepOpt",
    "echo_warnings",
    "parse_mount",
    "with_scanner_options",
]

_PANEL = "Scanner and input"

FirstAngleOpt = Annotated[
    float | None,
    typer.Option("--first-angle", help="Bearing of the first beam (deg).", rich_help_panel=_PANEL),
]
StepOpt = Annotated[
    float | None,
    typer.Option("--step", help="Angle between beams (deg).", rich_help_panel=_PANEL),
]
FovOpt = Annotated[
    float | None,
    typer.Option(
        "--fov",
        help="Angle from the first to the last beam (deg); first beam at -FOV/2 unless "
        "--first-angle.",
        rich_help_panel=_PANEL,
    ),
]
BeamsOpt = Annotated[
    int | None,
    typer.Option("--beams", help="Beams per scan (others are an error).", rich_help_panel=_PANEL),
]
MinRangeOpt = Annotated[
    float | None,
    typer.Option(
        "--min-range", help="Readings below this (m) are ignored.", rich_help_panel=_PANEL
    ),
]
MaxRangeOpt = Annotated[
    float | None,
    typer.Option(
        "--max-range", help="Readings at or above this (m) are no return.", rich_help_panel=_PANEL
    ),
]
MountOpt = Annotated[
    str | None,
    typer.Option(
        "--mount",
        help="Laser pose on the robot base 'X,Y,THETA' (m, m, deg); overrides the log and "
        "the catalogue.",
        rich_help_panel=_PANEL,
    ),
]
FrameOpt = Annotated[
    str | None,
    typer.Option(
        "--frame",
        help="Report the trajectory for the robot 'base' or the 'laser' (default: a catalogued "
        "log's relations frame, else the base).",
        rich_help_panel=_PANEL,
    ),
]
ScanTopicOpt = Annotated[
    str | None,
    typer.Option("--scan-topic", help="Bag: the LaserScan topic.", rich_help_panel=_PANEL),
]
OdomTopicOpt = Annotated[
    str | None,
    typer.Option("--odom-topic", help="Bag: the Odometry topic.", rich_help_panel=_PANEL),
]
OdometryOpt = Annotated[
    str | None,
    typer.Option(
        "--odometry",
        help="Bag: odometry from the 'topic', from 'tf' (odom -> base), or 'auto'.",
        rich_help_panel=_PANEL,
    ),
]
BaseFrameOpt = Annotated[
    str | None,
    typer.Option(
        "--base-frame",
        help="Bag: the robot's base frame (default: the odometry's child frame).",
        rich_help_panel=_PANEL,
    ),
]


def parse_mount(text: str) -> tuple[float, float, float]:
    """``"X,Y,THETA_DEG"`` → ``pose_base_laser`` ``(x m, y m, θ rad)``."""
    parts = [p for p in text.replace(" ", ",").split(",") if p]
    try:
        x, y, theta_deg = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--mount must be X,Y,THETA (m, m, deg), got {text!r}") from None
    if not all(math.isfinite(v) for v in (x, y, theta_deg)):
        raise ConfigError(f"--mount must be finite numbers, got {text!r}")
    return (x, y, math.radians(theta_deg))


def with_scanner_options(
    config: RunConfig,
    *,
    first_angle: float | None = None,
    step: float | None = None,
    fov: float | None = None,
    beams: int | None = None,
    min_range: float | None = None,
    max_range: float | None = None,
    mount: str | None = None,
    frame: str | None = None,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    odometry: str | None = None,
    base_frame: str | None = None,
) -> RunConfig:
    """``config`` with the options given on the command line set in ``[scanner]``."""
    changes: dict[str, Any] = {
        "first_angle_deg": first_angle,
        "step_deg": step,
        "fov_deg": fov,
        "beams": beams,
        "min_range_m": min_range,
        "max_range_m": max_range,
        "output_frame": frame,
        "scan_topic": scan_topic,
        "odom_topic": odom_topic,
        "odometry": odometry,
        "base_frame": base_frame,
    }
    changes = {k: v for k, v in changes.items() if v is not None}
    if mount is not None:
        changes["pose_base_laser"] = parse_mount(mount)
    if step is not None:
        changes["fov_deg"] = None  # the command line wins over a file's other choice
    if fov is not None:
        changes["step_deg"] = None
    if not changes:
        return config
    return replace(config, scanner=replace(config.scanner, **changes))


def echo_warnings(tally: WarningTally) -> None:
    """Print the run's warnings, one line per kind with its count, on stderr."""
    for line in tally.lines():
        typer.echo(f"lineslam: warning: {line}", err=True)
