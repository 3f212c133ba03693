"""GeoJSON export of a line map (``map.json`` of INTERFACES.md) for GIS and web viewers.

Main entry points::

    line_map_to_geojson(map_or_lines) -> dict     # a FeatureCollection
    write_geojson(path, map_or_lines) -> None

Input: either the ``map.json`` object ``{"frame": "world", "lines": [...]}`` or its list of
lines, each a mapping with ``id``, ``r``, ``alpha``, ``segments`` (``[[[x1, y1], [x2, y2]],
...]``) and optionally ``cov`` and ``n_observations``.  Each line becomes one Feature with a
``MultiLineString`` geometry (its visible segments) and the line parameters as properties.

Coordinates are metres in the map's own frame, not WGS 84 longitude/latitude: RFC 7946
allows other coordinate reference systems "by prior arrangement", and tools such as QGIS
display such a file in a local (engineering) CRS.  The collection says so in its
``"lineslam"`` member.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from slam.errors import InputError

__all__ = ["line_map_to_geojson", "write_geojson"]


def _lines_of(
    map_or_lines: Mapping[str, Any] | Iterable[Mapping[str, Any]],
) -> tuple[list[Mapping[str, Any]], str]:
    if isinstance(map_or_lines, Mapping):
        lines = map_or_lines.get("lines")
        if lines is None:
            raise InputError("a map object needs a 'lines' list (map.json format)")
        return list(lines), str(map_or_lines.get("frame", "world"))
    return list(map_or_lines), "world"


def _feature(line: Mapping[str, Any], k: int) -> dict[str, Any]:
    name = f"line {line.get('id', k)}"
    for key in ("r", "alpha", "segments"):
        if key not in line:
            raise InputError(f"{name}: missing {key!r}")
    r, alpha = float(line["r"]), float(line["alpha"])
    if not (math.isfinite(r) and math.isfinite(alpha)):
        raise InputError(f"{name}: r and alpha must be finite")
    try:
        segments = np.asarray(line["segments"], dtype=np.float64).reshape(-1, 2, 2)
    except (ValueError, TypeError):
        raise InputError(f"{name}: segments must be [[[x1, y1], [x2, y2]], ...]") from None
    if not np.isfinite(segments).all():
        raise InputError(f"{name}: segment end points must be finite")
    properties: dict[str, Any] = {"id": line.get("id", k), "r": r, "alpha": alpha}
    for key in ("n_observations", "cov"):
        if key in line:
            value = line[key]
            properties[key] = np.asarray(value).tolist() if key == "cov" else value
    return {
        "type": "Feature",
        "id": properties["id"],
        "geometry": {"type": "MultiLineString", "coordinates": segments.tolist()},
        "properties": properties,
    }


def line_map_to_geojson(
    map_or_lines: Mapping[str, Any] | Iterable[Mapping[str, Any]],
) -> dict[str, Any]:
    """A GeoJSON FeatureCollection of the map's lines (see the module docstring)."""
    lines, frame = _lines_of(map_or_lines)
    features = [_feature(line, k) for k, line in enumerate(lines)]
    return {
        "type": "FeatureCollection",
        "features": features,
        "lineslam": {"frame": frame, "units": "m", "crs": "local map frame, not WGS 84"},
    }


def write_geojson(
    path: str | Path, map_or_lines: Mapping[str, Any] | Iterable[Mapping[str, Any]]
) -> None:
    """Write :func:`line_map_to_geojson` to ``path``."""
    Path(path).write_text(json.dumps(line_map_to_geojson(map_or_lines), indent=1) + "\n")
