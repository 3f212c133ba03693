"""Lines of many scans through linefit's batch fast path, in file order (streaming).

Every estimator and runner that needs the lines of a log goes through :func:`iter_scan_lines`, so
the scan's own maximum range (no-return readings, reading note 6) is always honoured and the
per-call overhead of :func:`linefit.extract_lines` is paid once per batch instead of once per
scan (about 6× faster on the Intel log, see ``docs/linefit.md``).

Signals (:mod:`slam.interrupts`): the first extraction of a process loads linefit's compiled
kernel (numba's cache: about 0.3 s; a first run after installing compiles it: about 30 s).
That happens in a helper thread (:func:`ensure_kernel`), so that a signal stops the run at
once instead of after the loading, and never raises inside numba's loading (where an exception
is swallowed or crashes the process).  The extraction calls themselves run in
:func:`slam.interrupts.deferred` blocks: a second signal does not raise inside them either.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from linefit import Line, LineFitConfig, extract_lines_batch
from linefit.batch import kernel_ready, warm_up
from slam import interrupts
from slam.errors import InputError
from slam.types import Scan

__all__ = ["ensure_kernel", "extract_lines_of_scans", "extract_scan_lines", "iter_scan_lines"]


def ensure_kernel() -> None:
    """Load linefit's compiled kernel if not yet loaded, interruptibly (module docstring).

    Under :func:`slam.interrupts.handling_signals` it is loaded in a helper thread while the
    main thread checks for a signal; otherwise here.
    """
    if not kernel_ready():
        interrupts.call_in_thread(warm_up, name="linefit-kernel")


def _flush(batch: list[Scan], config: LineFitConfig) -> list[list[Line]]:
    ranges = np.stack([s.ranges for s in batch])
    bearings = np.stack([s.bearings for s in batch])
    max_range = np.array([s.max_range_m for s in batch], dtype=float)
    ensure_kernel()
    with interrupts.deferred():
        return extract_lines_batch(ranges, bearings, config, max_range_m=max_range)


def extract_lines_of_scans(
    scans: Sequence[Scan], config: LineFitConfig | None = None
) -> list[list[Line]]:
    """Lines of ``scans``, one :func:`linefit.extract_lines_batch` call per beam layout.

    Scans with the same beam count, first and last bearing and maximum range share a call
    (the order of the scans within a layout is kept); the result is in the order of ``scans``.
    """
    cfg = config if config is not None else LineFitConfig()
    groups: dict[tuple[int, float, float, float], list[int]] = {}
    for n, s in enumerate(scans):
        key = (s.n_beams, float(s.bearings[0]), float(s.bearings[-1]), float(s.max_range_m))
        groups.setdefault(key, []).append(n)
    out: list[list[Line]] = [[] for _ in scans]
    for members in groups.values():
        first = scans[members[0]]
        ranges = np.stack([scans[n].ranges for n in members])
        ensure_kernel()
        try:
            with interrupts.deferred():
                lines = extract_lines_batch(
                    ranges, first.bearings, cfg, max_range_m=first.max_range_m
                )
        except InputError as exc:
            where = first.source or f"scan {first.index}"
            raise InputError(f"{exc.reason} (scans from {where})") from None
        for n, ls in zip(members, lines, strict=True):
            out[n] = list(ls)
    return out


def iter_scan_lines(
    scans: Iterable[Scan], config: LineFitConfig | None = None, batch_size: int = 64
) -> Iterator[tuple[Scan, list[Line]]]:
    """Yield ``(scan, lines)`` for every scan, in order, extracting in batches.

    Consecutive scans with the same number of beams share a batch (a change of beam count
    starts a new one), so the result equals one :func:`linefit.extract_lines` call per scan
    with ``max_range_m=scan.max_range_m``.

    Parameters
    ----------
    scans
        Any iterable of scans (e.g. :func:`slam.io.iter_scans`); consumed lazily.
    config
        Line extraction settings.
    batch_size
        Scans per call of :func:`linefit.extract_lines_batch`.
    """
    cfg = config if config is not None else LineFitConfig()
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    batch: list[Scan] = []
    for scan in scans:
        interrupts.check()
        if batch and (scan.n_beams != batch[0].n_beams or len(batch) >= batch_size):
            yield from zip(batch, _flush(batch, cfg), strict=True)
            batch = []
        batch.append(scan)
    if batch:
        yield from zip(batch, _flush(batch, cfg), strict=True)


def extract_scan_lines(scan: Scan, config: LineFitConfig | None = None) -> list[Line]:
    """Lines of one scan, with the scan's own maximum range."""
    return _flush([scan], config if config is not None else LineFitConfig())[0]
