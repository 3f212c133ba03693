"""One comparison task: a variant on a data source, loaded, run and evaluated in a worker.

:func:`run_variant` is what every worker executes for a :class:`CompareTask`:

1. load the data — a simulated run (:func:`slam.experiments.linesim.simulate_line_run`; the
   estimators are told the simulator's true noise models,
   :func:`~slam.experiments.linesim.matched_run_config`, and start at the true first pose) or a
   log's scans and line fits (:func:`slam.experiments.logdata.cached_log_data`, extracted
   once per line-fit configuration, :func:`prepare_log_cache`);
2. run the variant's estimator (:func:`slam.experiments.estimators.run_estimator`);
3. evaluate the estimate against every reference the source has (:func:`evaluate_variant`):
   the relations metric (Kümmerle et al.) where there are relations; ATE, position error over
   the scans and pose NEES (:mod:`slam.evaluation`) where there is ground truth.

The outcome (:class:`VariantOutcome`) goes back to the caller, which writes the report
(:mod:`slam.experiments.report`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import RunConfig
from slam.errors import EvaluationError, LineslamError
from slam.evaluation import ate, pose_nees_values, relations_metric
from slam.experiments.estimators import EstimateOutput, run_estimator
from slam.experiments.linesim import (
    LineSimConfig,
    matched_run_config,
    simulate_line_run,
    world_and_trajectory,
)
from slam.experiments.variants import DataSpec, Variant
from slam.io import Relations, Trajectory

__all__ = [
    "CompareTask",
    "VariantOutcome",
    "evaluate_variant",
    "prepare_log_cache",
    "run_variant",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CompareTask:
    """One variant on one data source (picklable: sent to a worker).

    Attributes
    ----------
    data : DataSpec
    variant : Variant
    run_config : RunConfig
        Estimator settings shared by every variant.
    sim : LineSimConfig
        Noise of the line-level simulator (simulated sources).
    cache_dir : str or None
        Folder of the line-fit cache of a log (:func:`prepare_log_cache`).
    max_scans : int or None
        Use only the first scans of a log.
    """

    data: DataSpec
    variant: Variant
    run_config: RunConfig
    sim: LineSimConfig = field(default_factory=LineSimConfig)
    cache_dir: str | None = None
    max_scans: int | None = None


@dataclass(frozen=True, eq=False)
class VariantOutcome:
    """One variant's estimate and its evaluation (returned from a worker).

    Attributes
    ----------
    variant : Variant
    estimate : EstimateOutput
    metrics : dict
        Run facts (``runtime_s``, ``scans``, ``scans_processed``, ``landmarks``, and for logs
        ``extraction_s``), then the evaluation (:func:`evaluate_variant`).
    pos_err_m : ndarray or None
        Position error per scan after alignment (m; ground truth only; ``nan`` for a scan
        without ground truth).
    nees : ndarray or None
        Pose NEES per scan (ground truth and covariances only; ``nan`` where undefined).
    rel_err_m : ndarray or None
        Translation error of each used relation (logs with relations).
    rel_scan : ndarray or None
        Scan index of each used relation's first time stamp (abscissa for plots).
    """

    variant: Variant
    estimate: EstimateOutput
    metrics: dict[str, Any] = field(default_factory=dict)
    pos_err_m: FloatArray | None = None
    nees: FloatArray | None = None
    rel_err_m: FloatArray | None = None
    rel_scan: FloatArray | None = None


def run_variant(task: CompareTask) -> VariantOutcome:
    """Load the data, run the variant's estimator, evaluate it (executed in a worker)."""
    if task.data.kind != "sim":
        return _run_on_log(task)
    return _run_on_sim(task)


