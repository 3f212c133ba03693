"""SE(2) poses and lines across frames, with analytic Jacobians (vectorised).

Conventions
-----------
* A pose ``pose_a_b = (x, y, θ)`` is frame ``b`` expressed in frame ``a``: a point ``p_b`` maps to
  ``p_a = Rot(θ)·p_b + (x, y)``.
* Pose perturbations are applied on the **right**, in the body frame, as in GTSAM:
  ``pose ⊕ ξ = pose · Exp(ξ)`` with ``ξ = (v_x, v_y, ω)``.  To first order this moves the
  translation by ``Rot(θ)·(v_x, v_y)`` and the angle by ``ω``.  Every pose Jacobian and every
  pose covariance in lineslam is with respect to this ``ξ`` (GTSAM's ``Pose2`` marginals are
  in the same tangent space).
* Lines are ``(r, α, s)`` as in :mod:`linefit.line`: ``{p : p·(cos α, sin α) = r}`` and ``s``
  along the tangent ``(−sin α, cos α)``.

Eq. 30 of the paper moves a line from frame ``j`` to frame ``i`` given ``ĝ_ij = pose_i_j =
(x, y, γ)``.  Its Jacobians are derived here from Eq. 30 itself; the printed Eqs. 32-33 miss
terms (reading note 3).  With ``α_i = α_j + γ``:

``B = ∂L_i/∂L_j = [[1, −x sin α_i + y cos α_i, 0], [0, 1, 0], [0, −x cos α_i − y sin α_i, 1]]``

``K = ∂L_i/∂ξ = [[cos α_j, sin α_j, −x sin α_i + y cos α_i], [0, 0, 1],
[−sin α_j, cos α_j, −x cos α_i − y sin α_i]]``  (right perturbation of ``pose_i_j``).

All functions accept arrays with any number of leading dimensions (``(..., 3)`` for poses and
lines) and return arrays of matching leading shape.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.line import wrap_angle

__all__ = [
    "adjoint_pose2",
    "chain_covariance",
    "compose_covariance",
    "line_residual",
    "line_to_child",
    "line_to_parent",
    "pose_between",
    "pose_compose",
    "pose_exp",
    "pose_inverse",
    "pose_log",
    "pose_retract",
    "predict_line_measurement",
    "right_jacobian_pose2",
    "wrap_angle",
    "wrap_angle_compiled",
]


@njit(cache=True, nogil=True)
def wrap_angle_compiled(a: float) -> float:  # pragma: no cover - compiled
    """:func:`linefit.line.wrap_angle` of one float in compiled code (the same operations)."""
    return math.pi - (math.pi - a) % (2.0 * math.pi)


FloatArray = NDArray[np.float64]


def _as3(a: FloatArray | list[float] | tuple[float, ...]) -> FloatArray:
    arr = np.asarray(a, dtype=float)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) array, got shape {arr.shape}")
    return arr


# ---------------------------------------------------------------------------------------------
# SE(2)
# ---------------------------------------------------------------------------------------------
def _wrap(angle: float) -> float:
    """:func:`wrap_angle` of one float (the same operations, without array overhead)."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


def _last_axis(*columns: FloatArray) -> FloatArray:
    """``np.stack(columns, axis=-1)`` for same-shape arrays, without its overhead (hot path)."""
    first = np.asarray(columns[0])
    out = np.empty((*first.shape, len(columns)))
    for i, c in enumerate(columns):
        out[..., i] = c
    return out


