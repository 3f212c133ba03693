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
        be passed to :func:`linefit.noise.point_covariances` and :func:`linefit.extract_lines`
        directly (``sigma_range_fn``).
    bearing_error : {"beam", "reading"}
        What the bearing noise ε_φ means for the position of a point *along* its line (it
        makes no difference to ``r``, ``α`` and their covariance).  ``"beam"`` (default): the
        logged bearings are the nominal beam grid and the physical beam deviates by ε_φ, so
        the hit point slides along the surface; ``S`` and endpoint variances are relative to
        the surface point on the nominal ray.  ``"reading"``: the beam hits a fixed point and
        the reported bearing is off by ε_φ (the paper's Eqs. 4-5 taken literally).  See
        :mod:`linefit.covariance`.
    """

    sigma_range_m: float = 0.005
    sigma_bearing_rad: float = 1e-4
    sigma_range_per_m: float = 0.0
    bearing_error: Literal["beam", "reading"] = "beam"

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
        _require(
            self.bearing_error in ("beam", "reading"),
            f"bearing_error must be 'beam' or 'reading', got {self.bearing_error!r}",
        )


@dataclass(frozen=True)
class LineFitConfig:
    """Everything that controls :func:`linefit.extract_lines`.

    The defaults are the values used for every number reported in ``docs/linefit.md``.

    Attributes
    ----------
    noise : SensorNoiseConfig
        Point noise model (Eq. 8).
    grouping : {"hough", "split_merge"}
        How collinear points are grouped before the fit (Sec. IV, or split-and-merge).
    weighted : bool
        True: the paper's maximum-likelihood weighted fit.  False: plain unweighted total least
        squares (for comparison experiments); covariances are then propagated for the
        unweighted estimator (sandwich form).
    alpha_update : {"gauss_newton", "prop2"}
        The α step of the iteration.  ``"prop2"``: Eq. 24 exactly as printed (``δ_S`` measured
        from Prop. 1's ``P_S``-weighted ``S``).  ``"gauss_newton"`` (default): Eq. 24 with
        ``δ_S`` measured from the ``P_R``-weighted centre, which is the exact Gauss-Newton
        step; same numerator, same fixed point (tests check both reach the numerical optimum
        of Eq. 20), 3-5 iterations where ``"prop2"`` needs 15-100 for walls seen off to one
        side.
    max_iterations : int
        Cap on α iterations per fit.
    alpha_tolerance_rad : float
        The iteration stops when every line's ``|δα|`` is below this (rad).
    min_points : int
        Fewest supporting points for a line.  Default 3, the fewest that leave a residual to
        test (two points fix any line): how much wall a line must cover is set in metres
        (``min_length_m``, and the SLAM front end's ``min_line_length_m``), so that the lines
        kept do not depend on the scanner's angular resolution.
    min_length_m : float
        Shortest accepted line (m), total visible length of its segments.
    max_range_m : float or None
        Readings at or above this are "no return" and never enter a fit.  ``extract_lines``
        also takes the scan's own maximum range; the smaller of the two applies.
    outlier_chi2 : float
        A point whose normal residual ``δ_R²/P_R`` (by its own covariance) exceeds this is
        rejected and its line refitted.  Default 10.83, the 99.9 % quantile of χ²₁.
    max_refits : int
        Cap on reject-and-refit rounds.
    min_segment_points : int
        Pieces of a line (between gaps) with fewer points are dropped from it.
    max_missing_beams : int
        A gap of more beams between two neighbouring points of a line starts a new segment
        (and breaks clusters in split-and-merge).
    breakpoint_lambda_rad : float
        Most grazing angle between beam and surface that still counts as one surface
        (adaptive breakpoint of Borges & Aldon); default 10°, i.e. incidence up to 80°.
    breakpoint_sigma : float
        Multiple of σ_d added to the breakpoint distance.
    hough_angle_step_rad, hough_range_step_m : float
        Hough accumulator resolution Δβ (rad) and Δℛ (m); defaults 3° and 10 cm (coarse on
        purpose: each peak is refined by a total-least-squares line, see :mod:`linefit.hough`).
    hough_min_votes : int
        Smallest Hough peak that starts a line (default 3, as ``min_points``).
    hough_gather_m : float
        Points within this distance (m) of a peak's line, then of its refined line, join it.
    hough_max_peaks : int
        Cap on Hough peaks examined per scan.
    hough_recover : bool
        After the Hough lines are fitted, group the points that no line kept by
        split-and-merge and fit those pieces together with the lines (a coarse Hough peak can
        absorb, and then lose, the points of a small face that happens to be collinear with
        other points).  False: the pure Sec. IV grouping.
    split_threshold_m : float
        Split-and-merge: a point farther than ``max(split_threshold_m,
        split_threshold_sigma · σ_d)`` from a piece's chord splits it (m).
    split_threshold_sigma : float
        See ``split_threshold_m``.
    merge_collinear : bool
        After fitting, join lines of the scan whose ``(r, α)`` pass the χ² test
        ``merge_chi2`` into one line with several segments (both groupings).
    merge_chi2 : float
        Threshold of that test (2 dof); default 11.83, the paper's "3σ" (99.73 %).
    """

    noise: SensorNoiseConfig = field(default_factory=SensorNoiseConfig)
    grouping: Literal["hough", "split_merge"] = "hough"
    weighted: bool = True
    alpha_update: Literal["gauss_newton", "prop2"] = "gauss_newton"
    max_iterations: int = 30
    alpha_tolerance_rad: float = 1e-10
    min_points: int = 3
    min_length_m: float = 0.1
    max_range_m: float | None = None
    outlier_chi2: float = 10.83
    max_refits: int = 3
    min_segment_points: int = 3
    max_missing_beams: int = 2
    breakpoint_lambda_rad: float = math.radians(10.0)
    breakpoint_sigma: float = 3.0
    hough_angle_step_rad: float = math.radians(3.0)
    hough_range_step_m: float = 0.1
    hough_min_votes: int = 3
    hough_gather_m: float = 0.05
    hough_max_peaks: int = 60
    hough_recover: bool = True
    split_threshold_m: float = 0.03
    split_threshold_sigma: float = 4.0
    merge_collinear: bool = True
    merge_chi2: float = 11.83

    def __post_init__(self) -> None:
        _require(
            isinstance(self.noise, SensorNoiseConfig),
            f"noise must be a SensorNoiseConfig, got {type(self.noise).__name__}",
        )
        _require(
            self.grouping in ("hough", "split_merge"),
            f"grouping must be 'hough' or 'split_merge', got {self.grouping!r}",
        )
        _require(
            self.alpha_update in ("gauss_newton", "prop2"),
            f"alpha_update must be 'gauss_newton' or 'prop2', got {self.alpha_update!r}",
        )
        _require(isinstance(self.weighted, bool), "weighted must be true or false")
        _require(isinstance(self.merge_collinear, bool), "merge_collinear must be true or false")
        _require(isinstance(self.hough_recover, bool), "hough_recover must be true or false")
        for name, low in (
            ("min_points", 2),
            ("max_iterations", 1),
            ("max_refits", 0),
            ("min_segment_points", 1),
            ("max_missing_beams", 0),
            ("hough_min_votes", 2),
            ("hough_max_peaks", 1),
        ):
            value = getattr(self, name)
            _require(
                isinstance(value, int) and not isinstance(value, bool) and value >= low,
                f"{name} must be an integer >= {low}, got {value!r}",
            )
        for name in (
            "alpha_tolerance_rad",
            "outlier_chi2",
            "hough_angle_step_rad",
            "hough_range_step_m",
            "hough_gather_m",
            "split_threshold_m",
            "merge_chi2",
        ):
            value = getattr(self, name)
            _require(
                math.isfinite(value) and value > 0.0,
                f"{name} must be a positive number, got {value!r}",
            )
        for name in ("min_length_m", "breakpoint_sigma", "split_threshold_sigma"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0.0, f"{name} must be >= 0, got {value!r}")
        _require(
            0.0 < self.breakpoint_lambda_rad <= 0.5 * math.pi,
            f"breakpoint_lambda_rad must be in (0, π/2], got {self.breakpoint_lambda_rad!r}",
        )
        _require(
            self.hough_angle_step_rad <= 0.5,
            f"hough_angle_step_rad must be <= 0.5 rad, got {self.hough_angle_step_rad!r}",
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
