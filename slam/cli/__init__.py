"""The ``lineslam`` command line (typer).

Each command lives in its own module ``slam.cli.cmd_<name>`` and registers itself on the shared
:data:`app`; this module only assembles them.  Commands and files follow
``../shared/INTERFACES.md``.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import NoReturn

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

__all__ = ["Interrupted", "app", "main"]


def _unique(*classes: type[BaseException]) -> tuple[type[BaseException], ...]:
    return tuple(dict.fromkeys(classes))


# typer >= 0.2x vendors its own click: catch its classes as well as click's.
_EXIT = _unique(click.exceptions.Exit, typer.Exit)
_ABORT = _unique(click.exceptions.Abort, typer.Abort)
_CLICK_EXCEPTION = _unique(
    click.ClickException,
    *(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException"),
)


class Interrupted(BaseException):
    """Raised in the main thread by SIGINT or SIGTERM (not a ``KeyboardInterrupt``).

    Not a ``KeyboardInterrupt``, so that neither typer nor a library turns it into a normal
    return; a ``BaseException``, so that ``except Exception`` does not swallow it.  Every
    ``finally`` and context manager on the way runs (temporary results are removed).
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)

    @property
    def exit_status(self) -> int:
        """``128 + signal number``: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


@contextmanager
def _signals_interrupt() -> Iterator[list[int]]:
    """While the command runs, the first SIGINT or SIGTERM raises :class:`Interrupted`.

    Later signals are ignored while the run cleans up (it takes well under a second; a stuck
    process still yields to ``SIGKILL``).  The previous handlers come back afterwards.  Yields
    the signals received (compiled code, e.g. numba's, may turn the exception raised inside it
    into a ``SystemError``: the caller then knows it was the signal).
    """
    seen: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield seen
        return

    def handler(signum: int, _frame: FrameType | None) -> None:
        if seen:
            return
        seen.append(signum)
        raise Interrupted(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield seen
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


def _error(message: str, status: int) -> NoReturn:
    print(f"lineslam: {message}", file=sys.stderr)
    sys.exit(status)


def _interrupted_message(exc: Interrupted) -> str:
    from slam.io.atomic import committed_targets

    written = committed_targets()
    if written:
        return f"interrupted ({exc}) after writing {written[-1]}"
    return f"interrupted ({exc}); nothing written, earlier results unchanged"


def main(argv: list[str] | None = None) -> None:
    """Run ``lineslam``.

    Exit status: 0 on success; 2 with a one-line ``lineslam: error: ...`` on stderr for bad
    input, a bad configuration or a path that cannot be read or written; 130 (SIGINT) or 143
    (SIGTERM) with a one-line ``lineslam: interrupted ...`` when a signal stops the run.
    ``LINESLAM_DEBUG=1`` shows the traceback of an operating-system error instead.
    """
    with _signals_interrupt() as signals:
        try:
            status = app(args=argv, standalone_mode=False)
        except Interrupted as exc:
            _error(_interrupted_message(exc), exc.exit_status)
        except SystemError:
            if not signals:
                raise
            exc_sig = Interrupted(signals[0])
            _error(_interrupted_message(exc_sig), exc_sig.exit_status)
        except KeyboardInterrupt:
            _error("interrupted (SIGINT)", 130)
        except LineslamError as exc:
            _error(f"error: {exc}", 2)
        except _EXIT as exc:
            sys.exit(getattr(exc, "exit_code", 0))
        except _ABORT:
            _error("aborted", 130)
        except _CLICK_EXCEPTION as exc:
            exc.show()  # type: ignore[attr-defined]
            sys.exit(getattr(exc, "exit_code", 2))
        except OSError as exc:
            if os.environ.get("LINESLAM_DEBUG"):
                raise
            where = f"{exc.filename}: " if exc.filename else ""
            _error(f"error: {where}{exc.strerror or exc}", 2)
    if isinstance(status, int) and status != 0:
        # typer returns (rather than raises) the status of an Exit in non-standalone mode
        if status == 130:
            _error("interrupted (SIGINT)", 130)
        sys.exit(status)
