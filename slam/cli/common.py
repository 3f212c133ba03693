"""Options and chores shared by the ``lineslam`` commands.

Every command that writes results: takes ``--out``, writes ``config.toml`` (the full
:class:`~slam.config.RunConfig` used) with its results, honours ``--config``, ``--sigma-d``,
``--sigma-phi``, ``--seed`` and ``--quiet``.  Values given on the command line override the
file.  The results folder is written beside ``--out`` and put in place whole when complete
(:mod:`slam.io.atomic`): a bad ``--out`` is refused before anything is read, and a failed or
interrupted run leaves ``--out`` as it was.

The ``*Opt`` / ``*Arg`` aliases are typer parameter declarations used as type annotations
(``out: OutDirOpt``); a command whose option has other help text declares its own.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any

import typer

from slam.config import RunConfig
from slam.errors import ConfigError, OutputError

__all__ = [
    "ConfigOpt",
    "DaskOpt",
    "LogArg",
    "MaxScansOpt",
    "OutDirOpt",
    "QuietOpt",
    "SeedOpt",
    "SigmaDOpt",
    "SigmaPhiOpt",
    "StrictOpt",
    "build_config",
    "check_max_scans",
    "check_out_dir",
    "out_path",
    "results_dir",
    "task_progress",
    "warn_log_anomalies",
]


def out_path(value: str) -> Path:
    """Parse an ``--out`` value: an empty one is refused (it would mean the current folder)."""
    if not value.strip():
        raise OutputError(repr(value), "empty path given to --out")
    return Path(value)


LogArg = Annotated[str, typer.Argument(help="Log file, or a dataset name (intel, aces, fr079).")]
OutDirOpt = Annotated[
    Path,
    typer.Option(
        "--out",
        parser=out_path,
        help="Results folder (created, or an earlier results folder replaced whole).",
    ),
]
MaxScansOpt = Annotated[int | None, typer.Option("--max-scans", help="Use only the first N scans.")]
DaskOpt = Annotated[
    str | None, typer.Option("--dask", help="Dask scheduler address (tcp://host:port).")
]

ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", help="TOML configuration (e.g. a results folder's config.toml)."),
]
SigmaDOpt = Annotated[
    float | None,
    typer.Option("--sigma-d", help="Range noise σ_d (m); default 0.005."),
]
SigmaPhiOpt = Annotated[
    float | None,
    typer.Option("--sigma-phi", help="Bearing noise σ_φ (rad); default 1e-4."),
]
SeedOpt = Annotated[int | None, typer.Option("--seed", help="Seed for every random choice.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", help="No progress bars or tables.")]
StrictOpt = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Stop at the first log anomaly (time going backwards, odometry jumps, a cut-short "
        "last line, unknown messages) instead of warning about it.",
    ),
]


def build_config(
    config_path: Path | None,
    sigma_d: float | None = None,
    sigma_phi: float | None = None,
    seed: int | None = None,
) -> RunConfig:
    """Load ``--config`` (or the defaults) and apply the command-line overrides."""
    if config_path is not None and config_path.is_dir():
        raise ConfigError(f"{config_path}: is a folder; --config takes a TOML file")
    config = RunConfig.from_toml(config_path) if config_path is not None else RunConfig()
    config = config.with_sensor_noise(sigma_d, sigma_phi)
    if seed is not None:
        config = replace(config, seed=seed)
    return config


def check_out_dir(out: Path, inputs: Iterable[str | Path] = ()) -> Path:
    """Refuse a bad ``--out`` before any work (:func:`slam.io.atomic.check_output_dir`)."""
    from slam.io.atomic import check_output_dir

    return check_output_dir(out, inputs)


@contextmanager
def results_dir(
    out: Path, config: RunConfig, inputs: Iterable[str | Path] = (), reuse: tuple[str, ...] = ()
) -> Iterator[Path]:
    """A temporary results folder holding ``config.toml``; put at ``out`` when the block ends.

    Yields the folder to write into; if the block fails or is interrupted it is removed and
    ``out`` stays as it was (:func:`slam.io.atomic.staged_dir`).
    """
    from slam.io.atomic import staged_dir

    with staged_dir(out, inputs, reuse=reuse) as work:
        config.to_toml(work / "config.toml")
        yield work


def warn_log_anomalies(log: str | Path, anomalies: Mapping[str, Any] | None) -> None:
    """Print one ``lineslam: warning:`` line per kind of log anomaly (``summary.json``)."""
    from slam.io.anomalies import anomaly_messages

    for line in anomaly_messages(str(log), dict(anomalies or {})):
        print(f"lineslam: warning: {line}", file=sys.stderr)


def check_max_scans(max_scans: int | None) -> None:
    """Reject ``--max-scans`` below 1 (a usage error)."""
    if max_scans is not None and max_scans < 1:
        raise typer.BadParameter("--max-scans must be >= 1")


@contextmanager
def task_progress(
    total: int, desc: str, unit: str, quiet: bool
) -> Iterator[Callable[[int, int], None]]:
    """A ``progress(done, total)`` callback drawing a tqdm bar (none with ``quiet``)."""
    if quiet:
        yield lambda done, total: None
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=desc, unit=unit) as bar:

        def progress(done: int, total: int) -> None:
            bar.n = done
            bar.refresh()

        yield progress
