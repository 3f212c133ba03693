"""From numpy linearisations to GTSAM linear systems (and back).

* Line, odometry and prior factors, linearised in numpy, become pre-whitened
  ``gtsam.JacobianFactor``s with unit noise: one Python constructor call each (~4 µs), never a
  Python callback from inside GTSAM.
* A factor's ``[A | b]`` is also writable in place (``getA``/``getb`` are views of it):
  :class:`ReusableGraph` keeps the factors of one linear system and, when the next system has
  the same keys and shapes, overwrites their values instead of constructing new factors
  (~0.4 µs a factor instead of ~4 µs).
* GTSAM eliminates the ``GaussianFactorGraph``; the solution's ``VectorValues.vector()`` (one
  C++ call) is split into per-variable updates by key order: landmarks ``L(j)`` sort before
  poses ``X(i)`` (``'l' < 'x'``), each group by index.
* For iSAM2 (whose odometry factors are native): ``native_odometry_factors``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from slam.errors import EstimationError
from slam.graph.factors import LineLinearization
from slam.graph.problem import LineGraph

__all__ = [
    "UNIT2",
    "UNIT3",
    "FactorBatch",
    "JacobianRows",
    "ReusableGraph",
    "key_array",
    "keys_of",
    "landmark_prior_batch",
    "landmark_prior_factors",
    "line_factor_groups",
    "line_jacobian_batch",
    "line_jacobian_factors",
    "native_odometry_factors",
    "odometry_jacobian_batch",
    "odometry_jacobian_factors",
    "pairing_order",
    "split_delta",
    "unary_batch",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

UNIT2 = gtsam.noiseModel.Unit.Create(2)
UNIT3 = gtsam.noiseModel.Unit.Create(3)
UNIT4 = gtsam.noiseModel.Unit.Create(4)
UNIT6 = gtsam.noiseModel.Unit.Create(6)
_UNIT = {2: UNIT2, 3: UNIT3, 4: UNIT4, 6: UNIT6}
_X = np.uint64(ord("x")) << np.uint64(56)
_L = np.uint64(ord("l")) << np.uint64(56)


def keys_of(kind: str, indices: IntArray) -> list[int]:
    """GTSAM keys ``X(i)`` (``kind="x"``) or ``L(j)`` (``kind="l"``) as Python ints, vectorised."""
    keys: list[int] = key_array(kind, indices).tolist()
    return keys


def key_array(kind: str, indices: IntArray) -> NDArray[np.uint64]:
    """GTSAM keys ``X(i)`` (``kind="x"``) or ``L(j)`` (``kind="l"``) as a ``uint64`` array."""
    base = _X if kind == "x" else _L
    keys: NDArray[np.uint64] = np.asarray(indices, dtype=np.uint64) + base
    return keys


@dataclass(frozen=True, eq=False)
class JacobianRows:
    """``n`` pre-whitened factors of one shape (unit noise), stacked.

    Attributes
    ----------
    keys : ndarray, shape (n, k), uint64
        The GTSAM keys of each factor, in the order of its blocks.
    widths : tuple of int
        Columns of each of the ``k`` blocks.
    A : ndarray, shape (n, m, sum(widths))
        Each factor's ``[A_1 … A_k]`` (``m`` rows).
    b : ndarray, shape (n, m)
        Each factor's right-hand side.
    """

    keys: NDArray[np.uint64]
    widths: tuple[int, ...]
    A: FloatArray
    b: FloatArray

    def __len__(self) -> int:
        return int(self.A.shape[0])

    def factors(self) -> list[gtsam.JacobianFactor]:
        """One ``gtsam.JacobianFactor`` per row, unit noise."""
        cols = np.cumsum((0, *self.widths))
        args: list[Any] = []
        for k in range(len(self.widths)):
            args += [self.keys[:, k].tolist(), self.A[:, :, cols[k] : cols[k + 1]]]
        args.append(self.b)
        noise = _UNIT[self.A.shape[1]]
        make: Any = gtsam.JacobianFactor  # (its stubs list the overloads, not *args)
        return [make(*row, noise) for row in zip(*args, strict=True)]


@dataclass(frozen=True, eq=False)
class FactorBatch:
    """Factors of several shapes in one order.

    Attributes
    ----------
    rows : tuple of JacobianRows
        The factors of each shape.
    kind : ndarray, shape (n,)
        Which of ``rows`` each factor comes from; ``rows[g]``'s factors fill the places where
        ``kind == g``, in their order.
    """

    rows: tuple[JacobianRows, ...]
    kind: IntArray

    def factors(self) -> list[gtsam.JacobianFactor]:
        """The ``gtsam.JacobianFactor``s in order."""
        out: list[gtsam.JacobianFactor] = [None] * self.kind.shape[0]  # type: ignore[list-item]
        for g, rows in enumerate(self.rows):
            for slot, f in zip(
                np.flatnonzero(self.kind == g).tolist(), rows.factors(), strict=True
            ):
                out[slot] = f
        return out


def unary_batch(keys: NDArray[np.uint64], A: FloatArray, b: FloatArray) -> FactorBatch:
    """One-key factors ``‖A_i δ_{key_i} − b_i‖²``: ``A`` ``(n, m, d)``, ``b`` ``(n, m)``."""
    rows = JacobianRows(np.asarray(keys, dtype=np.uint64).reshape(-1, 1), (A.shape[2],), A, b)
    return FactorBatch((rows,), np.zeros(len(rows), np.intp))


def line_jacobian_factors(
    pose_index: IntArray, landmark_index: IntArray, lin: LineLinearization
) -> list[gtsam.JacobianFactor]:
    """Pre-whitened ``JacobianFactor``s (unit noise) of linearised line factors.

    Two consecutive line factors of the same pose on different landmarks share one 3-key
    factor (pose, both landmarks; 4 rows, zero blocks where a row does not involve a
    landmark): half the constructor calls (~5 µs each) for the same rows.  The factors keep
    the order of their rows; :func:`line_factor_groups` says which line factors each holds.
    """
    return line_jacobian_batch(pose_index, landmark_index, lin).factors()


def line_jacobian_batch(
    pose_index: IntArray, landmark_index: IntArray, lin: LineLinearization
) -> FactorBatch:
    """The factors of :func:`line_jacobian_factors` as a :class:`FactorBatch` (numpy only)."""
    first, paired = line_factor_groups(pose_index, landmark_index)
    Ap, Al, b = lin.A_pose, lin.A_landmark, lin.b
    f = first[paired]  # rows of factor f then f + 1, both landmarks
    A2 = np.zeros((f.shape[0], 4, 7))
    A2[:, :2, :3] = Ap[f]
    A2[:, 2:, :3] = Ap[f + 1]
    A2[:, :2, 3:5] = Al[f]
    A2[:, 2:, 5:7] = Al[f + 1]
    pairs = JacobianRows(
        np.stack(
            [
                key_array("x", pose_index[f]),
                key_array("l", landmark_index[f]),
                key_array("l", landmark_index[f + 1]),
            ],
            axis=1,
        ),
        (3, 2, 2),
        A2,
        np.concatenate([b[f], b[f + 1]], axis=1),
    )
    g = first[~paired]
    singles = JacobianRows(
        np.stack([key_array("x", pose_index[g]), key_array("l", landmark_index[g])], axis=1),
        (3, 2),
        np.concatenate([Ap[g], Al[g]], axis=2),
        b[g],
    )
    return FactorBatch((pairs, singles), (~paired).astype(np.intp))


def line_factor_groups(
    pose_index: IntArray, landmark_index: IntArray
) -> tuple[IntArray, NDArray[np.bool_]]:
    """How :func:`line_jacobian_factors` groups line factors.

    Returns the first line factor of each group and whether the group also holds the next
    one (same pose, another landmark; pairs taken in order, :func:`_pairs_in_order`).
    """
    can = np.zeros(pose_index.shape[0], bool)
    can[:-1] = (pose_index[1:] == pose_index[:-1]) & (landmark_index[1:] != landmark_index[:-1])
    return _pairs_in_order(can)


def pairing_order(pose_index: IntArray, landmark_index: IntArray) -> IntArray:
    """An order of line factors in which :func:`line_jacobian_factors` pairs the most.

    Grouped by pose; within a pose the first factor on each landmark, then the second ones,
    ... (so that a pose's two factors on one landmark are not neighbours).  The factors of a
    graph come in the order they were added, which interleaves poses (a tentative landmark's
    factors arrive when it is promoted) and repeats landmarks.
    """
    n = pose_index.shape[0]
    if n == 0:
        return np.zeros(0, np.intp)
    by_pair = np.lexsort((landmark_index, pose_index))
    p, m = pose_index[by_pair], landmark_index[by_pair]
    new_run = np.r_[True, (p[1:] != p[:-1]) | (m[1:] != m[:-1])]
    run_start = np.maximum.accumulate(np.where(new_run, np.arange(n), 0))
    rank = np.empty(n, np.intp)
    rank[by_pair] = np.arange(n) - run_start
    return np.lexsort((landmark_index, rank, pose_index)).astype(np.intp)


def _pairs_in_order(can: NDArray[np.bool_]) -> tuple[IntArray, NDArray[np.bool_]]:
    """Greedy pairing of neighbours: ``can[i]`` says item ``i`` may pair with ``i + 1``.

    Within each run of such items every other one leads a pair (the 1st, 3rd, ...).  Returns
    the first item of each group and whether the group is a pair.
    """
    n = can.shape[0]
    run_first = can & ~np.r_[False, can[:-1]]
    run_start = np.maximum.accumulate(np.where(run_first, np.arange(n), 0))
    lead = can & ((np.arange(n) - run_start) % 2 == 0)
    taken = np.zeros(n, bool)
    taken[1:] = lead[:-1]
    first = np.flatnonzero(~taken)
    return first, lead[first]


def landmark_prior_factors(
    landmark_index: IntArray, A_landmark: FloatArray, b: FloatArray
) -> list[gtsam.JacobianFactor]:
    """Line factors from constant poses, summed into one ``JacobianFactor`` per landmark.

    Rows ``‖A_k δ − b_k‖²`` on the same landmark add up to ``‖R δ − d‖² + const`` with
    ``RᵀR = Σ A_kᵀA_k`` (Cholesky) and ``Rᵀd = Σ A_kᵀb_k``: the same linear system with one
    factor per landmark instead of one per line factor (constructing a factor costs ~5 µs).
    A landmark whose sum is not safely positive definite keeps its factors one by one.

    Parameters
    ----------
    landmark_index : ndarray, shape (F,)
    A_landmark : ndarray, shape (F, 2, 2)
        Pre-whitened Jacobians.
    b : ndarray, shape (F, 2)
        Pre-whitened right-hand sides.
    """
    return landmark_prior_batch(landmark_index, A_landmark, b).factors()


def landmark_prior_batch(
    landmark_index: IntArray, A_landmark: FloatArray, b: FloatArray
) -> FactorBatch:
    """The factors of :func:`landmark_prior_factors` as a :class:`FactorBatch` (numpy only)."""
    lms, inverse = np.unique(landmark_index, return_inverse=True)
    H = np.zeros((lms.shape[0], 2, 2))
    g = np.zeros((lms.shape[0], 2))
    np.add.at(H, inverse, np.einsum("fki,fkj->fij", A_landmark, A_landmark))
    np.add.at(g, inverse, np.einsum("fki,fk->fi", A_landmark, b))
    det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]
    trace = H[:, 0, 0] + H[:, 1, 1]
    pd = (H[:, 0, 0] > 0.0) & (det > 1e-10 * trace**2)
    R = np.zeros((0, 2, 2))
    d = np.zeros((0, 2))
    if np.any(pd):
        L = np.linalg.cholesky(H[pd])  # H = L Lᵀ, R = Lᵀ
        d = np.linalg.solve(L, g[pd][:, :, None])[:, :, 0]
        R = np.transpose(L, (0, 2, 1))
    single = np.flatnonzero(~pd[inverse])
    keys = np.concatenate([key_array("l", lms[pd]), key_array("l", landmark_index[single])])
    rows = JacobianRows(
        keys.reshape(-1, 1),
        (2,),
        np.concatenate([R, A_landmark[single]]),
        np.concatenate([d, b[single]]),
    )
    return FactorBatch((rows,), np.zeros(len(rows), np.intp))


def landmark_link_batch(
    first: IntArray, second: IntArray, landmarks: FloatArray, sqrt_info: FloatArray
) -> tuple[FactorBatch, FloatArray]:
    """Links ``v_first − v_second ~ N(0, Σ)`` between landmarks (one chart), linearised.

    The residual is linear in the chart: ``W (v_first + δ₁ − v_second − δ₂)`` (``φ`` wrapped),
    so each factor is ``[W, −W]`` with ``b = −W (v_first − v_second)``.  Returns the batch
    and the whitened residuals ``(k, 2)``.
    """
    d = np.asarray(landmarks[first] - landmarks[second], dtype=float).reshape(-1, 2)
    d[:, 1] = np.remainder(d[:, 1] + np.pi, 2.0 * np.pi) - np.pi
    W = np.asarray(sqrt_info, dtype=float).reshape(-1, 2, 2)
    r = np.einsum("kij,kj->ki", W, d)
    rows = JacobianRows(
        np.stack([key_array("l", first), key_array("l", second)], axis=1),
        (2, 2),
        np.concatenate([W, -W], axis=2),
        -r,
    )
    return FactorBatch((rows,), np.zeros(first.shape[0], dtype=np.intp)), r


def odometry_jacobian_factors(
    first: IntArray, second: IntArray, A_first: FloatArray, A_second: FloatArray, b: FloatArray
) -> list[gtsam.JacobianFactor]:
    """Pre-whitened ``JacobianFactor``s of odometry factors (two 3×3 blocks each).

    Two consecutive factors of a chain (``x_a → x_b``, ``x_b → x_c``) share one 3-key factor
    (6 rows, zero blocks where a row does not involve a pose): the same rows in order, half
    the constructor calls.
    """
    return odometry_jacobian_batch(first, second, A_first, A_second, b).factors()


def odometry_jacobian_batch(
    first: IntArray, second: IntArray, A_first: FloatArray, A_second: FloatArray, b: FloatArray
) -> FactorBatch:
    """The factors of :func:`odometry_jacobian_factors` as a :class:`FactorBatch` (numpy only)."""
    can = np.zeros(first.shape[0], bool)
    can[:-1] = (second[:-1] == first[1:]) & (first[1:] != first[:-1])
    heads, paired = _pairs_in_order(can)
    f = heads[paired]
    A2 = np.zeros((f.shape[0], 6, 9))
    A2[:, :3, 0:3] = A_first[f]
    A2[:, :3, 3:6] = A_second[f]
    A2[:, 3:, 3:6] = A_first[f + 1]
    A2[:, 3:, 6:9] = A_second[f + 1]
    pairs = JacobianRows(
        np.stack(
            [key_array("x", first[f]), key_array("x", second[f]), key_array("x", second[f + 1])],
            axis=1,
        ),
        (3, 3, 3),
        A2,
        np.concatenate([b[f], b[f + 1]], axis=1),
    )
    g = heads[~paired]
    singles = JacobianRows(
        np.stack([key_array("x", first[g]), key_array("x", second[g])], axis=1),
        (3, 3),
        np.concatenate([A_first[g], A_second[g]], axis=2),
        b[g],
    )
    return FactorBatch((pairs, singles), (~paired).astype(np.intp))


def _writable_views(
    factors: list[gtsam.JacobianFactor], rows: JacobianRows
) -> list[tuple[FloatArray, FloatArray]] | None:
    """Writable views ``(A, b)`` of the factors' own memory (None if a view is not such)."""
    views = []
    for f in factors:
        A, b = f.getA(), f.getb()
        if A.shape != rows.A.shape[1:] or b.shape != rows.b.shape[1:]:
            return None
        if not (A.flags.writeable and b.flags.writeable) or A.flags.owndata or b.flags.owndata:
            return None
        views.append((A, b))
    return views


class ReusableGraph:
    """A ``GaussianFactorGraph`` whose factors are overwritten when only their values change.

    :meth:`load` returns a graph of the batches' factors in order: the graph it returned last
    time, with every factor's ``A`` and ``b`` overwritten in place (``getA`` and ``getb`` are
    views of the factor's memory), when the batches have the same kinds, keys and shapes as
    then: the same factors bit for bit as new ones would be.  Otherwise a new graph.  A graph
    returned earlier thus changes with the next :meth:`load`: it is for one iterative solve.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget the last graph (the next :meth:`load` builds a new one)."""
        self._batches: list[FactorBatch] | None = None
        self._factors: list[list[gtsam.JacobianFactor]] = []
        self._views: list[list[tuple[FloatArray, FloatArray]]] | None = None
        self._graph: gtsam.GaussianFactorGraph | None = None

    def _same_structure(self, batches: list[FactorBatch]) -> bool:
        old = self._batches
        if old is None or len(old) != len(batches):
            return False
        for a, b in zip(old, batches, strict=True):
            if len(a.rows) != len(b.rows) or not np.array_equal(a.kind, b.kind):
                return False
            for ra, rb in zip(a.rows, b.rows, strict=True):
                if (
                    ra.widths != rb.widths
                    or ra.A.shape != rb.A.shape
                    or not np.array_equal(ra.keys, rb.keys)
                ):
                    return False
        return True

    def _rewrite(self, batches: list[FactorBatch]) -> bool:
        """Overwrite the last graph's factors with the batches' values; False if impossible."""
        if self._views is None:  # the views are made when first needed
            made = []
            groups = (rows for batch in batches for rows in batch.rows)
            for factors, rows in zip(self._factors, groups, strict=True):
                v = _writable_views(factors, rows)
                if v is None:
                    return False
                made.append(v)
            self._views = made
        groups = (rows for batch in batches for rows in batch.rows)
        for views, rows in zip(self._views, groups, strict=True):
            for (A, b), A_new, b_new in zip(views, rows.A, rows.b, strict=True):
                A[...] = A_new
                b[...] = b_new
        return True

    def load(self, batches: list[FactorBatch]) -> gtsam.GaussianFactorGraph:
        """The batches' factors, in order, as a graph (class docstring)."""
        if self._graph is not None and self._same_structure(batches) and self._rewrite(batches):
            self._batches = batches
            return self._graph
        gfg = gtsam.GaussianFactorGraph()
        groups: list[list[gtsam.JacobianFactor]] = []
        for batch in batches:
            factors = batch.factors()
            for f in factors:
                gfg.push_back(f)
            for g in range(len(batch.rows)):
                groups.append([factors[i] for i in np.flatnonzero(batch.kind == g).tolist()])
        self._batches, self._factors, self._views, self._graph = batches, groups, None, gfg
        return gfg


def split_delta(
    delta: gtsam.VectorValues, n_landmarks: int, n_poses: int
) -> tuple[FloatArray, FloatArray]:
    """Per-variable updates ``(n_landmarks, 2)`` and ``(n_poses, 3)`` from a solution.

    The solution must hold exactly ``n_landmarks`` landmarks and ``n_poses`` poses; the
    landmarks come first in key order.

    Raises
    ------
    EstimationError
        The solution lacks variables: GTSAM solves only the variables of some factor.
    """
    v = np.asarray(delta.vector(), dtype=float)
    n_l = 2 * n_landmarks
    if v.shape[0] != n_l + 3 * n_poses:
        raise EstimationError(
            "linear system could not be solved: a variable has no factor (indeterminant)"
        )
    return v[:n_l].reshape(n_landmarks, 2), v[n_l:].reshape(n_poses, 3)


def native_odometry_factors(
    graph: LineGraph, start: int = 0, with_prior: bool = True
) -> gtsam.NonlinearFactorGraph:
    """Native factors of ``graph``: the prior (if set and asked for) and odometry ``start:``."""
    nfg = gtsam.NonlinearFactorGraph()
    if with_prior and graph.prior_pose is not None and graph.prior_cov is not None:
        p = graph.prior_pose
        nfg.add(
            gtsam.PriorFactorPose2(
                keys_of("x", np.array([0]))[0],
                gtsam.Pose2(*p),
                gtsam.noiseModel.Gaussian.Covariance(graph.prior_cov),
            )
        )
    first = keys_of("x", graph.odometry_first[start:])
    second = keys_of("x", graph.odometry_second[start:])
    for a, b, m, c in zip(
        first, second, graph.odometry_measured[start:], graph.odometry_cov[start:], strict=True
    ):
        nfg.add(
            gtsam.BetweenFactorPose2(a, b, gtsam.Pose2(*m), gtsam.noiseModel.Gaussian.Covariance(c))
        )
    return nfg
