"""The ``lineslam`` command line (typer).

Each command lives in its own module ``slam.cli.cmd_<name>`` and registers itself on the shared
:data:`app`; this module only assembles them.  Commands and files follow
``../shared/INTERFACES.md``.
"""

from __future__ import annotations

import sys

import click
import typer

from slam.cli import (  # noqa: F401  (commands register on import)
    cmd_compare,
    cmd_consistency,
    cmd_datasets,
    cmd_ekf,
    cmd_evaluate,
    cmd_export,
    cmd_extract,
    cmd_map,
    cmd_simulate,
    cmd_slam,
)
from slam.cli._app import app
from slam.errors import LineslamError

__all__ = ["app", "main"]


def _unique(*classes: type[BaseException]) -> tuple[type[BaseException], ...]:
    return tuple(dict.fromkeys(classes))


# typer >= 0.2x vendors its own click: catch its classes as well as click's.
_EXIT = _unique(click.exceptions.Exit, typer.Exit)
_ABORT = _unique(click.exceptions.Abort, typer.Abort)
_CLICK_EXCEPTION = _unique(
    click.ClickException,
    *(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException"),
)


def main(argv: list[str] | None = None) -> None:
    """Run ``lineslam``; a lineslam error becomes a one-line message on stderr and exit status 2."""
    try:
        app(args=argv, standalone_mode=False)
    except LineslamError as exc:
        print(f"lineslam: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except _EXIT as exc:
        sys.exit(getattr(exc, "exit_code", 0))
    except _ABORT:
        print("lineslam: aborted", file=sys.stderr)
        sys.exit(130)
    except _CLICK_EXCEPTION as exc:
        exc.show()  # type: ignore[attr-defined]
        sys.exit(getattr(exc, "exit_code", 2))
