"""Passes along the walls: how far they disagree, and the error each pass shares.

A line factor's covariance treats every observation of a wall as independent of the others.
If the wall's departures from a straight line (or anything else shared by observations from
nearby poses) make the observations of one *pass* along it err together, a pass averages
them far less than the factors say, and two passes disagree by more than the factors' own
covariances allow.  Loop closures join such passes, so this is where a run's relative poses
across loops would be over-confident.

**Passes.**  Each landmark's factors are split into passes: consecutive observations (in
time) less than ``gap_s`` apart are one pass (:func:`find_passes`).  Each factor is linearised
at the estimate with the run's robust kernel (its IRLS weight included), in the landmark's
anchored chart, ``A_l δ ≈ b`` (:func:`slam.graph.factors.linearize_line_factors`), so a pass
``p`` with factors ``i`` sees the landmark moved by

``m_p = (Σ A_lᵢᵀ A_lᵢ)⁻¹ Σ A_lᵢᵀ bᵢ``,   ``C_p = (Σ A_lᵢᵀ A_lᵢ)⁻¹``

with the poses held at their estimates.

**Consistency** (:func:`pass_consistency`).  For two passes of one landmark, ``d = m_p − m_q``
and ``t = dᵀ (C_p + C_q)⁻¹ d``; ``t_angle = d_φ² / (C_p + C_q)_φφ`` is its angle part.  With
the poses and landmarks at the truth and the factors' covariances true, ``t`` is χ²₂ and
``t_angle`` χ²₁ (``tests/test_passes.py``).  The report gives their medians over all pairs of
passes of every landmark, each divided by its χ² median, and the fraction of pairs beyond
χ²₂'s 95 % quantile.  At a run's estimate the poses have been fitted to these same factors,
loop closures included, which pulls the passes together: on simulated walls, where the
factors' model is true, the ratio comes out below 1.  Compare runs with it, not with 1.

**The pass error** (:func:`estimate_pass_error`, :func:`with_pass_links`).  Each pass sees its
wall moved by an error of its own, shared by all its observations: an offset ``σ_o`` along
the normal and an angle ``σ_a`` about the pass's place on the line (the foot of its mean
observing position; in the chart ``[[σ_o² + u²σ_a², uσ_a²], [uσ_a², σ_a²]]``, ``u`` that
place's tangent coordinate from the anchor).  Both are estimated from the pairs of passes as
the line factors' model error is (:mod:`slam.line_slam.line_noise`, Huber's Proposal 2), on
the angle part of each pair's difference and on its offset at the pair's middle place, with
the difference's covariance at the fit (:meth:`Passes.fitted_pair_terms`: the measurement
noise's part, and the part of each pass's own error the fit leaves in it)
(:func:`estimate_pass_error`), where the pairs disagree beyond chance (:data:`SIGNIFICANCE`).
In the graph each pass of a wall seen in two passes or more
becomes a landmark of its own, anchored as the wall, holding its factors and linked to the
wall by ``v_pass − v_wall ~ N(0, B_p)``
(:meth:`slam.graph.problem.LineGraph.add_landmark_links`): the observations of a pass share
one error, those of different passes do not.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import EvaluationError
from slam.graph.batch import BatchSolver
from slam.graph.config import SolverConfig
from slam.graph.factors import linearize_line_factors, sqrt_information_2x2
from slam.graph.linear import keys_of
from slam.graph.problem import LineGraph
from slam.graph.relative import information_factor, line_graph_from_file
from slam.io.g2o import read_line_graph_g2o
from slam.line_slam.line_noise import _sigma2_for_moment, excess_is_significant
from slam.models.anchored import r_alpha_from_anchored

__all__ = [
    "FittedPairs",
    "PassConsistency",
    "PassError",
    "Passes",
    "estimate_pass_error",
    "find_passes",
    "fitted_pairs",
    "pass_consistency",
    "pass_consistency_of_results",
    "pass_covariance",
    "with_pass_links",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

CHI2_2_MEDIAN = 2.0 * math.log(2.0)
"""Median of χ²₂."""
CHI2_1_MEDIAN = 0.454936423119572
"""Median of χ²₁."""
CHI2_2_95 = -2.0 * math.log(0.05)
"""95 % quantile of χ²₂."""


@dataclass(frozen=True)
class PassConsistency:
    """How far passes along the same walls agree (module docstring).

    Attributes
    ----------
    gap_s : float
        Observations of a landmark this far apart in time (s) or more start a new pass.
    landmarks : int
        Landmarks with at least two passes of ``min_observations``.
    pairs : int
        Pairs of passes compared.
    median_ratio : float
        Median of ``t`` over the pairs divided by the χ²₂ median (1 when the model holds).
    median_ratio_angle : float
        The same for the angle alone (χ²₁).
    fraction_beyond_95 : float
        Pairs with ``t`` above χ²₂'s 95 % quantile (0.05 expected).
    pass_error_sigma_offset_m, pass_error_sigma_angle_rad : float
        The pass error estimated from the same pairs (:func:`estimate_pass_error`; NaN when
        not judged at the fit or with fewer than :data:`MIN_PAIRS` pairs).
    median_ratio_with_pass_error, fraction_beyond_95_with_pass_error : float
        ``median_ratio`` and ``fraction_beyond_95`` with that pass error in each pair's
        covariance (``S + T_a B_a T_aᵀ + T_b B_b T_bᵀ``): how well the pass error explains
        the differences (NaN as the pass error).
    """

    gap_s: float
    landmarks: int
    pairs: int
    median_ratio: float
    median_ratio_angle: float
    fraction_beyond_95: float
    pass_error_sigma_offset_m: float = math.nan
    pass_error_sigma_angle_rad: float = math.nan
    median_ratio_with_pass_error: float = math.nan
    fraction_beyond_95_with_pass_error: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return asdict(self)


@dataclass(frozen=True)
class Passes:
    """A graph's line factors grouped into passes along their landmarks (module docstring).

    Attributes
    ----------
    gap_s : float
        Observations of a landmark this far apart in time (s) or more start a new pass.
    factor_pass : ndarray of int, shape (F,)
        Pass of each line factor.
    landmark : ndarray of int, shape (P,)
        Landmark of each pass (passes of one landmark are consecutive, in time order).
    count : ndarray of int, shape (P,)
        Factors in each pass.
    mean : ndarray, shape (P, 2)
        ``m_p``, the landmark as the pass sees it, relative to the estimate (chart ``(ρ, φ)``).
    cov : ndarray, shape (P, 2, 2)
        ``C_p``; NaN for a pass of fewer than ``min_observations`` factors or one that does
        not determine the line.
    place : ndarray, shape (P,)
        Tangent coordinate ``u`` (m) of the pass's place on its line, from the anchor.
    factor_pose : ndarray of int, shape (F,)
        Pose of each factor.
    factor_gain : ndarray, shape (F, 2, 3)
        ``∂m_p/∂ξ`` of each factor's pose: ``C_p A_lᵢᵀ A_xᵢ`` (NaN in passes without ``cov``).
    """

    gap_s: float
    factor_pass: IntArray
    landmark: IntArray
    count: IntArray
    mean: FloatArray
    cov: FloatArray
    place: FloatArray
    factor_pose: IntArray
    factor_gain: FloatArray

    def _pose_rows(
        self, p: int, blocks: FloatArray, pose_column: IntArray
    ) -> tuple[IntArray, IntArray, FloatArray]:
        """Rows, columns (0, 1) and values of ``(3, 2)`` blocks at the poses of pass ``p``."""
        f = self._factors_of(p)
        c0 = pose_column[self.factor_pose[f]]
        rows = (c0[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 2), np.intp)
        cols = np.broadcast_to(np.arange(2)[None, None, :], rows.shape)
        return rows.ravel(), cols.ravel(), blocks.ravel()

    @cached_property
    def _by_pass(self) -> tuple[IntArray, IntArray]:
        """The factors sorted by pass, and where each pass's start (``P + 1``)."""
        order = np.argsort(self.factor_pass, kind="stable")
        starts = np.searchsorted(self.factor_pass[order], np.arange(self.landmark.size + 1))
        return order, starts

    def _factors_of(self, p: int) -> IntArray:
        order, starts = self._by_pass
        return np.asarray(order[starts[p] : starts[p + 1]])

    def fitted_pair_terms(
        self,
        a: IntArray,
        b: IntArray,
        solve: Callable[[FloatArray], FloatArray],
        pose_column: IntArray,
        landmark_column: IntArray,
        n_columns: int,
        chunk: int = 256,
        pass_terms: bool = True,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(S, T_a, T_b)``, each ``(k, 2, 2)``: how ``m_a − m_b`` behaves at a fitted estimate.

        The residuals at the estimate are ``(I − A H⁻¹ Aᵀ) z`` (whitened), so the measurement
        noise gives ``m_a − m_b`` the covariance ``S = C_a + C_b − J H⁻¹ Jᵀ``, ``J`` its
        derivative in the poses of the two passes (the landmark's part cancels: both passes
        see the same landmark).  A pass's own error ``δ_p`` enters as ``T_a δ_a + T_b δ_b``
        with ``T_a = I − J H⁻¹ F_a`` and ``T_b = −I − J H⁻¹ F_b``, ``F_p = Aᵀ`` of the pass's
        factor rows moved by ``δ_p`` (the fit absorbs part of it).  ``solve(M)`` is ``H⁻¹ M``
        for ``M`` ``(n, m)`` (the graph's information,
        :func:`slam.graph.relative.information_factor`), ``n_columns`` its size;
        ``pose_column`` the first column of each pose in it, ``landmark_column`` that of each
        pass's landmark ``(P,)``.  ``pass_terms = False``: ``S`` only (``T_a = I``, ``T_b =
        −I``).
        """
        a = np.asarray(a, dtype=np.intp)
        b = np.asarray(b, dtype=np.intp)
        n = int(n_columns)
        S = self.cov[a] + self.cov[b]
        T_a = np.broadcast_to(np.eye(2), S.shape).copy()
        T_b = -T_a
        if a.size == 0:
            return S, T_a, T_b
        for lo in range(0, a.size, chunk):
            pa, pb = a[lo : lo + chunk], b[lo : lo + chunk]
            k = pa.size
            M = np.zeros((n, 2 * k))  # Jᵀ of each pair
            for j in range(k):
                for sign, p in ((1.0, int(pa[j])), (-1.0, int(pb[j]))):
                    blocks = sign * np.swapaxes(self.factor_gain[self._factors_of(p)], 1, 2)
                    r, c, v = self._pose_rows(p, blocks, pose_column)
                    np.add.at(M, (r, c + 2 * j), v)
            Mk = M.reshape(n, k, 2)
            X = np.asarray(solve(M)).reshape(n, k, 2)  # H⁻¹ Jᵀ
            S[lo : lo + k] -= np.einsum("nki,nkj->kij", Mk, X)
            if pass_terms:
                # J H⁻¹ F_p = (H⁻¹ Jᵀ)ᵀ F_p (H symmetric): no solve for F_p
                for T, side in ((T_a, pa), (T_b, pb)):
                    F = self._moved_normal_equations(side, pose_column, landmark_column, n)
                    T[lo : lo + k] -= np.einsum("nki,nkj->kij", X, F.reshape(n, k, 2))
        return S, T_a, T_b

    def _moved_normal_equations(
        self, passes: IntArray, pose_column: IntArray, landmark_column: IntArray, n: int
    ) -> FloatArray:
        """``F_p`` ``(n, 2)`` of each pass side by side, ``(n, 2·len(passes))``.

        What a pass's own error ``δ_p`` does to the normal equations: ``Aᵀ`` of the pass's
        factor rows moved by ``δ_p`` (:meth:`fitted_pair_terms`).
        """
        F = np.zeros((n, 2 * passes.size))
        for j, p in enumerate(passes.tolist()):
            info = np.linalg.inv(self.cov[p])
            blocks = np.swapaxes(info[None] @ self.factor_gain[self._factors_of(p)], 1, 2)
            r, c, v = self._pose_rows(p, blocks, pose_column)
            np.add.at(F, (r, c + 2 * j), v)
            F[landmark_column[p] : landmark_column[p] + 2, 2 * j : 2 * j + 2] += info
        return F

    def pairs(self, max_pairs: int | None = None, seed: int = 0) -> tuple[IntArray, IntArray]:
        """Every pair ``(a, b)`` of usable passes (finite ``cov``) of one landmark.

        With ``max_pairs``: at most that many of them, drawn without replacement with ``seed``
        (in their order).
        """
        kept = np.flatnonzero(np.isfinite(self.cov).all(axis=(1, 2)))
        lm = self.landmark[kept]
        bounds = np.flatnonzero(np.r_[True, lm[1:] != lm[:-1]])
        first: list[IntArray] = []
        second: list[IntArray] = []
        for group in np.split(kept, bounds[1:]):
            if group.size >= 2:
                a, b = np.triu_indices(group.size, 1)
                first.append(group[a])
                second.append(group[b])
        if not first:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        a, b = np.concatenate(first), np.concatenate(second)
        if max_pairs is not None and a.size > max_pairs:
            pick = np.sort(np.random.default_rng(seed).choice(a.size, max_pairs, replace=False))
            a, b = a[pick], b[pick]
        return a, b


def find_passes(
    graph: LineGraph,
    pose_timestamps: ArrayLike,
    robust_kernel: tuple[str, float] | None = None,
    gap_s: float = 30.0,
    min_observations: int = 3,
) -> Passes:
    """The passes of a graph's line factors at its estimate (module docstring).

    Parameters
    ----------
    graph : LineGraph
        Poses, landmarks and line factors at the estimate.
    pose_timestamps : array_like, shape (n_poses,)
        Time (s) of each pose.
    robust_kernel : (str, float), optional
        The kernel on the line factors and its width (default none).
    gap_s : float
        Time (s) between two observations of a landmark from which they are separate passes.
    min_observations : int
        Least number of factors in a pass for its ``cov`` to be given.

    Raises
    ------
    EvaluationError
        ``gap_s`` is not a positive number, or the time stamps are not one per pose.
    """
    if not (math.isfinite(gap_s) and gap_s > 0.0):
        raise EvaluationError(f"gap_s must be a positive number of seconds, got {gap_s!r}")
    stamps = np.asarray(pose_timestamps, dtype=float).reshape(-1)
    g = graph
    if stamps.shape[0] != g.n_poses:
        raise EvaluationError(f"{stamps.shape[0]} time stamps for {g.n_poses} poses")
    n = g.n_line_factors
    if n == 0:
        z = np.zeros(0, dtype=np.intp)
        empty = np.zeros((0, 2, 2))
        return Passes(gap_s, z, z, z, np.zeros((0, 2)), empty, np.zeros(0), z, np.zeros((0, 2, 3)))
    kernel, width = robust_kernel or ("none", 1.0)
    lm = g.factor_landmark[:n]
    fp = g.factor_pose[:n]
    lin = linearize_line_factors(
        g.poses[fp],
        g.landmarks[lm],
        g.anchors[lm],
        g.factor_z[:n],
        sqrt_information_2x2(g.factor_cov[:n]),
        kernel,  # type: ignore[arg-type]
        width,
    )
    A = lin.A_landmark
    info = np.swapaxes(A, 1, 2) @ A
    rhs = np.einsum("fji,fj->fi", A, lin.b)
    t_of = stamps[fp]
    order = np.lexsort((t_of, lm))
    lm_sorted, t_sorted = lm[order], t_of[order]
    # a new pass where the landmark changes or its observations are gap_s apart
    start = np.r_[True, (lm_sorted[1:] != lm_sorted[:-1]) | (np.diff(t_sorted) >= gap_s)]
    pass_sorted = np.cumsum(start) - 1
    n_pass = int(pass_sorted[-1]) + 1
    factor_pass = np.empty(n, dtype=np.intp)
    factor_pass[order] = pass_sorted
    count = np.bincount(factor_pass, minlength=n_pass)
    I_p = np.zeros((n_pass, 2, 2))
    r_p = np.zeros((n_pass, 2))
    np.add.at(I_p, factor_pass, info)
    np.add.at(r_p, factor_pass, rhs)
    pass_lm = lm_sorted[start]
    keep = (count >= min_observations) & (np.linalg.det(I_p) > 0.0)
    C_p = np.full_like(I_p, np.nan)
    C_p[keep] = np.linalg.inv(I_p[keep])
    m_p = np.einsum("pij,pj->pi", C_p, r_p)
    # the place of a pass: the foot of its mean observing position on the line
    xy = np.zeros((n_pass, 2))
    np.add.at(xy, factor_pass, g.poses[fp, :2])
    xy /= count[:, None]
    phi = g.landmarks[pass_lm, 1]
    tangent = np.column_stack([-np.sin(phi), np.cos(phi)])
    place = np.sum(tangent * (xy - g.anchors[pass_lm]), axis=1)
    gain = np.einsum("fij,fjk->fik", C_p[factor_pass], np.swapaxes(A, 1, 2) @ lin.A_pose)
    return Passes(gap_s, factor_pass, pass_lm, count, m_p, C_p, place, fp.copy(), gain)


@dataclass(frozen=True)
class FittedPairs:
    """Pairs of passes ``(a, b)`` and how their difference behaves at the fit (``(k, 2, 2)``).

    ``S``: covariance from the measurement noise; ``T_a``, ``T_b``: how each pass's own error
    enters (:meth:`Passes.fitted_pair_terms`).
    """

    a: IntArray
    b: IntArray
    S: FloatArray
    T_a: FloatArray
    T_b: FloatArray


def fitted_pairs(
    graph: LineGraph,
    passes: Passes,
    robust_kernel: tuple[str, float] | None = None,
    max_pairs: int | None = None,
    seed: int = 0,
    pass_terms: bool = True,
) -> FittedPairs:
    """Pairs of usable passes and how their differences behave at the graph's fit.

    :meth:`Passes.fitted_pair_terms` with the information of ``graph`` linearised at its
    estimate (:func:`slam.graph.relative.information_factor`, the kernel's weights in).
    Every pair, or ``max_pairs`` of them drawn without replacement with ``seed`` (each pair
    costs two solves with the information).  ``pass_terms = False``: ``S`` only (``T_a =
    I``, ``T_b = −I``).
    """
    kernel, width = robust_kernel or ("none", 1.0)
    solver = BatchSolver(SolverConfig(robust_kernel=kernel, robust_k=width))  # type: ignore[arg-type]
    a, b = passes.pairs(max_pairs, seed)
    if a.size == 0:
        empty = np.zeros((0, 2, 2))
        return FittedPairs(a, b, empty, empty, empty)
    A, lu, offset = information_factor(solver, graph)
    pose_column = np.array([offset[k] for k in keys_of("x", np.arange(graph.n_poses))])
    landmark_column = np.zeros(passes.landmark.size, dtype=np.intp)
    used = np.unique(np.r_[a, b])
    landmark_column[used] = [offset[k] for k in keys_of("l", passes.landmark[used])]
    S, T_a, T_b = passes.fitted_pair_terms(
        a, b, lu.solve, pose_column, landmark_column, A.shape[1], pass_terms=pass_terms
    )
    return FittedPairs(a, b, S, T_a, T_b)


def pass_consistency(
    graph: LineGraph,
    pose_timestamps: ArrayLike,
    robust_kernel: tuple[str, float] | None = None,
    gap_s: float = 30.0,
    min_observations: int = 3,
    fitted: bool = True,
    max_pairs: int | None = None,
) -> PassConsistency:
    """Between-pass consistency of a graph's landmarks at its estimate (module docstring).

    Arguments as :func:`find_passes`; ``min_observations`` is the least number of factors of
    a pass that is compared.  ``fitted``: each pair's ``t`` against the covariance of its
    difference at the fitted estimate (:func:`fitted_pairs`: about χ²₂ when the
    model holds), else against ``C_p + C_q`` (poses as if known); at the fit the pass error
    is estimated from the same pairs too and the pairs judged with it as well.  A graph with
    pass links (:func:`with_pass_links`) is judged on its walls: each pass landmark's factors
    count for the wall it is linked to, at the walls' fit (the same numbers as the graph
    without links).  ``max_pairs``: at most that many pairs, drawn with a fixed seed
    (:func:`fitted_pairs`).

    Raises
    ------
    EvaluationError
        ``gap_s`` is not a positive number, or the time stamps are not one per pose.
    """
    g = _walls(graph)
    passes = find_passes(g, pose_timestamps, robust_kernel, gap_s, min_observations)
    fit = None
    if fitted:
        fit = fitted_pairs(g, passes, robust_kernel, max_pairs)
        a, b, S = fit.a, fit.b, fit.S
    else:
        a, b = passes.pairs(max_pairs)
        S = passes.cov[a] + passes.cov[b]
    if a.size == 0:
        return PassConsistency(gap_s, 0, 0, math.nan, math.nan, math.nan)
    d = passes.mean[a] - passes.mean[b]

    def judged(S: FloatArray) -> FloatArray:
        return np.asarray(np.einsum("ki,kij,kj->k", d, np.linalg.inv(S), d))

    t = judged(S)
    ta = d[:, 1] ** 2 / S[:, 1, 1]
    with_error: dict[str, float] = {}
    if fit is not None and a.size >= MIN_PAIRS:
        error = estimate_pass_error(passes, fit)
        B_a, B_b = (
            pass_covariance(passes.place[p], error.sigma_offset_m, error.sigma_angle_rad)
            for p in (a, b)
        )
        t_p = judged(
            S
            + fit.T_a @ B_a @ np.swapaxes(fit.T_a, 1, 2)
            + fit.T_b @ B_b @ np.swapaxes(fit.T_b, 1, 2)
        )
        with_error = {
            "pass_error_sigma_offset_m": error.sigma_offset_m,
            "pass_error_sigma_angle_rad": error.sigma_angle_rad,
            "median_ratio_with_pass_error": float(np.median(t_p) / CHI2_2_MEDIAN),
            "fraction_beyond_95_with_pass_error": float(np.mean(t_p > CHI2_2_95)),
        }
    return PassConsistency(
        gap_s=gap_s,
        landmarks=int(np.unique(passes.landmark[a]).size),
        pairs=int(t.size),
        median_ratio=float(np.median(t) / CHI2_2_MEDIAN),
        median_ratio_angle=float(np.median(ta) / CHI2_1_MEDIAN),
        fraction_beyond_95=float(np.mean(t > CHI2_2_95)),
        **with_error,
    )


def _walls(graph: LineGraph) -> LineGraph:
    """``graph`` with each pass landmark's factors on the wall it is linked to (a copy)."""
    if graph.n_landmark_links == 0:
        return graph
    g = copy.deepcopy(graph)
    root = np.arange(g.n_landmarks)
    root[g.link_first] = g.link_second
    n = g.n_line_factors
    g.factor_landmark[:n] = root[g.factor_landmark[:n]]
    return g


