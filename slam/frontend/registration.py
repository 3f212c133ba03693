"""Weighted line-to-line registration of a scan against a local line map.

In the spirit of the paper's reference [3] (weighted range-sensor matching), but on lines: each
scan line ``k`` (sensor frame, covariance ``R_k`` from the weighted fit) is paired with a map line
``m`` (world frame, covariance ``P_m``) and the laser pose ``x`` minimises

    Σ_k ρ( e_kᵀ W_k e_k ) + (x ⊖ x̄)ᵀ P̄⁻¹ (x ⊖ x̄),     e_k = h(l_m, x) − z_k,

where ``h`` is :func:`slam.geometry.predict_line_measurement` (the inverse of Eq. 30), the residual
picks the same representative for both lines (:func:`slam.geometry.line_residual`),
``W_k = (R_k + H_l P_m H_lᵀ)⁻¹`` and ``ρ`` is an optional robust kernel.  The prior ``(x̄, P̄)``
is the odometry prediction: it keeps the problem well posed when the lines constrain only some
directions (a corridor of parallel walls says nothing about the position along it).

Association: every (scan line, map line) pair is tested with the χ² gate on the innovation
``e`` with covariance ``S = H_x P̄ H_xᵀ + H_l P_m H_lᵀ + R_k`` and must also overlap along the map
line (scan segment projected into the world at the current estimate, gap below
``overlap_margin_m``); each scan line takes its nearest (smallest D²) map line.  The gate, the
overlap test and the choice are those of :mod:`slam.association` (shared with the EKF and the
graph's loop closing).  After the first
solve the pairs are found again at the new estimate with the posterior covariance, so wrong
pairs from a poor initial guess drop out.

Outputs are the pose, its covariance (right-perturbation tangent space, as GTSAM) and separately
the information contributed by the lines alone (``information_lines``), which is what a
relative-pose factor may carry without counting the odometry prior twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from slam.association import (
    individual_gate,
    nearest_compatible,
    segment_extents,
    segment_gaps,
)
from slam.errors import ConfigError, InputError
from slam.geometry import (
    line_residual,
    pose_between,
    pose_log,
    pose_retract,
    predict_line_measurement,
)
from slam.lines.lineset import LineSet

__all__ = ["RegistrationConfig", "RegistrationResult", "register_lines"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RegistrationConfig:
    """Settings of :func:`register_lines`.

    Attributes
    ----------
    gate_probability : float
        χ² gate (2 dof) for pairing a scan line with a map line, as a probability.
    overlap_margin_m : float
        Largest gap (m) along the map line between the scan segment and the map segment for a
        pair to count; keeps collinear walls of other rooms out.
    max_iterations : int
        Gauss-Newton iterations per association round.
    association_rounds : int
        How many times pairs are found again at the current estimate.
    step_tolerance : float
        Stop when the update ``‖ξ‖`` (m and rad together) falls below this.
    robust_kernel : {"none", "huber", "cauchy"}
        Kernel on the whitened residual norm (IRLS weights).
    robust_k : float
        Kernel width, in standard deviations.
    min_matches : int
        Fewer matched lines than this: the result is the prior (flagged ``matched=False``).
    """

    gate_probability: float = 0.999
    overlap_margin_m: float = 0.5
    max_iterations: int = 8
    association_rounds: int = 2
    step_tolerance: float = 1e-7
    robust_kernel: Literal["none", "huber", "cauchy"] = "huber"
    robust_k: float = 2.0
    min_matches: int = 2

    def __post_init__(self) -> None:
        if not 0.0 < self.gate_probability < 1.0:
            raise ConfigError(f"gate_probability must be in (0, 1), got {self.gate_probability}")
        if not (self.overlap_margin_m >= 0.0 and math.isfinite(self.overlap_margin_m)):
            raise ConfigError(f"overlap_margin_m must be >= 0, got {self.overlap_margin_m}")
        if self.max_iterations < 1 or self.association_rounds < 1:
            raise ConfigError("max_iterations and association_rounds must be >= 1")
        if self.robust_kernel not in ("none", "huber", "cauchy"):
            raise ConfigError(f"unknown robust_kernel {self.robust_kernel!r}")
        if not self.robust_k > 0.0:
            raise ConfigError(f"robust_k must be > 0, got {self.robust_k}")
        if self.min_matches < 1:
            raise ConfigError(f"min_matches must be >= 1, got {self.min_matches}")


@dataclass(frozen=True, eq=False)
class RegistrationResult:
    """Outcome of :func:`register_lines`.

    Attributes
    ----------
    pose_world_laser : ndarray, shape (3,)
        Estimated laser pose.
    cov : ndarray, shape (3, 3)
        Its covariance (lines and prior together), right-perturbation tangent space.
    information_lines : ndarray, shape (3, 3)
        Information on the pose from the matched lines alone (may be singular).
    matches : ndarray of int, shape (K,)
        For each scan line, the row of the matched map line, or −1.
    n_matches : int
        Number of matched scan lines.
    matched : bool
        True when at least ``min_matches`` lines were matched.
    iterations : int
        Gauss-Newton iterations used in total.
    cost : float
        Final value of the (robust) line cost, without the prior.
    n_compatible : ndarray of int, shape (K,)
        Map lines inside each scan line's gate (and overlapping) in the last association round;
        more than one means the choice was ambiguous.
    """

    pose_world_laser: FloatArray
    cov: FloatArray
    information_lines: FloatArray
    matches: NDArray[np.int64]
    n_matches: int
    matched: bool
    iterations: int
    cost: float
    n_compatible: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    stats: dict[str, float] = field(default_factory=dict)


def _inv2(S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inverse and determinant of stacked 2×2 matrices."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    adj = np.empty(S.shape)
    adj[..., 0, 0] = d
    adj[..., 0, 1] = -b
    adj[..., 1, 0] = -c
    adj[..., 1, 1] = a
    return adj / det[..., None, None], det


def _flip_rows(H: FloatArray, sign: FloatArray) -> FloatArray:
    """Multiply the r row (row 0) of stacked Jacobians by ``sign``."""
    out = H.copy()
    out[..., 0, :] *= sign[..., None]
    return out


def _robust_weights(d2: FloatArray, kernel: str, k: float) -> FloatArray:
    if kernel == "none":
        return np.ones_like(d2)
    d = np.sqrt(np.maximum(d2, 0.0))
    if kernel == "huber":
        return np.where(d <= k, 1.0, k / np.maximum(d, 1e-300))
    return 1.0 / (1.0 + d2 / (k * k))  # cauchy


def _associate(
    scan: LineSet,
    map_lines: LineSet,
    pose: FloatArray,
    pose_cov: FloatArray,
    gate_probability: float,
    margin: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Nearest compatible map line for each scan line at ``pose`` (−1: none).

    The gate, the overlap test and the choice are :mod:`slam.association`'s
    (:func:`~slam.association.individual_gate`, :func:`~slam.association.segment_gaps`,
    :func:`~slam.association.nearest_compatible`); the map lines are independent of the pose,
    so ``S`` has no cross terms.  Also returns how many map lines each scan line is
    compatible with.
    """
    K, M = len(scan), len(map_lines)
    if K == 0 or M == 0:
        return np.full(K, -1, dtype=np.int64), np.zeros(K, dtype=np.int64)
    z_pred, H_x, H_l = predict_line_measurement(map_lines.r_alpha, pose)  # (M,2), (M,2,3), (M,2,2)
    res, sign = line_residual(z_pred[None, :, :], scan.r_alpha[:, None, :])  # (K,M,2), (K,M)
    C_map = H_x @ pose_cov @ H_x.swapaxes(-1, -2) + H_l @ map_lines.cov @ H_l.swapaxes(-1, -2)
    S = np.broadcast_to(C_map, (K, M, 2, 2)).copy()
    S[..., 0, 1] *= sign
    S[..., 1, 0] *= sign
    S += scan.cov[:, None, :, :]
    allowed = None
    if margin < np.inf:
        extents = segment_extents(map_lines.endpoints, map_lines.r_alpha)
        gaps = segment_gaps(scan.endpoints_in(pose), map_lines.r_alpha, extents)
        allowed = gaps <= margin
    d2 = individual_gate(res, S, gate_probability, allowed)
    matches = nearest_compatible(d2).astype(np.int64)
    return matches, np.count_nonzero(np.isfinite(d2), axis=1).astype(np.int64)


