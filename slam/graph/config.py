"""Configuration of the factor-graph back-end (frozen dataclasses, validated, TOML round trip).

``SlamConfig`` is the ``[slam]`` table of :class:`slam.config.RunConfig`; its sub-tables are
``[slam.motion]``, ``[slam.keyframes]``, ``[slam.association]``, ``[slam.fusion]``,
``[slam.solver]`` and ``[slam.isam2]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from slam.association import AssociationConfig
from slam.errors import ConfigError
from slam.frontend.registration import RegistrationConfig

__all__ = [
    "FrontendConfig",
    "FusionConfig",
    "Isam2Config",
    "KeyframeConfig",
    "LoopClosureConfig",
    "MotionNoiseConfig",
    "RelocalisationConfig",
    "SlamConfig",
    "SolverConfig",
    "TentativeConfig",
]

FloatArray = NDArray[np.float64]


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise ConfigError(message)


def _nonneg(name: str, value: float) -> None:
    _require(math.isfinite(value) and value >= 0.0, f"{name} must be a finite number >= 0")


def _pos(name: str, value: float) -> None:
    _require(math.isfinite(value) and value > 0.0, f"{name} must be a finite number > 0")


@dataclass(frozen=True)
class MotionNoiseConfig:
    """Odometry noise: a random walk in distance travelled and angle turned.

    The covariance of a relative motion ``(dx, dy, dθ)`` (right tangent space, body frame) is
    ``diag(σ_xy², σ_xy², σ_θ²)`` with

    ``σ_xy² = sigma_xy_min_m² + sigma_xy_per_m²·d + sigma_xy_per_rad²·|dθ|``,
    ``σ_θ²  = sigma_theta_min_rad² + sigma_theta_per_m²·d + sigma_theta_per_rad²·|dθ|``,

    ``d = √(dx² + dy²)``.  Variances grow linearly, so chaining steps gives (to first order) the
    same uncertainty as one step over the same path: ``sigma_xy_per_m`` is the standard
    deviation after 1 m (m/√m), ``sigma_theta_per_rad`` after turning 1 rad (rad/√rad), etc.

    Attributes
    ----------
    sigma_xy_per_m, sigma_xy_per_rad, sigma_theta_per_m, sigma_theta_per_rad : float
        See above.
    sigma_xy_min_m, sigma_theta_min_rad : float
        Floors, so that a standstill is not a perfect constraint.
    """

    sigma_xy_per_m: float = 0.05
    sigma_xy_per_rad: float = 0.02
    sigma_theta_per_m: float = 0.02
    sigma_theta_per_rad: float = 0.05
    sigma_xy_min_m: float = 0.002
    sigma_theta_min_rad: float = 0.001

    def __post_init__(self) -> None:
        for name in (
            "sigma_xy_per_m",
            "sigma_xy_per_rad",
            "sigma_theta_per_m",
            "sigma_theta_per_rad",
        ):
            _nonneg(name, getattr(self, name))
        _pos("sigma_xy_min_m", self.sigma_xy_min_m)
        _pos("sigma_theta_min_rad", self.sigma_theta_min_rad)

    def covariance(self, delta: FloatArray) -> FloatArray:
        """Covariance ``(..., 3, 3)`` of relative motions ``delta`` ``(..., 3)``."""
        d = np.asarray(delta, dtype=float)
        dist = np.hypot(d[..., 0], d[..., 1])
        turn = np.abs(d[..., 2])
        var_xy = self.sigma_xy_min_m**2 + self.sigma_xy_per_m**2 * dist
        var_xy = var_xy + self.sigma_xy_per_rad**2 * turn
        var_th = self.sigma_theta_min_rad**2 + self.sigma_theta_per_m**2 * dist
        var_th = var_th + self.sigma_theta_per_rad**2 * turn
        out = np.zeros((*d.shape[:-1], 3, 3))
        out[..., 0, 0] = var_xy
        out[..., 1, 1] = var_xy
        out[..., 2, 2] = var_th
        return out


@dataclass(frozen=True)
class KeyframeConfig:
    """When a scan becomes a pose variable.

    A scan is a keyframe when the odometry since the last keyframe exceeds ``min_distance_m``
    or ``min_angle_rad`` (the first scan always is).  Other scans get a pose from the last
    keyframe's estimate composed with their odometry, and their lines are not used.  Zero for
    both makes every scan a keyframe.
    """

    min_distance_m: float = 0.2
    min_angle_rad: float = 0.15

    def __post_init__(self) -> None:
        _nonneg("min_distance_m", self.min_distance_m)
        _nonneg("min_angle_rad", self.min_angle_rad)


@dataclass(frozen=True)
class FusionConfig:
    """Landmark fusion: merging two landmarks that turn out to be the same wall.

    Attributes
    ----------
    enabled : bool
        Test and merge at all.
    interval_keyframes : int
        Test every this many keyframes (and at :meth:`LineSlam.optimize`).
    gate_probability : float
        χ² gate (2 dof) of the Eq. 34-35 test on the joint marginal of the two landmarks;
        default the paper's "3σ" (11.83).
    max_gap_m : float
        Largest gap (m) between the two landmarks' extents along the line.
    max_angle_rad : float
        Pre-filter: pairs whose normals differ by more (mod π) are not tested.
    max_distance_m : float
        Pre-filter: largest distance between one landmark's extent mid-point and the other line.
    retest_growth : float
        A pair that failed the test is tested again once its landmarks have this many times the
        measurements (together) they had then.
    audit_max_median_chi2 : float
        A merge (fusion or loop closure) is undone when, some keyframes later, the median
        whitened squared residual of either side's line factors exceeds this (χ²₂ 99 %: 9.21);
        fusion never merges an undone pair again.
    max_path_gap_m : float
        During the run, two landmarks last seen more than this much driven path apart are
        not fused but left to loop closing, which verifies a whole submap and rejects
        ambiguous matches: after metres of drift a wall can land on its neighbour (rooms along
        a corridor repeat), and a wrong fusion binds the drifted estimate to the wrong place.
        Default: the front end's drift limit (``max_drift_xy_m / drift_xy_per_m`` = 20 m).
        The final round over the whole map (:meth:`LineSlam.optimize`) has no such limit.
    """

    enabled: bool = True
    interval_keyframes: int = 10
    gate_probability: float = 0.9973
    max_gap_m: float = 0.3
    max_angle_rad: float = 0.2
    max_distance_m: float = 0.5
    retest_growth: float = 2.0
    audit_max_median_chi2: float = 9.21
    max_path_gap_m: float = 20.0

    def __post_init__(self) -> None:
        _require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        _require(self.retest_growth >= 1.0, "retest_growth must be >= 1")
        _require(0.0 < self.gate_probability < 1.0, "gate_probability must be in (0, 1)")
        _nonneg("max_gap_m", self.max_gap_m)
        _pos("max_angle_rad", self.max_angle_rad)
        _pos("max_distance_m", self.max_distance_m)
        _pos("audit_max_median_chi2", self.audit_max_median_chi2)
        _pos("max_path_gap_m", self.max_path_gap_m)


@dataclass(frozen=True)
class SolverConfig:
    """Batch Gauss-Newton / Levenberg-Marquardt (own loop, GTSAM elimination) and kernels.

    Attributes
    ----------
    max_iterations : int
        Iterations of a final (:meth:`LineSlam.optimize`) solve.
    online_iterations : int
        Iterations of a periodic solve while scans arrive (batch back-end).
    batch_interval : int
        Keyframes between periodic solves (batch back-end).
    relative_tolerance : float
        Converged when the cost decreases by less than this fraction.
    step_tolerance : float
        Converged when the largest update component is below this.
    lambda_initial, lambda_min, lambda_max : float
        Levenberg-Marquardt damping ``λ·D`` (``D`` ≈ ``diag(AᵀA)``): a Gauss-Newton step that
        raises the cost is retried with ``λ = lambda_initial``, growing (×2, ×4, ...) per
        failure and following Nielsen's rule after a success; below ``lambda_min`` the solver
        returns to pure Gauss-Newton, above ``lambda_max`` it stops.
    robust_kernel : {"none", "huber", "cauchy"}
        Kernel on line factors (IRLS).
    robust_k : float
        Kernel width in standard deviations of the whitened residual.
    ordering : {"colamd", "metis"}
        Elimination ordering.
    """

    max_iterations: int = 30
    online_iterations: int = 3
    batch_interval: int = 1
    relative_tolerance: float = 1e-8
    step_tolerance: float = 1e-7
    lambda_initial: float = 1e-3
    lambda_min: float = 1e-7
    lambda_max: float = 1e10
    robust_kernel: Literal["none", "huber", "cauchy"] = "cauchy"
    robust_k: float = 3.0
    ordering: Literal["colamd", "metis"] = "colamd"

    def __post_init__(self) -> None:
        _require(self.max_iterations >= 1, "max_iterations must be >= 1")
        _require(self.online_iterations >= 1, "online_iterations must be >= 1")
        _require(self.batch_interval >= 1, "batch_interval must be >= 1")
        _nonneg("relative_tolerance", self.relative_tolerance)
        _nonneg("step_tolerance", self.step_tolerance)
        _pos("lambda_initial", self.lambda_initial)
        _pos("lambda_min", self.lambda_min)
        _require(self.lambda_min < self.lambda_initial, "lambda_min must be < lambda_initial")
        _require(self.lambda_max > self.lambda_initial, "lambda_max must exceed lambda_initial")
        _require(
            self.robust_kernel in ("none", "huber", "cauchy"),
            f"robust_kernel must be none, huber or cauchy, got {self.robust_kernel!r}",
        )
        _pos("robust_k", self.robust_k)
        _require(self.ordering in ("colamd", "metis"), "ordering must be colamd or metis")


@dataclass(frozen=True)
class Isam2Config:
    """Incremental back-end (``gtsam.ISAM2``) and its relinearisation policy.

    Attributes
    ----------
    relinearize_threshold_m, relinearize_threshold_rad : float
        iSAM2's own thresholds on the update of a variable (in its tangent space) above which
        the variable is relinearised: metres for a pose's translation and a landmark's ``ρ``,
        radians for a pose's heading and a landmark's ``φ``.  With ``final_relinearizations``
        the final :meth:`~slam.graph.backend.Isam2Backend.optimize` relinearises everything
        at the estimate until the step is below ``final_step_tolerance``, so they trade the
        accuracy of the online estimate (not of the final one) for time.  But the online estimate
        decides which loop closures pass: on Intel 0.03 / 0.03 took 117 s against 163 s with
        0.01 / 0.01 (iSAM2's own time 34 s against 61 s), while fr079 went to 1.08 m and the
        simulated loop of ``tests/test_graph_sim.py`` accepted two wrong closures with
        translation thresholds of 0.015-0.03 (``docs/real-logs.md``, sixth session).
    relin_translation_m, relin_angle_rad, relin_range_m : float
        A keyframe's line-factor block (a ``LinearContainerFactor``) is linearised again at
        iSAM2's linearisation point when a variable of it moved more than these (pose
        translation, any angle, landmark ``r``) since the block was built.  0 means any change.
    full_refresh_variables : int
        After an update that re-eliminated more variables than this (a loop closure), the whole
        estimate is read back from iSAM2; otherwise only the touched variables.
    full_refresh_interval : int
        Read back the whole estimate at least every this many updates.
    final_updates : int
        Most extra updates (no new factors) run by :meth:`optimize` to converge.
    final_relinearizations : int
        After those, the final :meth:`~slam.graph.backend.Isam2Backend.optimize` rebuilds
        iSAM2 at the estimate (every factor relinearised: one Gauss-Newton step) at most this
        many times, until the largest step component is below ``final_step_tolerance``.
        0 (default): the final estimate keeps iSAM2's linear updates below the
        relinearisation thresholds.  With the default thresholds the rebuilds buy little: on
        the simulated loop of ``tests/test_graph_sim.py`` ATE 2.3 → 1.7 mm; on Intel, 5 per
        ``optimize`` call, 25 rebuilds cost ~9 s and the step was still 1.8 mm (with the
        Cauchy kernel's weights refreshed at each rebuild the iteration converges linearly),
        relations error 0.0308 against 0.0292 m.  Meant for coarser thresholds.
    final_step_tolerance : float
        Metres or radians, any component of any variable.
    relinearize_skip : int
        iSAM2 checks for variables to relinearise only every this many updates (GTSAM's
        default 10).  Relinearising at every update (1) lets the one-update lag of the block
        rebuilds feed back into the next relinearisation: on long open chains the
        relinearisations then cascade over the whole graph (``docs/graph.md``).
    partial_relinearization_check : bool
        iSAM2's ``enablePartialRelinearizationCheck``: only the top of the tree is checked for
        variables to relinearise (cheap; deep variables may keep large updates).
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "relinearize_threshold": "split into relinearize_threshold_m and relinearize_threshold_rad"
    }

    relinearize_threshold_m: float = 0.01
    relinearize_threshold_rad: float = 0.01
    relin_translation_m: float = 0.0
    relin_angle_rad: float = 0.0
    relin_range_m: float = 0.0
    full_refresh_variables: int = 200
    full_refresh_interval: int = 50
    final_updates: int = 20
    final_relinearizations: int = 0
    final_step_tolerance: float = 1e-4
    relinearize_skip: int = 10
    partial_relinearization_check: bool = True

    def __post_init__(self) -> None:
        _pos("relinearize_threshold_m", self.relinearize_threshold_m)
        _pos("relinearize_threshold_rad", self.relinearize_threshold_rad)
        _require(self.final_relinearizations >= 0, "final_relinearizations must be >= 0")
        _pos("final_step_tolerance", self.final_step_tolerance)
        _nonneg("relin_translation_m", self.relin_translation_m)
        _nonneg("relin_angle_rad", self.relin_angle_rad)
        _nonneg("relin_range_m", self.relin_range_m)
        _require(self.full_refresh_variables >= 0, "full_refresh_variables must be >= 0")
        _require(self.full_refresh_interval >= 1, "full_refresh_interval must be >= 1")
        _require(self.final_updates >= 0, "final_updates must be >= 0")
        _require(self.relinearize_skip >= 1, "relinearize_skip must be >= 1")


