"""Covariances of the relative pose between any two scans of a run, from its ``graph.g2o``.

The relations NEES of ``lineslam evaluate`` (:mod:`slam.evaluation.relations_nees`) needs, for a
relation between the scans at ``t1`` and ``t2``, the covariance of the estimated relative pose
``ρ = p₁⁻¹ p₂``.  Per-pose marginals (``trajectory_covariance.txt``) cannot give it: the two
poses are correlated, and for a short relation the correlation is nearly all of their
covariance.  The results folder of ``lineslam slam`` holds the whole factor graph
(``graph.g2o``, :func:`slam.io.g2o.write_line_graph_g2o`: keyframe poses as estimated, odometry
and line factors with their information, the gauge prior, the robust kernel, and how every
other scan hangs from its keyframe), so the covariances are recomputed here exactly as the
batch back-end computes its own (:meth:`slam.graph.batch.BatchSolver.marginals`: the graph
linearised at the estimate, the kernel's IRLS weights at the estimate, ``gtsam.Marginals``):

* keyframes ``k₁ ≠ k₂``: their joint marginal ``Σ`` (6×6, ``jointMarginalCovariance``); a scan
  ``s`` hanging from keyframe ``k`` with offset ``δ_s`` has the right perturbation
  ``ξ_s = Ad(δ_s⁻¹) ξ_k + w_s``, independent between keyframes, with ``w_s ~ N(0, Q(δ_s))``
  (the run's final motion model) for an odometry offset and ``w_s ~ N(0, Σ_s)`` for a scan
  matched against its keyframe (the match's covariance, ``LINESLAM_SCAN_OFFSET`` with twelve
  fields), as :func:`slam.line_slam.assembly.assemble_result` computes each scan's own
  covariance;
* both scans on one keyframe: the keyframe cancels.  Two odometry scans share the odometry
  from the keyframe to the earlier one, and ``Cov(ρ) = Q(δ₁⁻¹ δ₂)`` (the odometry between them,
  the earlier scan first; moved to ``ρ``'s tangent space when the relation runs backwards).
  When either is a matched scan (or the keyframe itself) their noises are independent:
  ``Cov(ρ) = F Σ₁ Fᵀ + Σ₂``, ``F = Ad(ρ⁻¹)``, each ``Σ`` the scan's own noise (``Σ_s``,
  ``Q(δ_s)``, or zero for the keyframe), with the same ordering and backwards handling;
* then ``η = −Ad(ρ⁻¹) ξ₁ + ξ₂`` (right perturbation of ``ρ``), and in the reported frame
  ``base`` (``pose_world_base = pose_world_laser ∘ M⁻¹``, ``M = pose_base_laser``)
  ``η_base = Ad(M) η``.

The small interpolation by which a reported non-keyframe pose shares the correction between
its two keyframes (:func:`slam.line_slam.assembly.scan_poses`) is not in the covariance model,
as it is not in the per-pose covariances.

For the consistency of a whole run (the interval of one run's mean NEES,
:mod:`slam.evaluation.nees`, :mod:`slam.evaluation.relations_nees`) the same model gives the
joint covariance of many scans' errors (:meth:`RunCovariances.joint_scan_covariance`, dense)
and joint draws of many relations' errors (:meth:`RunCovariances.relation_error_draws`, from
the sparse information matrix).

Main entry point::

    cov = RunCovariances.from_file("out/graph.g2o", pose_base_laser=None)
    cov.relative_covariances(t1, t2)    # (m, 3, 3) in the reported frame
    cov.joint_scan_covariance(t)        # (3n, 3n), the scans' errors jointly
    cov.relation_error_draws(t1, t2, draws, seed)   # chunks (k, m, 3) of joint draws
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EstimationError, EvaluationError, LogFormatError
from slam.evaluation.nees import psd_factor
from slam.evaluation.timestamps import match_timestamps
from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_inverse
from slam.graph.batch import BatchSolver
from slam.graph.config import SolverConfig
from slam.graph.linear import keys_of
from slam.graph.problem import LineGraph
from slam.io.g2o import LineGraphFile, read_line_graph_g2o
from slam.models.motion import MotionNoiseConfig

__all__ = ["DEFAULT_PRIOR_SIGMAS", "RunCovariances", "information_factor", "line_graph_from_file"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

DEFAULT_PRIOR_SIGMAS = (1e-4, 1e-4, 1e-5)
"""Prior on pose 0 (m, m, rad) for a file without ``LINESLAM_PRIOR_SE2`` (``FIX 0`` only):
``SlamConfig``'s default ``prior_sigma_*``; relative covariances hardly depend on it."""


