"""Shapes every figure draws the same way: covariance ellipses, line uncertainty bands, segments.

The geometry is numpy (testable without drawing); :func:`add_polygons` and
:func:`add_segments` put it on matplotlib axes as one collection each.

* The ``k``-σ ellipse of a point with 2×2 covariance ``P`` centred on ``c`` is the curve
  ``(x − c)ᵀ P⁻¹ (x − c) = k²``: with ``P = V Λ Vᵀ``, the points ``c + k V Λ^½ (cos t, sin t)``.
* The ``k``-σ band of a line ``(r, α)`` with covariance ``P`` of ``(r, α)`` has, at tangent
  coordinate ``s`` (measured from the foot of the normal along ``(−sin α, cos α)``),
  half-width ``k σ(s)`` across the line, ``σ(s)² = P_rr − 2 s P_rα + s² P_αα``: the standard
  deviation of the line's distance from the fixed point at ``s`` (the paper's R-uncertainty
  with the joint ``(r, α)`` covariance, so the band widens away from the foot of the normal,
  where the uncertainty of α dominates).

Figures magnify uncertainties to make them visible at room scale (the paper multiplies by 50):
a magnification ``m`` of the ``k``-σ shape is the ``(k·m)``-σ shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from numpy.typing import ArrayLike, NDArray

from slam import interrupts

__all__ = [
    "add_polygons",
    "add_segments",
    "band_polygon",
    "band_polygons",
    "ellipse_polygons",
]

FloatArray = NDArray[np.float64]


def ellipse_polygons(
    centres: ArrayLike, covariances: ArrayLike, k: float, n: int = 24
) -> FloatArray:
    """Polygons of the ``k``-σ ellipses of 2×2 covariances.

    Parameters
    ----------
    centres : array_like, shape (m, 2)
        Ellipse centres (m, in the frame of the figure).
    covariances : array_like, shape (m, 2, 2)
        Positive semi-definite covariances (m²) of the centres.
    k : float
        Size in standard deviations (times the figure's magnification).
    n : int
        Vertices per ellipse, evenly spaced in the parameter ``t`` from 0 (not repeated at 2π).

    Returns
    -------
    ndarray, shape (m, n, 2)
        Vertices ``x`` with ``(x − c)ᵀ P⁻¹ (x − c) = k²`` (a degenerate direction of a singular
        ``P`` collapses to the centre).
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    vals, vecs = np.linalg.eigh(np.asarray(covariances, dtype=np.float64).reshape(-1, 2, 2))
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)  # (n, 2)
    axes = vecs * (k * np.sqrt(np.clip(vals, 0.0, None)))[:, None, :]  # columns: semi-axes
    return np.asarray(c[:, None, :] + circle @ np.swapaxes(axes, -1, -2))


def band_polygon(
    r: float,
    alpha: float,
    cov_r_alpha: ArrayLike,
    s_start: float,
    s_end: float,
    k: float,
    n: int = 12,
) -> FloatArray:
    """The ``k``-σ uncertainty band of the piece ``[s_start, s_end]`` of a line ``(r, α)``.

    Parameters
    ----------
    r, alpha : float
        The line ``x cos α + y sin α = r`` (m, rad).
    cov_r_alpha : array_like, shape (2, 2) or larger
        Covariance of ``(r, α)`` (its leading 2×2 block is used).
    s_start, s_end : float
        Extent of the piece along the tangent (m).
    k : float
        Half-width in standard deviations (times the figure's magnification).
    n : int
        Samples along the piece on each side.

    Returns
    -------
    ndarray, shape (2 n, 2)
        The polygon: the side ``+k σ(s)`` along the normal from ``s_start`` to ``s_end``, then
        the side ``−k σ(s)`` back.
    """
    P = np.asarray(cov_r_alpha, dtype=np.float64)
    normal = np.array([np.cos(alpha), np.sin(alpha)])
    tangent = np.array([-np.sin(alpha), np.cos(alpha)])
    s = np.linspace(s_start, s_end, n)
    sd = np.sqrt(np.clip(P[0, 0] - 2.0 * s * P[0, 1] + s**2 * P[1, 1], 0.0, None))
    half = k * sd
    centre = r * normal + s[:, None] * tangent
    upper = centre + half[:, None] * normal
    lower = centre - half[:, None] * normal
    return np.concatenate([upper, lower[::-1]])


def band_polygons(
    r_alpha: ArrayLike,
    cov_r_alpha: ArrayLike,
    segments: Sequence[ArrayLike],
    k: float,
    n: int = 12,
) -> list[FloatArray]:
    """Uncertainty bands of lines, one polygon per visible segment.

    Parameters
    ----------
    r_alpha : array_like, shape (K, 2)
        The lines ``(r, α)`` (m, rad).
    cov_r_alpha : array_like, shape (K, 2, 2)
        Their covariances.
    segments : sequence of array_like, each shape (j, 2, 2)
        End points of each line's visible pieces (m, same frame as the lines).
    k, n
        As in :func:`band_polygon`.
    """
    polys: list[FloatArray] = []
    ra = np.asarray(r_alpha, dtype=np.float64).reshape(-1, 2)
    covs = np.asarray(cov_r_alpha, dtype=np.float64).reshape(-1, 2, 2)
    for q, ((r, a), P, segs) in enumerate(zip(ra, covs, segments, strict=True)):
        if q % 1024 == 0:
            interrupts.check()  # a map of many lines takes seconds (slam.interrupts)
        tangent = np.array([-np.sin(a), np.cos(a)])
        for seg in np.asarray(segs, dtype=np.float64).reshape(-1, 2, 2):
            s0, s1 = seg @ tangent
            polys.append(band_polygon(r, a, P, s0, s1, k, n))
    return polys


def add_polygons(ax: Any, polygons: Sequence[FloatArray] | FloatArray, **style: Any) -> None:
    """Add polygons (ellipses, bands) to ``ax`` as one collection with matplotlib ``style``."""
    ax.add_collection(PolyCollection(list(polygons), **style))


def add_segments(ax: Any, segments: Sequence[FloatArray] | FloatArray, **style: Any) -> None:
    """Add line segments (each ``(2, 2)``: two end points) to ``ax`` as one collection."""
    ax.add_collection(LineCollection(list(segments), **style))
