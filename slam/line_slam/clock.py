"""Where the time of a :class:`~slam.line_slam.LineSlam` run goes: one clock, named stages."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["STAGES", "StageClock"]

STAGES = (
    "extract",
    "frontend",
    "associate",
    "backend",
    "fusion",
    "loop_closure",
    "judge",
    "optimize",
    "covariances",
)
"""The stages timed, in ``summary.json``'s ``runtime_s`` (seconds of wall-clock time each).

``judge`` and part of ``backend`` run inside ``loop_closure`` (a closure is judged and, when
accepted, converged there), so those three overlap; the others do not.
"""


class StageClock:
    """Accumulated wall-clock seconds per stage (``time_s``, keys :data:`STAGES`).

    Examples
    --------
    >>> clock = StageClock()
    >>> with clock("fusion"):
    ...     pass
    >>> clock.time_s["fusion"] >= 0.0
    True
    """

    def __init__(self) -> None:
        self.time_s: dict[str, float] = dict.fromkeys(STAGES, 0.0)

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        """Time the body of a ``with`` block and add it to ``stage``."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.time_s[stage] += time.perf_counter() - t0
