"""The typer application object that every ``slam.cli.cmd_*`` module registers commands on."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="lineslam",
    help="Weighted line fitting and line-based 2D laser SLAM.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
