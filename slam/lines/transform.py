"""Lines and poses with their covariances across frames (the paper's Eqs. 30-31, corrected).

Conventions
-----------
* ``pose_a_b = (x, y, θ)`` is frame ``b`` in frame ``a``.  A pose covariance is the covariance of
  the **right** perturbation ``ξ = (v_x, v_y, ω)`` in ``pose · Exp(ξ)`` (body frame, as GTSAM's
  ``Pose2`` marginals).  Pass GTSAM marginals unchanged; a covariance of the plain vector
  ``(x, y, θ)`` ("left"/global perturbation) must first be mapped with
  ``Ad(pose)⁻¹ P Ad(pose)⁻ᵀ`` (:func:`adjoint`).
* Lines are ``(r, α, s)`` with covariances ordered ``(r, α, s)`` (see :mod:`linefit.line`).

Eq. 31 with the Jacobians derived from Eq. 30 (the printed Eqs. 32-33 miss terms, reading
note 3).  For a line ``L_j`` seen from pose ``j`` and ``ĝ_ij = pose_i_j = (x, y, γ)``, with
``α_i = α_j + γ``::

    P_i = B P_j Bᵀ + K P^ij Kᵀ
    B = [[1, −x sin α_i + y cos α_i, 0],
         [0, 1,                      0],
         [0, −x cos α_i − y sin α_i, 1]]
    K = [[ cos α_j, sin α_j, −x sin α_i + y cos α_i],
         [ 0,       0,       1                     ],
         [−sin α_j, cos α_j, −x cos α_i − y sin α_i]]    (right perturbation of ĝ_ij)

(:func:`slam.geometry.line_to_parent` computes ``B`` and ``K``; tests check them by finite
differences and the covariance by Monte Carlo.)  The line and the displacement are assumed
independent (odometry), as in the paper.

Everything is vectorised over leading dimensions; inputs broadcast against each other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.geometry import line_to_child, line_to_parent, pose_compose, pose_inverse, wrap_angle
from slam.lines.checks import check_covariance

__all__ = [
    "adjoint",
    "between_poses",
    "compose_chain",
    "compound_poses",
    "invert_pose",
    "line_from_world",
    "line_to_world",
    "segment_shift",
    "transform_line",
    "transform_line_to_child",
    "transform_segments",
]

FloatArray = NDArray[np.float64]


def _pose_cov_or_zero(pose_cov: FloatArray | None, name: str = "pose_cov") -> FloatArray:
    if pose_cov is None:
        return np.zeros((3, 3))
    return check_covariance(pose_cov, 3, name)


def _sandwich(J: FloatArray, P: FloatArray) -> FloatArray:
    """``J P Jᵀ`` over leading dimensions."""
    return np.asarray(J @ P @ np.swapaxes(J, -1, -2))


# ---------------------------------------------------------------------------------------------
# Lines (Eqs. 30-31)
# ---------------------------------------------------------------------------------------------
def transform_line(
    line_j: FloatArray,
    cov_j: FloatArray,
    pose_i_j: FloatArray,
    pose_cov: FloatArray | None = None,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Move lines and their covariances from frame ``j`` to frame ``i`` (Eqs. 30-31).

    Parameters
    ----------
    line_j : ndarray, shape (..., 3)
        Lines ``(r, α, s)`` in frame ``j``.
    cov_j : ndarray, shape (..., 3, 3)
        Their covariances (``P_L^j``).
    pose_i_j : ndarray, shape (..., 3)
        Pose of ``j`` in ``i`` (the paper's ``ĝ_ij``).
    pose_cov : ndarray, shape (..., 3, 3), optional
        Covariance ``P^ij`` of ``pose_i_j`` for the right perturbation ``ĝ_ij · Exp(ξ)``.
        None: the displacement is known exactly.
    normal_form : bool
        True: result with ``r ≥ 0``, ``α ∈ (−π, π]`` (covariance rows follow the flip).
        False: ``α_i = wrap(α_j + γ)`` and ``r`` keeps the sign it gets, so the normal keeps
        pointing away from the sensor of frame ``j``.

    Returns
    -------
    line_i : ndarray, shape (..., 3)
    cov_i : ndarray, shape (..., 3, 3)
        ``B P_j Bᵀ + K P^ij Kᵀ``.
    """
    cov_j = check_covariance(cov_j, 3, "cov_j")
    P_pose = _pose_cov_or_zero(pose_cov)
    line_i, B, K = line_to_parent(line_j, pose_i_j, normal_form=normal_form)
    cov_i = _sandwich(B, cov_j) + _sandwich(K, P_pose)
    return line_i, 0.5 * (cov_i + np.swapaxes(cov_i, -1, -2))


