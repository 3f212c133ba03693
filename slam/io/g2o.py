"""g2o export (and read-back) of a planar pose graph: ``VERTEX_SE2`` and ``EDGE_SE2`` lines.

Main entry points::

    graph = odometry_pose_graph(poses, information)   # consecutive odometry edges
    write_g2o(path, graph, fix_first=True)            # readable by g2o and gtsam.readG2o
    read_g2o(path) -> PoseGraph2D
    write_line_graph_g2o(path, line_graph, result)    # lineslam's whole factor graph
    read_line_graph_g2o(path) -> LineGraphFile        # poses, odometry, lines and line factors

Format (g2o's ``types_slam2d``)::

    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33
    FIX id

An edge measures ``pose_i⁻¹ · pose_j`` (pose ``j`` in the frame of pose ``i``); its information
matrix (upper triangle, row by row) is in the tangent space ``(x, y, θ)`` of the measurement,
which is also GTSAM's ``Pose2`` tangent order.

The whole line-SLAM graph (``graph.g2o`` of ``lineslam slam``)
----------------------------------------------------------------
:func:`write_line_graph_g2o` writes the final factor graph of :class:`slam.line_slam.LineSlam`:

* ``VERTEX_SE2 i x y θ`` — keyframe ``i`` (0-based, in keyframe order), the **laser** pose in
  the world frame as optimised;
* ``EDGE_SE2 i j dx dy dθ I…`` — every odometry factor (``x_i⁻¹ x_j``), information = the
  inverse of the factor's covariance (the motion model's, or the laser odometry's steps'
  composed);
* ``FIX 0`` — the first pose (the prior that fixes the world frame);

all of which ``gtsam.readG2o`` and g2o read as a pose graph, and the extension (lines that
g2o and GTSAM skip as unknown tags)::

    LINESLAM_SCAN i timestamp                   keyframe i is the scan of this log time stamp
    LINESLAM_VERTEX_LINE2D k r alpha            landmark k (ids after the poses), world line
    LINESLAM_EDGE_SE2_LINE2D i k r alpha I_rr I_ralpha I_alphaalpha
    LINESLAM_PRIOR_SE2 i x y theta I11 I12 I13 I22 I23 I33
    LINESLAM_ROBUST_KERNEL name k               kernel on the line factors (none/huber/cauchy)
    LINESLAM_MOTION_NOISE sxy_min sxy_per_m sxy_per_rad sth_min sth_per_m sth_per_rad
    LINESLAM_SCAN_OFFSET i timestamp dx dy dtheta
    LINESLAM_SCAN_OFFSET i timestamp dx dy dtheta C11 C12 C13 C22 C23 C33
    LINESLAM_EDGE_LINE2D_LINK k l x y I11 I12 I22

A ``LINESLAM_EDGE_SE2_LINE2D`` is a line measurement: the line ``(r, α)`` measured in the
laser frame of pose ``i`` (``{p : p·(cos α, sin α) = r}``), predicted from landmark ``k`` by
:func:`slam.geometry` Eq. 30 (:mod:`slam.graph.factors`), with the inverse of its 2×2
covariance (upper triangle).  Only landmarks still in the graph (not fused into another) and
their factors are written; a landmark's id is ``n_poses +`` its index among them.  The file
has no ``#`` comment lines: ``gtsam.readG2o`` (4.2/4.3) stops reading edges at one, and at
some unknown tags (a line whose first fields are not integers), so the extension lines that
are not of that shape come after every ``EDGE_SE2``.

The rest makes the file enough to recompute the run's covariances (``lineslam evaluate``'s
relations NEES, :mod:`slam.graph.relative`): ``LINESLAM_PRIOR_SE2`` is the prior that fixes
the gauge (information in the tangent space of pose ``i``; ``FIX`` says the same to g2o),
``LINESLAM_ROBUST_KERNEL`` the kernel and its width (whitened units) on the line factors, and
every scan that is not a keyframe has a ``LINESLAM_SCAN_OFFSET``: it hangs from keyframe ``i``
with the offset ``(dx, dy, dθ)`` (laser frame of the keyframe), its pose covariance being the
keyframe's moved along the offset plus the noise of the offset.  With six fields the offset is
the odometry's and its noise the motion model's at the offset, ``LINESLAM_MOTION_NOISE`` (σ's
of :class:`slam.models.motion.MotionNoiseConfig`: m, m/√m, m/√rad, rad, rad/√m, rad/√rad);
with twelve it is a scan match's estimate against the keyframe and ``C`` its covariance
``Σ_s`` (upper triangle, row by row; right perturbation of the offset, the motion model's
convention).  A ``LINESLAM_EDGE_LINE2D_LINK`` links landmark ``k`` (a pass along a wall) to
landmark ``l`` (the wall): both are read in the chart anchored at ``(x, y)``
(:mod:`slam.models.anchored`), and their difference ``v_k − v_l`` has that information
(:meth:`slam.graph.problem.LineGraph.add_landmark_links`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError, LogFormatError
from slam.geometry import pose_between
from slam.io._text import iter_text_lines

__all__ = [
    "LineGraphFile",
    "PoseGraph2D",
    "odometry_pose_graph",
    "read_g2o",
    "read_line_graph_g2o",
    "write_g2o",
    "write_line_graph_g2o",
]

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


_LINE_VERTEX = "LINESLAM_VERTEX_LINE2D"
_LINE_EDGE = "LINESLAM_EDGE_SE2_LINE2D"
_SCAN = "LINESLAM_SCAN"
_PRIOR = "LINESLAM_PRIOR_SE2"
_ROBUST = "LINESLAM_ROBUST_KERNEL"
_MOTION = "LINESLAM_MOTION_NOISE"
_OFFSET = "LINESLAM_SCAN_OFFSET"
_LINK = "LINESLAM_EDGE_LINE2D_LINK"
_MOTION_FIELDS = (
    "sigma_xy_min_m",
    "sigma_xy_per_m",
    "sigma_xy_per_rad",
    "sigma_theta_min_rad",
    "sigma_theta_per_m",
    "sigma_theta_per_rad",
)
_KERNELS = ("none", "huber", "cauchy")
_OFFSET_FMT = ("%.6f", "%.9f", "%.9f", "%.9f")


def _is_covariance(cov: FloatArray) -> bool:
    """Whether a 3×3 matrix is finite, symmetric (to rounding) and positive definite."""
    if not np.isfinite(cov).all():
        return False
    scale = float(np.max(np.abs(cov)))
    if not np.allclose(cov, cov.T, rtol=0.0, atol=1e-9 * scale):
        return False
    try:
        np.linalg.cholesky(0.5 * (cov + cov.T))
    except np.linalg.LinAlgError:
        return False
    return True


def _upper(cov: FloatArray) -> FloatArray:
    """Upper triangle, row by row, of the symmetric part of a 3×3 matrix."""
    sym: FloatArray = 0.5 * (cov + cov.T)
    return sym[_UPPER[0], _UPPER[1]]


def _checked_offset_covariances(covs: FloatArray, scans: NDArray[np.intp]) -> FloatArray | None:
    """``covs`` ``(S, 3, 3)`` of the non-keyframe scans ``scans``: all-NaN or SPD rows.

    None when every row is NaN (no scan carries a covariance).
    """
    nan = np.isnan(covs).reshape(-1, 9)
    given = ~nan.all(axis=1)
    for cov, scan in zip(covs[given], scans[given].tolist(), strict=True):
        if not _is_covariance(cov):
            raise InputError(
                f"scan_offset_covariances: row {scan} is neither all NaN nor a symmetric "
                "positive-definite covariance"
            )
    return covs if given.any() else None


def write_line_graph_g2o(
    path: str | Path,
    graph: Any,
    result: Any = None,
    *,
    scan_offsets: ArrayLike | None = None,
    motion_noise: Any = None,
    robust_kernel: tuple[str, float] | None = None,
    scan_offset_covariances: ArrayLike | None = None,
) -> Path:
    """Write a :class:`slam.graph.problem.LineGraph` as g2o with the line extension (module doc).

    Parameters
    ----------
    path
        The ``.g2o`` file.
    graph
        The estimator's graph (``LineSlam.graph``): poses, odometry, line factors, the prior.
    result
        The run's :class:`slam.result.SlamResult`, for the keyframes' time stamps
        (``LINESLAM_SCAN``) and, with ``scan_offsets``, the other scans' keyframes; optional.
    scan_offsets : array_like, shape (N, 3), optional
        Each scan's odometry offset from the keyframe it hangs from (zero for keyframes), in
        the order of ``result``'s scans: ``LINESLAM_SCAN_OFFSET`` lines.
    motion_noise : optional
        The motion model of those offsets (the six σ attributes of
        :class:`slam.models.motion.MotionNoiseConfig`): ``LINESLAM_MOTION_NOISE``.
    robust_kernel : (name, k), optional
        The kernel on the line factors: ``LINESLAM_ROBUST_KERNEL``.
    scan_offset_covariances : array_like, shape (N, 3, 3), optional
        Row by row with ``scan_offsets``: the covariance ``Σ_s`` of a scan's offset when it is
        a scan match's estimate (symmetric positive definite, written after the offset), a
        row of NaN for an odometry offset (whose noise is the motion model's); the rows of
        keyframes are not read.

    Raises
    ------
    InputError
        ``scan_offsets`` or ``scan_offset_covariances`` of the wrong shape, a covariance row
        of a scan that is neither all NaN nor symmetric positive definite, or an unknown
        robust kernel.
    """
    poses = np.asarray(graph.poses, dtype=float)
    n = poses.shape[0]
    stamps: FloatArray | None = None
    offset_rows: FloatArray | None = None
    offset_covs: FloatArray | None = None
    covs: FloatArray | None = None
    if scan_offset_covariances is not None:
        if scan_offsets is None:
            raise InputError("scan_offset_covariances: needs scan_offsets")
        covs = np.asarray(scan_offset_covariances, dtype=float)
        n_scans = np.asarray(scan_offsets, dtype=float).reshape(-1, 3).shape[0]
        if covs.shape != (n_scans, 3, 3):
            raise InputError(
                f"scan_offset_covariances: need shape ({n_scans}, 3, 3), got {covs.shape}"
            )
    if result is not None:
        kf = np.asarray(result.is_keyframe, dtype=bool)
        if int(kf.sum()) == n:
            stamps = np.asarray(result.timestamps, dtype=float)[kf]
            if scan_offsets is not None:
                off = np.asarray(scan_offsets, dtype=float).reshape(-1, 3)
                if off.shape[0] != kf.shape[0]:
                    raise InputError(f"scan_offsets: need {kf.shape[0]} rows, got {off.shape[0]}")
                t = np.asarray(result.timestamps, dtype=float)
                k = np.asarray(result.keyframe_of_scan, dtype=np.int64)
                offset_rows = np.column_stack([k[~kf], t[~kf], off[~kf]])
                if covs is not None:
                    offset_covs = _checked_offset_covariances(covs[~kf], np.flatnonzero(~kf))
    alive = np.flatnonzero(np.asarray(graph.landmark_alive, dtype=bool))
    line_id = np.full(np.asarray(graph.landmark_alive).shape[0], -1, dtype=np.int64)
    line_id[alive] = n + np.arange(alive.shape[0])
    r_alpha = np.asarray(graph.landmarks_r_alpha, dtype=float)[alive]
    first = np.asarray(graph.odometry_first, dtype=np.int64)
    second = np.asarray(graph.odometry_second, dtype=np.int64)
    info = np.linalg.inv(np.asarray(graph.odometry_cov, dtype=float)).reshape(-1, 3, 3)
    info = 0.5 * (info + np.swapaxes(info, 1, 2))
    f_lm = np.asarray(graph.factor_landmark, dtype=np.int64)
    keep = line_id[f_lm] >= 0 if f_lm.size else np.zeros(0, bool)
    f_pose = np.asarray(graph.factor_pose, dtype=np.int64)[keep]
    f_id = line_id[f_lm[keep]]
    z = np.asarray(graph.factor_z, dtype=float)[keep]
    f_info = np.linalg.inv(np.asarray(graph.factor_cov, dtype=float)[keep]).reshape(-1, 2, 2)
    n_links = int(getattr(graph, "n_landmark_links", 0))
    links = np.zeros((0, 7))
    if n_links:
        k_first = np.asarray(graph.link_first, dtype=np.int64)
        k_second = np.asarray(graph.link_second, dtype=np.int64)
        k_info = np.linalg.inv(np.asarray(graph.link_cov, dtype=float)).reshape(-1, 2, 2)
        anchors = np.asarray(graph.anchors, dtype=float)[k_first]
        links = np.column_stack(
            [line_id[k_first], line_id[k_second], anchors, k_info[:, 0, 0], k_info[:, 0, 1],
             k_info[:, 1, 1]]
        )  # fmt: skip
    path = Path(path)
    with path.open("w", encoding="utf-8") as handle:
        if stamps is not None:
            for i, t in enumerate(stamps):
                handle.write(f"{_SCAN} {i} {t:.6f}\n")
        np.savetxt(
            handle,
            np.column_stack([np.arange(n), poses]),
            fmt=["VERTEX_SE2 %d", "%.9f", "%.9f", "%.9f"],
        )
        if r_alpha.shape[0]:
            np.savetxt(
                handle,
                np.column_stack([line_id[alive], r_alpha]),
                fmt=[f"{_LINE_VERTEX} %d", "%.9f", "%.9f"],
            )
        if first.shape[0]:
            measured = np.asarray(graph.odometry_measured, dtype=float)
            table = np.column_stack([first, second, measured, info[:, _UPPER[0], _UPPER[1]]])
            np.savetxt(handle, table, fmt=["EDGE_SE2 %d", "%d"] + ["%.9f"] * 3 + ["%.9g"] * 6)
        if f_pose.shape[0]:
            upper = np.column_stack([f_info[:, 0, 0], f_info[:, 0, 1], f_info[:, 1, 1]])
            table = np.column_stack([f_pose, f_id, z, upper])
            np.savetxt(handle, table, fmt=[f"{_LINE_EDGE} %d", "%d"] + ["%.9f"] * 2 + ["%.9g"] * 3)
        if links.shape[0]:
            np.savetxt(handle, links, fmt=[f"{_LINK} %d", "%d"] + ["%.9f"] * 2 + ["%.9g"] * 3)
        # after every edge: gtsam.readG2o stops reading edges at some unknown lines
        if offset_rows is not None and offset_rows.shape[0]:
            if offset_covs is None:
                np.savetxt(handle, offset_rows, fmt=[f"{_OFFSET} %d", *_OFFSET_FMT])
            else:
                row_fmt = " ".join([f"{_OFFSET} %d", *_OFFSET_FMT])
                for row, cov in zip(offset_rows, offset_covs, strict=True):
                    extra = (
                        ""
                        if np.isnan(cov).all()
                        else " " + " ".join(f"{v:.9e}" for v in _upper(cov))
                    )
                    handle.write(row_fmt % tuple(row) + extra + "\n")
        if robust_kernel is not None:
            name, width = robust_kernel
            if name not in _KERNELS:
                raise InputError(f"robust kernel must be one of {_KERNELS}, got {name!r}")
            handle.write(f"{_ROBUST} {name} {float(width):.17g}\n")
        if motion_noise is not None:
            sigmas = " ".join(f"{float(getattr(motion_noise, f)):.17g}" for f in _MOTION_FIELDS)
            handle.write(f"{_MOTION} {sigmas}\n")
        prior_pose = getattr(graph, "prior_pose", None)
        prior_cov = getattr(graph, "prior_cov", None)
        if n and prior_pose is not None and prior_cov is not None:
            p_info = np.linalg.inv(np.asarray(prior_cov, dtype=float))
            p_info = 0.5 * (p_info + p_info.T)
            values = " ".join(f"{v:.9f}" for v in np.asarray(prior_pose, dtype=float))
            info_text = " ".join(f"{v:.9g}" for v in p_info[_UPPER[0], _UPPER[1]])
            handle.write(f"{_PRIOR} 0 {values} {info_text}\n")
        if n:
            handle.write("FIX 0\n")
    return path


@dataclass(frozen=True, eq=False)
class LineGraphFile:
    """A ``graph.g2o`` read back (:func:`read_line_graph_g2o`).

    Attributes
    ----------
    pose_graph : PoseGraph2D
        Poses and odometry edges.
    line_ids : ndarray of int, shape (M,)
    lines_r_alpha : ndarray, shape (M, 2)
        World lines.
    factor_pose, factor_line : ndarray of int, shape (F,)
    factor_z : ndarray, shape (F, 2)
        Measured ``(r, α)`` in the laser frame of the pose.
    factor_information : ndarray, shape (F, 2, 2)
    timestamps : ndarray, shape (N,) or None
        The keyframes' scan time stamps, if written.
    prior_pose : ndarray, shape (3,) or None
    prior_information : ndarray, shape (3, 3) or None
        The gauge prior on pose 0 (``LINESLAM_PRIOR_SE2``), if written.
    robust_kernel : (str, float) or None
        Kernel name and width on the line factors, if written.
    motion_noise : dict or None
        The six σ of the non-keyframe scans' motion model (``MotionNoiseConfig`` fields).
    offset_timestamps, offset_keyframes, offsets : ndarray or None
        The scans that are not keyframes: time stamp ``(S,)``, keyframe they hang from ``(S,)``
        and offset from it ``(S, 3)``, if written.
    offset_covariances : ndarray, shape (S, 3, 3), or None
        The covariance ``Σ_s`` of each of those offsets that is a scan match's estimate, NaN
        for the odometry offsets (whose noise is ``motion_noise``'s); None when no offsets
        are written.
    line_links : ndarray, shape (K, 7), or None
        Links between two lines (``LINESLAM_EDGE_LINE2D_LINK``, a pass along a wall and the
        wall: :meth:`slam.graph.problem.LineGraph.add_landmark_links`): ids of the two lines,
        the anchor ``(x, y)`` of the chart both share, and the upper triangle of the
        information of their difference in that chart; None when there are none.
    """

    pose_graph: PoseGraph2D
    line_ids: NDArray[np.int64]
    lines_r_alpha: FloatArray
    factor_pose: NDArray[np.int64]
    factor_line: NDArray[np.int64]
    factor_z: FloatArray
    factor_information: FloatArray
    timestamps: FloatArray | None
    prior_pose: FloatArray | None = None
    prior_information: FloatArray | None = None
    robust_kernel: tuple[str, float] | None = None
    motion_noise: dict[str, float] | None = None
    offset_timestamps: FloatArray | None = None
    offset_keyframes: NDArray[np.int64] | None = None
    offsets: FloatArray | None = None
    offset_covariances: FloatArray | None = None
    line_links: FloatArray | None = None


def read_line_graph_g2o(path: str | Path) -> LineGraphFile:
    """Read a file of :func:`write_line_graph_g2o` (the pose graph and the line extension).

    Raises
    ------
    LogFormatError
        A line of the extension with the wrong fields (naming the file and line): among
        them a ``LINESLAM_SCAN_OFFSET`` whose covariance is not positive definite.
    """
    where = str(path)
    plain: list[str] = []
    lines_v: list[list[float]] = []
    lines_e: list[list[float]] = []
    stamps: dict[int, float] = {}
    offsets: list[list[float]] = []
    offset_covs: list[FloatArray] = []
    prior: list[float] | None = None
    robust: tuple[str, float] | None = None
    motion: dict[str, float] | None = None
    links: list[list[float]] = []
    ours = (_LINE_VERTEX, _LINE_EDGE, _SCAN, _PRIOR, _ROBUST, _MOTION, _OFFSET, _LINK)
    for line_number, line in iter_text_lines(path):
        tokens = line.split()
        if not tokens:
            continue
        try:
            if tokens[0] == _LINE_VERTEX and len(tokens) == 4:
                lines_v.append([float(t) for t in tokens[1:]])
            elif tokens[0] == _LINE_EDGE and len(tokens) == 8:
                lines_e.append([float(t) for t in tokens[1:]])
            elif tokens[0] == _LINK and len(tokens) == 8:
                links.append([float(t) for t in tokens[1:]])
                info_k = np.array([[links[-1][4], links[-1][5]], [links[-1][5], links[-1][6]]])
                if not _is_covariance(info_k):
                    raise LogFormatError(
                        f"{_LINK}: the information is not positive definite", where, line_number
                    )
            elif tokens[0] == _SCAN and len(tokens) == 3:
                stamps[int(tokens[1])] = float(tokens[2])
            elif tokens[0] == _OFFSET and len(tokens) in (6, 12):
                offsets.append([float(tokens[2]), int(tokens[1]), *map(float, tokens[3:6])])
                cov = np.full((3, 3), np.nan)
                if len(tokens) == 12:
                    cov[_UPPER[0], _UPPER[1]] = [float(t) for t in tokens[6:]]
                    cov[_UPPER[1], _UPPER[0]] = cov[_UPPER[0], _UPPER[1]]
                    if not _is_covariance(cov):
                        raise LogFormatError(
                            f"{_OFFSET}: the covariance is not positive definite",
                            where,
                            line_number,
                        )
                offset_covs.append(cov)
            elif tokens[0] == _PRIOR and len(tokens) == 11 and int(tokens[1]) == 0:
                prior = [float(t) for t in tokens[2:]]
            elif tokens[0] == _ROBUST and len(tokens) == 3 and tokens[1] in _KERNELS:
                robust = (tokens[1], float(tokens[2]))
            elif tokens[0] == _MOTION and len(tokens) == 7:
                motion = dict(zip(_MOTION_FIELDS, map(float, tokens[1:]), strict=True))
            elif tokens[0] in ours:
                raise ValueError
            else:
                plain.append(line)
        except ValueError:
            raise LogFormatError(f"{tokens[0]}: wrong fields", where, line_number) from None
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".g2o", delete=False) as tmp:
        tmp.writelines(plain)
    try:
        pose_graph = read_g2o(tmp.name)
    finally:
        Path(tmp.name).unlink()
    v = np.asarray(lines_v, dtype=float).reshape(-1, 3)
    e = np.asarray(lines_e, dtype=float).reshape(-1, 7)
    info = np.zeros((e.shape[0], 2, 2))
    info[:, 0, 0], info[:, 0, 1], info[:, 1, 0], info[:, 1, 1] = e[:, 4], e[:, 5], e[:, 5], e[:, 6]
    n = pose_graph.vertex_ids.shape[0]
    timestamps = np.array([stamps[i] for i in range(n)]) if stamps and len(stamps) == n else None
    prior_pose = prior_info = None
    if prior is not None:
        prior_pose = np.array(prior[:3])
        prior_info = np.zeros((3, 3))
        prior_info[_UPPER[0], _UPPER[1]] = prior[3:]
        prior_info[_UPPER[1], _UPPER[0]] = prior[3:]
    off = np.asarray(offsets, dtype=float).reshape(-1, 5)
    written = bool(offsets) or motion is not None  # a file of this writer: every scan stated
    if off.shape[0] and (off[:, 1].min() < 0 or off[:, 1].max() >= n):
        raise LogFormatError(f"{_OFFSET}: a keyframe index is not a pose of the graph", where)
    return LineGraphFile(
        pose_graph=pose_graph,
        line_ids=v[:, 0].astype(np.int64),
        lines_r_alpha=v[:, 1:],
        factor_pose=e[:, 0].astype(np.int64),
        factor_line=e[:, 1].astype(np.int64),
        factor_z=e[:, 2:4],
        factor_information=info,
        timestamps=timestamps,
        prior_pose=prior_pose,
        prior_information=prior_info,
        robust_kernel=robust,
        motion_noise=motion,
        offset_timestamps=off[:, 0].copy() if written else None,
        offset_keyframes=off[:, 1].astype(np.int64) if written else None,
        offsets=off[:, 2:].copy() if written else None,
        offset_covariances=np.asarray(offset_covs, dtype=float).reshape(-1, 3, 3)
        if written
        else None,
        line_links=np.asarray(links, dtype=float).reshape(-1, 7) if links else None,
    )
