"""Loop closing: search the old map for the local submap, gate, judge, apply or roll back.

Every ``loop_closure.interval_keyframes`` keyframes (:meth:`LoopCloser.attempt`):

1. **Search.**  The local submap (landmarks seen in the last ``local_keyframes`` keyframes) is
   searched for among the old landmarks (drifted beyond the front end's reach, near the robot)
   within a window of ``window_sigmas`` standard deviations of the drift since the old
   landmarks were last seen (:mod:`slam.line_slam.drift`; at least ``min_window_*``;
   :func:`slam.frontend.loop_closure.search_loop_closure`).  Every accepted closure tells the
   drift accumulator how far off the prediction was (its scale).
2. **Repeats.**  A hypothesis that repeats one rejected recently (same correction, no more pairs)
   is not judged again (``skip_repeated_rejections``).
3. **Consistency.**  The hypothesis, as a relative pose between the old keyframe and the
   current one, is compared with the front end's own trajectory between them (free of loop
   closures, so an earlier wrong closure cannot bias it) under that trajectory's covariance
   (:meth:`DriftAccumulator.relative_cov`): the squared Mahalanobis distance is logged
   (``correction_chi2``), not used as a gate.  With
   ``confirmations`` of 1 or more it must agree with that many other recent hypotheses
   (pairwise consistency through the front end's chains, as in PCM, Mangelson et al. 2018;
   within the ``consistency_probability`` quantile of χ²): a revisit is then recognised twice
   before it is judged; with ``judge_unconfirmed`` one that no other confirms is judged on
   its own by the next attempt that finds no new hypothesis, unless a newer one that
   contradicts it has taken its place (with ``judge_replaced`` it is then judged at once, and
   the newer one waits only if it is rejected); with ``agreement_same_place`` only
   hypotheses of the same revisit (old keyframes within ``local_keyframes``) agree.  How many
   recent hypotheses agree is passed to the judge either way.  The defaults: all three, with
   ``confirmations = 1``.
   With ``consistent_with_accepted`` it must also be consistent with every closure accepted
   within the last ``local_keyframes`` keyframes, by the same cycle with each hypothesis' own
   covariance (its paired lines' and the drift across its local submap): right after a
   closure the two places are tied, and a hypothesis that moves the robot further than that
   matched other walls; it is turned away before the judge (:meth:`LoopCloser.contradiction`).
   With ``graph_gate``, when it is about to be judged, it must also agree with the graph's
   own estimate of that relative pose, under the covariance the back end's joint marginal of
   the two keyframes gives it, scaled by what the closures accepted so far measured of that
   covariance, plus the hypothesis' own (:meth:`LoopCloser.graph_test`,
   :meth:`LoopCloser.graph_scale`); one that does not is rejected without the judge's solves.
4. **Judge.**  A large correction is first spread over the loop (:func:`spread_correction`); the
   paired landmarks are merged and a batch solve of the loop
   (:class:`slam.graph.batch.BatchSolver`, at most ``judge_iterations``) outside the back-end
   decides: the closure is kept when enough merged pairs are explained
   (:class:`slam.line_slam.audit.MergeAudit`) and the loop's cost rises little per merged
   degree of freedom against the loop solved without it (``judge_from_converged``: each at
   its own optimum; an F test in χ², or, for a closure whose every pair is explained and
   that a recent hypothesis agrees with, in the solver's robust cost:
   ``judge_robust_cost``; for a closure no hypothesis agrees with, in both costs:
   ``judge_alone_both_costs``; for a closure that lowers the loop's χ², in the robust cost
   too: ``judge_negative_f_robust``), else the landmark book is restored to its snapshot and the
   back-end never sees it.  An accepted closure with a large correction
   restarts the back-end from the judged estimate; a small one reaches it incrementally.
5. **Reconsider** (``reconsider_keyframes``: by default any closure accepted earlier; a
   number of keyframes limits it, 0 turns it off).  A rejected hypothesis that contradicts an
   accepted closure, lies closer to the front end's own trajectory than that closure did and has
   more recent hypotheses agreeing with it than the closure had, is judged again with the
   closure undone (its merges and the observations added to its merged landmarks since), the
   loops solved without it and its correction read again on that estimate
   (:meth:`LoopCloser.reconsider`): accepted, it replaces the closure; rejected, everything is
   as before.

Every attempt is recorded as a :class:`ClosureAttempt` (``summary.json``:
``loop_closures_log``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.association import candidate_landmarks
from slam.errors import EstimationError
from slam.frontend.loop_closure import (
    LoopClosure,
    correction_covariance,
    same_correction,
    search_loop_closure,
)
from slam.geometry import adjoint_pose2, pose_between, pose_compose, pose_inverse, pose_log
from slam.graph.backend import BatchBackend, Isam2Backend
from slam.graph.batch import BatchSolver
from slam.graph.problem import MergeRecord
from slam.graph.robust import RobustKernel
from slam.line_slam.audit import MergeAudit, residual_chi2
from slam.line_slam.clock import StageClock
from slam.line_slam.config import SlamConfig
from slam.line_slam.drift import DriftAccumulator
from slam.line_slam.keyframes import EveryKeyframes, KeyframeTrack
from slam.line_slam.landmarks import LandmarkBook
from slam.lines.merge import chi2_ppf

__all__ = ["ClosureAttempt", "Hypothesis", "LoopCloser", "spread_correction"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


_WHERE = ("scan", "old_keyframe", "old_scan", "pose_before", "old_pose_before")
_ORDER = {
    "not_found": ("keyframe", "local", "old", "window", "accepted", "reason"),
    "repeated": ("keyframe", "pairs", "correction", "accepted", "reason"),
    "gated": (
        "keyframe",
        "pairs",
        "correction",
        "correction_chi2",
        "graph_chi2",
        "graph_scale",
        "accepted",
        "reason",
        *_WHERE,
    ),
    "judged": (
        "keyframe",
        "pairs",
        "consistent_pairs",
        "worst_pair_chi2",
        "correction",
        "single_direction",
        "corridor_normal",
        "score",
        "runner_up",
        "judge_iterations",
        "judge_stop",
        "judge_free_from",
        "f_statistic",
        "f_statistic_robust",
        "agreeing_hypotheses",
        "reconsidered_closure",
        "judged_late",
        "judged_at_keyframe",
        "correction_chi2",
        "graph_chi2",
        "graph_scale",
        *_WHERE,
        "accepted",
        "backend_restarted",
    ),
}


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """A loop-closure hypothesis as a relative-pose measurement.

    Attributes
    ----------
    keyframe, k_old : int
        The current keyframe and the old one (where the paired old lines were last seen).
    z : ndarray, shape (3,)
        Pose of ``keyframe`` in the frame of ``k_old`` that the hypothesis implies.
    normal : ndarray, shape (2,) or None
        Along a corridor, the walls' normal in ``keyframe``'s frame (the component of ``z``
        along the walls is not measured); None otherwise.
    cov : ndarray, shape (3, 3) or None
        Covariance of the correction, in ``keyframe``'s frame: its paired lines'
        (:func:`slam.frontend.loop_closure.correction_covariance`) plus the front end's drift
        across the local submap; None when not computed.
    """

    keyframe: int
    k_old: int
    z: FloatArray
    normal: FloatArray | None = None
    cov: FloatArray | None = None

    @property
    def single(self) -> bool:
        """Corridor hypothesis (one direction)."""
        return self.normal is not None


@dataclass(frozen=True, eq=False)
class _Pending:
    """A hypothesis awaiting confirmation, with what :meth:`LoopCloser.apply` needs."""

    local: IntArray
    old: IntArray
    found: LoopClosure
    chi2_t: float
    hypothesis: Hypothesis


@dataclass(frozen=True, eq=False)
class _Accepted:
    """An accepted closure, as a later hypothesis may overturn it.

    Its hypothesis, its chain χ², the merges it made, how many hypotheses agreed with it, the
    first pose its judgement solved, and what it measured of the graph's covariance (its
    :class:`GraphTest`, None without one), which leaves :meth:`LoopCloser.graph_scale` with it
    when it is dropped.
    """

    hypothesis: Hypothesis
    chain_chi2: float
    records: list[MergeRecord]
    agreeing: int = 0
    free_from: int = 0
    graph: GraphTest | None = None

    @property
    def keyframe(self) -> int:
        return self.hypothesis.keyframe


@dataclass(frozen=True)
class GraphTest:
    """A hypothesis against the graph's own estimate (:meth:`LoopCloser.graph_test`).

    ``raw``: ``eᵀ S⁻¹ e`` under the graph's covariance as it is, with ``dof`` degrees of
    freedom; ``chi2``: ``eᵀ (k S + C)⁻¹ e`` with the graph's covariance scaled by ``scale``
    (``k``) and the hypothesis' own ``C``, None before any closure has been accepted (no
    scale yet).  ``w2`` and ``lam`` (``(dof,)``): the same χ² for every scale,
    ``eᵀ (k S + C)⁻¹ e = Σ w2 / (k lam + 1)`` (:func:`scaled_chi2_terms`).
    """

    raw: float
    dof: int
    chi2: float | None
    scale: float | None
    w2: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)
    lam: FloatArray = field(default_factory=lambda: np.zeros(0), repr=False)

    def chi2_at(self, k: float) -> float:
        """``eᵀ (k S + C)⁻¹ e``."""
        return float(np.sum(self.w2 / (k * self.lam + 1.0)))


def _scale_upper_bound(w2: FloatArray, lam: FloatArray, deviance: float) -> float:
    """Upper confidence bound of ``k ≥ 1`` from errors ``e ~ N(0, k S + C)`` (profile likelihood).

    In the terms of :func:`scaled_chi2_terms` the negative log-likelihood is, up to a
    constant, ``½ Σ [log(1 + k λ) + w² / (1 + k λ)]``.  Its minimum over ``k ≥ 1`` is ``k̂``;
    the bound is the ``k > k̂`` at which it has risen by ``deviance / 2`` (the likelihood-ratio
    bound).  Where ``S`` is small against ``C`` the errors say little about ``k``, and the
    bound is large: as large as makes ``k S`` comparable with ``C``.
    """

    def nll(k: float) -> float:
        d = 1.0 + k * lam
        return 0.5 * float(np.sum(np.log(d) + w2 / d))

    grid = np.logspace(0.0, 15.0, 151)
    values = np.array([nll(k) for k in grid])
    i = int(np.argmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    for _ in range(100):  # golden section in log k about the grid's minimum
        a = lo * (hi / lo) ** 0.382
        b = lo * (hi / lo) ** 0.618
        if nll(a) < nll(b):
            hi = b
        else:
            lo = a
        if hi / lo - 1.0 < 1e-9:
            break
    k_hat = max(float(np.sqrt(lo * hi)), 1.0)
    target = nll(k_hat) + 0.5 * deviance
    above = np.flatnonzero((grid > k_hat) & (values >= target))
    if above.size == 0:
        return float(grid[-1])
    lo, hi = k_hat, float(grid[above[0]])
    for _ in range(200):  # bisection in log k
        mid = math.sqrt(lo * hi)
        if nll(mid) < target:
            lo = mid
        else:
            hi = mid
        if hi / lo - 1.0 < 1e-10:
            break
    return hi


def scaled_chi2_terms(e: FloatArray, S: FloatArray, C: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(w², λ)`` such that ``eᵀ (k S + C)⁻¹ e = Σ w² / (k λ + 1)`` for every ``k ≥ 0``.

    ``C = L Lᵀ`` (Cholesky), ``L⁻¹ S L⁻ᵀ = U diag(λ) Uᵀ``, ``w = Uᵀ L⁻¹ e``: ``S`` and ``C``
    diagonalised together.  ``C`` must be positive definite; ``S`` positive semi-definite
    (a negative ``λ`` from rounding is set to 0).
    """
    L = np.linalg.cholesky(C)
    Li = np.linalg.inv(L)
    lam, U = np.linalg.eigh(Li @ S @ Li.T)
    w = U.T @ (Li @ e)
    return w * w, np.maximum(lam, 0.0)


