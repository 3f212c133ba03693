"""Estimators behind one call, for experiments that feed them the same scans and lines.

:func:`run_estimator` takes a name from :data:`ESTIMATORS`, the scans, their lines (laser frame),
the run configuration and the input policy (:class:`slam.inputs.InputPolicy`: laser odometry,
mounting, output frame; the same for every estimator), and returns an :class:`EstimateOutput`:
the trajectory with pose covariances (right-perturbation tangent space) and run times.  Names:

* ``"ekf"`` — :class:`slam.ekf.EkfSlam` with ``RunConfig.ekf`` (association as configured);
* ``"ekf-nn"``, ``"ekf-jcbb"`` — the same with the association forced;
* ``"ekf-fej"``, ``"ekf-oc"`` — the same with the first-estimates or the
  observability-constrained Jacobians (``EkfConfig.jacobians``);
* ``"graph-isam2"``, ``"graph-batch"`` — :class:`slam.line_slam.LineSlam` with ``RunConfig.slam``
  and that back-end, then :meth:`~slam.line_slam.LineSlam.optimize` (the graph's association is its
  registration front end's nearest neighbour, with no JCBB option);
* ``"odometry"`` — dead reckoning with the same motion model, covariance propagated (the EKF
  fed no lines), the reference every SLAM estimator must beat.

Lines per scan are a :class:`~slam.lines.lineset.LineSet` (line-level simulator; converted
to :class:`linefit.Line` objects for the graph, :func:`slam.experiments.linesim.lineset_to_lines`)
or a list of :class:`linefit.Line` (a log's fits); estimators apply their own length/support
filters.  ``None`` lets each estimator extract the lines itself.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam import interrupts
from slam.config import RunConfig
from slam.ekf import EkfSlam
from slam.ekf.threads import blas_threads
from slam.errors import ConfigError, EstimationError
from slam.inputs import InputPolicy
from slam.lines.lineset import LineSet
from slam.types import Scan

__all__ = ["ESTIMATORS", "EstimateOutput", "run_estimator"]

FloatArray = NDArray[np.float64]
ScanLines = Sequence[LineSet] | Sequence[Sequence[Line]] | None


@dataclass(frozen=True, eq=False)
class EstimateOutput:
    """A trajectory estimate with what experiments compare.

    Attributes
    ----------
    name : str
        Estimator name.
    timestamps : ndarray, shape (N,)
    poses_world_laser : ndarray, shape (N, 3)
    pose_covariances : ndarray, shape (N, 3, 3) or None
        Tangent-space covariances (None where the estimator gives none).
    scan_runtime_s : ndarray, shape (N,)
    landmarks_r_alpha : ndarray, shape (M, 2)
    stats : dict
        Estimator counters; ``stopped_at_scan`` / ``stop_reason`` when it stopped early;
        ``frame`` (``"laser"`` or ``"base"``) of the poses.
    result : SlamResult
        The estimator's result (:class:`slam.result.SlamResult`), for writing files.
    """

    name: str
    timestamps: FloatArray
    poses_world_laser: FloatArray
    pose_covariances: FloatArray | None
    scan_runtime_s: FloatArray
    landmarks_r_alpha: FloatArray
    stats: dict[str, Any] = field(default_factory=dict)
    result: Any = None


def _ekf(
    name: str,
    scans: Sequence[Scan],
    lines: ScanLines,
    config: RunConfig,
    initial_pose: FloatArray | None,
    policy: InputPolicy,
    association: Literal["nn", "jcbb"] | None = None,
    use_lines: bool = True,
    time_budget_s: float | None = None,
    jacobians: Literal["current", "first-estimates", "observability-constrained"] | None = None,
) -> EstimateOutput:
    ekf_cfg = config.ekf
    if association is not None:
        ekf_cfg = replace(ekf_cfg, association=replace(ekf_cfg.association, method=association))
    if jacobians is not None:
        ekf_cfg = replace(ekf_cfg, jacobians=jacobians)
    if time_budget_s is not None:
        limit = min(time_budget_s, ekf_cfg.max_runtime_s or math.inf)
        ekf_cfg = replace(ekf_cfg, max_runtime_s=limit)
    ekf = EkfSlam(ekf_cfg, config.linefit, policy, initial_pose_world_laser=initial_pose)
    with blas_threads(ekf_cfg.blas_threads):
        for k, scan in enumerate(scans):
            interrupts.check()
            if ekf.stopped:
                break
            if use_lines:
                ekf.add_scan(scan, None if lines is None else lines[k])
            else:
                ekf.add_scan(scan, LineSet.empty())
    res = ekf.result()
    return _output(name, res, {**res.stats, "frame": res.frame})


def _output(name: str, res: Any, stats: dict[str, Any]) -> EstimateOutput:
    """An estimator's result object (EKF or graph) as an :class:`EstimateOutput`."""
    return EstimateOutput(
        name=name,
        timestamps=res.timestamps,
        poses_world_laser=res.poses_world_laser,
        pose_covariances=res.pose_covariances,
        scan_runtime_s=res.scan_runtime_s,
        landmarks_r_alpha=res.landmarks_r_alpha,
        stats=stats,
        result=res,
    )


