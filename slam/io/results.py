"""Results folders (INTERFACES.md): ``trajectory.tum``, ``summary.json``, ``metrics.json``.

Main entry points::

    write_results(out_dir, timestamps, poses, summary, *, frame="laser", covariances=None)
    write_trajectory(out_dir, timestamps, poses, covariances=None) -> Path
    write_summary(out_dir, summary) -> Path
    read_results(out_dir) -> Results       # .trajectory, .summary, .frame, .covariances
    write_metrics(out_dir, metrics) -> Path
    to_jsonable(value)                     # what JSON can hold (NaN -> null)

Files
-----
``trajectory.tum``
    one pose per scan (:mod:`slam.io.tum`), time stamps as in the log.
``summary.json``
    the producer's summary; ``"frame"`` (``"laser"`` unless stated) says which frame the
    poses are of.
``trajectory_covariance.txt`` (optional, an extension of INTERFACES.md)
    ``timestamp c_xx c_xy c_xθ c_yy c_yθ c_θθ`` per pose: the upper triangle of the pose's
    marginal covariance in the right-perturbation tangent space ``(v_x, v_y, ω)`` of
    :mod:`slam.geometry` (GTSAM's ``Pose2`` marginals).  Used for NEES when ground truth
    exists.
``metrics.json``
    written by ``lineslam evaluate``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError, LogFormatError
from slam.io._table import read_numeric_table
from slam.io.atomic import write_text_atomic
from slam.io.trajectory import Trajectory
from slam.io.tum import read_tum, write_tum

__all__ = [
    "COVARIANCE_FILE",
    "METRICS_FILE",
    "RELATION_ERRORS_FILE",
    "SUMMARY_FILE",
    "TRAJECTORY_FILE",
    "Results",
    "read_covariances",
    "read_results",
    "to_jsonable",
    "write_covariances",
    "write_metrics",
    "write_relation_errors",
    "write_results",
    "write_summary",
    "write_trajectory",
]

TRAJECTORY_FILE = "trajectory.tum"
SUMMARY_FILE = "summary.json"
COVARIANCE_FILE = "trajectory_covariance.txt"
METRICS_FILE = "metrics.json"
RELATION_ERRORS_FILE = "relation_errors.csv"

FloatArray = NDArray[np.float64]
_UPPER = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))


@dataclass(frozen=True, eq=False)
class Results:
    """A results folder read back.

    Attributes
    ----------
    directory : Path
    trajectory : Trajectory
    summary : dict
        ``summary.json`` (empty if the folder has none).
    frame : str
        ``summary["frame"]``, default ``"laser"``.
    covariances : ndarray, shape (n, 3, 3) or None
        Pose covariances aligned with ``trajectory`` (``None`` if the folder has none).
    """

    directory: Path
    trajectory: Trajectory
    summary: dict[str, Any]
    frame: str
    covariances: FloatArray | None


def to_jsonable(value: Any) -> Any:
    """Numpy scalars/arrays → Python; NaN/inf → ``None`` (JSON has no NaN)."""
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def write_covariances(path: str | Path, timestamps: ArrayLike, covariances: ArrayLike) -> None:
    """Write ``trajectory_covariance.txt`` (upper triangles, see the module docstring)."""
    t = np.asarray(timestamps, dtype=np.float64)
    c = np.asarray(covariances, dtype=np.float64)
    if c.shape != (t.shape[0], 3, 3):
        raise InputError(f"covariances must have shape ({t.shape[0]}, 3, 3), got {c.shape}")
    if not np.isfinite(c).all():
        raise InputError("covariances contain NaN or infinite values")
    if not np.allclose(c, np.swapaxes(c, 1, 2), rtol=1e-9, atol=1e-15):
        raise InputError("covariances must be symmetric")
    table = np.column_stack([t, c[:, _UPPER[0], _UPPER[1]]])
    header = "timestamp c_xx c_xy c_xtheta c_yy c_ytheta c_thetatheta (tangent space, right)"
    np.savetxt(path, table, fmt=["%.6f"] + ["%.9e"] * 6, header=header, comments="# ")


def read_covariances(path: str | Path) -> tuple[FloatArray, FloatArray]:
    """Read ``trajectory_covariance.txt``: ``(timestamps (n,), covariances (n, 3, 3))``."""
    values, _ = read_numeric_table(path, 7, "pose covariance (timestamp + 6 entries)")
    c = np.zeros((values.shape[0], 3, 3))
    c[:, _UPPER[0], _UPPER[1]] = values[:, 1:]
    c[:, _UPPER[1], _UPPER[0]] = values[:, 1:]
    return values[:, 0].copy(), c


def write_trajectory(
    out_dir: str | Path,
    timestamps: ArrayLike,
    poses: ArrayLike,
    covariances: ArrayLike | None = None,
) -> Path:
    """Write ``trajectory.tum`` and, with ``covariances``, ``trajectory_covariance.txt``.

    Returns the folder (created if needed).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_tum(out / TRAJECTORY_FILE, timestamps, poses)
    if covariances is not None:
        write_covariances(out / COVARIANCE_FILE, timestamps, covariances)
    return out


