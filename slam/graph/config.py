"""Configuration of the factor-graph back-end (frozen dataclasses, validated, TOML round trip).

``SlamConfig`` is the ``[slam]`` table of :class:`slam.config.RunConfig`; its sub-tables are
``[slam.motion]``, ``[slam.keyframes]``, ``[slam.association]``, ``[slam.fusion]``,
``[slam.solver]`` and ``[slam.isam2]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from slam.association import AssociationConfig
from slam.errors import ConfigError

__all__ = [
    "FusionConfig",
    "Isam2Config",
    "KeyframeConfig",
    "MotionNoiseConfig",
    "SlamConfig",
    "SolverConfig",
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
    """

    enabled: bool = True
    interval_keyframes: int = 10
    gate_probability: float = 0.9973
    max_gap_m: float = 0.3
    max_angle_rad: float = 0.2
    max_distance_m: float = 0.5
    retest_growth: float = 2.0

    def __post_init__(self) -> None:
        _require(self.interval_keyframes >= 1, "interval_keyframes must be >= 1")
        _require(self.retest_growth >= 1.0, "retest_growth must be >= 1")
        _require(0.0 < self.gate_probability < 1.0, "gate_probability must be in (0, 1)")
        _nonneg("max_gap_m", self.max_gap_m)
        _pos("max_angle_rad", self.max_angle_rad)
        _pos("max_distance_m", self.max_distance_m)


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
    robust_kernel: Literal["none", "huber", "cauchy"] = "none"
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
    relinearize_threshold : float
        iSAM2's own threshold on the update of a variable (any component, in its tangent
        space) above which the variable is relinearised.
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
    relinearize_skip : int
        iSAM2 checks for variables to relinearise only every this many updates (GTSAM's
        default 10).  Relinearising at every update (1) lets the one-update lag of the block
        rebuilds feed back into the next relinearisation: on long open chains the
        relinearisations then cascade over the whole graph (``docs/graph.md``).
    partial_relinearization_check : bool
        iSAM2's ``enablePartialRelinearizationCheck``: only the top of the tree is checked for
        variables to relinearise (cheap; deep variables may keep large updates).
    """

    relinearize_threshold: float = 0.01
    relin_translation_m: float = 0.0
    relin_angle_rad: float = 0.0
    relin_range_m: float = 0.0
    full_refresh_variables: int = 200
    full_refresh_interval: int = 50
    final_updates: int = 20
    relinearize_skip: int = 10
    partial_relinearization_check: bool = True

    def __post_init__(self) -> None:
        _pos("relinearize_threshold", self.relinearize_threshold)
        _nonneg("relin_translation_m", self.relin_translation_m)
        _nonneg("relin_angle_rad", self.relin_angle_rad)
        _nonneg("relin_range_m", self.relin_range_m)
        _require(self.full_refresh_variables >= 0, "full_refresh_variables must be >= 0")
        _require(self.full_refresh_interval >= 1, "full_refresh_interval must be >= 1")
        _require(self.final_updates >= 0, "final_updates must be >= 0")
        _require(self.relinearize_skip >= 1, "relinearize_skip must be >= 1")


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
    pose_base_laser : tuple of 3 floats
        Laser pose on the robot base, used when a scan has only the base odometry.
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
    prior_sigma_xy_m: float = 1e-4
    prior_sigma_theta_rad: float = 1e-5
    pose_base_laser: tuple[float, float, float] = (0.0, 0.0, 0.0)
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
