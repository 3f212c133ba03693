"""A planar trajectory: time stamps and poses, the unit that is written, read and evaluated."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import InputError

__all__ = ["Trajectory"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Poses ``(x, y, θ)`` at time stamps, in file (or scan) order, never re-sorted.

    Attributes
    ----------
    timestamps : ndarray, shape (n,)
        Time stamps (s), as in the log.
    poses : ndarray, shape (n, 3)
        ``pose_world_frame`` (m, m, rad), ``frame`` as the producer says (laser or base).
    """

    timestamps: FloatArray
    poses: FloatArray

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64)
        p = np.asarray(self.poses, dtype=np.float64)
        if t.ndim != 1:
            raise InputError(f"timestamps must be 1-D, got shape {t.shape}")
        if p.shape != (t.shape[0], 3):
            raise InputError(f"poses must have shape ({t.shape[0]}, 3), got {p.shape}")
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            raise InputError("trajectory contains NaN or infinite values")
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "poses", p)

    @classmethod
    def from_arrays(cls, timestamps: ArrayLike, poses: ArrayLike) -> Trajectory:
        """Build from anything array-like (validated)."""
        return cls(np.asarray(timestamps, dtype=np.float64), np.asarray(poses, dtype=np.float64))

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])
