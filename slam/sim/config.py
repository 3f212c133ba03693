"""Configuration of a simulation (frozen dataclasses, validated, TOML round trip).

``config.toml`` of ``lineslam simulate`` is :class:`SimConfig` dumped to TOML: the scalar keys
``world`` and ``seed`` and one table per component (``[laser]``, ``[noise]``, ``[odometry]``,
``[trajectory]``, ``[relations]``).  Missing keys take their defaults; unknown keys are an
error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from linefit.errors import ConfigError
from linefit.tomlconfig import dump_toml, load_toml

__all__ = [
    "LaserConfig",
    "LaserNoiseConfig",
    "OdometryNoiseConfig",
    "RelationsConfig",
    "SimConfig",
    "TrajectoryConfig",
]


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


def _finite_at_least(value: float, low: float, name: str, unit: str = "") -> None:
    _require(
        isinstance(value, int | float) and math.isfinite(value) and value >= low,
        f"{name} must be a finite number >= {low:g}{unit}, got {value!r}",
    )


def _finite_positive(value: float, name: str, unit: str = "") -> None:
    _require(
        isinstance(value, int | float) and math.isfinite(value) and value > 0.0,
        f"{name} must be a finite number > 0{unit}, got {value!r}",
    )


@dataclass(frozen=True)
class LaserConfig:
    """Scanner geometry: beam ``i`` points at ``first_angle_deg + i·step_deg`` (laser frame).

    The default is the SICK LMS-200 of the CARMEN logs (180 beams, −90°, 1° steps; CARMEN's
    ``carmen_laser_guess_fov`` rule for 180 beams).  :meth:`paper` gives the 720 points per scan
    of the paper's experiments (0.25° over 180°).

    Attributes
    ----------
    n_beams : int
        Beams per scan.
    first_angle_deg : float
        Bearing of beam 0 (degrees, laser frame, counter-clockwise from the laser's x axis).
    step_deg : float
        Angle between consecutive beams (degrees, > 0); ``n_beams · step_deg ≤ 360``.
    max_range_m : float
        Hits at or beyond this range, and beams that hit nothing, read ``max_range_m`` ("no
        return", as a SICK reports one).  The default, 80 m, is the range limit a CARMEN reader
        assumes for ``FLASER`` logs without a manifest; with another value the log is written
        as ``ROBOTLASER1`` (which carries it).
    pose_base_laser : tuple of float
        Mounting ``(x, y, θ)`` of the laser on the robot base (m, m, rad).
    range_decimals : int
        Digits after the point of the ranges in the log (4: 0.1 mm, far below σ_d).
    """

    n_beams: int = 180
    first_angle_deg: float = -90.0
    step_deg: float = 1.0
    max_range_m: float = 80.0
    pose_base_laser: tuple[float, float, float] = (0.0, 0.0, 0.0)
    range_decimals: int = 4

    def __post_init__(self) -> None:
        _require(
            isinstance(self.n_beams, int) and self.n_beams >= 1,
            f"n_beams must be an integer >= 1, got {self.n_beams!r}",
        )
        _require(
            isinstance(self.first_angle_deg, int | float) and math.isfinite(self.first_angle_deg),
            f"first_angle_deg must be finite, got {self.first_angle_deg!r}",
        )
        _finite_positive(self.step_deg, "step_deg", " deg")
        _require(
            self.n_beams * self.step_deg <= 360.0 + 1e-9,
            f"n_beams * step_deg = {self.n_beams * self.step_deg:g} deg exceeds a full turn",
        )
        _finite_positive(self.max_range_m, "max_range_m", " m")
        _require(
            len(self.pose_base_laser) == 3
            and all(isinstance(v, int | float) and math.isfinite(v) for v in self.pose_base_laser),
            f"pose_base_laser must be 3 finite numbers (x, y, theta), got {self.pose_base_laser!r}",
        )
        _require(
            isinstance(self.range_decimals, int) and 1 <= self.range_decimals <= 9,
            f"range_decimals must be an integer in 1..9, got {self.range_decimals!r}",
        )

    @classmethod
    def paper(cls) -> LaserConfig:
        """720 beams, 0.25° apart over 180° (the scans of the paper's Section VI)."""
        return cls(n_beams=720, first_angle_deg=-90.0, step_deg=0.25)

    def bearings_rad(self) -> NDArray[np.float64]:
        """Beam angles (rad) in the laser frame, shape ``(n_beams,)``."""
        return np.deg2rad(self.first_angle_deg + self.step_deg * np.arange(self.n_beams))


@dataclass(frozen=True)
class LaserNoiseConfig:
    """The paper's range-sensor noise (Section II, Eqs. 3-4).

    The true ray is cast at ``Φ + ε_φ`` and reported at ``Φ``; the reading is the true range
    plus ``ε_d``.  ``ε_φ ~ N(0, σ_φ²)``, ``ε_d ~ N(0, σ_d²)`` with ``σ_d = sigma_range_m +
    sigma_range_per_m · D`` (``D`` the true range), independent per beam.  Zero disables a term.

    Attributes
    ----------
    sigma_range_m : float
        σ_d (m); default 5 mm (SICK LMS-200, the paper's value).
    sigma_bearing_rad : float
        σ_φ (rad); default 1e-4.  Section II assumes ``ε_φ ≪ 1°``: at most 0.01 rad.
    sigma_range_per_m : float
        Range-proportional part of σ_d (m per m); default 0.
    """

    sigma_range_m: float = 0.005
    sigma_bearing_rad: float = 1e-4
    sigma_range_per_m: float = 0.0

    def __post_init__(self) -> None:
        _finite_at_least(self.sigma_range_m, 0.0, "sigma_range_m", " m")
        _finite_at_least(self.sigma_bearing_rad, 0.0, "sigma_bearing_rad", " rad")
        _require(
            self.sigma_bearing_rad <= 0.01,
            f"sigma_bearing_rad must be <= 0.01 rad (the model assumes ε_φ ≪ 1°), "
            f"got {self.sigma_bearing_rad!r}",
        )
        _finite_at_least(self.sigma_range_per_m, 0.0, "sigma_range_per_m")


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Noise of the odometry, applied to the relative motion between consecutive scans.

    A true motion ``(dx, dy, dθ)`` (base frame of the earlier pose, ``Δs = |(dx, dy)|``) is
    read as::

        dx' = (1 + scale_bias)·dx + n_x          n_x, n_y ~ N(0, sigma_trans_per_m² · Δs)
        dy' = (1 + scale_bias)·dy + n_y
        dθ' = (1 + rot_scale_bias)·dθ + heading_drift_rad_per_m·Δs + n_θ
              n_θ ~ N(0, sigma_rot_per_rad² · |dθ| + sigma_rot_per_m² · Δs)

    Variances grow linearly with distance and angle, so the statistics of the integrated
    odometry do not depend on the scan spacing: ``sigma_trans_per_m`` is the standard
    deviation (m, per axis) of the translation error after 1 m of travel, ``sigma_rot_per_m``
    the heading error (rad) after 1 m, ``sigma_rot_per_rad`` the heading error (rad) after
    turning 1 rad.  The odometry poses are the integrated noisy motions, starting at the true
    first pose (the odometry frame coincides with the world frame at the first scan).

    Attributes
    ----------
    sigma_trans_per_m : float
        m / √m.
    sigma_rot_per_rad : float
        rad / √rad.
    sigma_rot_per_m : float
        rad / √m.
    scale_bias : float
        Systematic relative error of the travelled distance (0.01: odometry reads 1 % long).
    rot_scale_bias : float
        Systematic relative error of rotations.
    heading_drift_rad_per_m : float
        Systematic heading drift (rad per metre travelled; positive: counter-clockwise).
    """

    sigma_trans_per_m: float = 0.02
    sigma_rot_per_rad: float = 0.02
    sigma_rot_per_m: float = 0.005
    scale_bias: float = 0.0
    rot_scale_bias: float = 0.0
    heading_drift_rad_per_m: float = 0.0

    def __post_init__(self) -> None:
        _finite_at_least(self.sigma_trans_per_m, 0.0, "sigma_trans_per_m")
        _finite_at_least(self.sigma_rot_per_rad, 0.0, "sigma_rot_per_rad")
        _finite_at_least(self.sigma_rot_per_m, 0.0, "sigma_rot_per_m")
        for name in ("scale_bias", "rot_scale_bias"):
            value = getattr(self, name)
            _require(
                isinstance(value, int | float) and math.isfinite(value) and abs(value) < 0.5,
                f"{name} must be a finite fraction in (-0.5, 0.5), got {value!r}",
            )
        _require(
            isinstance(self.heading_drift_rad_per_m, int | float)
            and math.isfinite(self.heading_drift_rad_per_m)
            and abs(self.heading_drift_rad_per_m) < 0.5,
            f"heading_drift_rad_per_m must be finite and below 0.5 rad/m in magnitude, "
            f"got {self.heading_drift_rad_per_m!r}",
        )


@dataclass(frozen=True)
class TrajectoryConfig:
    """How a waypoint polyline becomes timed poses.

    The robot follows the polyline at ``speed_m_s``; each corner is rounded by a circular arc of
    ``turn_radius_m`` (smaller where the neighbouring legs are short), driven at most at
    ``max_turn_rate_rad_s`` (the speed drops on tight arcs; a corner with no room for an arc is
    turned on the spot).  A scan is taken every ``scan_spacing_m / speed_m_s`` seconds (the scan
    rate is fixed; on straights the scans are ``scan_spacing_m`` apart).

    Attributes
    ----------
    speed_m_s : float
        Cruise speed (m/s).
    scan_spacing_m : float
        Distance between scans at cruise speed (m).
    turn_radius_m : float
        Corner radius (m).
    max_turn_rate_rad_s : float
        Largest yaw rate (rad/s).
    start_time_s : float
        Time stamp of the first scan (s); stamps are rounded to µs.
    """

    speed_m_s: float = 0.4
    scan_spacing_m: float = 0.3
    turn_radius_m: float = 0.4
    max_turn_rate_rad_s: float = 0.6
    start_time_s: float = 1_000_000_000.0

    def __post_init__(self) -> None:
        _finite_positive(self.speed_m_s, "speed_m_s", " m/s")
        _require(self.speed_m_s <= 5.0, f"speed_m_s must be <= 5 m/s, got {self.speed_m_s!r}")
        _finite_positive(self.scan_spacing_m, "scan_spacing_m", " m")
        _finite_at_least(self.turn_radius_m, 0.0, "turn_radius_m", " m")
        _finite_positive(self.max_turn_rate_rad_s, "max_turn_rate_rad_s", " rad/s")
        _finite_at_least(self.start_time_s, 0.0, "start_time_s", " s")
        _require(
            self.start_time_s < 1e10, f"start_time_s must be < 1e10 s, got {self.start_time_s!r}"
        )

    @property
    def scan_period_s(self) -> float:
        """Time between scans (s)."""
        return self.scan_spacing_m / self.speed_m_s


@dataclass(frozen=True)
class RelationsConfig:
    """Which scan pairs get a ground-truth relation (``relations.txt``).

    As in Kümmerle et al.'s files, most relations join scans close in time, plus some longer
    ones:

    * **short**: every ``short_stride``-th scan ``i`` is paired with the first later scan that
      is at least ``d`` metres further along the path, for each ``d`` in
      ``short_distances_m``;
    * **revisits**: up to ``n_revisits`` pairs (drawn with the seed) of scans that are at least
      ``revisit_min_path_m`` apart along the path but within ``revisit_max_distance_m`` and
      ``revisit_max_angle_deg`` of each other (the robot passes the same place again; the
      scans overlap, as when a loop closes);
    * **random**: ``n_random`` pairs of scans drawn uniformly (long-range consistency).

    Attributes
    ----------
    short_stride : int
    short_distances_m : tuple of float
    n_revisits : int
    revisit_min_path_m : float
    revisit_max_distance_m : float
    revisit_max_angle_deg : float
    n_random : int
    """

    short_stride: int = 2
    short_distances_m: tuple[float, ...] = (1.0, 3.0)
    n_revisits: int = 60
    revisit_min_path_m: float = 10.0
    revisit_max_distance_m: float = 2.0
    revisit_max_angle_deg: float = 60.0
    n_random: int = 20

    def __post_init__(self) -> None:
        _require(
            isinstance(self.short_stride, int) and self.short_stride >= 1,
            f"short_stride must be an integer >= 1, got {self.short_stride!r}",
        )
        for d in self.short_distances_m:
            _finite_positive(d, "short_distances_m entries", " m")
        for name in ("n_revisits", "n_random"):
            value = getattr(self, name)
            _require(
                isinstance(value, int) and value >= 0,
                f"{name} must be an integer >= 0, got {value!r}",
            )
        _finite_positive(self.revisit_min_path_m, "revisit_min_path_m", " m")
        _finite_positive(self.revisit_max_distance_m, "revisit_max_distance_m", " m")
        _finite_positive(self.revisit_max_angle_deg, "revisit_max_angle_deg", " deg")


@dataclass(frozen=True)
class SimConfig:
    """Everything ``lineslam simulate`` needs to reproduce a simulated log bit for bit.

    Attributes
    ----------
    world : str
        A named world (:data:`slam.sim.worlds.WORLD_NAMES`) or a path to a ``world.json``.
    seed : int
        Seed of every random draw (laser noise, odometry noise, relation choice each get their
        own independent stream derived from it).
    laser : LaserConfig
    noise : LaserNoiseConfig
    odometry : OdometryNoiseConfig
    trajectory : TrajectoryConfig
    relations : RelationsConfig
    """

    world: str = "loop"
    seed: int = 0
    laser: LaserConfig = field(default_factory=LaserConfig)
    noise: LaserNoiseConfig = field(default_factory=LaserNoiseConfig)
    odometry: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    relations: RelationsConfig = field(default_factory=RelationsConfig)

    def __post_init__(self) -> None:
        _require(
            isinstance(self.world, str) and self.world.strip() != "",
            f"world must be a world name or a path, got {self.world!r}",
        )
        _require(
            isinstance(self.seed, int) and not isinstance(self.seed, bool) and self.seed >= 0,
            f"seed must be an integer >= 0, got {self.seed!r}",
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> SimConfig:
        """Load a configuration written by :meth:`to_toml` (or by hand)."""
        return load_toml(cls, path)

    def to_toml(self, path: str | Path) -> None:
        """Write the full configuration (defaults included) to ``path``."""
        dump_toml(self, path, header="lineslam simulate configuration; reload with --config")

    def with_sensor_noise(
        self, sigma_d: float | None = None, sigma_phi: float | None = None
    ) -> SimConfig:
        """Copy with σ_d (``--sigma-d``) and/or σ_φ (``--sigma-phi``) replaced."""
        noise = self.noise
        if sigma_d is not None:
            noise = replace(noise, sigma_range_m=sigma_d)
        if sigma_phi is not None:
            noise = replace(noise, sigma_bearing_rad=sigma_phi)
        return replace(self, noise=noise)
