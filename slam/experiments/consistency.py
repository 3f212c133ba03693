"""Monte-Carlo consistency: seeded runs per estimator on simulated worlds, pose NEES over time.

Each run ``i`` simulates the world with seed ``task_seed(seed, i)`` (the same data for every
estimator: a paired comparison), runs each estimator on it, and records per pose the NEES
(:func:`slam.evaluation.pose_nees_values`, tangent space) and its heading part alone
(``ξ_θ² / P_θθ``, 1 dof: where the EKF's spurious heading information shows, Huang, Mourikis &
Roumeliotis 2010), the position and heading errors and the run time.  The summary per
estimator is the average NEES over runs at each time step (ANEES) with its two-sided χ² bounds
(``n_runs · ANEES ~ χ²_{3 n_runs}`` for a consistent estimator,
:func:`slam.evaluation.nees_bounds`; ``χ²_{n_runs}`` for the heading part), the fraction of
time steps inside them, and the mean over time.

Filtering estimators (EKF) are evaluated on their filtered pose at each time; smoothing ones
(the batch graph) on their final trajectory; both are what the estimator reports for that pose.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import RunConfig
from slam.errors import ConfigError
from slam.evaluation import nees_bounds, pose_nees_values
from slam.experiments.estimators import ESTIMATORS, run_estimator
from slam.experiments.linesim import (
    LineSimConfig,
    matched_run_config,
    simulate_line_run,
    world_and_trajectory,
)
from slam.experiments.parallel import map_tasks, task_seed
from slam.geometry import pose_between, pose_log

__all__ = [
    "ConsistencyConfig",
    "ConsistencyResult",
    "ConsistencyTask",
    "EstimatorConsistency",
    "consistency_task",
    "run_consistency",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ConsistencyConfig:
    """What a Monte-Carlo consistency study runs.

    Attributes
    ----------
    world : str
        Simulated world (:func:`slam.experiments.linesim.world_and_trajectory`).
    loops : float
        Repetitions of the world's route.
    n_runs : int
        Seeded runs per estimator (the issue asks for at least 50).
    estimators : tuple of str
        Names from :data:`slam.experiments.estimators.ESTIMATORS`.
    probability : float
        Coverage of the ANEES bounds.
    seed : int
        Base seed; run ``i`` uses ``task_seed(seed, i)``.
    linesim : LineSimConfig
        Line-level simulator noise.  The estimators are told its true models
        (:func:`slam.experiments.linesim.matched_run_config`: its odometry noise, no
        model-error floor on the exact line covariances), so the study measures the
        estimators, not a mismatched model.
    """

    world: str = "corridor_loop"
    loops: float = 1.0
    n_runs: int = 50
    estimators: tuple[str, ...] = ("ekf", "graph-isam2", "graph-batch", "odometry")
    probability: float = 0.95
    seed: int = 0
    linesim: LineSimConfig = field(default_factory=LineSimConfig)

    def __post_init__(self) -> None:
        if self.n_runs < 1:
            raise ConfigError(f"n_runs must be >= 1, got {self.n_runs}")
        if not 0.0 < self.probability < 1.0:
            raise ConfigError(f"probability must be in (0, 1), got {self.probability}")
        unknown = [e for e in self.estimators if e not in ESTIMATORS]
        if unknown or not self.estimators:
            raise ConfigError(
                f"unknown estimator(s) {unknown}; known: {', '.join(sorted(ESTIMATORS))}"
            )
        if not (math.isfinite(self.loops) and self.loops > 0.0):
            raise ConfigError(f"loops must be > 0, got {self.loops}")
        world_and_trajectory(self.world, 1.0)  # validates the name


@dataclass(frozen=True)
class ConsistencyTask:
    """One seeded run: simulate once, run every estimator on the same data."""

    run_index: int
    seed: int
    config: ConsistencyConfig
    run_config: RunConfig


def consistency_task(task: ConsistencyTask) -> dict[str, dict[str, Any]]:
    """Run one seeded simulation through every estimator; per-pose NEES, errors and times.

    Returns
    -------
    dict
        ``{estimator: {"nees": (N,), "nees_heading": (N,), "pos_err_m": (N,),
        "rot_err_rad": (N,), "runtime_s": float, "landmarks": int,
        "stopped_at_scan": int or None}}``.
    """
    cfg = task.config
    world, truth = world_and_trajectory(cfg.world, cfg.loops)
    run = simulate_line_run(world, truth, cfg.linesim, seed=task.seed)
    run_config = matched_run_config(task.run_config, cfg.linesim)
    out: dict[str, dict[str, Any]] = {}
    for name in cfg.estimators:
        t0 = time.perf_counter()
        est = run_estimator(name, run.scans, run.lines, run_config, truth[0])
        runtime = time.perf_counter() - t0
        n = est.poses_world_laser.shape[0]
        nees = np.full(truth.shape[0], np.nan)
        nees_heading = np.full(truth.shape[0], np.nan)
        if est.pose_covariances is not None:
            nees[:n] = pose_nees_values(est.poses_world_laser, est.pose_covariances, truth[:n])
            nees_heading[:n] = _heading_nees(est.poses_world_laser, est.pose_covariances, truth[:n])
            nees_heading[~np.isfinite(nees)] = np.nan  # defined where the pose NEES is
        err = pose_between(truth[:n], est.poses_world_laser)
        pos = np.full(truth.shape[0], np.nan)
        rot = np.full(truth.shape[0], np.nan)
        pos[:n] = np.hypot(err[:, 0], err[:, 1])
        rot[:n] = np.abs(err[:, 2])
        out[name] = {
            "nees": nees,
            "nees_heading": nees_heading,
            "pos_err_m": pos,
            "rot_err_rad": rot,
            "runtime_s": runtime,
            "landmarks": int(est.landmarks_r_alpha.shape[0]),
            "stopped_at_scan": est.stats.get("stopped_at_scan"),
        }
    return out


def _heading_nees(poses_est: FloatArray, covariances: FloatArray, truth: FloatArray) -> FloatArray:
    """Heading part of the pose NEES, ``ξ_θ² / P_θθ`` (1 dof), ``ξ = Log(P̂⁻¹ · Q)``.

    It never exceeds the pose NEES of the same pose (a marginal of a quadratic form).
    """
    xi_theta = pose_log(pose_between(poses_est, truth))[:, 2]
    var_theta = covariances[:, 2, 2]
    out = np.full(xi_theta.shape, np.nan)
    ok = np.isfinite(var_theta) & (var_theta > 0.0)
    out[ok] = xi_theta[ok] ** 2 / var_theta[ok]
    return out


@dataclass(frozen=True, eq=False)
class EstimatorConsistency:
    """Monte-Carlo summary of one estimator.

    Attributes
    ----------
    name : str
    nees : ndarray, shape (n_runs, N)
        Pose NEES of every run at every time step (``nan`` where undefined, e.g. the anchored
        first pose).
    anees : ndarray, shape (N,)
        Average over runs at each time step.
    bounds : tuple of float
        Two-sided χ² bounds of the ANEES for 3 dof and ``n_runs`` runs.
    nees_heading : ndarray, shape (n_runs, N)
        The heading part of ``nees`` alone, ``ξ_θ² / P_θθ`` (1 dof; ``nan`` where ``nees``
        is).
    heading_bounds : tuple of float
        Two-sided χ² bounds of its average over runs (1 dof, ``n_runs`` runs).
    fraction_inside : float
        Share of time steps (with a defined ANEES) inside the bounds.
    pos_err_m : ndarray, shape (n_runs, N)
        Position error of every run at every time step.
    pos_rmse_m : ndarray, shape (n_runs,)
        Position RMSE of each run.
    runtime_s : ndarray, shape (n_runs,)
    landmarks : ndarray of int, shape (n_runs,)
    """

    name: str
    nees: FloatArray
    anees: FloatArray
    bounds: tuple[float, float]
    fraction_inside: float
    pos_err_m: FloatArray
    pos_rmse_m: FloatArray
    runtime_s: FloatArray
    landmarks: NDArray[np.int64]
    nees_heading: FloatArray
    heading_bounds: tuple[float, float]

    @property
    def mean_anees(self) -> float:
        """ANEES averaged over time."""
        return float(np.nanmean(self.anees))

    @property
    def anees_heading(self) -> FloatArray:
        """Average heading NEES over runs at each time step, shape (N,) (1 dof)."""
        return _nanmean_rows(self.nees_heading)

    @property
    def mean_anees_heading(self) -> float:
        """Heading ANEES averaged over time (1 dof: 1 for a consistent estimator)."""
        return float(np.nanmean(self.anees_heading))

    @property
    def pos_rmse_over_time(self) -> FloatArray:
        """Position RMSE over runs at each time step, shape (N,)."""
        return np.sqrt(_nanmean_rows(np.square(self.pos_err_m)))

    @property
    def fraction_above(self) -> float:
        """Share of time steps above the upper bound (over-confidence)."""
        ok = np.isfinite(self.anees)
        return float(np.mean(self.anees[ok] > self.bounds[1])) if np.any(ok) else float("nan")

    def anees_per_segment(self, n_segments: int) -> FloatArray:
        """ANEES averaged over each of ``n_segments`` equal stretches of the run (e.g. loops)."""
        return _segment_means(self.anees, n_segments)

    def anees_heading_per_segment(self, n_segments: int) -> FloatArray:
        """Heading ANEES averaged over each of ``n_segments`` equal stretches of the run."""
        return _segment_means(self.anees_heading, n_segments)

    @property
    def run_mean_nees(self) -> FloatArray:
        """Each run's NEES averaged over its time steps, shape (n_runs,)."""
        return _nanmean_rows(self.nees.T)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (per-time ANEES and per-run mean NEES included)."""
        return {
            "name": self.name,
            "n_runs": int(self.nees.shape[0]),
            "mean_anees": self.mean_anees,
            "median_run_nees": float(np.nanmedian(self.run_mean_nees)),
            "run_mean_nees": [float(v) for v in self.run_mean_nees],
            "pos_rmse_m": [float(v) for v in self.pos_rmse_m],
            "bounds": list(self.bounds),
            "fraction_inside": self.fraction_inside,
            "fraction_above": self.fraction_above,
            "pos_rmse_m_mean": float(np.mean(self.pos_rmse_m)),
            "pos_rmse_m_median": float(np.median(self.pos_rmse_m)),
            "runtime_s_mean": float(np.mean(self.runtime_s)),
            "landmarks_mean": float(np.mean(self.landmarks)),
            "anees": [None if not np.isfinite(v) else float(v) for v in self.anees],
            "mean_anees_heading": self.mean_anees_heading,
            "heading_bounds": list(self.heading_bounds),
        }


@dataclass(frozen=True, eq=False)
class ConsistencyResult:
    """Monte-Carlo consistency study: one :class:`EstimatorConsistency` per estimator."""

    config: ConsistencyConfig
    estimators: dict[str, EstimatorConsistency]
    wall_time_s: float = 0.0

    @property
    def n_loops(self) -> int:
        """Whole repetitions of the route (at least 1): the stretches of :meth:`table`."""
        return max(round(self.config.loops), 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``anees_per_loop``: each estimator's ANEES over each loop)."""
        sim = self.config.linesim
        return {
            "world": self.config.world,
            "loops": self.config.loops,
            "n_runs": self.config.n_runs,
            "seed": self.config.seed,
            "probability": self.config.probability,
            "wall_time_s": self.wall_time_s,
            "linesim": {
                "sigma_range_m": sim.sigma_range_m,
                "point_spacing_m": sim.point_spacing_m,
                "max_range_m": sim.max_range_m,
                "odometry": asdict(sim.odometry),
            },
            "estimators": {
                k: {
                    **v.to_dict(),
                    "anees_per_loop": v.anees_per_segment(self.n_loops).tolist(),
                    "anees_heading_per_loop": v.anees_heading_per_segment(self.n_loops).tolist(),
                }
                for k, v in self.estimators.items()
            },
        }

    def table(self) -> str:
        """A plain-text table of the summary."""
        lo, hi = next(iter(self.estimators.values())).bounds
        lines = [
            f"Monte-Carlo consistency: world {self.config.world} x{self.config.loops:g}, "
            f"{self.config.n_runs} runs, pose NEES (3 dof), "
            f"{100 * self.config.probability:.0f}% bounds [{lo:.2f}, {hi:.2f}]; "
            "median = median over runs of each run's mean NEES",
            f"{'estimator':<12} {'ANEES':>7} {'median':>7} {'inside':>7} {'above':>7} "
            f"{'RMSE m':>8} {'time s':>7} {'landmarks':>9}",
        ]
        for est in self.estimators.values():
            lines.append(
                f"{est.name:<12} {est.mean_anees:>7.2f} "
                f"{float(np.nanmedian(est.run_mean_nees)):>7.2f} {est.fraction_inside:>7.2f} "
                f"{est.fraction_above:>7.2f} {np.mean(est.pos_rmse_m):>8.4f} "
                f"{np.mean(est.runtime_s):>7.2f} {np.mean(est.landmarks):>9.1f}"
            )
        hlo, hhi = next(iter(self.estimators.values())).heading_bounds
        lines.append(f"heading part (1 dof), bounds [{hlo:.2f}, {hhi:.2f}]:")
        for est in self.estimators.values():
            lines.append(f"{est.name:<12} {est.mean_anees_heading:>7.2f}")
        if self.n_loops >= 2:
            lines.append(f"ANEES per loop ({self.n_loops} loops), then its heading part:")
            for est in self.estimators.values():
                per = " ".join(f"{v:.2f}" for v in est.anees_per_segment(self.n_loops))
                lines.append(f"{est.name:<12} {per}")
            for est in self.estimators.values():
                per = " ".join(f"{v:.2f}" for v in est.anees_heading_per_segment(self.n_loops))
                lines.append(f"{est.name:<12} {per}")
        return "\n".join(lines)


