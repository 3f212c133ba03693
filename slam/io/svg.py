"""SVG picture of a line map (``map.json``) and, optionally, a trajectory.

Main entry point::

    write_svg(path, map_doc, trajectory_xy=None, *, px_per_m=20.0)

One ``<g id="map">`` group with a ``<line>`` per visible segment (``data-line-id`` = the map
line's id) and, with a trajectory, a ``<polyline id="trajectory">``.  Coordinates are metres of
the map's world frame scaled by ``px_per_m``, y up (the document flips the SVG's y-down axis),
so the picture looks as the map does in the figures.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike

from slam.errors import InputError

__all__ = ["write_svg"]


def write_svg(
    path: str | Path,
    map_doc: Mapping[str, Any],
    trajectory_xy: ArrayLike | None = None,
    *,
    px_per_m: float = 20.0,
    margin_m: float = 1.0,
) -> Path:
    """Write the map's segments (and the trajectory) as an SVG file; returns its path."""
    lines = map_doc.get("lines")
    if not isinstance(lines, list):
        raise InputError("a map object needs a 'lines' list (map.json format)")
    segs: list[tuple[Any, np.ndarray]] = []
    for k, line in enumerate(lines):
        try:
            pieces = np.asarray(line["segments"], dtype=float).reshape(-1, 2, 2)
        except (KeyError, ValueError, TypeError):
            raise InputError(f"line {k}: segments must be [[[x1, y1], [x2, y2]], ...]") from None
        for piece in pieces:
            segs.append((line.get("id", k), piece))
    traj = None if trajectory_xy is None else np.asarray(trajectory_xy, dtype=float)[:, :2]
    pts = [p for _, p in segs] + ([traj] if traj is not None and traj.size else [])
    if not pts:
        raise InputError("nothing to draw: the map has no segments and there is no trajectory")
    allp = np.vstack([p.reshape(-1, 2) for p in pts])
    if not np.isfinite(allp).all():
        raise InputError("coordinates must be finite")
    lo, hi = allp.min(axis=0) - margin_m, allp.max(axis=0) + margin_m
    width, height = (hi - lo) * px_per_m

    def xy(p: np.ndarray) -> tuple[float, float]:
        return (p[0] - lo[0]) * px_per_m, (hi[1] - p[1]) * px_per_m

    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.1f}" height="{height:.1f}" '
        f'viewBox="0 0 {width:.3f} {height:.3f}">',
        f"<title>lineslam map: {len(lines)} lines, {len(segs)} segments, "
        f"{px_per_m:g} px per m</title>",
        '<g id="map" stroke="black" stroke-width="2" stroke-linecap="round">',
    ]
    for line_id, (a, b) in segs:
        (x1, y1), (x2, y2) = xy(a), xy(b)
        out.append(
            f'<line data-line-id={quoteattr(str(line_id))} x1="{x1:.2f}" y1="{y1:.2f}" '
            f'x2="{x2:.2f}" y2="{y2:.2f}"/>'
        )
    out.append("</g>")
    if traj is not None and traj.size:
        coords = " ".join(f"{x:.2f},{y:.2f}" for x, y in (xy(p) for p in traj))
        out.append(
            f'<polyline id="trajectory" fill="none" stroke="#1f77b4" stroke-width="1" '
            f'points="{coords}"/>'
        )
    out.append("</svg>")
    path = Path(path)
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path
