"""Configuration of map building across poses (the ``[map]`` table of ``config.toml``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError

__all__ = ["MapConfig"]


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


@dataclass(frozen=True)
class MapConfig:
    """Settings of :class:`slam.lines.mapbuilder.MapBuilder` and ``lineslam map``.

    Attributes
    ----------
    gate_probability : float
        Probability of the χ² merge gate on ``(r, α)`` (2 dof).  Default: the paper's 3σ
        (0.9973, χ²₂ = 11.83).
    max_gap_m : float
        Two lines merge only if the gap between their visible extents along the line is at most
        this (m).  Collinear pieces across a door (the paper's Fig. 4) merge; collinear walls of
        different rooms far apart do not.  ``inf`` reproduces the paper (no spatial condition).
    segment_gap_m : float
        Segments of one merged line closer than this (m) are united into one segment; wider gaps
        are kept (a multi-segment line, e.g. a wall broken by a door).
    same_side : bool
        Merge only lines seen from the same side (normals within 90° when each points away from
        the sensor that saw it): the two faces of a thin wall stay two lines.
    pose_sigma_xy_m : float
        Standard deviation (m) of each translation component of a scan's pose in the map frame,
        used as ``P^ij`` in Eq. 31 when the caller gives no pose covariance (``lineslam map``).
    pose_sigma_theta_rad : float
        Standard deviation (rad) of a scan's heading in the map frame (same use).
    merge_within_scan : bool
        First merge collinear pieces of one scan in the sensor frame (no pose uncertainty: the
        pieces share the pose), then merge the result into the map.
    """

    gate_probability: float = 0.9973
    max_gap_m: float = 1.5
    segment_gap_m: float = 0.2
    same_side: bool = True
    pose_sigma_xy_m: float = 0.05
    pose_sigma_theta_rad: float = 0.01
    merge_within_scan: bool = True

    def __post_init__(self) -> None:
        _require(
            0.0 < self.gate_probability < 1.0,
            f"gate_probability must be in (0, 1), got {self.gate_probability!r}",
        )
        _require(
            self.max_gap_m >= 0.0 and not math.isnan(self.max_gap_m),
            f"max_gap_m must be >= 0 (inf allowed), got {self.max_gap_m!r}",
        )
        _require(
            math.isfinite(self.segment_gap_m) and self.segment_gap_m >= 0.0,
            f"segment_gap_m must be >= 0, got {self.segment_gap_m!r}",
        )
        _require(
            math.isfinite(self.pose_sigma_xy_m) and self.pose_sigma_xy_m >= 0.0,
            f"pose_sigma_xy_m must be >= 0, got {self.pose_sigma_xy_m!r}",
        )
        _require(
            math.isfinite(self.pose_sigma_theta_rad) and self.pose_sigma_theta_rad >= 0.0,
            f"pose_sigma_theta_rad must be >= 0, got {self.pose_sigma_theta_rad!r}",
        )

    @property
    def pose_cov(self) -> NDArray[np.float64]:
        """The default pose covariance ``diag(σ_xy², σ_xy², σ_θ²)`` (right perturbation)."""
        return np.diag(
            [self.pose_sigma_xy_m**2, self.pose_sigma_xy_m**2, self.pose_sigma_theta_rad**2]
        )