def pass_consistency_of_results(
    directory: str | Path, gap_s: float = 30.0, max_pairs: int | None = None
) -> PassConsistency:
    """:func:`pass_consistency` of a results folder's ``graph.g2o``.

    Raises
    ------
    EvaluationError
        The file states no scan time stamps (``LINESLAM_SCAN`` lines).
    """
    f = read_line_graph_g2o(Path(directory) / "graph.g2o")
    if f.timestamps is None:
        raise EvaluationError(f"{directory}/graph.g2o states no scan time stamps")
    return pass_consistency(
        line_graph_from_file(f), f.timestamps, f.robust_kernel, gap_s, max_pairs=max_pairs
    )


@dataclass(frozen=True)
class PassError:
    """The error each pass along a wall shares, estimated (module docstring).

    Attributes
    ----------
    gap_s : float
        The gap (s) that separates passes.
    sigma_offset_m, sigma_angle_rad : float
        Offset along the normal and angle about the pass's place.
    pairs : int
        Pairs of passes the estimate used.
    linked_passes : int
        Passes that became landmarks linked to their wall (0: the model is not used).
    """

    gap_s: float
    sigma_offset_m: float
    sigma_angle_rad: float
    pairs: int
    linked_passes: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (for ``summary.json``)."""
        return asdict(self)


MIN_PAIRS = 20
"""Fewest pairs of passes for an estimate of the pass error (else none is used)."""


SIGNIFICANCE = 0.99
"""A pass error is estimated only when the pairs of passes disagree beyond their covariances
with this one-sided significance (:func:`slam.line_slam.line_noise.excess_is_significant`, on
the angle part or the offset part of the differences): where the walls have none, chance
alone would give a positive estimate about half the time."""

ESTIMATE_ROUNDS = 6
"""Rounds of the alternating estimate of the pass error's angle and offset."""


