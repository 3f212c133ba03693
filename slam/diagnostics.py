"""Warnings of a run counted instead of printed: one line per kind at the end, and in the summary.

Main entry point::

    with tally_warnings() as tally:
        ...                      # warnings.warn(...) anywhere inside is counted, not printed
    tally.as_list()              # [{"category": "SlamWarning", "message": ..., "count": 12}, ...]
    tally.lines()                # ["12 x SlamWarning: ...", ...] for the end of a run

Python prints a warning with the source line that issued it and, by default, only the first
time per place, so how often a degradation happened is lost.  Inside :func:`tally_warnings`
every warning is recorded (filter ``"always"``) and grouped by category and message;
``summary.json`` gets the list under ``"warnings"`` and the command line prints the lines.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

__all__ = ["WarningTally", "tally_warnings"]


@dataclass
class WarningTally:
    """Warnings recorded by :func:`tally_warnings`, grouped by category and message."""

    records: list[Any] = field(default_factory=list)

    def counts(self) -> dict[tuple[str, str], int]:
        """``{(category, message): count}`` in the order first seen."""
        out: dict[tuple[str, str], int] = {}
        for w in self.records:
            key = (w.category.__name__, str(w.message))
            out[key] = out.get(key, 0) + 1
        return out

    def as_list(self) -> list[dict[str, Any]]:
        """JSON-ready: one ``{"category", "message", "count"}`` per kind."""
        return [{"category": c, "message": m, "count": n} for (c, m), n in self.counts().items()]

    def lines(self) -> list[str]:
        """One line per kind: ``"12 x SlamWarning: message"``."""
        return [f"{n} x {c}: {m}" for (c, m), n in self.counts().items()]


@contextmanager
def tally_warnings() -> Iterator[WarningTally]:
    """Record every warning issued inside (see the module docstring)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", DeprecationWarning)  # for developers, not for a run
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        tally = WarningTally(caught)
        yield tally
