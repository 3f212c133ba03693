"""State augmentation: new line landmarks from measured lines (the paper's Eq. 30).

A line measured in the laser frame, ``z = (r_s, α_s)`` with covariance ``R``, becomes the world
line ``l = g(pose, z)`` by Eq. 30 (:func:`slam.geometry.line_to_parent`).  With

``G_z = ∂l/∂z = B[:2, :2]``  and  ``G_x = ∂l/∂(x, y, θ) = K[:2, :] · J(θ)⁻¹``

(``K`` is Eq. 30's Jacobian for the right pose perturbation, converted to the filter's additive
pose error, see :mod:`slam.ekf.conventions`) the augmented covariance is

``P_ll = G_x P_xx G_xᵀ + G_z R G_zᵀ``,  ``P_l· = G_x P_x·``  (cross-covariance with the whole
state through the pose rows).  Several lines of one scan are added together: they are correlated
through the pose (``G_x,a P_xx G_x,bᵀ``) but their measurement noises are independent.

The new landmark is stored in normal form (``r ≥ 0``); later updates may move it to a negative
``r`` (the parameterisation is signed).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slam.ekf.conventions import state_jacobian_from_tangent
from slam.geometry import line_to_parent

__all__ = ["augment_state", "landmark_from_measurement"]

FloatArray = NDArray[np.float64]


def landmark_from_measurement(
    z_r_alpha: FloatArray, pose_world_laser: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """World lines from laser-frame measurements, with their Jacobians.

    Parameters
    ----------
    z_r_alpha : ndarray, shape (q, 2)
        Measured lines ``(r_s, α_s)`` in the laser frame.
    pose_world_laser : ndarray, shape (3,)
        The laser pose (filter state).

    Returns
    -------
    landmarks : ndarray, shape (q, 2)
        World lines ``(r_w, α_w)`` in normal form.
    G_x : ndarray, shape (q, 2, 3)
        ``∂l/∂(x, y, θ)`` (additive pose error).
    G_z : ndarray, shape (q, 2, 2)
        ``∂l/∂z``.
    """
    z = np.asarray(z_r_alpha, dtype=float).reshape(-1, 2)
    pose = np.asarray(pose_world_laser, dtype=float).reshape(3)
    line_s = np.concatenate([z, np.zeros((z.shape[0], 1))], axis=1)
    line_w, B, K = line_to_parent(line_s, pose[None, :], normal_form=True)
    G_x = state_jacobian_from_tangent(K[:, :2, :], pose[2])
    G_z = B[:, :2, :2]
    return line_w[:, :2], G_x, G_z


def augment_state(
    x: FloatArray, P: FloatArray, z_r_alpha: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Append landmarks initialised from measurements to the state and its covariance.

    Parameters
    ----------
    x : ndarray, shape (n,)
        State ``(x, y, θ, r_1, α_1, …)``; the pose is ``x[:3]``.
    P : ndarray, shape (n, n)
        Its covariance.
    z_r_alpha : ndarray, shape (q, 2)
        Measurements that start new landmarks.
    R : ndarray, shape (q, 2, 2)
        Their covariances.

    Returns
    -------
    x_new : ndarray, shape (n + 2q,)
    P_new : ndarray, shape (n + 2q, n + 2q)
    """
    n = x.shape[0]
    lm, G_x, G_z = landmark_from_measurement(z_r_alpha, x[:3])
    q = lm.shape[0]
    if q == 0:
        return x.copy(), P.copy()
    Gx = G_x.reshape(2 * q, 3)
    cross = Gx @ P[:3, :]  # (2q, n)
    block = Gx @ P[:3, :3] @ Gx.T
    noise = G_z @ np.asarray(R, dtype=float) @ np.swapaxes(G_z, -1, -2)
    for i in range(q):
        block[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] += noise[i]
    P_new = np.empty((n + 2 * q, n + 2 * q))
    P_new[:n, :n] = P
    P_new[n:, :n] = cross
    P_new[:n, n:] = cross.T
    P_new[n:, n:] = 0.5 * (block + block.T)
    return np.concatenate([x, lm.reshape(-1)]), P_new