def pose_compose(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a · b`` for poses ``(..., 3)``: ``pose_x_y · pose_y_z = pose_x_z``."""
    a = _as3(a)
    b = _as3(b)
    if a.shape == b.shape == (3,):  # one pose: plain floats (a fifth of the time)
        (ax, ay, at), (bx, by, bt) = a.tolist(), b.tolist()
        ca, sa = math.cos(at), math.sin(at)
        return np.array([ax + ca * bx - sa * by, ay + sa * bx + ca * by, _wrap(at + bt)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    t = np.asarray(wrap_angle(a[..., 2] + b[..., 2]))
    return _last_axis(x, y, t)


def pose_inverse(a: FloatArray) -> FloatArray:
    """``a⁻¹`` for poses ``(..., 3)``: ``pose_x_y⁻¹ = pose_y_x``."""
    a = _as3(a)
    if a.shape == (3,):
        ax, ay, at = a.tolist()
        ca, sa = math.cos(at), math.sin(at)
        return np.array([-ca * ax - sa * ay, sa * ax - ca * ay, _wrap(-at)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return _last_axis(x, y, np.asarray(wrap_angle(-a[..., 2])))


def pose_between(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a⁻¹ · b``: pose ``b`` expressed in the frame of pose ``a`` (the paper's ``g_ij``)."""
    return pose_compose(pose_inverse(a), b)


def pose_exp(xi: FloatArray) -> FloatArray:
    """SE(2) exponential of tangent vectors ``ξ = (v_x, v_y, ω)`` (as ``gtsam.Pose2.Expmap``)."""
    xi = _as3(xi)
    if xi.shape == (3,):
        vx, vy, om = xi.tolist()
        if abs(om) < 1e-9:
            a1, b1 = 1.0 - om**2 / 6.0, om / 2.0
        else:
            a1, b1 = math.sin(om) / om, (1.0 - math.cos(om)) / om
        return np.array([a1 * vx - b1 * vy, b1 * vx + a1 * vy, _wrap(om)])
    w = xi[..., 2]
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    sin_w, cos_w = np.sin(w), np.cos(w)
    a = np.where(small, 1.0 - w**2 / 6.0, sin_w / w_safe)
    b = np.where(small, w / 2.0, (1.0 - cos_w) / w_safe)
    x = a * xi[..., 0] - b * xi[..., 1]
    y = b * xi[..., 0] + a * xi[..., 1]
    return _last_axis(x, y, np.asarray(wrap_angle(w)))


def pose_log(pose: FloatArray) -> FloatArray:
    """SE(2) logarithm, inverse of :func:`pose_exp` (same as ``gtsam.Pose2.Logmap``)."""
    pose = _as3(pose)
    if pose.shape == (3,):
        px, py, om = pose.tolist()
        h = om / 2.0
        hc = 1.0 - om**2 / 12.0 if abs(om) < 1e-9 else h / math.tan(h)
        return np.array([hc * px + h * py, -h * px + hc * py, om])
    w = pose[..., 2]
    small = np.abs(w) < 1e-9
    half = w / 2.0
    # V^{-1} = [[h·cot h, h], [−h, h·cot h]] with h = w/2
    tan_half = np.tan(np.where(small, 1.0, half))
    hcot = np.where(small, 1.0 - w**2 / 12.0, half / np.where(small, 1.0, tan_half))
    vx = hcot * pose[..., 0] + half * pose[..., 1]
    vy = -half * pose[..., 0] + hcot * pose[..., 1]
    return _last_axis(vx, vy, w)


def pose_retract(pose: FloatArray, xi: FloatArray) -> FloatArray:
    """``pose ⊕ ξ = pose · Exp(ξ)`` (right perturbation, GTSAM's ``Pose2.retract``)."""
    return pose_compose(pose, pose_exp(xi))


def pose_interpolate(a: FloatArray, b: FloatArray, fraction: float) -> FloatArray:
    """The pose ``fraction`` of the way from ``a`` to ``b``, shape ``(3,)``.

    Linear in x and y; the heading along the shorter arc from ``a``'s, wrapped to
    ``[−π, π]`` (``math.remainder``).  Used to read odometry between two logged poses.
    """
    pa = np.asarray(a, dtype=float)
    pb = np.asarray(b, dtype=float)
    f = float(fraction)
    dtheta = math.remainder(float(pb[2] - pa[2]), math.tau)
    theta = math.remainder(float(pa[2]) + f * dtheta, math.tau)
    return np.array([pa[0] + f * (pb[0] - pa[0]), pa[1] + f * (pb[1] - pa[1]), theta])


def adjoint_pose2(pose: FloatArray) -> FloatArray:
    """SE(2) adjoint of poses ``(..., 3)``: ``(..., 3, 3)``."""
    p = np.asarray(pose, dtype=float)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    Ad = np.zeros((*p.shape[:-1], 3, 3))
    Ad[..., 0, 0] = c
    Ad[..., 0, 1] = -s
    Ad[..., 1, 0] = s
    Ad[..., 1, 1] = c
    Ad[..., 0, 2] = p[..., 1]
    Ad[..., 1, 2] = -p[..., 0]
    Ad[..., 2, 2] = 1.0
    return Ad


def compose_covariance(cov_a: FloatArray, b: FloatArray, cov_b: FloatArray) -> FloatArray:
    """Covariance ``(3, 3)`` of ``a ∘ b`` from those of ``a`` and of ``b`` (independent).

    Right perturbations, each in its own pose's frame: ``a Exp(ξ) ∘ b = a ∘ b Exp(Ad(b⁻¹) ξ)``,
    so ``Cov = Ad(b⁻¹) Cov_a Ad(b⁻¹)ᵀ + Cov_b``.
    """
    Ad = adjoint_pose2(pose_inverse(np.asarray(b, dtype=float)))
    return np.asarray(Ad @ np.asarray(cov_a, dtype=float) @ Ad.T + np.asarray(cov_b, dtype=float))


def chain_covariance(
    cov: FloatArray | None, step: FloatArray, step_cov: FloatArray | None
) -> FloatArray | None:
    """A running composed covariance (:func:`compose_covariance`) carried one step on.

    ``cov`` is the covariance of the motion so far (None: unknown); ``step`` ``(3,)`` and
    ``step_cov`` ``(3, 3)`` the next step and its covariance (None: unknown).  Once any step
    lacks a covariance the result stays None until the caller starts a new chain.
    """
    if cov is None or step_cov is None:
        return None
    return compose_covariance(cov, step, step_cov)


def right_jacobian_pose2(xi: FloatArray) -> FloatArray:
    """Right Jacobian ``J_r(ξ)`` of SE(2)'s exponential (Solà et al. 2018, Eq. 163), vectorised."""
    x = np.asarray(xi, dtype=float)
    v1, v2, w = x[..., 0], x[..., 1], x[..., 2]
    small = np.abs(w) < 1e-4
    ws = np.where(small, 1.0, w)
    s, c = np.sin(w), np.cos(w)
    a = np.where(small, 1.0 - w**2 / 6.0, s / ws)
    b = np.where(small, w / 2.0 - w**3 / 24.0, (1.0 - c) / ws)
    j02 = np.where(small, -v2 / 2.0 + v1 * w / 6.0, (w * v1 - v2 + v2 * c - v1 * s) / ws**2)
    j12 = np.where(small, v1 / 2.0 + v2 * w / 6.0, (v1 + w * v2 - v1 * c - v2 * s) / ws**2)
    J = np.zeros((*x.shape[:-1], 3, 3))
    J[..., 0, 0] = a
    J[..., 0, 1] = b
    J[..., 1, 0] = -b
    J[..., 1, 1] = a
    J[..., 0, 2] = j02
    J[..., 1, 2] = j12
    J[..., 2, 2] = 1.0
    return J


# ---------------------------------------------------------------------------------------------
# Lines across frames (Eq. 30 and its inverse)
# ---------------------------------------------------------------------------------------------
def _normalise_with_jacobians(
    line: FloatArray, jacobians: tuple[FloatArray, ...]
) -> tuple[FloatArray, tuple[FloatArray, ...]]:
    """Normal form of ``line`` (..., 3); rows r and s of each Jacobian flip sign with it."""
    flipped = line[..., 0] < 0.0
    sign = np.where(flipped, -1.0, 1.0)
    out = np.stack(
        [
            sign * line[..., 0],
            np.asarray(wrap_angle(line[..., 1] + np.where(flipped, np.pi, 0.0))),
            sign * line[..., 2],
        ],
        axis=-1,
    )
    row_sign = np.stack([sign, np.ones_like(sign), sign], axis=-1)[..., :, None]
    return out, tuple(J * row_sign for J in jacobians)


def line_to_parent(
    line_j: FloatArray, pose_i_j: FloatArray, normal_form: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Move lines from frame ``j`` to frame ``i`` (the paper's Eq. 30).

    Parameters
    ----------
    line_j : ndarray, shape (..., 3)
        Lines ``(r, α, s)`` in frame ``j``.
    pose_i_j : ndarray, shape (..., 3)
        Pose of frame ``j`` in frame ``i`` (the paper's ``ĝ_ij = (x, y, γ)``).
    normal_form : bool
        Return the result with ``r ≥ 0``, ``α ∈ (−π, π]`` (Jacobian rows follow the flip).
        Otherwise ``α_i = wrap(α_j + γ)`` and ``r`` keeps its sign.

    Returns
    -------
    line_i : ndarray, shape (..., 3)
    B : ndarray, shape (..., 3, 3)
        ``∂line_i / ∂line_j``.
    K : ndarray, shape (..., 3, 3)
        ``∂line_i / ∂ξ`` for the right perturbation ``pose_i_j · Exp(ξ)``.
    """
    line_j = _as3(line_j)
    pose_i_j = _as3(pose_i_j)
    line_j, pose_i_j = np.broadcast_arrays(line_j, pose_i_j)
    x, y, g = pose_i_j[..., 0], pose_i_j[..., 1], pose_i_j[..., 2]
    r_j, a_j, s_j = line_j[..., 0], line_j[..., 1], line_j[..., 2]
    a_i = a_j + g
    ca_i, sa_i = np.cos(a_i), np.sin(a_i)
    ca_j, sa_j = np.cos(a_j), np.sin(a_j)
    dr_da = -x * sa_i + y * ca_i
    ds_da = -x * ca_i - y * sa_i
    line_i = np.stack([r_j + x * ca_i + y * sa_i, np.asarray(wrap_angle(a_i)), s_j + dr_da], -1)
    zeros, ones = np.zeros_like(x), np.ones_like(x)
    B = np.stack(
        [
            np.stack([ones, dr_da, zeros], -1),
            np.stack([zeros, ones, zeros], -1),
            np.stack([zeros, ds_da, ones], -1),
        ],
        -2,
    )
    K = np.stack(
        [
            np.stack([ca_j, sa_j, dr_da], -1),
            np.stack([zeros, zeros, ones], -1),
            np.stack([-sa_j, ca_j, ds_da], -1),
        ],
        -2,
    )
    if normal_form:
        line_i, (B, K) = _normalise_with_jacobians(line_i, (B, K))
    return line_i, B, K


def line_to_child(
    line_i: FloatArray, pose_i_j: FloatArray, normal_form: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Move lines from frame ``i`` to frame ``j`` (the inverse of Eq. 30).

    Parameters
    ----------
    line_i : ndarray, shape (..., 3)
        Lines ``(r, α, s)`` in frame ``i``.
    pose_i_j : ndarray, shape (..., 3)
        Pose of frame ``j`` in frame ``i``.
    normal_form : bool
        As in :func:`line_to_parent`.

    Returns
    -------
    line_j : ndarray, shape (..., 3)
    J_line : ndarray, shape (..., 3, 3)
        ``∂line_j / ∂line_i``.
    J_pose : ndarray, shape (..., 3, 3)
        ``∂line_j / ∂ξ`` for the right perturbation ``pose_i_j · Exp(ξ)``:
        ``[[−cos α_j, −sin α_j, 0], [0, 0, −1], [sin α_j, −cos α_j, 0]]``.
    """
    line_i = _as3(line_i)
    pose_i_j = _as3(pose_i_j)
    line_i, pose_i_j = np.broadcast_arrays(line_i, pose_i_j)
    x, y, g = pose_i_j[..., 0], pose_i_j[..., 1], pose_i_j[..., 2]
    r_i, a_i, s_i = line_i[..., 0], line_i[..., 1], line_i[..., 2]
    ca_i, sa_i = np.cos(a_i), np.sin(a_i)
    a_j = a_i - g
    ca_j, sa_j = np.cos(a_j), np.sin(a_j)
    line_j = np.stack(
        [
            r_i - x * ca_i - y * sa_i,
            np.asarray(wrap_angle(a_j)),
            s_i + x * sa_i - y * ca_i,
        ],
        -1,
    )
    zeros, ones = np.zeros_like(x), np.ones_like(x)
    J_line = np.stack(
        [
            np.stack([ones, x * sa_i - y * ca_i, zeros], -1),
            np.stack([zeros, ones, zeros], -1),
            np.stack([zeros, x * ca_i + y * sa_i, ones], -1),
        ],
        -2,
    )
    J_pose = np.stack(
        [
            np.stack([-ca_j, -sa_j, zeros], -1),
            np.stack([zeros, zeros, -ones], -1),
            np.stack([sa_j, -ca_j, zeros], -1),
        ],
        -2,
    )
    if normal_form:
        line_j, (J_line, J_pose) = _normalise_with_jacobians(line_j, (J_line, J_pose))
    return line_j, J_line, J_pose


def predict_line_measurement(
    landmark_r_alpha: FloatArray, pose_world_laser: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predict the measured ``(r, α)`` of world lines seen from laser poses (measurement model).

    This is the ``(r, α)`` part of :func:`line_to_child` with ``i = world``, ``j = laser``,
    without normalisation (``r`` may come out negative; pair it with :func:`line_residual`).

    Parameters
    ----------
    landmark_r_alpha : ndarray, shape (..., 2)
        World lines ``(r_w, α_w)``; ``r_w`` may be negative (signed parameterisation).
    pose_world_laser : ndarray, shape (..., 3)
        Laser poses in the world.

    Returns
    -------
    z_pred : ndarray, shape (..., 2)
        ``(r_w − x cos α_w − y sin α_w,  α_w − θ)`` with the angle wrapped.
    H_pose : ndarray, shape (..., 2, 3)
        ``∂z/∂ξ`` (right perturbation): ``[[−cos α_s, −sin α_s, 0], [0, 0, −1]]``.
    H_landmark : ndarray, shape (..., 2, 2)
        ``∂z/∂(r_w, α_w)``: ``[[1, x sin α_w − y cos α_w], [0, 1]]``.
    """
    lm = np.asarray(landmark_r_alpha, dtype=float)
    pose = _as3(pose_world_laser)
    shape = np.broadcast_shapes(lm.shape[:-1], pose.shape[:-1])
    lm = np.broadcast_to(lm, (*shape, 2))
    pose = np.broadcast_to(pose, (*shape, 3))
    r_w, a_w = lm[..., 0], lm[..., 1]
    x, y, th = pose[..., 0], pose[..., 1], pose[..., 2]
    ca_w, sa_w = np.cos(a_w), np.sin(a_w)
    a_s = a_w - th
    ca_s, sa_s = np.cos(a_s), np.sin(a_s)
    z = _last_axis(r_w - x * ca_w - y * sa_w, np.asarray(wrap_angle(a_s)))
    H_pose = np.zeros((*shape, 2, 3))
    H_pose[..., 0, 0] = -ca_s
    H_pose[..., 0, 1] = -sa_s
    H_pose[..., 1, 2] = -1.0
    H_lm = np.zeros((*shape, 2, 2))
    H_lm[..., 0, 0] = 1.0
    H_lm[..., 0, 1] = x * sa_w - y * ca_w
    H_lm[..., 1, 1] = 1.0
    return z, H_pose, H_lm


def line_residual(z_pred: FloatArray, z_measured: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Residual ``h − z`` between predicted and measured ``(r, α)``, same representative.

    The prediction is replaced by ``(−r, α + π)`` where its normal points away from the
    measurement's (``|wrap(α_pred − α_meas)| > π/2``), so a line through the sensor or a
    world line through the origin never produces a 2π jump or a sign jump in the residual.

    Returns
    -------
    residual : ndarray, shape (..., 2)
        ``(r_pred' − r_meas, wrap(α_pred' − α_meas))``.
    sign : ndarray, shape (...)
        +1 or −1: multiply the ``r`` row of the prediction's Jacobians by it.
    """
    zp = np.asarray(z_pred, dtype=float)
    zm = np.asarray(z_measured, dtype=float)
    d_alpha = np.asarray(wrap_angle(zp[..., 1] - zm[..., 1]))
    flip = np.abs(d_alpha) > np.pi / 2.0
    sign = np.where(flip, -1.0, 1.0)
    d_alpha = np.asarray(wrap_angle(np.where(flip, d_alpha + np.pi, d_alpha)))
    return _last_axis(sign * zp[..., 0] - zm[..., 0], d_alpha), sign
