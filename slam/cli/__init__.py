"""The ``lineslam`` command line (typer).

Each command lives in its own module ``slam.cli.cmd_<name>`` and registers itself on the shared
:data:`app`; this module only assembles them.  Commands and files follow
``../shared/INTERFACES.md``.
"""

from __future__ import annotations

import sys

import click

from slam.cli import cmd_compare, cmd_consistency, cmd_ekf  # noqa: F401  (register the commands)
from slam.cli._app import app
from slam.errors import LineslamError

__all__ = ["app", "main"]


def main(argv: list[str] | None = None) -> None:
    """Run ``lineslam``; a lineslam error becomes a one-line message on stderr and exit status 2."""
    try:
        app(args=argv, standalone_mode=False)
    except LineslamError as exc:
        print(f"lineslam: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.exceptions.Abort:
        print("lineslam: aborted", file=sys.stderr)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
