"""Parameterisation of line landmarks: anchored ``(ρ, φ)``, a global chart of the lines.

Each landmark ``j`` has a fixed **anchor** point ``c_j`` in the world (the mid-point of the
segment that created it) and is stored as the 2-vector ``v = (ρ, φ)``: the line with normal
angle ``α = φ`` passing at signed distance ``ρ`` from the anchor,

``{p : (p − c)·n(φ) = ρ}``,   i.e.   ``r = c·n(φ) + ρ``,  ``α = φ``   (``n(φ) = (cos φ, sin φ)``).

The retraction is additive, ``v ⊕ δ = (ρ + δρ, wrap(φ + δφ))``: a change of ``φ`` rotates the
line about its anchor, a change of ``ρ`` shifts it along its normal.  Why not plain ``(r, α)``
with ``(r + δr, α + δα)`` (which rotates the line about the world origin):

* **Invariance to where the world origin is.**  With ``(r, α)``, ``∂r_sensor/∂α`` is the
  distance along the line between the robot and the world origin's foot point, and a change
  ``δα`` rotates the landmark about the world origin, moving it by ``δα`` times that lever arm.
  The anchored Jacobian involves only ``c − p``, the distance from the robot to a point of the
  wall it sees, so the problem looks the same wherever the map lies.  Measured on a 250-pose
  synthetic problem (``tests/test_graph_batch.py``): both charts converge in 4 Gauss-Newton
  iterations near the origin; moved 1 km away, the ``(r, α)`` chart no longer converges in 200
  iterations (cost 1173.8 instead of 1152.9, pose errors ×3) and at 100 km GTSAM reports the
  system indeterminate, while the anchored chart gives the same 4 iterations and the same
  solution at all three places.  (This does not help the slow convergence of long open chains
  started from dead reckoning, which comes from the poses' rotations and is the same in both
  charts.)
* **Lines through the world origin** (``r = 0``) and **normals near ±π** are ordinary points of
  this chart: ``ρ`` is signed (``(ρ, φ)`` and ``(−ρ, φ + π)`` are the same line), the landmark's
  own value is never compared with anything, and every residual goes through
  :func:`slam.geometry.line_residual`, which picks the measurement's representative and wraps
  the angle.  ``ρ ≈ 0`` is in fact the normal state (the line passes through its anchor).

Inside GTSAM (iSAM2, the ``CustomFactor`` reference) the value is a ``gtsam.Point2`` holding
``(ρ, φ)``; its additive retraction is exactly this chart (``φ`` may leave ``(−π, π]`` there,
which changes nothing: every function of it is 2π-periodic).  Output is ``(r, α)`` in normal form
(:func:`landmarks_normal_form`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle

__all__ = [
    "LANDMARK_DIM",
    "anchored_from_r_alpha",
    "anchored_jacobian",
    "landmarks_normal_form",
    "r_alpha_from_anchored",
    "retract_landmarks",
]

FloatArray = NDArray[np.float64]

LANDMARK_DIM = 2
"""Tangent dimension of a line landmark ``(δρ, δφ)``."""


def r_alpha_from_anchored(rho_phi: FloatArray, anchors: FloatArray) -> FloatArray:
    """Signed ``(r, α) = (c·n(φ) + ρ, φ)`` of anchored landmarks ``(..., 2)``."""
    v = np.asarray(rho_phi, dtype=float)
    c = np.asarray(anchors, dtype=float)
    phi = v[..., 1]
    r = c[..., 0] * np.cos(phi) + c[..., 1] * np.sin(phi) + v[..., 0]
    return np.stack([r, np.asarray(wrap_angle(phi))], axis=-1)


def anchored_from_r_alpha(r_alpha: FloatArray, anchors: FloatArray) -> FloatArray:
    """``(ρ, φ) = (r − c·n(α), α)``: the inverse of :func:`r_alpha_from_anchored`."""
    la = np.asarray(r_alpha, dtype=float)
    c = np.asarray(anchors, dtype=float)
    a = la[..., 1]
    rho = la[..., 0] - c[..., 0] * np.cos(a) - c[..., 1] * np.sin(a)
    return np.stack([rho, np.asarray(wrap_angle(a))], axis=-1)


def anchored_jacobian(rho_phi: FloatArray, anchors: FloatArray) -> FloatArray:
    """``∂(r, α)/∂(ρ, φ) = [[1, c·t(φ)], [0, 1]]``, ``t(φ) = (−sin φ, cos φ)``; ``(..., 2, 2)``."""
    v = np.asarray(rho_phi, dtype=float)
    c = np.asarray(anchors, dtype=float)
    phi = v[..., 1]
    s_c = -c[..., 0] * np.sin(phi) + c[..., 1] * np.cos(phi)
    J = np.zeros((*np.broadcast_shapes(v.shape[:-1], c.shape[:-1]), 2, 2))
    J[..., 0, 0] = 1.0
    J[..., 0, 1] = s_c
    J[..., 1, 1] = 1.0
    return J


def retract_landmarks(rho_phi: FloatArray, delta: FloatArray) -> FloatArray:
    """``v ⊕ δ = (ρ + δρ, wrap(φ + δφ))`` for landmarks ``(..., 2)``."""
    out = np.asarray(rho_phi, dtype=float) + np.asarray(delta, dtype=float)
    out[..., 1] = np.asarray(wrap_angle(out[..., 1]))
    return out


def landmarks_normal_form(
    landmarks_r_alpha: FloatArray, covariances: FloatArray | None = None
) -> tuple[FloatArray, FloatArray | None]:
    """``(r, α)`` lines in normal form (``r ≥ 0``, ``α ∈ (−π, π]``) and their covariances.

    Where the representative is flipped, ``r`` changes sign, and so do the ``r`` row and column
    of the ``(r, α)`` covariance.

    Parameters
    ----------
    landmarks_r_alpha : ndarray, shape (..., 2)
    covariances : ndarray, shape (..., 2, 2), optional
        Covariances of ``(r, α)``.

    Returns
    -------
    landmarks : ndarray, shape (..., 2)
    covariances : ndarray, shape (..., 2, 2) or None
    """
    lm = np.array(landmarks_r_alpha, dtype=float, copy=True)
    flip = lm[..., 0] < 0.0
    sign = np.where(flip, -1.0, 1.0)
    lm[..., 0] *= sign
    lm[..., 1] = np.asarray(wrap_angle(lm[..., 1] + np.where(flip, np.pi, 0.0)))
    if covariances is None:
        return lm, None
    cov = np.array(covariances, dtype=float, copy=True)
    cov[..., 0, 1] *= sign
    cov[..., 1, 0] *= sign
    return lm, cov