@dataclass
class ClosureAttempt:
    """One loop-closure attempt that found a hypothesis or searched in vain.

    ``kind`` is ``"not_found"`` (the search found nothing: ``local``, ``old`` landmarks and the
    ``window`` (m, rad) searched), ``"repeated"`` (repeats a rejected hypothesis: ``reason``),
    ``"gated"`` (not judged now: awaiting a confirming hypothesis, or contradicting a recent
    closure: ``reason``) or ``"judged"``.  Keyframes and scans are 0-based; ``correction`` is
    ``(t_x, t_y, dθ)`` (m, m, rad) about the current pose; ``correction_chi2`` the hypothesis'
    squared Mahalanobis distance from the front end's own trajectory
    (:meth:`LoopCloser.chain_chi2`); ``graph_chi2`` its distance from the graph's estimate
    under the graph's covariance scaled by ``graph_scale`` (:meth:`LoopCloser.graph_test`);
    ``pose_before``/``old_pose_before`` the two keyframes' estimates before the attempt;
    ``consistent_pairs`` of ``pairs`` were explained by the judge, whose worst pair left
    ``worst_pair_chi2``; along a corridor (``single_direction``) ``corridor_normal`` is the
    walls' unit normal in the world frame (only the correction's component along it is used);
    ``judged_late`` marks a hypothesis found at ``keyframe`` that waited for confirmation and
    was judged by the attempt at ``judged_at_keyframe`` (None: at the end of the run).
    """

    kind: str
    keyframe: int
    accepted: bool = False
    reason: str | None = None
    local: int | None = None
    old: int | None = None
    window: list[float] | None = None
    pairs: int | None = None
    correction: list[float] | None = None
    correction_chi2: float | None = None
    graph_chi2: float | None = None
    graph_scale: float | None = None
    consistent_pairs: int | None = None
    worst_pair_chi2: float | None = None
    single_direction: bool | None = None
    corridor_normal: list[float] | None = None
    score: float | None = None
    runner_up: float | None = None
    judge_iterations: int | None = None
    judge_stop: str | None = None
    judge_free_from: int | None = None
    backend_restarted: bool | None = None
    f_statistic: float | None = None
    f_statistic_robust: float | None = None
    agreeing_hypotheses: int | None = None
    reconsidered_closure: int | None = None
    judged_late: bool | None = None
    judged_at_keyframe: int | None = None
    where: dict[str, Any] = field(default_factory=dict)

    def as_log(self) -> dict[str, Any]:
        """The attempt as a ``loop_closures_log`` entry (JSON-ready; unset fields left out)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(self.where)
        return {k: values[k] for k in _ORDER[self.kind] if values.get(k) is not None}


def spread_correction(
    book: LandmarkBook,
    track: KeyframeTrack,
    correction: FloatArray,
    center: FloatArray,
    k_old: int,
    pose: int,
    local_keyframes: int,
) -> None:
    """Move the estimate towards a loop closure before optimising (a good starting point).

    The local submap (the last ``local_keyframes`` keyframes) moves by the whole correction
    ``T`` (``p → R(dθ)(p − c) + c + t``), poses since ``k_old`` (when the old landmarks were
    last seen) by the fraction ``f`` of the path driven since then, ``T_f = (f t, f dθ)``;
    landmarks move with the fraction of their last sighting.
    """
    g = book.graph
    path = track.keyframe_path_m
    start = max(pose - local_keyframes, 0)
    span = max(path[start] - path[k_old], 1e-9)

    def fraction(kf: IntArray) -> FloatArray:
        return np.clip((path[kf] - path[k_old]) / span, 0.0, 1.0)

    tx, ty, dth = (float(v) for v in correction)
    f = fraction(np.arange(g.n_poses))
    ang = f * dth
    cs, sn = np.cos(ang), np.sin(ang)
    d = g.poses[:, :2] - center
    g.poses[:, 0] = cs * d[:, 0] - sn * d[:, 1] + center[0] + f * tx
    g.poses[:, 1] = sn * d[:, 0] + cs * d[:, 1] + center[1] + f * ty
    g.poses[:, 2] = np.asarray(wrap_angle(g.poses[:, 2] + ang))
    alive = np.flatnonzero(g.landmark_alive)
    fl = fraction(book.last_keyframe[alive])
    la = g.landmarks_r_alpha[alive]
    a_new = la[:, 1] + fl * dth
    n_old = np.stack([np.cos(la[:, 1]), np.sin(la[:, 1])], -1)
    n_new = np.stack([np.cos(a_new), np.sin(a_new)], -1)
    r_new = la[:, 0] - n_old @ center + n_new @ center + n_new @ np.array([tx, ty]) * fl
    g.set_landmarks_r_alpha(alive, np.column_stack([r_new, a_new]))


class LoopCloser:
    """Loop closing over the landmark book (module docstring).

    Parameters
    ----------
    book, track, drift, audit
        The run's landmark book, keyframe track, drift accumulator and merge audit.
    backend : BatchBackend or Isam2Backend
        The online back-end (brought to the graph and converged after an accepted closure).
    config : SlamConfig
        ``loop_closure``, ``association.max_range_m``, the front end's drift model, the
        solver settings of the judge, ``fusion.audit_max_median_chi2``.
    counters : dict
        The run's counters (``loop_closure_*``, ``loop_closures*``).
    clock : StageClock
        Times ``loop_closure``, and within it ``judge`` and ``backend``.
    """

    def __init__(
        self,
        book: LandmarkBook,
        track: KeyframeTrack,
        drift: DriftAccumulator,
        audit: MergeAudit,
        backend: BatchBackend | Isam2Backend,
        config: SlamConfig,
        counters: dict[str, int],
        clock: StageClock,
    ) -> None:
        self.book = book
        self.track = track
        self.drift = drift
        self.audit = audit
        self.backend = backend
        self.config = config
        self.counters = counters
        self.clock = clock
        self.attempts: list[ClosureAttempt] = []
        # judged and rejected hypotheses: (keyframe, correction, paired lines)
        self._rejected: list[tuple[int, FloatArray, int]] = []
        # recent hypotheses that passed the drift test (for confirmation)
        self._recent: list[Hypothesis] = []
        # recently accepted closures (consistent_with_accepted, reconsider_keyframes)
        self._accepted: list[_Accepted] = []
        # the hypothesis awaiting confirmation, judged late (judge_unconfirmed), and the one it
        # has just replaced, to be judged now (judge_replaced)
        self._pending: _Pending | None = None
        self._replaced: _Pending | None = None
        self._every = EveryKeyframes()
        # the graph's covariance against the closures accepted so far (graph_gate): each
        # closure's test, and the scale they give (None: not worked out since the last change)
        self._graph_tests: list[GraphTest] = []
        self._graph_scale: float | None = None
        self._judge = BatchSolver(
            replace(config.solver, relative_tolerance=config.loop_closure.judge_relative_tolerance)
        )

    def due(self) -> bool:
        """Count a keyframe; whether an attempt is due (every ``interval_keyframes``)."""
        lcc = self.config.loop_closure
        return self._every.tick(lcc.enabled, lcc.interval_keyframes)

    # -- one attempt -------------------------------------------------------------------------
    def attempt(self, pose: int) -> int:
        """Search, gate, judge; returns 1 when a closure was accepted, else 0.

        With ``judge_unconfirmed``, an attempt that finds no new hypothesis judges the one
        left awaiting confirmation by an earlier attempt (:meth:`judge_pending`).
        """
        with self.clock("loop_closure"):
            n_attempts = len(self.attempts)
            accepted = self._attempt(pose)
            new = self.attempts[n_attempts:]
            if self._replaced is not None:
                accepted += self._judge_replaced(pose)
            elif not any(a.kind in ("gated", "judged") for a in new):
                accepted += self._judge_pending(pose)
            return accepted

    def judge_pending(self) -> int:
        """Judge the hypothesis still awaiting confirmation, if any (at the end of a run).

        Returns 1 when it was accepted, else 0.
        """
        with self.clock("loop_closure"):
            return self._judge_pending(None)

    def _judge_replaced(self, now: int) -> int:
        """Judge the hypothesis the newest one replaced (``judge_replaced``), late.

        If it is accepted, the newest one (which does not agree with it) is dropped; else the
        newest one waits.  Returns 1 when it was accepted, else 0.
        """
        replaced, self._replaced = self._replaced, None
        assert replaced is not None
        gated = self.attempts[-1]  # the newer one's entry (gate() has just replaced)
        accepted = self._judge_late(replaced, now)
        if accepted:
            self._pending = None
            gated.reason = (gated.reason or "") + "; dropped: the one it replaced was accepted"
        return accepted

    def _judge_pending(self, now: int | None) -> int:
        pending, self._pending = self._pending, None
        return 0 if pending is None else self._judge_late(pending, now)

    def _judge_late(self, candidate: _Pending, now: int | None) -> int:
        """Judge a hypothesis that waited (``judged_late``, by the attempt at ``now``)."""
        return self.apply(
            candidate.local,
            candidate.old,
            candidate.found,
            candidate.hypothesis.keyframe,
            candidate.chi2_t,
            0,
            candidate.hypothesis,
            late=True,
            judged_at=now,
        )

    def _attempt(self, pose: int) -> int:
        cfg = self.config
        lcc = cfg.loop_closure
        book = self.book
        g = book.graph
        alive = book.alive_with_extent()
        last = book.last_keyframe
        local = np.flatnonzero(alive & (last > pose - lcc.local_keyframes))
        if local.size < lcc.min_matches:
            return 0
        x = g.poses[pose]
        sxy, sth = self.drift.since(last)
        old_mask = (
            alive & (sxy > cfg.frontend.max_drift_xy_m) & (last <= pose - lcc.local_keyframes)
        )
        win_xy = np.maximum(lcc.window_sigmas * sxy, lcc.min_window_xy_m)
        win_th = np.maximum(lcc.window_sigmas * sth, lcc.min_window_theta_rad)
        reach = cfg.association.max_range_m + win_xy
        near = candidate_landmarks(
            x,
            g.landmarks_r_alpha,
            book.extents,
            float(reach.max(initial=0.0)),
            alive=old_mask,
            anchors=g.anchors,
        )
        if near.size < lcc.min_matches:
            return 0
        if lcc.graph_window:
            window = self.graph_window(int(np.median(last[near])), pose)
            if window is not None:  # the graph's, where it is narrower than the drift's
                win_xy[near] = np.minimum(win_xy[near], window[0])
                win_th[near] = np.minimum(win_th[near], window[1])
        # the window: what the oldest candidate allows (capped); a hypothesis must also lie
        # within what the old lines it pairs allow (window_of_pairs)
        wxy = float(np.max(win_xy[near]))
        wth = float(np.max(win_th[near]))
        self.counters["loop_closure_attempts"] += 1
        search = search_loop_closure(
            book.loop_lines(local),
            book.loop_lines(near),
            x[:2],
            wxy,
            wth,
            lcc,
            old_windows=(win_xy[near], win_th[near]) if lcc.window_of_pairs else None,
        )
        found = search.closure
        if found is None:
            self.attempts.append(
                ClosureAttempt(
                    "not_found",
                    int(pose),
                    reason=search.reason,
                    local=int(local.size),
                    old=int(near.size),
                    window=[wxy, wth],
                )
            )
            return 0
        repeated = self.repeated_rejection(found, pose)
        if repeated is not None:
            self.attempts.append(
                ClosureAttempt(
                    "repeated",
                    int(pose),
                    reason=f"repeats the hypothesis rejected at keyframe {repeated}",
                    pairs=len(found.pairs),
                    correction=[float(v) for v in found.correction],
                )
            )
            self.counters["loop_closures_repeated"] += 1
            return 0
        # consistency: with the front end's own trajectory, then with an earlier hypothesis
        k_old = int(np.median(last[near[[j for _, j in found.pairs]]]))
        # the correction's covariance: its pairs, and the drift across the local submap (the
        # correction lays the whole submap, seen over the last local_keyframes, onto the old
        # lines; the current pose is at one end of it)
        cov = correction_covariance(
            book.loop_lines(local),
            book.loop_lines(near),
            found.pairs,
            x[:2],
            found.correction,
            lcc,
            (wxy, wth),
        )
        dxy, dth = self.drift.between(max(pose - lcc.local_keyframes, 0), pose)
        cov = cov + np.diag([float(dxy) ** 2, float(dxy) ** 2, float(dth) ** 2])
        hyp = self.hypothesis(found, near, pose, k_old, cov)
        chi2_t = self.chain_chi2(hyp)
        agree = self.agreement(hyp)
        reason = self.gate(_Pending(local, near, found, chi2_t, hyp), agree)
        if reason is not None:
            self.attempts.append(
                ClosureAttempt(
                    "gated",
                    int(pose),
                    reason=reason,
                    pairs=len(found.pairs),
                    correction=[float(v) for v in found.correction],
                    correction_chi2=chi2_t,
                    where=self.where(pose, k_old),
                )
            )
            self.counters["loop_closures_gated"] += 1
            return 0
        return self.apply(local, near, found, pose, chi2_t, agree, hyp)

    # -- the rules ---------------------------------------------------------------------------
    def gate(self, candidate: _Pending, agree: int) -> str | None:
        """Why a hypothesis is not judged now, or None (it is judged at once).

        ``agree`` recent hypotheses agree with it (:meth:`agreement`).  It is turned away when
        it contradicts a recent closure (``consistent_with_accepted``), and waits while fewer
        than ``confirmations`` agree; with ``judge_unconfirmed`` it is then kept, in place of
        any earlier one waiting (which it does not agree with), for :meth:`attempt` to judge
        at the next attempt that finds no new hypothesis (with ``judge_replaced`` the earlier
        one is kept for :meth:`attempt` to judge now).  One judged at once clears the one
        waiting (it agrees with it).
        """
        lcc = self.config.loop_closure
        reason = self.contradiction(candidate.hypothesis) if lcc.consistent_with_accepted else None
        if reason is not None:
            return reason
        if agree >= lcc.confirmations:
            self._pending = None
            return None
        reason = "awaiting a consistent second hypothesis"
        if lcc.judge_unconfirmed:
            if self._pending is not None:
                reason += (
                    f" (replaces the one waiting since keyframe "
                    f"{self._pending.hypothesis.keyframe}, which it does not agree with)"
                )
                if lcc.judge_replaced:
                    self._replaced = self._pending
            self._pending = candidate
        return reason

    @property
    def waiting(self) -> Hypothesis | None:
        """The hypothesis awaiting confirmation (``judge_unconfirmed``), or None."""
        return None if self._pending is None else self._pending.hypothesis

    def repeated_rejection(self, found: LoopClosure, pose: int) -> int | None:
        """The keyframe of a recent rejected hypothesis that ``found`` repeats, if any.

        See ``LoopClosureConfig.skip_repeated_rejections``.
        """
        lcc = self.config.loop_closure
        self._rejected = [r for r in self._rejected if r[0] > pose - lcc.local_keyframes]
        if not lcc.skip_repeated_rejections:
            return None
        corr = np.asarray(found.correction, dtype=float)
        for kf, rejected, n_pairs in self._rejected:
            if same_correction(corr, rejected, lcc) and len(found.pairs) <= n_pairs:
                return kf
        return None

    def _corridor_angle(self, found: LoopClosure, old: IntArray) -> float | None:
        """Along a corridor, the angle of the walls' normal (world frame); None otherwise."""
        if not found.single_direction:
            return None
        return float(self.book.loop_lines(old[[found.pairs[0][1]]]).alpha[0])

    def corridor_normal(self, found: LoopClosure, old: IntArray) -> FloatArray | None:
        """Along a corridor, the walls' unit normal (world frame); None otherwise."""
        a = self._corridor_angle(found, old)
        return None if a is None else np.array([np.cos(a), np.sin(a)])

    def effective_correction(self, found: LoopClosure, old: IntArray) -> FloatArray:
        """The hypothesis' correction; along a corridor without its arbitrary along-component."""
        corr = np.asarray(found.correction, dtype=float).copy()
        n = self.corridor_normal(found, old)
        if n is not None:
            corr[:2] = (corr[:2] @ n) * n
        return corr

    def correction_at(self, h: Hypothesis) -> FloatArray:
        """The correction ``(t_x, t_y, dθ)`` that ``h`` asks of the current estimate.

        The inverse of :meth:`hypothesis`: the move of keyframe ``h.keyframe`` (about its
        position) onto ``x_old ∘ z``, with the two keyframes' estimates as they are now.
        """
        g = self.book.graph
        x = g.poses[h.keyframe]
        target = pose_compose(g.poses[h.k_old], h.z)
        return np.array([target[0] - x[0], target[1] - x[1], float(wrap_angle(target[2] - x[2]))])

    def graph_scale(self) -> float | None:
        """How many times too small the graph's covariance of a loop is, from its closures.

        Each closure accepted so far, and not dropped since (:meth:`reconsider`), measured it:
        its hypothesis ``z`` against the graph's relative pose of the two keyframes, before the
        closure, ``e ~ N(0, k S + C)`` (``S`` the graph's covariance, ``C`` the hypothesis'
        own, ``k`` the scale).  The scale is an upper confidence bound of ``k ≥ 1`` at
        ``consistency_probability``:

        * all of the error put on the graph (``C`` left out, so ``E[eᵀS⁻¹e] ≥ k dof``):
          ``Σ eᵀS⁻¹e`` over χ²'s quantile ``1 − p`` for the summed dof;
        * with ``graph_scale_with_hypotheses``, the smaller of that and the likelihood bound
          with ``C`` (:func:`_scale_upper_bound`), which can tell ``k`` where ``S`` is not
          small against ``C``; where it is, the first bound is the tighter.

        None before the first closure.
        """
        tests = self._graph_tests
        if not tests:
            return None
        if self._graph_scale is None:
            p = self.config.loop_closure.consistency_probability
            # all of the closures' error put on the graph: E[eᵀS⁻¹e] = k dof + tr(S⁻¹C)
            dof = sum(t.dof for t in tests)
            alone = max(sum(t.raw for t in tests) / max(chi2_ppf(1.0 - p, dof), 1e-12), 1.0)
            self._graph_scale = alone
            if self.config.loop_closure.graph_scale_with_hypotheses:
                # with the hypotheses' own covariance (one-sided: χ²₁'s quantile 2p − 1)
                w2 = np.concatenate([t.w2 for t in tests])
                lam = np.concatenate([t.lam for t in tests])
                both = _scale_upper_bound(w2, lam, chi2_ppf(2.0 * p - 1.0, 1))
                self._graph_scale = min(alone, both)
        return self._graph_scale

    def graph_report(self) -> dict[str, Any]:
        """``summary.json`` ``loop_closure_graph_scale``: what the accepted closures measured."""
        tests = self._graph_tests
        n = sum(t.dof for t in tests)
        return {
            "dof": n,
            "chi2_per_dof": sum(t.raw for t in tests) / n if n else None,
            "chi2_per_dof_with_hypotheses": (sum(t.chi2_at(1.0) for t in tests) / n if n else None),
            "scale": self.graph_scale(),
        }

    def graph_relative_cov(self, k_old: int, pose: int) -> tuple[FloatArray, FloatArray] | None:
        """The graph's pose of keyframe ``pose`` in the frame of ``k_old``, and its covariance.

        ``J Σ Jᵀ`` from the back end's joint marginal ``Σ`` of the two keyframes (right
        perturbations: ``∂x̂/∂x_old = −Ad(x̂⁻¹)``, ``∂x̂/∂x_k = I``).  None when the back end
        gives no covariance or it is not finite.
        """
        g = self.book.graph
        try:
            P = self.backend.joint_pose_covariance(g, np.array([k_old, pose]))
        except EstimationError:
            return None
        est = pose_between(g.poses[k_old], g.poses[pose])
        J = np.hstack([-adjoint_pose2(pose_inverse(est)), np.eye(3)])
        S = J @ P @ J.T
        if not np.all(np.isfinite(S)):
            return None
        return est, S

    def graph_window(self, k_old: int, pose: int) -> tuple[float, float] | None:
        """Search window (m, rad) from the graph's scaled relative covariance (``graph_window``).

        ``window_sigmas`` standard deviations of :meth:`graph_relative_cov` scaled by
        :meth:`graph_scale` (the largest in the plane; the heading's), at least the
        ``min_window_*``; None before the first closure or without a covariance.
        """
        lcc = self.config.loop_closure
        k = self.graph_scale()
        rel = None if k is None else self.graph_relative_cov(k_old, pose)
        if k is None or rel is None:
            return None
        S = k * rel[1]
        wxy = lcc.window_sigmas * float(np.sqrt(np.max(np.linalg.eigvalsh(S[:2, :2]))))
        wth = lcc.window_sigmas * float(np.sqrt(S[2, 2]))
        return max(wxy, lcc.min_window_xy_m), max(wth, lcc.min_window_theta_rad)

    def graph_test(
        self, found: LoopClosure, old: IntArray, pose: int, k_old: int, h: Hypothesis
    ) -> GraphTest | None:
        """The hypothesis against the graph's estimate of the same relative pose.

        ``e = Log(x̂⁻¹ z)``: ``z`` the hypothesis' pose of keyframe ``pose`` in the frame of
        ``k_old`` (:meth:`hypothesis`, at the current estimate), ``x̂`` the graph's; ``S =
        J Σ Jᵀ`` the covariance of ``x̂`` from the back end's joint marginal ``Σ`` of the two
        keyframes (right perturbations: ``∂x̂/∂x_old = −Ad(x̂⁻¹)``, ``∂x̂/∂x_k = I``); ``C`` the
        hypothesis' own covariance (its paired lines' and the drift across the local submap);
        along a corridor the direction along the walls left out.  ``S`` is scaled by
        :meth:`graph_scale`, what the closures accepted so far measured of it (the graph
        counts every sighting of a wall as an independent measurement, while the sightings of
        one pass may share their error).  None when the back end gives no covariance or ``h``
        has none.
        """
        if h.cov is None:
            return None
        now = self.hypothesis(found, old, pose, k_old)
        rel = self.graph_relative_cov(k_old, pose)
        if rel is None:
            return None
        est, S = rel
        e = pose_log(pose_between(est, now.z))
        if not np.all(np.isfinite(e)):
            return None
        normals = [] if now.normal is None else [now.normal]
        k = self.graph_scale()
        try:
            B = self._counted_basis(normals)  # the directions counted (3, dof)
            dof = int(B.shape[1])
            raw = self._mahalanobis_in(e, S + 1e-12 * np.eye(3), B)
            chi2 = None if k is None else self._mahalanobis_in(e, k * S + h.cov, B)
            w2, lam = scaled_chi2_terms(B.T @ e, B.T @ S @ B, B.T @ h.cov @ B + 1e-12 * np.eye(dof))
        except np.linalg.LinAlgError:
            return None
        return GraphTest(float(raw), int(dof), chi2, k, w2, lam)

    def hypothesis(
        self,
        found: LoopClosure,
        old: IntArray,
        pose: int,
        k_old: int,
        cov: FloatArray | None = None,
    ) -> Hypothesis:
        """A found closure as a relative-pose measurement from keyframe ``k_old`` to ``pose``.

        The correction moves the current keyframe by ``(t, dθ)`` (it rotates about its
        position), so it measures ``z = x_old⁻¹ ∘ (x_k + (t, dθ))`` with the estimates at the
        time.  Along a corridor the correction's component along the walls is arbitrary: the
        hypothesis then carries the walls' normal (in the current keyframe's frame).  ``cov``
        (world frame, the correction's) is carried in the current keyframe's frame.
        """
        g = self.book.graph
        x = g.poses[pose]
        corr = self.effective_correction(found, old)
        moved = np.array([x[0] + corr[0], x[1] + corr[1], float(wrap_angle(x[2] + corr[2]))])
        z = pose_between(g.poses[k_old], moved)
        normal = None
        a = self._corridor_angle(found, old)
        if a is not None:
            normal = np.array([np.cos(a - float(moved[2])), np.sin(a - float(moved[2]))])
        cov_k = None
        if cov is not None:
            c, s = np.cos(moved[2]), np.sin(moved[2])
            R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            cov_k = R.T @ cov @ R
        return Hypothesis(int(pose), int(k_old), z, normal, cov_k)

    def _z_cov(self) -> FloatArray:
        lcc = self.config.loop_closure
        return np.diag(
            [lcc.offset_tolerance_m**2, lcc.offset_tolerance_m**2, lcc.angle_tolerance_rad**2]
        )

    def _chi2_limit(self, dof: int) -> float:
        return chi2_ppf(self.config.loop_closure.consistency_probability, dof)

    @staticmethod
    def _mahalanobis(
        e: FloatArray, cov: FloatArray, normals: list[FloatArray]
    ) -> tuple[float, int]:
        """``eᵀ S⁻¹ e`` without the components along any corridor, and its χ² dof.

        The tangents of ``normals`` are left out; the dof is the number of directions counted.
        """
        B = LoopCloser._counted_basis(normals)
        return LoopCloser._mahalanobis_in(e, cov, B), int(B.shape[1])

    @staticmethod
    def _mahalanobis_in(e: FloatArray, cov: FloatArray, B: FloatArray) -> float:
        """``eᵀ S⁻¹ e`` in the directions of the orthonormal basis ``B`` (3, dof)."""
        eb = B.T @ e
        Sb = B.T @ cov @ B
        return float(eb @ np.linalg.solve(Sb, eb))

    @staticmethod
    def _counted_basis(normals: list[FloatArray]) -> FloatArray:
        """Orthonormal basis ``(3, dof)`` of the directions a test counts.

        The tangents of ``normals`` (the directions along a corridor's walls) are left out.
        """
        P = np.eye(3)
        for n in normals:
            t = np.array([-n[1], n[0], 0.0])
            P = P - np.outer(P @ t, P @ t) / max(float(t @ P @ t), 1e-12)
        w, V = np.linalg.eigh(P)
        return V[:, w > 0.5]

    def chain_chi2(self, h: Hypothesis) -> float:
        """How far the hypothesis is from the front end's own trajectory, in its drift.

        ``e = Log(F⁻¹ z)`` with ``F`` the front end's relative pose from ``k_old`` to the
        current keyframe (free of loop closures) and covariance the chain's between them
        (:meth:`DriftAccumulator.relative_cov`: the steps composed with their heading's lever
        arm) plus the match tolerances; squared Mahalanobis distance (two degrees of freedom
        along a corridor, three otherwise).  Logged (``correction_chi2``), not used.
        """
        F = self.drift.relative(h.k_old, h.keyframe)
        e = pose_log(pose_between(F, h.z))
        S = self.drift.relative_cov(h.k_old, h.keyframe) + self._z_cov()
        return self._mahalanobis(e, S, [] if h.normal is None else [h.normal])[0]

    def pair_chi2(self, a: Hypothesis, b: Hypothesis) -> float:
        """Pairwise consistency of two hypotheses (PCM, Mangelson et al. 2018).

        The cycle ``old_a → old_b → k_b → k_a → old_a`` through the front end's chains and the
        two measurements: ``e = Log(z_a⁻¹ ∘ F(old_a→old_b) ∘ z_b ∘ F(k_b→k_a))``, covariance the
        drift along both chains plus both measurements' tolerances.
        """
        return self._cycle(a, b, fitted=False)[0]

    def _cycle(self, a: Hypothesis, b: Hypothesis, fitted: bool) -> tuple[float, int]:
        """:meth:`pair_chi2` and its dof.

        With ``fitted`` the hypotheses' own covariances (``cov``) stand for the tolerances.
        """
        d = self.drift
        cycle = pose_compose(
            pose_compose(pose_inverse(a.z), d.relative(a.k_old, b.k_old)),
            pose_compose(b.z, d.relative(b.keyframe, a.keyframe)),
        )
        e = pose_log(cycle)
        s1xy, s1th = d.between(a.k_old, b.k_old)
        s2xy, s2th = d.between(b.keyframe, a.keyframe)
        var_xy = float(s1xy) ** 2 + float(s2xy) ** 2
        S = np.diag([var_xy, var_xy, float(s1th) ** 2 + float(s2th) ** 2])
        if fitted and a.cov is not None and b.cov is not None:
            S = S + a.cov + b.cov
        else:
            S = S + 2.0 * self._z_cov()
        normals = [n for n in (a.normal, b.normal) if n is not None]
        return self._mahalanobis(e, S, normals)

    def contradiction(self, h: Hypothesis) -> str | None:
        """Why ``h`` contradicts a recently accepted closure, or None.

        Recent: accepted within the last ``local_keyframes`` keyframes.  ``h`` contradicts
        one when their cycle (:meth:`pair_chi2`, with each hypothesis' own covariance,
        ``Hypothesis.cov``) lies beyond the ``consistency_probability`` quantile of χ² with as many
        degrees of freedom as directions are compared.
        """
        lcc = self.config.loop_closure
        for r in self._recent_accepted(h.keyframe, lcc.local_keyframes):
            chi2, dof = self._cycle(r.hypothesis, h, fitted=True)
            if chi2 > self._chi2_limit(dof):
                return (
                    f"contradicts the closure accepted at keyframe {r.keyframe} "
                    f"(χ² {chi2:.1f} > {self._chi2_limit(dof):.1f}, {dof} dof)"
                )
        return None

    def _recent_accepted(self, keyframe: int, window: int | None) -> list[_Accepted]:
        """The closures accepted less than ``window`` keyframes before ``keyframe``, oldest first.

        ``window`` None: all of them.  Closures beyond both windows that look back
        (``local_keyframes`` for :meth:`contradiction`, ``reconsider_keyframes`` inclusive for
        :meth:`rival`; None: no limit) are forgotten.
        """
        lcc = self.config.loop_closure
        if lcc.reconsider_keyframes is not None:
            longest = max(lcc.local_keyframes, lcc.reconsider_keyframes + 1)
            self._accepted = [a for a in self._accepted if a.keyframe > keyframe - longest]
        if window is None:
            return list(self._accepted)
        return [a for a in self._accepted if a.keyframe > keyframe - window]

    def agreement(self, h: Hypothesis) -> int:
        """How many recent hypotheses agree with ``h`` (``h`` then joins them).

        Recent: found within the last ``local_keyframes`` keyframes at another keyframe; two
        agree when their pairwise consistency (:meth:`pair_chi2`) lies within the
        ``consistency_probability`` quantile of χ²₃ (with ``agreement_same_place``, only
        hypotheses whose old keyframes also lie within ``local_keyframes`` of each other).
        """
        lcc = self.config.loop_closure
        self._recent = [r for r in self._recent if r.keyframe > h.keyframe - lcc.local_keyframes]
        agree = sum(
            r.keyframe != h.keyframe
            and (not lcc.agreement_same_place or abs(r.k_old - h.k_old) < lcc.local_keyframes)
            and self.pair_chi2(r, h) <= self._chi2_limit(3)
            for r in self._recent
        )
        self._recent.append(h)
        return agree

    def where(self, pose: int, k_old: int) -> dict[str, Any]:
        """Where a candidate was: the two keyframes, their scans and poses."""
        g = self.book.graph
        scans = self.track.keyframe_scan
        return {
            "scan": int(scans[pose]),
            "old_keyframe": k_old,
            "old_scan": int(scans[k_old]),
            "pose_before": [float(v) for v in g.poses[pose]],
            "old_pose_before": [float(v) for v in g.poses[k_old]],
        }

    # -- judge and apply ---------------------------------------------------------------------
    def apply(
        self,
        local: IntArray,
        old: IntArray,
        found: LoopClosure,
        pose: int,
        chi2_t: float = float("nan"),
        agree: int = 0,
        hypothesis: Hypothesis | None = None,
        late: bool = False,
        judged_at: int | None = None,
        reconsidering: _Accepted | None = None,
    ) -> int:
        """Test against the graph; spread the correction, merge the pairs, judge; keep if explained.

        With ``graph_gate`` a hypothesis the graph's own estimate rules out
        (:meth:`graph_test`) is rejected first, without the solves (logged ``gated``).

        The candidate is judged by a batch solve in our own loop (``judge_iterations`` at most)
        of the loop (the poses since ``local_keyframes`` before the old landmarks were last
        seen, the earlier ones held; the whole graph with ``judge_loop_only = False``), against
        the same solve of the loop without it (``judge_from_converged``), without
        touching the back-end: a rejected closure is rolled back (the book's snapshot) and the
        back-end never sees it; an accepted one with a large correction restarts the back-end
        from the judged estimate, a small one reaches it incrementally
        (``large_correction_*``).  ``agree`` is the number of recent hypotheses that agree
        with this one (:meth:`agreement`; the robust second chance needs one); an accepted
        ``hypothesis`` is kept for :meth:`contradiction`.  ``late``: a hypothesis found
        at ``pose`` by an earlier attempt, judged by the attempt at keyframe ``judged_at``
        (``judge_unconfirmed``; None at the end of a run).  Returns 1 when accepted, else 0.
        """
        book = self.book
        g = book.graph
        lcc = self.config.loop_closure
        before = book.snapshot()
        old_last = book.last_keyframe[old[[j for _, j in found.pairs]]]
        loop_from = max(int(old_last.min()) - lcc.local_keyframes, 0)
        kernel = self._judge_kernel()
        k_old = int(np.median(old_last))
        where = self.where(pose, k_old)  # as the search saw it
        # the graph's own estimate, its covariance scaled by the closures so far: a hypothesis
        # beyond it is turned away before the judge (not a reconsidered one: the graph still
        # holds the closure it would replace)
        graph = None
        if lcc.graph_gate and reconsidering is None and hypothesis is not None:
            graph = self.graph_test(found, old, pose, k_old, hypothesis)
        if (
            graph is not None
            and graph.chi2 is not None
            and graph.chi2 > self._chi2_limit(graph.dof)
        ):
            self.attempts.append(
                ClosureAttempt(
                    "gated",
                    int(pose),
                    reason=(
                        f"inconsistent with the graph (chi2 {graph.chi2:.1f} with its covariance "
                        f"scaled by {graph.scale:.1f})"
                    ),
                    pairs=len(found.pairs),
                    correction=[float(v) for v in found.correction],
                    correction_chi2=chi2_t,
                    graph_chi2=graph.chi2,
                    graph_scale=graph.scale,
                    where=where,
                )
            )
            self.counters["loop_closures_gated"] += 1
            return self._rejected_now(
                local, old, found, pose, chi2_t, agree, hypothesis, late, judged_at, reconsidering
            )
        if reconsidering is None:
            self.counters["loop_closure_candidates"] += 1
        # the map before the loop is the reference: held, only the loop is solved
        free_from = loop_from if lcc.judge_loop_only else 0
        if lcc.judge_from_converged:
            # the loop without the closure solved first, by the same solver: the F statistic
            # then compares the two hypotheses each at its own optimum
            with self.clock("judge"):
                self._judge.solve(g, lcc.judge_iterations, free_from=free_from)
        loop_before, loop_before_robust, _ = residual_chi2(g, loop_from, *kernel)
        corr = self.effective_correction(found, old)
        normal = self.corridor_normal(found, old)
        big = bool(
            np.hypot(corr[0], corr[1]) > lcc.large_correction_m
            or abs(corr[2]) > lcc.large_correction_rad
        )
        if big:
            spread_correction(
                book, self.track, corr, g.poses[pose, :2].copy(), k_old, pose, lcc.local_keyframes
            )
        n_log = len(g.merge_log)
        done: set[int] = set()
        for i, j in found.pairs:
            keep, drop = int(old[j]), int(local[i])
            if drop in done or not (g.landmark_alive[keep] and g.landmark_alive[drop]):
                continue
            book.merge(keep, drop)
            done.add(drop)
        if not done:
            book.restore(before)
            return 0
        records = list(g.merge_log[n_log:])

        def hopeless(iterations: int, poses: FloatArray, landmarks: FloatArray) -> bool:
            """At most one pair explained after ``judge_hopeless_after`` linearisations."""
            if iterations != lcc.judge_hopeless_after:
                return False
            with book.estimate_at(poses, landmarks):
                good = sum(self.audit.consistent(r) is True for r in records)
            return good <= 1

        with self.clock("judge"):
            judged = self._judge.solve(g, lcc.judge_iterations, free_from=free_from, stop=hopeless)
        chi2 = [c for c in (self.audit.chi2(r) for r in records) if c is not None]
        good = sum(c <= self.config.fusion.audit_max_median_chi2 for c in chi2)
        worst = max(chi2, default=0.0)
        # likelihood ratio of the merged loop against the graph without it, in units of the
        # graph's own residual level (its variance factor, from the line factors' median χ²)
        # F statistic: the loop region's cost increase per merged degree of freedom against its
        # own cost per residual degree of freedom before
        loop_after, loop_after_robust, _ = residual_chi2(g, loop_from, *kernel)
        m_loop = max(
            2 * int(np.count_nonzero(g.factor_pose >= loop_from))
            + 3 * int(np.count_nonzero(g.odometry_second >= loop_from))
            - 3 * (g.n_poses - loop_from),
            1,
        )

        def f_statistic(before: float, after: float) -> float:
            return ((after - before) / (2 * len(done))) / max(before / m_loop, 1e-12)

        f_stat = f_statistic(loop_before, loop_after)
        f_robust = f_statistic(loop_before_robust, loop_after_robust)
        attempt = ClosureAttempt(
            "judged",
            int(pose),
            pairs=len(done),
            consistent_pairs=good,
            worst_pair_chi2=worst,
            correction=[float(v) for v in found.correction],
            single_direction=bool(found.single_direction),
            corridor_normal=None if normal is None else [float(v) for v in normal],
            score=float(found.score),
            runner_up=float(found.runner_up),
            judge_iterations=judged.iterations,
            judge_stop=judged.reason,
            judge_free_from=free_from,
            correction_chi2=chi2_t,
            where=where,
        )
        if late:
            attempt.judged_late = True
            attempt.judged_at_keyframe = judged_at
        attempt.f_statistic = float(f_stat)
        attempt.f_statistic_robust = float(f_robust)
        if graph is not None:
            attempt.graph_chi2, attempt.graph_scale = graph.chi2, graph.scale
        attempt.agreeing_hypotheses = int(agree)
        if reconsidering is not None:
            attempt.reconsidered_closure = reconsidering.keyframe
        self.attempts.append(attempt)
        explained = (
            good >= max(lcc.min_matches - 1, 2)
            and good >= lcc.min_consistent_fraction * len(records)
            and worst <= lcc.judge_max_pair_chi2
        )
        f_ok = f_stat <= lcc.judge_max_f or (
            lcc.judge_robust_cost
            and agree >= 1
            and good == len(records)
            and f_robust <= lcc.judge_max_f
        )
        # the robust cost must accept it too: judged alone, or where the loop's χ² fell
        # (without judge_robust_cost both costs are χ² and this adds nothing)
        if (lcc.judge_alone_both_costs and agree == 0) or (
            lcc.judge_negative_f_robust and f_stat < 0.0
        ):
            f_ok = f_ok and f_robust <= lcc.judge_max_f
        if explained and f_ok:
            # explained (up to a few wrong pairs, which are undone)
            self.audit.audit(records)
            self.converge(reset=big)
            sxy, sth = self.drift.since(np.array([k_old]))
            self.drift.observe_closure(
                corr,
                float(sxy[0]) / self.drift.scale_xy,
                float(sth[0]) / self.drift.scale_theta,
                bool(found.single_direction),
            )
            attempt.accepted = True
            attempt.backend_restarted = big
            if graph is not None:  # what this closure says of the graph's covariance
                self._graph_tests.append(graph)
                self._graph_scale = None
            if hypothesis is not None:
                kept = [r for r in records if not r.undo and not g.landmark_alive[r.drop]]
                self._accepted.append(
                    _Accepted(
                        hypothesis,
                        float(chi2_t),
                        kept,
                        int(agree),
                        free_from,
                        graph,
                    )
                )
            self.counters["loop_closures"] += 1
            return 1
        # not explained: the back-end never saw it; the book goes back to its snapshot
        book.restore(before)
        book.refresh_extents()
        self.counters["loop_closures_undone"] += 1
        return self._rejected_now(
            local, old, found, pose, chi2_t, agree, hypothesis, late, judged_at, reconsidering
        )

    def _rejected_now(
        self,
        local: IntArray,
        old: IntArray,
        found: LoopClosure,
        pose: int,
        chi2_t: float,
        agree: int,
        hypothesis: Hypothesis | None,
        late: bool,
        judged_at: int | None,
        reconsidering: _Accepted | None,
    ) -> int:
        """After a rejection (by the judge or the graph): remember it; reconsider a rival.

        The rejection is remembered for ``skip_repeated_rejections``; a rejected hypothesis
        may overturn an accepted closure it contradicts (:meth:`rival`, :meth:`reconsider`).
        Returns what :meth:`reconsider` returns, else 0.
        """
        self._rejected.append(
            (int(pose), np.asarray(found.correction, dtype=float), len(found.pairs))
        )
        if hypothesis is not None and reconsidering is None:
            rival = self.rival(hypothesis, chi2_t, agree)
            if rival is not None:
                return self.reconsider(
                    rival, local, old, found, pose, chi2_t, agree, hypothesis, late, judged_at
                )
        return 0

    def rival(self, h: Hypothesis, chi2_t: float, agree: int) -> _Accepted | None:
        """The most recent accepted closure that a rejected ``h`` may overturn, if any.

        Within ``reconsider_keyframes`` (None: any), at another keyframe, inconsistent with ``h``
        (:meth:`pair_chi2` beyond the ``consistency_probability`` quantile of χ²₃), while ``h``
        agrees with the front end's own trajectory (:meth:`chain_chi2` within that quantile)
        better than the closure did, and more recent hypotheses agree with ``h`` (``agree``)
        than agreed with the closure when it was judged: the larger consistent set wins.
        """
        lcc = self.config.loop_closure
        if lcc.reconsider_keyframes == 0 or not np.isfinite(chi2_t):
            return None
        if chi2_t > self._chi2_limit(2 if h.single else 3):
            return None
        window = None if lcc.reconsider_keyframes is None else lcc.reconsider_keyframes + 1
        for a in reversed(self._recent_accepted(h.keyframe, window)):
            if a.keyframe == h.keyframe or not chi2_t < a.chain_chi2 or agree <= a.agreeing:
                continue
            if self.pair_chi2(a.hypothesis, h) > self._chi2_limit(3):
                return a
        return None

    def reconsider(
        self,
        rival: _Accepted,
        local: IntArray,
        old: IntArray,
        found: LoopClosure,
        pose: int,
        chi2_t: float,
        agree: int,
        hypothesis: Hypothesis,
        late: bool = False,
        judged_at: int | None = None,
    ) -> int:
        """Judge ``found`` again with ``rival``'s merges undone; keep whichever explains.

        With the merges undone, the loops of both are solved first (the judge's solver, from
        the first pose either judgement freed), so that the judgement starts from, and its F
        test compares against, the graph converged without ``rival``.  Accepted: ``rival``
        stays dropped (its undone pairs vetoed, so fusion does not redo them; it no longer
        turns hypotheses away).  Rejected: the book goes back to its state with ``rival``,
        the back-end never having seen the difference.  Returns 1 when accepted, else 0.
        """
        book = self.book
        g = book.graph
        undone = [
            r
            for r in rival.records
            if g.landmark_alive[r.keep]
            and not g.landmark_alive[r.drop]
            and np.all(g.factor_landmark[r.factors] == r.keep)
        ]
        if not undone:
            return 0
        before = book.snapshot()
        for r in undone:
            # the merge's factors, and those added to the merged landmark since (factors are
            # numbered in the order they came): the current pass's, which belong to the
            # landmark that was dropped into it
            on_keep = np.flatnonzero(g.factor_landmark == r.keep)
            later = on_keep[on_keep > int(r.factors.max())]
            g.unmerge(MergeRecord(r.keep, r.drop, np.union1d(r.factors, later)))
        book.recompute_info(np.array(sorted({r.keep for r in undone} | {r.drop for r in undone})))
        lcc = self.config.loop_closure
        # the first pose this judgement frees (as apply), or the closure's if earlier
        old_last = book.last_keyframe[old[[j for _, j in found.pairs]]]
        loop_from = max(int(old_last.min()) - lcc.local_keyframes, 0)
        free_from = min(loop_from, rival.free_from) if lcc.judge_loop_only else 0
        with self.clock("judge"):
            self._judge.solve(g, lcc.judge_iterations, free_from=free_from)
        book.refresh_extents()
        # the hypothesis measures the relative pose of its two keyframes; its correction was
        # read at the estimate the closure had shaped, and is read again at the one without it
        found = replace(found, correction=self.correction_at(hypothesis))
        if self.apply(
            local, old, found, pose, chi2_t, agree, hypothesis, late, judged_at, reconsidering=rival
        ):
            self.audit.vetoed.update((min(r.keep, r.drop), max(r.keep, r.drop)) for r in undone)
            self._accepted.remove(rival)
            # a dropped closure no longer says how far the graph's covariance is off
            if rival.graph is not None:
                self._graph_tests = [t for t in self._graph_tests if t is not rival.graph]
                self._graph_scale = None
            self.counters["loop_closures_dropped"] += 1
            return 1
        book.restore(before)  # the undone merges are merged again
        book.refresh_extents()
        return 0

    def _judge_kernel(self) -> tuple[RobustKernel, float]:
        """The kernel of the judge's loop cost: the solver's own, or none (Gaussian)."""
        if self.config.loop_closure.judge_robust_cost:
            return self.config.solver.robust_kernel, self.config.solver.robust_k
        return "none", 1.0

    def converge(self, reset: bool) -> None:
        """Bring the back-end to the graph, converge, and refresh the extents.

        With ``reset`` iSAM2 is rebuilt from the graph's estimate (after a large change of it).
        """
        g = self.book.graph
        with self.clock("backend"):
            if reset:
                self.backend.reset(g)
            else:
                self.backend.update(g)
            self.backend.optimize(g, self.config.loop_closure.max_updates)
            self.book.refresh_extents()
