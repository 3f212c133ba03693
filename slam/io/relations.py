"""Kümmerle et al. relations files: ``t1 t2 x y z roll pitch yaw`` per line.

Main entry points (stable, used across the project)::

    write_relations(path, t1, t2, poses, *, decimals=6, header=True) -> None
    read_relations(path) -> Relations          # .t1, .t2 (m,), .poses (m, 3), .z/.roll/.pitch
    relations_from_trajectory(timestamps, poses, pairs) -> Relations

Each line is the pose at ``t2`` expressed in the frame of the pose at ``t1``:
``pose(t1)⁻¹ · pose(t2)``.  ``#`` lines (a header) are skipped when reading, as the files of the
Freiburg SLAM evaluation site are read by Cartographer's ``ReadRelationsTextFile`` (which does
not accept the header; we do).  Planar relations are written with ``z = roll = pitch = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from linefit.line import wrap_angle
from slam.errors import InputError, LogFormatError
from slam.geometry import pose_between
from slam.io._table import read_numeric_table

__all__ = ["Relations", "read_relations", "relations_from_trajectory", "write_relations"]

FloatArray = NDArray[np.float64]

HEADER = "t1 t2 x y z roll pitch yaw  (pose at t2 in the frame of the pose at t1; m, rad)"


@dataclass(frozen=True, eq=False)
class Relations:
    """Relative-pose ground truth.

    Attributes
    ----------
    t1, t2 : ndarray, shape (m,)
        Time stamps (s) of the two poses.
    poses : ndarray, shape (m, 3)
        ``(x, y, yaw)`` of the pose at ``t2`` in the frame of the pose at ``t1``.
    z, roll, pitch : ndarray, shape (m,)
        The out-of-plane parts (zero in 2D files); kept so that the metric is Cartographer's.
    line_numbers : ndarray, shape (m,)
        Line numbers in the file (0 for relations made in memory).
    """

    t1: FloatArray
    t2: FloatArray
    poses: FloatArray
    z: FloatArray
    roll: FloatArray
    pitch: FloatArray
    line_numbers: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t1.shape[0])

    def subset(self, mask: ArrayLike) -> Relations:
        """The relations where ``mask`` (boolean, shape ``(m,)``) is true, in file order."""
        m = np.asarray(mask, dtype=bool)
        if m.shape != self.t1.shape:
            raise InputError(f"relations mask has shape {m.shape}, expected {self.t1.shape}")
        return Relations(
            self.t1[m],
            self.t2[m],
            self.poses[m],
            self.z[m],
            self.roll[m],
            self.pitch[m],
            self.line_numbers[m],
        )

    @classmethod
    def planar(cls, t1: ArrayLike, t2: ArrayLike, poses: ArrayLike) -> Relations:
        """Planar relations (``z = roll = pitch = 0``) from arrays, validated."""
        a = np.asarray(t1, dtype=np.float64)
        b = np.asarray(t2, dtype=np.float64)
        p = np.asarray(poses, dtype=np.float64)
        if a.ndim != 1 or b.shape != a.shape or p.shape != (a.shape[0], 3):
            raise InputError(
                f"relations need t1 (m,), t2 (m,), poses (m, 3); got {a.shape}, {b.shape}, "
                f"{p.shape}"
            )
        if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(p).all()):
            raise InputError("relations contain NaN or infinite values")
        zeros = np.zeros_like(a)
        return cls(a, b, p, zeros, zeros.copy(), zeros.copy(), np.zeros(a.shape, np.int64))


def write_relations(
    path: str | Path,
    t1: ArrayLike,
    t2: ArrayLike,
    poses: ArrayLike,
    *,
    decimals: int = 6,
    header: bool = True,
) -> None:
    """Write planar relations ``t1 t2 x y 0 0 0 yaw``.

    Parameters
    ----------
    path
        Output file.
    t1, t2 : array_like, shape (m,)
        Time stamps (s) of the first and second pose, written with ``decimals`` digits
        (≥ 6, so CARMEN µs stamps are exact).
    poses : array_like, shape (m, 3)
        ``pose(t1)⁻¹ · pose(t2)`` as ``(x, y, yaw)``; written with 9 decimals.
    header
        Start with a ``#`` line naming the columns.
    """
    if decimals < 6:
        raise InputError(f"decimals must be >= 6 (µs time stamps), got {decimals}")
    rel = Relations.planar(t1, t2, poses)
    m = len(rel)
    yaw = np.asarray(wrap_angle(rel.poses[:, 2]))
    table = np.column_stack(
        [
            rel.t1,
            rel.t2,
            rel.poses[:, 0],
            rel.poses[:, 1],
            np.zeros(m),
            np.zeros(m),
            np.zeros(m),
            yaw,
        ]
    )
    fmt = [f"%.{decimals}f"] * 2 + ["%.9f"] * 6
    with Path(path).open("w", encoding="utf-8") as handle:
        if header:
            handle.write(f"# {HEADER}\n")
        np.savetxt(handle, table, fmt=fmt, delimiter=" ")


def read_relations(path: str | Path) -> Relations:
    """Read a relations file (``#`` header lines allowed); errors name file and line.

    A relation of a time stamp to itself (``t1 == t2``) is an error: it relates a pose to
    itself, which no trajectory can err on and whose covariance is zero.
    """
    values, lines = read_numeric_table(path, 8, "relation (t1 t2 x y z roll pitch yaw)")
    same = values[:, 0] == values[:, 1]
    if same.any():
        i = int(np.flatnonzero(same)[0])
        raise LogFormatError(
            f"relation of a time stamp to itself (t1 = t2 = {float(values[i, 0])!r})",
            str(path),
            int(lines[i]),
        )
    return Relations(
        t1=values[:, 0].copy(),
        t2=values[:, 1].copy(),
        poses=values[:, [2, 3, 7]].copy(),
        z=values[:, 4].copy(),
        roll=values[:, 5].copy(),
        pitch=values[:, 6].copy(),
        line_numbers=lines,
    )


def relations_from_trajectory(
    timestamps: ArrayLike, poses: ArrayLike, pairs: ArrayLike
) -> Relations:
    """Relations ``pose(i)⁻¹ · pose(j)`` of a (ground-truth) trajectory for index pairs.

    Parameters
    ----------
    timestamps : array_like, shape (n,)
    poses : array_like, shape (n, 3)
    pairs : array_like of int, shape (m, 2)
        ``(i, j)`` indices into the trajectory.
    """
    t = np.asarray(timestamps, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    ij = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if p.shape != (t.shape[0], 3):
        raise InputError(f"poses must have shape ({t.shape[0]}, 3), got {p.shape}")
    if ij.size and (ij.min() < 0 or ij.max() >= t.shape[0]):
        raise InputError("relation index out of range of the trajectory")
    return Relations.planar(t[ij[:, 0]], t[ij[:, 1]], pose_between(p[ij[:, 0]], p[ij[:, 1]]))
