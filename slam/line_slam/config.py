"""Configuration of :class:`slam.line_slam.LineSlam`.

The ``[slam]`` table of :class:`slam.config.RunConfig` and its own steps' tables
(``[slam.keyframes]``, ``[slam.fusion]``); the front end's and the back-end's tables are
defined beside their code (:mod:`slam.frontend.config`, :mod:`slam.graph.config`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from slam.association import AssociationConfig
from slam.frontend.config import (
    FrontendConfig,
    LoopClosureConfig,
    RelocalisationConfig,
    TentativeConfig,
)
from slam.graph.config import Isam2Config, SolverConfig
from slam.models.motion import MotionNoiseConfig
from slam.validate import nonneg, positive, require

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
        nonneg("min_distance_m", self.min_distance_m)
        nonneg("min_angle_rad", self.min_angle_rad)


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
        Pre-filter: pairs whose normals differ by more (rad, mod π) are not tested.
    max_distance_m : float
        Pre-filter: largest distance (m) between one landmark's extent mid-point and the other
        line.
    retest_growth : float
        A pair that failed the test is tested again once its landmarks have this many times the
        measurements (together) they had then.
    audit_max_median_chi2 : float
        A merge (fusion or loop closure) is undone when, some keyframes later, the median
        whitened squared residual of either side's line factors exceeds this (χ²₂ 99 %: 9.21);
        fusion never merges an undone pair again.

    During the run, two landmarks whose last sightings are further apart in drift than the
    front end's reach (``frontend.max_drift_xy_m``) are not fused but left to loop closing,
    which verifies a whole submap and rejects ambiguous matches: after metres of drift a wall
    can land on its neighbour (rooms along a corridor repeat), and a wrong fusion binds the
    drifted estimate to the wrong place.  The final round over the whole map
    (:meth:`LineSlam.optimize`) has no such limit.
    """

    RENAMED_KEYS: ClassVar[dict[str, str]] = {
        "max_path_gap_m": "removed: fusion compares the drift between the two landmarks' last "
        "sightings with frontend.max_drift_xy_m; delete the line"
    }

    enabled: bool = True
    interval_keyframes: int = 10
    gate_probability: float = 0.9973
    max_gap_m: float = 0.3
    max_angle_rad: float = 0.2
    max_distance_m: float = 0.5
    retest_growth: float = 2.0
    audit_max_median_chi2: float = 9.21

    def __post_init__(self) -> None:
        require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        require(self.retest_growth >= 1.0, "retest_growth must be >= 1")
        require(0.0 < self.gate_probability < 1.0, "gate_probability must be in (0, 1)")
        nonneg("max_gap_m", self.max_gap_m)
        positive("max_angle_rad", self.max_angle_rad)
        positive("max_distance_m", self.max_distance_m)
        positive("audit_max_median_chi2", self.audit_max_median_chi2)