def write_summary(out_dir: str | Path, summary: Mapping[str, Any]) -> Path:
    """Write ``summary.json`` (:func:`to_jsonable`, one-space indent); returns its path."""
    path = Path(out_dir) / SUMMARY_FILE
    path.write_text(json.dumps(to_jsonable(summary), indent=1) + "\n", "utf-8")
    return path


def write_results(
    out_dir: str | Path,
    timestamps: ArrayLike,
    poses: ArrayLike,
    summary: Mapping[str, Any],
    *,
    frame: str = "laser",
    covariances: ArrayLike | None = None,
) -> Path:
    """Write ``trajectory.tum``, ``summary.json`` (with ``"frame"``) and optional covariances.

    Returns the folder (created if needed).
    """
    if frame not in ("laser", "base"):
        raise InputError(f"frame must be 'laser' or 'base', got {frame!r}")
    out = write_trajectory(out_dir, timestamps, poses, covariances)
    write_summary(out, {**dict(summary), "frame": frame})
    return out


def read_results(out_dir: str | Path) -> Results:
    """Read a results folder (``trajectory.tum`` required; the rest optional)."""
    out = Path(out_dir)
    if not out.is_dir():
        raise InputError("not a results folder (no such directory)", str(out))
    tum = out / TRAJECTORY_FILE
    if not tum.is_file():
        raise InputError(f"no {TRAJECTORY_FILE} in the results folder", str(out))
    trajectory = read_tum(tum)
    summary: dict[str, Any] = {}
    if (out / SUMMARY_FILE).is_file():
        try:
            summary = json.loads((out / SUMMARY_FILE).read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise LogFormatError(f"not valid JSON ({exc})", str(out / SUMMARY_FILE)) from None
        if not isinstance(summary, dict):
            raise LogFormatError("summary must be a JSON object", str(out / SUMMARY_FILE))
    covariances = None
    if (out / COVARIANCE_FILE).is_file():
        stamps, covariances = read_covariances(out / COVARIANCE_FILE)
        if stamps.shape != trajectory.timestamps.shape or not np.allclose(
            stamps, trajectory.timestamps, rtol=0.0, atol=1e-6
        ):
            raise LogFormatError(
                f"time stamps differ from those of {TRAJECTORY_FILE}", str(out / COVARIANCE_FILE)
            )
    frame = str(summary.get("frame", "laser"))
    return Results(out, trajectory, summary, frame, covariances)


def write_relation_errors(out_dir: str | Path, columns: Mapping[str, NDArray[Any]]) -> Path:
    """Write ``relation_errors.csv`` into ``out_dir`` (a header line, one row per relation).

    ``columns``: equal-length arrays by column name, written in the given order with 9
    significant digits (time stamps with 6 decimals); NaN as ``nan``.  Replaced whole or not
    at all, as ``metrics.json``.
    """
    names = list(columns)
    data = [np.asarray(columns[n], dtype=float) for n in names]
    n_rows = {d.shape for d in data}
    if len(n_rows) != 1 or len(next(iter(n_rows))) != 1:
        raise ValueError(f"columns of different lengths or not 1-D: {sorted(n_rows)}")
    fmt = ["%.6f" if n.endswith("_s") else "%.9g" for n in names]
    lines = [",".join(names)]
    for row in zip(*data, strict=True):
        lines.append(",".join(f % v for f, v in zip(fmt, row, strict=True)))
    path = Path(out_dir) / RELATION_ERRORS_FILE
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def write_metrics(out_dir: str | Path, metrics: Mapping[str, Any]) -> Path:
    """Write ``metrics.json`` into ``out_dir``; returns its path.

    Written through a temporary file and a rename: an earlier ``metrics.json`` is replaced
    whole or not at all.
    """
    path = Path(out_dir) / METRICS_FILE
    write_text_atomic(path, json.dumps(to_jsonable(metrics), indent=2) + "\n")
    return path
