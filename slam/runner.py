"""Runners: read a log, feed an estimator scan by scan, write the results folder.

``lineslam slam`` (:func:`run_slam`, the factor graph) and ``lineslam ekf`` (:func:`run_ekf`,
the EKF baseline) run the same way (:func:`run_estimator_on_log`): the log is read with the input
policy (:mod:`slam.inputs`: odometry sign, laser mounting of a catalogued log, output frame),
the scans are fed to an estimator with ``add_scan``, ``optimize()`` and ``result()`` (a
:class:`slam.result.SlamResult`), and the result's files are written.

Results folder (``../shared/INTERFACES.md``): ``trajectory.tum`` (poses in the policy's output
frame, log time stamps), ``trajectory_covariance.txt``, ``map.json``, ``summary.json`` (written
once, at the end, with ``runtime_s`` per stage: ``read``, ``extract`` (when the runner extracts
the lines), ``estimate``, ``optimize``, ``write``, ``total``, and the log's anomalies,
``log_anomalies``, :mod:`slam.io.anomalies`), ``config.toml`` (the configuration used) and,
with ``plot``, ``figures/``.

The folder is written into a temporary folder beside ``out`` and put in place whole when the
run is complete (:func:`slam.io.atomic.staged_dir`): a failed or interrupted run leaves
``out`` as it was, a successful one replaces an earlier results folder whole.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from slam.config import RunConfig, check_run_config
from slam.errors import InputError
from slam.inputs import InputPolicy, policy_for_log, read_log_scans
from slam.types import Scan

if TYPE_CHECKING:
    from linefit.config import LineFitConfig
    from slam.io.carmen import CarmenStats

__all__ = ["ScanEstimator", "feed_scans", "run_ekf", "run_estimator_on_log", "run_slam"]


class ScanEstimator(Protocol):
    """What a runner needs from an estimator.

    ``add_scan(scan, lines)`` takes the scan's lines when the runner extracts them
    (:func:`feed_scans` with ``linefit_config``).  An estimator with a true ``stopped``
    attribute (the EKF after a guard tripped) is fed no more scans.
    """

    def add_scan(self, scan: Scan, lines: Any = None) -> Any:
        """Process one scan (with its lines, or None)."""

    def optimize(self) -> Any:
        """Finish (final optimisation)."""

    def result(self) -> Any:
        """The result, a :class:`slam.result.SlamResult`."""


def _timed(scans: Iterable[Any], clock: dict[str, float], stage: str) -> Iterator[Any]:
    """Yield ``scans``, adding the time spent producing them to ``clock[stage]``."""
    it = iter(scans)
    while True:
        t0 = time.perf_counter()
        try:
            scan = next(it)
        except StopIteration:
            clock[stage] += time.perf_counter() - t0
            return
        clock[stage] += time.perf_counter() - t0
        yield scan


def feed_scans(
    estimator: ScanEstimator,
    scans: Iterable[Scan],
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    chunk: int = 256,
    linefit_config: LineFitConfig | None = None,
) -> dict[str, float]:
    """Feed ``scans`` (at most ``max_scans``) to ``estimator``; return time per stage (s).

    An estimator with ``add_scans`` (e.g. :class:`slam.line_slam.LineSlam`, which then extracts
    the keyframes' lines in one vectorised call) gets the scans in chunks of ``chunk``.  With
    ``linefit_config`` the runner extracts every scan's lines on the way
    (:func:`slam.extraction.iter_scan_lines`, batches of consecutive scans) and calls
    ``add_scan(scan, lines)`` scan by scan; ``progress`` is then called with 1 per scan.
    Feeding stops early once ``estimator.stopped`` is true.
    """
    clock = {"read": 0.0, "estimate": 0.0}
    source: Iterable[Scan] = _timed(itertools.islice(scans, max_scans), clock, "read")
    if linefit_config is not None:
        return _feed_with_lines(estimator, source, clock, progress, linefit_config)
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

    for scan in source:
        buffer.append(scan)
        n += 1
        if len(buffer) >= (chunk if batch_fn is not None else 1):
            flush()
            if getattr(estimator, "stopped", False):
                break
    if buffer:
        flush()
    if n == 0:
        raise _NoScansError("the log contains no laser scans")
    return clock


class _NoScansError(InputError):
    """The scans fed were none."""


def _no_scans(log: Path, stats: CarmenStats) -> InputError:
    odometry = f" ({stats.odometry} ODOM messages)" if stats.odometry else ""
    return InputError(f"the log contains no laser scans{odometry}", str(log))


def _feed_with_lines(
    estimator: ScanEstimator,
    scans: Iterable[Scan],
    clock: dict[str, float],
    progress: Callable[[int], None] | None,
    linefit_config: LineFitConfig,
) -> dict[str, float]:
    """:func:`feed_scans` with the lines extracted by the runner (``clock["extract"]``)."""
    from slam.extraction import iter_scan_lines

    clock["extract"] = 0.0
    n = 0
    for scan, lines in _timed(iter_scan_lines(scans, linefit_config), clock, "extract"):
        t0 = time.perf_counter()
        estimator.add_scan(scan, lines)
        clock["estimate"] += time.perf_counter() - t0
        n += 1
        if progress is not None:
            progress(1)
        if getattr(estimator, "stopped", False):
            break
    if n == 0:
        raise _NoScansError("the log contains no laser scans")
    clock["extract"] -= clock["read"]  # reading happened inside the extraction's iterator
    return clock


def run_estimator_on_log(
    log: str | Path,
    out: Path,
    estimator: ScanEstimator,
    policy: InputPolicy,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    linefit_config: LineFitConfig | None = None,
    min_observations: int = 1,
    config: RunConfig | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """Resolve ``log`` (file or dataset name), run ``estimator`` on it, write ``out``.

    The scans are read with ``policy``'s odometry sign (:func:`slam.inputs.read_log_scans`)
    and fed by :func:`feed_scans` (``linefit_config``: the runner extracts the lines).  The
    result's files are written with the map lines of at least ``min_observations``
    measurements, ``config.toml`` (with ``config``), then ``summary.json`` once, with the
    run's times and the log's anomalies (``strict``: the first anomaly is an error).  The
    folder appears at ``out`` only when complete (module docstring).  Returns the summary.

    Raises
    ------
    OutputError
        ``out`` cannot be written, or is or holds the log (:mod:`slam.io.atomic`).
    InputError
        The log has no laser scans, or a malformed line (``LogFormatError``; with
        ``strict``, an anomaly).
    """
    from slam.io.atomic import staged_dir
    from slam.io.carmen import CarmenStats, iter_scans
    from slam.io.catalog import resolve_log
    from slam.io.results import write_summary

    resolved = resolve_log(log)
    stats = CarmenStats(path=str(resolved.log))
    with staged_dir(out, inputs=[resolved.log]) as work:
        if config is not None:
            config.to_toml(work / "config.toml")
        t_start = time.perf_counter()
        scans = read_log_scans(resolved.log, policy, stats=stats, strict=strict)
        try:
            clock = feed_scans(
                estimator,
                scans,
                max_scans=max_scans,
                progress=progress,
                linefit_config=linefit_config,
            )
        except _NoScansError:
            raise _no_scans(resolved.log, stats) from None
        t0 = time.perf_counter()
        estimator.optimize()
        clock["optimize"] = time.perf_counter() - t0
        result = estimator.result()
        t0 = time.perf_counter()
        result.write_files(work, min_observations)
        if plot:
            from slam.plotting.trajectory_map import plot_slam_result, raw_points_world

            points = raw_points_world(
                iter_scans(resolved.log), result.poses_world_laser, result.is_keyframe
            )
            plot_slam_result(result, work / "figures", title=resolved.name, points_world=points)
        clock["write"] = time.perf_counter() - t0
        clock["total"] = time.perf_counter() - t_start
        summary: dict[str, Any] = result.summary_dict(min_observations)
        summary["log"] = str(resolved.log)
        summary["dataset"] = resolved.name
        runtime = dict(summary.get("runtime_s", {}))
        runtime.update({f"{k}": float(v) for k, v in clock.items()})
        summary["runtime_s"] = runtime
        summary["log_anomalies"] = stats.anomalies.to_dict()
        write_summary(work, summary)
    return summary


def run_slam(
    log: str | Path,
    out: Path,
    config: RunConfig,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    strict: bool = False,
) -> dict[str, Any]:
    """``lineslam slam``: factor-graph line SLAM on a log (see the module docstring).

    Writes ``config`` as ``config.toml`` with the results; ``strict``: a log anomaly is an
    error.
    """
    from slam.line_slam import LineSlam

    config = check_run_config(config)
    policy = policy_for_log(InputPolicy.of(config.slam), log, config.slam.mount_source)
    slam = LineSlam(config.slam, config.linefit, policy)
    return run_estimator_on_log(
        log,
        out,
        slam,
        policy,
        max_scans=max_scans,
        progress=progress,
        plot=plot,
        config=config,
        strict=strict,
    )


def run_ekf(
    log: str | Path,
    out: Path,
    config: RunConfig,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    strict: bool = False,
) -> dict[str, Any]:
    """``lineslam ekf``: the EKF baseline on a log (see the module docstring).

    Same input policy as :func:`run_slam` (the catalogue's laser mounting included); the
    lines of every scan are extracted by the runner in batches of consecutive scans, the
    filter runs with ``ekf.blas_threads`` BLAS threads, and the map keeps the landmarks with
    at least ``ekf.min_landmark_observations`` measurements.  When a guard stops the filter
    (``ekf.max_landmarks``, ``ekf.max_runtime_s``), the trajectory covers the scans processed
    and ``summary.json`` says at which scan and why (``stopped_at_scan``, ``stop_reason``).
    """
    from slam.ekf import EkfSlam
    from slam.ekf.threads import blas_threads

    config = check_run_config(config)
    policy = policy_for_log(InputPolicy.of(config.slam), log, config.slam.mount_source)
    ekf = EkfSlam(config.ekf, config.linefit, policy)
    with blas_threads(config.ekf.blas_threads):
        return run_estimator_on_log(
            log,
            out,
            ekf,
            policy,
            max_scans=max_scans,
            progress=progress,
            plot=plot,
            linefit_config=config.linefit,
            min_observations=config.ekf.min_landmark_observations,
            config=config,
            strict=strict,
        )
