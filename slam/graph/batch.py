"""Batch Gauss-Newton / Levenberg-Marquardt over the whole line graph, in our own loop.

Each iteration:

1. linearise every factor at once in numpy: line factors
   (:func:`slam.graph.factors.linearize_line_factors`, IRLS weights when a robust kernel is
   configured), odometry and the gauge prior (:mod:`slam.graph.odometry`, GTSAM's
   ``BetweenFactorPose2`` / ``PriorFactorPose2`` semantics);
2. hand the pre-whitened blocks to GTSAM as ``JacobianFactor``s (unit noise) and eliminate
   the ``GaussianFactorGraph`` (multifrontal Cholesky; COLAMD or METIS ordering, computed once
   per solve), or, with ``SolverConfig.linear_solver = "sparse"``, sum them into the normal
   equations ``H δ = g`` and solve those by a compiled sparse ``LDLᵀ``
   (:mod:`slam.graph.sparse`: pattern, ordering and symbolic analysis once per solve): the
   same step to rounding, several times faster;
3. retract in numpy (poses ``x·Exp(ξ)``, landmarks additively in their anchored chart) and
   evaluate the cost in numpy: the trial point is linearised (the same cost as
   :meth:`BatchSolver.cost` from the same residuals), and that linearisation is the next
   iteration's if the step is accepted.

Nothing in the loop costs more per factor as the graph grows except the elimination itself,
whose fill per factor stays flat on the planar problems here (``scripts/bench_graph.py``).

Step control: Gauss-Newton first; a step that raises the cost is rejected and retried with
Levenberg-Marquardt damping ``λ·D`` (``D`` ≈ ``diag(AᵀA)``, Marquardt's scaling) on every
variable; after an accepted damped step ``λ`` follows Nielsen's rule from the gain ratio and
drops back to pure Gauss-Newton below ``lambda_initial``.  Converged when the relative cost
decrease or the largest update component falls below its tolerance
(:class:`slam.graph.config.SolverConfig`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray

from slam import interrupts
from slam.errors import EstimationError
from slam.geometry import pose_retract
from slam.graph.config import SolverConfig
from slam.graph.factors import LineLinearization, line_factor_costs, linearize_line_factors
from slam.graph.linear import (
    UNIT2,
    UNIT3,
    FactorBatch,
    ReusableGraph,
    key_array,
    keys_of,
    landmark_link_batch,
    landmark_prior_batch,
    line_jacobian_batch,
    odometry_jacobian_batch,
    pairing_order,
    split_delta,
    unary_batch,
)
from slam.graph.odometry import between_costs, linearize_between, linearize_prior
from slam.graph.problem import LineGraph
from slam.graph.robust import robust_cost
from slam.graph.sparse import BlockTerms, NormalEquations
from slam.models.anchored import retract_landmarks

__all__ = ["BatchSolver", "SolveStats"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass
class SolveStats:
    """What one solve did.

    Attributes
    ----------
    iterations : int
        Linearisations performed.
    initial_cost, final_cost : float
        ``Σ ρ`` over line factors plus ``½‖e‖²`` over odometry and prior.
    converged : bool
        A convergence criterion was met (not just the iteration limit).
    reason : str
        Why the loop stopped.
    time_s : dict
        Wall-clock time per stage (``linearize``, ``solve``, ``retract``, ``cost``).
    history : list of (float, float, bool)
        ``(cost of the trial, λ, accepted)`` for every trial step.
    """

    iterations: int = 0
    initial_cost: float = float("nan")
    final_cost: float = float("nan")
    converged: bool = False
    reason: str = ""
    time_s: dict[str, float] = field(default_factory=dict)
    history: list[tuple[float, float, bool]] = field(default_factory=list)


@dataclass(frozen=True, eq=False)
class _LinearPoint:
    """A linearisation of :meth:`BatchSolver._linear_batches`.

    The factors' numpy batches, the line factors' linearisation and indices, and the cost of
    these factors at the point.
    """

    batches: list[FactorBatch]
    lin: LineLinearization | None
    used: IntArray
    cost: float


class BatchSolver:
    """Own Gauss-Newton / Levenberg-Marquardt loop (sparse ``LDLᵀ`` or GTSAM elimination).

    Parameters
    ----------
    config : SolverConfig
    """

    def __init__(self, config: SolverConfig | None = None) -> None:
        self.config = config or SolverConfig()

    @staticmethod
    def active_landmarks(graph: LineGraph) -> IntArray:
        """Landmarks that are alive and have at least one factor or link (the solved ones)."""
        counts = graph.observation_counts()
        if graph.n_landmark_links:
            np.add.at(counts, graph.link_first, 1)
            np.add.at(counts, graph.link_second, 1)
        return np.flatnonzero(graph.landmark_alive & (counts > 0))

    # -- cost and linearisation ----------------------------------------------------------------
    def cost(
        self,
        graph: LineGraph,
        poses: FloatArray,
        landmarks: FloatArray,
        line_factors: IntArray | None = None,
        odometry: IntArray | None = None,
        with_prior: bool = True,
    ) -> float:
        """Total cost at the given full-size estimate arrays (poses, anchored landmarks).

        ``line_factors`` / ``odometry`` (indices) and ``with_prior`` restrict it to some factors
        (default: all; the landmark links count with ``line_factors = None`` only).
        """
        total = 0.0
        f = np.arange(graph.n_line_factors) if line_factors is None else line_factors
        if f.size:
            lm = graph.factor_landmark[f]
            total += float(
                np.sum(
                    line_factor_costs(
                        poses[graph.factor_pose[f]],
                        landmarks[lm],
                        graph.anchors[lm],
                        graph.factor_z[f],
                        graph.factor_sqrt_info[f],
                        self.config.robust_kernel,
                        self.config.robust_k,
                    )
                )
            )
        e = np.arange(graph.n_odometry) if odometry is None else odometry
        if e.size:
            total += float(
                np.sum(
                    between_costs(
                        poses[graph.odometry_first[e]],
                        poses[graph.odometry_second[e]],
                        graph.odometry_measured[e],
                        graph.odometry_sqrt_info[e],
                    )
                )
            )
        if line_factors is None and graph.n_landmark_links:
            _, r = landmark_link_batch(
                graph.link_first, graph.link_second, landmarks, graph.link_sqrt_info
            )
            total += float(0.5 * np.sum(r * r))
        if with_prior and graph.prior_pose is not None and graph.prior_sqrt_info is not None:
            total += linearize_prior(poses[0], graph.prior_pose, graph.prior_sqrt_info)[2]
        return total

    def linearize(
        self,
        graph: LineGraph,
        poses: FloatArray | None = None,
        landmarks: FloatArray | None = None,
    ) -> gtsam.GaussianFactorGraph:
        """The whole graph linearised at the given estimate (default: the graph's own)."""
        poses = graph.poses if poses is None else poses
        landmarks = graph.landmarks if landmarks is None else landmarks
        return self._linearize(graph, poses, landmarks)[0]

    def _linearize(
        self,
        graph: LineGraph,
        poses: FloatArray,
        landmarks: FloatArray,
        free_from: int = 0,
        solved: NDArray[np.bool_] | None = None,
        reuse: ReusableGraph | None = None,
    ) -> tuple[gtsam.GaussianFactorGraph, LineLinearization | None, IntArray]:
        """:meth:`linearize`, also returning the line factors' linearisation and their indices.

        :meth:`damping_scale` at the same point reuses it instead of linearising again.  With
        ``free_from > 0`` poses before it are constants: factors touching only constants are
        left out, and a factor between a constant and a variable becomes a one-key factor.
        ``solved`` (per landmark) says which landmarks are variables (default: all).  With
        ``reuse`` the factors of its last graph are overwritten where the structure allows
        (:class:`slam.graph.linear.ReusableGraph`): the same graph, built faster.
        """
        point = self._linear_batches(graph, poses, landmarks, free_from, solved)
        if reuse is None:
            reuse = ReusableGraph()
        return reuse.load(point.batches), point.lin, point.used

    def _linear_batches(
        self,
        graph: LineGraph,
        poses: FloatArray,
        landmarks: FloatArray,
        free_from: int = 0,
        solved: NDArray[np.bool_] | None = None,
        structure: dict[str, Any] | None = None,
    ) -> _LinearPoint:
        """The factors of :meth:`_linearize` as numpy batches, and their cost at the point.

        The cost is the one :meth:`cost` gives for the same factors (every factor with
        ``free_from == 0``, else the line factors on solved landmarks and the odometry into
        free poses): the same residuals, summed in the same order.  ``structure`` keeps the
        index arrays that depend only on the graph's structure, ``free_from`` and ``solved``
        (which factors, in which order) from one call to the next of a solve.
        """
        batches: list[FactorBatch] = []
        lin: LineLinearization | None = None
        used = np.zeros(0, dtype=np.intp)
        prior_cost: float | None = None
        odometry_cost: float | None = None
        if structure is None:
            structure = {}
        if free_from == 0 and graph.prior_pose is not None and graph.prior_sqrt_info is not None:
            A, b, prior_cost = linearize_prior(poses[0], graph.prior_pose, graph.prior_sqrt_info)
            batches.append(unary_batch(key_array("x", np.array([0])), A[None], b[None]))
        if graph.n_odometry:
            if "odometry" not in structure:
                e = np.flatnonzero(graph.odometry_second >= free_from)
                first, second = graph.odometry_first[e], graph.odometry_second[e]
                structure["odometry"] = (e, first, second, first >= free_from)
            e, first, second, both = structure["odometry"]
            A1, A2, b = linearize_between(
                poses[first], poses[second], graph.odometry_measured[e], graph.odometry_sqrt_info[e]
            )
            if e.size:
                odometry_cost = float(np.sum(0.5 * np.sum(b**2, axis=-1)))  # b = −W e
            batches.append(
                odometry_jacobian_batch(first[both], second[both], A1[both], A2[both], b[both])
            )
            batches.append(unary_batch(key_array("x", second[~both]), A2[~both], b[~both]))
        if graph.n_line_factors:
            if "lines" not in structure:
                lm_all = graph.factor_landmark
                used = (
                    np.arange(graph.n_line_factors)
                    if solved is None
                    else np.flatnonzero(solved[lm_all])
                )
                lm = lm_all[used]
                fp = graph.factor_pose[used]
                free = fp >= free_from
                o = np.flatnonzero(free)
                o = o[pairing_order(fp[o], lm[o])]  # most factors two to a JacobianFactor
                structure["lines"] = (used, lm, fp, free, o)
            used, lm, fp, free, o = structure["lines"]
            lin = self._linearize_lines(graph, poses, landmarks, used)
            sub = LineLinearization(
                lin.A_pose[o], lin.A_landmark[o], lin.b[o], lin.whitened_residual[o], lin.weights[o]
            )
            batches.append(line_jacobian_batch(fp[o], lm[o], sub))
            if not free.all():
                fixed = ~free
                batches.append(landmark_prior_batch(lm[fixed], lin.A_landmark[fixed], lin.b[fixed]))
        link_cost: float | None = None
        if graph.n_landmark_links and free_from == 0 and solved is None:
            batch, r = landmark_link_batch(
                graph.link_first, graph.link_second, landmarks, graph.link_sqrt_info
            )
            batches.append(batch)
            link_cost = float(0.5 * np.sum(r * r))
        total = 0.0
        if link_cost is not None:
            total += link_cost
        if used.size:
            assert lin is not None
            rho = robust_cost(
                self.config.robust_kernel,
                np.linalg.norm(lin.whitened_residual, axis=-1),
                self.config.robust_k,
            )
            total += float(np.sum(rho))
        if odometry_cost is not None:
            total += odometry_cost
        if prior_cost is not None:
            total += prior_cost
        return _LinearPoint(batches, lin, used, total)

    def _linearize_lines(
        self, graph: LineGraph, poses: FloatArray, landmarks: FloatArray, factors: IntArray
    ) -> LineLinearization:
        """Linearise line factors ``factors`` at ``poses`` / ``landmarks``, kernel weights in."""
        lm = graph.factor_landmark[factors]
        return linearize_line_factors(
            poses[graph.factor_pose[factors]],
            landmarks[lm],
            graph.anchors[lm],
            graph.factor_z[factors],
            graph.factor_sqrt_info[factors],
            self.config.robust_kernel,
            self.config.robust_k,
        )

    def _region(
        self, graph: LineGraph, free_from: int, lms: IntArray, solved: NDArray[np.bool_] | None
    ) -> tuple[NormalEquations, dict[str, Any]]:
        """The factors of a solve and the structure of its normal equations (once per solve).

        The same factors as :meth:`_linearize`: the prior (``free_from == 0``), odometry into
        a solved pose (one-variable when its first pose is held), line factors on solved
        landmarks (one-variable when their pose is held).  Variables: the solved landmarks,
        then the solved poses (the order of :func:`slam.graph.linear.split_delta`).
        """
        n_l = lms.shape[0]
        lm_var = np.full(graph.n_landmarks, -1, dtype=np.intp)
        lm_var[lms] = np.arange(n_l)
        dims = np.r_[np.full(n_l, 2), np.full(graph.n_poses - free_from, 3)].astype(np.int64)
        terms: list[BlockTerms] = []
        parts: dict[str, Any] = {}
        with_prior = free_from == 0 and graph.prior_pose is not None
        if with_prior:
            terms.append(BlockTerms(np.array([n_l]), 3))
        parts["prior"] = with_prior
        e = np.flatnonzero(graph.odometry_second >= free_from)
        both = graph.odometry_first[e] >= free_from
        parts["odometry"] = e
        parts["odometry_both"] = both
        pose_var = n_l - free_from
        if np.any(both):
            terms.append(
                BlockTerms(
                    graph.odometry_first[e[both]] + pose_var,
                    3,
                    graph.odometry_second[e[both]] + pose_var,
                    3,
                )
            )
        if not np.all(both):
            terms.append(BlockTerms(graph.odometry_second[e[~both]] + pose_var, 3))
        used = (
            np.arange(graph.n_line_factors)
            if solved is None
            else np.flatnonzero(solved[graph.factor_landmark])
        )
        fp = graph.factor_pose[used]
        lm = graph.factor_landmark[used]
        free = fp >= free_from
        parts["used"] = used
        parts["free"] = free
        if np.any(free):
            terms.append(BlockTerms(fp[free] + pose_var, 3, lm_var[lm[free]], 2))
        if not np.all(free):
            terms.append(BlockTerms(lm_var[lm[~free]], 2))

        def describe(v: int) -> str:
            return f"landmark {int(lms[v])}" if v < n_l else f"pose {v - n_l + free_from}"

        return NormalEquations(dims, terms, self.config.ordering, describe), parts

    def _linearize_point(
        self, graph: LineGraph, poses: FloatArray, landmarks: FloatArray, parts: dict[str, Any]
    ) -> tuple[
        list[tuple[FloatArray, FloatArray | None, FloatArray]], LineLinearization | None, float
    ]:
        """The solve's factors (:meth:`_region`) linearised at ``(poses, landmarks)``.

        Returns the blocks for :meth:`NormalEquations.assemble`, the line factors'
        linearisation (for :meth:`damping_scale`) and the cost of these factors there, the
        same number :meth:`cost` gives for them (the same residuals, summed in the same order).
        """
        values: list[tuple[FloatArray, FloatArray | None, FloatArray]] = []
        prior_cost = 0.0
        if parts["prior"]:
            assert graph.prior_pose is not None and graph.prior_sqrt_info is not None
            A, b, prior_cost = linearize_prior(poses[0], graph.prior_pose, graph.prior_sqrt_info)
            values.append((A[None], None, b[None]))
        e, both = parts["odometry"], parts["odometry_both"]
        odometry_cost = None
        if e.size:
            A1, A2, b = linearize_between(
                poses[graph.odometry_first[e]],
                poses[graph.odometry_second[e]],
                graph.odometry_measured[e],
                graph.odometry_sqrt_info[e],
            )
            odometry_cost = float(np.sum(0.5 * np.sum(b**2, axis=-1)))  # b = −W e
            if np.any(both):
                values.append((A1[both], A2[both], b[both]))
            if not np.all(both):
                values.append((A2[~both], None, b[~both]))
        used, free = parts["used"], parts["free"]
        lin: LineLinearization | None = None
        total = 0.0
        if used.size:
            lin = self._linearize_lines(graph, poses, landmarks, used)
            rho = robust_cost(
                self.config.robust_kernel,
                np.linalg.norm(lin.whitened_residual, axis=-1),
                self.config.robust_k,
            )
            total += float(np.sum(rho))
            if np.any(free):
                values.append((lin.A_pose[free], lin.A_landmark[free], lin.b[free]))
            if not np.all(free):
                values.append((lin.A_landmark[~free], None, lin.b[~free]))
        if odometry_cost is not None:
            total += odometry_cost
        if parts["prior"]:
            total += prior_cost
        return values, lin, total

    def damping_scale(
        self,
        graph: LineGraph,
        poses: FloatArray,
        landmarks: FloatArray,
        lin: LineLinearization | None = None,
        factors: IntArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Marquardt scaling: ``diag(AᵀA)`` per pose ``(N, 3)`` and landmark ``(M, 2)``.

        ``factors``: the line factors ``lin`` linearised (default all).
        Line factors contribute their whitened Jacobian columns' squared norms exactly; odometry
        contributes ``diag(Σ⁻¹)`` to both of its poses (its Jacobians are rotations of the
        identity to first order).  Floored at ``1e-9`` of the largest entry.
        """
        N, M = graph.n_poses, graph.n_landmarks
        dp = np.zeros((N, 3))
        dl = np.zeros((M, 2))
        if graph.n_line_factors:
            f = np.arange(graph.n_line_factors) if factors is None else factors
            lm = graph.factor_landmark[f]
            fp = graph.factor_pose[f]
            if lin is None:
                lin = self._linearize_lines(graph, poses, landmarks, f)
            np.add.at(dp, fp, np.sum(lin.A_pose**2, axis=1))
            np.add.at(dl, lm, np.sum(lin.A_landmark**2, axis=1))
        if graph.n_odometry:
            info = np.sum(graph.odometry_sqrt_info**2, axis=1)  # diag(WᵀW)
            np.add.at(dp, graph.odometry_first, info)
            np.add.at(dp, graph.odometry_second, info)
        if graph.prior_sqrt_info is not None and N:
            dp[0] += np.sum(graph.prior_sqrt_info**2, axis=0)
        top = max(float(dp.max(initial=0.0)), float(dl.max(initial=0.0)), 1e-300)
        return np.maximum(dp, 1e-9 * top), np.maximum(dl, 1e-9 * top)

    @staticmethod
    def _damped(
        gfg: gtsam.GaussianFactorGraph,
        landmarks: IntArray,
        scale_poses: FloatArray,
        scale_landmarks: FloatArray,
        lam: float,
        free_from: int = 0,
    ) -> gtsam.GaussianFactorGraph:
        """``gfg`` plus damping factors ``√(λ D)`` on every variable (poses from ``free_from``)."""
        out = gtsam.GaussianFactorGraph()
        out.push_back(gfg)
        z3, z2 = np.zeros(3), np.zeros(2)
        sp = np.sqrt(lam * scale_poses[free_from:])
        sl = np.sqrt(lam * scale_landmarks[landmarks])
        free = np.arange(free_from, scale_poses.shape[0])
        for k, d in zip(keys_of("x", free), sp, strict=True):
            out.push_back(gtsam.JacobianFactor(k, np.diag(d), z3, UNIT3))
        for k, d in zip(keys_of("l", landmarks), sl, strict=True):
            out.push_back(gtsam.JacobianFactor(k, np.diag(d), z2, UNIT2))
        return out

    def _ordering(self, gfg: gtsam.GaussianFactorGraph) -> gtsam.Ordering:
        if self.config.ordering == "metis":
            return gtsam.Ordering.MetisGaussianFactorGraph(gfg)
        return gtsam.Ordering.ColamdGaussianFactorGraph(gfg)

    # -- the loop ---------------------------------------------------------------------------
    def solve(
        self,
        graph: LineGraph,
        max_iterations: int | None = None,
        free_from: int = 0,
        stop: Callable[[int, FloatArray, FloatArray], bool] | None = None,
    ) -> SolveStats:
        """Optimise ``graph``'s estimate in place.

        Parameters
        ----------
        graph : LineGraph
            Needs the gauge prior (:meth:`LineGraph.set_prior`).
        max_iterations : int, optional
            Most linearisations; default ``config.max_iterations``.
        free_from : int, optional
            Poses before this index are held at their current estimate; only the later poses
            and the landmarks they observe are solved (with the held poses' factors on those
            landmarks as constants).  E.g. judging a loop closure, where the map before the
            loop is the reference.  Default 0: the whole graph.
        stop : callable, optional
            ``stop(iterations, poses, landmarks)`` after every accepted step (full-size
            arrays of the new estimate); True ends the solve there (reason "stopped").

        Returns
        -------
        SolveStats

        Raises
        ------
        EstimationError
            No prior, a non-finite cost, or a linear system that cannot be solved (not
            positive definite: a variable the factors do not determine; the sparse path
            names the pose or landmark).
        """
        cfg = self.config
        iters = cfg.max_iterations if max_iterations is None else max_iterations
        stats = SolveStats(time_s={"linearize": 0.0, "solve": 0.0, "retract": 0.0, "cost": 0.0})
        if graph.n_poses == 0:
            stats.converged, stats.reason = True, "empty graph"
            return stats
        if graph.prior_pose is None:
            raise EstimationError("the graph has no prior on its first pose (gauge)")
        if not 0 <= free_from < graph.n_poses:
            raise EstimationError(f"free_from={free_from} is not a pose of the graph")
        if graph.n_landmark_links and (free_from > 0 or cfg.linear_solver == "sparse"):
            raise EstimationError(
                "a graph with landmark links is solved whole, with GTSAM's linear solver"
            )
        lms = self.active_landmarks(graph)
        solved: NDArray[np.bool_] | None = None
        if free_from > 0:
            seen = np.zeros(graph.n_landmarks, dtype=bool)
            seen[graph.factor_landmark[graph.factor_pose >= free_from]] = True
            lms = lms[seen[lms]]
            solved = np.zeros(graph.n_landmarks, dtype=bool)
            solved[lms] = True
        poses = graph.poses.copy()
        landmarks = graph.landmarks.copy()
        cost = self.cost(graph, poses, landmarks)
        if not np.isfinite(cost):
            raise EstimationError("the initial estimate has a non-finite cost")
        # with held poses only the factors on solved variables change: cost = theirs + constant
        varying: dict[str, Any] = {}
        constant = 0.0
        if solved is not None:
            varying = {
                "line_factors": np.flatnonzero(solved[graph.factor_landmark]),
                "odometry": np.flatnonzero(graph.odometry_second >= free_from),
                "with_prior": False,
            }
            constant = cost - self.cost(graph, poses, landmarks, **varying)
        stats.initial_cost = cost
        lam, nu = 0.0, 2.0
        scale: tuple[FloatArray, FloatArray] | None = None
        lin: LineLinearization | None = None
        used = np.zeros(0, dtype=np.intp)
        sparse = cfg.linear_solver == "sparse"
        if sparse:
            t0 = time.perf_counter()
            system, parts = self._region(graph, free_from, lms, solved)
            used = parts["used"]
            stats.time_s["linearize"] += time.perf_counter() - t0
        ordering = None
        gfg = gtsam.GaussianFactorGraph()
        reuse = ReusableGraph()  # the factors of one iteration are rewritten in the next
        at_point: tuple[Any, LineLinearization | None, float] | None = None
        trial: tuple[Any, LineLinearization | None, float] | None = None
        point: _LinearPoint | None = None
        trial_point: _LinearPoint | None = None
        structure: dict[str, Any] = {}  # the factors' index arrays, the same all solve long
        relinearize = True
        while True:
            interrupts.check()  # between iterations (slam.interrupts)
            if relinearize:
                if stats.iterations >= iters:
                    stats.reason = "iteration limit"
                    break
                t0 = time.perf_counter()
                if sparse:
                    if at_point is None:  # else the accepted trial's linearisation
                        at_point = self._linearize_point(graph, poses, landmarks, parts)
                    system.assemble(at_point[0])
                    lin = at_point[1]
                    at_point = None
                else:
                    if point is None:  # else the accepted trial's linearisation
                        point = self._linear_batches(
                            graph, poses, landmarks, free_from, solved, structure
                        )
                    gfg, lin, used = reuse.load(point.batches), point.lin, point.used
                    point = None
                    if ordering is None:
                        ordering = self._ordering(gfg)
                stats.iterations += 1
                scale = None
                stats.time_s["linearize"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            if lam > 0.0 and scale is None:
                scale = self.damping_scale(graph, poses, landmarks, lin, used)
            if sparse:
                damping = None
                if lam > 0.0:
                    assert scale is not None
                    damping = lam * np.r_[scale[1][lms].ravel(), scale[0][free_from:].ravel()]
                delta_vector = system.solve(damping)  # EstimationError when not solvable
                # the model's predicted decrease, for the gain ratio of a damped step only
                predicted = system.predicted_decrease(delta_vector) if lam > 0.0 else 0.0
                n_l = 2 * lms.shape[0]
                d_lm = delta_vector[:n_l].reshape(-1, 2)
                d_pose = delta_vector[n_l:].reshape(-1, 3)
            else:
                if lam > 0.0:
                    assert scale is not None
                    damped = self._damped(gfg, lms, scale[0], scale[1], lam, free_from)
                else:
                    damped = gfg
                assert ordering is not None
                try:
                    delta = damped.optimize(ordering)
                except RuntimeError as exc:
                    raise EstimationError(f"linear system could not be solved: {exc}") from exc
                predicted = (
                    float(gfg.error(delta.scale(0.0)) - gfg.error(delta)) if lam > 0.0 else 0.0
                )
                d_lm, d_pose = split_delta(delta, lms.shape[0], graph.n_poses - free_from)
            stats.time_s["solve"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            step = float(max(np.max(np.abs(d_pose)), np.max(np.abs(d_lm), initial=0.0)))
            new_poses = poses.copy()
            new_poses[free_from:] = pose_retract(poses[free_from:], d_pose)
            new_landmarks = landmarks.copy()
            new_landmarks[lms] = retract_landmarks(landmarks[lms], d_lm)
            stats.time_s["retract"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            # linearised at the trial point already: reused if it is accepted
            if sparse:
                trial = self._linearize_point(graph, new_poses, new_landmarks, parts)
                new_cost = trial[2] + constant
            else:
                trial_point = self._linear_batches(
                    graph, new_poses, new_landmarks, free_from, solved, structure
                )
                new_cost = trial_point.cost + constant
            stats.time_s["cost"] += time.perf_counter() - t0
            accepted = bool(np.isfinite(new_cost)) and new_cost <= cost * (1.0 + 1e-12) + 1e-15
            stats.history.append((new_cost, lam, accepted))
            if accepted:
                decrease = cost - new_cost
                poses, landmarks, cost = new_poses, new_landmarks, new_cost
                at_point = trial
                point = trial_point
                relinearize = True
                if lam > 0.0:
                    rho = decrease / predicted if predicted > 0.0 else 0.0
                    lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                    nu = 2.0
                    if lam < cfg.lambda_min:
                        lam = 0.0
                if stop is not None and stop(stats.iterations, poses, landmarks):
                    stats.reason = "stopped"
                    break
                if step < cfg.step_tolerance:
                    stats.converged, stats.reason = True, "step below tolerance"
                    break
                if decrease <= cfg.relative_tolerance * max(cost, 1e-300):
                    stats.converged, stats.reason = True, "relative decrease below tolerance"
                    break
                if decrease <= cfg.absolute_tolerance:
                    stats.converged, stats.reason = True, "decrease below absolute tolerance"
                    break
            else:
                relinearize = False
                if lam == 0.0:
                    lam = cfg.lambda_initial
                else:
                    lam *= nu
                    nu *= 2.0
                if lam > cfg.lambda_max:
                    stats.converged, stats.reason = True, "no step decreases the cost"
                    break
        graph.poses[:] = poses
        graph.landmarks[:] = landmarks
        stats.final_cost = cost
        return stats

    def marginals(self, graph: LineGraph) -> gtsam.Marginals:
        """``gtsam.Marginals`` of the system linearised at the graph's current estimate.

        Landmark covariances from it are in the anchored chart ``(ρ, φ)``
        (:func:`slam.models.anchored.anchored_jacobian` maps them to ``(r, α)``).
        """
        gfg = self.linearize(graph)
        try:
            return gtsam.Marginals(gfg, gtsam.VectorValues())
        except RuntimeError as exc:
            raise EstimationError(f"marginals could not be computed: {exc}") from exc
