"""Configuration of per-scan line extraction (frozen dataclasses, validated, TOML round trip)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from linefit.errors import ConfigError
from linefit.tomlconfig import dump_toml, load_toml

__all__ = ["LineFitConfig", "SensorNoiseConfig"]


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


@dataclass(frozen=True)
class SensorNoiseConfig:
    """Range-sensor noise model of the paper's Section II (Eq. 8).

    Attributes
    ----------
    sigma_range_m : float
        Standard deviation σ_d of the range noise ε_d (m).  Default: SICK LMS-200, 5 mm.
    sigma_bearing_rad : float
        Standard deviation σ_φ of the bearing noise ε_φ (rad).  Default: 1e-4 rad.
    sigma_range_per_m : float
        Range-dependent part of σ_d: ``σ_d(d) = sigma_range_m + sigma_range_per_m · d``.
        Zero (the default) gives the paper's constant σ_d.  Arbitrary ``σ_d(d)`` functions can
        be passed to :func:`linefit.noise.point_covariances` directly.
    """

    sigma_range_m: float = 0.005
    sigma_bearing_rad: float = 1e-4
    sigma_range_per_m: float = 0.0

    def __post_init__(self) -> None:
        _require(
            math.isfinite(self.sigma_range_m) and self.sigma_range_m > 0.0,
            f"sigma_range_m must be a positive number of metres, got {self.sigma_range_m!r}",
        )
        _require(
            math.isfinite(self.sigma_bearing_rad) and self.sigma_bearing_rad >= 0.0,
            f"sigma_bearing_rad must be >= 0 rad, got {self.sigma_bearing_rad!r}",
        )
        _require(
            math.isfinite(self.sigma_range_per_m) and self.sigma_range_per_m >= 0.0,
            f"sigma_range_per_m must be >= 0, got {self.sigma_range_per_m!r}",
        )


@dataclass(frozen=True)
class LineFitConfig:
    """Everything that controls :func:`linefit.extract_lines`.

    Attributes
    ----------
    noise : SensorNoiseConfig
        Point noise model (Eq. 8).
    grouping : {"hough", "split_merge"}
        How collinear points are grouped before the fit (Sec. IV, or split-and-merge).
    weighted : bool
        True: the paper's maximum-likelihood weighted fit.  False: plain unweighted total least
        squares (for comparison experiments); covariances are then propagated for the
        unweighted estimator.
    min_points : int
        Fewest supporting points for a line.
    min_length_m : float
        Shortest accepted segment (m).
    max_range_m : float or None
        Readings at or above this are "no return" and never enter a fit.  None: use the
        scan's own maximum range (CARMEN logs give it), else no cut.
    """

    noise: SensorNoiseConfig = field(default_factory=SensorNoiseConfig)
    grouping: Literal["hough", "split_merge"] = "hough"
    weighted: bool = True
    min_points: int = 5
    min_length_m: float = 0.1
    max_range_m: float | None = None

    def __post_init__(self) -> None:
        _require(
            self.grouping in ("hough", "split_merge"),
            f"grouping must be 'hough' or 'split_merge', got {self.grouping!r}",
        )
        _require(self.min_points >= 2, f"min_points must be >= 2, got {self.min_points!r}")
        _require(
            math.isfinite(self.min_length_m) and self.min_length_m >= 0.0,
            f"min_length_m must be >= 0, got {self.min_length_m!r}",
        )
        _require(
            self.max_range_m is None or (self.max_range_m > 0 and math.isfinite(self.max_range_m)),
            f"max_range_m must be positive, got {self.max_range_m!r}",
        )

    @classmethod
    def from_toml(cls, path: str | Path, section: str | None = None) -> LineFitConfig:
        """Load from a TOML file (optionally one of its tables, e.g. ``"linefit"``)."""
        return load_toml(cls, path, section)

    def to_toml(self, path: str | Path) -> None:
        """Write this configuration to ``path`` as TOML."""
        dump_toml(self, path, header="lineslam line-extraction configuration (linefit)")
