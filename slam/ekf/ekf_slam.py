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
``H``, ``y``, ``S``, ``K`` of the filter after each update).

Where ``F`` and ``H`` are evaluated is ``EkfConfig.jacobians``: at the estimates of the moment
(the standard EKF), or at the first estimates (FEJ-EKF: the propagated poses and each
landmark's first estimate; Huang, Mourikis & Roumeliotis 2008), whose linearised model keeps
the three unobservable directions of the nonlinear one; or the Jacobians at the estimates of
the moment projected so that they see none of those directions (an OC-EKF: the constraint
of Huang, Mourikis & Roumeliotis 2010, the projection of Hesch et al. 2014).

One scan (:meth:`EkfSlam.add_scan`)
-----------------------------------
The laser odometry is read by the input policy (:class:`slam.inputs.InputPolicy`).  A scan is
processed when the odometry since the last update reaches the graph's keyframe thresholds
(:func:`slam.models.moved_enough`); other scans get the last update's pose composed with the
odometry since, the covariance compounded with the motion noise.

1. **Predict** with the odometry increment ``u = pose_odom[k-1]⁻¹ pose_odom[k]``
   (:mod:`slam.ekf.motion`).
2. **Lines**: given, or extracted with :func:`slam.extraction.extract_scan_lines`; lines with
   too little support are dropped and lines whose covariance is not finite and positive
   definite are skipped (both counted; :func:`slam.lines.lineset.supported_lines`,
   :meth:`~slam.lines.lineset.LineSet.well_posed`).
3. **Associate** with the graph's code (:mod:`slam.association`): candidates within range,
   segment-overlap test along the landmark, individual χ² gate on each (line, landmark) pair
   with ``S = H P Hᵀ + R`` from the current joint covariance; then nearest neighbour or JCBB.
4. **Update** all matched lines at once, Joseph form (:mod:`slam.ekf.update`).
5. **Augment** the state with unmatched lines that no landmark could explain (Eq. 30 with the
   cross-covariances, :mod:`slam.ekf.augment`).
6. Optionally **merge** landmarks that became compatible (:mod:`slam.ekf.merging`).

:meth:`EkfSlam.result` reports the poses in the policy's output frame as a
:class:`slam.result.SlamResult`, the result type of both estimators (:mod:`slam.ekf.records`).

The ``O(n²)`` cost of an update (``n = 3 + 2M``) is guarded by ``EkfConfig.max_landmarks`` and
``max_runtime_s``; when a guard trips the result records at which scan and why.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from linefit.config import LineFitConfig
from linefit.line import Line, wrap_angle
from slam.association import associate, build_problem, candidate_landmarks, overlap_mask
from slam.ekf.augment import augment_state
from slam.ekf.config import EkfConfig
from slam.ekf.conventions import cov_state_to_tangent, tangent_to_state_jacobian
from slam.ekf.extents import LandmarkExtents
from slam.ekf.merging import merge_compatible_landmarks, wrap_state_angles
from slam.ekf.motion import (
    first_estimates_propagation_jacobian,
    odometry_covariance,
    predict_pose,
)
from slam.ekf.records import ScanRecords, ScanReport
from slam.ekf.update import (
    MeasurementStack,
    filterpy_update,
    joseph_update,
    line_measurements,
    observability_constrained,
)
from slam.errors import InputError
from slam.geometry import chain_covariance, pose_between
from slam.inputs import InputPolicy
from slam.lines import chi2_gate
from slam.lines.lineset import LineSet, supported_lines
from slam.models import landmarks_normal_form, moved_enough
from slam.types import Scan, check_lines, check_scan
from slam.validate import check_config

if TYPE_CHECKING:
    from slam.result import SlamResult

__all__ = ["EkfSlam", "ScanReport"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class EkfSlam:
    """EKF-SLAM over line landmarks, fed one scan at a time.

    Parameters
    ----------
    config : EkfConfig, optional
        Filter settings.
    linefit_config : LineFitConfig, optional
        Used only when :meth:`add_scan` is called without lines.
    policy : InputPolicy, optional
        How a scan's laser odometry is read and which frame :meth:`result` reports
        (:mod:`slam.inputs`); default: the logged laser odometry, laser frame.
    initial_pose_world_laser : array_like, shape (3,), optional
        Pose of the first scan's laser in the world.  Default: its odometry pose (the world
        frame is the odometry frame at the start).

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
        policy: InputPolicy | None = None,
        initial_pose_world_laser: FloatArray | Sequence[float] | None = None,
    ) -> None:
        self.config = check_config(config, EkfConfig, "config")
        self.linefit_config = (
            None
            if linefit_config is None
            else check_config(linefit_config, LineFitConfig, "linefit_config")
        )
        self.policy = check_config(policy, InputPolicy, "policy")
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
        self._last_measurements: tuple[MeasurementStack, int] | None = None
        self.S: FloatArray = np.zeros((0, 0))
        self.K: FloatArray = np.zeros((3, 0))
        self._extents = LandmarkExtents(self.config.segment_gap_m)
        self._n_obs: list[int] = []
        # the first-estimates Jacobians' linearisation points (config.jacobians)
        self._pose_propagated: FloatArray = np.zeros(3)
        self._lm_first: list[FloatArray] = []
        self._touched: set[int] = set()
        self._update_odom: FloatArray | None = None
        # covariance of the odometry since the last update, where every scan states its step's
        # (the laser odometry: Scan.odometry_step_cov); None: the motion model's
        self._update_cov: FloatArray | None = np.zeros((3, 3))
        self._last_odom: FloatArray | None = None
        self._n_updates = 0
        self._started = False
        self.stopped = False
        self.stop_reason = ""
        self._elapsed_s = 0.0
        self._records = ScanRecords()
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

    @property
    def H(self) -> FloatArray:
        """The last update's Jacobian, dense ``(2m, n)`` (``n`` the state size at that update).

        Formed on request from the sparse columns the update used; ``(0, 3)`` before any.
        """
        if self._last_measurements is None:
            return np.zeros((0, 3))
        meas, n = self._last_measurements
        return meas.dense_H(n)

    def landmark_marginals(self) -> FloatArray:
        """Marginal covariances of the landmarks, shape ``(M, 2, 2)``."""
        M = self.n_landmarks
        idx = np.arange(M)
        return self.P[3:, 3:].reshape(M, 2, M, 2)[idx, :, idx, :].copy()

    def _wrap_angles(self) -> None:
        wrap_state_angles(self.x)

    # ------------------------------------------------------------------ filter steps
    def initialize(self, pose_world_laser: FloatArray, cov_state: FloatArray | None = None) -> None:
        """Start the filter at a pose (additive covariance ``cov_state``, default from config)."""
        self.x = np.asarray(pose_world_laser, dtype=float).reshape(3).copy()
        self.x[2] = wrap_angle(self.x[2])
        if cov_state is None:
            cov_state = np.diag(np.square(self.config.initial_pose_sigma))
        self.P = np.asarray(cov_state, dtype=float).reshape(3, 3).copy()
        self._pose_propagated = self.x[:3].copy()
        self._lm_first = []
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
        self._pose_propagated = self.x[:3].copy()
        self._lm_first = [row.copy() for row in lm]
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
        if self.config.jacobians != "current":
            F = first_estimates_propagation_jacobian(pose_new, self._pose_propagated)
        self._pose_propagated = pose_new.copy()
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
        jac = self.config.jacobians
        lin = None
        if jac != "current":
            first = np.array([self._lm_first[int(j)] for j in idx]).reshape(-1, 2)
            lin = (self._pose_propagated, first)
        meas = line_measurements(self.x, idx, z, R, lin if jac == "first-estimates" else None)
        if jac == "observability-constrained":
            assert lin is not None
            meas = observability_constrained(meas, lin[0], lin[1][:, 1])
        self._last_measurements = (meas, self.x.shape[0])
        if self.config.update_impl == "filterpy":
            H = None if jac == "current" else self.H
            x, P, S, K = filterpy_update(self.x, self.P, idx, z, R, H)
        else:
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
        m_before = self.n_landmarks
        self.x, self.P = augment_state(self.x, self.P, z, np.asarray(R, dtype=float))
        self._wrap_angles()
        self._lm_first.extend(
            self.x[3 + 2 * j : 5 + 2 * j].copy() for j in range(m_before, self.n_landmarks)
        )
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

        :func:`slam.ekf.merging.merge_compatible_landmarks` with ``config.merge_probability``
        and ``config.association.overlap_margin_m``.

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
        self.x, self.P, removed = merge_compatible_landmarks(
            self.x,
            self.P,
            self._extents,
            self._n_obs,
            self.config.merge_probability,
            self.config.association.overlap_margin_m,
            candidates,
            self._lm_first,
        )
        self.stats["landmarks_merged"] += removed
        return removed

    # ------------------------------------------------------------------ scans
    def _as_lineset(self, scan: Scan, lines: Sequence[Line] | LineSet | None) -> LineSet:
        """The scan's lines as a set: given, or extracted; the support rule applied to fits."""
        if isinstance(lines, LineSet):
            return lines
        if lines is None:
            from slam.extraction import extract_scan_lines

            lines = extract_scan_lines(scan, self.linefit_config or LineFitConfig())
        keep = supported_lines(lines, self.config.min_line_points, self.config.min_line_length_m)
        self.stats["lines_too_short"] += int(np.count_nonzero(~keep))
        return LineSet.from_lines([ln for ln, k in zip(lines, keep, strict=True) if k])

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
            ``scan`` is not a :class:`Scan`, ``lines`` not a sequence of :class:`Line` (or a
            :class:`LineSet`), or the scan has no (finite) odometry pose.
        """
        check_scan(scan)
        if lines is not None and not isinstance(lines, LineSet):
            lines = check_lines(lines, scan)
        if self.stopped:
            # a guard tripped earlier: the scan is not processed and gets no pose (runners
            # built for the graph keep feeding; the result says where and why it stopped)
            self.stats["scans_after_stop"] = self.stats.get("scans_after_stop", 0) + 1
            report = ScanReport(scan.index)
            report.skipped = True
            return report
        t0 = time.perf_counter()
        report = ScanReport(scan.index)
        odom = self.policy.pose_odom_laser(scan)
        first_scan = not self._started
        if first_scan:
            self.initialize(odom if self._initial_pose is None else self._initial_pose)
            delta = np.zeros(3)
            self._update_odom = odom
        else:
            assert self._update_odom is not None and self._last_odom is not None
            delta = pose_between(self._update_odom, odom)
            self._update_cov = chain_covariance(
                self._update_cov, pose_between(self._last_odom, odom), scan.odometry_step_cov
            )
        self._last_odom = odom
        # the graph's keyframe rule on the odometry since the last update
        due = first_scan or moved_enough(
            delta, self.config.update_min_distance_m, self.config.update_min_angle_rad
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
            self.predict(delta, self._update_cov)
            self._update_odom = odom
            self._update_cov = np.zeros((3, 3))
        short_before = self.stats["lines_too_short"]
        ls = self._as_lineset(scan, lines)
        report.n_lines = len(ls)
        self.stats["lines_fit"] += len(ls) + self.stats["lines_too_short"] - short_before
        valid = ls.well_posed()
        report.n_invalid = int(np.count_nonzero(~valid))
        self.stats["lines_invalid"] += report.n_invalid
        ls = ls.subset(valid).with_model_error(*self.config.line_sigma_extra)
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
        if offset is None:
            pose, cov = self.x[:3].copy(), self.pose_covariance
        else:
            Q_u = odometry_covariance(offset, self.config.odometry)
            pose, F, Q = predict_pose(self.x[:3], offset, Q_u)
            cov = cov_state_to_tangent(F @ self.P[:3, :3] @ F.T + Q, pose[2])
        self._records.append(
            timestamp, pose, cov, offset is None, report.runtime_s, self.n_landmarks
        )
        self._elapsed_s += report.runtime_s
        if self.config.max_runtime_s is not None and self._elapsed_s > self.config.max_runtime_s:
            self._stop(
                f"the run exceeded max_runtime_s={self.config.max_runtime_s} at scan "
                f"{report.index} with {self.n_landmarks} landmarks"
            )

    # ------------------------------------------------------------------ output
    def optimize(self) -> None:
        """Nothing to finish: a filter's estimate is final after each scan (runner protocol)."""

    def result(self) -> SlamResult:
        """The trajectory so far, the current map in normal form, and the run statistics.

        :meth:`slam.ekf.records.ScanRecords.result`: poses in the policy's output frame, the
        updates as keyframes, ``state_dim`` the final state size.
        """
        M = self.n_landmarks
        lm, cov = landmarks_normal_form(self.x[3:].reshape(M, 2), self.landmark_marginals())
        assert cov is not None
        segments = [self._extents.segments(j, lm[j]) for j in range(M)]
        return self._records.result(
            lm, cov, segments, self._n_obs, self.stats, self.policy, int(self.x.shape[0])
        )
