"""The usable lines of one keyframe, as arrays, with the model-error floor added."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from linefit.line import Line
from slam.frontend.tentative import Observation
from slam.line_slam.config import SlamConfig
from slam.lines.lineset import supported_lines
from slam.models.anchored import model_error_covariance

__all__ = ["ScanLines", "usable_lines"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ScanLines:
    """Usable lines of one keyframe (laser frame), ``K`` of them.

    Attributes
    ----------
    z : ndarray, shape (K, 2)
        ``(r, α)`` of each line (m, rad).
    R : ndarray, shape (K, 2, 2)
        Covariance of ``(r, α)``, model error included.
    endpoints : ndarray, shape (K, 2, 2)
        Segment end points (m).
    endpoint_var : ndarray, shape (K, 2)
        Variance (m²) of each end point along the line.
    pieces, pieces_var : list of ndarray
        The segment's visible pieces (end points) and their variances.
    R_fit : ndarray, shape (K, 2, 2)
        The fit's covariance of ``(r, α)`` alone (``R`` without the model error).
    """

    z: FloatArray
    R: FloatArray
    endpoints: FloatArray
    endpoint_var: FloatArray
    pieces: list[FloatArray]
    pieces_var: list[FloatArray]
    R_fit: FloatArray

    def __len__(self) -> int:
        return int(self.z.shape[0])

    @classmethod
    def empty(cls) -> ScanLines:
        """No lines."""
        empty = np.zeros((0, 2, 2))
        return cls(np.zeros((0, 2)), empty, empty, np.zeros((0, 2)), [], [], empty)

    def observation(self, pose: int, k: int) -> Observation:
        """Line ``k`` as a measurement from pose variable ``pose``."""
        return Observation(
            pose,
            self.z[k],
            self.R[k],
            self.endpoints[k],
            self.endpoint_var[k],
            self.pieces[k],
            self.pieces_var[k],
            self.R_fit[k],
        )


def usable_lines(
    lines: Sequence[Line], config: SlamConfig, model_error: tuple[float, float] | None = None
) -> tuple[ScanLines, int]:
    """The usable lines of a scan and how many were rejected.

    A line is usable with at least ``min_line_points`` points, a length of at least
    ``min_line_length_m``, finite values and a positive-definite ``(r, α)`` covariance; the
    model error ``(σ_o, σ_a)`` (m, rad, at the segment's mid-point:
    :func:`slam.models.anchored.model_error_covariance`; default ``line_model_sigma_r_m``,
    ``line_model_sigma_alpha_rad``) is added to it.
    """
    sigma_o, sigma_a = (
        (config.line_model_sigma_r_m, config.line_model_sigma_alpha_rad)
        if model_error is None
        else model_error
    )
    z, R, ep, ev = [], [], [], []
    pieces: list[FloatArray] = []
    pieces_var: list[FloatArray] = []
    rejected = 0
    supported = supported_lines(lines, config.min_line_points, config.min_line_length_m)
    for ln, ok_support in zip(lines, supported, strict=True):
        cov = np.asarray(ln.cov, dtype=float)[:2, :2]
        ok = (
            ok_support
            and np.isfinite(cov).all()
            and np.isfinite([ln.r, ln.alpha]).all()
            and cov[0, 0] > 0.0
            and cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0] > 0.0
        )
        if not ok:
            rejected += 1
            continue
        z.append([ln.r, ln.alpha])
        R.append(0.5 * (cov + cov.T))
        ep.append(ln.endpoints)
        ev.append([ln.segments_var[0, 0], ln.segments_var[-1, 1]])
        pieces.append(ln.point_at(ln.segments_s))
        pieces_var.append(np.asarray(ln.segments_var, dtype=float))
    if not z:
        return ScanLines.empty(), rejected
    z_arr, R_fit, ep_arr = np.array(z), np.array(R), np.array(ep)
    R_arr = R_fit
    if sigma_o > 0.0 or sigma_a > 0.0:
        R_arr = R_fit + model_error_covariance(z_arr, ep_arr, sigma_o, sigma_a)
    return ScanLines(z_arr, R_arr, ep_arr, np.array(ev), pieces, pieces_var, R_fit), rejected
