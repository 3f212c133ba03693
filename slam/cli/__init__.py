"""The ``lineslam`` command line (typer).

Each command lives in its own module ``slam.cli.cmd_<name>`` and registers itself on the shared
typer application ``app`` (:mod:`slam.cli._app`); this module assembles them.  Commands and
files follow ``../shared/INTERFACES.md``.

Importing this module is cheap: the commands (numpy, numba, GTSAM, ...) are imported by
:func:`main` once the signal handlers are installed (:mod:`slam.interrupts`), in an
``at_once`` block, so that a signal during the start-up (a second or two on a loaded machine)
stops it at once, with the one line and the exit status 130/143; ``slam.cli.app`` imports them
on first use.
"""

from __future__ import annotations

import os
import sys
from typing import Any, NoReturn

from slam import interrupts
from slam.interrupts import Interrupted, check, handling_signals, requested

__all__ = ["Interrupted", "app", "main"]


def _commands() -> Any:
    """Import every command (each registers on the typer application); return the app."""
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

    return app


def __getattr__(name: str) -> Any:
    if name == "app":
        return _commands()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _unique(*classes: type[BaseException]) -> tuple[type[BaseException], ...]:
    return tuple(dict.fromkeys(classes))


def _error(message: str, status: int) -> NoReturn:
    print(f"lineslam: {message}", file=sys.stderr)
    sys.exit(status)


def _stop(exc: Interrupted, before: int) -> NoReturn:
    """Report the interruption and exit 130/143 (the run has cleaned up by now).

    A call left running in a helper thread (:func:`slam.interrupts.call_in_thread`, e.g.
    numba compiling the kernel) may be inside compiled code: the process ends with
    ``os._exit`` then, so that Python's shutdown does not tear the runtime down under it.
    """
    message = _interrupted_message(exc, before)
    if interrupts.abandoned():
        print(f"lineslam: {message}", file=sys.stderr)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(exc.exit_status)
    _error(message, exc.exit_status)


def _committed() -> list[Any]:
    """What this process has put in place so far (``slam.io.atomic`` not imported: nothing)."""
    atomic = sys.modules.get("slam.io.atomic")
    return atomic.committed_targets() if atomic is not None else []


def _interrupted_message(exc: Interrupted, before: int) -> str:
    written = _committed()[before:]  # by this command
    if written:
        return f"interrupted ({exc}) after writing {written[-1]}"
    return f"interrupted ({exc}); nothing written, earlier results unchanged"


def main(argv: list[str] | None = None) -> None:
    """Run ``lineslam``.

    Exit status: 0 on success; 2 with a one-line ``lineslam: error: ...`` on stderr for bad
    input, a bad configuration or a path that cannot be read or written; 130 (SIGINT) or 143
    (SIGTERM) with a one-line ``lineslam: interrupted ...`` when a signal stops the run
    (:mod:`slam.interrupts`: the run stops at its next check, within a second or two).
    ``LINESLAM_DEBUG=1`` shows the traceback of an operating-system error instead.
    """
    before = len(_committed())
    with handling_signals():
        try:
            status = _run(argv)
            check()  # a signal received after the last check (e.g. while writing)
        except Interrupted as exc:
            _stop(exc, before)
        except SystemError:
            # numba turns an exception raised inside its compiled code into a SystemError: only
            # a second signal can do that (the first is never raised there, slam.interrupts)
            signum = requested()
            if signum is None:
                raise
            _stop(Interrupted(signum), before)
        except KeyboardInterrupt:
            _error("interrupted (SIGINT)", 130)
    if isinstance(status, int) and status != 0:
        # typer returns (rather than raises) the status of an Exit in non-standalone mode
        if status == 130:
            _error("interrupted (SIGINT)", 130)
        sys.exit(status)


def _run(argv: list[str] | None) -> Any:
    """Import the commands, run one; errors become one line and an exit status."""
    with interrupts.at_once():  # nothing to clean up yet: a signal stops the imports
        import click
        import typer

        from slam.errors import LineslamError

        app = globals().get("app")  # set when a test replaced slam.cli.app
        if app is None:
            app = _commands()
    check()
    # typer >= 0.2x vendors its own click: catch its classes as well as click's.
    exit_ = _unique(click.exceptions.Exit, typer.Exit)
    abort = _unique(click.exceptions.Abort, typer.Abort)
    click_exception = _unique(
        click.ClickException,
        *(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException"),
    )
    try:
        return app(args=argv, standalone_mode=False)
    except LineslamError as exc:
        _error(f"error: {exc}", 2)
    except exit_ as exc:
        sys.exit(getattr(exc, "exit_code", 0))
    except abort:
        _error("aborted", 130)
    except click_exception as exc:
        exc.show()  # type: ignore[attr-defined]
        sys.exit(getattr(exc, "exit_code", 2))
    except OSError as exc:
        if os.environ.get("LINESLAM_DEBUG"):
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        _error(f"error: {where}{exc.strerror or exc}", 2)
