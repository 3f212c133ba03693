"""g2o export (and read-back) of a planar pose graph: ``VERTEX_SE2`` and ``EDGE_SE2`` lines.

Main entry points::

    graph = odometry_pose_graph(poses, information)   # consecutive odometry edges
    write_g2o(path, graph, fix_first=True)            # readable by g2o and gtsam.readG2o
    read_g2o(path) -> PoseGraph2D

Format (g2o's ``types_slam2d``)::

    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33
    FIX id

An edge measures ``pose_i⁻¹ · pose_j`` (pose ``j`` in the frame of pose ``i``); its information
matrix (upper triangle, row by row) is in the tangent space ``(x, y, θ)`` of the measurement,
which is also GTSAM's ``Pose2`` tangent order.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError, LogFormatError
from slam.geometry import pose_between
from slam.io._text import iter_text_lines

__all__ = ["PoseGraph2D", "odometry_pose_graph", "read_g2o", "write_g2o"]

FloatArray = NDArray[np.float64]
_UPPER = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))


@dataclass(frozen=True, eq=False)
class PoseGraph2D:
    """Vertices (poses) and relative-pose edges.

    Attributes
    ----------
    vertex_ids : ndarray of int, shape (n,)
    poses : ndarray, shape (n, 3)
        ``pose_world_vertex`` (m, m, rad).
    edges : ndarray of int, shape (m, 2)
        ``(i, j)`` vertex ids.
    measurements : ndarray, shape (m, 3)
        ``pose_i⁻¹ · pose_j`` measured.
    information : ndarray, shape (m, 3, 3)
        Symmetric positive-definite information matrices.
    fixed : tuple of int
        Ids held fixed (``FIX`` lines).
    """

    vertex_ids: NDArray[np.int64]
    poses: FloatArray
    edges: NDArray[np.int64]
    measurements: FloatArray
    information: FloatArray
    fixed: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        n, m = self.vertex_ids.shape[0], self.edges.shape[0]
        if self.poses.shape != (n, 3):
            raise InputError(f"poses must have shape ({n}, 3), got {self.poses.shape}")
        if self.edges.shape != (m, 2) or self.measurements.shape != (m, 3):
            raise InputError("edges must be (m, 2) and measurements (m, 3)")
        if self.information.shape != (m, 3, 3):
            raise InputError(f"information must be (m, 3, 3), got {self.information.shape}")
        if not (np.isfinite(self.poses).all() and np.isfinite(self.measurements).all()):
            raise InputError("pose graph contains NaN or infinite values")
        if not np.allclose(self.information, np.swapaxes(self.information, 1, 2)):
            raise InputError("information matrices must be symmetric")
        known = set(self.vertex_ids.tolist())
        if len(known) != n:
            raise InputError("vertex ids must be unique")
        if m and not set(np.unique(self.edges).tolist()) <= known:
            raise InputError("an edge refers to a vertex id that is not in the graph")


def odometry_pose_graph(
    poses: ArrayLike, information: ArrayLike, vertex_ids: ArrayLike | None = None
) -> PoseGraph2D:
    """A chain of odometry edges ``pose_k⁻¹ · pose_{k+1}`` between consecutive poses.

    Parameters
    ----------
    poses : array_like, shape (n, 3)
        Odometry poses in file order.
    information : array_like, shape (3, 3) or (n − 1, 3, 3)
        Information of every edge (one matrix for all, or one per edge).
    vertex_ids : array_like of int, shape (n,), optional
        Default ``0..n−1``.
    """
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise InputError(f"poses must have shape (n, 3), got {p.shape}")
    n = p.shape[0]
    ids = np.arange(n) if vertex_ids is None else np.asarray(vertex_ids, dtype=np.int64)
    info = np.broadcast_to(np.asarray(information, dtype=np.float64), (n - 1, 3, 3)).copy()
    return PoseGraph2D(
        vertex_ids=ids.astype(np.int64),
        poses=p,
        edges=np.column_stack([ids[:-1], ids[1:]]).astype(np.int64),
        measurements=pose_between(p[:-1], p[1:]),
        information=info,
        fixed=(int(ids[0]),),
    )


def write_g2o(path: str | Path, graph: PoseGraph2D, *, fix_first: bool = True) -> None:
    """Write ``graph`` as a g2o file (vertices, edges, then ``FIX`` lines)."""
    fixed = set(graph.fixed)
    if fix_first and graph.vertex_ids.size:
        fixed.add(int(graph.vertex_ids[0]))
    with Path(path).open("w", encoding="utf-8") as handle:
        vertices = np.column_stack([graph.vertex_ids, graph.poses])
        np.savetxt(handle, vertices, fmt=["VERTEX_SE2 %d", "%.9f", "%.9f", "%.9f"], delimiter=" ")
        if graph.edges.shape[0]:
            upper = graph.information[:, _UPPER[0], _UPPER[1]]
            table = np.column_stack([graph.edges, graph.measurements, upper])
            fmt = ["EDGE_SE2 %d", "%d"] + ["%.9f"] * 3 + ["%.9g"] * 6
            np.savetxt(handle, table, fmt=fmt, delimiter=" ")
        for vertex in sorted(fixed):
            handle.write(f"FIX {vertex}\n")


def read_g2o(path: str | Path) -> PoseGraph2D:
    """Read ``VERTEX_SE2`` / ``EDGE_SE2`` / ``FIX`` lines (others are an error naming the line)."""
    vertices: list[list[str]] = []
    edges: list[list[str]] = []
    fixed: list[int] = []
    where = str(path)
    for line_number, line in iter_text_lines(path):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        kind, n = tokens[0], len(tokens)
        if not ((kind == "VERTEX_SE2" and n == 5) or (kind == "EDGE_SE2" and n == 12)) and not (
            kind == "FIX" and n >= 2
        ):
            raise LogFormatError(
                f"expected VERTEX_SE2 (5 fields), EDGE_SE2 (12) or FIX, got {kind!r} "
                f"with {n} fields",
                where,
                line_number,
            )
        n_ids = {"VERTEX_SE2": 1, "EDGE_SE2": 2}.get(kind, n - 1)
        try:
            ids = [int(t) for t in tokens[1 : 1 + n_ids]]
            np.array(tokens[1 + n_ids :], dtype=np.float64)
        except ValueError:
            raise LogFormatError(f"{kind}: a field is not a number", where, line_number) from None
        if kind == "VERTEX_SE2":
            vertices.append(tokens[1:])
        elif kind == "EDGE_SE2":
            edges.append(tokens[1:])
        else:
            fixed.extend(ids)
    if not vertices:
        raise LogFormatError("no VERTEX_SE2 lines", where)
    v = np.array(vertices, dtype=np.float64)
    e = np.array(edges, dtype=np.float64).reshape(-1, 11)
    information = np.zeros((e.shape[0], 3, 3))
    information[:, _UPPER[0], _UPPER[1]] = e[:, 5:]
    information[:, _UPPER[1], _UPPER[0]] = e[:, 5:]
    try:
        return PoseGraph2D(
            vertex_ids=v[:, 0].astype(np.int64),
            poses=v[:, 1:],
            edges=e[:, :2].astype(np.int64),
            measurements=e[:, 2:5],
            information=information,
            fixed=tuple(fixed),
        )
    except InputError as exc:
        raise LogFormatError(exc.reason, where) from None
