"""Measurement update of the EKF: line model, sparse Joseph form and filterpy's reference update.

Notation (filterpy's): ``x`` state ``(n,)``, ``P`` covariance ``(n, n)``, ``z`` stacked
measurements ``(2m,)``, ``H`` Jacobian ``(2m, n)``, ``R`` noise ``(2m, 2m)``, ``y = z − h(x)``
the innovation, ``S = H P Hᵀ + R`` its covariance, ``K = P Hᵀ S⁻¹`` the gain.

Measurement model: a landmark ``l_j = (r_j, α_j)`` (world) seen from the laser pose predicts
``h = (r_j − x cos α_j − y sin α_j, α_j − θ)`` (:func:`slam.geometry.predict_line_measurement`).
The innovation is formed with :func:`slam.geometry.line_residual`, which picks the
representative ``(−r, α + π)`` of the prediction when its normal points away from the
measurement's and wraps the angle; the ``r`` row of ``H`` is multiplied by the returned sign.
Pose columns of ``H`` are the right-perturbation Jacobians converted to the filter's additive
pose error (:mod:`slam.ekf.conventions`).

Joseph form, ``P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ``, evaluated without forming ``I − KH``:
``H`` touches only the pose and the observed landmarks (columns ``cols``), so with
``A = (I − KH) P = P − K (P Hᵀ)ᵀ`` and ``A Hᵀ = A[:, cols] H_subᵀ``,
``P⁺ = A − (A Hᵀ − K R) Kᵀ``, the exact Joseph product in ``O(n² m)`` instead of ``O(n³)``
(the bracket vanishes for the optimal gain up to rounding; keeping it is what makes the Joseph
form insensitive to errors in ``K``).  :func:`filterpy_update` runs the same update through
``filterpy.kalman.ExtendedKalmanFilter.update`` (dense ``O(n³)``) as the reference.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from filterpy.kalman import ExtendedKalmanFilter
from numpy.typing import NDArray

from slam.ekf.conventions import state_jacobian_from_tangent
from slam.errors import EstimationError
from slam.geometry import line_residual, predict_line_measurement

__all__ = [
    "MeasurementStack",
    "filterpy_update",
    "joseph_update",
    "line_measurements",
    "observability_constrained",
    "unobservable_directions",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class MeasurementStack:
    """Line measurements of matched landmarks, linearised at one state.

    Attributes
    ----------
    y : ndarray, shape (2m,)
        Innovation ``z − h(x)`` (same representative, angle wrapped).
    H_sub : ndarray, shape (2m, k)
        The non-zero columns of ``H``.
    cols : ndarray of int, shape (k,)
        Which state columns ``H_sub`` fills (``H[:, cols] = H_sub``; repeated columns add).
    R : ndarray, shape (2m, 2m)
        Block-diagonal measurement noise.
    """

    def __init__(self, y: FloatArray, H_sub: FloatArray, cols: IntArray, R: FloatArray):
        self.y = y
        self.H_sub = H_sub
        self.cols = cols
        self.R = R

    def dense_H(self, n: int) -> FloatArray:
        """The full ``H`` of shape ``(2m, n)``."""
        H = np.zeros((self.H_sub.shape[0], n))
        np.add.at(H.T, self.cols, self.H_sub.T)
        return H


def _block_diag2(blocks: FloatArray) -> FloatArray:
    """Block-diagonal matrix ``(2m, 2m)`` from ``(m, 2, 2)`` blocks."""
    m = blocks.shape[0]
    out = np.zeros((m, 2, m, 2))
    idx = np.arange(m)
    out[idx, :, idx, :] = blocks
    return out.reshape(2 * m, 2 * m)


def line_measurements(
    x: FloatArray,
    landmark_idx: IntArray,
    z_r_alpha: FloatArray,
    R: FloatArray,
    linearization: tuple[FloatArray, FloatArray] | None = None,
) -> MeasurementStack:
    """Linearise the line measurement model at ``x`` for measured landmarks.

    Parameters
    ----------
    x : ndarray, shape (n,)
        State ``(x, y, θ, r_1, α_1, …)``.
    landmark_idx : ndarray of int, shape (m,)
        Landmark (0-based) that measurement ``i`` observes.
    z_r_alpha : ndarray, shape (m, 2)
        Measured ``(r, α)`` in the laser frame.
    R : ndarray, shape (m, 2, 2)
        Their covariances.
    linearization : (ndarray (3,), ndarray (m, 2)), optional
        The pose and the landmarks at which ``H`` is evaluated (the first-estimates Jacobians
        of :class:`slam.ekf.EkfConfig` ``jacobians``); the innovation is still ``z − h(x)``.
        Default: ``x`` itself.

    Returns
    -------
    MeasurementStack
    """
    idx = np.asarray(landmark_idx, dtype=np.intp).reshape(-1)
    m = idx.shape[0]
    pose = x[:3]
    lm = np.stack([x[3 + 2 * idx], x[4 + 2 * idx]], axis=-1)
    z_pred, H_xi, H_l = predict_line_measurement(lm, pose[None, :])
    res, sign = line_residual(z_pred, np.asarray(z_r_alpha, dtype=float).reshape(m, 2))
    if linearization is not None:
        pose = np.asarray(linearization[0], dtype=float).reshape(3)
        lm_lin = np.asarray(linearization[1], dtype=float).reshape(m, 2)
        _, H_xi, H_l = predict_line_measurement(lm_lin, pose[None, :])
    H_x = state_jacobian_from_tangent(H_xi, pose[2])
    H_x[:, 0, :] *= sign[:, None]
    H_l = H_l.copy()
    H_l[:, 0, :] *= sign[:, None]
    H_sub = np.concatenate([H_x.reshape(2 * m, 3), _block_diag2(H_l)], axis=1)
    cols = np.concatenate([np.arange(3), np.stack([3 + 2 * idx, 4 + 2 * idx], -1).reshape(-1)])
    R_big = _block_diag2(np.asarray(R, dtype=float).reshape(m, 2, 2))
    return MeasurementStack(-res.reshape(-1), H_sub, cols.astype(np.intp), R_big)


def unobservable_directions(
    pose_world_laser: FloatArray, landmarks_alpha: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The directions no line measurement sees: moving the world by ``(dx, dy)``, turning it.

    Parameters
    ----------
    pose_world_laser : ndarray, shape (3,)
    landmarks_alpha : ndarray, shape (m,)
        The landmarks' ``α``.

    Returns
    -------
    N_pose : ndarray, shape (3, 3)
        Columns ``dx``, ``dy``, ``dφ`` (a turn about the world origin) on ``(x, y, θ)``:
        ``[[1, 0, −y], [0, 1, x], [0, 0, 1]]``.
    N_landmarks : ndarray, shape (m, 2, 3)
        The same on each ``(r, α)``: ``[[cos α, sin α, 0], [0, 0, 1]]``.
    """
    pose = np.asarray(pose_world_laser, dtype=float).reshape(3)
    alpha = np.asarray(landmarks_alpha, dtype=float).reshape(-1)
    N_pose = np.eye(3)
    N_pose[0, 2] = -pose[1]
    N_pose[1, 2] = pose[0]
    N_lm = np.zeros((alpha.shape[0], 2, 3))
    N_lm[:, 0, 0] = np.cos(alpha)
    N_lm[:, 0, 1] = np.sin(alpha)
    N_lm[:, 1, 2] = 1.0
    return N_pose, N_lm


