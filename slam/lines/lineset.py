"""A batch of lines as arrays (one row per line), the form the vectorised code works on."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam.errors import InputError
from slam.geometry import pose_compose
from slam.models.anchored import model_error_covariance

__all__ = ["LineSet", "supported_lines"]

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

    def well_posed(self) -> NDArray[np.bool_]:
        """Lines usable as measurements, shape (K,).

        Finite ``(r, α)``, finite end points, and a finite, positive definite ``(r, α)``
        covariance (``σ_r² > 0``, ``σ_α² > 0``, determinant ``> 0``).
        """
        cov = self.cov
        det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] * cov[:, 1, 0]
        finite = (
            np.all(np.isfinite(self.r_alpha), axis=1)
            & np.all(np.isfinite(cov), axis=(1, 2))
            & np.all(np.isfinite(self.endpoints), axis=(1, 2))
        )
        with np.errstate(invalid="ignore"):
            return finite & (cov[:, 0, 0] > 0.0) & (cov[:, 1, 1] > 0.0) & (det > 0.0)

    def with_model_error(self, sigma_offset_m: float, sigma_angle_rad: float) -> LineSet:
        """The lines with the model error added to their covariances.

        :func:`slam.models.anchored.model_error_covariance` (offset ``sigma_offset_m`` along the
        normal and angle ``sigma_angle_rad`` about each segment's mid-point); the set itself
        when both are zero or it is empty.
        """
        if len(self) == 0 or (sigma_offset_m <= 0.0 and sigma_angle_rad <= 0.0):
            return self
        extra = model_error_covariance(
            self.r_alpha, self.endpoints, sigma_offset_m, sigma_angle_rad
        )
        return LineSet(self.r_alpha, self.cov + extra, self.endpoints, self.ids)

    def subset(self, mask_or_index: NDArray[np.bool_] | NDArray[np.intp]) -> LineSet:
        """The lines selected by a boolean mask or an index array."""
        return LineSet(
            self.r_alpha[mask_or_index],
            self.cov[mask_or_index],
            self.endpoints[mask_or_index],
            self.ids[mask_or_index],
        )


def supported_lines(
    lines: Sequence[Line], min_points: int, min_length_m: float
) -> NDArray[np.bool_]:
    """Lines fitted to at least ``min_points`` points and at least ``min_length_m`` long (K,).

    The support rule both estimators apply to a scan's fitted lines before using them
    (``min_line_points`` and ``min_line_length_m`` of their configurations).
    """
    return np.array(
        [ln.n_points >= min_points and ln.length >= min_length_m for ln in lines], dtype=bool
    ).reshape(len(lines))