@dataclass(frozen=True)
class RelocalisationConfig:
    """Relocalisation: the front end's fallback when the registration pairs too few lines.

    After wheel slip or a fast turn the odometry prediction is too far off for the χ² gates:
    the scan's lines are then searched for in the local map over a window with
    :func:`slam.frontend.loop_closure.search_loop_closure` (same meaning of the fields as in
    :class:`LoopClosureConfig`), and the registration is run again from the correction found.

    Attributes
    ----------
    enabled : bool
    min_matched_fraction : float
        Relocalise when the registration paired fewer than this fraction of the lines (and
        fewer than all of them).
    window_xy_m, window_theta_rad : float
        Search window around the odometry prediction.
    """

    enabled: bool = True
    min_matched_fraction: float = 0.5
    window_xy_m: float = 0.5
    window_theta_rad: float = 0.4
    cell_m: float = 0.05
    angle_tolerance_rad: float = 0.04
    offset_tolerance_m: float = 0.1
    overlap_margin_m: float = 0.3
    min_matched_length_m: float = 1.0
    min_matches: int = 2
    min_direction_angle_rad: float = 0.5
    max_ambiguity: float = 0.8
    corridor_closures: bool = True

    def __post_init__(self) -> None:
        _require(0.0 <= self.min_matched_fraction <= 1.0, "min_matched_fraction in [0, 1]")
        for name in (
            "window_xy_m",
            "window_theta_rad",
            "cell_m",
            "angle_tolerance_rad",
            "offset_tolerance_m",
            "min_direction_angle_rad",
        ):
            _pos(name, getattr(self, name))
        _nonneg("overlap_margin_m", self.overlap_margin_m)
        _nonneg("min_matched_length_m", self.min_matched_length_m)
        _require(self.min_matches >= 2, "min_matches must be >= 2")
        _require(0.0 < self.max_ambiguity <= 1.0, "max_ambiguity must be in (0, 1]")


