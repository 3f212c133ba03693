"""Laser geometry: where the beams of a scan point, when the log itself does not say.

CARMEN's old ``FLASER``/``RLASER`` lines carry only the ranges.  Their beam angles come from
the dataset's manifest (``datasets/catalog.toml``) or, failing that, from CARMEN's own rule
(``carmen_laser_guess_fov``): the first beam at −90° and

=========  ==================  ===============
beams      step                field of view
=========  ==================  ===============
180        1° (π/180)          179°
360        0.5° (π/360)        179.5°
181, 361   π/(n−1)             180°
other n    π/(n−1)             180°
=========  ==================  ===============

Messages that carry their own geometry (``ROBOTLASER1``, ``RAWLASER1..4``) use it instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError

__all__ = ["DEFAULT_MAX_RANGE_M", "LaserGeometry", "beam_bearings", "guess_laser_geometry"]

#: Range (m) at and above which a reading of a log without a manifest is taken as "no return".
#: SICK LMS 2xx in CARMEN logs report no return as 81.83 m or 81.91 m (and the bags of the
#: public logs give ``range_max`` = 80 m); 80 m classifies both as no return.
DEFAULT_MAX_RANGE_M = 80.0


@dataclass(frozen=True)
class LaserGeometry:
    """Beam layout and range limit of a laser scanner.

    Attributes
    ----------
    first_angle_rad : float
        Bearing of beam 0 in the laser frame (rad).
    step_rad : float
        Angle between consecutive beams (rad, > 0; beam ``i`` is at ``first + i·step``).
    n_beams : int or None
        Beams per scan; ``None`` accepts any count.  A line with another count is malformed.
    max_range_m : float
        Readings ``>= max_range_m`` are "no return" (see :attr:`slam.types.Scan.max_range_m`).
    pose_base_laser : tuple of float
        Mounting of the laser on the robot base ``(x, y, θ)`` (m, m, rad).  Carried as data;
        the CARMEN reader does not apply it (``Scan.pose_odom_laser`` is the logged one).
    """

    first_angle_rad: float
    step_rad: float
    n_beams: int | None = None
    max_range_m: float = DEFAULT_MAX_RANGE_M
    pose_base_laser: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not math.isfinite(self.first_angle_rad):
            raise ConfigError(f"first_angle_rad must be finite, got {self.first_angle_rad!r}")
        if not (math.isfinite(self.step_rad) and self.step_rad > 0.0):
            raise ConfigError(f"step_rad must be a positive angle, got {self.step_rad!r}")
        if self.n_beams is not None and self.n_beams < 1:
            raise ConfigError(f"n_beams must be >= 1, got {self.n_beams!r}")
        if not self.max_range_m > 0.0:
            raise ConfigError(f"max_range_m must be > 0, got {self.max_range_m!r}")
        if len(self.pose_base_laser) != 3 or not all(map(math.isfinite, self.pose_base_laser)):
            raise ConfigError(f"pose_base_laser must be 3 finite numbers: {self.pose_base_laser}")

    def bearings(self, n_beams: int) -> NDArray[np.float64]:
        """Read-only bearings (rad) of ``n_beams`` beams (shared between calls)."""
        return beam_bearings(self.first_angle_rad, self.step_rad, n_beams)


@lru_cache(maxsize=64)
def beam_bearings(first_angle_rad: float, step_rad: float, n_beams: int) -> NDArray[np.float64]:
    """``first + i·step`` for ``i = 0..n-1`` as a cached, read-only array."""
    out = first_angle_rad + step_rad * np.arange(n_beams, dtype=np.float64)
    out.flags.writeable = False
    return out


def guess_laser_geometry(n_beams: int, max_range_m: float = DEFAULT_MAX_RANGE_M) -> LaserGeometry:
    """CARMEN's ``carmen_laser_guess_fov`` rule for a scan of ``n_beams`` (first beam −90°)."""
    if n_beams == 180 or n_beams == 360:
        step = math.pi / n_beams
    elif n_beams > 1:
        step = math.pi / (n_beams - 1)
    else:
        step = math.pi
    return LaserGeometry(-math.pi / 2.0, step, n_beams, max_range_m)
