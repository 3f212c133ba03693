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

Observations in the chart (used by both estimators' front ends):

* :func:`observe_anchored`: a measured line ``z = (r, α)`` (laser frame, covariance ``R``) seen
  from a known laser pose, moved into the world (Eq. 30, :func:`slam.geometry.line_to_parent`)
  and expressed at an anchor; covariance ``G R Gᵀ`` with ``G = ∂(ρ, φ)/∂(r, α)`` (the pose is
  taken as known: relative to the poses that see it, a line is as good as its fits).
* :func:`drift_covariance`: what an unknown drift of the robot relative to a line (translation
  ``σ_xy``, rotation ``σ_θ`` about the robot) adds to the line's covariance in the chart.
* :func:`model_error_covariance`: a model-error floor for a measured segment, specified at the
  segment's mid-point (see the function).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.geometry import line_to_parent

__all__ = [
    "LANDMARK_DIM",
    "align_representative",
    "anchored_from_r_alpha",
    "anchored_jacobian",
    "drift_covariance",
    "landmarks_normal_form",
    "model_error_covariance",
    "observe_anchored",
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


def observe_anchored(
    z: FloatArray, R: FloatArray, pose_world_laser: FloatArray, anchors: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Measured lines moved into the world and written at ``anchors``.

    Parameters
    ----------
    z : ndarray, shape (K, 2)
        Measured ``(r, α)`` in the laser frame.
    R : ndarray, shape (K, 2, 2)
        Their covariances.
    pose_world_laser : ndarray, shape (3,) or (K, 3)
        Laser pose(s) (taken as exact).
    anchors : ndarray, shape (K, 2)
        World anchor of each line.

    Returns
    -------
    rho_phi : ndarray, shape (K, 2)
        ``(ρ, φ)`` with ``φ = wrap(α + θ)`` (the measurement's own representative).
    cov : ndarray, shape (K, 2, 2)
        ``G R Gᵀ``, ``G = [[1, ∂r_w/∂α − c·t(φ)], [0, 1]]``.
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    K = z.shape[0]
    z3 = np.column_stack([z, np.zeros(K)])
    lw, B, _ = line_to_parent(z3, np.asarray(pose_world_laser, dtype=float), normal_form=False)
    c = np.asarray(anchors, dtype=float).reshape(K, 2)
    phi = lw[:, 1]
    t = np.stack([-np.sin(phi), np.cos(phi)], -1)
    rho = lw[:, 0] - c[:, 0] * np.cos(phi) - c[:, 1] * np.sin(phi)
    G = np.array(B[:, :2, :2])
    G[:, 0, 1] -= np.sum(c * t, axis=1)
    cov = G @ np.asarray(R, dtype=float).reshape(K, 2, 2) @ np.swapaxes(G, -1, -2)
    return np.column_stack([rho, phi]), 0.5 * (cov + np.swapaxes(cov, -1, -2))


def align_representative(
    reference: FloatArray, rho_phi: FloatArray, cov: FloatArray | None = None
) -> tuple[FloatArray, FloatArray | None]:
    """``rho_phi`` (same anchors as ``reference``) in the representative nearest ``reference``.

    ``(ρ, φ)`` and ``(−ρ, φ + π)`` are the same line; where the normals point apart the second
    form is returned, with ``φ`` unwrapped to within ``π/2`` of the reference's, and the ``ρ``
    row and column of ``cov`` negated.
    """
    ref = np.asarray(reference, dtype=float).reshape(-1, 2)
    v = np.array(rho_phi, dtype=float).reshape(-1, 2)
    d = np.asarray(wrap_angle(v[:, 1] - ref[:, 1]))
    flip = np.abs(d) > 0.5 * np.pi
    v[flip, 0] *= -1.0
    d = np.asarray(wrap_angle(np.where(flip, d + np.pi, d)))
    v[:, 1] = ref[:, 1] + d
    if cov is None:
        return v, None
    P = np.array(cov, dtype=float).reshape(-1, 2, 2)
    P[flip, 0, 1] *= -1.0
    P[flip, 1, 0] *= -1.0
    return v, P


def drift_covariance(
    rho_phi: FloatArray,
    anchors: FloatArray,
    position: FloatArray,
    sigma_xy_m: FloatArray | float,
    sigma_theta_rad: FloatArray | float,
) -> FloatArray:
    """Covariance added to anchored lines by a drift of the robot relative to them.

    A translation ``δp`` of the robot relative to the line shifts it by ``n·δp``; a rotation
    ``δθ`` about the robot at ``p`` rotates it there: ``δφ = δθ``, ``δρ = δθ·t·(p − c)``.  With
    ``δp ~ N(0, σ_xy² I)`` and ``δθ ~ N(0, σ_θ²)``:
    ``[[σ_xy² + u² σ_θ², u σ_θ²], [u σ_θ², σ_θ²]]``, ``u = t(φ)·(p − c)``.

    Returns
    -------
    ndarray, shape (K, 2, 2)
    """
    v = np.asarray(rho_phi, dtype=float).reshape(-1, 2)
    c = np.asarray(anchors, dtype=float).reshape(-1, 2)
    p = np.asarray(position, dtype=float).reshape(-1, 2)
    phi = v[:, 1]
    u = -np.sin(phi) * (p[:, 0] - c[:, 0]) + np.cos(phi) * (p[:, 1] - c[:, 1])
    sxy2 = np.broadcast_to(np.asarray(sigma_xy_m, dtype=float) ** 2, phi.shape)
    sth2 = np.broadcast_to(np.asarray(sigma_theta_rad, dtype=float) ** 2, phi.shape)
    out = np.empty((v.shape[0], 2, 2))
    out[:, 0, 0] = sxy2 + u * u * sth2
    out[:, 0, 1] = out[:, 1, 0] = u * sth2
    out[:, 1, 1] = sth2
    return out


def model_error_covariance(
    z: FloatArray, endpoints_laser: FloatArray, sigma_offset_m: float, sigma_angle_rad: float
) -> FloatArray:
    """Model-error covariance of measured lines, specified at each segment's mid-point.

    Real walls are not the straight lines of the fit's noise model (the fit's covariance only
    knows the per-beam noise): the wall bends, the beams have a footprint, ranges are quantised
    and biased by the surface.  This adds an offset error ``σ_offset`` along the normal at the
    segment's mid-point and an independent angle error ``σ_angle`` about it.  With the mid-point
    at tangent coordinate ``s_m`` (``p = r n + s t``, ``t = (−sin α, cos α)``) a rotation ``δα``
    about it changes ``r`` by ``s_m δα``, so in ``(r, α)``:
    ``[[σ_o² + s_m² σ_a², s_m σ_a²], [s_m σ_a², σ_a²]]``.  Specifying the error at the foot point
    instead would make lines seen far along themselves (``|s_m|`` large) absurdly uncertain at
    the part actually seen.

    Parameters
    ----------
    z : ndarray, shape (K, 2)
        Measured ``(r, α)``.
    endpoints_laser : ndarray, shape (K, 2, 2)
        Segment end points (laser frame).
    sigma_offset_m, sigma_angle_rad : float

    Returns
    -------
    ndarray, shape (K, 2, 2)
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    mid = np.asarray(endpoints_laser, dtype=float).reshape(-1, 2, 2).mean(axis=1)
    a = z[:, 1]
    s_m = -np.sin(a) * mid[:, 0] + np.cos(a) * mid[:, 1]
    sa2 = sigma_angle_rad**2
    out = np.empty((z.shape[0], 2, 2))
    out[:, 0, 0] = sigma_offset_m**2 + s_m * s_m * sa2
    out[:, 0, 1] = out[:, 1, 0] = s_m * sa2
    out[:, 1, 1] = sa2
    return out