@dataclass(frozen=True)
class FrontendConfig:
    """Registration of each keyframe's lines against the local map (initial guess, association).

    The local map is every landmark (graph or tentative) whose extent is within
    ``association.max_range_m`` of the predicted pose and whose drift relative to the robot is
    small: a landmark last seen ``d`` metres of path ago has drifted by about
    ``σ_xy = drift_xy_per_m·d`` and ``σ_θ = drift_theta_per_m·d``
    (:func:`slam.frontend.anchored.drift_covariance` adds this to its covariance); beyond
    ``max_drift_xy_m`` it is left to loop closing.

    Attributes
    ----------
    registration : RegistrationConfig
        Gates, iterations, kernel of :func:`slam.frontend.register_lines`.
    relocalisation : RelocalisationConfig
        Fallback search when the registration pairs too few lines.
    prior_sigma_xy_m, prior_sigma_theta_rad : float
        Added (in quadrature) to the odometry covariance of the prediction used as the
        registration's prior, so that a bad odometry step (wheel slip) can be corrected.
    drift_xy_per_m, drift_theta_per_m : float
        Drift model of the front end (m per m of path, rad per m of path).
    max_drift_xy_m : float
        Landmarks whose drift ``σ_xy`` exceeds this are not offered to the registration.
    landmark_sigma_r_m, landmark_sigma_alpha_rad : float
        Floor on a landmark's covariance relative to the poses that saw it (its observations'
        information, summed, never makes it better than this: their errors are not independent).
    pose_factor : {"none", "inflated"}
        ``"none"``: the registration is the initial guess and the association, and the scan's
        lines enter as line factors only (no double counting).  ``"inflated"``: also a
        relative-pose factor from the previous keyframe with the registration's covariance
        multiplied by ``pose_factor_inflation`` (see ``docs/real-logs.md``).
    pose_factor_inflation : float
    """

    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    relocalisation: RelocalisationConfig = field(default_factory=RelocalisationConfig)
    prior_sigma_xy_m: float = 0.02
    prior_sigma_theta_rad: float = 0.01
    drift_xy_per_m: float = 0.01
    drift_theta_per_m: float = 0.002
    max_drift_xy_m: float = 0.2
    landmark_sigma_r_m: float = 0.005
    landmark_sigma_alpha_rad: float = 0.002
    pose_factor: Literal["none", "inflated"] = "none"
    pose_factor_inflation: float = 4.0

    def __post_init__(self) -> None:
        for name in (
            "prior_sigma_xy_m",
            "prior_sigma_theta_rad",
            "drift_xy_per_m",
            "drift_theta_per_m",
            "landmark_sigma_r_m",
            "landmark_sigma_alpha_rad",
        ):
            _nonneg(name, getattr(self, name))
        _pos("max_drift_xy_m", self.max_drift_xy_m)
        _require(self.pose_factor in ("none", "inflated"), "pose_factor must be none or inflated")
        _require(self.pose_factor_inflation >= 1.0, "pose_factor_inflation must be >= 1")