def observability_constrained(
    meas: MeasurementStack, pose_world_laser: FloatArray, landmarks_alpha: FloatArray
) -> MeasurementStack:
    """The Jacobians closest to ``meas``'s that see none of the unobservable directions.

    Each measurement's rows ``H_i`` (pose and its landmark) are replaced by the closest (in the
    Frobenius norm) ``H_i*`` with ``H_i* U_i = 0``, ``U_i`` the rows of
    :func:`unobservable_directions` for the pose and that landmark: ``H_i* = H_i (I − U_i
    U_i⁺)``: the observability constraint of Huang, Mourikis & Roumeliotis (2010) met by the
    projection of Hesch, Kottas, Bowman & Roumeliotis (2014), here for line landmarks.

    Parameters
    ----------
    meas : MeasurementStack
        From :func:`line_measurements` (``m`` measurements of distinct landmarks).
    pose_world_laser : ndarray, shape (3,)
        The pose the unobservable directions are taken at (the propagated pose).
    landmarks_alpha : ndarray, shape (m,)
        ``α`` of each measurement's landmark for those directions (its first estimate).
    """
    N_pose, N_lm = unobservable_directions(pose_world_laser, landmarks_alpha)
    m = N_lm.shape[0]
    H_sub = meas.H_sub.copy()
    for i in range(m):
        rows = slice(2 * i, 2 * i + 2)
        cols = np.r_[0:3, 3 + 2 * i, 4 + 2 * i]
        U = np.vstack([N_pose, N_lm[i]])  # (5, 3)
        Hi = H_sub[rows][:, cols]
        Hi = Hi - Hi @ U @ np.linalg.solve(U.T @ U, U.T)
        H_sub[rows.start : rows.stop, cols] = Hi
    return MeasurementStack(meas.y, H_sub, meas.cols, meas.R)


