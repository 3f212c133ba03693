"""Configuration of the EKF-SLAM baseline (frozen dataclass, TOML table ``[ekf]``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from slam.association import AssociationConfig
from slam.errors import ConfigError
from slam.models.motion import MotionNoiseConfig

__all__ = ["AssociationConfig", "EkfConfig", "MotionNoiseConfig"]


def _probability(name: str, value: float) -> None:
    if not (isinstance(value, float | int) and 0.0 < value < 1.0):
        raise ConfigError(f"ekf.{name} must be a probability in (0, 1), got {value!r}")


@dataclass(frozen=True)
class EkfConfig:
    """Settings of :class:`slam.ekf.EkfSlam`.

    Attributes
    ----------
    odometry : MotionNoiseConfig
        Motion model of the prediction: the graph back-end's class
        (:class:`slam.models.motion.MotionNoiseConfig`) with its defaults, so both estimators
        assume the same odometry noise unless told otherwise.
    association : AssociationConfig
        Data association: the graph's class and code (:mod:`slam.association`: χ² gate on the
        joint covariance of pose and landmark, segment-overlap test with the pose-dependent
        margin, candidates within ``max_range_m``, nearest neighbour or JCBB) with its
        defaults, so both estimators gate alike unless told otherwise.
    new_landmark_probability : float
        An unmatched line starts a new landmark only if no overlapping landmark passes the χ²
        gate at this (looser) probability; otherwise it is ambiguous and dropped.
    segment_gap_m : float
        Seen pieces of a landmark closer than this (m) are merged (``map.json`` segments).
    update_min_distance_m, update_min_angle_rad : float
        Update policy (the graph's keyframe policy): a scan is predicted to and its lines are
        used only when the odometry since the last update (straight-line distance, heading
        change) reaches this distance or this angle; 0 and 0 use every scan.  Other scans get
        the last update's pose composed with their odometry offset and its covariance
        compounded with the motion noise (as the graph's non-keyframe scans).
    max_landmarks : int
        Guard on the ``O(n²)`` cost per update (``n = 3 + 2·landmarks``).
    on_max_landmarks : {"stop", "freeze"}
        When the map is full: ``"stop"`` ends the run at that scan (the result says where and
        why); ``"freeze"`` keeps filtering with the existing landmarks and starts no new ones.
    max_runtime_s : float or None
        Wall-clock budget; when exceeded the run stops at that scan (recorded in the result).
    update_impl : {"sparse", "filterpy"}
        ``"sparse"``: Joseph form on the columns ``H`` touches, ``O(n² m)``.  ``"filterpy"``:
        ``filterpy.kalman.ExtendedKalmanFilter.update`` on the dense state, ``O(n³)`` (the
        reference; same numbers).
    jacobians : {"current", "first-estimates", "observability-constrained"}
        Where the filter linearises.  ``"current"``: the standard EKF, every Jacobian at the
        estimates of the moment.  ``"first-estimates"``: the first-estimates Jacobian EKF
        (FEJ-EKF; Huang, Mourikis & Roumeliotis 2008): the propagation Jacobian from the
        propagated poses (``x̂_{k+1|k} − x̂_{k|k−1}`` in place of ``x̂_{k+1|k} − x̂_{k|k}``) and
        the measurement Jacobians at the propagated pose and each landmark's first estimate,
        so that the linearised model, like the nonlinear one, carries no information on the
        global position and heading (three unobservable directions; the standard EKF's
        linearised model observes all three with line landmarks, and this spurious
        information is what makes it over-confident over long runs; ``tests/test_ekf_fej.py``).
        ``"observability-constrained"``: an OC-EKF (the observability constraint of Huang,
        Mourikis & Roumeliotis 2010, met by projecting the Jacobian as Hesch, Kottas, Bowman &
        Roumeliotis 2014 do): the FEJ-EKF's propagation Jacobian, and each measurement's
        Jacobian at the current estimates projected onto the closest one that sees none of
        the three directions (taken at the propagated pose and the landmarks' first
        estimates): the FEJ-EKF's property without linearising at a first estimate that may
        be far off.
        Innovations, gating and landmark merging use the current estimates in every case.
    merge_landmarks : bool
        Fuse two landmarks that pass the χ² test on their joint marginal and overlap (an exact
        EKF constraint update ``l_i − l_j = 0`` followed by deleting ``l_j``).  Tested for the
        landmarks observed or created since the last test against all others.  This is how a
        wall first seen in two pieces (farther apart than ``association.overlap_margin_m``)
        becomes one landmark once the pieces meet.
    merge_probability : float
        χ² probability (2 dof) of the landmark merge test.
    merge_every_n_updates : int
        How often the merge test runs (in measurement updates).
    initial_pose_sigma : tuple of float
        Standard deviations ``(σ_x, σ_y, σ_θ)`` (m, m, rad) of the first pose; zeros anchor the
        world frame at it.
    min_landmark_observations : int
        Landmarks seen fewer times are left out of ``map.json`` (they stay in the state).
    min_line_points, min_line_length_m : int, float
        Lines (``linefit.Line``) with fewer supporting points or a shorter visible length (m,
        gaps excluded) are ignored, as in the graph back-end (a ``LineSet`` is used as given).
    blas_threads : int
        BLAS threads the runners allow while filtering (:mod:`slam.ekf.threads`); 0 leaves the
        library default.  One is fastest on small shared machines.
    line_sigma_extra : tuple of float
        Model-error floor ``(σ_offset, σ_angle)`` (m, rad) added to every line's covariance,
        specified at the segment's mid-point
        (:func:`slam.models.anchored.model_error_covariance`, the graph's function):
        real walls are not ideal lines and real range noise is not the fit's model.  The
        default (0.02 m, 0.01 rad) is the graph back-end's ``line_model_sigma_*``; zero trusts
        the fit's covariance as it is (right for simulated data whose fit covariances are
        exact, e.g. the consistency study).
    """

    odometry: MotionNoiseConfig = field(default_factory=MotionNoiseConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    new_landmark_probability: float = 0.99999
    segment_gap_m: float = 0.3
    update_min_distance_m: float = 0.2
    update_min_angle_rad: float = 0.15
    max_landmarks: int = 2000
    on_max_landmarks: Literal["stop", "freeze"] = "stop"
    max_runtime_s: float | None = None
    update_impl: Literal["sparse", "filterpy"] = "sparse"
    jacobians: Literal["current", "first-estimates", "observability-constrained"] = "current"
    merge_landmarks: bool = True
    merge_probability: float = 0.999
    merge_every_n_updates: int = 1
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    min_landmark_observations: int = 3
    line_sigma_extra: tuple[float, float] = (0.02, 0.01)
    blas_threads: int = 1
    min_line_points: int = 3
    min_line_length_m: float = 0.3

    def __post_init__(self) -> None:
        if not isinstance(self.association, AssociationConfig):
            raise ConfigError(
                f"ekf.association must be an AssociationConfig, got {self.association!r}"
            )
        for name in ("new_landmark_probability", "merge_probability"):
            _probability(name, getattr(self, name))
        if self.new_landmark_probability < self.association.gate_probability:
            raise ConfigError(
                "ekf.new_landmark_probability must be >= ekf.association.gate_probability"
            )
        if not (math.isfinite(self.segment_gap_m) and self.segment_gap_m >= 0.0):
            raise ConfigError(f"ekf.segment_gap_m must be >= 0, got {self.segment_gap_m}")
        for name in ("update_min_distance_m", "update_min_angle_rad"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ConfigError(f"ekf.{name} must be >= 0, got {v!r}")
        if self.max_landmarks < 1:
            raise ConfigError(f"ekf.max_landmarks must be >= 1, got {self.max_landmarks}")
        if self.on_max_landmarks not in ("stop", "freeze"):
            raise ConfigError(
                f"ekf.on_max_landmarks must be 'stop' or 'freeze', got {self.on_max_landmarks!r}"
            )
        if self.max_runtime_s is not None and not self.max_runtime_s > 0.0:
            raise ConfigError(f"ekf.max_runtime_s must be > 0, got {self.max_runtime_s}")
        if self.update_impl not in ("sparse", "filterpy"):
            raise ConfigError(
                f"ekf.update_impl must be 'sparse' or 'filterpy', got {self.update_impl!r}"
            )
        if self.jacobians not in ("current", "first-estimates", "observability-constrained"):
            raise ConfigError(
                "ekf.jacobians must be 'current', 'first-estimates' or "
                f"'observability-constrained', got {self.jacobians!r}"
            )
        if self.merge_every_n_updates < 1:
            raise ConfigError("ekf.merge_every_n_updates must be >= 1")
        if len(self.initial_pose_sigma) != 3 or not all(
            math.isfinite(s) and s >= 0.0 for s in self.initial_pose_sigma
        ):
            raise ConfigError(
                f"ekf.initial_pose_sigma must be three numbers >= 0, got {self.initial_pose_sigma}"
            )
        if len(self.line_sigma_extra) != 2 or not all(
            math.isfinite(v) and v >= 0.0 for v in self.line_sigma_extra
        ):
            raise ConfigError(
                f"ekf.line_sigma_extra must be two numbers >= 0, got {self.line_sigma_extra}"
            )
        if self.min_line_points < 2:
            raise ConfigError(f"ekf.min_line_points must be >= 2, got {self.min_line_points}")
        if not (math.isfinite(self.min_line_length_m) and self.min_line_length_m >= 0.0):
            raise ConfigError(f"ekf.min_line_length_m must be >= 0, got {self.min_line_length_m}")
        if self.blas_threads < 0:
            raise ConfigError(f"ekf.blas_threads must be >= 0, got {self.blas_threads}")
        if self.min_landmark_observations < 1:
            raise ConfigError("ekf.min_landmark_observations must be >= 1")