def line_graph_from_file(graph_file: LineGraphFile) -> LineGraph:
    """A :class:`LineGraph` holding the file's poses, landmarks and factors at its estimate.

    Each landmark's anchor is the foot of its first observing pose on the line (the anchor
    only chooses the landmark's chart, which the pose marginals do not depend on).  The
    measured segments are not in the file: the factors get zero-length end points, which
    only the extents (not used here) would read.  Landmarks without a factor are left out.
    """
    pg = graph_file.pose_graph
    n = pg.vertex_ids.shape[0]
    if not np.array_equal(pg.vertex_ids, np.arange(n)):
        raise LogFormatError("graph.g2o: pose ids must be 0..n-1 in order")
    g = LineGraph()
    for p in pg.poses:
        g.add_pose(p)
    if graph_file.prior_pose is not None and graph_file.prior_information is not None:
        g.set_prior(
            graph_file.prior_pose, np.asarray(np.linalg.inv(graph_file.prior_information), float)
        )
    elif n:
        g.set_prior(pg.poses[0], np.diag(np.square(DEFAULT_PRIOR_SIGMAS)))
    for (i, j), z, info in zip(pg.edges, pg.measurements, pg.information, strict=True):
        g.add_odometry(int(i), int(j), z, np.linalg.inv(info))
    if graph_file.factor_pose.size == 0:
        return g
    row_of = {int(k): r for r, k in enumerate(graph_file.line_ids)}
    links = graph_file.line_links if graph_file.line_links is not None else np.zeros((0, 7))
    try:
        rows = np.array([row_of[int(k)] for k in graph_file.factor_line], dtype=np.intp)
        link_rows = np.array(
            [[row_of[int(a)], row_of[int(b)]] for a, b in links[:, :2]], dtype=np.intp
        ).reshape(-1, 2)
    except KeyError as exc:
        raise LogFormatError(f"graph.g2o: a line factor or link names unknown line {exc}") from None
    used, first = np.unique(rows, return_index=True)
    lines = graph_file.lines_r_alpha[used]
    nrm = np.column_stack([np.cos(lines[:, 1]), np.sin(lines[:, 1])])
    seen_from = pg.poses[graph_file.factor_pose[first], :2]
    anchors = seen_from - (np.sum(seen_from * nrm, axis=1) - lines[:, 0])[:, None] * nrm
    # linked lines share the chart their link is written in (a wall holds no factor)
    all_rows = np.union1d(used, link_rows.ravel())
    anchor_of = np.full((graph_file.line_ids.shape[0], 2), np.nan)
    anchor_of[used] = anchors
    anchor_of[link_rows[:, 0]] = links[:, 2:4]
    anchor_of[link_rows[:, 1]] = links[:, 2:4]
    index = np.full(graph_file.line_ids.shape[0], -1, dtype=np.intp)
    index[all_rows] = g.add_landmarks(graph_file.lines_r_alpha[all_rows], anchor_of[all_rows])
    lm = index[rows]
    inv = np.asarray(np.linalg.inv(graph_file.factor_information), dtype=np.float64)
    cov: FloatArray = 0.5 * (inv + np.swapaxes(inv, 1, 2))
    order = np.argsort(graph_file.factor_pose, kind="stable")
    poses_sorted = graph_file.factor_pose[order]
    starts = np.flatnonzero(np.r_[True, poses_sorted[1:] != poses_sorted[:-1]])
    for sel in np.split(order, starts[1:]):
        k = sel.shape[0]
        g.add_line_factors(
            int(graph_file.factor_pose[sel[0]]),
            lm[sel],
            graph_file.factor_z[sel],
            cov[sel],
            np.zeros((k, 2, 2)),
        )
    if links.shape[0]:
        info = np.zeros((links.shape[0], 2, 2))
        info[:, 0, 0], info[:, 1, 1] = links[:, 4], links[:, 6]
        info[:, 0, 1] = info[:, 1, 0] = links[:, 5]
        g.add_landmark_links(index[link_rows[:, 0]], index[link_rows[:, 1]], np.linalg.inv(info))
    return g


