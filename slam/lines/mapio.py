"""``map.json`` (INTERFACES.md): write and read a :class:`~slam.lines.mapbuilder.LineMap`.

Format (world frame)::

    {"frame": "world", "lines": [
      {"id": 3, "r": 4.2, "alpha": 1.57, "cov": [[PRR, PRa], [PaR, Paa]],
       "segments": [[[x1, y1], [x2, y2]], ...], "n_observations": 12,
       "s": 0.3, "cov_ras": [[...3×3...]], "segments_var": [[v1, v2], ...]}]}

``cov`` is the 2×2 marginal covariance of ``(r, alpha)``.  ``s``, ``cov_ras`` (covariance of
``(r, alpha, s)``) and ``segments_var`` are lineslam extensions; a reader that does not know
them ignores them, and :func:`read_map_json` accepts files without them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from slam.errors import InputError
from slam.lines.checks import check_covariance
from slam.lines.mapbuilder import LineMap, MapLine

__all__ = ["line_map_from_json_dict", "line_map_to_json_dict", "read_map_json", "write_map_json"]


def _finite_list(a: np.ndarray) -> Any:
    return [_finite_list(x) for x in a] if np.ndim(a) > 0 else float(a)


def line_map_to_json_dict(line_map: LineMap) -> dict[str, Any]:
    """The ``map.json`` document of ``line_map`` as a ``dict``."""
    lines = []
    for ln in line_map.lines:
        lines.append(
            {
                "id": int(ln.id),
                "r": float(ln.r),
                "alpha": float(ln.alpha),
                "cov": _finite_list(ln.cov_r_alpha),
                "segments": _finite_list(ln.segments),
                "n_observations": int(ln.n_observations),
                "s": float(ln.s),
                "cov_ras": _finite_list(ln.cov),
                "segments_var": _finite_list(ln.segments_var),
            }
        )
    return {"frame": line_map.frame, "lines": lines}


def write_map_json(path: str | Path, line_map: LineMap) -> Path:
    """Write ``line_map`` to ``path`` (``map.json``); returns the path."""
    path = Path(path)
    path.write_text(json.dumps(line_map_to_json_dict(line_map), indent=1) + "\n", "utf-8")
    return path


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def line_map_from_json_dict(doc: Any, source: str = "map.json") -> LineMap:
    """Build a :class:`LineMap` from a parsed ``map.json`` document (validated)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("lines"), list):
        raise InputError('not a line map: expected {"frame": ..., "lines": [...]}', source)
    frame = doc.get("frame", "world")
    if not isinstance(frame, str):
        raise InputError(f"frame must be a string, got {frame!r}", source)
    out = []
    for k, item in enumerate(doc["lines"]):
        where = f"{source}: lines[{k}]"
        if not isinstance(item, dict):
            raise InputError(f"{where}: expected an object")
        try:
            r = _number(item["r"], f"{where}.r")
            alpha = _number(item["alpha"], f"{where}.alpha")
            cov2 = np.asarray(item["cov"], dtype=float)
            segs = np.asarray(item["segments"], dtype=float)
            n_obs = item.get("n_observations", 1)
            line_id = item["id"]
        except KeyError as exc:
            raise InputError(f"{where}: missing field {exc.args[0]!r}") from exc
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: malformed numbers ({exc})") from exc
        if isinstance(line_id, bool) or not isinstance(line_id, int):
            raise InputError(f"{where}.id: expected an integer, got {line_id!r}")
        if isinstance(n_obs, bool) or not isinstance(n_obs, int) or n_obs < 1:
            raise InputError(f"{where}.n_observations: expected a positive integer")
        cov2 = check_covariance(cov2, 2, f"{where}.cov")
        if segs.ndim != 3 or segs.shape[1:] != (2, 2) or not np.isfinite(segs).all():
            raise InputError(f"{where}.segments: expected [[[x1, y1], [x2, y2]], ...]")
        if "cov_ras" in item:
            cov = check_covariance(np.asarray(item["cov_ras"], dtype=float), 3, f"{where}.cov_ras")
        else:
            cov = np.zeros((3, 3))
            cov[:2, :2] = cov2
        s = float(item["s"]) if "s" in item else 0.0
        var = np.asarray(item.get("segments_var", np.zeros((segs.shape[0], 2))), dtype=float)
        if var.shape != (segs.shape[0], 2):
            raise InputError(f"{where}.segments_var: expected one pair per segment")
        out.append(MapLine(line_id, r, alpha, s, cov, segs, var, n_obs))
    return LineMap(tuple(out), frame)


def read_map_json(path: str | Path) -> LineMap:
    """Read a ``map.json`` file.

    Raises
    ------
    InputError
        Not a file, not JSON, or not a line map (the message names the file and the line).
    """
    path = Path(path)
    try:
        text = path.read_text("utf-8")
    except FileNotFoundError as exc:
        raise InputError("no such file", str(path)) from exc
    except (UnicodeDecodeError, IsADirectoryError) as exc:
        raise InputError("not a text file", str(path)) from exc
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON ({exc.msg})", str(path), exc.lineno) from exc
    return line_map_from_json_dict(doc, str(path))
