"""Figures of the comparison and consistency experiments (matplotlib, imported only to draw).

Every function writes one PNG and returns its path; none of them shows a window (Agg backend).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.plotting.figure import plt, save_figure

__all__ = [
    "plot_errors_over_time",
    "plot_nees_over_time",
    "plot_runtime_per_scan",
    "plot_trajectories",
]

FloatArray = NDArray[np.float64]


def _finish_log_scale(
    fig: Any, ax: Any, path: str | Path, xlabel: str, ylabel: str, title: str, legend_loc: str
) -> Path:
    """Log-scale ordinate, labels, legend and grid of a curves-over-scans figure; save it."""
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc=legend_loc, fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    return save_figure(fig, path, dpi=120)


def plot_nees_over_time(
    anees: Mapping[str, FloatArray],
    bounds: tuple[float, float],
    path: str | Path,
    dof: int = 3,
    title: str = "",
    n_runs: int | None = None,
    segments: int = 1,
    ylabel: str = "average pose NEES",
) -> Path:
    """Average pose NEES over time per estimator with the χ² band of a consistent estimator.

    ``dof`` is the dimension of the error (3 for the pose; 1 for its heading part, with
    ``ylabel`` saying so).

    With ``segments > 1`` (the loops of a long run) each curve is drawn thin and its mean over
    each of ``segments`` equal stretches is drawn over it as a thick step, with the stretches'
    boundaries marked: growth over the run shows as rising steps.
    """
    fig, ax = plt.subplots(figsize=(8, 4.2))
    n = max(v.shape[0] for v in anees.values())
    edges = np.linspace(0, n, max(segments, 1) + 1).round().astype(int)
    for name, values in anees.items():
        if segments <= 1:
            ax.plot(np.arange(values.shape[0]), values, lw=1.2, label=name)
            continue
        (line,) = ax.plot(np.arange(values.shape[0]), values, lw=0.6, alpha=0.45)
        means = []
        for a, b in itertools.pairwise(edges):
            part = values[a:b]
            ok = np.isfinite(part)
            means.append(float(np.mean(part[ok])) if np.any(ok) else np.nan)
        ax.stairs(
            means, edges, baseline=None, color=line.get_color(), lw=2.2, zorder=3,
            label=f"{name} (mean per loop)",
        )  # fmt: skip
    if segments > 1:
        for e in edges[1:-1]:
            ax.axvline(e, color="0.6", lw=0.6, ls=":")
    lo, hi = bounds
    ax.fill_between([0, n - 1], lo, hi, color="0.85", label=f"95% bounds ({dof} dof)")
    ax.axhline(dof, color="0.4", lw=0.8, ls="--")
    ax.set_ylim(*nees_axis_limits(anees, bounds))
    runs = f", {n_runs} runs" if n_runs else ""
    title = title or f"Pose NEES over time{runs}"
    return _finish_log_scale(fig, ax, path, "scan", ylabel, title, "upper left")


def nees_axis_limits(
    anees: Mapping[str, FloatArray], bounds: tuple[float, float]
) -> tuple[float, float]:
    """Log-axis range of :func:`plot_nees_over_time`: the band and the bulk of the curves.

    The first pose's NEES (the gauge: its covariance is the prior's, its error ~0) and other
    values below the curves' 1st percentile do not stretch the axis down by 30 decades.
    """
    values = np.concatenate([np.asarray(v, dtype=float)[1:] for v in anees.values()])
    values = values[np.isfinite(values) & (values > 0.0)]
    lo, hi = bounds
    if values.size == 0:
        return lo / 2.0, hi * 2.0
    return min(lo, float(np.percentile(values, 1.0))) / 2.0, max(hi, float(values.max())) * 2.0


def plot_trajectories(
    trajectories: Mapping[str, FloatArray],
    path: str | Path,
    segments: Sequence[FloatArray] | None = None,
    truth: FloatArray | None = None,
    title: str = "Trajectories over the map",
) -> Path:
    """Trajectories (N, 3) over map segments (each (k, 2, 2), world frame)."""
    fig, ax = plt.subplots(figsize=(7, 7))
    if segments:
        segs = np.concatenate([np.asarray(s).reshape(-1, 2, 2) for s in segments], axis=0)
        # one line artist per wall (not a collection): the legend's "best" place avoids them
        for (x1, y1), (x2, y2) in segs:
            ax.plot([x1, x2], [y1, y2], color="0.2", lw=1.0)
    if truth is not None:
        ax.plot(truth[:, 0], truth[:, 1], color="k", lw=1.5, ls="--", label="ground truth")
    for name, traj in trajectories.items():
        ax.plot(traj[:, 0], traj[:, 1], lw=1.0, label=name)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    return save_figure(fig, path, dpi=120)


def plot_errors_over_time(
    errors: Mapping[str, FloatArray],
    path: str | Path,
    ylabel: str = "position error (m)",
    title: str = "Error over time",
    x: Mapping[str, FloatArray] | None = None,
    xlabel: str = "scan",
) -> Path:
    """One error curve per estimator (log scale), against scan index or given abscissae."""
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for name, err in errors.items():
        xs = x[name] if x is not None and name in x else np.arange(err.shape[0])
        ax.plot(xs, err, lw=1.0, label=name)
    return _finish_log_scale(fig, ax, path, xlabel, ylabel, title, "best")


def plot_runtime_per_scan(
    runtimes: Mapping[str, FloatArray],
    path: str | Path,
    map_sizes: Mapping[str, FloatArray] | None = None,
    title: str = "Run time per scan",
) -> Path:
    """Run time per scan (ms, log scale), and the map size on a second axis where given."""
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for name, t in runtimes.items():
        ax.plot(np.arange(t.shape[0]), 1e3 * np.maximum(t, 1e-6), lw=0.6, label=name)
    if map_sizes:
        ax2 = ax.twinx()
        for name, m in map_sizes.items():
            ax2.plot(np.arange(m.shape[0]), m, lw=1.2, ls=":", label=f"{name} landmarks")
        ax2.set_ylabel("landmarks")
        ax2.legend(loc="lower right", fontsize=8)
    return _finish_log_scale(fig, ax, path, "scan", "time per scan (ms)", title, "upper left")