def estimate_pass_error(passes: Passes, pairs: FittedPairs | None = None) -> PassError:
    """``(σ_o, σ_a)`` of the pass error from pairs of usable passes (module docstring).

    Each pair's difference ``d`` has covariance ``S + T_a B_a T_aᵀ + T_b B_b T_bᵀ``
    (:class:`FittedPairs`; default every pair with the poses as if known: ``S = C_a + C_b``,
    ``T_a = I``, ``T_b = −I``), linear in ``σ_o²`` and ``σ_a²``.  They are found in turn, each
    holding the other, by the moment of :mod:`slam.line_slam.line_noise` (Huber's Proposal 2)
    on the angle part of ``d`` and on its offset at the pair's middle place.  With fewer than
    :data:`MIN_PAIRS` pairs, or differences that the measurement noise alone explains
    (:data:`SIGNIFICANCE`), both σ are 0 (no pass error).
    """
    if pairs is None:
        a, b = passes.pairs()
        S = passes.cov[a] + passes.cov[b]
        T_a = np.broadcast_to(np.eye(2), S.shape)
        T_b = -T_a
    else:
        a, b, S, T_a, T_b = pairs.a, pairs.b, pairs.S, pairs.T_a, pairs.T_b
    if a.size < MIN_PAIRS:
        return PassError(passes.gap_s, 0.0, 0.0, int(a.size))
    d = passes.mean[a] - passes.mean[b]
    u_a, u_b = passes.place[a], passes.place[b]
    u_m = 0.5 * (u_a + u_b)
    h = np.column_stack([np.ones_like(u_m), -u_m])  # the offset at u_m
    d_o = np.einsum("ki,ki->k", h, d)

    def along_h(V: FloatArray) -> FloatArray:
        return np.asarray(np.einsum("ki,kij,kj->k", h, V, h))

    S_o = along_h(S)
    # no pass error unless the pairs disagree beyond chance, in the angle or the offset
    if not (
        excess_is_significant(d[:, 1] ** 2, S[:, 1, 1], SIGNIFICANCE)
        or excess_is_significant(d_o**2, S_o, SIGNIFICANCE)
    ):
        return PassError(passes.gap_s, 0.0, 0.0, int(a.size))

    def spread(T: FloatArray, B: FloatArray) -> FloatArray:
        return np.asarray(T @ B @ np.swapaxes(T, 1, 2))

    K_o = spread(T_a, pass_covariance(u_a, 1.0, 0.0)) + spread(T_b, pass_covariance(u_b, 1.0, 0.0))
    K_a = spread(T_a, pass_covariance(u_a, 0.0, 1.0)) + spread(T_b, pass_covariance(u_b, 0.0, 1.0))
    s2_o = s2_a = 0.0
    for _ in range(ESTIMATE_ROUNDS):
        k = K_a[:, 1, 1]
        s2_a = _sigma2_for_moment(d[:, 1] ** 2 / k, (S[:, 1, 1] + s2_o * K_o[:, 1, 1]) / k)
        k = along_h(K_o)
        s2_o = _sigma2_for_moment(d_o**2 / k, (S_o + s2_a * along_h(K_a)) / k)
    return PassError(passes.gap_s, math.sqrt(s2_o), math.sqrt(s2_a), int(a.size))


