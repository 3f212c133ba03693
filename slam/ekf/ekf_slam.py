"""EKF-SLAM with line landmarks: the baseline the factor graph is compared against.

State and shapes (filterpy's names)
-----------------------------------
``x`` : ``(3 + 2M,)`` — the laser pose ``(x, y, θ)`` in the world frame, then ``M`` line
landmarks ``(r_j, α_j)`` (signed world lines, ``{p : p·(cos α, sin α) = r}``; ``r`` may be
negative, ``α`` is kept wrapped to ``(−π, π]``).

``P`` : ``(3 + 2M, 3 + 2M)`` — covariance of the **additive** error of ``x`` (pose error
``(δx, δy, δθ)`` in the world frame; see :mod:`slam.ekf.conventions` for the conversion to the
right-perturbation tangent space that the rest of lineslam and GTSAM use; results are reported
in that tangent space).

``F``, ``Q`` : ``(3, 3)`` — the pose block of the last prediction's transition Jacobian and
process noise (the full ``F`` is ``blockdiag(F, I)``, the full ``Q`` is ``blockdiag(Q, 0)``;
prediction touches only the pose rows and columns, ``O(M)``).

``H`` : ``(2m, 3 + 2M)``, ``R`` : ``(2m, 2m)``, ``y`` : ``(2m,)``, ``S`` : ``(2m, 2m)``,
``K`` : ``(3 + 2M, 2m)`` — the last update with ``m`` matched lines (stored as attributes
``y``, ``S``, ``K`` of the filter after each update).

One scan (:meth:`EkfSlam.add_scan`)
-----------------------------------
1. **Predict** with the odometry increment ``u = pose_odom[k-1]⁻¹ pose_odom[k]``
   (:mod:`slam.ekf.motion`).
2. **Lines**: given, or extracted with :func:`linefit.extract_lines`; lines whose covariance is
   not finite and positive definite are skipped (counted).
3. **Associate** with the graph's code (:mod:`slam.association`): candidates within range,
   segment-overlap test along the landmark, individual χ² gate on each (line, landmark) pair
   with ``S = H P Hᵀ + R`` from the current joint covariance; then nearest neighbour or JCBB.
4. **Update** all matched lines at once, Joseph form (:mod:`slam.ekf.update`).
5. **Augment** the state with unmatched lines that no landmark could explain (Eq. 30 with the
   cross-covariances, :mod:`slam.ekf.augment`).
6. Optionally **merge** landmarks that became compatible (exact constraint update, then delete).

The ``O(n²)`` cost of an update (``n = 3 + 2M``) is guarded by ``EkfConfig.max_landmarks`` and
``max_runtime_s``; when a guard trips the result records at which scan and why.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line, wrap_angle
from slam.association import (
    associate,
    build_problem,
    candidate_landmarks,
    individual_gate,
    overlap_mask,
)
from slam.ekf.augment import augment_state
from slam.ekf.config import EkfConfig
from slam.ekf.conventions import cov_state_to_tangent, tangent_to_state_jacobian
from slam.ekf.extents import LandmarkExtents
from slam.ekf.motion import odometry_covariance, predict_pose
from slam.ekf.result import EkfResult
from slam.ekf.update import (
    MeasurementStack,
    constrain_and_remove,
    filterpy_update,
    joseph_update,
    line_measurements,
)
from slam.errors import EstimationError, InputError
from slam.geometry import line_residual, pose_between
from slam.lines import chi2_gate
from slam.lines.lineset import LineSet
from slam.models.anchored import model_error_covariance
from slam.types import Scan

if TYPE_CHECKING:
    from linefit.config import LineFitConfig

__all__ = ["EkfSlam", "ScanReport"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class ScanReport:
    """What one :meth:`EkfSlam.add_scan` call did.

    Attributes
    ----------
    index : int
        Scan index.
    n_lines, n_matched, n_new, n_ambiguous, n_invalid : int
        Lines given / matched to landmarks / starting new landmarks / dropped as ambiguous /
        skipped for a bad covariance.
    updated : bool
        False when the update policy skipped this scan's lines.
    skipped : bool
        True when the filter had stopped before this scan (no pose for it).
    runtime_s : float
        Time spent on the scan.
    """

    def __init__(self, index: int) -> None:
        self.index = index
        self.n_lines = 0
        self.n_matched = 0
        self.n_new = 0
        self.n_ambiguous = 0
        self.n_invalid = 0
        self.updated = False
        self.skipped = False
        self.runtime_s = 0.0

    def __repr__(self) -> str:
        return (
            f"ScanReport(index={self.index}, lines={self.n_lines}, matched={self.n_matched}, "
            f"new={self.n_new}, ambiguous={self.n_ambiguous}, invalid={self.n_invalid})"
        )


def _valid_lines(lines: LineSet) -> NDArray[np.bool_]:
    """Lines with finite ``(r, α)``, finite end points and a positive definite 2×2 covariance."""
    cov = lines.cov
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] * cov[:, 1, 0]
    finite = (
        np.all(np.isfinite(lines.r_alpha), axis=1)
        & np.all(np.isfinite(cov), axis=(1, 2))
        & np.all(np.isfinite(lines.endpoints), axis=(1, 2))
    )
    with np.errstate(invalid="ignore"):
        return finite & (cov[:, 0, 0] > 0.0) & (cov[:, 1, 1] > 0.0) & (det > 0.0)


class EkfSlam:
    """EKF-SLAM over line landmarks, fed one scan at a time.

    Parameters
    ----------
    config : EkfConfig, optional
        Filter settings.
    linefit_config : LineFitConfig, optional
        Used only when :meth:`add_scan` is called without lines.
    initial_pose_world_laser : array_like, shape (3,), optional
        Pose of the first scan in the world.  Default: the first scan's odometry pose (the
        world frame is the odometry frame at the start).

    Examples
    --------
    >>> ekf = EkfSlam(EkfConfig())                      # doctest: +SKIP
    >>> for scan, lines in scans_with_lines:            # doctest: +SKIP
    ...     ekf.add_scan(scan, lines)
    >>> result = ekf.result()                           # doctest: +SKIP
    """

    def __init__(
        self,
        config: EkfConfig | None = None,
        linefit_config: LineFitConfig | None = None,
        initial_pose_world_laser: FloatArray | Sequence[float] | None = None,
    ) -> None:
        self.config = config or EkfConfig()
        self.linefit_config = linefit_config
        self._initial_pose = (
            None
            if initial_pose_world_laser is None
            else np.asarray(initial_pose_world_laser, dtype=float).reshape(3)
        )
        self.x: FloatArray = np.zeros(3)
        self.P: FloatArray = np.zeros((3, 3))
        self.F: FloatArray = np.eye(3)
        self.Q: FloatArray = np.zeros((3, 3))
        self.y: FloatArray = np.zeros(0)
        self.S: FloatArray = np.zeros((0, 0))
        self.K: FloatArray = np.zeros((3, 0))
        self._extents = LandmarkExtents(self.config.segment_gap_m)
        self._n_obs: list[int] = []
        self._touched: set[int] = set()
        self._update_odom: FloatArray | None = None
        self._n_updates = 0
        self._started = False
        self.stopped = False
        self.stop_reason = ""
        self._elapsed_s = 0.0
        # per-scan records
        self._t: list[float] = []
        self._poses: list[FloatArray] = []
        self._covs: list[FloatArray] = []
        self._runtime: list[float] = []
        self._n_lm_hist: list[int] = []
        self.stats: dict[str, Any] = {
            "scans": 0,
            "points": 0,
            "lines_fit": 0,
            "lines_matched": 0,
            "lines_new": 0,
            "lines_ambiguous": 0,
            "lines_invalid": 0,
            "lines_too_short": 0,
            "lines_not_added": 0,
            "landmarks_merged": 0,
            "jcbb_incomplete": 0,
            "updates": 0,
        }
        self._new_gate = chi2_gate(self.config.new_landmark_probability)

    # ------------------------------------------------------------------ state access
    @property
    def n_landmarks(self) -> int:
        """Number of landmarks ``M`` in the state."""
        return (self.x.shape[0] - 3) // 2

    @property
    def pose_world_laser(self) -> FloatArray:
        """Current laser pose estimate ``(x, y, θ)``."""
        return self.x[:3].copy()

    @property
    def pose_covariance(self) -> FloatArray:
        """Current pose covariance in the right-perturbation tangent space (3, 3)."""
        return cov_state_to_tangent(self.P[:3, :3], self.x[2])

    @property
    def landmarks_r_alpha(self) -> FloatArray:
        """Current landmarks ``(M, 2)`` as stored (signed, not normalised)."""
        return self.x[3:].reshape(-1, 2).copy()

    def landmark_marginals(self) -> FloatArray:
        """Marginal covariances of the landmarks, shape ``(M, 2, 2)``."""
        M = self.n_landmarks
        idx = np.arange(M)
        return self.P[3:, 3:].reshape(M, 2, M, 2)[idx, :, idx, :].copy()

    def _wrap_angles(self) -> None:
        self.x[2] = wrap_angle(self.x[2])
        self.x[4::2] = np.asarray(wrap_angle(self.x[4::2]))

    # ------------------------------------------------------------------ filter steps
    def initialize(self, pose_world_laser: FloatArray, cov_state: FloatArray | None = None) -> None:
        """Start the filter at a pose (additive covariance ``cov_state``, default from config)."""
        self.x = np.asarray(pose_world_laser, dtype=float).reshape(3).copy()
        self.x[2] = wrap_angle(self.x[2])
        if cov_state is None:
            cov_state = np.diag(np.square(self.config.initial_pose_sigma))
        self.P = np.asarray(cov_state, dtype=float).reshape(3, 3).copy()
        self._started = True

    def set_state(self, x: FloatArray, P: FloatArray, ends_world: FloatArray | None = None) -> None:
        """Replace the whole state (pose and landmarks) and its covariance.

        Parameters
        ----------
        x : ndarray, shape (3 + 2M,)
        P : ndarray, shape (3 + 2M, 3 + 2M)
            Symmetric positive semi-definite.
        ends_world : ndarray, shape (M, 2, 2), optional
            Seen extent of each landmark; default: a point at the foot of each line's normal
            (overlap gating then accepts only measurements within the margin of it, so set
            ``association.overlap_margin_m`` large when landmarks have no extent).
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        n = x.shape[0]
        P = np.asarray(P, dtype=float)
        if n < 3 or (n - 3) % 2 or P.shape != (n, n):
            raise InputError(
                f"set_state: x must be (3 + 2M,) and P (n, n); got {x.shape}, {P.shape}"
            )
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise InputError("set_state: x and P must be finite")
        M = (n - 3) // 2
        self.x, self.P = x.copy(), 0.5 * (P + P.T)
        self._wrap_angles()
        lm = self.x[3:].reshape(M, 2)
        if ends_world is None:
            foot = lm[:, :1] * np.stack([np.cos(lm[:, 1]), np.sin(lm[:, 1])], -1)
            ends_world = np.stack([foot, foot], axis=1)
        self._extents = LandmarkExtents(self.config.segment_gap_m)
        for ends in np.asarray(ends_world, dtype=float).reshape(M, 2, 2):
            self._extents.append(ends)
        self._n_obs = [1] * M
        self._started = True

    def predict(self, increment: FloatArray, Q_u: FloatArray | None = None) -> None:
        """Prediction with an odometry increment (laser frame of the previous pose).

        Parameters
        ----------
        increment : ndarray, shape (3,)
            ``u = pose_odom_laser[k-1]⁻¹ · pose_odom_laser[k]``.
        Q_u : ndarray, shape (3, 3), optional
            Covariance of the increment in the tangent space; default from
            ``config.odometry``.
        """
        u = np.asarray(increment, dtype=float).reshape(3)
        if Q_u is None:
            Q_u = odometry_covariance(u, self.config.odometry)
        pose_new, F, Q = predict_pose(self.x[:3], u, Q_u)
        self.F, self.Q = F, Q
        self.x[:3] = pose_new
        P = self.P
        P[:3, :3] = F @ P[:3, :3] @ F.T + Q
        if P.shape[0] > 3:
            P[:3, 3:] = F @ P[:3, 3:]
            P[3:, :3] = P[:3, 3:].T

    def update(self, landmark_idx: IntArray, z_r_alpha: FloatArray, R: FloatArray) -> None:
        """Update with lines ``z`` (laser frame, covariances ``R`` (m, 2, 2)) of known landmarks."""
        idx = np.asarray(landmark_idx, dtype=np.intp).reshape(-1)
        if idx.size == 0:
            return
        z = np.asarray(z_r_alpha, dtype=float).reshape(-1, 2)
        R = np.asarray(R, dtype=float).reshape(-1, 2, 2)
        if self.config.update_impl == "filterpy":
            x, P, S, K = filterpy_update(self.x, self.P, idx, z, R)
            self.y = line_measurements(self.x, idx, z, R).y
        else:
            meas = line_measurements(self.x, idx, z, R)
            x, P, S, K = joseph_update(self.x, self.P, meas)
            self.y = meas.y
        self.x, self.P, self.S, self.K = x, P, S, K
        self._wrap_angles()
        for j in idx:
            self._n_obs[int(j)] += 1
        self._n_updates += 1
        self.stats["updates"] += 1

    def add_landmarks(self, z_r_alpha: FloatArray, R: FloatArray, ends_world: FloatArray) -> None:
        """Augment the state with new landmarks from lines measured at the current pose.

        Parameters
        ----------
        z_r_alpha : ndarray, shape (q, 2)
        R : ndarray, shape (q, 2, 2)
        ends_world : ndarray, shape (q, 2, 2)
            Segment end points in the world frame (for the landmark's seen extent).
        """
        z = np.asarray(z_r_alpha, dtype=float).reshape(-1, 2)
        if z.shape[0] == 0:
            return
        self.x, self.P = augment_state(self.x, self.P, z, np.asarray(R, dtype=float))
        self._wrap_angles()
        for ends in np.asarray(ends_world, dtype=float).reshape(-1, 2, 2):
            self._extents.append(ends)
            self._n_obs.append(1)

    # ------------------------------------------------------------------ association
    def _joint_tangent_covariance(self, landmarks: IntArray) -> FloatArray:
        """Joint covariance of the pose and ``landmarks`` with the pose in the tangent space.

        The filter's pose error is additive, ``δ = J(θ) ξ``; :mod:`slam.association` (shared
        with the graph) works with right-perturbation Jacobians, so the pose rows and columns
        are mapped with ``J(θ)⁻¹``: ``H_ξ P_ξ H_ξᵀ = H_δ P_δ H_δᵀ`` (same ``S``).
        """
        cols = np.concatenate(
            [np.arange(3), np.stack([3 + 2 * landmarks, 4 + 2 * landmarks], -1).ravel()]
        )
        P = self.P[np.ix_(cols, cols)]
        J_inv = tangent_to_state_jacobian(self.x[2]).T
        P[:3, :] = J_inv @ P[:3, :]
        P[:, :3] = P[:, :3] @ J_inv.T
        return P

    def associate(self, lines: LineSet) -> tuple[IntArray, NDArray[np.bool_]]:
        """Match scan lines to landmarks at the current (predicted) state.

        The graph's association code (:mod:`slam.association`) with ``config.association``:
        landmarks whose seen extent comes within ``max_range_m`` of the laser, thinned by the
        segment-overlap test (pose covariance only) and capped at the ``max_candidates``
        nearest, then the χ² gate on the joint covariance of the pose and each candidate and
        nearest neighbour or JCBB.

        Returns
        -------
        matches : ndarray of int, shape (K,)
            Landmark index per line, or −1.
        ambiguous : ndarray of bool, shape (K,)
            Unmatched lines that an overlapping landmark explains at the looser
            ``new_landmark_probability`` gate (they start no landmark).
        """
        K, M = len(lines), self.n_landmarks
        matches = np.full(K, -1, dtype=np.intp)
        no_match = np.zeros(K, dtype=bool)
        if K == 0 or M == 0:
            return matches, no_match
        acfg = self.config.association
        pose = self.x[:3]
        lm = self.x[3:].reshape(M, 2)
        extents = np.column_stack(self._extents.intervals(lm[:, 1]))
        cand = candidate_landmarks(pose, lm, extents, acfg.max_range_m)
        if cand.size:
            P_pose = cov_state_to_tangent(self.P[:3, :3], pose[2])
            near = overlap_mask(lines.endpoints, pose, P_pose, lm[cand], extents[cand], acfg)
            cand = cand[np.any(near, axis=0)]
            if cand.size > acfg.max_candidates:  # the nearest to the laser
                keep = candidate_landmarks(
                    pose, lm[cand], extents[cand], acfg.max_range_m, None, None, acfg.max_candidates
                )
                cand = cand[keep]
        if cand.size == 0:
            return matches, no_match
        problem = build_problem(
            lines.r_alpha,
            lines.cov,
            lines.endpoints,
            pose,
            self._joint_tangent_covariance(cand),
            lm[cand],
            extents[cand],
            acfg,
        )
        found = associate(problem, acfg)
        if not found.complete:
            self.stats["jcbb_incomplete"] += 1
        has = found.assignment >= 0
        matches[has] = cand[found.assignment[has]]
        ambiguous = np.any(found.d2 <= self._new_gate, axis=1)
        return matches, ambiguous & ~has

    # ------------------------------------------------------------------ merging
    def merge_landmarks(self, candidates: IntArray | None = None) -> int:
        """Fuse pairs of landmarks that pass the χ² test on their joint marginal and overlap.

        The fusion is the EKF update with the exact constraint ``l_i − l_j = 0`` (same
        representative, ``R = 0``), after which ``l_j`` equals ``l_i`` and is deleted
        (marginalised); both in one pass (:func:`slam.ekf.update.constrain_and_remove`).
        Pairs are fused greedily by increasing ``D²``, one at a time.

        Parameters
        ----------
        candidates : ndarray of int, optional
            Test only pairs that involve one of these landmarks (e.g. those observed in the
            last scan), ``O(len(candidates) · M)``; default: all pairs, ``O(M²)``.

        Returns
        -------
        int
            Number of landmarks removed.
        """
        removed = 0
        touched = None if candidates is None else {int(c) for c in candidates}
        while self.n_landmarks >= 2:
            M = self.n_landmarks
            lm = self.x[3:].reshape(M, 2)
            if touched is None:
                i, j = np.triu_indices(M, 1)
            else:
                if not touched:
                    break
                t = np.array(sorted(c for c in touched if c < M), dtype=np.intp)
                is_t = np.zeros(M, dtype=bool)
                is_t[t] = True
                ii = np.repeat(t, M)
                jj = np.tile(np.arange(M), t.size)
                sel = (jj != ii) & (~is_t[jj] | (ii < jj))  # each pair once
                i, j = ii[sel], jj[sel]
            if i.size == 0:
                break
            res, sign = line_residual(lm[i], lm[j])
            Ji = np.zeros((i.size, 2, 2))
            Ji[:, 0, 0] = sign
            Ji[:, 1, 1] = 1.0
            base_i, base_j = 3 + 2 * i, 3 + 2 * j
            P_ii = np.empty((i.size, 2, 2))
            P_jj = np.empty((i.size, 2, 2))
            P_ij = np.empty((i.size, 2, 2))
            for a in range(2):
                for b in range(2):
                    P_ii[:, a, b] = self.P[base_i + a, base_i + b]
                    P_jj[:, a, b] = self.P[base_j + a, base_j + b]
                    P_ij[:, a, b] = self.P[base_i + a, base_j + b]
            JP = Ji @ P_ij
            C = Ji @ P_ii @ Ji.swapaxes(-1, -2) + P_jj - JP - JP.swapaxes(-1, -2)
            lo, hi = self._extents.intervals(lm[:, 1])
            gap = np.maximum(lo[i], lo[j]) - np.minimum(hi[i], hi[j])
            overlap = gap <= self.config.association.overlap_margin_m
            d2 = individual_gate(res, C, self.config.merge_probability, overlap)
            best = int(np.argmin(d2))
            if not np.isfinite(d2[best]):
                break
            a, b = int(i[best]), int(j[best])
            H_sub = np.zeros((2, 4))
            H_sub[:, :2] = Ji[best]
            H_sub[:, 2:] = -np.eye(2)
            cols = np.array([3 + 2 * a, 4 + 2 * a, 3 + 2 * b, 4 + 2 * b], dtype=np.intp)
            meas = MeasurementStack(-res[best], H_sub, cols, np.zeros((2, 2)))
            try:
                self.x, self.P = constrain_and_remove(self.x, self.P, meas, cols[2:])
            except EstimationError:
                break
            self._wrap_angles()
            a_kept = a - 1 if a > b else a  # index of l_a once l_b is gone
            pieces = self._extents.pieces(b)
            self._extents.absorb(a, self.x[3 + 2 * a_kept : 5 + 2 * a_kept], pieces)
            self._extents.delete(b)
            self._n_obs[a] += self._n_obs[b]
            del self._n_obs[b]
            removed += 1
            if touched is not None:
                if b in touched:
                    touched.add(a)
                touched = {c - 1 if c > b else c for c in touched if c != b}
        self.stats["landmarks_merged"] += removed
        return removed

    # ------------------------------------------------------------------ scans
    @staticmethod
    def _odometry_of(scan: Scan) -> FloatArray:
        pose = scan.pose_odom_laser if scan.pose_odom_laser is not None else scan.pose_odom_base
        if pose is None:
            raise InputError(f"scan {scan.index} has no odometry pose", path=scan.source or None)
        pose = np.asarray(pose, dtype=float).reshape(3)
        if not np.all(np.isfinite(pose)):
            raise InputError(
                f"scan {scan.index} has a non-finite odometry pose {pose.tolist()}",
                path=scan.source or None,
            )
        return pose

    def _as_lineset(self, scan: Scan, lines: Sequence[Line] | LineSet | None) -> LineSet:
        if isinstance(lines, LineSet):
            return lines
        if lines is None:
            try:
                from linefit import extract_lines
            except ImportError as exc:  # pragma: no cover - depends on what is installed
                raise EstimationError(
                    "line extraction (linefit.extract_lines) is not available; pass lines="
                ) from exc
            from linefit.config import LineFitConfig

            cfg = self.linefit_config or LineFitConfig()
            lines = list(
                extract_lines(scan.ranges, scan.bearings, cfg, max_range_m=scan.max_range_m)
            )
        kept = [
            ln
            for ln in lines
            if ln.n_points >= self.config.min_line_points
            and ln.length >= self.config.min_line_length_m
        ]
        self.stats["lines_too_short"] += len(lines) - len(kept)
        return LineSet.from_lines(kept)

    def add_scan(self, scan: Scan, lines: Sequence[Line] | LineSet | None = None) -> ScanReport:
        """Process one scan: predict with its odometry, then associate, update and augment.

        Parameters
        ----------
        scan : Scan
            The scan (its odometry pose is required; ranges are only used when ``lines`` is
            None, and to count points).
        lines : sequence of Line, LineSet or None
            Lines of this scan in the laser frame; None extracts them with ``linefit``.

        Returns
        -------
        ScanReport

        Raises
        ------
        EstimationError
            When an update is indeterminate (innovation covariance not positive definite).
        InputError
            When the scan has no (finite) odometry pose.
        """
        if self.stopped:
            # a guard tripped earlier: the scan is not processed and gets no pose (runners
            # built for the graph keep feeding; the result says where and why it stopped)
            self.stats["scans_after_stop"] = self.stats.get("scans_after_stop", 0) + 1
            report = ScanReport(scan.index)
            report.skipped = True
            return report
        t0 = time.perf_counter()
        report = ScanReport(scan.index)
        odom = self._odometry_of(scan)
        first_scan = not self._started
        if first_scan:
            self.initialize(odom if self._initial_pose is None else self._initial_pose)
            delta = np.zeros(3)
            self._update_odom = odom
        else:
            assert self._update_odom is not None
            delta = pose_between(self._update_odom, odom)
        # the graph's keyframe rule on the odometry since the last update
        due = first_scan or (
            math.hypot(delta[0], delta[1]) >= self.config.update_min_distance_m
            or abs(delta[2]) >= self.config.update_min_angle_rad
        )
        self.stats["scans"] += 1
        self.stats["points"] += int(np.count_nonzero(scan.valid_mask()))
        if not due:
            if lines is not None:
                self.stats["lines_fit"] += len(lines)
            report.runtime_s = time.perf_counter() - t0
            self._record(scan.timestamp, report, delta)
            return report
        if not first_scan:
            self.predict(delta)
            self._update_odom = odom
        short_before = self.stats["lines_too_short"]
        ls = self._as_lineset(scan, lines)
        report.n_lines = len(ls)
        self.stats["lines_fit"] += len(ls) + self.stats["lines_too_short"] - short_before
        valid = _valid_lines(ls) if len(ls) else np.zeros(0, dtype=bool)
        report.n_invalid = int(np.count_nonzero(~valid))
        self.stats["lines_invalid"] += report.n_invalid
        ls = ls.subset(valid)
        extra_r, extra_a = self.config.line_sigma_extra
        if len(ls) and (extra_r > 0.0 or extra_a > 0.0):
            cov = ls.cov + model_error_covariance(ls.r_alpha, ls.endpoints, extra_r, extra_a)
            ls = LineSet(ls.r_alpha, cov, ls.endpoints, ls.ids)
        if len(ls) > 0:
            self._process_lines(ls, report)
        report.runtime_s = time.perf_counter() - t0
        self._record(scan.timestamp, report)
        return report

    def _process_lines(self, ls: LineSet, report: ScanReport) -> None:
        report.updated = True
        matches, ambiguous = self.associate(ls)
        k_m = np.flatnonzero(matches >= 0)
        if k_m.size:
            self.update(matches[k_m], ls.r_alpha[k_m], ls.cov[k_m])
            ends = ls.endpoints_in(self.x[:3])
            for k in k_m:
                j = int(matches[k])
                self._extents.extend(j, self.x[3 + 2 * j : 5 + 2 * j], ends[k])
        new = np.flatnonzero((matches < 0) & ~ambiguous)
        room = self.config.max_landmarks - self.n_landmarks
        if new.size > room:
            if self.config.on_max_landmarks == "stop":
                self._stop(
                    f"the map reached max_landmarks={self.config.max_landmarks} at scan "
                    f"{report.index} (state dimension {self.x.shape[0]}); "
                    "the O(n^2) update cost is guarded by ekf.max_landmarks"
                )
            self.stats["lines_not_added"] += int(new.size - max(room, 0))
            new = new[: max(room, 0)]
        if new.size:
            self.add_landmarks(ls.r_alpha[new], ls.cov[new], ls.endpoints_in(self.x[:3])[new])
        report.n_matched = int(k_m.size)
        report.n_new = int(new.size)
        report.n_ambiguous = int(np.count_nonzero(ambiguous))
        self.stats["lines_matched"] += report.n_matched
        self.stats["lines_new"] += report.n_new
        self.stats["lines_ambiguous"] += report.n_ambiguous
        self._touched.update(int(j) for j in matches[k_m])
        self._touched.update(range(self.n_landmarks - new.size, self.n_landmarks))
        if self.config.merge_landmarks and self._n_updates % self.config.merge_every_n_updates == 0:
            self.merge_landmarks(np.array(sorted(self._touched), dtype=np.intp))
            self._touched.clear()

    def _stop(self, reason: str) -> None:
        if not self.stopped:
            self.stopped = True
            self.stop_reason = reason
            self.stats["stopped_at_scan"] = self.stats["scans"] - 1
            self.stats["stop_reason"] = reason

    def _record(
        self, timestamp: float, report: ScanReport, offset: FloatArray | None = None
    ) -> None:
        """Store the scan's pose and covariance.

        After an update the state's; between updates (``offset``: the odometry since the last
        one) the state's composed with the offset, its covariance compounded with the motion
        noise.
        """
        self._t.append(float(timestamp))
        if offset is None:
            self._poses.append(self.x[:3].copy())
            self._covs.append(self.pose_covariance)
        else:
            Q_u = odometry_covariance(offset, self.config.odometry)
            pose, F, Q = predict_pose(self.x[:3], offset, Q_u)
            self._poses.append(pose)
            self._covs.append(cov_state_to_tangent(F @ self.P[:3, :3] @ F.T + Q, pose[2]))
        self._runtime.append(report.runtime_s)
        self._n_lm_hist.append(self.n_landmarks)
        self._elapsed_s += report.runtime_s
        if self.config.max_runtime_s is not None and self._elapsed_s > self.config.max_runtime_s:
            self._stop(
                f"the run exceeded max_runtime_s={self.config.max_runtime_s} at scan "
                f"{report.index} with {self.n_landmarks} landmarks"
            )

    # ------------------------------------------------------------------ output
    def optimize(self) -> None:
        """Nothing to finish: a filter's estimate is final after each scan (runner protocol)."""

    def result(self) -> EkfResult:
        """The trajectory so far, the current map in normal form, and the run statistics."""
        M = self.n_landmarks
        lm = self.x[3:].reshape(M, 2).copy()
        cov = self.landmark_marginals()
        flip = lm[:, 0] < 0.0
        lm[flip, 0] *= -1.0
        lm[:, 1] = np.asarray(wrap_angle(np.where(flip, lm[:, 1] + np.pi, lm[:, 1])))
        cov[flip, 0, 1] *= -1.0
        cov[flip, 1, 0] *= -1.0
        segments = [self._extents.segments(j, lm[j]) for j in range(M)]
        return EkfResult(
            timestamps=np.asarray(self._t, dtype=float),
            poses_world_laser=np.asarray(self._poses, dtype=float).reshape(-1, 3),
            pose_covariances=np.asarray(self._covs, dtype=float).reshape(-1, 3, 3),
            landmarks_r_alpha=lm,
            landmark_covariances=cov,
            landmark_segments=segments,
            landmark_n_observations=np.asarray(self._n_obs, dtype=np.int64),
            scan_runtime_s=np.asarray(self._runtime, dtype=float),
            n_landmarks=np.asarray(self._n_lm_hist, dtype=np.int64),
            stats=dict(self.stats),
            state_dim=int(self.x.shape[0]),
        )
