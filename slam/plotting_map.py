"""Figures in the style of the paper's Figs. 3-8 (matplotlib; import only where a picture is drawn).

* :func:`plot_points` - raw scan points with the 3σ ellipses of selected points (Eq. 8),
  uncertainty scaled for visibility (the paper scales by 50).
* :func:`plot_lines` - lines (fitted per scan, or merged) with their 3σ uncertainty band across
  the line: at tangent coordinate ``s`` (from the foot of the normal) the lateral standard
  deviation of the line is ``sqrt(P_rr − 2 s P_rα + s² P_αα)``.
* :func:`figure_panels` - the paper's A/B/C layout (points, fitted lines, merged lines).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from numpy.typing import NDArray

__all__ = [
    "band_polygons",
    "figure_panels",
    "nice_scale",
    "plot_lines",
    "plot_points",
    "point_ellipses",
]

FloatArray = NDArray[np.float64]


def point_ellipses(
    centers: FloatArray, covs: FloatArray, n_sigma: float = 3.0, scale: float = 50.0, n: int = 24
) -> FloatArray:
    """Polygons ``(K, n, 2)`` of the ``n_sigma`` ellipses of 2×2 covariances, scaled."""
    vals, vecs = np.linalg.eigh(covs)
    vals = np.clip(vals, 0.0, None)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    circle = np.stack([np.cos(th), np.sin(th)], -1)  # (n, 2)
    axes = vecs * (n_sigma * scale * np.sqrt(vals))[:, None, :]  # (K, 2, 2)
    return np.asarray(centers[:, None, :] + circle @ np.swapaxes(axes, -1, -2))


def band_polygons(
    r_alpha: FloatArray,
    cov_r_alpha: FloatArray,
    segments: Sequence[FloatArray],
    n_sigma: float = 3.0,
    scale: float = 50.0,
    n: int = 12,
) -> list[FloatArray]:
    """Uncertainty bands (one polygon per segment) around lines with ``(r, α)`` covariance."""
    polys: list[FloatArray] = []
    for (r, a), P, segs in zip(r_alpha, cov_r_alpha, segments, strict=True):
        nrm = np.array([np.cos(a), np.sin(a)])
        tan = np.array([-np.sin(a), np.cos(a)])
        for seg in np.asarray(segs).reshape(-1, 2, 2):
            s0, s1 = seg @ tan
            s = np.linspace(s0, s1, n)
            sd = np.sqrt(np.clip(P[0, 0] - 2 * s * P[0, 1] + s**2 * P[1, 1], 0.0, None))
            half = n_sigma * scale * sd
            centre = r * nrm + s[:, None] * tan
            upper = centre + half[:, None] * nrm
            lower = centre - half[:, None] * nrm
            polys.append(np.concatenate([upper, lower[::-1]]))
    return polys


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
        polys = point_ellipses(np.asarray(ellipse_centers), np.asarray(ellipse_covs), scale=scale)
        ax.add_collection(
            PolyCollection(list(polys), facecolor="none", edgecolor="tab:red", linewidth=0.5)
        )
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
        polys = band_polygons(np.asarray(r_alpha), np.asarray(cov_r_alpha), segs, scale=scale)
        ax.add_collection(
            PolyCollection(polys, facecolor=color, alpha=0.25, edgecolor="none", rasterized=True)
        )
    ax.add_collection(LineCollection(list(flat), colors=color, linewidths=0.8))
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
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