def joseph_update(
    x: FloatArray, P: FloatArray, meas: MeasurementStack
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """EKF update in Joseph form exploiting the sparsity of ``H`` (cost ``O(n² m)``).

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    meas : MeasurementStack

    Returns
    -------
    x_post : ndarray, shape (n,)
        ``x + K y`` (angles not wrapped; the caller knows which entries are angles).
    P_post : ndarray, shape (n, n)
        Joseph-form posterior covariance, symmetrised.
    S : ndarray, shape (2m, 2m)
        Innovation covariance.
    K : ndarray, shape (n, 2m)
        Gain.
    """
    cols, H_sub, R = meas.cols, meas.H_sub, meas.R
    PHt = P[:, cols] @ H_sub.T  # (n, 2m)
    S = H_sub @ PHt[cols, :] + R
    S = 0.5 * (S + S.T)
    try:
        factor = scipy.linalg.cho_factor(S)
    except np.linalg.LinAlgError as exc:
        raise EstimationError("EKF update: innovation covariance is not positive definite") from exc
    K = scipy.linalg.cho_solve(factor, PHt.T).T  # (n, 2m)
    x_post = x + K @ meas.y
    A = K @ PHt.T
    np.subtract(P, A, out=A)  # A = (I − KH) P
    D = A[:, cols] @ H_sub.T  # (I − KH) P Hᵀ
    D -= K @ R
    A -= D @ K.T  # (I − KH) P (I − KH)ᵀ + K R Kᵀ
    A += A.T
    A *= 0.5
    P_post = A
    return x_post, P_post, S, K


def constrain_and_remove(
    x: FloatArray, P: FloatArray, meas: MeasurementStack, remove: IntArray
) -> tuple[FloatArray, FloatArray]:
    """Condition the state on an exact constraint ``H x = y`` (``R = 0``), then delete entries.

    Used to fuse two landmarks (``l_i − l_j = 0``, then ``l_j`` removed).  With
    ``U = P Hᵀ``, ``S = H U = L Lᵀ`` and ``G = U L⁻ᵀ`` the conditional covariance is
    ``P − G Gᵀ`` (exactly symmetric as computed), evaluated only on the entries kept, so the
    deletion and the update are one pass over ``P`` plus one rank-``2m`` product instead of a
    Joseph update followed by a copy.

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    meas : MeasurementStack
        The constraint (its ``R`` is ignored: the constraint is exact).
    remove : ndarray of int
        State entries deleted after conditioning.

    Returns
    -------
    x_post : ndarray, shape (n − len(remove),)
    P_post : ndarray, shape (n − len(remove), n − len(remove))

    Raises
    ------
    EstimationError
        When ``H P Hᵀ`` is not positive definite.
    """
    cols, H_sub = meas.cols, meas.H_sub
    U = P[:, cols] @ H_sub.T  # (n, 2m)
    S = H_sub @ U[cols, :]
    S = 0.5 * (S + S.T)
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError as exc:
        raise EstimationError("EKF constraint: H P Hᵀ is not positive definite") from exc
    G = scipy.linalg.solve_triangular(L, U.T, lower=True).T  # U L⁻ᵀ, (n, 2m)
    x_post = x + G @ scipy.linalg.solve_triangular(L, meas.y, lower=True)
    keep = np.ones(x.shape[0], dtype=bool)
    keep[np.asarray(remove, dtype=np.intp)] = False
    G_k = G[keep]
    P_post = P[np.ix_(keep, keep)]
    P_post -= G_k @ G_k.T
    return x_post[keep], P_post


def filterpy_update(
    x: FloatArray,
    P: FloatArray,
    landmark_idx: IntArray,
    z_r_alpha: FloatArray,
    R: FloatArray,
    H: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The same update through ``filterpy.kalman.ExtendedKalmanFilter.update`` (dense, O(n³)).

    The measurement function, its Jacobian and the residual are handed to filterpy as
    callables; filterpy forms ``H``, ``S``, ``K`` and the Joseph-form ``P`` itself.  ``H``
    (dense, ``(2m, n)``) replaces the Jacobian at ``x`` (the first-estimates or
    observability-constrained Jacobians of ``EkfConfig.jacobians``).

    Returns
    -------
    x_post, P_post, S, K
        As :func:`joseph_update`.
    """
    n = x.shape[0]
    idx = np.asarray(landmark_idx, dtype=np.intp).reshape(-1)
    z = np.asarray(z_r_alpha, dtype=float).reshape(-1, 2)
    R_arr = np.asarray(R, dtype=float).reshape(-1, 2, 2)

    def hx(state: FloatArray) -> FloatArray:
        lm = np.stack([state[3 + 2 * idx], state[4 + 2 * idx]], axis=-1)
        z_pred, _, _ = predict_line_measurement(lm, state[None, :3])
        return np.asarray(z_pred.reshape(-1))

    def h_jacobian(state: FloatArray) -> FloatArray:
        if H is not None:
            return H
        return line_measurements(state, idx, z, R_arr).dense_H(n)

    def residual(z_flat: FloatArray, h_flat: FloatArray) -> FloatArray:
        res, _ = line_residual(h_flat.reshape(-1, 2), z_flat.reshape(-1, 2))
        return np.asarray(-res.reshape(-1))

    kf = ExtendedKalmanFilter(dim_x=n, dim_z=2 * idx.shape[0])
    kf.x = x.astype(float).copy()
    kf.P = P.astype(float).copy()
    R_big = _block_diag2(R_arr)
    kf.update(z.reshape(-1), h_jacobian, hx, R=R_big, residual=residual)
    P_post = 0.5 * (kf.P + kf.P.T)
    return np.asarray(kf.x, dtype=float), P_post, np.asarray(kf.S), np.asarray(kf.K)
