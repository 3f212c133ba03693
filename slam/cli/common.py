"""Options and chores shared by the ``lineslam`` commands.

Every command that writes results: takes ``--out``, creates it, writes ``config.toml`` (the full
:class:`~slam.config.RunConfig` used), honours ``--config``, ``--sigma-d``, ``--sigma-phi``,
``--seed`` and ``--quiet``.  Values given on the command line override the file.

The ``*Opt`` / ``*Arg`` aliases are typer parameter declarations used as type annotations
(``out: OutDirOpt``); a command whose option has other help text declares its own.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from slam.config import RunConfig

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
    "build_config",
    "check_max_scans",
    "prepare_out_dir",
    "task_progress",
]

LogArg = Annotated[str, typer.Argument(help="Log file, or a dataset name (intel, aces, fr079).")]
OutDirOpt = Annotated[Path, typer.Option("--out", help="Results folder (created).")]
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


def build_config(
    config_path: Path | None,
    sigma_d: float | None = None,
    sigma_phi: float | None = None,
    seed: int | None = None,
) -> RunConfig:
    """Load ``--config`` (or the defaults) and apply the command-line overrides."""
    config = RunConfig.from_toml(config_path) if config_path is not None else RunConfig()
    config = config.with_sensor_noise(sigma_d, sigma_phi)
    if seed is not None:
        config = replace(config, seed=seed)
    return config


def prepare_out_dir(out: Path, config: RunConfig) -> Path:
    """Create ``out`` (and parents) and write ``out/config.toml``; return ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    config.to_toml(out / "config.toml")
    return out


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