def information_factor(solver: BatchSolver, graph: LineGraph) -> tuple[Any, Any, dict[int, int]]:
    """``A``, the sparse LU of ``H = AᵀA`` and each key's first column.

    ``A`` is the whitened Jacobian of ``graph`` linearised at its estimate by ``solver`` (its
    kernel's IRLS weights in; GTSAM's ``sparseJacobian_``); ``H``'s LU is SciPy's, in a
    symmetric minimum-degree order with diagonal pivots.

    Raises
    ------
    EstimationError
        ``H`` is singular.
    """
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import splu

    gfg = solver.linearize(graph)
    rows, cols, vals = gfg.sparseJacobian_()
    key_set = gfg.keys()  # kept alive while it is iterated (pybind11 iterators do not)
    keys = sorted(int(k) for k in key_set)
    dims = [2 if chr(gtsam.Symbol(k).chr()) == "l" else 3 for k in keys]
    offset = dict(zip(keys, np.cumsum([0, *dims[:-1]]).tolist(), strict=True))
    n = int(sum(dims))
    a_part = cols <= n  # the last column is the right-hand side
    rc = (rows[a_part].astype(np.intp) - 1, cols[a_part].astype(np.intp) - 1)
    A = csc_matrix((vals[a_part], rc), shape=(int(rows.max()), n))
    try:
        # symmetric positive definite: a symmetric fill-reducing order, diagonal pivots
        lu = splu(
            csc_matrix(A.T @ A),
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
    except RuntimeError as exc:
        raise EstimationError(f"information matrix of the graph is singular: {exc}") from exc
    return A, lu, offset


class RunCovariances:
    """Relative-pose covariances between a run's scans (module docstring).

    Parameters
    ----------
    graph_file : LineGraphFile
        ``graph.g2o`` read back; it must state the keyframes' time stamps and the other
        scans' offsets (``lineslam slam`` writes both).
    pose_base_laser : array_like, shape (3,), optional
        The mounting when the trajectory is reported in the base frame (``summary.json``
        ``"frame": "base"``); None for the laser frame.

    Raises
    ------
    EvaluationError
        The file lacks the time stamps or the scans' offsets (written by an older version).
    """

    def __init__(self, graph_file: LineGraphFile, pose_base_laser: ArrayLike | None = None):
        f = graph_file
        if f.timestamps is None or f.offset_timestamps is None or f.motion_noise is None:
            raise EvaluationError(
                "graph.g2o does not say how every scan hangs from the graph (no "
                "LINESLAM_SCAN / LINESLAM_SCAN_OFFSET / LINESLAM_MOTION_NOISE lines): "
                "run lineslam slam again to write it"
            )
        assert f.offset_keyframes is not None and f.offsets is not None
        self.graph_file = f
        self.graph = line_graph_from_file(f)
        kernel, width = f.robust_kernel if f.robust_kernel is not None else ("none", 1.0)
        self.solver = BatchSolver(SolverConfig(robust_kernel=kernel, robust_k=width))  # type: ignore[arg-type]
        self.motion = MotionNoiseConfig(**f.motion_noise)
        n_kf = f.timestamps.shape[0]
        self.scan_timestamps = np.concatenate([f.timestamps, f.offset_timestamps])
        self.scan_keyframe = np.concatenate([np.arange(n_kf), f.offset_keyframes])
        self.scan_offset = np.concatenate([np.zeros((n_kf, 3)), f.offsets])
        own = f.offset_covariances
        if own is None:
            own = np.full((f.offsets.shape[0], 3, 3), np.nan)
        self.scan_offset_cov = np.concatenate([np.full((n_kf, 3, 3), np.nan), own])
        """Each scan's match covariance ``Σ_s`` ``(N, 3, 3)``; NaN for keyframes and odometry."""
        self.scan_matched = np.all(np.isfinite(self.scan_offset_cov.reshape(-1, 9)), axis=1)
        """Whether each scan's offset is a scan match's (its noise ``Σ_s``, not ``Q(δ_s)``)."""
        self.mount = None if pose_base_laser is None else np.asarray(pose_base_laser, float)
        self._marginals: gtsam.Marginals | None = None
        self._information_lu: tuple[Any, Any, dict[int, int]] | None = None

    @classmethod
    def from_file(
        cls, path: str | Path, pose_base_laser: ArrayLike | None = None
    ) -> RunCovariances:
        """Read ``graph.g2o`` (:func:`slam.io.g2o.read_line_graph_g2o`)."""
        return cls(read_line_graph_g2o(path), pose_base_laser)

    @classmethod
    def from_results(cls, directory: str | Path, summary: dict[str, Any]) -> RunCovariances:
        """From a results folder: its ``graph.g2o`` and the frame ``summary.json`` states."""
        mount = None
        if summary.get("frame", "laser") == "base":
            mount = (summary.get("input") or {}).get("pose_base_laser")
        return cls.from_file(Path(directory) / "graph.g2o", mount)

    @property
    def marginals(self) -> gtsam.Marginals:
        """``gtsam.Marginals`` of the graph linearised at its estimate (built once)."""
        if self._marginals is None:
            self._marginals = self.solver.marginals(self.graph)
        return self._marginals

    def keyframe_covariances(self, keyframes: ArrayLike) -> FloatArray:
        """Marginal covariances ``(m, 3, 3)`` of keyframes (laser, right tangent space)."""
        keys = keys_of("x", np.asarray(keyframes, dtype=np.intp).reshape(-1))
        return np.array([self.marginals.marginalCovariance(k) for k in keys]).reshape(-1, 3, 3)

    def _joint(self, k1: int, k2: int) -> FloatArray:
        keys = gtsam.KeyVector(keys_of("x", np.array([k1, k2])))
        try:
            return np.asarray(self.marginals.jointMarginalCovariance(keys).fullMatrix(), float)
        except RuntimeError as exc:
            raise EstimationError(f"joint marginal of keyframes {k1}, {k2}: {exc}") from exc

    def scans_of(self, timestamps: ArrayLike, tolerance_s: float = 1e-5) -> IntArray:
        """Row of each time stamp among the run's scans (EvaluationError if one is missing)."""
        t = np.asarray(timestamps, dtype=float).reshape(-1)
        idx, found = match_timestamps(t, self.scan_timestamps, tolerance_s)
        if not found.all():
            bad = float(t[np.flatnonzero(~found)[0]])
            raise EvaluationError(f"time stamp {bad:.6f} is not a scan of graph.g2o")
        return idx.astype(np.intp)

    def relative_covariances(
        self, t1: ArrayLike, t2: ArrayLike, tolerance_s: float = 1e-5
    ) -> FloatArray:
        """Covariance ``(m, 3, 3)`` of ``pose(t1)⁻¹ pose(t2)`` for each pair of time stamps.

        In the right tangent space of the relative pose, in the reported frame (module
        docstring).
        """
        s1 = self.scans_of(t1, tolerance_s)
        s2 = self.scans_of(t2, tolerance_s)
        out = np.zeros((s1.shape[0], 3, 3))
        joint: dict[tuple[int, int], FloatArray] = {}
        if self.graph.n_landmark_links:
            # GTSAM's joint marginals pass through the links: from the information's LU instead
            k1, k2 = self.scan_keyframe[s1], self.scan_keyframe[s2]
            other = k1 != k2
            pairs = np.unique(np.sort(np.column_stack([k1[other], k2[other]]), axis=1), axis=0)
            joint = self.joint_covariances_from_information(pairs)
        for m, (a, b) in enumerate(zip(s1.tolist(), s2.tolist(), strict=True)):
            out[m] = self._relative(a, b, joint)
        if self.mount is not None:
            F = adjoint_pose2(self.mount)
            out = F @ out @ F.T
        return 0.5 * (out + np.swapaxes(out, 1, 2))

    def joint_scan_covariance(self, timestamps: ArrayLike, tolerance_s: float = 1e-5) -> FloatArray:
        """Joint covariance ``(3m, 3m)`` of the errors of the scans at ``m`` time stamps.

        Block ``(i, j)`` is ``Cov(ξᵢ, ξⱼ)``, each scan's error in its own right tangent space
        in the reported frame: the keyframes' joint marginal (``jointMarginalCovariance``),
        each other scan ``ξ_s = Ad(δ_s⁻¹) ξ_k + w_s`` with its own noise ``w_s`` (``Q(δ_s)``
        or a match's ``Σ_s``) independent of the keyframes and of other keyframes' scans
        (module docstring); two odometry scans on one keyframe get the cross-covariance of
        ``w`` that makes the covariance of their relative pose the odometry's between them,
        a matched scan none (:meth:`odometry_noise`), as in :meth:`relative_covariances`.
        Its diagonal blocks are the per-scan covariances of ``trajectory_covariance.txt``.
        Dense: meant for a few thousand scans at most
        (:data:`slam.evaluation.nees.MAX_BOUND_POSES`).
        """
        s = self.scans_of(timestamps, tolerance_s)
        kfs, column = np.unique(self.scan_keyframe[s], return_inverse=True)
        keys = gtsam.KeyVector(keys_of("x", kfs.astype(np.intp)))
        try:
            K = np.asarray(self.marginals.jointMarginalCovariance(keys).fullMatrix(), float)
        except RuntimeError as exc:
            raise EstimationError(f"joint marginal of {kfs.size} keyframes: {exc}") from exc
        m = s.shape[0]
        A = np.zeros((3 * m, 3 * kfs.size))
        scans = s.tolist()
        for i, (scan, c) in enumerate(zip(scans, column.tolist(), strict=True)):
            A[3 * i : 3 * i + 3, 3 * c : 3 * c + 3] = adjoint_pose2(
                pose_inverse(self.scan_offset[scan])
            )
        noise = np.zeros((3 * m, 3 * m))
        for rows in _groups(column):
            idx = (3 * rows[:, None] + np.arange(3)).reshape(-1)
            noise[np.ix_(idx, idx)] = self.odometry_noise(s[rows])
        out = A @ K @ A.T + noise
        if self.mount is not None:
            mount = np.kron(np.eye(m), adjoint_pose2(self.mount))
            out = mount @ out @ mount.T
        return np.asarray(0.5 * (out + out.T))

    def odometry_noise(self, scans: IntArray) -> FloatArray:
        """Joint covariance ``(3n, 3n)`` of the noises ``w_s`` of scans on one keyframe.

        A keyframe has none; a matched scan its match's covariance ``Σ_s``, independent of
        the others'; another scan ``Q(δ_s)``, the motion model at its offset, and two such
        scans ``a`` before ``b`` share the stretch of odometry between the keyframe and ``a``:
        their cross-covariance ``C`` makes the covariance of their relative pose the
        odometry's between them, as :meth:`relative_covariances` has it:
        ``F Q_a Fᵀ + Q_b − F C − (F C)ᵀ = Q_ab`` with ``F = Ad(ρ⁻¹)`` and ``F C`` symmetric.
        """
        rows = [int(x) for x in np.asarray(scans).reshape(-1)]
        n = len(rows)
        out = np.zeros((3 * n, 3 * n))
        for i in range(n):
            out[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = self._own_noise(rows[i])
        odometry = [i for i in range(n) if not (self._is_kf(rows[i]) or self.scan_matched[rows[i]])]
        for i, j in ((i, j) for i in odometry for j in odometry if i < j):
            ia, ib = (i, j) if self._earlier(rows[i], rows[j]) else (j, i)
            da, db = self.scan_offset[rows[ia]], self.scan_offset[rows[ib]]
            rho = pose_between(da, db)
            F = adjoint_pose2(pose_inverse(rho))
            FC = 0.5 * (
                F @ self.motion.covariance(da) @ F.T
                + self.motion.covariance(db)
                - self.motion.covariance(rho)
            )
            C = np.linalg.solve(F, FC)  # Cov(w_a, w_b)
            out[3 * ia : 3 * ia + 3, 3 * ib : 3 * ib + 3] = C
            out[3 * ib : 3 * ib + 3, 3 * ia : 3 * ia + 3] = C.T
        return out

    def relation_error_draws(
        self,
        t1: ArrayLike,
        t2: ArrayLike,
        draws: int,
        seed: int,
        tolerance_s: float = 1e-5,
        chunk: int = 100,
    ) -> Iterator[FloatArray]:
        """Draws of the errors of ``pose(t1)⁻¹ pose(t2)`` under the run's own model, jointly.

        The keyframes' errors are drawn from ``N(0, H⁻¹)``, ``H = AᵀA`` the information of the
        graph linearised at its estimate as :attr:`marginals` has it (``A`` the whitened
        Jacobian, GTSAM's ``sparseJacobian_``; a draw is ``H⁻¹ Aᵀ z``, ``z ~ N(0, I)``, solved
        with SciPy's sparse LU), each other scan's by its own noise from its keyframe
        (:meth:`odometry_noise`, drawn per keyframe), and each relation's error is
        ``η = −Ad(ρ⁻¹) ξ₁ + ξ₂`` as in :meth:`relative_covariances`, whose covariances the
        draws have.  Yields arrays ``(k, m, 3)`` (``k ≤ chunk`` draws of the ``m`` relations)
        in the reported frame, ``draws`` in all, reproducibly for a ``seed``.
        """
        s1 = self.scans_of(t1, tolerance_s)
        s2 = self.scans_of(t2, tolerance_s)
        A, lu, offset = self._information()
        # the scans of the relations, their keyframes and the keyframes' columns
        scans, where = np.unique(np.concatenate([s1, s2]), return_inverse=True)
        w1, w2 = where[: s1.shape[0]], where[s1.shape[0] :]
        kfs, kf_col = np.unique(self.scan_keyframe[scans], return_inverse=True)
        pose_cols = np.array([offset[k] for k in keys_of("x", kfs.astype(np.intp))], dtype=np.intp)[
            :, None
        ] + np.arange(3)
        to_scan = np.array([adjoint_pose2(pose_inverse(self.scan_offset[x])) for x in scans])
        groups = [scans_idx for scans_idx in _groups(kf_col) if scans_idx.size]
        noise_factors = [psd_factor(self.odometry_noise(scans[g])) for g in groups]
        graph_poses = self.graph.poses
        scan_pose = pose_compose(graph_poses[self.scan_keyframe[scans]], self.scan_offset[scans])
        rho = pose_between(scan_pose[w1], scan_pose[w2])
        back = -np.array([adjoint_pose2(pose_inverse(r)) for r in rho])  # (m, 3, 3)
        mount = None if self.mount is None else adjoint_pose2(self.mount)
        rng = np.random.default_rng(seed)
        for start in range(0, draws, chunk):
            k = min(chunk, draws - start)
            z = rng.standard_normal((A.shape[0], k))
            x = lu.solve(np.asarray(A.T @ z))  # (n, k)
            xi_kf = np.moveaxis(x[pose_cols], 2, 0)  # (k, kfs, 3)
            xi = np.einsum("sij,ksj->ksi", to_scan, xi_kf[:, kf_col])
            for g, L in zip(groups, noise_factors, strict=True):
                w = rng.standard_normal((k, L.shape[1])) @ L.T
                xi[:, g] += w.reshape(k, g.size, 3)
            eta = np.einsum("mij,kmj->kmi", back, xi[:, w1]) + xi[:, w2]
            if mount is not None:
                eta = eta @ mount.T
            yield eta

    def _information(self) -> tuple[Any, Any, dict[int, int]]:
        """``A``, the sparse LU of ``H = AᵀA`` and each key's first column, built once.

        ``A`` is the whitened Jacobian of the graph linearised at its estimate
        (:meth:`relation_error_draws`, :func:`information_factor`).
        """
        if self._information_lu is None:
            self._information_lu = information_factor(self.solver, self.graph)
        return self._information_lu

    def _relative(self, a: int, b: int, joint: dict[tuple[int, int], FloatArray]) -> FloatArray:
        """Covariance of ``scan_a⁻¹ scan_b`` in the laser frame (module docstring)."""
        ka, kb = int(self.scan_keyframe[a]), int(self.scan_keyframe[b])
        da, db = self.scan_offset[a], self.scan_offset[b]
        if ka == kb:
            # the same keyframe: only the noise between the two scans, earlier one first
            forward = self._earlier(a, b)
            first, second = (a, b) if forward else (b, a)
            rho = pose_between(self.scan_offset[first], self.scan_offset[second])
            if self.scan_matched[first] or self.scan_matched[second]:
                F = adjoint_pose2(pose_inverse(rho))  # independent noises
                Q = F @ self._own_noise(first) @ F.T + self._own_noise(second)
            else:
                Q = self.motion.covariance(rho)  # the odometry between them
            if forward:
                return np.asarray(Q)
            F = adjoint_pose2(rho)  # η of ρ⁻¹ = −Ad(ρ) η of ρ
            return np.asarray(F @ Q @ F.T)
        key = (min(ka, kb), max(ka, kb))
        if key not in joint:
            joint[key] = self._joint(*key)
        J = joint[key]
        if ka > kb:
            J = np.block([[J[3:, 3:], J[3:, :3]], [J[:3, 3:], J[:3, :3]]])
        Fa = adjoint_pose2(pose_inverse(da))
        Fb = adjoint_pose2(pose_inverse(db))
        P = np.zeros((6, 6))
        P[:3, :3] = Fa @ J[:3, :3] @ Fa.T + self._own_noise(a)
        P[3:, 3:] = Fb @ J[3:, 3:] @ Fb.T + self._own_noise(b)
        P[:3, 3:] = Fa @ J[:3, 3:] @ Fb.T
        P[3:, :3] = P[:3, 3:].T
        graph_poses = self.graph.poses
        pa = pose_compose(graph_poses[ka], da)
        pb = pose_compose(graph_poses[kb], db)
        rho = pose_between(pa, pb)
        A = np.hstack([-adjoint_pose2(pose_inverse(rho)), np.eye(3)])
        return np.asarray(A @ P @ A.T)

    def joint_covariances_from_information(
        self, pairs: ArrayLike, chunk: int = 200
    ) -> dict[tuple[int, int], FloatArray]:
        """Joint covariances ``(6, 6)`` of keyframe pairs ``(k₁ < k₂)`` from ``H⁻¹`` columns.

        The same numbers as :meth:`_joint` (the information at the estimate, kernel weights
        in), from solves with the sparse LU of :func:`information_factor`: three columns of
        ``H⁻¹`` per keyframe, ``chunk`` keyframes at a time.  Used for a graph with landmark
        links, whose joint marginals GTSAM computes slowly.
        """
        p = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
        if p.shape[0] == 0:
            return {}
        A, lu, offset = self._information()
        n = A.shape[1]
        kfs = np.unique(p)
        col = np.array([offset[k] for k in keys_of("x", kfs)], dtype=np.intp)
        where = {int(k): i for i, k in enumerate(kfs.tolist())}
        diag = np.zeros((kfs.size, 3, 3))
        cross: dict[tuple[int, int], FloatArray] = {}
        first_of = np.array([where[int(k)] for k in p[:, 0]])
        for lo in range(0, kfs.size, chunk):
            part = np.arange(lo, min(lo + chunk, kfs.size))
            E = np.zeros((n, 3 * part.size))
            rows = (col[part][:, None] + np.arange(3)[None, :]).ravel()
            E[rows, np.arange(3 * part.size)] = 1.0
            X = np.asarray(lu.solve(E)).reshape(n, part.size, 3)
            for j, i in enumerate(part.tolist()):
                diag[i] = X[col[i] : col[i] + 3, j, :]
            for m in np.flatnonzero((first_of >= lo) & (first_of < lo + part.size)).tolist():
                a, b = int(p[m, 0]), int(p[m, 1])
                j = where[a] - lo
                cross[(a, b)] = X[col[where[b]] : col[where[b]] + 3, j, :].T  # Cov(x_a, x_b)
        out: dict[tuple[int, int], FloatArray] = {}
        for (a, b), C_ab in cross.items():
            J = np.zeros((6, 6))
            J[:3, :3] = diag[where[a]]
            J[3:, 3:] = diag[where[b]]
            J[:3, 3:] = C_ab
            J[3:, :3] = C_ab.T
            out[(a, b)] = 0.5 * (J + J.T)
        return out

    def _own_noise(self, scan: int) -> FloatArray:
        """Covariance of a scan's noise ``w_s`` from its keyframe: 0, ``Σ_s`` or ``Q(δ_s)``."""
        if self._is_kf(scan):
            return np.zeros((3, 3))
        if self.scan_matched[scan]:
            return np.asarray(self.scan_offset_cov[scan], dtype=np.float64)
        return np.asarray(self.motion.covariance(self.scan_offset[scan]), dtype=np.float64)

    def _is_kf(self, scan: int) -> bool:
        return bool(scan < self.graph_file.pose_graph.vertex_ids.shape[0])

    def _earlier(self, a: int, b: int) -> bool:
        """Whether scan ``a`` comes before scan ``b`` on their keyframe's stretch.

        The keyframe comes first; the offsets are in file order (not time-stamp order).
        """
        if self._is_kf(a):
            return True
        if self._is_kf(b):
            return False
        return a <= b


def _groups(labels: IntArray) -> list[IntArray]:
    """Indices of each value of ``labels`` (in order of the values)."""
    labels = np.asarray(labels)
    order = np.argsort(labels, kind="stable")
    bounds = np.flatnonzero(np.diff(labels[order])) + 1
    return [np.asarray(g, dtype=np.intp) for g in np.split(order, bounds)] if labels.size else []
