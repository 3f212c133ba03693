"""Paper-style figures of one scan and its fitted lines (Pfister et al., Fig. 3).

Left: the raw points with the 3σ ellipses of their Eq. 8 covariances; right: the fitted line
segments with their 3σ uncertainty band across the line.  As in the paper, uncertainties are
drawn magnified (``scale``, default 50) so they are visible at room scale.

The band and the ellipses are those of :mod:`slam.plotting.shapes`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from numpy.typing import NDArray

from linefit import Line, LineFitConfig
from linefit.extract import valid_readings
from linefit.noise import point_covariances
from slam.plotting.figure import plt, save_figure
from slam.plotting.shapes import add_polygons, add_segments, band_polygon, ellipse_polygons

__all__ = ["draw_lines", "draw_points", "save_scan_figure"]

FloatArray = NDArray[np.float64]


def draw_points(
    ax: Axes,
    ranges: FloatArray,
    bearings: FloatArray,
    config: LineFitConfig,
    *,
    max_range_m: float | None = None,
    scale: float = 50.0,
    every: int = 10,
) -> None:
    """Raw points, with the magnified 3σ ellipses of every ``every``-th point."""
    valid = valid_readings(np.asarray(ranges, dtype=float), max_range_m, config)
    d = np.asarray(ranges, dtype=float)[valid]
    phi = np.asarray(bearings, dtype=float)[valid]
    xy = np.stack([d * np.cos(phi), d * np.sin(phi)], axis=1)
    ax.plot(xy[:, 0], xy[:, 1], ".", ms=2, color="k", label="scan points")
    if xy.shape[0] and every > 0:
        sel = np.arange(0, xy.shape[0], every)
        Q = point_covariances(d[sel], phi[sel], config.noise)
        add_polygons(
            ax,
            ellipse_polygons(xy[sel], Q, 3.0 * scale, n=23),
            facecolors="tab:orange",
            edgecolors="tab:red",
            alpha=0.5,
            label=f"3σ ellipses ×{scale:g}",
        )
    ax.plot([0.0], [0.0], "^", color="tab:blue", ms=8, label="sensor")


def draw_lines(ax: Axes, lines: Sequence[Line], *, scale: float = 50.0) -> None:
    """Fitted segments, with their magnified 3σ band across the line."""
    bands = []
    segs = []
    for line in lines:
        for s0, s1 in line.segments_s:
            bands.append(band_polygon(line.r, line.alpha, line.cov, s0, s1, 3.0 * scale, n=16))
            segs.append(line.point_at(np.array([s0, s1])))
    if bands:
        add_polygons(ax, bands, facecolors="tab:cyan", edgecolors="none", alpha=0.5)
        add_segments(ax, segs, colors="tab:blue", linewidths=1.5)
    ax.plot([], [], color="tab:blue", label=f"{len(lines)} fitted lines (3σ band ×{scale:g})")


def save_scan_figure(
    path: str | Path,
    ranges: FloatArray,
    bearings: FloatArray,
    lines: Sequence[Line],
    config: LineFitConfig,
    *,
    max_range_m: float | None = None,
    scale: float = 50.0,
    title: str = "",
) -> Path:
    """Write the two-panel figure (points + ellipses | lines + bands) to ``path`` (PNG/PDF)."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 6), sharex=True, sharey=True)
    draw_points(axes[0], ranges, bearings, config, max_range_m=max_range_m, scale=scale)
    axes[0].set_title("raw points and 3σ covariances")
    draw_points(axes[1], ranges, bearings, config, max_range_m=max_range_m, scale=scale, every=0)
    draw_lines(axes[1], lines, scale=scale)
    axes[1].set_title("fitted lines and 3σ uncertainty across the line")
    for ax in axes:
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("y (m)")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi=110)
