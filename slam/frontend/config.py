"""Configuration of the front end.

Registration and relocalisation (``[slam.frontend]``), tentative landmarks
(``[slam.tentative]``) and loop closing (``[slam.loop_closure]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slam.frontend.registration import RegistrationConfig
from slam.frontend.scan_match import ScanMatchConfig
from slam.validate import nonneg, positive, require

__all__ = ["FrontendConfig", "LoopClosureConfig", "RelocalisationConfig", "TentativeConfig"]


@dataclass(frozen=True)
class RelocalisationConfig:
    """Relocalisation: the front end's fallback when the registration pairs too few lines.

    When the registration pairs too few lines, or its correction is not consistent with the
    odometry, the scan's lines are searched for in the local map over a window around the
    prediction with :func:`slam.frontend.loop_closure.search_loop_closure` (same meaning of the
    fields as in :class:`LoopClosureConfig`), and the registration is run again from the
    correction found, with the same prior (so the same consistency test applies).

    Attributes
    ----------
    enabled : bool
        Relocalise at all (off: a keyframe whose registration fails rests on odometry).
    min_matched_fraction : float
        Relocalise when the registration paired fewer than this fraction of the lines (and
        fewer than all of them).
    window_sigmas : float
        Half-widths of the search window around the odometry prediction, in standard
        deviations of the prediction's covariance (translation: its larger eigenvalue).  The
        refinement of a hypothesis also takes the window as the σ of a weak zero-mean prior on
        the correction, so that a scan pairing only parallel lines cannot slide it along them.
    min_window_xy_m, min_window_theta_rad : float
        Least half-widths (m, rad): the search's own resolution.
    cell_m, angle_tolerance_rad, offset_tolerance_m, overlap_margin_m : float
        The search's vote grid (m), match tolerances (rad, m) and largest gap between matched
        segments (m); the same meaning as in :class:`LoopClosureConfig`.
    min_matched_length_m, min_matches, min_direction_angle_rad, min_cross_length_m, max_ambiguity
        Least matched length (m), least number of pairs, least angle between two matched
        directions (rad), least matched length across the dominant direction (m), largest
        runner-up score as a fraction of the winner's; as in :class:`LoopClosureConfig`, with
        looser defaults for the short, local search.
    corridor_closures : bool
        Accept a correction whose paired lines are all parallel (as in
        :class:`LoopClosureConfig`).
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "window_xy_m": "replaced by window_sigmas (and min_window_xy_m): the window follows "
        "the prediction's covariance",
        "window_theta_rad": "replaced by window_sigmas (and min_window_theta_rad)",
    }

    enabled: bool = True
    min_matched_fraction: float = 0.5
    window_sigmas: float = 3.0
    min_window_xy_m: float = 0.2
    min_window_theta_rad: float = 0.1
    cell_m: float = 0.05
    angle_tolerance_rad: float = 0.04
    offset_tolerance_m: float = 0.1
    overlap_margin_m: float = 0.3
    min_matched_length_m: float = 1.0
    min_matches: int = 2
    min_direction_angle_rad: float = 0.5
    min_cross_length_m: float = 0.5
    max_ambiguity: float = 0.8
    corridor_closures: bool = True

    def __post_init__(self) -> None:
        require(0.0 <= self.min_matched_fraction <= 1.0, "min_matched_fraction in [0, 1]")
        for name in (
            "window_sigmas",
            "min_window_xy_m",
            "min_window_theta_rad",
            "cell_m",
            "angle_tolerance_rad",
            "offset_tolerance_m",
            "min_direction_angle_rad",
        ):
            positive(name, getattr(self, name))
        nonneg("overlap_margin_m", self.overlap_margin_m)
        nonneg("min_matched_length_m", self.min_matched_length_m)
        nonneg("min_cross_length_m", self.min_cross_length_m)
        require(self.min_matches >= 2, "min_matches must be >= 2")
        require(0.0 < self.max_ambiguity <= 1.0, "max_ambiguity must be in (0, 1]")