def register_lines(
    scan: LineSet,
    map_lines: LineSet,
    pose_prior: FloatArray,
    pose_prior_cov: FloatArray,
    config: RegistrationConfig | None = None,
    initial_pose: FloatArray | None = None,
) -> RegistrationResult:
    """Estimate the laser pose that best aligns ``scan`` (sensor frame) with ``map_lines`` (world).

    Parameters
    ----------
    scan : LineSet
        Lines of one scan in the laser frame with their ``(r, α)`` covariances.
    map_lines : LineSet
        Local map in the world frame; covariances relative to the map's own frame.
    pose_prior : ndarray, shape (3,)
        Predicted ``pose_world_laser`` (e.g. previous estimate composed with odometry).
    pose_prior_cov : ndarray, shape (3, 3)
        Covariance of the prediction (right-perturbation tangent space); must be positive
        definite.
    config : RegistrationConfig, optional
        Gates, iterations and kernel.
    initial_pose : ndarray, shape (3,), optional
        Where the iterations start (default ``pose_prior``), e.g. a relocalisation's guess far
        from the prediction; the prior term stays ``(pose_prior, pose_prior_cov)``.

    Returns
    -------
    RegistrationResult
        The estimate, its covariance and the matches.  With fewer than ``min_matches`` matched
        lines the prior is returned unchanged with ``matched=False``.
    """
    cfg = config or RegistrationConfig()
    pose_prior = np.asarray(pose_prior, dtype=float).reshape(3)
    P_prior = np.asarray(pose_prior_cov, dtype=float).reshape(3, 3)
    if not (np.all(np.isfinite(pose_prior)) and np.all(np.isfinite(P_prior))):
        raise InputError("register_lines: pose prior or its covariance is not finite")
    P_prior = 0.5 * (P_prior + P_prior.T)
    try:
        L_prior = np.linalg.cholesky(P_prior)
    except np.linalg.LinAlgError as exc:
        raise InputError("register_lines: pose_prior_cov is not positive definite") from exc
    info_prior = np.linalg.inv(L_prior @ L_prior.T)

    pose = pose_prior.copy() if initial_pose is None else np.asarray(initial_pose, float).reshape(3)
    cov_assoc = P_prior
    matches = np.full(len(scan), -1, dtype=np.int64)
    n_compat = np.zeros(len(scan), dtype=np.int64)
    info_lines = np.zeros((3, 3))
    iterations = 0
    cost = 0.0
    for _round in range(cfg.association_rounds):
        matches, n_compat = _associate(
            scan, map_lines, pose, cov_assoc, cfg.gate_probability, cfg.overlap_margin_m
        )
        k_idx = np.flatnonzero(matches >= 0)
        if len(k_idx) < cfg.min_matches:
            break
        m_idx = matches[k_idx]
        z = scan.r_alpha[k_idx]
        R_meas = scan.cov[k_idx]
        lm = map_lines.r_alpha[m_idx]
        P_lm = map_lines.cov[m_idx]
        for _ in range(cfg.max_iterations):
            iterations += 1
            z_pred, H_x, H_l = predict_line_measurement(lm, pose)
            e, sign = line_residual(z_pred, z)
            H_x = _flip_rows(H_x, sign)
            H_l = _flip_rows(H_l, sign)
            W, _ = _inv2(R_meas + H_l @ P_lm @ H_l.swapaxes(-1, -2))
            d2 = np.einsum("ki,kij,kj->k", e, W, e)
            w = _robust_weights(d2, cfg.robust_kernel, cfg.robust_k)
            Ww = W * w[:, None, None]
            info_lines = np.einsum("kia,kij,kjb->ab", H_x, Ww, H_x)
            grad_lines = np.einsum("kia,kij,kj->a", H_x, Ww, e)
            # prior residual in the tangent space at the current estimate (first order)
            e_prior = pose_log(pose_between(pose_prior, pose))
            A = info_lines + info_prior
            g = grad_lines + info_prior @ e_prior
            try:
                step = -np.linalg.solve(A, g)
            except np.linalg.LinAlgError:
                break
            pose = pose_retract(pose, step)
            cost = float(np.sum(w * d2))
            if np.linalg.norm(step) < cfg.step_tolerance:
                break
        cov_assoc = np.linalg.inv(info_lines + info_prior)
    n_matches = int(np.count_nonzero(matches >= 0))
    matched = n_matches >= cfg.min_matches
    if not matched:
        pose = pose_prior.copy()
        info_lines = np.zeros((3, 3))
        cov = P_prior.copy()
    else:
        cov = np.linalg.inv(info_lines + info_prior)
        cov = 0.5 * (cov + cov.T)
    return RegistrationResult(
        pose_world_laser=pose,
        cov=cov,
        information_lines=0.5 * (info_lines + info_lines.T),
        matches=matches,
        n_matches=n_matches,
        matched=matched,
        iterations=iterations,
        cost=cost,
        n_compatible=n_compat,
    )
