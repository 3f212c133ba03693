"""Runners: read a log, feed an estimator scan by scan, write the results folder.

``lineslam slam`` (:func:`run_slam`, the factor graph) and ``lineslam ekf`` (:func:`run_ekf`,
the EKF baseline) run the same way (:func:`run_estimator_on_log`): the log (a CARMEN file, a ROS
bag, or a catalogue name) is opened with the run's ``[scanner]`` settings
(:func:`slam.inputs.open_log`: beam geometry, range limits, laser mounting, odometry, output
frame), the scans are fed to an estimator with ``add_scan``, ``optimize()`` and ``result()`` (a
:class:`slam.result.SlamResult`), and the result's files are written.

Results folder (``../shared/INTERFACES.md``): ``trajectory.tum`` (poses in the policy's output
frame, log time stamps), ``trajectory_covariance.txt``, ``map.json``, ``summary.json`` (written
once, at the end, with ``runtime_s`` per stage: ``read``, ``extract`` (when the runner extracts
the lines), ``estimate``, ``optimize``, ``write``, ``total``; ``input``, what was read and
assumed, :meth:`slam.inputs.LogInput.describe`; ``scans_in_log`` and ``partial`` for a run over
the first scans; ``warnings``, counted, :mod:`slam.diagnostics`; the log's anomalies,
``log_anomalies``, :mod:`slam.io.anomalies`, for a CARMEN log), ``config.toml`` (the
configuration used) and, with ``plot``, ``figures/``; ``lineslam slam`` adds ``graph.g2o``.

The folder is written into a temporary folder beside ``out`` and put in place whole when the
run is complete (:func:`slam.io.atomic.staged_dir`): a failed or interrupted run leaves
``out`` as it was, a successful one replaces an earlier results folder whole.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from slam import interrupts
from slam.config import RunConfig, check_run_config, open_run_log
from slam.diagnostics import WarningTally, tally_warnings
from slam.errors import InputError
from slam.inputs import InputPolicy, LogInput, open_log
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
    Feeding stops early once ``estimator.stopped`` is true.  A signal (:mod:`slam.interrupts`)
    stops it between scans (between chunks for an estimator whose ``add_scans`` checks itself).
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
        interrupts.check()
        buffer.append(scan)
        n += 1
        if len(buffer) >= (chunk if batch_fn is not None else 1):
            flush()
            if getattr(estimator, "stopped", False):
                break
    if buffer:
        flush()
    interrupts.check()
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
        interrupts.check()
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


def _tallying(tally: WarningTally | None) -> AbstractContextManager[WarningTally]:
    return nullcontext(tally) if tally is not None else tally_warnings()


def _source(log: str | Path | LogInput, config: RunConfig, max_scans: int | None) -> LogInput:
    if isinstance(log, LogInput):
        return log
    return open_run_log(log, config, max_scans=max_scans)


def run_estimator_on_log(
    log: str | Path | LogInput,
    out: Path,
    estimator: ScanEstimator,
    policy: InputPolicy | None = None,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    linefit_config: LineFitConfig | None = None,
    min_observations: int = 1,
    tally: WarningTally | None = None,
    config: RunConfig | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """Run ``estimator`` on a log (an opened :class:`~slam.inputs.LogInput`, a file or a name).

    The scans are read as the log was opened (:func:`slam.inputs.open_log`; a path or name is
    opened with the default :class:`~slam.inputs.ScannerConfig`; ``policy`` is then only
    documentation: the estimator holds its own) and fed by :func:`feed_scans`
    (``linefit_config``: the runner extracts the lines).  The result's files are written with
    the map lines of at least ``min_observations`` measurements, ``config.toml`` (with
    ``config``), then ``summary.json`` once, with the run's times, the warnings counted and
    the log's anomalies (``strict``: the first anomaly is an error; a bag is not checked).
    The folder appears at ``out`` only when complete (module docstring).  Returns the summary.

    Raises
    ------
    OutputError
        ``out`` cannot be written, or is or holds the log (:mod:`slam.io.atomic`).
    InputError
        The log has no laser scans, or a malformed line (``LogFormatError``; with
        ``strict``, an anomaly).
    """
    from slam.blas import kernels_in_use
    from slam.io.atomic import staged_dir
    from slam.io.carmen import CarmenStats
    from slam.io.results import write_summary

    source = log if isinstance(log, LogInput) else open_log(log, max_scans=max_scans)
    stats = CarmenStats(path=str(source.log))
    with _tallying(tally) as tallied, staged_dir(out, inputs=[source.log]) as work:
        if config is not None:
            config.to_toml(work / "config.toml")
        t_start = time.perf_counter()
        try:
            clock = feed_scans(
                estimator,
                source.scans(max_scans, stats=stats, strict=strict),
                max_scans=max_scans,
                progress=progress,
                linefit_config=linefit_config,
            )
        except _NoScansError:
            raise _no_scans(source.log, stats) from None
        t0 = time.perf_counter()
        estimator.optimize()
        clock["optimize"] = time.perf_counter() - t0
        interrupts.check()
        result = estimator.result()
        interrupts.check()
        t0 = time.perf_counter()
        result.write_files(work, min_observations)
        write_graph = getattr(estimator, "write_graph_g2o", None)
        if write_graph is not None:
            write_graph(work / "graph.g2o", result)
        if plot:
            from slam.plotting.trajectory_map import plot_slam_result, raw_points_world

            points = raw_points_world(
                source.scans(max_scans, need_odometry=False),
                result.poses_world_laser,
                result.is_keyframe,
            )
            plot_slam_result(result, work / "figures", title=source.name, points_world=points)
        clock["write"] = time.perf_counter() - t0
        clock["total"] = time.perf_counter() - t_start
        summary: dict[str, Any] = result.summary_dict(min_observations)
        summary.update(source.run_summary(result.n_scans, max_scans))
        runtime = dict(summary.get("runtime_s", {}))
        runtime.update({f"{k}": float(v) for k, v in clock.items()})
        summary["runtime_s"] = runtime
        summary["warnings"] = tallied.as_list()
        summary["log_anomalies"] = stats.anomalies.to_dict()
        summary["blas"] = kernels_in_use()
        write_summary(work, summary)
    return summary


def run_slam(
    log: str | Path | LogInput,
    out: Path,
    config: RunConfig,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    tally: WarningTally | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """``lineslam slam``: factor-graph line SLAM on a log (see the module docstring).

    Besides the common files it writes ``graph.g2o``, the final factor graph
    (:func:`slam.io.g2o.write_line_graph_g2o`), and ``config`` as ``config.toml``;
    ``strict``: a log anomaly is an error.
    """
    from slam.line_slam import LineSlam

    config = check_run_config(config)
    with _tallying(tally) as tallied:
        source = _source(log, config, max_scans)
        slam = LineSlam(config.slam, config.linefit, source.policy)
        return run_estimator_on_log(
            source,
            out,
            slam,
            source.policy,
            max_scans=max_scans,
            progress=progress,
            plot=plot,
            tally=tallied,
            config=config,
            strict=strict,
        )


def run_ekf(
    log: str | Path | LogInput,
    out: Path,
    config: RunConfig,
    *,
    max_scans: int | None = None,
    progress: Callable[[int], None] | None = None,
    plot: bool = False,
    tally: WarningTally | None = None,
    strict: bool = False,
) -> dict[str, Any]:
    """``lineslam ekf``: the EKF baseline on a log (see the module docstring).

    Same input as :func:`run_slam` (:func:`slam.inputs.open_log`); the lines of every scan are
    extracted by the runner in batches of consecutive scans, the filter runs with
    ``ekf.blas_threads`` BLAS threads, and the map keeps the landmarks with at least
    ``ekf.min_landmark_observations`` measurements.  When a guard stops the filter
    (``ekf.max_landmarks``, ``ekf.max_runtime_s``), the trajectory covers the scans processed
    and ``summary.json`` says at which scan and why (``stopped_at_scan``, ``stop_reason``).
    ``config`` is written as ``config.toml``; ``strict``: a log anomaly is an error.
    """
    from slam.ekf import EkfSlam
    from slam.ekf.threads import blas_threads

    config = check_run_config(config)
    with _tallying(tally) as tallied:
        source = _source(log, config, max_scans)
        ekf = EkfSlam(config.ekf, config.linefit, source.policy)
        with blas_threads(config.ekf.blas_threads):
            return run_estimator_on_log(
                source,
                out,
                ekf,
                source.policy,
                max_scans=max_scans,
                progress=progress,
                plot=plot,
                linefit_config=config.linefit,
                min_observations=config.ekf.min_landmark_observations,
                tally=tallied,
                config=config,
                strict=strict,
            )
