"""Fusing EKF landmarks that turned out to be the same line.

Two landmarks ``l_i``, ``l_j`` are candidates when their segments overlap along the line
(within ``association.overlap_margin_m``) and the residual ``l_i − l_j`` (same representative,
:func:`slam.geometry.line_residual`) passes the χ² test at ``merge_probability`` on their joint
marginal.  The fusion is the EKF update with the exact constraint ``l_i − l_j = 0`` (``R = 0``),
after which ``l_j`` equals ``l_i`` and is deleted (marginalised); both in one pass
(:func:`slam.ekf.update.constrain_and_remove`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.association import individual_gate
from slam.ekf.extents import LandmarkExtents
from slam.ekf.update import MeasurementStack, constrain_and_remove
from slam.errors import EstimationError
from slam.geometry import line_residual

__all__ = ["merge_compatible_landmarks", "wrap_state_angles"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def wrap_state_angles(x: FloatArray) -> None:
    """Wrap the pose angle and the landmarks' ``α`` of a state ``(3 + 2M,)`` in place."""
    x[2] = wrap_angle(x[2])
    x[4::2] = np.asarray(wrap_angle(x[4::2]))


def _pairs(m: int, touched: set[int] | None) -> tuple[IntArray, IntArray]:
    """Landmark pairs ``(i, j)`` to test: all, or those involving a touched landmark (once)."""
    if touched is None:
        i, j = np.triu_indices(m, 1)
        return i.astype(np.intp), j.astype(np.intp)
    t = np.array(sorted(c for c in touched if c < m), dtype=np.intp)
    is_t = np.zeros(m, dtype=bool)
    is_t[t] = True
    ii = np.repeat(t, m)
    jj = np.tile(np.arange(m), t.size)
    sel = (jj != ii) & (~is_t[jj] | (ii < jj))  # each pair once
    return ii[sel], jj[sel]


def merge_compatible_landmarks(
    x: FloatArray,
    P: FloatArray,
    extents: LandmarkExtents,
    n_obs: list[int],
    merge_probability: float,
    overlap_margin_m: float,
    candidates: IntArray | None = None,
    first_estimates: list[FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray, int]:
    """Fuse compatible landmark pairs greedily by increasing ``D²``, one at a time.

    Parameters
    ----------
    x : ndarray, shape (3 + 2M,)
        Filter state (pose, then landmarks ``(r, α)``).
    P : ndarray, shape (3 + 2M, 3 + 2M)
        Its covariance.
    extents : LandmarkExtents
        Seen pieces of each landmark; updated in place (the kept landmark absorbs the pieces
        of the removed one).
    n_obs : list of int
        Measurements per landmark; updated in place (summed, the removed entry deleted).
    merge_probability : float
        χ² gate probability of the test on ``l_i − l_j``.
    overlap_margin_m : float
        Largest gap (m) between the two landmarks' extents along the line.
    candidates : ndarray of int, optional
        Test only pairs that involve one of these landmarks (e.g. those observed in the last
        scan), ``O(len(candidates) · M)``; default: all pairs, ``O(M²)``.
    first_estimates : list of ndarray, optional
        Each landmark's first estimate (the FEJ-EKF's linearisation point); updated in place
        (the removed landmark's entry deleted, the kept one keeps its own).

    Returns
    -------
    x, P : ndarray
        The state and covariance without the removed landmarks.
    removed : int
        Number of landmarks removed.
    """
    removed = 0
    touched = None if candidates is None else {int(c) for c in candidates}
    while (x.shape[0] - 3) // 2 >= 2:
        M = (x.shape[0] - 3) // 2
        lm = x[3:].reshape(M, 2)
        if touched is not None and not touched:
            break
        i, j = _pairs(M, touched)
        if i.size == 0:
            break
        res, sign = line_residual(lm[i], lm[j])
        Ji = np.zeros((i.size, 2, 2))
        Ji[:, 0, 0] = sign
        Ji[:, 1, 1] = 1.0
        base_i, base_j = 3 + 2 * i, 3 + 2 * j
        P_ii = np.empty((i.size, 2, 2))
        P_jj = np.empty((i.size, 2, 2))
        P_ij = np.empty((i.size, 2, 2))
        for a in range(2):
            for b in range(2):
                P_ii[:, a, b] = P[base_i + a, base_i + b]
                P_jj[:, a, b] = P[base_j + a, base_j + b]
                P_ij[:, a, b] = P[base_i + a, base_j + b]
        JP = Ji @ P_ij
        C = Ji @ P_ii @ Ji.swapaxes(-1, -2) + P_jj - JP - JP.swapaxes(-1, -2)
        lo, hi = extents.intervals(lm[:, 1])
        gap = np.maximum(lo[i], lo[j]) - np.minimum(hi[i], hi[j])
        d2 = individual_gate(res, C, merge_probability, gap <= overlap_margin_m)
        best = int(np.argmin(d2))
        if not np.isfinite(d2[best]):
            break
        a, b = int(i[best]), int(j[best])
        H_sub = np.zeros((2, 4))
        H_sub[:, :2] = Ji[best]
        H_sub[:, 2:] = -np.eye(2)
        cols = np.array([3 + 2 * a, 4 + 2 * a, 3 + 2 * b, 4 + 2 * b], dtype=np.intp)
        meas = MeasurementStack(-res[best], H_sub, cols, np.zeros((2, 2)))
        try:
            x, P = constrain_and_remove(x, P, meas, cols[2:])
        except EstimationError:
            break
        wrap_state_angles(x)
        a_kept = a - 1 if a > b else a  # index of l_a once l_b is gone
        extents.absorb(a, x[3 + 2 * a_kept : 5 + 2 * a_kept], extents.pieces(b))
        extents.delete(b)
        n_obs[a] += n_obs[b]
        del n_obs[b]
        if first_estimates is not None:
            del first_estimates[b]
        removed += 1
        if touched is not None:
            if b in touched:
                touched.add(a)
            touched = {c - 1 if c > b else c for c in touched if c != b}
    return x, P, removed