@dataclass(frozen=True)
class TentativeConfig:
    """When a new line becomes a graph landmark (:mod:`slam.frontend.tentative`).

    Attributes
    ----------
    min_observations : int
        Keyframes that must observe a line before it gets a graph variable (1: at once).
    max_age_keyframes : int
        A tentative line not observed for this many keyframes is dropped with its observations.
    """

    min_observations: int = 3
    max_age_keyframes: int = 10

    def __post_init__(self) -> None:
        _require(self.min_observations >= 1, "min_observations must be >= 1")
        _require(self.max_age_keyframes >= 1, "max_age_keyframes must be >= 1")


@dataclass(frozen=True)
class LoopClosureConfig:
    """Loop closing: re-associating revisited walls after drift (:mod:`slam.frontend.loop_closure`).

    Every ``interval_keyframes`` keyframes the local submap (landmarks seen during the last
    ``local_keyframes`` keyframes) is searched for in the old map (landmarks beyond the front
    end's drift limit, within reach) over a window that grows with the path since they were
    seen: rotation candidates from the histogram of line angle differences, translation by a
    vote of line-pair constraints on a grid, then verification (segment overlap, matched length,
    two directions, a clear winner) and a refinement.  Verified pairs of landmarks are merged;
    the closure is kept only if the graph explains it afterwards (a batch solve of the loop,
    after which at least ``min_consistent_fraction`` of the merged pairs have both sides'
    median whitened χ² below ``fusion.audit_max_median_chi2``), else undone.

    Attributes
    ----------
    enabled : bool
    interval_keyframes : int
    local_keyframes : int
    window_xy_per_m, window_theta_per_m : float
        Search half-widths per metre of path since the old landmarks were seen.
    min_window_xy_m, min_window_theta_rad, max_window_xy_m, max_window_theta_rad : float
        ``max_window_xy_m``: the front end's drift with loop closing off, against the default
        runs' trajectories, stayed under 3.1 m (99th percentile) over every 10-200 m of path
        on Intel, ACES and fr079, largest 3.4 m (``scripts/front_end_drift.py``,
        2026-11-29).  Wider windows mostly admit aliases: fr079's repeating rooms offered
        5-13 m corrections where well under 1 m was needed.
    window_of_pairs : bool
        A hypothesis must lie within the window of the old lines it pairs (the median of
        their windows), not only within the search window (that of the oldest line in
        reach): where the local lines match walls seen 20 m ago, a 9 m correction is not
        allowed because a wall in reach was seen 200 m ago.
    cell_m : float
        Translation grid of the vote.
    angle_tolerance_rad, offset_tolerance_m : float
        A transformed local line matches an old line within these.
    overlap_margin_m : float
        Largest gap along the line between matched segments.
    min_matched_length_m : float
        Matched local lines must add up to this length.
    min_matches : int
    min_direction_angle_rad : float
        Matched lines must include two directions at least this far apart.
    max_ambiguity : float
        A distinct runner-up hypothesis with more than this fraction of the winner's score
        makes the closure ambiguous (rejected).
    corridor_closures : bool
        Accept closures whose paired lines are all parallel (a corridor: they fix the
        rotation and the offset across it, not the position along it) if their matched length
        is 1.5 × ``min_matched_length_m``; ambiguity is then judged across the corridor only.
    max_updates : int
        Most iSAM2 updates (``Isam2Solver.optimize``) run to settle the back-end after an
        accepted closure.
    large_correction_m, large_correction_rad : float
        A correction larger than either is large: it is spread along the loop before the
        judgement (a starting point near the closed loop), and once accepted the back-end
        restarts from the judged estimate.  A smaller one (the loop is already nearly closed)
        reaches the back-end incrementally, like a fusion merge.  0: every closure is large.
    judge_iterations : int
        Most linearisations of the batch solve that judges a candidate closure (outside the
        back-end; a rejected candidate never reaches it).
    judge_relative_tolerance : float
        That solve stops when the cost decreases by less than this fraction.
    min_consistent_fraction : float
        A judged closure is accepted when at least this fraction of its merged pairs (and at
        least ``min_matches - 1``) are explained by the solved loop (both sides' median
        whitened χ² below ``fusion.audit_max_median_chi2``); the others are undone.
    judge_max_pair_chi2 : float
        A judged closure with a merged pair that the solved loop leaves this far apart (the
        larger of its two sides' median whitened χ²) is rejected whole, however many pairs
        are explained: at ~30σ the local map sits on other walls than the hypothesis says,
        which a few mismatched lines in a right closure do not do.  inf: off.
    max_correction_chi2 : float
        Gate before the judgement: the correction, as a change of the relative pose between
        the keyframe where the paired old lines were last seen and the current one, must lie
        within this squared Mahalanobis distance under the back-end's joint marginal
        covariance of the two poses (``Backend.joint_pose_covariance``); a hypothesis beyond it
        is rejected without being judged.  The covariances are over-confident on real logs
        (right closures reach ~600, ``docs/real-logs.md``), so this is a wide gate, not a χ²
        quantile.  inf: off.
    gate_override_after : int
        A hypothesis whose correction the gate has already turned away this many times within
        the last ``local_keyframes`` keyframes (the same correction within twice the angle and
        offset tolerances) is judged anyway: persistent evidence against the marginals, which
        a wrong closure accepted earlier makes over-confident.  0: never.
    judge_loop_only : bool
        Solve only the loop in that judgement: the poses from ``local_keyframes`` before the
        matched old landmarks were last seen on, the earlier poses held at their estimate
        (the map before the loop is the reference).  False: the whole graph.
    judge_hopeless_after : int
        After this many linearisations a judgement that explains at most one of its pairs
        stops (it is then rejected: acceptance needs ``max(min_matches − 1, 2)``).  Measured
        on Intel and fr079 (one run each, 2026-11-29): none of the 50 accepted closures had
        fewer than 2 explained pairs after 5 linearisations; 26 of the 54 rejected ones had
        at most 1.  0: judgements always run their ``judge_iterations``.
    skip_repeated_rejections : bool
        A candidate that repeats a hypothesis judged and rejected during the last
        ``local_keyframes`` keyframes (a correction within twice the angle and offset
        tolerances of it) with no more paired lines than it had is not judged again: no new
        evidence.  (A rejected candidate leaves the graph as it was, so the repeat would be
        judged on the same estimate.)
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "max_chi2_per_factor": "removed (it had no effect; the verdict is judge_* and "
        "min_consistent_fraction): delete the line"
    }

    enabled: bool = True
    interval_keyframes: int = 5
    local_keyframes: int = 20
    window_xy_per_m: float = 0.05
    window_theta_per_m: float = 0.005
    min_window_xy_m: float = 0.5
    min_window_theta_rad: float = 0.05
    max_window_xy_m: float = 5.0
    max_window_theta_rad: float = 0.5
    window_of_pairs: bool = True
    cell_m: float = 0.1
    angle_tolerance_rad: float = 0.04
    offset_tolerance_m: float = 0.15
    overlap_margin_m: float = 0.3
    min_matched_length_m: float = 4.0
    min_matches: int = 4
    min_direction_angle_rad: float = 0.5
    max_ambiguity: float = 0.7
    corridor_closures: bool = True
    max_updates: int = 20
    judge_iterations: int = 10
    judge_relative_tolerance: float = 1e-4
    judge_loop_only: bool = True
    judge_max_pair_chi2: float = float("inf")
    max_correction_chi2: float = float("inf")
    gate_override_after: int = 0
    min_consistent_fraction: float = 0.6
    skip_repeated_rejections: bool = True
    judge_hopeless_after: int = 5
    large_correction_m: float = 0.1
    large_correction_rad: float = 0.01

    def __post_init__(self) -> None:
        _require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        _require(self.judge_iterations >= 1, "judge_iterations must be >= 1")
        _require(self.judge_hopeless_after >= 0, "judge_hopeless_after must be >= 0")
        _require(self.local_keyframes >= 1, "local_keyframes must be >= 1")
        _require(self.max_updates >= 1, "max_updates must be >= 1")
        _require(self.min_matches >= 2, "min_matches must be >= 2")
        for name in (
            "window_xy_per_m",
            "window_theta_per_m",
            "min_window_xy_m",
            "min_window_theta_rad",
            "overlap_margin_m",
            "min_matched_length_m",
            "large_correction_m",
            "large_correction_rad",
        ):
            _nonneg(name, getattr(self, name))
        for name in (
            "max_window_xy_m",
            "max_window_theta_rad",
            "cell_m",
            "angle_tolerance_rad",
            "offset_tolerance_m",
            "min_direction_angle_rad",
            "judge_relative_tolerance",
        ):
            _pos(name, getattr(self, name))
        _require(0.0 < self.max_ambiguity <= 1.0, "max_ambiguity must be in (0, 1]")
        _require(
            0.0 < self.min_consistent_fraction <= 1.0, "min_consistent_fraction must be in (0, 1]"
        )
        _require(self.judge_max_pair_chi2 > 0.0, "judge_max_pair_chi2 must be > 0 (inf: off)")
        _require(self.max_correction_chi2 > 0.0, "max_correction_chi2 must be > 0 (inf: off)")
        _require(self.gate_override_after >= 0, "gate_override_after must be >= 0")


@dataclass(frozen=True)
class SlamConfig:
    """Everything :class:`slam.graph.LineSlam` needs.

    Attributes
    ----------
    backend : {"batch", "isam2"}
        Online estimator: periodic batch LM over the whole graph, or incremental iSAM2.
    motion, keyframes, association, fusion, solver, isam2
        Sub-configurations.
    prior_sigma_xy_m, prior_sigma_theta_rad : float
        Prior on the first pose (defines the world frame: the first laser pose).
    frontend, tentative, loop_closure
        Registration front end, tentative landmarks, loop closing.
    pose_base_laser : tuple of 3 floats
        Laser pose on the robot base (the mounting): used with the base odometry
        (``laser_odometry = "base"``, or when a scan has no logged laser pose) and to report
        base poses (``output_frame = "base"``).
    mount_source : {"catalog", "config"}
        ``"catalog"``: for a catalogued log whose laser poses lack the recorded mounting, the
        runner (:func:`slam.runner.slam_config_for_log`) sets ``pose_base_laser`` from the
        catalogue, ``laser_odometry = "base"`` and ``output_frame = "base"``; ``"config"``:
        these three are taken as configured.
    laser_odometry : {"logged", "base"}
        ``"logged"``: the laser's odometry is ``Scan.pose_odom_laser`` as logged (else the base
        odometry composed with the mounting); ``"base"``: always
        ``Scan.pose_odom_base ∘ pose_base_laser`` (logs whose laser pose lacks the mounting).
    output_frame : {"laser", "base"}
        Frame of the trajectory in the result (``summary.json`` says which).
    odometry_sign : {"velocity", "logged"}
        ``"velocity"``: when a CARMEN log is read for an estimator (the graph, and the EKF
        and the comparisons, which read this setting too), pose increments that moved forwards
        while the ``ODOM`` speed ``tv`` was negative are negated
        (:func:`slam.io.carmen.velocity_signed_scans`; fr079 logs reversing as forward
        motion); logs whose ``tv`` is never negative are unchanged.  ``"logged"``: the
        odometry poses as logged.
    line_model_sigma_r_m, line_model_sigma_alpha_rad : float
        Model error added to every measured line's covariance, at the segment's mid-point
        (:func:`slam.frontend.anchored.model_error_covariance`); 0 for simulated data whose
        fit covariances are exact.
    min_line_points : int
        Lines with fewer supporting points are ignored (neither matched nor new landmarks).
    min_line_length_m : float
        Shorter lines are ignored (default 0.3 m: shorter stubs have so uncertain an angle that
        their gates admit unrelated stubs; see ``docs/graph.md``).
    pose_covariances : {"keyframes", "none"}
        Compute the marginal covariance of every keyframe pose for the result (non-keyframe
        scans get their keyframe's covariance compounded with the odometry noise).
    map_segment_gap_m : float
        In the output map, observed pieces of a line closer than this are one segment.
    map_min_observations : int
        Landmarks with fewer line measurements stay in the graph but are left out of the
        output map (one-off lines: clutter, lines fitted across depth jumps).
    """

    backend: Literal["batch", "isam2"] = "isam2"
    motion: MotionNoiseConfig = field(default_factory=MotionNoiseConfig)
    keyframes: KeyframeConfig = field(default_factory=KeyframeConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    isam2: Isam2Config = field(default_factory=Isam2Config)
    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    tentative: TentativeConfig = field(default_factory=TentativeConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    prior_sigma_xy_m: float = 1e-4
    prior_sigma_theta_rad: float = 1e-5
    pose_base_laser: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_source: Literal["catalog", "config"] = "catalog"
    laser_odometry: Literal["logged", "base"] = "logged"
    output_frame: Literal["laser", "base"] = "laser"
    odometry_sign: Literal["velocity", "logged"] = "velocity"
    line_model_sigma_r_m: float = 0.02
    line_model_sigma_alpha_rad: float = 0.01
    min_line_points: int = 5
    min_line_length_m: float = 0.3
    pose_covariances: Literal["keyframes", "none"] = "keyframes"
    map_segment_gap_m: float = 0.3
    map_min_observations: int = 3

    def __post_init__(self) -> None:
        _require(
            self.backend in ("batch", "isam2"), f"backend must be batch or isam2: {self.backend!r}"
        )
        _pos("prior_sigma_xy_m", self.prior_sigma_xy_m)
        _pos("prior_sigma_theta_rad", self.prior_sigma_theta_rad)
        _require(
            len(self.pose_base_laser) == 3 and all(math.isfinite(v) for v in self.pose_base_laser),
            "pose_base_laser must be three finite numbers (x, y, theta)",
        )
        _require(self.laser_odometry in ("logged", "base"), "laser_odometry must be logged or base")
        _require(
            self.mount_source in ("catalog", "config"), "mount_source must be catalog or config"
        )
        _require(self.output_frame in ("laser", "base"), "output_frame must be laser or base")
        _require(
            self.odometry_sign in ("velocity", "logged"),
            "odometry_sign must be velocity or logged",
        )
        _nonneg("line_model_sigma_r_m", self.line_model_sigma_r_m)
        _nonneg("line_model_sigma_alpha_rad", self.line_model_sigma_alpha_rad)
        _require(self.min_line_points >= 2, "min_line_points must be >= 2")
        _nonneg("min_line_length_m", self.min_line_length_m)
        _require(
            self.pose_covariances in ("keyframes", "none"),
            "pose_covariances must be keyframes or none",
        )
        _nonneg("map_segment_gap_m", self.map_segment_gap_m)
        _require(self.map_min_observations >= 1, "map_min_observations must be >= 1")

    @property
    def prior_cov(self) -> FloatArray:
        """Covariance of the first-pose prior."""
        return np.diag(
            [self.prior_sigma_xy_m**2, self.prior_sigma_xy_m**2, self.prior_sigma_theta_rad**2]
        )
