"""Stopping a run on SIGINT or SIGTERM at safe points.

The signal handler installed by :func:`handling_signals` only records the signal; the
long-running loops call :func:`check` at safe points (between chunks of scans, between tasks,
between the iterations of a solve), which raises :class:`Interrupted` there.  So the exception
never starts inside compiled code (numba's kernel or its loading, GTSAM's elimination), where
it could be swallowed ("Exception ignored on calling ctypes callback") or crash the process.

Signals, in order:

1. The first SIGINT or SIGTERM is recorded; the next :func:`check` raises :class:`Interrupted`
   (checks are frequent enough that a run stops within a second or two).
2. A further signal while the first is still pending (no :func:`check` has raised yet) raises
   :class:`Interrupted` at once, wherever the main thread is: the way out of a step that runs
   longer than expected.  Not inside a :func:`deferred` block (compiled code and its
   loading), where it is only recorded like the first.
3. Once :class:`Interrupted` has been raised, later signals are ignored while the run cleans up
   (temporary results are removed; a stuck process still yields to ``SIGKILL``).

Inside an :func:`at_once` block (plain Python with nothing to clean up: the command line
importing its commands at start-up) the first signal raises at once as well.

:class:`Interrupted` is a ``BaseException``, not an ``Exception``: ``except Exception`` does
not swallow it and every ``finally`` on the way runs.  A run stopped this way leaves its
estimator (e.g. :class:`slam.line_slam.LineSlam`) part-way through; it is not to be used again.

Library use: without :func:`handling_signals` nothing is recorded and :func:`check` does nothing
unless :func:`request` was called (e.g. by a GUI's stop button, or a test).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from types import FrameType
from typing import TypeVar

__all__ = [
    "Interrupted",
    "abandoned",
    "at_once",
    "call_in_thread",
    "check",
    "deferred",
    "handling_signals",
    "request",
    "requested",
    "wait_abandoned",
]

T = TypeVar("T")

POLL_S = 0.05
"""How often (s) :func:`call_in_thread` checks for a signal while it waits."""

SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""The signals :func:`handling_signals` records."""


class Interrupted(BaseException):
    """The run was stopped by SIGINT or SIGTERM (not a ``KeyboardInterrupt``).

    Not a ``KeyboardInterrupt``, so that neither typer nor a library turns it into a normal
    return; a ``BaseException``, so that ``except Exception`` does not swallow it.

    Parameters
    ----------
    signum : int
        The signal that stopped the run (the first one received).
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)

    @property
    def exit_status(self) -> int:
        """``128 + signal number``: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


@dataclass
class _State:
    signum: int | None = None  # the first signal received (pending until raised)
    raised: bool = False  # Interrupted was raised: the run is cleaning up
    deferred: int = 0  # depth of deferred() blocks
    at_once: int = 0  # depth of at_once() blocks
    active: bool = False  # inside handling_signals()


_STATE = _State()
_ABANDONED: list[threading.Thread] = []


def requested() -> int | None:
    """The signal recorded (pending, or already raised as :class:`Interrupted`), or None."""
    return _STATE.signum


def check() -> None:
    """Raise :class:`Interrupted` if a signal has been recorded (a safe point of a loop).

    Costs a global look-up: call it as often as convenient.  It raises again on every later
    call (a run that swallowed the exception stops at its next check).
    """
    signum = _STATE.signum
    if signum is not None:
        _STATE.raised = True
        raise Interrupted(signum)


def request(signum: int = signal.SIGINT) -> None:
    """Record ``signum`` as if it had been received: the next :func:`check` raises."""
    if _STATE.signum is None:
        _STATE.signum = int(signum)


@contextmanager
def deferred() -> Iterator[None]:
    """A block during which no signal raises, not even a second one (compiled code).

    Signals received inside are recorded; the first :func:`check` after the block raises.
    """
    _STATE.deferred += 1
    try:
        yield
    finally:
        _STATE.deferred -= 1


@contextmanager
def at_once() -> Iterator[None]:
    """A block during which even the first signal raises at once (no compiled code inside)."""
    _STATE.at_once += 1
    try:
        yield
    finally:
        _STATE.at_once -= 1


def call_in_thread(fn: Callable[[], T], name: str = "lineslam-call") -> T:
    """``fn()`` in a helper thread, the main thread checking for a signal while it waits.

    For one long call that cannot check for itself and must not be interrupted inside (numba
    compiling or loading the compiled kernel): on a signal the main thread raises
    :class:`Interrupted` at once and leaves the call running in its (daemon) thread; the
    process should then end with ``os._exit`` once it has cleaned up (:func:`abandoned`),
    since the call may still be inside compiled code when Python shuts down.  Outside
    :func:`handling_signals` (or in another thread) it simply calls ``fn()``.  An exception
    of ``fn`` is raised here.
    """
    if not _STATE.active or threading.current_thread() is not threading.main_thread():
        return fn()
    box: dict[str, object] = {}

    def target() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # handed to the caller
            box["error"] = exc

    thread = threading.Thread(target=target, name=name, daemon=True)
    thread.start()
    try:
        while thread.is_alive():
            check()
            thread.join(POLL_S)
    except BaseException:
        if thread.is_alive():
            _ABANDONED.append(thread)
        raise
    check()
    if "error" in box:
        raise box["error"]  # type: ignore[misc]
    return box["value"]  # type: ignore[return-value]


def abandoned() -> bool:
    """A call left running by :func:`call_in_thread` is still running."""
    return any(t.is_alive() for t in _ABANDONED)


def wait_abandoned(timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` for the calls left running by :func:`call_in_thread` to end.

    For a caller that made such a call end early (e.g. killed the processes it was starting).
    Returns True if none is left running.
    """
    deadline = time.monotonic() + timeout_s
    for thread in _ABANDONED:
        thread.join(max(0.0, deadline - time.monotonic()))
    return not abandoned()


def _handler(signum: int, _frame: FrameType | None) -> None:
    state = _STATE
    if state.signum is None:
        state.signum = signum
        if not state.at_once or state.deferred:
            return
    elif state.raised or state.deferred:
        return
    # a further signal while the first is pending (the user insists), or inside at_once()
    state.raised = True
    raise Interrupted(state.signum)


@contextmanager
def handling_signals() -> Iterator[None]:
    """Record SIGINT and SIGTERM while the block runs (module docstring); restore afterwards.

    Starts with nothing recorded; after the block the handlers and the record of an enclosing
    block come back.  Outside the main thread (where Python runs signal handlers) it installs
    nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    outer = replace(_STATE)
    _set_state(_State(active=True))
    previous = {s: signal.signal(s, _handler) for s in SIGNALS}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
        _set_state(outer)


def _set_state(state: _State) -> None:
    _STATE.signum, _STATE.raised, _STATE.active = state.signum, state.raised, state.active
    _STATE.deferred, _STATE.at_once = state.deferred, state.at_once
