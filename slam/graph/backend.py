"""The two online estimators behind :class:`slam.line_slam.LineSlam`, one interface.

Both keep :class:`~slam.graph.problem.LineGraph`'s estimate current and answer covariance
queries (pose blocks in the right tangent space, landmark blocks in the anchored chart
``(ρ, φ)``; :class:`LineSlam` converts them to ``(r, α)``).

* :class:`Isam2Backend`: one ``ISAM2.update`` per keyframe (:mod:`slam.graph.isam2`);
  covariances from ``ISAM2.jointMarginalCovariance``, exact for the current linearisation.
* :class:`BatchBackend`: a warm-started batch solve (:mod:`slam.graph.batch`) every
  ``solver.batch_interval`` keyframes (``online_iterations`` iterations at most), a full solve in
  :meth:`optimize`.  Covariances come from ``gtsam.Marginals`` of the whole graph linearised at
  the current estimate, built after each solve; a pose added since is reached by compounding
  the odometry chain from the newest pose in the marginals (Smith-Cheeseman, cross-covariances
  with the landmarks carried along), and a landmark added since gets the covariance of its first
  observation moved into the world (Eq. 31) with that of its pose, without cross terms.
  With ``batch_interval = 1`` (the default) every query is exact.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any, Protocol

import gtsam
import numpy as np
from numpy.typing import NDArray

from slam import interrupts
from slam.errors import EstimationError
from slam.geometry import adjoint_pose2, line_to_parent, pose_inverse
from slam.graph.batch import BatchSolver
from slam.graph.config import Isam2Config, SolverConfig
from slam.graph.isam2 import Isam2Solver
from slam.graph.linear import keys_of
from slam.graph.problem import LineGraph
from slam.models.anchored import anchored_jacobian

__all__ = ["Backend", "BatchBackend", "Isam2Backend", "make_backend"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class Backend(Protocol):
    """What :class:`LineSlam` needs from an estimator."""

    name: str
    estimate_moved: bool

    def update(self, graph: LineGraph) -> None:
        """Take in what was added to ``graph`` since the last call; refresh its estimate."""

    def reset(self, graph: LineGraph) -> None:
        """Take in a graph whose estimate was changed from outside."""

    def optimize(self, graph: LineGraph, max_updates: int | None = None) -> dict[str, Any]:
        """Converge the whole problem; return statistics."""

    def joint_covariance(
        self, graph: LineGraph, pose: int | None, landmarks: IntArray
    ) -> FloatArray:
        """Joint covariance of one pose (3, if given) and landmarks (2 each), anchored chart."""

    def joint_pose_covariance(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """Joint covariance ``(3n, 3n)`` of distinct poses (right tangent spaces)."""

    def pose_covariances(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """Marginal covariances ``(n, 3, 3)`` of poses."""

    def landmark_covariances(self, graph: LineGraph, landmarks: IntArray) -> FloatArray:
        """Marginal covariances ``(m, 2, 2)`` of landmarks (anchored chart)."""

    def stats(self) -> dict[str, Any]:
        """Counters and timings."""


def _checked(indices: IntArray, every: int = 64) -> Iterator[int]:
    """``indices`` as ints, checking for a signal every ``every`` (:mod:`slam.interrupts`)."""
    for k, i in enumerate(np.asarray(indices).tolist()):
        if k % every == 0:
            interrupts.check()
        yield int(i)


class Isam2Backend:
    """iSAM2, one update per keyframe."""

    name = "isam2"

    def __init__(self, isam2: Isam2Config, solver: SolverConfig) -> None:
        self.solver = Isam2Solver(isam2, solver)
        self.estimate_moved = False
        self._last_full = 0
        self.optimize_updates = 0
        self.resets = 0

    def reset(self, graph: LineGraph) -> None:
        """Start iSAM2 afresh from the graph's current estimate.

        Used after a large correction of it, e.g. a loop closure spread over the trajectory.
        """
        self.resets += 1
        self.solver.restart(graph)
        self._last_full = self.solver.stats.full_refreshes
        self.estimate_moved = True

    def update(self, graph: LineGraph) -> None:
        """One ``ISAM2.update``."""
        self.solver.update(graph)
        full = self.solver.stats.full_refreshes
        self.estimate_moved = full != self._last_full
        self._last_full = full

    def optimize(self, graph: LineGraph, max_updates: int | None = None) -> dict[str, Any]:
        """Extra updates until iSAM2 settles (at most ``max_updates``, default the config's).

        Without ``max_updates`` (the final convergence) every factor is then relinearised at
        the estimate until converged (``Isam2Solver.optimize(exact=True)``).
        """
        t0 = time.perf_counter()
        runs = self.solver.optimize(graph, max_updates, exact=max_updates is None)
        self.optimize_updates += runs
        self.estimate_moved = True
        return {"updates": runs, "time_s": time.perf_counter() - t0}

    def joint_covariance(
        self, graph: LineGraph, pose: int | None, landmarks: IntArray
    ) -> FloatArray:
        """From ``ISAM2.jointMarginalCovariance``."""
        poses = np.zeros(0, dtype=np.intp) if pose is None else np.array([pose])
        return self.solver.joint_covariance(poses, np.asarray(landmarks))

    def joint_pose_covariance(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """From ``ISAM2.jointMarginalCovariance``."""
        return self.solver.joint_covariance(np.asarray(poses), np.zeros(0, dtype=np.intp))

    def pose_covariances(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """``ISAM2.marginalCovariance`` per pose."""
        out = [self.solver.pose_covariance(i) for i in _checked(poses)]
        return np.array(out).reshape(-1, 3, 3)

    def landmark_covariances(self, graph: LineGraph, landmarks: IntArray) -> FloatArray:
        """``ISAM2.marginalCovariance`` per landmark."""
        out = [self.solver.landmark_covariance(j) for j in _checked(landmarks)]
        return np.array(out).reshape(-1, 2, 2)

    def stats(self) -> dict[str, Any]:
        """iSAM2 counters."""
        s = self.solver.stats
        return {
            "backend": self.name,
            "updates": s.updates,
            "blocks_built": s.blocks_built,
            "blocks_relinearized": s.blocks_relinearized,
            "blocks_merged": s.blocks_merged,
            "variables_relinearized": s.variables_relinearized,
            "full_refreshes": s.full_refreshes,
            "resets": self.resets,
            "final_relinearizations": s.final_relinearizations,
            "relinearizations_predicted": s.relinearizations_predicted,
            "relinearizations_unforeseen": s.relinearizations_unforeseen,
            "qr_fallbacks": s.qr_fallbacks,
            "final_step": s.final_step,
            "time_s": dict(s.time_s),
        }


class BatchBackend:
    """Periodic warm-started batch solves; see the module docstring."""

    name = "batch"

    def __init__(self, solver: SolverConfig) -> None:
        self.config = solver
        self.solver = BatchSolver(solver)
        self.estimate_moved = False
        self._since_solve = 0
        self._marginals: gtsam.Marginals | None = None
        self._marg_poses = 0
        self._marg_landmarks: set[int] = set()
        self.solves = 0
        self.iterations = 0
        self.time_s = {"solve": 0.0, "marginals": 0.0}

    def reset(self, graph: LineGraph) -> None:
        """The estimate was changed from outside: the marginals are stale."""
        self._marginals = None
        self.estimate_moved = True

    def update(self, graph: LineGraph) -> None:
        """Solve every ``batch_interval`` keyframes."""
        self._since_solve += 1
        self.estimate_moved = False
        if self._since_solve >= self.config.batch_interval:
            self._solve(graph, self.config.online_iterations)

    def _solve(self, graph: LineGraph, iterations: int) -> None:
        t0 = time.perf_counter()
        st = self.solver.solve(graph, iterations)
        self.time_s["solve"] += time.perf_counter() - t0
        self.solves += 1
        self.iterations += st.iterations
        self._since_solve = 0
        self._marginals = None
        self.estimate_moved = True

    def optimize(self, graph: LineGraph, max_updates: int | None = None) -> dict[str, Any]:
        """A full solve to convergence (``max_updates`` is for iSAM2 and ignored here)."""
        t0 = time.perf_counter()
        st = self.solver.solve(graph)
        self.solves += 1
        self.iterations += st.iterations
        self._since_solve = 0
        self._marginals = None
        self.estimate_moved = True
        dt = time.perf_counter() - t0
        self.time_s["solve"] += dt
        return {
            "iterations": st.iterations,
            "converged": st.converged,
            "reason": st.reason,
            "initial_cost": st.initial_cost,
            "final_cost": st.final_cost,
            "time_s": dt,
        }

    def _ensure_marginals(self, graph: LineGraph) -> gtsam.Marginals:
        if self._marginals is None:
            t0 = time.perf_counter()
            self._marginals = self.solver.marginals(graph)
            self._marg_poses = graph.n_poses
            self._marg_landmarks = {int(j) for j in self.solver.active_landmarks(graph)}
            self.time_s["marginals"] += time.perf_counter() - t0
        return self._marginals

    def _exact(self, poses: list[int], landmarks: list[int]) -> FloatArray:
        assert self._marginals is not None
        keys = keys_of("x", np.asarray(poses, dtype=np.intp)) + keys_of(
            "l", np.asarray(landmarks, dtype=np.intp)
        )
        try:
            jm = self._marginals.jointMarginalCovariance(gtsam.KeyVector(keys))
        except RuntimeError as exc:
            raise EstimationError(f"marginals failed: {exc}") from exc
        return np.asarray(jm.fullMatrix(), dtype=float)

    def _marginal(self, key: int) -> FloatArray:
        """Marginal covariance of one variable of the last solve."""
        assert self._marginals is not None
        try:
            return np.asarray(self._marginals.marginalCovariance(key), dtype=float)
        except RuntimeError as exc:
            raise EstimationError(f"marginals failed: {exc}") from exc

    def _chain_to(self, graph: LineGraph, pose: int) -> tuple[int, list[int]]:
        """Newest pose in the marginals and the odometry factors leading from it to ``pose``."""
        chain: list[int] = []
        i = pose
        while i >= self._marg_poses:
            e = np.flatnonzero(graph.odometry_second == i)
            if e.size == 0:
                raise EstimationError(f"pose {pose} is not linked by odometry to the solved graph")
            chain.append(int(e[0]))
            i = int(graph.odometry_first[e[0]])
        return i, chain[::-1]

    def _new_landmark_cov(self, graph: LineGraph, landmark: int) -> FloatArray:
        """First observation moved into the world with its pose's covariance (anchored chart)."""
        f = int(np.flatnonzero(graph.factor_landmark == landmark)[0])
        p = int(graph.factor_pose[f])
        P_pose = self.joint_covariance(graph, p, np.zeros(0, dtype=np.intp))
        z = np.r_[graph.factor_z[f], 0.0]
        _, B, K = line_to_parent(z, graph.poses[p], normal_form=False)
        R3 = np.zeros((3, 3))
        R3[:2, :2] = graph.factor_cov[f]
        P_ra = (B @ R3 @ B.T + K @ P_pose @ K.T)[:2, :2]
        J_inv = np.linalg.inv(anchored_jacobian(graph.landmarks[landmark], graph.anchors[landmark]))
        return np.asarray(J_inv @ P_ra @ J_inv.T)

    def joint_covariance(
        self, graph: LineGraph, pose: int | None, landmarks: IntArray
    ) -> FloatArray:
        """Exact from the marginals when possible, else propagated (module docstring)."""
        self._ensure_marginals(graph)
        lms = [int(j) for j in np.asarray(landmarks)]
        known = [j for j in lms if j in self._marg_landmarks]
        if pose is None:
            n = 2 * len(lms)
            P = np.zeros((n, n))
            pos = {j: 2 * k for k, j in enumerate(lms)}
            if known:
                idx = np.array([pos[j] + d for j in known for d in (0, 1)], dtype=int)
                P[np.ix_(idx, idx)] = self._exact([], known)
            for j in lms:
                if j not in self._marg_landmarks:
                    P[pos[j] : pos[j] + 2, pos[j] : pos[j] + 2] = self._new_landmark_cov(graph, j)
            return P
        base, chain = (pose, []) if pose < self._marg_poses else self._chain_to(graph, pose)
        P_known = self._exact([base], known)
        # compound the pose along the odometry chain (right perturbation)
        for e in chain:
            F = adjoint_pose2(pose_inverse(graph.odometry_measured[e]))
            P_known[:3, :] = F @ P_known[:3, :]
            P_known[:, :3] = P_known[:, :3] @ F.T
            P_known[:3, :3] += graph.odometry_cov[e]
        n = 3 + 2 * len(lms)
        P = np.zeros((n, n))
        pos = {j: 3 + 2 * k for k, j in enumerate(lms)}
        idx_known = np.r_[np.arange(3), [pos[j] + d for j in known for d in (0, 1)]].astype(int)
        P[np.ix_(idx_known, idx_known)] = P_known
        for j in lms:
            if j not in self._marg_landmarks:
                sl = slice(pos[j], pos[j] + 2)
                P[sl, sl] = self._new_landmark_cov(graph, j)
        return P

    def joint_pose_covariance(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """Joint covariance of poses from the marginals, newer ones compounded.

        Exact for solved poses; a newer pose is compounded along the odometry from the newest
        solved one (as :meth:`joint_covariance`).

        Two poses that are both newer than the last solve share that chain; each is
        compounded on its own, so their correlation through it is left out.
        """
        self._ensure_marginals(graph)
        ps = [int(i) for i in np.asarray(poses)]
        if len(set(ps)) != len(ps):
            raise EstimationError("joint_pose_covariance needs distinct poses")
        routes = [(p, []) if p < self._marg_poses else self._chain_to(graph, p) for p in ps]
        bases = sorted({b for b, _ in routes})
        P_bases = self._exact(bases, [])
        at = {b: 3 * k for k, b in enumerate(bases)}
        idx = np.concatenate([np.arange(at[b], at[b] + 3) for b, _ in routes])
        P = P_bases[np.ix_(idx, idx)]
        for k, (_, chain) in enumerate(routes):
            sl = slice(3 * k, 3 * k + 3)
            for e in chain:  # right perturbation, as in joint_covariance
                F = adjoint_pose2(pose_inverse(graph.odometry_measured[e]))
                P[sl, :] = F @ P[sl, :]
                P[:, sl] = P[:, sl] @ F.T
                P[sl, sl] += graph.odometry_cov[e]
        return np.asarray(P)

    def pose_covariances(self, graph: LineGraph, poses: IntArray) -> FloatArray:
        """Marginals of each pose (newer poses than the last solve compounded)."""
        self._ensure_marginals(graph)
        out = []
        for i in _checked(poses):
            if i < self._marg_poses:
                out.append(self._marginal(keys_of("x", np.array([i]))[0]))
            else:
                out.append(self.joint_covariance(graph, i, np.zeros(0, np.intp)))
        return np.array(out).reshape(-1, 3, 3)

    def landmark_covariances(self, graph: LineGraph, landmarks: IntArray) -> FloatArray:
        """Marginals of each landmark (anchored chart)."""
        self._ensure_marginals(graph)
        out = []
        for j in _checked(landmarks):
            if j in self._marg_landmarks:
                out.append(self._marginal(keys_of("l", np.array([j]))[0]))
            else:
                out.append(self._new_landmark_cov(graph, int(j)))
        return np.array(out).reshape(-1, 2, 2)

    def stats(self) -> dict[str, Any]:
        """Solve counters."""
        return {
            "backend": self.name,
            "solves": self.solves,
            "iterations": self.iterations,
            "time_s": dict(self.time_s),
        }


def make_backend(
    kind: str, solver: SolverConfig, isam2: Isam2Config
) -> BatchBackend | Isam2Backend:
    """The back-end named ``kind`` (``"batch"`` or ``"isam2"``)."""
    if kind == "batch":
        return BatchBackend(solver)
    return Isam2Backend(isam2, solver)
