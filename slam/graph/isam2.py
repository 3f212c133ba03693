"""Incremental smoothing with ``gtsam.ISAM2``, with no Python callback inside GTSAM.

Design (measured in ``scripts/bench_graph.py``; see ``docs/graph.md``):

* **Odometry and the gauge prior** are native ``BetweenFactorPose2`` / ``PriorFactorPose2``;
  iSAM2 relinearises them itself in C++.
* **Line factors** are linearised in numpy (:func:`slam.graph.factors.linearize_line_factors`)
  at iSAM2's linearisation point ``θ`` of their variables.  All line factors of one keyframe
  are stacked into one ``gtsam.JacobianFactor`` (pose + its landmarks) and wrapped in one
  ``gtsam.LinearContainerFactor`` (native C++): one Python object per keyframe instead of per
  line, and iSAM2 never calls back into Python.  A keyframe's stacked factor is kept and, when
  the block is rebuilt on the same landmarks, overwritten in place (:class:`_BlockTemplate`).
* **Relinearisation policy.**  A ``LinearContainerFactor`` keeps its Jacobian; when iSAM2
  moves ``θ`` of one of its variables (its own relinearisation, ``relinearize_threshold_*``) it
  only shifts the right-hand side.  So on an update where iSAM2 relinearises (every
  ``relinearize_skip`` updates), the variables it is about to move are foreseen first — its
  full check: any component of ``δ`` above the threshold — the mirrored ``θ`` takes the same
  step, and every keyframe block with such a variable is removed by factor index and added
  again linearised at the new ``θ``, in that same ``ISAM2.update`` call; iSAM2's ``θ`` is
  then read back and compared with the mirror (a variable it moved unforeseen queues its
  blocks for the next update).  With the default thresholds the line factors are thus always
  linearised where iSAM2 linearises its native factors.
* **Robust kernels** weight a block when it is (re)built, from the residual at ``θ`` (IRLS with
  weights refreshed on relinearisation).  ``θ`` lags the estimate by up to the relinearisation
  thresholds, so the final convergence rebuilds iSAM2 at the estimate
  (``Isam2Config.final_weight_refresh``): the final estimate and covariances then carry the
  weights at the estimate, as the batch solver's do.
* **The final convergence** (:meth:`Isam2Solver.optimize` with ``exact``) is by default the
  batch solver's (``Isam2Config.final_solver``): Levenberg-Marquardt over the whole graph
  from the online estimate, then iSAM2 rebuilt at its solution, so that the marginals are
  iSAM2's at the final estimate.
* **Landmark fusion**: the blocks of keyframes that saw the retired landmark are rebuilt
  against the kept one; the retired variable keeps a weak prior (σ = 1) so that the system
  stays well posed (iSAM2 cannot delete a variable).
* iSAM2's ``enablePartialRelinearizationCheck`` is off: its full check is the one that can
  be foreseen, and it runs only every ``relinearize_skip`` updates.

The estimate is read back after each update: the variables touched by the update, or the whole
estimate (iSAM2's ``δ`` in one vector, retracted onto the mirrored ``θ`` in numpy) after a large
re-elimination (a loop closure) and at least every ``full_refresh_interval`` updates.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import chain

import gtsam
import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam import interrupts
from slam.errors import EstimationError
from slam.geometry import pose_retract
from slam.graph.batch import BatchSolver
from slam.graph.config import Isam2Config, SolverConfig
from slam.graph.factors import LineLinearization, linearize_line_factors
from slam.graph.linear import (
    keys_of,
    line_factor_groups,
    line_jacobian_factors,
    native_odometry_factors,
    split_delta,
)
from slam.graph.problem import GrowableArray, LineGraph

__all__ = ["Isam2Solver", "Isam2Stats"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass
class Isam2Stats:
    """Counters of an :class:`Isam2Solver` (cumulative).

    Attributes
    ----------
    updates : int
        ``ISAM2.update`` calls.
    blocks_built : int
        Keyframe blocks (``LinearContainerFactor``) built, first time or again.
    blocks_relinearized : int
        Of those, rebuilt because iSAM2 moved a variable (relinearisation policy).
    blocks_merged : int
        Rebuilt because of landmark fusion.
    variables_relinearized : int
        Sum of iSAM2's own relinearised-variable counts.
    full_refreshes : int
        Whole-estimate read-backs.
    final_relinearizations : int
        Rebuilds of iSAM2 at the estimate by ``optimize(exact=True)``.
    relinearizations_predicted : int
        Variables whose relinearisation by iSAM2 was foreseen and their blocks rebuilt in the
        same update (``Isam2Config.blocks_relinearized_in_step``).
    relinearizations_unforeseen : int
        Variables iSAM2 relinearised that were not foreseen (their blocks follow one update
        later; 0 when the prediction holds).
    qr_fallbacks : int
        Times an update hit a system too poorly conditioned for the Cholesky factorisation
        (GTSAM's ``IndeterminateLinearSystemException``) and iSAM2 was rebuilt with QR.
    final_step : float
        The largest component of the last such rebuild's step (nan before any).
    time_s : dict
        ``build`` (numpy + factor objects), ``update`` (GTSAM), ``readback``.
    """

    updates: int = 0
    blocks_built: int = 0
    blocks_relinearized: int = 0
    blocks_merged: int = 0
    variables_relinearized: int = 0
    full_refreshes: int = 0
    final_relinearizations: int = 0
    relinearizations_predicted: int = 0
    relinearizations_unforeseen: int = 0
    qr_fallbacks: int = 0
    final_step: float = float("nan")
    time_s: dict[str, float] = field(
        default_factory=lambda: {"build": 0.0, "update": 0.0, "readback": 0.0}
    )


def _retracted(poses: FloatArray, delta: FloatArray) -> FloatArray:
    """``poses ⊕ delta`` (GTSAM's ``Pose2.retract``), headings wrapped as GTSAM reads them."""
    out = pose_retract(poses, delta)
    out[:, 2] = np.asarray(wrap_angle(out[:, 2]))
    return out


@njit(cache=True, nogil=True)
def _block_layout(
    column: NDArray[np.int64],
    n_landmarks: int,
    A_pose: FloatArray,
    A_landmark: FloatArray,
    b: FloatArray,
    flat_A: FloatArray,
    flat_b: FloatArray,
) -> tuple[NDArray[np.int64], NDArray[np.int64], bool]:  # pragma: no cover - compiled
    """Where a stacked factor keeps its line factors' entries, and whether it holds them.

    ``k`` line factors, factor ``f`` on the landmark of column block ``column[f]`` (of
    ``n_landmarks``, the pose's block after them), stacked in column-major memory ``flat_A``
    (``2k`` rows) and ``flat_b``: row ``2f + r`` holds factor ``f``'s row ``r``.  Returns the
    positions of ``A_pose`` ``(k, 2, 3)`` and ``A_landmark`` ``(k, 2, 2)`` in ``flat_A``, and
    whether ``flat_A`` holds exactly these entries and zeros elsewhere and ``flat_b`` equals
    ``b`` (``(2k,)``) (``np.array_equal``'s comparison: NaN never equal).
    """
    k = column.shape[0]
    m = 2 * k
    at_pose = np.empty((k, 2, 3), np.int64)
    at_landmark = np.empty((k, 2, 2), np.int64)
    expected = np.zeros(flat_A.shape[0])
    for f in range(k):
        for r in range(2):
            row = 2 * f + r
            for c in range(3):
                at = (2 * n_landmarks + c) * m + row
                at_pose[f, r, c] = at
                expected[at] = A_pose[f, r, c]
            for c in range(2):
                at = (2 * column[f] + c) * m + row
                at_landmark[f, r, c] = at
                expected[at] = A_landmark[f, r, c]
    same = flat_b.shape[0] == b.shape[0]
    for i in range(flat_A.shape[0]):
        if flat_A[i] != expected[i]:
            same = False
    if same:
        for i in range(b.shape[0]):
            if flat_b[i] != b[i]:
                same = False
    return at_pose, at_landmark, same


class _BlockTemplate:
    """A keyframe's stacked line factors, kept to be overwritten when its block is rebuilt.

    GTSAM stacks a keyframe's factors (``JacobianFactor(GaussianFactorGraph)``) with the rows
    of its line factors in order, two each, and the columns of its keys in key order (the
    landmarks ``L(j)`` by index, then the pose ``X(i)``), zero where a row does not involve a
    key.  :meth:`make` checks that layout entry by entry against the stacked factor; then
    :meth:`write` puts new values of line factors on the same landmarks, in the same order,
    into the same entries of its memory (``getA()`` / ``getb()`` are views of it): the factor
    a new stacking would give, bit for bit.

    Attributes
    ----------
    factor : gtsam.JacobianFactor
        The stacked factor (written in place).
    landmarks : ndarray, shape (k,)
        The landmark of each line factor, in order.
    landmark_list : list of int
        The same as a list.
    """

    def __init__(
        self,
        factor: gtsam.JacobianFactor,
        landmarks: IntArray,
        flat_A: FloatArray,
        b: FloatArray,
        at_pose: IntArray,
        at_landmark: IntArray,
    ) -> None:
        self.factor = factor
        self.landmarks = landmarks
        self.landmark_list: list[int] = landmarks.tolist()
        self._flat_A = flat_A
        self._b = b
        self._at_pose = at_pose
        self._at_landmark = at_landmark

    @classmethod
    def make(
        cls,
        factor: gtsam.JacobianFactor,
        pose: int,
        landmarks: IntArray,
        A_pose: FloatArray,
        A_landmark: FloatArray,
        b: FloatArray,
    ) -> _BlockTemplate | None:
        """The template of a stacked ``factor`` (None if it is not laid out as expected).

        ``A_pose`` ``(k, 2, 3)``, ``A_landmark`` ``(k, 2, 2)``, ``b`` ``(k, 2)``: the line
        factors ``factor`` was stacked from.
        """
        k = landmarks.shape[0]
        landmark_list = landmarks.tolist()
        lms = sorted(set(landmark_list))
        place = {j: i for i, j in enumerate(lms)}
        column = np.array([place[j] for j in landmark_list], dtype=np.int64)
        m, n = 2 * k, 2 * len(lms) + 3
        keys = keys_of("l", np.array(lms, dtype=np.intp)) + keys_of("x", np.array([pose]))
        A, b_view = factor.getA(), factor.getb()
        if (
            list(factor.keys()) != keys
            or A.shape != (m, n)
            or b_view.shape != (m,)
            or not (A.flags.f_contiguous and A.flags.writeable and b_view.flags.writeable)
            or A.flags.owndata
            or b_view.flags.owndata
        ):
            return None
        flat_A = A.T.reshape(-1)  # column-major memory: entry (r, c) at c·m + r
        if not np.shares_memory(flat_A, A):
            return None
        at_pose, at_landmark, laid_out = _block_layout(
            column,
            len(lms),
            np.ascontiguousarray(A_pose),
            np.ascontiguousarray(A_landmark),
            np.ascontiguousarray(b).reshape(-1),
            flat_A,
            b_view,
        )
        if not laid_out:
            return None
        return cls(factor, landmarks.copy(), flat_A, b_view, at_pose, at_landmark)

    def write(self, A_pose: FloatArray, A_landmark: FloatArray, b: FloatArray) -> None:
        """New values of the same line factors (shapes as in :meth:`make`)."""
        self._flat_A[self._at_pose] = A_pose
        self._flat_A[self._at_landmark] = A_landmark
        self._b[...] = b.reshape(-1)


class Isam2Solver:
    """Mirror a :class:`LineGraph` into ``gtsam.ISAM2``, one update per call.

    Parameters
    ----------
    config : Isam2Config
    solver : SolverConfig
        For the robust kernel.
    """

    def __init__(self, config: Isam2Config | None = None, solver: SolverConfig | None = None):
        self.config = config or Isam2Config()
        self.solver = solver or SolverConfig()
        self.stats = Isam2Stats()
        # per keyframe, its last stacked block (kept across restarts)
        self._templates: dict[int, _BlockTemplate] = {}
        # the native odometry factors built so far and what they were built from (kept across
        # restarts)
        self._odometry: list[gtsam.NonlinearFactor] = []
        self._odometry_measured = GrowableArray((3,))
        self._odometry_cov = GrowableArray((3, 3))
        self._start()

    def _start(self) -> None:
        """A new ``gtsam.ISAM2`` holding nothing (the statistics carry on)."""
        params = gtsam.ISAM2Params()
        thresholds = gtsam.ISAM2ThresholdMap()
        m, rad = self.config.relinearize_threshold_m, self.config.relinearize_threshold_rad
        thresholds.insert(("x", np.array([m, m, rad])))  # Pose2 tangent: (x, y, θ)
        thresholds.insert(("l", np.array([m, rad])))  # anchored landmark chart: (ρ, φ)
        params.setRelinearizeThreshold(thresholds)
        params.relinearizeSkip = self.config.relinearize_skip
        params.enablePartialRelinearizationCheck = self.config.partial_relinearization_check
        params.setFactorization("QR" if self.stats.qr_fallbacks else "CHOLESKY")
        self.isam = gtsam.ISAM2(params)
        self._n_poses = 0
        self._n_landmarks = 0
        self._n_odometry = 0
        self._n_factors = 0
        self._n_merges = 0
        self._prior_added = False
        self._factors_of_pose: dict[int, list[int]] = {}
        self._slot_of_pose: dict[int, int] = {}
        self._pending: set[int] = set()
        self._weak_prior: set[int] = set()
        self._lin_pose = GrowableArray((3,))
        self._lin_lm = GrowableArray((2,))
        self._theta_poses = GrowableArray((3,))
        self._theta_lms = GrowableArray((2,))
        self._theta_changed = False
        self._since_full = 0
        self._isam_updates = 0  # iSAM2's own count of updates (its relinearisation steps)

    # -- native factors ----------------------------------------------------------------------
    def _odometry_factors(self, graph: LineGraph, start: int) -> gtsam.NonlinearFactorGraph:
        """The native odometry factors ``start:`` of ``graph`` (:func:`native_odometry_factors`).

        Each factor is built once and given again after a restart (:meth:`restart`), as long as
        the graph's odometry measurements and covariances are the ones it was built from (else
        they are all built again).
        """
        built = len(self._odometry)
        if start < built and not (
            np.array_equal(self._odometry_measured.data, graph.odometry_measured[:built])
            and np.array_equal(self._odometry_cov.data, graph.odometry_cov[:built])
        ):
            self._odometry = []
            self._odometry_measured = GrowableArray((3,))
            self._odometry_cov = GrowableArray((3, 3))
            built = 0
        if graph.n_odometry > built:
            new = native_odometry_factors(graph, built, with_prior=False)
            self._odometry.extend(new.at(i) for i in range(new.size()))
            self._odometry_measured.append(graph.odometry_measured[built:])
            self._odometry_cov.append(graph.odometry_cov[built:])
        nfg = gtsam.NonlinearFactorGraph()
        for factor in self._odometry[start : graph.n_odometry]:
            nfg.push_back(factor)
        return nfg

    # -- linearisation point -----------------------------------------------------------------
    def _refresh_theta(self) -> None:
        poses, lms = self._isam_theta()
        self._theta_poses.data[:] = poses
        self._theta_lms.data[:] = lms

    def _isam_theta(self) -> tuple[FloatArray, FloatArray]:
        """iSAM2's linearisation point: poses ``(N, 3)``, landmarks ``(M, 2)``."""
        lp = self.isam.getLinearizationPoint()
        poses = np.asarray(gtsam.utilities.extractPose2(lp), dtype=float).reshape(-1, 3)
        lms = np.asarray(gtsam.utilities.extractPoint2(lp), dtype=float).reshape(-1, 2)
        return poses, lms

    @property
    def _foresees_relinearization(self) -> bool:
        cfg = self.config
        return cfg.blocks_relinearized_in_step and not cfg.partial_relinearization_check

    def _foresee_relinearization(self) -> None:
        """Move the mirrored ``θ`` as iSAM2 is about to in this update.

        iSAM2's full relinearisation check (``enablePartialRelinearizationCheck`` off)
        relinearises every variable with a component of its ``δ`` above the threshold and
        moves its ``θ`` to ``θ ⊕ δ`` before it linearises the update's new factors.  The same
        step on the mirror makes the blocks on those variables stale now, so that they are
        rebuilt at the new ``θ`` in this very update (:meth:`update`) instead of one update
        later, after iSAM2 has re-eliminated them once already with their old Jacobians.
        """
        n_p, n_l = self._n_poses, self._n_landmarks
        d_lms, d_poses = split_delta(self.isam.getDelta(), n_l, n_p)
        m, rad = self.config.relinearize_threshold_m, self.config.relinearize_threshold_rad
        moved_p = np.flatnonzero(np.any(np.abs(d_poses) > np.array([m, m, rad]), axis=1))
        moved_l = np.flatnonzero(np.any(np.abs(d_lms) > np.array([m, rad]), axis=1))
        if moved_p.size:
            self._theta_poses.data[moved_p] = _retracted(
                self._theta_poses.data[moved_p], d_poses[moved_p]
            )
        if moved_l.size:
            self._theta_lms.data[moved_l] += d_lms[moved_l]
        if moved_p.size or moved_l.size:
            self._theta_changed = True
        self.stats.relinearizations_predicted += int(moved_p.size + moved_l.size)

    def _check_foreseen_theta(self) -> None:
        """After a relinearisation step, iSAM2's ``θ`` against the mirror's foresight.

        Agreement to 1e-9 keeps the mirror (so that the blocks just built stay current);
        a variable iSAM2 moved otherwise takes iSAM2's ``θ``, and its blocks follow one
        update later.
        """
        poses, lms = self._isam_theta()
        mine_p, mine_l = self._theta_poses.data, self._theta_lms.data
        dp = np.abs(poses - mine_p)
        dp[:, 2] = np.abs(np.asarray(wrap_angle(poses[:, 2] - mine_p[:, 2])))
        off_p = np.flatnonzero(np.any(dp > 1e-9, axis=1))
        off_l = np.flatnonzero(np.any(np.abs(lms - mine_l) > 1e-9, axis=1))
        if off_p.size or off_l.size:
            mine_p[off_p] = poses[off_p]
            mine_l[off_l] = lms[off_l]
            self._theta_changed = True
            self.stats.relinearizations_unforeseen += int(off_p.size + off_l.size)

    def _stale_groups(self) -> set[int]:
        """Keyframes whose block was built at a linearisation point iSAM2 has since left."""
        n = len(self._lin_pose)
        if n == 0:
            return set()
        cfg = self.config
        fp = self._graph_factor_pose[:n]
        fl = self._graph_factor_lm[:n]
        tp = self._theta_poses.data[fp]
        tl = self._theta_lms.data[fl]
        lp = self._lin_pose.data
        ll = self._lin_lm.data
        moved = np.hypot(tp[:, 0] - lp[:, 0], tp[:, 1] - lp[:, 1]) > cfg.relin_translation_m
        moved |= np.abs(tp[:, 2] - lp[:, 2]) > cfg.relin_angle_rad
        moved |= np.abs(tl[:, 0] - ll[:, 0]) > cfg.relin_range_m
        moved |= np.abs(tl[:, 1] - ll[:, 1]) > cfg.relin_angle_rad
        return {int(p) for p in np.unique(fp[moved])}

    # -- blocks --------------------------------------------------------------------------------
    def _build_blocks(
        self, graph: LineGraph, poses: list[int]
    ) -> list[gtsam.LinearContainerFactor]:
        """One ``LinearContainerFactor`` per keyframe in ``poses``, linearised at ``θ``.

        The numpy linearisation runs once for all the blocks' factors together.  A keyframe
        whose line factors are on the same landmarks as when its block was last built reuses
        that block's stacked ``JacobianFactor`` (:class:`_BlockTemplate`, overwritten in
        place; ``LinearContainerFactor`` copies it); the others are stacked by GTSAM.
        """
        if not poses:
            return []
        groups = [self._factors_of_pose[p] for p in poses]
        fs = np.fromiter(chain.from_iterable(groups), dtype=np.intp)
        fp = graph.factor_pose[fs]
        lm = graph.factor_landmark[fs]
        theta_p = self._theta_poses.data[fp]
        theta_l = self._theta_lms.data[lm]
        lin = linearize_line_factors(
            theta_p,
            theta_l,
            graph.anchors[lm],
            graph.factor_z[fs],
            graph.factor_sqrt_info[fs],
            self.solver.robust_kernel,
            self.solver.robust_k,
        )
        self._lin_pose.data[fs] = theta_p
        self._lin_lm.data[fs] = theta_l
        offsets = np.cumsum([0] + [len(g) for g in groups]).tolist()
        lm_list = lm.tolist()
        stacked: list[gtsam.JacobianFactor | None] = [None] * len(poses)
        fresh: list[int] = []
        for b, p in enumerate(poses):
            a, e = offsets[b], offsets[b + 1]
            template = self._templates.get(p)
            if template is not None and template.landmark_list == lm_list[a:e]:
                template.write(lin.A_pose[a:e], lin.A_landmark[a:e], lin.b[a:e])
                stacked[b] = template.factor
            else:
                fresh.append(b)
        if fresh:
            rows = np.concatenate([np.arange(offsets[b], offsets[b + 1]) for b in fresh])
            sub = LineLinearization(
                lin.A_pose[rows],
                lin.A_landmark[rows],
                lin.b[rows],
                lin.whitened_residual[rows],
                lin.weights[rows],
            )
            jfs = line_jacobian_factors(fp[rows], lm[rows], sub)
            first, _ = line_factor_groups(fp[rows], lm[rows])  # the line factors jfs start with
            sizes = [offsets[b + 1] - offsets[b] for b in fresh]
            bounds = np.searchsorted(first, np.cumsum([0] + sizes)).tolist()
            for i, b in enumerate(fresh):
                gfg = gtsam.GaussianFactorGraph()
                for jf in jfs[bounds[i] : bounds[i + 1]]:
                    gfg.push_back(jf)
                factor = gtsam.JacobianFactor(gfg)
                stacked[b] = factor
                a, e = offsets[b], offsets[b + 1]
                template = _BlockTemplate.make(
                    factor, poses[b], lm[a:e], lin.A_pose[a:e], lin.A_landmark[a:e], lin.b[a:e]
                )
                if template is None:
                    self._templates.pop(poses[b], None)
                else:
                    self._templates[poses[b]] = template
        # one Values with the linearisation point of every variable of these blocks (a
        # LinearContainerFactor copies only its own keys from it)
        values = gtsam.Values()
        key_p = keys_of("x", np.asarray(poses))
        for key, (x, y, t) in zip(key_p, self._theta_poses.data[poses].tolist(), strict=True):
            values.insert(key, gtsam.Pose2(x, y, t))
        lms = np.unique(lm)
        for key, (r, a) in zip(keys_of("l", lms), self._theta_lms.data[lms].tolist(), strict=True):
            values.insert(key, gtsam.Point2(r, a))
        blocks = []
        for stack in stacked:
            assert stack is not None
            blocks.append(gtsam.LinearContainerFactor(stack, values))
        self.stats.blocks_built += len(blocks)
        return blocks

    # -- the update ----------------------------------------------------------------------------
    def update(self, graph: LineGraph, force_relinearize: bool = False) -> gtsam.ISAM2Result:
        """Bring iSAM2 up to date with ``graph`` (one ``ISAM2.update``) and read back.

        ``force_relinearize`` checks every variable for relinearisation now, whatever
        ``relinearize_skip`` says (used by :meth:`optimize`).
        """
        if graph.prior_pose is None:
            raise EstimationError("the graph has no prior on its first pose (gauge)")
        t0 = time.perf_counter()
        self._isam_updates += 1  # the count iSAM2 will have during this update
        relinearization_step = (
            force_relinearize or self._isam_updates % self.config.relinearize_skip == 0
        )
        foreseen = relinearization_step and self._foresees_relinearization and self._n_poses > 0
        if foreseen:
            self._foresee_relinearization()
        nfg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        touched_poses: set[int] = set()
        touched_lms: set[int] = set()
        # new variables
        new_p = np.arange(self._n_poses, graph.n_poses)
        for key, (x, y, t) in zip(keys_of("x", new_p), graph.poses[new_p].tolist(), strict=True):
            values.insert(key, gtsam.Pose2(x, y, t))
        self._theta_poses.append(graph.poses[new_p])
        new_l = np.arange(self._n_landmarks, graph.n_landmarks)
        for key, (r, a) in zip(keys_of("l", new_l), graph.landmarks[new_l].tolist(), strict=True):
            values.insert(key, gtsam.Point2(r, a))
        self._theta_lms.append(graph.landmarks[new_l])
        touched_poses.update(int(i) for i in new_p)
        touched_lms.update(int(j) for j in new_l)
        # native factors
        if not self._prior_added:
            nfg.push_back(native_odometry_factors(graph, graph.n_odometry, with_prior=True))
            self._prior_added = True
        if graph.n_odometry > self._n_odometry:
            nfg.push_back(self._odometry_factors(graph, self._n_odometry))
            touched_poses.update(int(i) for i in graph.odometry_first[self._n_odometry :])
            self._n_odometry = graph.n_odometry
        # new line factors
        self._graph_factor_pose = graph.factor_pose
        self._graph_factor_lm = graph.factor_landmark
        new_f = np.arange(self._n_factors, graph.n_line_factors)
        if new_f.size:
            self._lin_pose.append(np.zeros((new_f.size, 3)))
            self._lin_lm.append(np.zeros((new_f.size, 2)))
            fp_new = graph.factor_pose[new_f]
            order = np.argsort(fp_new, kind="stable")
            owners, starts = np.unique(fp_new[order], return_index=True)
            for p, group in zip(owners.tolist(), np.split(new_f[order], starts[1:]), strict=True):
                self._factors_of_pose.setdefault(p, []).extend(group.tolist())
            self._pending.update(owners.tolist())
        self._n_factors = graph.n_line_factors
        # landmark fusion since the last update
        weak = gtsam.noiseModel.Isotropic.Sigma(2, 1.0)
        records = graph.merge_log[self._n_merges :]
        if records:
            # every keyframe block with a rewired factor is rebuilt (one vectorised pass)
            rewired = np.concatenate([np.asarray(r.factors, dtype=np.intp) for r in records])
            owner = np.repeat(np.arange(len(records)), [len(r.factors) for r in records])
            poses = graph.factor_pose[rewired]
            self.stats.blocks_merged += int(np.unique(owner * graph.n_poses + poses).size)
            self._pending.update(np.unique(poses).tolist())
        for rec in records:
            if rec.undo or rec.drop in self._weak_prior:
                continue  # a revived landmark keeps its weak prior; only its blocks change
            self._weak_prior.add(rec.drop)
            t = self._theta_lms.data[rec.drop]
            nfg.add(
                gtsam.PriorFactorPoint2(
                    keys_of("l", np.array([rec.drop]))[0], gtsam.Point2(t[0], t[1]), weak
                )
            )
        self._n_merges = len(graph.merge_log)
        # relinearisation policy
        if self._theta_changed:
            stale = self._stale_groups() - self._pending
            self.stats.blocks_relinearized += len(stale)
            self._pending.update(stale)
            self._theta_changed = False
        rebuild = sorted(self._pending)
        self._pending = set()
        remove = [self._slot_of_pose[p] for p in rebuild if p in self._slot_of_pose]
        n_before_blocks = nfg.size()
        for block in self._build_blocks(graph, rebuild):
            nfg.add(block)
        if rebuild:
            touched_poses.update(rebuild)
            fs = np.fromiter(
                chain.from_iterable(self._factors_of_pose[p] for p in rebuild), dtype=np.intp
            )
            touched_lms.update(np.unique(graph.factor_landmark[fs]).tolist())
        self.stats.time_s["build"] += time.perf_counter() - t0
        if rebuild and len(rebuild) > 64:
            interrupts.check()  # a restart: building and updating each take a while
        t0 = time.perf_counter()
        try:
            result = self.isam.update(nfg, values, remove, force_relinearize=force_relinearize)
        except RuntimeError as exc:
            if "Indeterminate" not in str(exc) or self.stats.qr_fallbacks:
                raise EstimationError(f"iSAM2 update failed: {exc}") from exc
            # lines known to a fraction of a millimetre beside metres of odometry: too stiff
            # for Cholesky's pivots; QR factors the same system without forming its normal
            # equations (slower), from here on
            self.stats.qr_fallbacks += 1
            self._start()
            return self.update(graph, force_relinearize)
        self.stats.time_s["update"] += time.perf_counter() - t0
        slots = list(result.getNewFactorsIndices())
        for p, slot in zip(rebuild, slots[n_before_blocks:], strict=True):
            self._slot_of_pose[p] = int(slot)
        self._n_poses = graph.n_poses
        self._n_landmarks = graph.n_landmarks
        self.stats.updates += 1
        n_relin = int(result.getVariablesRelinearized())
        self.stats.variables_relinearized += n_relin
        t0 = time.perf_counter()
        if foreseen:
            self._check_foreseen_theta()
        elif n_relin > 0:
            self._refresh_theta()
            self._theta_changed = True
        self._since_full += 1
        full = (
            int(result.getVariablesReeliminated()) > self.config.full_refresh_variables
            or self._since_full >= self.config.full_refresh_interval
        )
        if full:
            self.read_all(graph)
        else:
            self._read_some(graph, touched_poses, touched_lms)
        self.stats.time_s["readback"] += time.perf_counter() - t0
        return result

    def read_all(self, graph: LineGraph) -> None:
        """Copy the whole current estimate ``θ ⊕ δ`` into ``graph``.

        ``δ`` is iSAM2's solution (``getDelta``, one C++ call and one vector); ``θ`` is the
        mirrored linearisation point; the retraction runs in numpy (a quarter of the time of
        ``calculateEstimate``, which builds a new ``Values`` of every variable).
        """
        d_lms, d_poses = split_delta(self.isam.getDelta(), self._n_landmarks, self._n_poses)
        poses = _retracted(self._theta_poses.data, d_poses)
        lms = self._theta_lms.data + d_lms
        lms[:, 1] = np.asarray(wrap_angle(lms[:, 1]))
        graph.poses[:] = poses
        graph.landmarks[:] = lms
        self._since_full = 0
        self.stats.full_refreshes += 1

    def _read_some(self, graph: LineGraph, poses: set[int], landmarks: set[int]) -> None:
        for i, key in zip(sorted(poses), keys_of("x", np.array(sorted(poses))), strict=True):
            p = self.isam.calculateEstimatePose2(key)
            graph.poses[i] = (p.x(), p.y(), p.theta())
        for j, key in zip(
            sorted(landmarks), keys_of("l", np.array(sorted(landmarks))), strict=True
        ):
            v = np.asarray(self.isam.calculateEstimatePoint2(key), dtype=float)
            graph.landmarks[j] = (v[0], float(wrap_angle(v[1])))

    def restart(self, graph: LineGraph) -> None:
        """A new iSAM2 linearised at ``graph``'s estimate (every factor), solved, read back.

        The statistics carry on.  Used after a large change of the estimate from outside (a
        loop closure spread over the trajectory) and by :meth:`optimize`.
        """
        self._start()
        self.update(graph)  # every variable is new: the whole estimate is read back

    def optimize(
        self, graph: LineGraph, max_updates: int | None = None, exact: bool = False
    ) -> int:
        """Extra updates (no new factors) until iSAM2 and the block policy settle.

        With ``exact`` (the final convergence) and ``final_solver = "batch"``, the batch
        solver (:class:`~slam.graph.batch.BatchSolver`, the ``solver`` settings) solves the
        whole graph instead of the updates.  iSAM2 is then rebuilt at the estimate
        (:meth:`restart`: every factor relinearised, one Gauss-Newton step) until the step's
        largest component is below ``final_step_tolerance``, ``final_relinearizations`` times
        at most (at least once after the batch solver, which iSAM2 has not seen, and with a
        robust kernel and ``final_weight_refresh``: the blocks' IRLS weights were taken at
        ``θ``).  Updates below the relinearisation thresholds stay linear in iSAM2; they do
        not in the result.

        Returns the number of updates run (restarts not counted).
        """
        n = self.config.final_updates if max_updates is None else max_updates
        batch = exact and self.config.final_solver == "batch"
        runs = 0
        if batch:
            BatchSolver(self.solver).solve(graph)  # the graph holds its solution
        else:
            for _ in range(n):
                interrupts.check()  # between updates (slam.interrupts)
                result = self.update(graph, force_relinearize=True)
                runs += 1
                # settled: iSAM2 relinearised nothing, so no block is stale and none queued
                if int(result.getVariablesRelinearized()) == 0 and not self._pending:
                    break
            self.read_all(graph)
        if not exact:
            return runs
        rebuilds = self.config.final_relinearizations
        if batch or (self.config.final_weight_refresh and self.solver.robust_kernel != "none"):
            # iSAM2 at the batch solution; the kernel's weights at the estimate, not at θ
            rebuilds = max(rebuilds, 1)
        for _ in range(rebuilds):
            interrupts.check()
            poses, landmarks = graph.poses.copy(), graph.landmarks.copy()
            self.restart(graph)
            d_poses, d_lms = graph.poses - poses, graph.landmarks - landmarks
            d_poses[:, 2] = np.asarray(wrap_angle(d_poses[:, 2]))
            d_lms[:, 1] = np.asarray(wrap_angle(d_lms[:, 1]))
            self.stats.final_relinearizations += 1
            self.stats.final_step = max(
                float(np.max(np.abs(d_poses), initial=0.0)),
                float(np.max(np.abs(d_lms), initial=0.0)),
            )
            if self.stats.final_step < self.config.final_step_tolerance:
                break
        return runs

    # -- covariances -----------------------------------------------------------------------
    def joint_covariance(self, poses: IntArray, landmarks: IntArray) -> FloatArray:
        """Joint marginal covariance of ``poses`` (3 each) then ``landmarks`` (2 each).

        Landmark blocks are in the anchored chart ``(ρ, φ)``.
        """
        keys = keys_of("x", np.asarray(poses)) + keys_of("l", np.asarray(landmarks))
        try:
            return np.asarray(
                self.isam.jointMarginalCovariance(gtsam.KeyVector(keys)).fullMatrix(), dtype=float
            )
        except RuntimeError as exc:
            raise EstimationError(f"iSAM2 marginals failed: {exc}") from exc

    def pose_covariance(self, pose: int) -> FloatArray:
        """Marginal covariance of one pose (right tangent space)."""
        return np.asarray(self.isam.marginalCovariance(keys_of("x", np.array([pose]))[0]))

    def landmark_covariance(self, landmark: int) -> FloatArray:
        """Marginal covariance of one landmark (anchored chart)."""
        return np.asarray(self.isam.marginalCovariance(keys_of("l", np.array([landmark]))[0]))