@dataclass(frozen=True)
class SlamConfig:
    """Everything :class:`slam.line_slam.LineSlam` needs.

    The log's scanner, laser mounting, odometry and output frame are the ``[scanner]`` table
    (:class:`slam.inputs.ScannerConfig`); an older ``config.toml`` with those keys in
    ``[slam]`` is migrated on loading (:func:`slam.inputs.migrate_slam_keys`).

    Attributes
    ----------
    backend : {"batch", "isam2"}
        Online estimator: periodic batch LM over the whole graph, or incremental iSAM2.
    motion, keyframes, association, fusion, solver, isam2
        Sub-configurations.
    prior_sigma_xy_m, prior_sigma_theta_rad : float
        Standard deviations (m, rad) of the prior on the first pose (it defines the world
        frame: the first laser pose).
    frontend, tentative, loop_closure
        Registration front end, tentative landmarks, loop closing.
    line_model_error : {"estimated", "fixed"}
        ``"estimated"`` (default): the model error added to every measured line's covariance
        is estimated during the run from the residuals of the landmarks seen many times
        (:mod:`slam.line_slam.line_noise`; first after 20 keyframes, then every 50 and at the
        end; the line factors are re-weighted, and the back-end restarted, when an estimate
        moves by more than 20 %): simulated walls get about zero, real walls what their
        residuals show.  The estimate is in ``summary.json`` (``line_model_error``).
        ``"fixed"``: the configured values below throughout.
    line_model_sigma_r_m, line_model_sigma_alpha_rad : float
        Model error (m, rad) added to every measured line's covariance, at the segment's
        mid-point (:func:`slam.models.anchored.model_error_covariance`): real walls are not
        the fit's straight lines.  With ``line_model_error = "estimated"`` (the default) the
        values used until the first estimate.
    line_pass_error : {"estimated", "off"}
        ``"estimated"`` (default): the observations of one pass along a wall share an error
        of their own (:mod:`slam.line_slam.passes`): estimated at the end of the run from how
        far the passes along the same walls disagree, and, where it is not zero, each pass of
        a wall seen in several passes becomes a landmark linked to the wall for the
        covariances (``trajectory_covariance.txt``, the landmarks' and ``graph.g2o``; the
        estimate is not changed).  With fewer than 20 pairs of passes there is no estimate
        and the covariances are the back-end's.  ``summary.json`` ``line_pass_error``.
        ``"off"``: every observation's error is independent of the others'.
    line_pass_gap_s : float
        Observations of a wall this far apart in time (s) or more are separate passes.
    odometry_calibration : {"off", "estimated", "mounting"}
        ``"estimated"``: the odometry's persistent error (translation scale, turn gain, heading
        drift per metre) is estimated during the run from the registrations that pin a
        keyframe down, the laser's unstated mounting as with ``"mounting"``, and both are
        taken out of every later step of the log's odometry before the front end and the graph
        use it (:class:`slam.line_slam.odometry_calibration.OdometryAndMountingCalibrator`;
        ``summary.json`` ``odometry_calibration``).  ``"mounting"`` (default): where the laser
        sits in the frame whose motion the odometry reports (a lever arm the log does not
        state, on top of any mounting it does or the catalogue records: every turn moves such
        a laser sideways), estimated from the graph's estimate of every keyframe step and
        applied once significant (:class:`slam.line_slam.odometry_calibration.
        MountingEstimator`); until then, and on a log with fewer than 30 turning keyframe
        steps, the odometry is used as with ``"off"``.  ``"off"``: the odometry's steps are
        used as logged (with the stated mounting), with the random-walk noise of ``motion``.
    min_line_points : int
        Lines with fewer supporting points are ignored (neither matched nor new landmarks).
        Default 3, the fewest with a residual: how much wall a usable line covers is
        ``min_line_length_m``, in metres, whatever the scanner's angular resolution.
    min_line_length_m : float
        Shorter lines are ignored (default 0.3 m: shorter stubs have so uncertain an angle that
        their gates admit unrelated stubs; see ``docs/graph.md``).
    pose_covariances : {"keyframes", "none"}
        Compute the marginal covariance of every keyframe pose for the result (non-keyframe
        scans get their keyframe's covariance compounded with the odometry noise).
    map_segment_gap_m : float
        In the output map, observed pieces of a line closer than this (m) are one segment.
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
    line_model_error: Literal["estimated", "fixed"] = "estimated"
    line_model_sigma_r_m: float = 0.02
    line_model_sigma_alpha_rad: float = 0.01
    line_pass_error: Literal["estimated", "off"] = "estimated"
    line_pass_gap_s: float = 30.0
    odometry_calibration: Literal["off", "estimated", "mounting"] = "mounting"
    min_line_points: int = 3
    min_line_length_m: float = 0.3
    pose_covariances: Literal["keyframes", "none"] = "keyframes"
    map_segment_gap_m: float = 0.3
    map_min_observations: int = 3

    def __post_init__(self) -> None:
        require(
            self.backend in ("batch", "isam2"), f"backend must be batch or isam2: {self.backend!r}"
        )
        positive("prior_sigma_xy_m", self.prior_sigma_xy_m)
        positive("prior_sigma_theta_rad", self.prior_sigma_theta_rad)
        nonneg("line_model_sigma_r_m", self.line_model_sigma_r_m)
        nonneg("line_model_sigma_alpha_rad", self.line_model_sigma_alpha_rad)
        require(self.min_line_points >= 2, "min_line_points must be >= 2")
        nonneg("min_line_length_m", self.min_line_length_m)
        require(
            self.pose_covariances in ("keyframes", "none"),
            "pose_covariances must be keyframes or none",
        )
        require(
            self.line_model_error in ("estimated", "fixed"),
            "line_model_error must be estimated or fixed",
        )
        nonneg("map_segment_gap_m", self.map_segment_gap_m)
        require(
            self.line_pass_error in ("estimated", "off"),
            f"line_pass_error must be estimated or off: {self.line_pass_error!r}",
        )
        positive("line_pass_gap_s", self.line_pass_gap_s)
        require(
            self.odometry_calibration in ("off", "estimated", "mounting"),
            "odometry_calibration must be off, estimated or mounting: "
            f"{self.odometry_calibration!r}",
        )
        require(self.map_min_observations >= 1, "map_min_observations must be >= 1")

    @property
    def prior_cov(self) -> FloatArray:
        """Covariance of the first-pose prior."""
        return np.diag(
            [self.prior_sigma_xy_m**2, self.prior_sigma_xy_m**2, self.prior_sigma_theta_rad**2]
        )