def transform_line_to_child(
    line_i: FloatArray,
    cov_i: FloatArray,
    pose_i_j: FloatArray,
    pose_cov: FloatArray | None = None,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Move lines and covariances from frame ``i`` to frame ``j`` (inverse of Eqs. 30-31).

    Parameters are as in :func:`transform_line`, with ``pose_cov`` the covariance of
    ``pose_i_j`` (right perturbation).  Returns ``(line_j, J_l P_i J_lᵀ + J_ξ P^ij J_ξᵀ)`` with the
    Jacobians of :func:`slam.geometry.line_to_child`.
    """
    cov_i = check_covariance(cov_i, 3, "cov_i")
    P_pose = _pose_cov_or_zero(pose_cov)
    line_j, J_line, J_pose = line_to_child(line_i, pose_i_j, normal_form=normal_form)
    cov_j = _sandwich(J_line, cov_i) + _sandwich(J_pose, P_pose)
    return line_j, 0.5 * (cov_j + np.swapaxes(cov_j, -1, -2))


def line_to_world(
    line_laser: FloatArray,
    cov_laser: FloatArray,
    pose_world_laser: FloatArray,
    pose_cov: FloatArray | None = None,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Lines seen by the laser at ``pose_world_laser`` (covariance ``pose_cov``) in the world.

    Same as :func:`transform_line` with ``i = world``, ``j = laser``.
    """
    return transform_line(line_laser, cov_laser, pose_world_laser, pose_cov, normal_form)


def line_from_world(
    line_world: FloatArray,
    cov_world: FloatArray,
    pose_world_laser: FloatArray,
    pose_cov: FloatArray | None = None,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """World lines (with covariance) as the laser at ``pose_world_laser`` would see them.

    Same as :func:`transform_line_to_child` with ``i = world``, ``j = laser``.
    """
    return transform_line_to_child(line_world, cov_world, pose_world_laser, pose_cov, normal_form)


def segment_shift(
    line_j: FloatArray,
    cov_j: FloatArray,
    pose_i_j: FloatArray,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """How tangent coordinates on lines move from frame ``j`` to frame ``i`` (vectorised).

    A point at tangent coordinate ``s`` on the line maps by Eq. 30 to ``s + shift`` with
    ``shift = −x sin α_i + y cos α_i`` (common to all points of the line).  The variance of an
    end grows by the pose term ``(K P^ij Kᵀ)_ss`` plus the lever-arm term
    ``(x cos α_i + y sin α_i)² P_αα`` (first order; the correlation between an extreme point and
    ``α`` is not tracked).

    Parameters
    ----------
    line_j : ndarray, shape (..., 3)
    cov_j : ndarray, shape (..., 3, 3)
        Only ``P_αα`` is used (not validated here).
    pose_i_j : ndarray, shape (..., 3)
    pose_cov : ndarray, shape (..., 3, 3), optional

    Returns
    -------
    shift, extra_var : ndarray, shape (...)
    flipped : ndarray of bool, shape (...)
        True where the normal form of the moved line has the opposite tangent (``s → −s``).
    """
    line_j = np.asarray(line_j, dtype=float)
    P_pose = _pose_cov_or_zero(pose_cov)
    _, _, K = line_to_parent(line_j, pose_i_j, normal_form=False)
    pose = np.asarray(pose_i_j, dtype=float)
    x, y, g = pose[..., 0], pose[..., 1], pose[..., 2]
    a_i = line_j[..., 1] + g
    shift = -x * np.sin(a_i) + y * np.cos(a_i)
    lever = -x * np.cos(a_i) - y * np.sin(a_i)
    k_s = K[..., 2, :]
    extra = np.einsum("...i,...ij,...j->...", k_s, P_pose, k_s)
    extra = extra + lever**2 * np.asarray(cov_j, dtype=float)[..., 1, 1]
    r_i = line_j[..., 0] + x * np.cos(a_i) + y * np.sin(a_i)
    return np.asarray(shift), np.asarray(extra), np.asarray(r_i < 0.0)


def transform_segments(
    segments_s: FloatArray,
    segments_var: FloatArray,
    line_j: FloatArray,
    cov_j: FloatArray,
    pose_i_j: FloatArray,
    pose_cov: FloatArray | None = None,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Move the segment extents of one line from frame ``j`` to frame ``i``.

    Shift and variance growth as in :func:`segment_shift`; if the result is flipped to the
    normal form, ``s`` changes sign and each segment's ends swap.

    Parameters
    ----------
    segments_s, segments_var : ndarray, shape (k, 2)
        Extents ``(s_start, s_end)`` in frame ``j`` and their variances.
    line_j : ndarray, shape (3,)
    cov_j : ndarray, shape (3, 3)
    pose_i_j : ndarray, shape (3,)
    pose_cov : ndarray, shape (3, 3), optional
    normal_form : bool
        As in :func:`transform_line` (must match the call that moved the line).

    Returns
    -------
    segments_s, segments_var : ndarray, shape (k, 2)
        Sorted by start, ``start < end``.
    """
    seg = np.asarray(segments_s, dtype=float).reshape(-1, 2)
    var = np.asarray(segments_var, dtype=float).reshape(-1, 2)
    cov = check_covariance(cov_j, 3, "cov_j")
    shift, extra, flipped = segment_shift(line_j, cov, pose_i_j, pose_cov)
    seg_i = seg + float(shift)
    var_i = var + float(extra)
    if normal_form and bool(flipped):
        seg_i = -seg_i[::-1, ::-1]
        var_i = var_i[::-1, ::-1]
    return np.ascontiguousarray(seg_i), np.ascontiguousarray(var_i)


# ---------------------------------------------------------------------------------------------
# Poses with covariances (right perturbation)
# ---------------------------------------------------------------------------------------------
def adjoint(pose: FloatArray) -> FloatArray:
    """SE(2) adjoint ``Ad(T) = [[cos θ, −sin θ, y], [sin θ, cos θ, −x], [0, 0, 1]]``.

    ``T · Exp(ξ) · T⁻¹ = Exp(Ad(T) ξ)`` (as ``gtsam.Pose2.AdjointMap``); shape ``(..., 3, 3)``.
    """
    p = np.asarray(pose, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    zeros, ones = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [
            np.stack([c, -s, p[..., 1]], -1),
            np.stack([s, c, -p[..., 0]], -1),
            np.stack([zeros, zeros, ones], -1),
        ],
        -2,
    )


def compound_poses(
    pose_a: FloatArray,
    cov_a: FloatArray | None,
    pose_b: FloatArray,
    cov_b: FloatArray | None,
    cross: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``a · b`` and its covariance (Smith-Cheeseman compounding in the right tangent space).

    With ``a' = a·Exp(ξ_a)`` and ``b' = b·Exp(ξ_b)``, ``a'·b' ≈ (a·b)·Exp(Ad(b⁻¹) ξ_a + ξ_b)``, so
    ``P_ab = Ad(b⁻¹) P_a Ad(b⁻¹)ᵀ + P_b + Ad(b⁻¹) X + Xᵀ Ad(b⁻¹)ᵀ`` with ``X = E[ξ_a ξ_bᵀ]``.

    Parameters
    ----------
    pose_a, pose_b : ndarray, shape (..., 3)
    cov_a, cov_b : ndarray, shape (..., 3, 3) or None
        Right-perturbation covariances (None: exact).
    cross : ndarray, shape (..., 3, 3), optional
        Cross-covariance ``E[ξ_a ξ_bᵀ]``; None: independent.

    Returns
    -------
    pose_ab : ndarray, shape (..., 3)
    cov_ab : ndarray, shape (..., 3, 3)
    """
    Pa = _pose_cov_or_zero(cov_a, "cov_a")
    Pb = _pose_cov_or_zero(cov_b, "cov_b")
    J = adjoint(pose_inverse(pose_b))
    cov = _sandwich(J, Pa) + Pb
    if cross is not None:
        X = np.asarray(cross, dtype=float)
        JX = J @ X
        cov = cov + JX + np.swapaxes(JX, -1, -2)
    return pose_compose(pose_a, pose_b), 0.5 * (cov + np.swapaxes(cov, -1, -2))


def invert_pose(pose: FloatArray, cov: FloatArray | None) -> tuple[FloatArray, FloatArray]:
    """``T⁻¹`` and its covariance ``Ad(T) P Ad(T)ᵀ`` (right perturbation)."""
    P = _pose_cov_or_zero(cov, "cov")
    return pose_inverse(pose), _sandwich(adjoint(pose), P)


def between_poses(
    pose_a: FloatArray,
    cov_a: FloatArray | None,
    pose_b: FloatArray,
    cov_b: FloatArray | None,
    cross: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``a⁻¹ · b`` (the paper's ``g_ab``) and its covariance.

    ``ξ_ab ≈ −Ad(d⁻¹) ξ_a + ξ_b`` with ``d = a⁻¹·b``.  Two *marginal* covariances from one
    estimator are correlated; pass that correlation as ``cross = E[ξ_a ξ_bᵀ]`` (None:
    independent).  For poses along one odometry chain use :func:`compose_chain` instead.
    """
    Pa = _pose_cov_or_zero(cov_a, "cov_a")
    Pb = _pose_cov_or_zero(cov_b, "cov_b")
    d = pose_compose(pose_inverse(pose_a), pose_b)
    J = -adjoint(pose_inverse(d))
    cov = _sandwich(J, Pa) + Pb
    if cross is not None:
        X = np.asarray(cross, dtype=float)
        JX = J @ X
        cov = cov + JX + np.swapaxes(JX, -1, -2)
    return d, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def compose_chain(
    increments: FloatArray,
    increment_covs: FloatArray | None = None,
    pose0: FloatArray | None = None,
    cov0: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Poses and covariances along a chain of independent relative poses (odometry), vectorised.

    ``pose_k = pose0 · u_1 · … · u_k``.  In the world frame the perturbations add up:
    ``Ad(pose_k) P_k Ad(pose_k)ᵀ = Ad(pose0) P0 Ad(pose0)ᵀ + Σ_{m≤k} Ad(pose_m) C_m Ad(pose_m)ᵀ``
    (exactly the recursion of :func:`compound_poses` with independent steps), which is one
    cumulative sum.

    Parameters
    ----------
    increments : ndarray, shape (N, 3)
        ``u_k = pose_{k−1}⁻¹ · pose_k``.
    increment_covs : ndarray, shape (N, 3, 3) or (3, 3), optional
        Right-perturbation covariance of each increment (None: exact).
    pose0 : ndarray, shape (3,), optional
        Start pose (default the origin).
    cov0 : ndarray, shape (3, 3), optional
        Its covariance (default zero: the chain is expressed relative to pose 0).

    Returns
    -------
    poses : ndarray, shape (N + 1, 3)
    covs : ndarray, shape (N + 1, 3, 3)
        ``covs[k]`` is the covariance of ``poses[k]``; with ``cov0`` None it is the covariance of
        the displacement ``g_0k`` (Eq. 2) accumulated by odometry.
    """
    u = np.asarray(increments, dtype=float).reshape(-1, 3)
    n = u.shape[0]
    p0 = np.zeros(3) if pose0 is None else np.asarray(pose0, dtype=float)
    C = (
        np.zeros((n, 3, 3))
        if increment_covs is None
        else np.broadcast_to(check_covariance(increment_covs, 3, "increment_covs"), (n, 3, 3))
    )
    P0 = _pose_cov_or_zero(cov0, "cov0")
    theta = p0[2] + np.concatenate([[0.0], np.cumsum(u[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    dxy = np.stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]], -1)
    xy = p0[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(dxy, axis=0)])
    poses = np.column_stack([xy, np.asarray(wrap_angle(theta))])
    Ad = adjoint(poses)
    world = np.concatenate([(Ad[0] @ P0 @ Ad[0].T)[None], _sandwich(Ad[1:], C)])
    world = np.cumsum(world, axis=0)
    Ad_inv = adjoint(pose_inverse(poses))
    covs = _sandwich(Ad_inv, world)
    return poses, 0.5 * (covs + np.swapaxes(covs, -1, -2))
