"""The :class:`Line` result type and the normal form of a line.

Conventions (used everywhere in lineslam; see ``docs/conventions.md``)
-------------------------------------------------------------------
* A line is ``{p : p · n(α) = r}`` with the unit normal ``n(α) = (cos α, sin α)``.
* Normal form: ``r ≥ 0`` and ``α ∈ (−π, π]``.  ``(r, α)`` and ``(−r, α + π)`` are the same line.
* ``s`` is the coordinate along the line's tangent ``t(α) = (−sin α, cos α)``, i.e. a point on the
  line is ``r·n(α) + s·t(α)``.  This is the sign convention under which the paper's Prop. 2
  (Eq. 24) and transform (Eq. 30) hold; Eq. 10 as printed has the opposite sign (reading note 1).
  For a point ``(d, φ)`` in polar coordinates: ``u_R = d·cos(α − φ)``, ``u_S = d·sin(φ − α)``.
* ``Line.s`` is the paper's S: the weighted mean position of the supporting points along the line.
* Covariances are ordered ``(r, alpha, s)``; units metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["Line", "normal_form", "wrap_angle"]

FloatArray = NDArray[np.float64]


def wrap_angle(angle: float | FloatArray) -> float | FloatArray:
    """Wrap angles to ``(−π, π]`` (vectorised).

    Parameters
    ----------
    angle
        Angle(s) in radians, any shape.

    Returns
    -------
    float or ndarray
        The same angle(s) in ``(−π, π]``.
    """
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi)
    if np.ndim(wrapped) == 0:
        return float(wrapped)
    return wrapped


def normal_form(
    r: float | FloatArray, alpha: float | FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Bring ``(r, α)`` to the normal form ``r ≥ 0``, ``α ∈ (−π, π]`` (vectorised).

    Parameters
    ----------
    r, alpha
        Signed distance (m) and normal angle (rad), broadcastable arrays.

    Returns
    -------
    r, alpha : ndarray
        The same lines in normal form.
    flipped : ndarray of bool
        True where the representative was changed to ``(−r, α + π)``.  A covariance over
        ``(r, α, s)`` transforms with ``diag(−1, 1, −1)`` where flipped (both ``r`` and ``s``
        change sign because the normal and the tangent both reverse).
    """
    r_arr = np.asarray(r, dtype=float)
    a_arr = np.asarray(alpha, dtype=float)
    flipped = r_arr < 0.0
    r_out = np.where(flipped, -r_arr, r_arr)
    a_out = np.asarray(wrap_angle(np.where(flipped, a_arr + np.pi, a_arr)), dtype=float)
    return r_out, a_out, flipped


@dataclass(frozen=True, eq=False)
class Line:
    """One fitted line of one scan, in the sensor frame of that scan.

    Attributes
    ----------
    r : float
        Distance of the infinite line from the sensor origin (m), ``r ≥ 0``.
    alpha : float
        Angle of the line's normal (rad), ``α ∈ (−π, π]``.
    s : float
        Weighted mean position of the supporting points along the tangent ``(−sin α, cos α)`` (m).
    cov : ndarray, shape (3, 3)
        Covariance of ``(r, alpha, s)`` (m², rad², m·rad).  The ``(r, α)`` block is the joint
        maximum-likelihood covariance (inverse Fisher information), see reading note 8.
    segments_s : ndarray, shape (k, 2)
        Extents of the visible segments along the tangent: row ``j`` is ``(s_start, s_end)``
        with ``s_start < s_end``; one row for an unbroken segment, ``k > 1`` for collinear
        pieces separated by gaps.  Sorted by ``s_start``.
    segments_var : ndarray, shape (k, 2)
        Variances (m²) of the entries of ``segments_s``.
    n_points : int
        Number of scan points that support the fit.
    indices : ndarray of int, shape (n_points,)
        Beam indices (positions in the scan's range array) of the supporting points.
    """

    r: float
    alpha: float
    s: float
    cov: FloatArray
    segments_s: FloatArray
    segments_var: FloatArray
    n_points: int
    indices: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, dtype=np.intp))

    def __post_init__(self) -> None:
        object.__setattr__(self, "cov", np.asarray(self.cov, dtype=float).reshape(3, 3))
        seg = np.asarray(self.segments_s, dtype=float).reshape(-1, 2)
        var = np.asarray(self.segments_var, dtype=float).reshape(-1, 2)
        object.__setattr__(self, "segments_s", seg)
        object.__setattr__(self, "segments_var", var)
        object.__setattr__(self, "indices", np.asarray(self.indices, dtype=np.intp))

    @classmethod
    def _trusted(
        cls,
        r: float,
        alpha: float,
        s: float,
        cov: FloatArray,
        segments_s: FloatArray,
        segments_var: FloatArray,
        n_points: int,
        indices: NDArray[np.intp],
    ) -> Line:
        """Build from arrays that already have the right dtypes and shapes (no conversions).

        For :mod:`linefit.extract`, which creates many lines per scan; user code should call
        the normal constructor.
        """
        line = object.__new__(cls)
        line.__dict__.update(
            r=r,
            alpha=alpha,
            s=s,
            cov=cov,
            segments_s=segments_s,
            segments_var=segments_var,
            n_points=n_points,
            indices=indices,
        )
        return line

    # -- derived geometry -------------------------------------------------------------------
    @property
    def normal(self) -> FloatArray:
        """Unit normal ``(cos α, sin α)``."""
        return np.array([np.cos(self.alpha), np.sin(self.alpha)])

    @property
    def tangent(self) -> FloatArray:
        """Unit tangent ``(−sin α, cos α)``, the direction in which ``s`` grows."""
        return np.array([-np.sin(self.alpha), np.cos(self.alpha)])

    def point_at(self, s: float | FloatArray) -> FloatArray:
        """Points on the line at tangent coordinate(s) ``s``; shape ``(..., 2)``."""
        s_arr = np.asarray(s, dtype=float)[..., None]
        return self.r * self.normal + s_arr * self.tangent

    @property
    def endpoints(self) -> FloatArray:
        """The two extreme endpoints ``[[x1, y1], [x2, y2]]`` (m) over all segments."""
        return self.point_at(np.array([self.segments_s[0, 0], self.segments_s[-1, 1]]))

    @property
    def length(self) -> float:
        """Total visible length (m), gaps excluded."""
        return float(np.sum(self.segments_s[:, 1] - self.segments_s[:, 0]))

    @property
    def cov_r_alpha(self) -> FloatArray:
        """The 2×2 covariance of ``(r, alpha)``."""
        return self.cov[:2, :2]

    def to_json_dict(self) -> dict[str, object]:
        """The INTERFACES.md ``extract`` representation of this line (plus ``segments``)."""
        ends = self.endpoints
        return {
            "r": float(self.r),
            "alpha": float(self.alpha),
            "s": float(self.s),
            "cov": self.cov.tolist(),
            "endpoints": ends.tolist(),
            "n_points": int(self.n_points),
            "segments": [self.point_at(row).tolist() for row in self.segments_s],
            "segments_var": self.segments_var.tolist(),
        }
