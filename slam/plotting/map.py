"""Map-building figures in the style of the paper's Figs. 4-8: points, fitted and merged lines.

* :func:`plot_points` - raw scan points with the 3σ ellipses of selected points (Eq. 8),
  uncertainty scaled for visibility (the paper scales by 50).
* :func:`plot_lines` - lines (fitted per scan, or merged) with their 3σ uncertainty band across
  the line (:mod:`slam.plotting.shapes`).
* :func:`figure_panels` - the paper's A/B/C layout (points, fitted lines, merged lines).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam import interrupts
from slam.plotting.figure import plt, save_figure
from slam.plotting.shapes import add_polygons, add_segments, band_polygons, ellipse_polygons

__all__ = ["figure_panels", "nice_scale", "plot_lines", "plot_points"]

FloatArray = NDArray[np.float64]


def plot_points(
    ax: Any,
    points: FloatArray,
    ellipse_centers: FloatArray | None = None,
    ellipse_covs: FloatArray | None = None,
    scale: float = 50.0,
    max_points: int = 200_000,
) -> None:
    """Raw points (world frame) and scaled 3σ ellipses of selected points."""
    pts = np.asarray(points).reshape(-1, 2)
    if pts.shape[0] > max_points:
        pts = pts[:: int(np.ceil(pts.shape[0] / max_points))]
    ax.plot(pts[:, 0], pts[:, 1], ",", color="k", alpha=0.6, rasterized=True)
    if ellipse_centers is not None and ellipse_covs is not None and len(ellipse_centers):
        polys = ellipse_polygons(ellipse_centers, ellipse_covs, 3.0 * scale)
        add_polygons(ax, polys, facecolor="none", edgecolor="tab:red", linewidth=0.5)
    ax.set_aspect("equal")


def plot_lines(
    ax: Any,
    r_alpha: FloatArray,
    cov_r_alpha: FloatArray,
    segments: Sequence[FloatArray],
    scale: float = 50.0,
    color: str = "tab:blue",
    bands: bool = True,
) -> None:
    """Line segments with their scaled 3σ uncertainty bands."""
    segs = [np.asarray(s).reshape(-1, 2, 2) for s in segments]
    flat = np.concatenate(segs) if segs else np.zeros((0, 2, 2))
    if bands and len(segs):
        polys = band_polygons(r_alpha, cov_r_alpha, segs, 3.0 * scale)
        add_polygons(ax, polys, facecolor=color, alpha=0.25, edgecolor="none", rasterized=True)
    add_segments(ax, flat, colors=color, linewidths=0.8)
    if flat.shape[0]:
        lo, hi = flat.reshape(-1, 2).min(axis=0), flat.reshape(-1, 2).max(axis=0)
        pad = 0.03 * max(float(np.max(hi - lo)), 1.0)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")


def nice_scale(target: float) -> float:
    """Largest of 1, 2, 5 × 10^k not above ``target`` (at least 1)."""
    if not np.isfinite(target) or target <= 1.0:
        return 1.0
    k = np.floor(np.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= target:
            return float(m * 10**k)
    return float(10**k)


def figure_panels(
    path: str | Path,
    points: FloatArray,
    ellipse_centers: FloatArray,
    ellipse_covs: FloatArray,
    fit: tuple[FloatArray, FloatArray, Sequence[FloatArray]],
    merged: tuple[FloatArray, FloatArray, Sequence[FloatArray]] | None,
    title: str = "",
    scale: float | None = None,
) -> Path:
    """The paper's panels A (points), B (fitted lines), C (merged lines).

    ``fit`` and ``merged`` are ``(r_alpha (K, 2), cov (K, 2, 2), segments list of (k, 2, 2))``
    in the world frame.  Uncertainties are multiplied by a factor shown in each title (the paper
    uses 50); ``scale=None`` picks, per panel, a round factor that makes the typical 3σ region
    about 1 % of the map's extent (pose uncertainty makes merged lines far wider than fits).
    """
    pts = np.asarray(points).reshape(-1, 2)
    if pts.shape[0]:
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    else:
        lo, hi = np.zeros(2), np.ones(2)
    extent = float(max(np.max(hi - lo), 1.0))

    def auto(sd: FloatArray) -> float:
        if scale is not None:
            return scale
        sd = sd[np.isfinite(sd) & (sd > 0)]
        return nice_scale(0.01 * extent / (3 * float(np.median(sd)))) if sd.size else 1.0

    n_panels = 3 if merged is not None else 2
    wide = (hi[0] - lo[0]) > 2.0 * (hi[1] - lo[1])
    shape = (n_panels, 1) if wide else (1, n_panels)
    size = (11.0, 3.2 * n_panels) if wide else (5.5 * n_panels, 5.5)
    fig, axes = plt.subplots(*shape, figsize=size)
    covs = np.asarray(ellipse_covs).reshape(-1, 2, 2)
    sc = auto(np.sqrt(np.linalg.eigvalsh(covs)[:, -1]) if covs.size else np.zeros(0))
    plot_points(axes[0], pts, ellipse_centers, ellipse_covs, scale=sc)
    axes[0].set_title(f"A: raw points ({len(pts)}), 3σ ×{sc:g}")
    interrupts.check()
    sc = auto(np.sqrt(np.asarray(fit[1]).reshape(-1, 2, 2)[:, 0, 0]))
    plot_lines(axes[1], *fit, scale=sc)
    axes[1].set_title(f"B: fitted lines ({len(fit[0])}), 3σ ×{sc:g}")
    if merged is not None:
        sc = auto(np.sqrt(np.asarray(merged[1]).reshape(-1, 2, 2)[:, 0, 0]))
        plot_lines(axes[2], *merged, scale=sc, color="tab:green")
        axes[2].set_title(f"C: merged lines ({len(merged[0])}), 3σ ×{sc:g}")
    pad = 0.05 * extent
    for ax in axes:
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    if title:
        fig.suptitle(title)
    interrupts.check()
    return save_figure(fig, path, dpi=130)