def pass_covariance(place: FloatArray, sigma_offset_m: float, sigma_angle_rad: float) -> FloatArray:
    """``B_p`` ``(P, 2, 2)`` in the landmark's chart for passes at tangent places ``u`` ``(P,)``."""
    u = np.asarray(place, dtype=float).reshape(-1)
    sa2 = sigma_angle_rad**2
    out = np.empty((u.shape[0], 2, 2))
    out[:, 0, 0] = sigma_offset_m**2 + u * u * sa2
    out[:, 0, 1] = out[:, 1, 0] = u * sa2
    out[:, 1, 1] = sa2
    return out


MIN_SIGMA_OFFSET_M = 1e-4
"""Smallest pass offset error a link carries (m): a link needs a positive-definite ``B``."""
MIN_SIGMA_ANGLE_RAD = 1e-5
"""Smallest pass angle error a link carries (rad)."""


def with_pass_links(graph: LineGraph, passes: Passes, error: PassError) -> tuple[LineGraph, int]:
    """A copy of ``graph`` with each pass of a multi-pass wall as a linked landmark.

    Every pass of a landmark seen in two passes or more becomes a landmark of its own (the
    wall's estimate and anchor) holding the pass's factors, linked to the wall with
    ``B_p`` (:func:`pass_covariance`, each σ at least :data:`MIN_SIGMA_OFFSET_M`,
    :data:`MIN_SIGMA_ANGLE_RAD`).  The wall keeps its index and holds no factor.  Returns the
    copy and the number of linked passes; with both σ of ``error`` zero, ``graph`` itself and 0.
    """
    if error.sigma_offset_m <= 0.0 and error.sigma_angle_rad <= 0.0:
        return graph, 0
    per_landmark = np.bincount(passes.landmark, minlength=graph.n_landmarks)
    linked = np.flatnonzero(per_landmark[passes.landmark] >= 2)
    if linked.size == 0:
        return graph, 0
    g = copy.deepcopy(graph)
    wall = passes.landmark[linked]
    v = g.landmarks[wall].copy()
    c = g.anchors[wall].copy()
    new = g.add_landmarks(r_alpha_from_anchored(v, c), c)
    g.landmarks[new] = v  # the wall's chart values exactly
    variable = np.full(passes.landmark.shape[0], -1, dtype=np.intp)
    variable[linked] = new
    n = g.n_line_factors
    moved = variable[passes.factor_pass] >= 0
    g.factor_landmark[:n][moved] = variable[passes.factor_pass[moved]]
    B = pass_covariance(
        passes.place[linked],
        max(error.sigma_offset_m, MIN_SIGMA_OFFSET_M),
        max(error.sigma_angle_rad, MIN_SIGMA_ANGLE_RAD),
    )
    g.add_landmark_links(new, wall, B)
    return g, int(linked.size)