def _graph(
    name: str,
    scans: Sequence[Scan],
    lines: ScanLines,
    config: RunConfig,
    initial_pose: FloatArray | None,
    policy: InputPolicy,
    backend: Literal["batch", "isam2"],
    time_budget_s: float | None = None,
) -> EstimateOutput:
    import warnings

    from slam.experiments.linesim import lineset_to_lines
    from slam.line_slam import LineSlam

    cfg = replace(config.slam, backend=backend)
    if initial_pose is not None and scans:
        odom0 = policy.pose_odom_laser(scans[0])
        if not np.allclose(odom0, initial_pose, atol=1e-9):
            raise ConfigError(
                f"{name}: the graph's world frame is the first scan's odometry pose; "
                "an initial pose different from it is not supported"
            )
    slam = LineSlam(cfg, config.linefit, policy)
    stop: dict[str, Any] = {}
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SlamWarnings are counted in the result's stats
        for k, scan in enumerate(scans):
            interrupts.check()
            if time_budget_s is not None and time.perf_counter() - t0 > time_budget_s:
                stop = {
                    "stopped_at_scan": k,
                    "stop_reason": (
                        f"the comparison's time budget of {time_budget_s:g} s per variant was "
                        f"spent at scan {k} ({cfg.backend} back-end); the graph so far was "
                        "optimised and evaluated"
                    ),
                }
                break
            scan_lines: Any = None if lines is None else lines[k]
            if isinstance(scan_lines, LineSet):
                scan_lines = lineset_to_lines(scan_lines)
            slam.add_scan(scan, scan_lines)
        slam.optimize()
    res = slam.result()
    return _output(name, res, {**res.stats, "frame": res.frame, **stop})


EstimatorFn = Callable[..., EstimateOutput]
"""``fn(scans, lines, config, initial_pose, policy, time_budget_s=None) -> EstimateOutput``."""

ESTIMATORS: dict[str, EstimatorFn] = {
    "ekf": partial(_ekf, "ekf"),
    "ekf-nn": partial(_ekf, "ekf-nn", association="nn"),
    "ekf-jcbb": partial(_ekf, "ekf-jcbb", association="jcbb"),
    "ekf-fej": partial(_ekf, "ekf-fej", jacobians="first-estimates"),
    "ekf-oc": partial(_ekf, "ekf-oc", jacobians="observability-constrained"),
    "odometry": partial(_ekf, "odometry", use_lines=False),
    "graph-isam2": partial(_graph, "graph-isam2", backend="isam2"),
    "graph-batch": partial(_graph, "graph-batch", backend="batch"),
}


def run_estimator(
    name: str,
    scans: Sequence[Scan],
    lines: ScanLines,
    config: RunConfig,
    initial_pose_world_laser: FloatArray | None = None,
    time_budget_s: float | None = None,
    policy: InputPolicy | None = None,
) -> EstimateOutput:
    """Run the estimator ``name`` on scans (with their lines, or None to extract them).

    ``policy`` reads the scans' laser odometry and chooses the reported frame (default:
    ``InputPolicy.of(config.scanner)``, the stated settings; :func:`slam.inputs.open_log`
    resolves them for a log).

    With ``time_budget_s`` the estimator stops taking scans once that much time is spent
    (the EKF through ``ekf.max_runtime_s``; the graph optimises what it has); its statistics
    then say at which scan and why (``stopped_at_scan``, ``stop_reason``).

    Raises
    ------
    ConfigError
        For an unknown estimator name.
    """
    try:
        fn = ESTIMATORS[name]
    except KeyError as exc:
        raise ConfigError(
            f"unknown estimator {name!r}; known: {', '.join(sorted(ESTIMATORS))}"
        ) from exc
    t0 = time.perf_counter()
    pol = policy if policy is not None else InputPolicy.of(config.scanner)
    out = fn(scans, lines, config, initial_pose_world_laser, pol, time_budget_s=time_budget_s)
    if out.poses_world_laser.shape[0] == 0:
        raise EstimationError(f"estimator {name} produced no poses")
    out.stats.setdefault("wall_time_s", time.perf_counter() - t0)
    return out