def evaluate_variant(
    variant: Variant,
    est: EstimateOutput,
    metrics: dict[str, Any],
    ground_truth: Trajectory | None,
    relations: Relations | None,
    *,
    started_at_truth: bool,
) -> VariantOutcome:
    """A variant's outcome: its run facts and every evaluation its references allow.

    Parameters
    ----------
    variant : Variant
    est : EstimateOutput
        The estimate; its poses are paired with the references by time stamp.
    metrics : dict
        Run facts, copied into the outcome's metrics ahead of the evaluation.
    ground_truth : Trajectory or None
        True poses in the estimate's frame.  Adds ``ate_rmse_m`` (after SE(2) alignment,
        :func:`slam.evaluation.ate`) with the per-scan position errors, and, with pose
        covariances, ``nees_mean`` with the per-scan pose NEES
        (:func:`slam.evaluation.pose_nees_values`; no alignment: the estimate and the truth
        share the world frame).
    relations : Relations or None
        Relative poses to check (:func:`slam.evaluation.relations_metric`).  Adds
        ``rel_trans_mean_m``, ``rel_trans_std_m``, ``rel_rot_mean_deg``, ``rel_rot_std_deg``,
        ``relations_used`` and ``relations_total`` with the per-relation errors, or
        ``relations_error`` when no relation could be used.
    started_at_truth : bool
        The estimator started at the true first pose (simulated sources), so its errors
        before alignment mean something: adds ``pos_err_mean_m`` and ``rot_err_mean_deg``,
        the mean position (m) and heading (deg) errors without alignment.
    """
    metrics = dict(metrics)
    traj = Trajectory.from_arrays(est.timestamps, est.poses_world_laser)
    n = len(traj)
    out = VariantOutcome(variant, est, metrics)
    if relations is not None:
        try:
            m = relations_metric(traj, relations, max_unmatched_fraction=1.0)
        except LineslamError as exc:
            metrics["relations_error"] = str(exc)
        else:
            metrics.update(
                {
                    "rel_trans_mean_m": m.abs_trans_m.mean,
                    "rel_trans_std_m": m.abs_trans_m.std,
                    "rel_rot_mean_deg": m.abs_rot_deg.mean,
                    "rel_rot_std_deg": m.abs_rot_deg.std,
                    "relations_used": m.n_used,
                    "relations_total": m.n_relations,
                }
            )
            scan_of = {float(t): i for i, t in enumerate(est.timestamps)}
            t1 = relations.t1[
                np.isin(relations.t1, est.timestamps) & np.isin(relations.t2, est.timestamps)
            ]
            out = replace(
                out,
                rel_err_m=np.asarray(m.trans_errors_m, dtype=float),
                rel_scan=np.array([scan_of.get(float(t), np.nan) for t in t1], dtype=float),
            )
    if ground_truth is None:
        return out
    try:
        aligned = ate(traj, ground_truth, max_unmatched_fraction=1.0)
    except EvaluationError:
        # too little motion to determine an alignment (a run stopped after a few scans)
        aligned = ate(traj, ground_truth, align=False, max_unmatched_fraction=1.0)
        metrics["ate_aligned"] = False
    metrics["ate_rmse_m"] = aligned.translation_m.rmse
    matched, truth_index = aligned.index_estimate, aligned.index_reference
    pos_err = np.full(n, np.nan)
    pos_err[matched] = aligned.translation_errors_m
    out = replace(out, pos_err_m=pos_err)
    if started_at_truth:
        raw = ate(traj, ground_truth, align=False, max_unmatched_fraction=1.0)
        metrics["pos_err_mean_m"] = raw.translation_m.mean
        metrics["rot_err_mean_deg"] = raw.rotation_deg.mean
    if est.pose_covariances is not None:
        nees = np.full(n, np.nan)
        nees[matched] = pose_nees_values(
            est.poses_world_laser[matched],
            est.pose_covariances[matched],
            ground_truth.poses[truth_index],
        )
        defined = nees[np.isfinite(nees)]
        metrics["nees_mean"] = float(np.mean(defined)) if defined.size else None
        out = replace(out, nees=nees)
    return out


def prepare_log_cache(tasks: list[CompareTask], cache_dir: str | Path) -> None:
    """Extract a log's lines once per line-fit configuration of the tasks, into ``cache_dir``.

    Run before the tasks start, so that parallel workers read the cached fits instead of each
    extracting them (a Dask cluster needs ``cache_dir`` on a shared file system).  The cache is
    keyed as the workers read it (log, line-fit configuration, ``max_scans``, odometry sign).
    """
    from slam.experiments.logdata import cached_log_data

    seen = set()
    for task in tasks:
        if task.variant.weighted not in seen:
            seen.add(task.variant.weighted)
            cached_log_data(
                task.data.name,
                _linefit_for(task),
                Path(cache_dir),
                task.max_scans,
                scanner=task.run_config.scanner,
                relations=task.data.relations,
                ground_truth=task.data.ground_truth,
            )


def _linefit_for(task: CompareTask) -> Any:
    return replace(task.run_config.linefit, weighted=task.variant.weighted)


def _run_on_sim(task: CompareTask) -> VariantOutcome:
    variant, data = task.variant, task.data
    world, truth = world_and_trajectory(data.name, data.loops)
    run = simulate_line_run(world, truth, task.sim, seed=data.seed)
    rc = matched_run_config(task.run_config, task.sim)
    t0 = time.perf_counter()
    est = run_estimator(
        variant.estimator, run.scans, run.lines, rc, truth[0], time_budget_s=variant.time_budget_s
    )
    wall = time.perf_counter() - t0
    metrics: dict[str, Any] = {
        "runtime_s": wall,
        "scans": int(truth.shape[0]),
        "scans_processed": est.poses_world_laser.shape[0],
        "landmarks": int(est.landmarks_r_alpha.shape[0]),
    }
    stamps = np.array([scan.timestamp for scan in run.scans])
    ground_truth = Trajectory.from_arrays(stamps, truth)
    return evaluate_variant(variant, est, metrics, ground_truth, None, started_at_truth=True)


def _run_on_log(task: CompareTask) -> VariantOutcome:
    from slam.experiments.logdata import cached_log_data
    from slam.io import read_relations
    from slam.io.tum import read_ground_truth

    cache = Path(task.cache_dir) if task.cache_dir else None
    data = cached_log_data(
        task.data.name,
        _linefit_for(task),
        cache,
        task.max_scans,
        scanner=task.run_config.scanner,
        relations=task.data.relations,
        ground_truth=task.data.ground_truth,
    )
    # the log's input policy (mounting, laser odometry, frame), for every estimator alike
    pol = data.policy
    rc = replace(task.run_config, linefit=_linefit_for(task))
    t0 = time.perf_counter()
    est = run_estimator(
        task.variant.estimator,
        data.scans,
        data.lines,
        rc,
        None,
        time_budget_s=task.variant.time_budget_s,
        policy=pol,
    )
    wall = time.perf_counter() - t0
    n = est.poses_world_laser.shape[0]
    metrics: dict[str, Any] = {
        "runtime_s": wall,
        "extraction_s": data.extraction_s,
        "scans": len(data.scans),
        "scans_processed": n,
        "landmarks": int(est.landmarks_r_alpha.shape[0]),
    }
    relations = None if data.relations_path is None else read_relations(data.relations_path)
    truth = None if data.ground_truth_path is None else read_ground_truth(data.ground_truth_path)
    return evaluate_variant(task.variant, est, metrics, truth, relations, started_at_truth=False)
