"""From numpy linearisations to GTSAM linear systems (and back).

* Line, odometry and prior factors, linearised in numpy, become pre-whitened
  ``gtsam.JacobianFactor``s with unit noise: one Python constructor call each (~4 µs), never a
  Python callback from inside GTSAM.
* GTSAM eliminates the ``GaussianFactorGraph``; the solution's ``VectorValues.vector()`` (one
  C++ call) is split into per-variable updates by key order: landmarks ``L(j)`` sort before
  poses ``X(i)`` (``'l' < 'x'``), each group by index.
* For iSAM2 (whose odometry factors are native): ``native_odometry_factors``.
"""

from __future__ import annotations

from collections.abc import Iterable
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
    "keys_of",
    "landmark_prior_factors",
    "line_factor_groups",
    "line_jacobian_factors",
    "native_odometry_factors",
    "odometry_jacobian_factors",
    "pairing_order",
    "split_delta",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

UNIT2 = gtsam.noiseModel.Unit.Create(2)
UNIT3 = gtsam.noiseModel.Unit.Create(3)
UNIT4 = gtsam.noiseModel.Unit.Create(4)
UNIT6 = gtsam.noiseModel.Unit.Create(6)
_X = np.uint64(ord("x")) << np.uint64(56)
_L = np.uint64(ord("l")) << np.uint64(56)


def keys_of(kind: str, indices: IntArray) -> list[int]:
    """GTSAM keys ``X(i)`` (``kind="x"``) or ``L(j)`` (``kind="l"``) as Python ints, vectorised."""
    base = _X if kind == "x" else _L
    idx = np.asarray(indices, dtype=np.uint64)
    keys: list[int] = (idx + base).tolist()
    return keys


def line_jacobian_factors(
    pose_index: IntArray, landmark_index: IntArray, lin: LineLinearization
) -> list[gtsam.JacobianFactor]:
    """Pre-whitened ``JacobianFactor``s (unit noise) of linearised line factors.

    Two consecutive line factors of the same pose on different landmarks share one 3-key
    factor (pose, both landmarks; 4 rows, zero blocks where a row does not involve a
    landmark): half the constructor calls (~5 µs each) for the same rows.  The factors keep
    the order of their rows; :func:`line_factor_groups` says which line factors each holds.
    """
    first, paired = line_factor_groups(pose_index, landmark_index)
    Ap, Al, b = lin.A_pose, lin.A_landmark, lin.b
    f = first[paired]  # rows of factor f then f + 1, both landmarks
    A_1 = np.zeros((f.shape[0], 4, 2))
    A_1[:, :2] = Al[f]
    A_2 = np.zeros((f.shape[0], 4, 2))
    A_2[:, 2:] = Al[f + 1]
    pairs = zip(
        keys_of("x", pose_index[f]),
        np.concatenate([Ap[f], Ap[f + 1]], axis=1),
        keys_of("l", landmark_index[f]),
        A_1,
        keys_of("l", landmark_index[f + 1]),
        A_2,
        np.concatenate([b[f], b[f + 1]], axis=1),
        strict=True,
    )
    g = first[~paired]
    singles = zip(
        keys_of("x", pose_index[g]),
        Ap[g],
        keys_of("l", landmark_index[g]),
        Al[g],
        b[g],
        strict=True,
    )
    return _place(paired, pairs, UNIT4, singles, UNIT2)


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


def _place(
    paired: NDArray[np.bool_],
    pairs: Iterable[tuple[Any, ...]],
    pair_noise: gtsam.noiseModel.Base,
    singles: Iterable[tuple[Any, ...]],
    single_noise: gtsam.noiseModel.Base,
) -> list[gtsam.JacobianFactor]:
    """``JacobianFactor(*args, noise)`` for the groups in order: pairs where ``paired``."""
    out: list[gtsam.JacobianFactor] = [None] * paired.shape[0]  # type: ignore[list-item]
    make: Any = gtsam.JacobianFactor  # (its stubs list the overloads, not *args)
    for slot, args in zip(np.flatnonzero(paired).tolist(), pairs, strict=True):
        out[slot] = make(*args, pair_noise)
    for slot, args in zip(np.flatnonzero(~paired).tolist(), singles, strict=True):
        out[slot] = make(*args, single_noise)
    return out


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
    lms, inverse = np.unique(landmark_index, return_inverse=True)
    H = np.zeros((lms.shape[0], 2, 2))
    g = np.zeros((lms.shape[0], 2))
    np.add.at(H, inverse, np.einsum("fki,fkj->fij", A_landmark, A_landmark))
    np.add.at(g, inverse, np.einsum("fki,fk->fi", A_landmark, b))
    det = H[:, 0, 0] * H[:, 1, 1] - H[:, 0, 1] * H[:, 1, 0]
    trace = H[:, 0, 0] + H[:, 1, 1]
    pd = (H[:, 0, 0] > 0.0) & (det > 1e-10 * trace**2)
    factors: list[gtsam.JacobianFactor] = []
    if np.any(pd):
        L = np.linalg.cholesky(H[pd])  # H = L Lᵀ, R = Lᵀ
        d = np.linalg.solve(L, g[pd][:, :, None])[:, :, 0]
        R = np.transpose(L, (0, 2, 1))
        for key, Rj, dj in zip(keys_of("l", lms[pd]), R, d, strict=True):
            factors.append(gtsam.JacobianFactor(key, Rj, dj, UNIT2))
    single = np.flatnonzero(~pd[inverse])
    for key, A, rhs in zip(
        keys_of("l", landmark_index[single]), A_landmark[single], b[single], strict=True
    ):
        factors.append(gtsam.JacobianFactor(key, A, rhs, UNIT2))
    return factors


def odometry_jacobian_factors(
    first: IntArray, second: IntArray, A_first: FloatArray, A_second: FloatArray, b: FloatArray
) -> list[gtsam.JacobianFactor]:
    """Pre-whitened ``JacobianFactor``s of odometry factors (two 3×3 blocks each).

    Two consecutive factors of a chain (``x_a → x_b``, ``x_b → x_c``) share one 3-key factor
    (6 rows, zero blocks where a row does not involve a pose): the same rows in order, half
    the constructor calls.
    """
    can = np.zeros(first.shape[0], bool)
    can[:-1] = (second[:-1] == first[1:]) & (first[1:] != first[:-1])
    heads, paired = _pairs_in_order(can)
    f = heads[paired]
    z = np.zeros((f.shape[0], 3, 3))
    pairs = zip(
        keys_of("x", first[f]),
        np.concatenate([A_first[f], z], axis=1),
        keys_of("x", second[f]),
        np.concatenate([A_second[f], A_first[f + 1]], axis=1),
        keys_of("x", second[f + 1]),
        np.concatenate([z, A_second[f + 1]], axis=1),
        np.concatenate([b[f], b[f + 1]], axis=1),
        strict=True,
    )
    g = heads[~paired]
    singles = zip(
        keys_of("x", first[g]), A_first[g], keys_of("x", second[g]), A_second[g], b[g], strict=True
    )
    return _place(paired, pairs, UNIT6, singles, UNIT3)


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
