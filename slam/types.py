"""Plain data types passed between the layers of ``slam``.

Naming: a pose ``pose_a_b`` is the pose of frame ``b`` expressed in frame ``a`` (it maps points
from ``b`` to ``a``), stored as ``(x, y, theta)`` in metres and radians.  Frames: ``world`` (the
map), ``odom`` (the odometry's own drifting frame), ``base`` (the robot), ``laser`` (the
scanner).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Scan"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Scan:
    """One laser scan with the odometry that came with it.

    Attributes
    ----------
    index : int
        0-based position among the log's laser scans, in file order (never re-sorted: Intel's
        timestamps go backwards now and then).
    timestamp : float
        Time stamp (s) exactly as in the log (CARMEN: the ``ipc_timestamp`` field).
    ranges : ndarray, shape (n,)
        Measured ranges (m), as logged (max-range, zero and non-finite readings included).
    bearings : ndarray, shape (n,)
        Beam angles (rad) in the laser frame.
    max_range_m : float
        Readings ``>= max_range_m`` are "no return" and are not measurements of a surface.
    pose_odom_base : ndarray, shape (3,) or None
        Odometry pose of the robot base at this scan ``(x, y, theta)``, if the log has one.
    pose_odom_laser : ndarray, shape (3,) or None
        Pose of the laser in the odometry frame as logged (CARMEN ``FLASER x y theta``,
        ``ROBOTLASER1 laser_x laser_y laser_theta``), if the log has one.
    source : str
        Where the scan came from, for messages (``"path:line"``).
    """

    index: int
    timestamp: float
    ranges: FloatArray
    bearings: FloatArray
    max_range_m: float = np.inf
    pose_odom_base: FloatArray | None = None
    pose_odom_laser: FloatArray | None = None
    source: str = ""

    @property
    def n_beams(self) -> int:
        """Number of beams in the scan."""
        return int(self.ranges.shape[0])

    def valid_mask(self) -> NDArray[np.bool_]:
        """True for readings that are measurements of a surface (finite, > 0, < max range)."""
        r = self.ranges
        return np.isfinite(r) & (r > 0.0) & (r < self.max_range_m)

    def points_xy(self) -> FloatArray:
        """Cartesian points ``(n, 2)`` in the laser frame for all beams (invalid ones too)."""
        return np.stack(
            [self.ranges * np.cos(self.bearings), self.ranges * np.sin(self.bearings)], 1
        )
