"""Runners: read a log, feed an estimator scan by scan, write the results folder.

Shared by ``lineslam slam`` (the factor graph) and any other estimator with the same shape
(the EKF baseline): an object with ``add_scan(scan)``, ``optimize()`` and ``result()``, whose
result has ``write(out_dir)`` and ``summary_dict()``.

Results folder (``../shared/INTERFACES.md``): ``trajectory.tum`` (laser poses, log time stamps),
``map.json``, ``summary.json`` (with ``runtime_s`` per stage: ``read``, ``estimate``,
``optimize``, ``write``, ``total``), ``config.toml`` (written by the CLI before the run) and,
with ``plot``, ``figures/``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, Protocol

from slam.config import RunConfig
from slam.errors import InputError
from slam.inputs import InputPolicy, policy_for_log
from slam.types import Scan

__all__ = ["ScanEstimator", "feed_scans", "run_estimator_on_log", "run_slam"]


class ScanEstimator(Protocol):
    """What a runner needs from an estimator."""

    def add_scan(self, scan: Scan) -> Any:
        """Process one scan."""

    def optimize(self) -> Any:
        """Finish (final optimisation)."""

    def result(self) -> Any:
        """The result: has ``write(out_dir)`` and ``summary_dict()``."""


def _timed(scans: Iterable[Scan], clock: dict[str, float]) -> Iterator[Scan]:
    """Yield ``scans``, adding the time spent producing them to ``clock["read"]``."""
    it = iter(scans)
    while True:
        t0 = time.perf_counter()
        try:
            scan = next(it)
        except StopIteration:
            clock["read"] += time.perf_counter() - t0
            return
        clock["read"] += time.perf_counter() - t0
        yield scan


def feed_scans(
    estimator: ScanEstimator,
    scans: Iterable[Scan],
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    chunk: int = 256,
) -> dict[str, float]:
    """Feed ``scans`` (at most ``max_scans``) to ``estimator``; return time per stage (s).

    An estimator with ``add_scans`` (e.g. :class:`slam.line_slam.LineSlam`, which then extracts the
    keyframes' lines in one vectorised call) gets the scans in chunks of ``chunk``.
    """
    clock = {"read": 0.0, "estimate": 0.0}
    n = 0
    batch_fn = getattr(estimator, "add_scans", None)
    buffer: list[Scan] = []

    def flush() -> None:
        t0 = time.perf_counter()
        if batch_fn is not None:
            batch_fn(buffer)
        else:
            for s in buffer:
                estimator.add_scan(s)
        clock["estimate"] += time.perf_counter() - t0
        if progress is not None:
            progress(len(buffer))
        buffer.clear()

    for scan in _timed(scans, clock):
        buffer.append(scan)
        n += 1
        if len(buffer) >= (chunk if batch_fn is not None else 1):
            flush()
        if max_scans is not None and n >= max_scans:
            break
    if buffer:
        flush()
    if n == 0:
        raise InputError("the log contains no laser scans")
    return clock


def run_estimator_on_log(
    log: str | Path,
    out: Path,
    estimator: ScanEstimator,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    odometry_sign: str = "velocity",
) -> dict[str, Any]:
    """Resolve ``log`` (file or dataset name), run ``estimator`` on it, write ``out``.

    ``odometry_sign`` chooses the odometry (:func:`slam.io.carmen.iter_log_scans`).  Returns the
    summary written to ``out/summary.json``.
    """
    from slam.io.carmen import iter_log_scans, iter_scans
    from slam.io.catalog import resolve_log

    resolved = resolve_log(log)
    t_start = time.perf_counter()
    scans = iter_log_scans(resolved.log, odometry_sign)
    clock = feed_scans(estimator, scans, max_scans=max_scans, progress=progress)
    t0 = time.perf_counter()
    estimator.optimize()
    clock["optimize"] = time.perf_counter() - t0
    result = estimator.result()
    t0 = time.perf_counter()
    result.write(out)
    if plot:
        from slam.plotting.trajectory_map import plot_slam_result, raw_points_world

        points = None
        if hasattr(result, "poses_world_laser") and hasattr(result, "is_keyframe"):
            points = raw_points_world(
                iter_scans(resolved.log), result.poses_world_laser, result.is_keyframe
            )
        plot_slam_result(result, out / "figures", title=resolved.name, points_world=points)
    clock["write"] = time.perf_counter() - t0
    clock["total"] = time.perf_counter() - t_start
    summary: dict[str, Any] = result.summary_dict()
    summary["log"] = str(resolved.log)
    summary["dataset"] = resolved.name
    runtime = dict(summary.get("runtime_s", {}))
    runtime.update({f"{k}": float(v) for k, v in clock.items()})
    summary["runtime_s"] = runtime
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", "utf-8")
    return summary


def run_slam(
    log: str | Path,
    out: Path,
    config: RunConfig,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
) -> dict[str, Any]:
    """``lineslam slam``: factor-graph line SLAM on a log (see the module docstring)."""
    from slam.line_slam import LineSlam

    policy = policy_for_log(InputPolicy.of(config.slam), log, config.slam.mount_source)
    slam = LineSlam(config.slam, config.linefit, policy)
    summary = run_estimator_on_log(
        log,
        out,
        slam,
        max_scans=max_scans,
        progress=progress,
        plot=plot,
        odometry_sign=policy.odometry_sign,
    )
    return summary
