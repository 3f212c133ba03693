"""The line-SLAM factor graph as numpy arrays: the single source of truth for both solvers.

:class:`LineGraph` holds the variables (laser poses ``x_i``, line landmarks ``v_j = (ρ, φ)``
with their anchors ``c_j``, :mod:`slam.models.anchored`), their current estimate, and the
factors:

* a prior on the first pose (fixes the gauge: the world frame),
* odometry factors ``x_i⁻¹ x_j ≈ u_ij`` (``gtsam.BetweenFactorPose2`` semantics, covariance in
  the right tangent space of the relative pose),
* line factors (:mod:`slam.graph.factors`) with each measurement's whitening matrix and the
  measured segment's end points in the laser frame (the landmark's world extent is recomputed
  from them and the current estimate, so it follows every correction).

Landmark fusion (:meth:`LineGraph.merge_landmarks`) rewires the factors of one landmark to
another and retires the first; both solvers read the graph from these arrays (the batch solver
every iteration, iSAM2 incrementally through :attr:`LineGraph.merge_log`).

GTSAM keys: pose ``i`` is ``X(i)``, landmark ``j`` is ``L(j)`` (``gtsam.symbol_shorthand``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gtsam.symbol_shorthand import L, X
from numba import njit
from numpy.typing import NDArray

from slam.errors import EstimationError, InputError
from slam.geometry import pose_compose
from slam.graph.factors import sqrt_information_2x2
from slam.graph.odometry import sqrt_information
from slam.models.anchored import anchored_from_r_alpha, r_alpha_from_anchored

__all__ = [
    "GrowableArray",
    "LineGraph",
    "MergeRecord",
    "landmark_key",
    "pose_key",
    "unite_factor_extents",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def pose_key(i: int) -> int:
    """GTSAM key of pose ``i``."""
    return int(X(int(i)))


def landmark_key(j: int) -> int:
    """GTSAM key of landmark ``j``."""
    return int(L(int(j)))


class GrowableArray:
    """A numpy array that grows along its first axis with amortised O(1) appends."""

    def __init__(self, tail: tuple[int, ...], dtype: type | np.dtype = float, fill: float = 0):
        self._tail = tail
        self._fill = fill
        self._buf = np.full((16, *tail), fill, dtype=dtype)
        self._n = 0

    def __len__(self) -> int:
        return self._n

    @property
    def data(self) -> NDArray:
        """View of the filled rows (writable)."""
        return self._buf[: self._n]

    def append(self, rows: NDArray | list | float) -> IntArray:
        """Append rows ``(k, *tail)``; return their indices."""
        arr = np.asarray(rows, dtype=self._buf.dtype).reshape(-1, *self._tail)
        k = arr.shape[0]
        need = self._n + k
        if need > self._buf.shape[0]:
            cap = max(need, 2 * self._buf.shape[0])
            new = np.full((cap, *self._tail), self._fill, dtype=self._buf.dtype)
            new[: self._n] = self._buf[: self._n]
            self._buf = new
        self._buf[self._n : need] = arr
        idx = np.arange(self._n, need, dtype=np.intp)
        self._n = need
        return idx


@njit(cache=True, nogil=True)
def _extents_kernel(
    endpoints: FloatArray, poses: FloatArray, anchors: FloatArray, trig: FloatArray, out: FloatArray
) -> None:  # pragma: no cover - compiled
    """The arithmetic of :meth:`LineGraph.factor_extents` after its sines and cosines.

    ``trig`` holds the rows ``cos θ`` and ``sin θ`` of each factor's pose and the tangent
    ``(−sin α, cos α)`` of its landmark.  The end points are moved into the world as
    :func:`slam.geometry.pose_compose` moves them, their coordinates along the tangent summed
    as ``einsum`` sums them; ``out`` gets ``(min, max)`` per factor.
    """
    for f in range(endpoints.shape[0]):
        c, s = trig[0, f], trig[1, f]
        t0, t1 = trig[2, f], trig[3, f]
        lo = hi = 0.0
        for k in range(2):
            ex, ey = endpoints[f, k, 0], endpoints[f, k, 1]
            x = poses[f, 0] + c * ex - s * ey
            y = poses[f, 1] + s * ex + c * ey
            u = 0.0 + (x - anchors[f, 0]) * t0 + (y - anchors[f, 1]) * t1
            if k == 0:
                lo = hi = u
            else:
                lo = min(lo, u)
                hi = max(hi, u)
        out[f, 0] = lo
        out[f, 1] = hi


@dataclass(frozen=True)
class MergeRecord:
    """Landmark ``drop`` was fused into ``keep``; ``factors`` are the rewired line factors.

    ``undo``: the record of an undone merge (the factors went back to ``drop``).
    """

    keep: int
    drop: int
    factors: IntArray
    undo: bool = False


def unite_factor_extents(s: FloatArray, factor_landmark: IntArray, n_landmarks: int) -> FloatArray:
    """Per landmark, the union ``(s_min, s_max)`` of its factors' intervals ``s`` ``(F, 2)``.

    ``(n_landmarks, 2)``; landmarks without factors get ``(nan, nan)``.
    """
    out = np.full((n_landmarks, 2), np.nan)
    lo = np.full(n_landmarks, np.inf)
    hi = np.full(n_landmarks, -np.inf)
    np.minimum.at(lo, factor_landmark, s[:, 0])
    np.maximum.at(hi, factor_landmark, s[:, 1])
    seen = np.isfinite(lo)
    out[seen, 0] = lo[seen]
    out[seen, 1] = hi[seen]
    return out


class LineGraph:
    """Variables, estimate and factors of a line-SLAM problem (see the module docstring)."""

    def __init__(self) -> None:
        self._poses = GrowableArray((3,))
        self._landmarks = GrowableArray((2,))
        self._anchors = GrowableArray((2,))
        self._lm_alive = GrowableArray((), dtype=bool, fill=False)
        self._lm_merged_into = GrowableArray((), dtype=np.intp, fill=-1)
        # line factors
        self._f_pose = GrowableArray((), dtype=np.intp)
        self._f_lm = GrowableArray((), dtype=np.intp)
        self._f_z = GrowableArray((2,))
        self._f_cov = GrowableArray((2, 2))
        self._f_sqrt_info = GrowableArray((2, 2))
        self._f_endpoints = GrowableArray((2, 2))
        self._f_endpoint_var = GrowableArray((2,))
        # visible pieces of each measured line (a line may have gaps): ragged, by factor
        self._p_factor = GrowableArray((), dtype=np.intp)
        self._p_ends = GrowableArray((2, 2))
        self._p_var = GrowableArray((2,))
        # odometry factors
        self._o_first = GrowableArray((), dtype=np.intp)
        self._o_second = GrowableArray((), dtype=np.intp)
        self._o_measured = GrowableArray((3,))
        self._o_cov = GrowableArray((3, 3))
        self._o_sqrt_info = GrowableArray((3, 3))
        # links between two landmarks in one chart (a pass along a wall and the wall)
        self._k_first = GrowableArray((), dtype=np.intp)
        self._k_second = GrowableArray((), dtype=np.intp)
        self._k_cov = GrowableArray((2, 2))
        self._k_sqrt_info = GrowableArray((2, 2))
        self.prior_pose: FloatArray | None = None
        self.prior_cov: FloatArray | None = None
        self.prior_sqrt_info: FloatArray | None = None
        self.merge_log: list[MergeRecord] = []

    # -- sizes and views -----------------------------------------------------------------------
    @property
    def n_poses(self) -> int:
        """Number of pose variables."""
        return len(self._poses)

    @property
    def n_landmarks(self) -> int:
        """Number of landmark variables ever created (retired ones included)."""
        return len(self._landmarks)

    @property
    def n_line_factors(self) -> int:
        """Number of line factors (each one measurement)."""
        return len(self._f_pose)

    @property
    def n_odometry(self) -> int:
        """Number of odometry factors."""
        return len(self._o_first)

    @property
    def poses(self) -> FloatArray:
        """Current estimate of the laser poses, ``(N, 3)`` (writable view)."""
        return self._poses.data

    @property
    def landmarks(self) -> FloatArray:
        """Current estimate of the landmarks, anchored ``(ρ, φ)``, ``(M, 2)`` (writable view)."""
        return self._landmarks.data

    @property
    def anchors(self) -> FloatArray:
        """Anchor point of each landmark (world), ``(M, 2)``."""
        return self._anchors.data

    @property
    def landmarks_r_alpha(self) -> FloatArray:
        """Current estimate of the landmarks as signed world lines ``(r, α)``, ``(M, 2)``."""
        return r_alpha_from_anchored(self.landmarks, self.anchors)

    def set_landmarks_r_alpha(self, landmarks: IntArray, r_alpha: FloatArray) -> None:
        """Set the estimate of ``landmarks`` from world lines ``(r, α)`` ``(k, 2)``."""
        idx = np.asarray(landmarks, dtype=np.intp)
        self.landmarks[idx] = anchored_from_r_alpha(r_alpha, self.anchors[idx])

    @property
    def landmark_alive(self) -> NDArray[np.bool_]:
        """False for landmarks fused into another one, ``(M,)``."""
        return self._lm_alive.data

    @property
    def landmark_merged_into(self) -> IntArray:
        """For retired landmarks, the landmark they were fused into (else −1), ``(M,)``."""
        return self._lm_merged_into.data

    @property
    def factor_pose(self) -> IntArray:
        """Pose index of each line factor, ``(F,)``."""
        return self._f_pose.data

    @property
    def factor_landmark(self) -> IntArray:
        """Landmark index of each line factor, ``(F,)`` (rewired on fusion)."""
        return self._f_lm.data

    @property
    def factor_z(self) -> FloatArray:
        """Measured ``(r, α)`` of each line factor, laser frame, ``(F, 2)``."""
        return self._f_z.data

    @property
    def factor_cov(self) -> FloatArray:
        """Measurement covariance of each line factor, ``(F, 2, 2)``."""
        return self._f_cov.data

    @property
    def factor_sqrt_info(self) -> FloatArray:
        """Whitening matrix ``W`` (``WᵀW = R⁻¹``) of each line factor, ``(F, 2, 2)``."""
        return self._f_sqrt_info.data

    @property
    def factor_endpoints(self) -> FloatArray:
        """Measured segment end points in the laser frame, ``(F, 2, 2)``."""
        return self._f_endpoints.data

    @property
    def factor_endpoint_var(self) -> FloatArray:
        """Variances (m²) of the measured end points along the line, ``(F, 2)``."""
        return self._f_endpoint_var.data

    @property
    def piece_factor(self) -> IntArray:
        """Line factor of each visible piece, ``(P,)`` (a measured line has one or more)."""
        return self._p_factor.data

    @property
    def piece_ends(self) -> FloatArray:
        """End points of each piece in its laser frame, ``(P, 2, 2)``."""
        return self._p_ends.data

    @property
    def piece_var(self) -> FloatArray:
        """Variances (m²) of each piece's ends along the line, ``(P, 2)``."""
        return self._p_var.data

    @property
    def odometry_first(self) -> IntArray:
        """First pose of each odometry factor, ``(E,)``."""
        return self._o_first.data

    @property
    def odometry_second(self) -> IntArray:
        """Second pose of each odometry factor, ``(E,)``."""
        return self._o_second.data

    @property
    def odometry_measured(self) -> FloatArray:
        """Measured relative poses ``x_first⁻¹ x_second``, ``(E, 3)``."""
        return self._o_measured.data

    @property
    def odometry_cov(self) -> FloatArray:
        """Their covariances (right tangent space), ``(E, 3, 3)``."""
        return self._o_cov.data

    @property
    def odometry_sqrt_info(self) -> FloatArray:
        """Their whitening matrices (``WᵀW = Σ⁻¹``), ``(E, 3, 3)``."""
        return self._o_sqrt_info.data

    @property
    def n_landmark_links(self) -> int:
        """Number of landmark links (:meth:`add_landmark_links`)."""
        return len(self._k_first)

    @property
    def link_first(self) -> IntArray:
        """First landmark of each link, ``(K,)``."""
        return self._k_first.data

    @property
    def link_second(self) -> IntArray:
        """Second landmark of each link, ``(K,)``."""
        return self._k_second.data

    @property
    def link_cov(self) -> FloatArray:
        """Covariance of each link's difference ``v_first − v_second``, ``(K, 2, 2)``."""
        return self._k_cov.data

    @property
    def link_sqrt_info(self) -> FloatArray:
        """Their whitening matrices, ``(K, 2, 2)``."""
        return self._k_sqrt_info.data

    # -- building ------------------------------------------------------------------------------
    def add_landmark_links(self, first: IntArray, second: IntArray, cov: FloatArray) -> IntArray:
        """Add links ``v_first − v_second ~ N(0, cov)`` between landmarks; return indices.

        The two landmarks of a link must share their anchor, so that the difference of their
        anchored ``(ρ, φ)`` is the difference of the lines (``φ`` wrapped); ``cov`` ``(k, 2,
        2)`` is in that chart.  A pass along a wall seen as its own landmark, linked to the
        wall (:mod:`slam.line_slam.passes`).
        """
        a = np.asarray(first, dtype=np.intp).reshape(-1)
        b = np.asarray(second, dtype=np.intp).reshape(-1)
        c = np.asarray(cov, dtype=float).reshape(-1, 2, 2)
        m = self.n_landmarks
        if a.shape != b.shape or c.shape[0] != a.shape[0]:
            raise InputError("landmark links: first, second and cov differ in length")
        if np.any((a < 0) | (a >= m) | (b < 0) | (b >= m) | (a == b)):
            raise InputError(f"landmark links between invalid landmarks (have {m})")
        if not np.allclose(self.anchors[a], self.anchors[b], rtol=0.0, atol=1e-9):
            raise InputError("linked landmarks must share their anchor")
        W = sqrt_information_2x2(c, "landmark link covariance")
        for i, j, ci, wi in zip(a.tolist(), b.tolist(), c, W, strict=True):
            self._k_first.append(i)
            self._k_second.append(j)
            self._k_cov.append(0.5 * (ci + ci.T))
            self._k_sqrt_info.append(wi)
        return np.arange(self.n_landmark_links - a.shape[0], self.n_landmark_links, dtype=np.intp)

    def add_pose(self, pose_world_laser: FloatArray) -> int:
        """Add a pose variable with its initial estimate; return its index."""
        p = np.asarray(pose_world_laser, dtype=float).reshape(3)
        if not np.isfinite(p).all():
            raise InputError(f"pose must be finite, got {p}")
        return int(self._poses.append(p)[0])

    def add_landmarks(self, landmarks_r_alpha: FloatArray, anchors: FloatArray) -> IntArray:
        """Add landmark variables; return their indices.

        Parameters
        ----------
        landmarks_r_alpha : ndarray, shape (k, 2)
            Initial estimates as world lines ``(r, α)``.
        anchors : ndarray, shape (k, 2)
            Anchor points (world), normally the mid-points of the creating segments.
        """
        lm = np.asarray(landmarks_r_alpha, dtype=float).reshape(-1, 2)
        c = np.asarray(anchors, dtype=float).reshape(-1, 2)
        if not (np.isfinite(lm).all() and np.isfinite(c).all()) or c.shape != lm.shape:
            raise InputError("landmarks and anchors must be finite (k, 2) arrays")
        self._anchors.append(c)
        idx = self._landmarks.append(anchored_from_r_alpha(lm, c))
        self._lm_alive.append(np.ones(lm.shape[0], dtype=bool))
        self._lm_merged_into.append(np.full(lm.shape[0], -1, dtype=np.intp))
        return idx

    def set_prior(self, pose_world_laser: FloatArray, cov: FloatArray) -> None:
        """Prior on pose 0 (the gauge)."""
        self.prior_pose = np.asarray(pose_world_laser, dtype=float).reshape(3).copy()
        self.prior_cov = np.asarray(cov, dtype=float).reshape(3, 3).copy()
        self.prior_sqrt_info = sqrt_information(self.prior_cov)

    def add_odometry(self, first: int, second: int, measured: FloatArray, cov: FloatArray) -> int:
        """Add an odometry factor ``x_first⁻¹ x_second ≈ measured``; return its index."""
        n = self.n_poses
        if not (0 <= first < n and 0 <= second < n) or first == second:
            raise InputError(f"odometry between invalid poses {first}, {second} (have {n})")
        c = np.asarray(cov, dtype=float).reshape(3, 3)
        if not np.isfinite(c).all() or np.any(np.linalg.eigvalsh(0.5 * (c + c.T)) <= 0.0):
            raise InputError("odometry covariance must be finite and positive definite")
        self._o_first.append(first)
        self._o_second.append(second)
        self._o_measured.append(np.asarray(measured, dtype=float).reshape(3))
        self._o_sqrt_info.append(sqrt_information(c))
        return int(self._o_cov.append(c)[0])

    def add_line_factors(
        self,
        pose: int,
        landmarks: IntArray,
        z: FloatArray,
        cov: FloatArray,
        endpoints_laser: FloatArray,
        endpoint_var: FloatArray | None = None,
        pieces: list[FloatArray] | None = None,
        pieces_var: list[FloatArray] | None = None,
    ) -> IntArray:
        """Add line factors from pose ``pose`` to ``landmarks`` (``(k,)``); return indices.

        Parameters
        ----------
        pose : int
        landmarks : ndarray of int, shape (k,)
            Alive landmarks.
        z : ndarray, shape (k, 2)
            Measured ``(r, α)`` (laser frame).
        cov : ndarray, shape (k, 2, 2)
            Their covariances (positive definite, else DegenerateGeometryError).
        endpoints_laser : ndarray, shape (k, 2, 2)
            Measured segments' extreme end points (laser frame).
        endpoint_var : ndarray, shape (k, 2), optional
            Their variances along the line (m²); default 0.
        pieces : list of k arrays of shape (p_i, 2, 2), optional
            Visible pieces of each measured line (laser frame); default one piece from end
            point to end point.
        pieces_var : list of k arrays of shape (p_i, 2), optional
            Variances of the pieces' ends; default ``endpoint_var``.
        """
        lm = np.asarray(landmarks, dtype=np.intp).reshape(-1)
        k = lm.shape[0]
        if k == 0:
            return np.zeros(0, dtype=np.intp)
        if not 0 <= pose < self.n_poses:
            raise InputError(f"line factor on unknown pose {pose}")
        if np.any((lm < 0) | (lm >= self.n_landmarks)) or not np.all(self.landmark_alive[lm]):
            raise InputError("line factor on an unknown or retired landmark")
        z_arr = np.asarray(z, dtype=float).reshape(k, 2)
        c = np.asarray(cov, dtype=float).reshape(k, 2, 2)
        W = sqrt_information_2x2(c)
        self._f_pose.append(np.full(k, pose, dtype=np.intp))
        self._f_lm.append(lm)
        self._f_z.append(z_arr)
        self._f_cov.append(c)
        self._f_sqrt_info.append(W)
        ev = np.zeros((k, 2)) if endpoint_var is None else np.asarray(endpoint_var, dtype=float)
        ev = ev.reshape(k, 2)
        ep = np.asarray(endpoints_laser, dtype=float).reshape(k, 2, 2)
        self._f_endpoint_var.append(ev)
        idx = self._f_endpoints.append(ep)
        if pieces is None:
            self._p_factor.append(idx)
            self._p_ends.append(ep)
            self._p_var.append(ev)
        else:
            if len(pieces) != k:
                raise InputError(f"expected {k} piece arrays, got {len(pieces)}")
            for n, f in enumerate(idx):
                pe = np.asarray(pieces[n], dtype=float).reshape(-1, 2, 2)
                pv = (
                    np.broadcast_to(ev[n], (pe.shape[0], 2))
                    if pieces_var is None
                    else np.asarray(pieces_var[n], dtype=float).reshape(-1, 2)
                )
                self._p_factor.append(np.full(pe.shape[0], f, dtype=np.intp))
                self._p_ends.append(pe)
                self._p_var.append(pv)
        return idx

    def set_line_factor_covariances(self, factors: IntArray, cov: FloatArray) -> None:
        """Replace the measurement covariances ``(k, 2, 2)`` of line factors ``factors``.

        A back-end that has them must be restarted (``reset``) to see the change.
        """
        f = np.asarray(factors, dtype=np.intp).reshape(-1)
        c = np.asarray(cov, dtype=float).reshape(f.size, 2, 2)
        self._f_cov.data[f] = c
        self._f_sqrt_info.data[f] = sqrt_information_2x2(c)

    def merge_landmarks(self, keep: int, drop: int, value: FloatArray | None = None) -> IntArray:
        """Fuse landmark ``drop`` into ``keep``: rewire ``drop``'s factors, retire ``drop``.

        Parameters
        ----------
        keep, drop : int
            Alive landmarks, ``keep != drop``.
        value : ndarray, shape (2,), optional
            New estimate of ``keep`` as a world line ``(r, α)`` (e.g. the fused line);
            default: unchanged.

        Returns
        -------
        ndarray of int
            The rewired line factors.
        """
        if keep == drop or not (self.landmark_alive[keep] and self.landmark_alive[drop]):
            raise EstimationError(f"cannot merge landmark {drop} into {keep}")
        rewired = np.flatnonzero(self.factor_landmark == drop)
        self.factor_landmark[rewired] = keep
        self.landmark_alive[drop] = False
        self.landmark_merged_into[drop] = keep
        if value is not None:
            self.set_landmarks_r_alpha(
                np.array([keep]), np.asarray(value, dtype=float).reshape(1, 2)
            )
        self.merge_log.append(MergeRecord(keep, drop, rewired))
        return rewired

    def unmerge(self, record: MergeRecord) -> None:
        """Undo a merge (e.g. of a rejected loop closure).

        ``record.factors`` go back to ``record.drop``, which is alive again.  Logged in
        :attr:`merge_log` as a record with ``undo=True`` so that incremental solvers rebuild
        the affected factors.
        """
        keep, drop = record.keep, record.drop
        if self.landmark_alive[drop] or not self.landmark_alive[keep]:
            raise EstimationError(f"cannot undo the merge of {drop} into {keep}")
        self.factor_landmark[record.factors] = drop
        self.landmark_alive[drop] = True
        self.landmark_merged_into[drop] = -1
        self.merge_log.append(MergeRecord(keep, drop, record.factors, undo=True))

    def revert_merges(self, since: int) -> None:
        """Undo the merges logged from ``merge_log[since]`` on and drop them from the log.

        Unlike :meth:`unmerge` this leaves no trace: only for merges no incremental solver has
        read yet (e.g. a loop-closure candidate judged and rejected before the back-end saw it).
        """
        if not 0 <= since <= len(self.merge_log):
            raise EstimationError(f"no merge log entry {since} to revert to")
        for record in reversed(self.merge_log[since:]):
            if record.undo:
                self.factor_landmark[record.factors] = record.keep
                self.landmark_alive[record.drop] = False
                self.landmark_merged_into[record.drop] = record.keep
            else:
                self.factor_landmark[record.factors] = record.drop
                self.landmark_alive[record.drop] = True
                self.landmark_merged_into[record.drop] = -1
        del self.merge_log[since:]

    # -- derived quantities --------------------------------------------------------------------
    def factors_of_landmarks(self, landmarks: IntArray) -> IntArray:
        """Line factors on any of ``landmarks``."""
        return np.flatnonzero(np.isin(self.factor_landmark, np.asarray(landmarks)))

    def observation_counts(self) -> NDArray[np.int64]:
        """Number of line factors on each landmark, ``(M,)``."""
        return np.bincount(self.factor_landmark, minlength=self.n_landmarks).astype(np.int64)

    def world_endpoints(self, factors: IntArray | None = None) -> FloatArray:
        """Measured end points moved into the world with the current pose estimate."""
        f = np.arange(self.n_line_factors) if factors is None else np.asarray(factors)
        ep = self.factor_endpoints[f]
        poses = self.poses[self.factor_pose[f]]
        pts = np.concatenate([ep, np.zeros((*ep.shape[:-1], 1))], axis=-1)
        return pose_compose(np.broadcast_to(poses[:, None, :], pts.shape), pts)[..., :2]

    def factor_extents(self, factors: IntArray | None = None) -> FloatArray:
        """Interval ``(s_min, s_max)`` of each factor's measured segment along its landmark.

        ``s = (p − c)·t`` is the coordinate of a world point ``p`` along the tangent
        ``t = (−sin α, cos α)`` of the landmark's current estimate, measured from its anchor
        ``c`` (so that small rotations of the landmark barely move it); the end points are
        moved into the world with the current pose estimate.  Shape ``(F, 2)``.
        """
        f = np.arange(self.n_line_factors) if factors is None else np.asarray(factors)
        lm = self.factor_landmark[f]
        theta = self.poses[self.factor_pose[f], 2]
        a = self.landmarks[lm, 1]  # φ = α
        trig = np.empty((4, f.shape[0]))
        np.cos(theta, out=trig[0])
        np.sin(theta, out=trig[1])
        np.negative(np.sin(a), out=trig[2])
        np.cos(a, out=trig[3])
        out = np.empty((f.shape[0], 2))
        _extents_kernel(
            self.factor_endpoints[f], self.poses[self.factor_pose[f]], self.anchors[lm], trig, out
        )
        return out

    def landmark_extents(self) -> FloatArray:
        """Extent ``(s_min, s_max)`` of each landmark (see :meth:`factor_extents`), ``(M, 2)``.

        The union of its factors' intervals; landmarks without factors get ``(nan, nan)``.
        """
        if self.n_line_factors == 0:
            return np.full((self.n_landmarks, 2), np.nan)
        return unite_factor_extents(self.factor_extents(), self.factor_landmark, self.n_landmarks)
