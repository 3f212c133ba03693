"""A batch of lines as arrays (one row per line), the form the vectorised code works on."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam.errors import InputError
from slam.geometry import pose_compose

__all__ = ["LineSet"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class LineSet:
    """``K`` lines in one frame, as arrays.

    Attributes
    ----------
    r_alpha : ndarray, shape (K, 2)
        ``(r, α)`` of each line; ``r`` may be negative (signed representation).
    cov : ndarray, shape (K, 2, 2)
        Covariance of ``(r, α)``.
    endpoints : ndarray, shape (K, 2, 2)
        The two extreme endpoints ``[[x1, y1], [x2, y2]]`` of each line's visible extent, in the
        same frame.
    ids : ndarray of int, shape (K,)
        Caller's identifiers (e.g. landmark ids or indices into a scan's line list).
    """

    r_alpha: FloatArray
    cov: FloatArray
    endpoints: FloatArray
    ids: NDArray[np.int64]

    def __post_init__(self) -> None:
        k = np.asarray(self.r_alpha).shape[0] if np.ndim(self.r_alpha) == 2 else -1
        shapes_ok = (
            k >= 0
            and np.shape(self.r_alpha) == (k, 2)
            and np.shape(self.cov) == (k, 2, 2)
            and np.shape(self.endpoints) == (k, 2, 2)
            and np.shape(self.ids) == (k,)
        )
        if not shapes_ok:
            raise InputError(
                "LineSet arrays must have shapes (K,2), (K,2,2), (K,2,2), (K,): got "
                f"{np.shape(self.r_alpha)}, {np.shape(self.cov)}, {np.shape(self.endpoints)}, "
                f"{np.shape(self.ids)}"
            )

    def __len__(self) -> int:
        return int(self.r_alpha.shape[0])

    @classmethod
    def empty(cls) -> LineSet:
        """A set with no lines."""
        return cls(
            np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), np.zeros(0, np.int64)
        )

    @classmethod
    def from_lines(cls, lines: Sequence[Line], ids: Sequence[int] | None = None) -> LineSet:
        """Stack :class:`linefit.Line` objects (sensor frame) into a :class:`LineSet`."""
        if len(lines) == 0:
            return cls.empty()
        r_alpha = np.array([[ln.r, ln.alpha] for ln in lines], dtype=float)
        cov = np.stack([ln.cov[:2, :2] for ln in lines])
        endpoints = np.stack([ln.endpoints for ln in lines])
        id_arr = np.arange(len(lines)) if ids is None else np.asarray(ids)
        return cls(r_alpha, cov, endpoints, id_arr.astype(np.int64))

    def endpoints_in(self, pose_parent_self: FloatArray) -> FloatArray:
        """Endpoints moved into a parent frame given this frame's pose there; shape (K, 2, 2)."""
        pose = np.asarray(pose_parent_self, dtype=float)
        pts = np.concatenate([self.endpoints, np.zeros((len(self), 2, 1))], axis=-1)
        return pose_compose(np.broadcast_to(pose, pts.shape), pts)[..., :2]

    def subset(self, mask_or_index: NDArray[np.bool_] | NDArray[np.intp]) -> LineSet:
        """The lines selected by a boolean mask or an index array."""
        return LineSet(
            self.r_alpha[mask_or_index],
            self.cov[mask_or_index],
            self.endpoints[mask_or_index],
            self.ids[mask_or_index],
        )