def _segment_means(series: FloatArray, n_segments: int) -> FloatArray:
    """Mean of the finite values of ``series`` over each of ``n_segments`` equal stretches."""
    edges = np.linspace(0, series.shape[0], max(n_segments, 1) + 1).round().astype(int)
    out = []
    for a, b in itertools.pairwise(edges):
        part = series[a:b]
        ok = np.isfinite(part)
        out.append(float(np.mean(part[ok])) if np.any(ok) else float("nan"))
    return np.array(out)


def _nanmean_rows(a: FloatArray) -> FloatArray:
    """Column means ignoring nan; nan where a column has no finite value (no warning)."""
    ok = np.isfinite(a)
    count = ok.sum(axis=0)
    total = np.where(ok, a, 0.0).sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def run_consistency(
    config: ConsistencyConfig,
    run_config: RunConfig | None = None,
    workers: int = 1,
    dask_address: str | None = None,
    progress: Any = None,
) -> ConsistencyResult:
    """Run the study serially, on a local process pool, or on a Dask cluster (same numbers).

    Parameters
    ----------
    config : ConsistencyConfig
    run_config : RunConfig, optional
        Estimator settings (``ekf`` etc.); its odometry noise is replaced by the simulator's.
    workers : int
        Local worker processes (``<= 1``: serial).
    dask_address : str, optional
        A Dask scheduler to run on instead.
    progress : callable, optional
        ``progress(done, total)``.
    """
    rc = run_config or RunConfig()
    tasks = [
        ConsistencyTask(i, task_seed(config.seed, i), config, rc) for i in range(config.n_runs)
    ]
    t0 = time.perf_counter()
    outputs = map_tasks(consistency_task, tasks, workers, dask_address, progress)
    wall = time.perf_counter() - t0
    lo, hi = nees_bounds(3, config.n_runs, config.probability)
    summary: dict[str, EstimatorConsistency] = {}
    for name in config.estimators:
        nees = np.array([o[name]["nees"] for o in outputs])
        pos = np.array([o[name]["pos_err_m"] for o in outputs])
        anees = _nanmean_rows(nees)
        defined = np.isfinite(anees)
        inside = (
            float(np.mean((anees[defined] > lo) & (anees[defined] < hi)))
            if np.any(defined)
            else float("nan")
        )
        summary[name] = EstimatorConsistency(
            name=name,
            nees=nees,
            anees=anees,
            bounds=(lo, hi),
            fraction_inside=inside,
            pos_err_m=pos,
            pos_rmse_m=np.sqrt(np.nanmean(pos**2, axis=1)),
            runtime_s=np.array([o[name]["runtime_s"] for o in outputs]),
            landmarks=np.array([o[name]["landmarks"] for o in outputs], dtype=np.int64),
            nees_heading=np.array([o[name]["nees_heading"] for o in outputs]),
            heading_bounds=nees_bounds(1, config.n_runs, config.probability),
        )
    return ConsistencyResult(config, summary, wall)