@dataclass(frozen=True)
class FrontendConfig:
    """Registration of each keyframe's lines against the local map (initial guess, association).

    The local map is every landmark (graph or tentative) whose extent is within
    ``association.max_range_m`` of the predicted pose and whose drift relative to the robot is
    small: the drift since the landmark was last seen is the sum of the front end's step
    covariances since then (:mod:`slam.line_slam.drift`;
    :func:`slam.models.anchored.drift_covariance` adds it to the landmark's covariance); beyond
    ``max_drift_xy_m`` it is left to loop closing.  Every registration's correction of the
    odometry prediction must be consistent with the prediction's covariance
    (``consistency_probability``; :mod:`slam.line_slam.front_end`).

    Attributes
    ----------
    registration : RegistrationConfig
        Gates, iterations, kernel of :func:`slam.frontend.register_lines`.
    relocalisation : RelocalisationConfig
        Fallback search when the registration pairs too few lines.
    scan_matching : ScanMatchConfig
        Dense matching of each keyframe's points against the previous keyframe's
        (:mod:`slam.frontend.scan_match`): an accepted match is the keyframe's prediction,
        and where it finds the odometry's heading slipped it replaces that step's odometry
        factor.
    prior_sigma_xy_m, prior_sigma_theta_rad : float
        Added (in quadrature) to the odometry covariance of the prediction used as the
        registration's prior, so that a bad odometry step (wheel slip) can be corrected.
    drift_xy_per_m, drift_theta_per_m : float
        The systematic part of the front end's drift, per metre of path (m/m, rad/m; added in
        quadrature to the accumulated step covariances, :mod:`slam.line_slam.drift`).
    consistency_probability : float
        A registration (or relocalisation) whose correction of the prediction lies beyond this
        quantile of χ² (degrees of freedom: the directions its lines constrain) is not used.
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
    scan_matching: ScanMatchConfig = field(default_factory=ScanMatchConfig)
    prior_sigma_xy_m: float = 0.02
    prior_sigma_theta_rad: float = 0.01
    drift_xy_per_m: float = 0.01
    drift_theta_per_m: float = 0.002
    consistency_probability: float = 0.999
    max_drift_xy_m: float = 0.2
    landmark_sigma_r_m: float = 0.005
    landmark_sigma_alpha_rad: float = 0.002
    pose_factor: Literal["none", "inflated"] = "none"
    pose_factor_inflation: float = 4.0

    def __post_init__(self) -> None:
        require(
            0.0 < self.consistency_probability < 1.0, "consistency_probability must be in (0, 1)"
        )
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
    end's drift limit, within reach) over a window from the drift since they were seen
    (:mod:`slam.line_slam.drift`): rotation candidates from the histogram of line angle
    differences, translation by a vote of line-pair constraints on a grid, then verification
    (segment overlap, matched length,
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
    window_sigmas : float
        The search window around the current pose, in standard deviations of the drift since
        the old landmarks were last seen (:mod:`slam.line_slam.drift`; translation and heading
        separately).
    min_window_xy_m, min_window_theta_rad : float
        Least half-widths (m, rad): the search's own resolution.
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
        Least number of matched line pairs of a hypothesis (two fix a correction).
    min_direction_angle_rad : float
        Matched lines must include two directions at least this far apart.
    min_cross_length_m : float
        A hypothesis in two directions must match at least this length (m) of lines across
        the dominant direction (the lines that fix the position along it); evidence is counted
        in metres of matched wall, not in lines.
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
    consistency_probability : float
        With ``confirmations`` of 1 or more, two hypotheses agree when their pairwise
        consistency (the cycle through the front end's chains, Mangelson et al. 2018; the
        drift from :mod:`slam.line_slam.drift`) lies within this quantile of χ².  Each
        hypothesis' distance from the front end's own trajectory (the relative pose the front
        end estimated between the two keyframes, free of loop closures) under the drift
        between them is logged as ``correction_chi2``; it is not a gate: closures that the
        final trajectory confirms score far beyond its quantile on the catalogued logs (on
        ACES up to ~150 against 16.3; the drift model is not that accurate).
    consistent_with_accepted : bool
        A hypothesis must be consistent with every closure accepted within the last
        ``local_keyframes`` keyframes: the cycle through the two hypotheses and the front
        end's chains between their keyframes (as for ``confirmations``), with each
        hypothesis' own covariance instead of the tolerances (its paired lines',
        :func:`slam.frontend.loop_closure.correction_covariance`, plus the drift across the
        local submap that it lays onto the old lines), within the ``consistency_probability``
        quantile of χ² (the directions along a corridor left out).  One that is not is turned
        away before the judge (``gated``, ``contradicts``): right after a closure the two
        places are tied, and another hypothesis between them that moves the robot by more
        than its pairs and the drift allow matched other walls (a parallel wall a few
        decimetres off along a corridor).
    judge_max_f : float
        A judged closure is rejected when it raises the loop's cost per merged degree of
        freedom more than this many times the loop's cost per residual degree of freedom before
        (an F statistic of the merge against the graph's own residual level: a right closure
        spreads the drift along the loop, a wrong one strains it where it binds).
    judge_robust_cost : bool
        A second chance for a closure rejected only by that F statistic: it is accepted when
        all of its merged pairs are explained, a hypothesis found at another keyframe within
        the last ``local_keyframes`` agrees with it (pairwise consistency at
        ``consistency_probability``), and the statistic is within ``judge_max_f`` with the
        loop's cost counted as the judge's solver minimises it: each line factor ``2 ρ(‖e‖)``
        of the solver's robust kernel (``solver.robust_kernel``, ``robust_k``), not its χ².
        A line that the front end associated wrongly inside the loop, which the right closure
        leaves hundreds of σ off, then weighs as the outlier the solver treats it as, not as
        evidence against the closure.  The log has ``f_statistic_robust`` and
        ``agreeing_hypotheses``.
    judge_alone_both_costs : bool
        A closure that no recent hypothesis agrees with (``agreeing_hypotheses`` 0: judged on
        its own, e.g. late with ``judge_unconfirmed``) is accepted only when its F statistic
        is within ``judge_max_f`` in both costs: in χ² and in the solver's robust cost
        (``f_statistic_robust``; with ``judge_robust_cost``, else both are χ² and this adds
        nothing).  The judge's solve minimises the robust cost, and a merge that raises it
        beyond the limit has not been explained by it, even where the loop's χ² falls; with
        no second hypothesis to vouch for the closure, both readings must accept it.  One
        that another hypothesis agrees with keeps the robust second chance.
    judge_negative_f_robust : bool
        A closure whose F statistic in χ² is negative (the loop's χ² fell when it was merged)
        is accepted only when its F statistic in the solver's robust cost is within
        ``judge_max_f`` as well (with ``judge_robust_cost``, else both are χ² and this adds
        nothing).  Both hypotheses are solved in
        the robust cost (``judge_from_converged``), so their χ² can differ in either
        direction; a fall says the solve with the closure left the χ² optimum behind, not
        that the closure explains the loop better, and the comparison is then read in the
        cost that was minimised.
    confirmations : int
        How many hypotheses found at other keyframes within the last ``local_keyframes`` must
        agree with one before it is judged at once (0: none, every hypothesis is judged when
        it is found; with 1 or more and without ``judge_unconfirmed`` a hypothesis is never
        accepted on its own, so a revisit must be recognised twice).  The defaults (1, with
        ``judge_unconfirmed``, ``judge_replaced`` and ``agreement_same_place``) judge every
        hypothesis that passes the gates: at once when another of the same revisit agrees
        with it, else a few keyframes late, before any later hypothesis that contradicts it
        (``docs/real-logs.md``, Pipeline step 8 and Opt-in settings).
    agreement_same_place : bool
        Two hypotheses agree (for ``confirmations`` and the robust second chance of
        ``judge_robust_cost``) only when their old keyframes, like their current ones, lie
        within ``local_keyframes`` of each other: the same revisit.  The pairwise test runs
        through the front end's chain between the two old keyframes, whose drift grows with
        its length; between places far apart along it nearly any two hypotheses pass.
    judge_unconfirmed : bool
        With ``confirmations`` of 1 or more, a hypothesis that awaits confirmation is judged on
        its own by the next attempt that finds no new hypothesis (or at the end of the run),
        so a revisit seen once is still closed, a few keyframes late.  A newer hypothesis
        that does not agree with it takes its place: the two cannot both be right (pairwise
        consistency, PCM, Mangelson et al. 2018), and the newer one waits in turn; the older
        one is then never judged, unless ``judge_replaced``.  The log marks such a judgement
        ``judged_late``, with the keyframe of the attempt that judged it
        (``judged_at_keyframe``).
    judge_replaced : bool
        With ``judge_unconfirmed``, the waiting hypothesis that a newer one replaces is judged
        on its own by the attempt that found the newer one, instead of being dropped.  If it
        is accepted the newer one, which does not agree with it, is dropped (its log entry's
        reason says so); if not, the newer one waits.  So every hypothesis that passes the
        gate is judged, at once when another agrees with it, else a few keyframes late.
    reconsider_keyframes : int or None
        An accepted closure (None, the default: whenever it was accepted; a number: at most that
        many keyframes ago) is reconsidered when a later hypothesis is rejected that agrees with
        the front end's own trajectory better than that closure did (``correction_chi2`` within
        the ``consistency_probability`` quantile and below the closure's), disagrees with the
        closure (pairwise, as ``confirmations``) and has more recent hypotheses agreeing with it
        than the closure had: the closure's merges are undone with the observations added to its
        merged landmarks since, the loops are solved without it, and the hypothesis is judged
        again; if it is accepted the earlier closure stays dropped (its pairs vetoed), else both
        are as before.  0: never.  The larger consistent set wins however late it forms: a wrong
        closure that right hypotheses contradict for tens of keyframes before one of them has
        more agreeing than it had is still dropped.
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
    graph_gate : bool
        Before the judge, the hypothesis is tested against the graph's own estimate of the
        two keyframes' relative pose (:meth:`slam.line_slam.loop_closer.LoopCloser.graph_test`):
        the back end's joint marginal covariance of the two keyframes, scaled by what the
        closures accepted so far measured of it (their χ² under it alone is one to two orders
        of magnitude too large on the real logs; the scale at its upper confidence bound,
        ``consistency_probability``: :meth:`~slam.line_slam.loop_closer.LoopCloser.graph_scale`),
        plus the hypothesis' own
        covariance, within the ``consistency_probability`` quantile of χ² (the direction along
        a corridor left out).  One beyond it is turned away (``gated``, "inconsistent with the
        graph"; the log has ``graph_chi2`` and ``graph_scale``) and counts as a rejection
        (``skip_repeated_rejections``, ``reconsider_keyframes``).  Until the first closure is
        accepted there is no scale and no test.  Not for a reconsidered hypothesis (the graph
        still holds the closure it would replace).
    graph_scale_with_hypotheses : bool
        Opt-in.  ``graph_gate``'s scale is the smaller of the bound from the closures' χ²
        under the graph's covariance alone (the default) and the likelihood bound with each
        closure hypothesis' own covariance counted
        (:meth:`~slam.line_slam.loop_closer.LoopCloser.graph_scale`), which is tighter where
        the hypotheses' covariance explains their errors.
    graph_window : bool
        Opt-in.  Once a closure has been accepted (``graph_gate``'s scale exists), the search
        window is at most ``window_sigmas`` standard deviations of the graph's covariance of
        the relative pose between the current keyframe and the one where the candidate old
        landmarks were last seen (their median; the back end's joint marginal of the two,
        scaled by :meth:`slam.line_slam.loop_closer.LoopCloser.graph_scale`), and at least
        ``min_window_*``; before, and where it is wider, the drift's window.
    judge_from_converged : bool
        The loop is solved without the closure first (the judge's solver, its
        ``judge_iterations``, the same poses freed), and the F statistic's cost before is
        taken there: the closure and its absence are each compared at their own optimum (a
        likelihood-ratio test).  Without it the cost before is the estimate's as the back end
        left it, and whatever the judge's solve gains on the loop without the closure counts
        for the closure.  The closure's judgement starts from that solution.  False: the
        estimate as it is.
    skip_repeated_rejections : bool
        A candidate that repeats a hypothesis judged and rejected during the last
        ``local_keyframes`` keyframes (a correction within twice the angle and offset
        tolerances of it) with no more paired lines than it had is not judged again: no new
        evidence.  (A rejected candidate leaves the graph as it was, so the repeat would be
        judged on the same estimate.)
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "max_chi2_per_factor": "removed (it had no effect; the verdict is judge_* and "
        "min_consistent_fraction): delete the line",
        "window_xy_per_m": "replaced by window_sigmas: the window follows the drift "
        "accumulated from the front end's covariances",
        "window_theta_per_m": "replaced by window_sigmas",
        "max_window_xy_m": "removed: the window is not capped",
        "max_window_theta_rad": "removed: the window is not capped",
        "max_correction_chi2": "replaced by consistency_probability (the correction against the "
        "front end's own trajectory and drift)",
        "gate_override_after": "removed: hypotheses are checked against the front end's own "
        "trajectory, which loop closures do not change; delete the line",
    }

    enabled: bool = True
    interval_keyframes: int = 5
    local_keyframes: int = 20
    window_sigmas: float = 3.0
    min_window_xy_m: float = 0.5
    min_window_theta_rad: float = 0.05
    window_of_pairs: bool = True
    cell_m: float = 0.1
    angle_tolerance_rad: float = 0.04
    offset_tolerance_m: float = 0.15
    overlap_margin_m: float = 0.3
    min_matched_length_m: float = 4.0
    min_matches: int = 2
    min_direction_angle_rad: float = 0.5
    min_cross_length_m: float = 1.0
    max_ambiguity: float = 0.7
    corridor_closures: bool = True
    max_updates: int = 20
    judge_iterations: int = 10
    judge_relative_tolerance: float = 1e-4
    judge_loop_only: bool = True
    judge_max_pair_chi2: float = float("inf")
    consistency_probability: float = 0.999
    confirmations: int = 1
    judge_unconfirmed: bool = True
    judge_replaced: bool = True
    agreement_same_place: bool = True
    consistent_with_accepted: bool = True
    judge_max_f: float = 100.0
    judge_robust_cost: bool = True
    judge_alone_both_costs: bool = True
    judge_negative_f_robust: bool = True
    min_consistent_fraction: float = 0.6
    skip_repeated_rejections: bool = True
    judge_hopeless_after: int = 5
    judge_from_converged: bool = True
    graph_gate: bool = True
    graph_scale_with_hypotheses: bool = False
    graph_window: bool = False
    large_correction_m: float = 0.1
    large_correction_rad: float = 0.01
    reconsider_keyframes: int | None = None

    def __post_init__(self) -> None:
        require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        require(self.judge_iterations >= 1, "judge_iterations must be >= 1")
        require(
            self.reconsider_keyframes is None or self.reconsider_keyframes >= 0,
            "reconsider_keyframes must be >= 0 (or left out: no limit)",
        )
        require(self.judge_hopeless_after >= 0, "judge_hopeless_after must be >= 0")
        require(self.local_keyframes >= 1, "local_keyframes must be >= 1")
        require(self.max_updates >= 1, "max_updates must be >= 1")
        require(self.min_matches >= 2, "min_matches must be >= 2")
        for name in (
            "min_window_xy_m",
            "min_window_theta_rad",
            "overlap_margin_m",
            "min_matched_length_m",
            "min_cross_length_m",
            "large_correction_m",
            "large_correction_rad",
        ):
            nonneg(name, getattr(self, name))
        for name in (
            "window_sigmas",
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
        require(
            0.0 < self.consistency_probability < 1.0, "consistency_probability must be in (0, 1)"
        )
        require(self.confirmations >= 0, "confirmations must be >= 0")
        require(self.judge_max_f > 0.0, "judge_max_f must be > 0")
