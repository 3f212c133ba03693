"""Comparison runs: several estimator variants on the same data, evaluated, one report.

A :class:`Variant` names an estimator (:data:`slam.experiments.estimators.ESTIMATORS`) and the
front-end choices that matter for the paper's claims (weighted or unweighted line fits; the
association is part of the estimator name, e.g. ``ekf-nn`` / ``ekf-jcbb``).  A data source gives
the scans, their lines and what to evaluate against:

* ``sim:WORLD[:LOOPS[:SEED]]`` — the line-level simulator (:mod:`slam.experiments.linesim`;
  the estimators are told its true noise models,
  :func:`~slam.experiments.linesim.matched_run_config`), with ground truth: ATE, position
  error over time and pose NEES over time;
* a CARMEN log (path or registered name) — scans read with :mod:`slam.io`, lines extracted with
  :mod:`linefit` (weighted and unweighted), evaluated with the relations metric.

Variants run as independent tasks through :func:`slam.experiments.parallel.map_tasks`
(serially, on local processes, or on a Dask cluster); results come back to the caller, which
writes every variant's folder (``trajectory.tum``, ``map.json``, ``summary.json``) and the
report (``report.json``, ``report.md``, figures).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from slam.config import RunConfig
from slam.errors import ConfigError, LineslamError
from slam.evaluation import align_se2
from slam.experiments.estimators import ESTIMATORS, EstimateOutput, run_estimator
from slam.experiments.linesim import (
    LineSimConfig,
    matched_run_config,
    simulate_line_run,
    world_and_trajectory,
)
from slam.experiments.nees import pose_nees
from slam.experiments.parallel import map_tasks
from slam.geometry import pose_between, pose_compose

__all__ = [
    "GRAPH_BATCH_BUDGET_S",
    "CompareReport",
    "DataSpec",
    "Variant",
    "VariantOutcome",
    "ate_rmse",
    "default_variants",
    "parse_source",
    "run_compare",
    "run_variant",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Variant:
    """One configuration to compare.

    Attributes
    ----------
    name : str
        Label in the report (unique).
    estimator : str
        Key of :data:`slam.experiments.estimators.ESTIMATORS`.
    weighted : bool
        Weighted (the paper's) or unweighted line fits; only meaningful for real logs.
    time_budget_s : float or None
        Stop feeding scans once the estimator has run this long (the report says at which
        scan); None: no limit.
    """

    name: str
    estimator: str
    weighted: bool = True
    time_budget_s: float | None = None

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ConfigError(
                f"variant {self.name!r}: unknown estimator {self.estimator!r}; "
                f"known: {', '.join(sorted(ESTIMATORS))}"
            )


GRAPH_BATCH_BUDGET_S = 150.0
"""Time budget (s) of the ``graph-batch`` variant on logs (see :func:`default_variants`)."""


def default_variants(simulated: bool) -> tuple[Variant, ...]:
    """The variants ``lineslam compare`` runs by default (those whose estimators exist).

    Every variant runs with the default configuration of its estimator (one for all logs):
    the graph with the batch and the iSAM2 back-end, the EKF with JCBB (its default) and with
    nearest neighbour, odometry only, and for logs the unweighted line fits (graph iSAM2 and
    EKF).  The graph's association is its registration front end's (nearest neighbour after
    registration, :mod:`slam.frontend.registration`), which has no JCBB option, so the NN vs
    JCBB comparison is made on the EKF.

    On logs the online batch back-end (a warm-started solve of the whole graph every keyframe,
    ``O(graph)`` per keyframe) gets :data:`GRAPH_BATCH_BUDGET_S` seconds: on Intel it reached
    5632 of 13631 scans in 8 minutes and was slowing down, so running it to the end would
    take the comparison far past its 15-minute budget.  The report says where it stopped.
    """
    # longest first: tasks start in this order, so a pool of workers finishes sooner
    names = [
        ("graph-batch", "graph-batch", True),
        ("graph-isam2", "graph-isam2", True),
        ("graph-isam2-unweighted", "graph-isam2", False),
        ("ekf", "ekf-jcbb", True),
        ("ekf-nn", "ekf-nn", True),
        ("ekf-unweighted", "ekf-jcbb", False),
        ("odometry", "odometry", True),
    ]
    if simulated:  # the simulator's lines are not fitted: no weighted / unweighted choice
        names = [n for n in names if n[2]]
    return tuple(
        Variant(n, e, w, None if simulated or e != "graph-batch" else GRAPH_BATCH_BUDGET_S)
        for n, e, w in names
        if e in ESTIMATORS
    )


@dataclass(frozen=True)
class DataSpec:
    """Where the data of a comparison come from (picklable, resolved inside each task).

    Attributes
    ----------
    kind : {"sim", "log"}
    name : str
        World name (sim) or log path / registered dataset name (log).
    loops : float
        Route repetitions (sim).
    seed : int
        Simulation seed (sim).
    """

    kind: str
    name: str
    loops: float = 1.0
    seed: int = 0

    @property
    def label(self) -> str:
        """Short name for reports."""
        if self.kind == "sim":
            return f"sim:{self.name}:{self.loops:g}:{self.seed}"
        if "/" not in self.name:
            return self.name
        path = Path(self.name)  # a file named like its folder's log, e.g. sim/demo/log.clf
        return path.parent.name if path.stem == "log" else path.stem


def parse_source(source: str, seed: int = 0) -> DataSpec:
    """``sim:WORLD[:LOOPS[:SEED]]`` or a log path / dataset name."""
    if source.startswith("sim:"):
        parts = source.split(":")
        try:
            loops = float(parts[2]) if len(parts) > 2 and parts[2] else 1.0
            run_seed = int(parts[3]) if len(parts) > 3 and parts[3] else seed
        except ValueError as exc:
            raise ConfigError(f"bad simulated source {source!r}: sim:WORLD[:LOOPS[:SEED]]") from exc
        world_and_trajectory(parts[1], 1.0)  # validates the world name
        return DataSpec("sim", parts[1], loops, run_seed)
    return DataSpec("log", source)


@dataclass(frozen=True, eq=False)
class VariantOutcome:
    """One variant's estimate and its evaluation (returned from a worker).

    Attributes
    ----------
    variant : Variant
    estimate : EstimateOutput
    metrics : dict
        ``ate_rmse_m`` (ground truth), relations metrics (logs), ``nees_mean``, run times.
    pos_err_m : ndarray or None
        Position error per scan after alignment (ground truth only).
    nees : ndarray or None
        Pose NEES per scan (ground truth and covariances only).
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


def ate_rmse(poses: FloatArray, reference: FloatArray) -> tuple[float, FloatArray]:
    """ATE (RMSE of positions after SE(2) alignment, :func:`slam.evaluation.align_se2`)."""
    T = align_se2(poses[:, :2], reference[:, :2])
    aligned = pose_compose(np.broadcast_to(T, poses.shape), poses)
    err = np.linalg.norm(aligned[:, :2] - reference[:, :2], axis=1)
    return float(np.sqrt(np.mean(err**2))), err


@dataclass(frozen=True)
class CompareTask:
    """One variant on one data source."""

    data: DataSpec
    variant: Variant
    run_config: RunConfig
    sim: LineSimConfig = field(default_factory=LineSimConfig)
    cache_dir: str | None = None
    max_scans: int | None = None


def run_variant(task: CompareTask) -> VariantOutcome:
    """Load the data, run the variant's estimator, evaluate it (executed in a worker)."""
    variant, data = task.variant, task.data
    if data.kind != "sim":
        return _run_on_log(task)
    world, truth = world_and_trajectory(data.name, data.loops)
    run = simulate_line_run(world, truth, task.sim, seed=data.seed)
    rc = matched_run_config(task.run_config, task.sim)
    t0 = time.perf_counter()
    est = run_estimator(
        variant.estimator, run.scans, run.lines, rc, truth[0], time_budget_s=variant.time_budget_s
    )
    wall = time.perf_counter() - t0
    n = est.poses_world_laser.shape[0]
    ate, err = ate_rmse(est.poses_world_laser, truth[:n])
    nees = None
    if est.pose_covariances is not None:
        nees = pose_nees(est.poses_world_laser, est.pose_covariances, truth[:n])
    rel = pose_between(truth[:n], est.poses_world_laser)
    metrics: dict[str, Any] = {
        "ate_rmse_m": ate,
        "pos_err_mean_m": float(np.mean(np.hypot(rel[:, 0], rel[:, 1]))),
        "rot_err_mean_deg": float(np.degrees(np.mean(np.abs(rel[:, 2])))),
        "nees_mean": None if nees is None else float(np.nanmean(nees)),
        "runtime_s": wall,
        "scans": int(truth.shape[0]),
        "scans_processed": n,
        "landmarks": int(est.landmarks_r_alpha.shape[0]),
    }
    return VariantOutcome(variant, est, metrics, err, nees)


def _linefit_for(task: CompareTask) -> Any:
    return replace(task.run_config.linefit, weighted=task.variant.weighted)


def _run_on_log(task: CompareTask) -> VariantOutcome:
    from slam.evaluation import ate, pose_nees, relations_metric
    from slam.experiments.logdata import cached_log_data
    from slam.inputs import InputPolicy, policy_for_log
    from slam.io import Trajectory, read_relations, read_tum

    cache = Path(task.cache_dir) if task.cache_dir else None
    data = cached_log_data(
        task.data.name,
        _linefit_for(task),
        cache,
        task.max_scans,
        odometry_sign=task.run_config.slam.odometry_sign,
    )
    # the laser mounting of a catalogued log, for every estimator alike
    slam_cfg = task.run_config.slam
    pol = policy_for_log(InputPolicy.of(slam_cfg), task.data.name, slam_cfg.mount_source)
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
    traj = Trajectory.from_arrays(est.timestamps, est.poses_world_laser)
    metrics: dict[str, Any] = {
        "runtime_s": wall,
        "extraction_s": data.extraction_s,
        "scans": len(data.scans),
        "scans_processed": n,
        "landmarks": int(est.landmarks_r_alpha.shape[0]),
    }
    out = VariantOutcome(task.variant, est, metrics)
    if data.relations_path is not None:
        rel = read_relations(data.relations_path)
        try:
            m = relations_metric(traj, rel, max_unmatched_fraction=1.0)
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
            t1 = rel.t1[np.isin(rel.t1, est.timestamps) & np.isin(rel.t2, est.timestamps)]
            out = replace(
                out,
                rel_err_m=np.asarray(m.trans_errors_m, dtype=float),
                rel_scan=np.array([scan_of.get(float(t), np.nan) for t in t1], dtype=float),
            )
    if data.ground_truth_path is not None:
        gt = read_tum(data.ground_truth_path)
        a = ate(traj, gt, max_unmatched_fraction=1.0)
        metrics["ate_rmse_m"] = a.translation_m.rmse
        if est.pose_covariances is not None:
            ok = np.all(np.isfinite(est.pose_covariances), axis=(1, 2)) & (
                np.linalg.det(est.pose_covariances) > 0.0
            )
            sub = Trajectory.from_arrays(est.timestamps[ok], est.poses_world_laser[ok])
            nr = pose_nees(sub, est.pose_covariances[ok], gt, max_unmatched_fraction=1.0)
            metrics["nees_mean"] = nr.mean
            nees = np.full(n, np.nan)
            nees[np.flatnonzero(ok)[: nr.values.shape[0]]] = nr.values
            out = replace(out, nees=nees)
    return out


@dataclass(frozen=True, eq=False)
class CompareReport:
    """All variants of one comparison."""

    data: DataSpec
    outcomes: list[VariantOutcome]
    wall_time_s: float

    def rows(self) -> list[dict[str, Any]]:
        """One row per variant for the table (JSON-ready)."""
        out = []
        for o in self.outcomes:
            est = o.estimate
            rt = est.scan_runtime_s
            out.append(
                {
                    "variant": o.variant.name,
                    "estimator": o.variant.estimator,
                    "weighted": o.variant.weighted,
                    **o.metrics,
                    "runtime_per_scan_ms_mean": float(1e3 * np.mean(rt)) if rt.size else None,
                    "runtime_per_scan_ms_max": float(1e3 * np.max(rt)) if rt.size else None,
                    "stopped_at_scan": est.stats.get("stopped_at_scan"),
                    "stop_reason": est.stats.get("stop_reason"),
                }
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        """``report.json`` content."""
        return {
            "source": self.data.label,
            "kind": self.data.kind,
            "wall_time_s": self.wall_time_s,
            "variants": self.rows(),
        }

    def markdown_table(self) -> str:
        """The one comparison table (GitHub markdown)."""
        rows = self.rows()
        has_rel = any(r.get("rel_trans_mean_m") is not None for r in rows)
        has_gt = any(r.get("ate_rmse_m") is not None for r in rows)
        cols = ["variant"]
        if has_rel:
            cols += ["relations trans. (m)", "relations rot. (deg)", "relations used"]
        if has_gt:
            cols += ["ATE RMSE (m)", "mean NEES"]
        cols += ["landmarks", "time/scan (ms)", "total (s)", "note"]
        lines = ["| " + " | ".join(cols) + " |", "|---" + "|---:" * (len(cols) - 2) + "|---|"]
        for r in rows:
            note = ""
            if r.get("stopped_at_scan") is not None:
                note = f"stopped at scan {r['stopped_at_scan']}: {r['stop_reason']}"
            cells = [r["variant"]]
            if has_rel:
                cells += [
                    f"{_fmt(r.get('rel_trans_mean_m'), 3)} ± {_fmt(r.get('rel_trans_std_m'), 3)}",
                    f"{_fmt(r.get('rel_rot_mean_deg'), 2)} ± {_fmt(r.get('rel_rot_std_deg'), 2)}",
                    f"{r.get('relations_used', '–')}/{r.get('relations_total', '–')}",
                ]
            if has_gt:
                cells += [_fmt(r.get("ate_rmse_m"), 4), _fmt(r.get("nees_mean"), 2)]
            cells += [
                str(r.get("landmarks", "")),
                _fmt(r.get("runtime_per_scan_ms_mean"), 2),
                _fmt(r.get("runtime_s"), 1),
                note,
            ]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)


def _fmt(value: Any, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}"


def run_compare(
    data: DataSpec,
    variants: tuple[Variant, ...],
    run_config: RunConfig | None = None,
    workers: int = 1,
    dask_address: str | None = None,
    progress: Any = None,
    sim: LineSimConfig | None = None,
    cache_dir: str | Path | None = None,
    max_scans: int | None = None,
) -> CompareReport:
    """Run every variant on the data (one task each) and collect the outcomes in order.

    For a log, the lines are extracted once per line-fit configuration (weighted /
    unweighted) before the variants run, and cached as pickles in ``cache_dir`` where every
    worker reads them (a Dask cluster needs ``cache_dir`` on a shared file system).
    """
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ConfigError(f"variant names must be unique, got {names}")
    if not variants:
        raise ConfigError("no variants to compare")
    rc = run_config or RunConfig()
    cache = None if cache_dir is None else str(cache_dir)
    tasks = [CompareTask(data, v, rc, sim or LineSimConfig(), cache, max_scans) for v in variants]
    t0 = time.perf_counter()
    if data.kind == "log" and cache_dir is not None:
        from slam.experiments.logdata import cached_log_data

        seen = set()
        for task in tasks:  # extract once per line-fit configuration, before the variants
            if task.variant.weighted not in seen:
                seen.add(task.variant.weighted)
                cached_log_data(data.name, _linefit_for(task), Path(cache_dir), max_scans)
    outcomes = map_tasks(run_variant, tasks, workers, dask_address, progress)
    return CompareReport(data, outcomes, time.perf_counter() - t0)


def write_report(report: CompareReport, out_dir: str | Path, figures: bool = True) -> Path:
    """Write every variant's folder, ``report.json``, ``report.md`` and the figures."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for o in report.outcomes:
        if o.estimate.result is not None and hasattr(o.estimate.result, "write"):
            o.estimate.result.write(out / o.variant.name)
    doc = report.to_dict()
    fig_names: list[str] = []
    if figures:
        fig_names = _figures(report, out)
    doc["figures"] = fig_names
    (out / "report.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    md = [
        f"# Comparison on {report.data.label}",
        "",
        report.markdown_table(),
        "",
        f"Wall time {report.wall_time_s:.1f} s. EKF poses are filtered estimates (each uses the "
        "scans up to its own); graph poses are smoothed.",
        "",
    ]
    md += _filter_notes(report)
    md += [f"![{name}]({name})" for name in fig_names]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return out


def _filter_notes(report: CompareReport) -> list[str]:
    """Per EKF variant: ran to the end, or where and why it stopped; other variants if stopped.

    Other variants stop only on a time budget (``Variant.time_budget_s``).
    """
    lines: list[str] = []
    for o in report.outcomes:
        res = o.estimate.result
        stop = o.estimate.stats.get("stopped_at_scan")
        rt = np.asarray(o.estimate.scan_runtime_s)
        total = o.metrics.get("scans", rt.size)
        is_ekf = o.variant.estimator.startswith("ekf") and hasattr(res, "n_landmarks")
        if not is_ekf:
            if stop is not None:
                lines.append(
                    f"* {o.variant.name}: **stopped at scan {stop} of {total}**: "
                    f"{o.estimate.stats.get('stop_reason')}."
                )
            continue
        n_lm = np.asarray(res.n_landmarks)
        tail = rt[-max(1, rt.size // 20) :] if rt.size else rt
        size = (
            f"{int(n_lm[-1]) if n_lm.size else 0} landmarks at the end (peak "
            f"{int(n_lm.max()) if n_lm.size else 0}, state dimension {res.state_dim}), "
            f"{1e3 * float(np.mean(tail)) if tail.size else float('nan'):.1f} ms per scan over "
            f"the last 5 % of its scans (max {1e3 * float(np.max(rt)) if rt.size else 0:.0f} ms)"
        )
        if stop is None:
            lines.append(f"* {o.variant.name}: ran to the end ({total} scans); {size}.")
        else:
            lines.append(
                f"* {o.variant.name}: **stopped at scan {stop} of {total}**: "
                f"{o.estimate.stats.get('stop_reason')}; {size}."
            )
    head = "Runs (the EKF's update costs `O(n²)`, `n` its state dimension):"
    return [head, "", *lines, ""] if lines else []


def _figures(report: CompareReport, out: Path) -> list[str]:
    from slam.plotting_compare import (
        plot_errors_over_time,
        plot_nees_over_time,
        plot_runtime_per_scan,
        plot_trajectories,
    )

    names = []
    trajs = {o.variant.name: o.estimate.poses_world_laser for o in report.outcomes}
    segments: list[FloatArray] = []
    mapped = [o for o in report.outcomes if o.estimate.landmarks_r_alpha.shape[0] > 0]
    # the map of a variant that ran to the end (a time-budgeted one covers part of the log)
    mapped.sort(key=lambda o: o.estimate.stats.get("stopped_at_scan") is not None)
    if mapped and hasattr(mapped[0].estimate.result, "landmark_segments"):
        segments = list(mapped[0].estimate.result.landmark_segments)
    truth = None
    if report.data.kind == "sim":
        _, truth = world_and_trajectory(report.data.name, report.data.loops)
    title = "Trajectories over the map" + (f" ({mapped[0].variant.name})" if mapped else "")
    plot_trajectories(trajs, out / "trajectories.png", segments, truth, title=title)
    names.append("trajectories.png")
    errs = {o.variant.name: o.pos_err_m for o in report.outcomes if o.pos_err_m is not None}
    rel = {
        o.variant.name: (o.rel_scan, o.rel_err_m)
        for o in report.outcomes
        if o.rel_err_m is not None and o.rel_scan is not None
    }
    if errs:
        plot_errors_over_time(errs, out / "error.png", ylabel="position error after alignment (m)")
        names.append("error.png")
    elif rel:
        plot_errors_over_time(
            {k: np.maximum(v[1], 1e-4) for k, v in rel.items()},
            out / "error.png",
            ylabel="relation translation error (m)",
            title="Relations error over time (by the scan of each relation's first pose)",
            x={k: v[0] for k, v in rel.items()},
        )
        names.append("error.png")
    runtimes = {o.variant.name: o.estimate.scan_runtime_s for o in report.outcomes}
    sizes = {
        o.variant.name: np.asarray(o.estimate.result.n_landmarks, dtype=float)
        for o in report.outcomes
        if hasattr(o.estimate.result, "n_landmarks") and o.estimate.landmarks_r_alpha.shape[0]
    }
    plot_runtime_per_scan(runtimes, out / "runtime.png", sizes or None)
    names.append("runtime.png")
    nees = {o.variant.name: o.nees for o in report.outcomes if o.nees is not None}
    if nees:
        bounds = (float(chi2.ppf(0.025, 3)), float(chi2.ppf(0.975, 3)))
        plot_nees_over_time(
            nees,
            bounds,
            out / "nees.png",
            title="Pose NEES over time (one run; 95 % bounds of χ²₃)",
        )
        names.append("nees.png")
    return names
