"""Configuration of the front end.

Registration and relocalisation (``[slam.frontend]``), tentative landmarks
(``[slam.tentative]``) and loop closing (``[slam.loop_closure]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slam.frontend.registration import RegistrationConfig
from slam.validate import nonneg, positive, require

__all__ = ["FrontendConfig", "LoopClosureConfig", "RelocalisationConfig", "TentativeConfig"]


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
        Relocalise at all (off: a keyframe whose registration fails rests on odometry).
    min_matched_fraction : float
        Relocalise when the registration paired fewer than this fraction of the lines (and
        fewer than all of them).
    window_xy_m, window_theta_rad : float
        Half-widths of the search window around the odometry prediction (m, rad).  The
        refinement of a hypothesis also takes them as the σ of a weak zero-mean prior on the
        correction, so that a scan pairing only parallel lines cannot slide it along them.
    cell_m, angle_tolerance_rad, offset_tolerance_m, overlap_margin_m : float
        The search's vote grid (m), match tolerances (rad, m) and largest gap between matched
        segments (m); the same meaning as in :class:`LoopClosureConfig`.
    min_matched_length_m, min_matches, min_direction_angle_rad, max_ambiguity : float
        Least matched length (m), least number of pairs, least angle between two matched
        directions (rad), largest runner-up score as a fraction of the winner's; as in
        :class:`LoopClosureConfig`, with looser defaults for the short, local search.
    corridor_closures : bool
        Accept a correction whose paired lines are all parallel (as in
        :class:`LoopClosureConfig`).
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
        require(0.0 <= self.min_matched_fraction <= 1.0, "min_matched_fraction in [0, 1]")
        for name in (
            "window_xy_m",
            "window_theta_rad",
            "cell_m",
            "angle_tolerance_rad",
            "offset_tolerance_m",
            "min_direction_angle_rad",
        ):
            positive(name, getattr(self, name))
        nonneg("overlap_margin_m", self.overlap_margin_m)
        nonneg("min_matched_length_m", self.min_matched_length_m)
        require(self.min_matches >= 2, "min_matches must be >= 2")
        require(0.0 < self.max_ambiguity <= 1.0, "max_ambiguity must be in (0, 1]")


@dataclass(frozen=True)
class FrontendConfig:
    """Registration of each keyframe's lines against the local map (initial guess, association).

    The local map is every landmark (graph or tentative) whose extent is within
    ``association.max_range_m`` of the predicted pose and whose drift relative to the robot is
    small: a landmark last seen ``d`` metres of path ago has drifted by about
    ``σ_xy = drift_xy_per_m·d`` and ``σ_θ = drift_theta_per_m·d``
    (:func:`slam.models.anchored.drift_covariance` adds this to its covariance); beyond
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
        Factor (≥ 1) on the registration's covariance for ``pose_factor = "inflated"``.
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
            nonneg(name, getattr(self, name))
        positive("max_drift_xy_m", self.max_drift_xy_m)
        require(self.pose_factor in ("none", "inflated"), "pose_factor must be none or inflated")
        require(self.pose_factor_inflation >= 1.0, "pose_factor_inflation must be >= 1")


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
        require(self.min_observations >= 1, "min_observations must be >= 1")
        require(self.max_age_keyframes >= 1, "max_age_keyframes must be >= 1")


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
        Search for loop closures at all (off: the front end alone, registration,
        relocalisation and fusion, carries the estimate).
    interval_keyframes : int
        Search every this many keyframes.
    local_keyframes : int
        The local submap is the landmarks seen during the last this many keyframes; also the
        memory (in keyframes) of rejected and gated hypotheses, and how far before the old
        landmarks' last sighting the judged loop starts.
    window_xy_per_m, window_theta_per_m : float
        Search half-widths per metre of path since the old landmarks were seen (m/m, rad/m).
    min_window_xy_m, min_window_theta_rad, max_window_xy_m, max_window_theta_rad : float
        Bounds on those half-widths (m, rad).  ``max_window_xy_m`` (5 m) covers the front
        end's drift between closures: with loop closing off, against the default run, the
        translation error over any 10-200 m of path stays below 3.3 m on Intel, ACES and fr079
        (``scripts/front_end_drift.py``).  Wider windows mostly admit aliases in
        buildings whose rooms repeat (fr079).
    window_of_pairs : bool
        A hypothesis must lie within the window of the old lines it pairs (the median of
        their windows), not only within the search window (that of the oldest line in
        reach): where the local lines match walls seen 20 m ago, a 9 m correction is not
        allowed because a wall in reach was seen 200 m ago.
    cell_m : float
        Translation grid of the vote (m).
    angle_tolerance_rad, offset_tolerance_m : float
        A transformed local line matches an old line within these (rad, m).
    overlap_margin_m : float
        Largest gap along the line between matched segments (m).
    min_matched_length_m : float
        Matched local lines must add up to this length (m).
    min_matches : int
        Least number of matched line pairs of a hypothesis.
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
        stops (it is then rejected: acceptance needs ``max(min_matches − 1, 2)``).  On Intel
        and fr079 no accepted closure had fewer than 2 explained pairs after 5
        linearisations, while about half of the rejected ones had at most 1.  0: judgements
        always run their ``judge_iterations``.
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
        require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        require(self.judge_iterations >= 1, "judge_iterations must be >= 1")
        require(self.judge_hopeless_after >= 0, "judge_hopeless_after must be >= 0")
        require(self.local_keyframes >= 1, "local_keyframes must be >= 1")
        require(self.max_updates >= 1, "max_updates must be >= 1")
        require(self.min_matches >= 2, "min_matches must be >= 2")
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
            nonneg(name, getattr(self, name))
        for name in (
            "max_window_xy_m",
            "max_window_theta_rad",
            "cell_m",
            "angle_tolerance_rad",
            "offset_tolerance_m",
            "min_direction_angle_rad",
            "judge_relative_tolerance",
        ):
            positive(name, getattr(self, name))
        require(0.0 < self.max_ambiguity <= 1.0, "max_ambiguity must be in (0, 1]")
        require(
            0.0 < self.min_consistent_fraction <= 1.0, "min_consistent_fraction must be in (0, 1]"
        )
        require(self.judge_max_pair_chi2 > 0.0, "judge_max_pair_chi2 must be > 0 (inf: off)")
        require(self.max_correction_chi2 > 0.0, "max_correction_chi2 must be > 0 (inf: off)")
        require(self.gate_override_after >= 0, "gate_override_after must be >= 0")
