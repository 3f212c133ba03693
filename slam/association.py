"""Data association of measured lines with map landmarks (shared by the graph and the EKF).

One scan gives ``K`` lines ``z_k = (r, α)`` in the laser frame with covariances ``R_k``; the map
offers ``C`` candidate landmarks ``l_c = (r, α)`` in the world.  Both estimators provide the
predicted laser pose ``x`` and the joint covariance ``P`` of ``(x, l_1 … l_C)``.

Innovation and its covariance (first order, :func:`slam.geometry.predict_line_measurement`):

``ν_kc = z_k − h(l_c, x)`` (same representative, angle wrapped:
:func:`slam.geometry.line_residual`),

``S_kc = H_x P_xx H_xᵀ + H_x P_xc H_lᵀ + H_l P_cx H_xᵀ + H_l P_cc H_lᵀ + R_k``.

* **Individual compatibility**: ``D²_kc = ν_kcᵀ S_kc⁻¹ ν_kc ≤ χ²₂(gate_probability)``, and the
  measured segment must overlap (or come within a margin of) the landmark's extent along the
  line in the world frame: ``(r, α)`` alone would match every collinear wall of a building
  (:func:`individual_gate`, :func:`segment_gaps`; the registration uses them with
  :func:`nearest_compatible`, where a landmark may serve several measurements).
* **Nearest neighbour**: each measurement takes the compatible landmark with the smallest
  ``D²``, greedily in order of ``D²`` so that a landmark is used at most once per scan.
* **Joint compatibility branch and bound** (Neira & Tardós 2001): the largest set of pairings
  whose stacked innovation passes ``χ²_{2h}(joint_probability)`` with all cross-covariances
  (ties: smallest joint ``D²``).
* **Landmark fusion test** (:func:`landmarks_compatible`): the paper's Eq. 34-35 on two
  landmarks' joint marginal, with :func:`slam.lines.mahalanobis2`.

numpy and :mod:`slam.lines` only (the χ² quantile is :func:`slam.lines.chi2_gate`): no gtsam, so
that the EKF can use it unchanged.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, InputError
from slam.geometry import line_residual, pose_compose, predict_line_measurement

__all__ = [
    "AssociationConfig",
    "AssociationProblem",
    "AssociationResult",
    "associate",
    "build_problem",
    "candidate_landmarks",
    "individual_gate",
    "jcbb",
    "landmarks_compatible",
    "nearest_compatible",
    "nearest_neighbour",
    "overlap_mask",
    "segment_extents",
    "segment_gaps",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class AssociationConfig:
    """How measured lines are paired with landmarks.

    Attributes
    ----------
    method : {"nn", "jcbb"}
        Nearest neighbour or joint compatibility branch and bound.
    gate_probability : float
        Individual χ² gate (2 dof), as a probability (0.999: ``D² ≤ 13.8``).
    joint_probability : float
        JCBB's joint gate (``2h`` dof for ``h`` pairings), as a probability.
    overlap_margin_m : float
        Largest gap (m) along the landmark between its extent and the measured segment.
    overlap_sigma_factor : float
        The margin grows by this many standard deviations of the segment's end points in the
        world (pose uncertainty), so that a loop closure after drift can still overlap.
    max_range_m : float
        Landmarks whose extent is farther than this (m) from the laser are not candidates.
    max_candidates : int
        At most this many candidates per scan (after the overlap test, those whose lines pass
        closest to a measured segment): bounds the size of the joint covariance computed.
    jcbb_max_nodes : int
        Node budget of the JCBB search (best hypothesis so far when exhausted).
    cross_covariances : bool
        Use the joint covariance of the pose and the candidates; False: only the marginals
        (block-diagonal ``P``), cheaper and more conservative.
    """

    method: Literal["nn", "jcbb"] = "jcbb"
    gate_probability: float = 0.999
    joint_probability: float = 0.999
    overlap_margin_m: float = 0.5
    overlap_sigma_factor: float = 3.0
    max_range_m: float = 30.0
    max_candidates: int = 40
    jcbb_max_nodes: int = 2000
    cross_covariances: bool = True

    def __post_init__(self) -> None:
        if self.method not in ("nn", "jcbb"):
            raise ConfigError(f"association method must be nn or jcbb, got {self.method!r}")
        for name in ("gate_probability", "joint_probability"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise ConfigError(f"{name} must be in (0, 1), got {v!r}")
        for name in ("overlap_margin_m", "overlap_sigma_factor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ConfigError(f"{name} must be a finite number >= 0, got {v!r}")
        if not self.max_range_m > 0.0:
            raise ConfigError(f"max_range_m must be > 0, got {self.max_range_m!r}")
        if self.max_candidates < 1:
            raise ConfigError("max_candidates must be >= 1")
        if self.jcbb_max_nodes < 1:
            raise ConfigError("jcbb_max_nodes must be >= 1")


@functools.lru_cache(maxsize=4096)
def _chi2_quantile(probability: float, dof: int) -> float:
    from slam.lines import chi2_gate

    return chi2_gate(probability, dof)


def _chi2_ppf(probability: float, dof: Any) -> Any:
    """χ² quantile(s) for integer degrees of freedom (cached)."""
    d = np.asarray(dof)
    if d.ndim == 0:
        return _chi2_quantile(float(probability), int(d))
    return np.array([_chi2_quantile(float(probability), int(k)) for k in d])


def _mahalanobis2_2x2(nu: FloatArray, S: FloatArray) -> FloatArray:
    """``νᵀ S⁻¹ ν`` for stacked 2-vectors and 2×2 matrices; ``inf`` where ``S`` is not PD."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    ok = (det > 0.0) & (a > 0.0)
    det_safe = np.where(ok, det, 1.0)
    n0, n1 = nu[..., 0], nu[..., 1]
    d2 = (d * n0 * n0 - (b + c) * n0 * n1 + a * n1 * n1) / det_safe
    return np.where(ok, d2, np.inf)


def individual_gate(
    nu: FloatArray,
    S: FloatArray,
    gate_probability: float,
    allowed: BoolArray | None = None,
) -> FloatArray:
    """Individual compatibility test of measurement-landmark pairs (vectorised).

    ``D² = νᵀ S⁻¹ ν`` of each pair, kept where ``D² ≤ χ²₂(gate_probability)``, ``S`` is
    positive definite and the pair is ``allowed`` (e.g. by :func:`segment_gaps`).

    Parameters
    ----------
    nu : ndarray, shape (..., 2)
        Innovations (either sign: ``D²`` is even in ``ν``).
    S : ndarray, shape (..., 2, 2)
        Their covariances.
    gate_probability : float
        Probability of the χ² gate (2 dof).
    allowed : ndarray of bool, shape (...), optional
        Pairs that passed the non-statistical tests; default all.

    Returns
    -------
    ndarray, shape (...)
        ``D²`` inside the gate, ``inf`` outside it.
    """
    d2 = _mahalanobis2_2x2(np.asarray(nu, dtype=float), np.asarray(S, dtype=float))
    ok = d2 <= float(_chi2_ppf(gate_probability, 2))
    if allowed is not None:
        ok &= np.asarray(allowed, dtype=bool)
    return np.where(ok, d2, np.inf)


def nearest_compatible(d2_gated: FloatArray) -> IntArray:
    """Each measurement's compatible landmark with the smallest ``D²`` (−1: none).

    Unlike :func:`nearest_neighbour` a landmark may serve several measurements (the
    registration's choice: one wall seen as two segments pairs both with the wall).

    Parameters
    ----------
    d2_gated : ndarray, shape (K, C)
        From :func:`individual_gate` (``inf``: not compatible).

    Returns
    -------
    ndarray of int, shape (K,)
    """
    d2 = np.asarray(d2_gated, dtype=float)
    out = np.full(d2.shape[0], -1, dtype=np.intp)
    if d2.shape[0] == 0 or d2.shape[1] == 0:
        return out
    best = np.argmin(d2, axis=1)
    has = np.isfinite(d2[np.arange(d2.shape[0]), best])
    out[has] = best[has]
    return out


@dataclass(frozen=True, eq=False)
class AssociationProblem:
    """``K`` measurements against ``C`` candidate landmarks.

    Attributes
    ----------
    nu : ndarray, shape (K, C, 2)
        Innovations ``z_k − h(l_c, x)`` (same representative, angle wrapped).
    H_x : ndarray, shape (K, C, 2, 3)
        ``∂h/∂ξ`` of the pose (right perturbation), ``r`` row signed by the representative.
    H_l : ndarray, shape (K, C, 2, 2)
        ``∂h/∂l_c``, signed likewise.
    R : ndarray, shape (K, 2, 2)
        Measurement covariances.
    P : ndarray, shape (3 + 2C, 3 + 2C)
        Joint covariance of the pose (first 3) and the candidates (2 each, in order).
    allowed : ndarray of bool, shape (K, C)
        Pairs that pass the non-statistical tests (segment overlap).
    """

    nu: FloatArray
    H_x: FloatArray
    H_l: FloatArray
    R: FloatArray
    P: FloatArray
    allowed: BoolArray

    @property
    def n_measurements(self) -> int:
        """``K``."""
        return int(self.nu.shape[0])

    @property
    def n_candidates(self) -> int:
        """``C``."""
        return int(self.nu.shape[1])

    def innovation_covariances(self) -> FloatArray:
        """``S_kc``, shape ``(K, C, 2, 2)``."""
        C = self.n_candidates
        P_xx = self.P[:3, :3]
        idx = 3 + 2 * np.arange(C)[:, None] + np.arange(2)[None, :]  # (C, 2)
        P_xl = self.P[:3][:, idx].transpose(1, 0, 2)  # (C, 3, 2)
        P_ll = self.P[idx[:, :, None], idx[:, None, :]]  # (C, 2, 2)
        HxT = np.swapaxes(self.H_x, -1, -2)
        HlT = np.swapaxes(self.H_l, -1, -2)
        cross = self.H_x @ P_xl[None] @ HlT
        S = self.H_x @ P_xx @ HxT + cross + np.swapaxes(cross, -1, -2)
        S = S + self.H_l @ P_ll[None] @ HlT
        return S + self.R[:, None, :, :]

    def individual_d2(self) -> FloatArray:
        """``D²_kc``, shape ``(K, C)``; ``inf`` where not allowed or ``S`` is not PD."""
        if self.n_candidates == 0 or self.n_measurements == 0:
            return np.full((self.n_measurements, self.n_candidates), np.inf)
        d2 = _mahalanobis2_2x2(self.nu, self.innovation_covariances())
        return np.where(self.allowed, d2, np.inf)

    def joint_d2(self, pairs: list[tuple[int, int]]) -> float:
        """Joint ``D²`` of a hypothesis ``[(k, c), …]`` with all cross-covariances."""
        h = len(pairs)
        if h == 0:
            return 0.0
        n = self.P.shape[0]
        H = np.zeros((2 * h, n))
        nu = np.empty(2 * h)
        R = np.zeros((2 * h, 2 * h))
        for i, (k, c) in enumerate(pairs):
            H[2 * i : 2 * i + 2, :3] = self.H_x[k, c]
            H[2 * i : 2 * i + 2, 3 + 2 * c : 5 + 2 * c] = self.H_l[k, c]
            nu[2 * i : 2 * i + 2] = self.nu[k, c]
            R[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = self.R[k]
        S = H @ self.P @ H.T + R
        try:
            L = np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            return float("inf")
        y = np.linalg.solve(L, nu)
        return float(y @ y)


@dataclass(frozen=True, eq=False)
class AssociationResult:
    """Outcome of :func:`associate`.

    Attributes
    ----------
    assignment : ndarray of int, shape (K,)
        Candidate index (column of the problem) matched to each measurement, or −1.
    d2 : ndarray, shape (K, C)
        Individual ``D²`` (``inf`` where not allowed).
    n_compatible : ndarray of int, shape (K,)
        Candidates inside the individual gate, per measurement (> 1: ambiguous).
    complete : bool
        False when JCBB ran out of its node budget.
    """

    assignment: IntArray
    d2: FloatArray
    n_compatible: IntArray
    complete: bool = True


def _origins(anchors: FloatArray | None, n: int) -> FloatArray:
    return np.zeros((n, 2)) if anchors is None else np.asarray(anchors, dtype=float).reshape(n, 2)


def candidate_landmarks(
    pose_world_laser: FloatArray,
    landmarks_r_alpha: FloatArray,
    extents: FloatArray,
    max_range_m: float,
    alive: BoolArray | None = None,
    anchors: FloatArray | None = None,
    max_candidates: int | None = None,
) -> IntArray:
    """Landmarks whose extent comes within ``max_range_m`` of the laser (vectorised).

    Parameters
    ----------
    pose_world_laser : ndarray, shape (3,)
    landmarks_r_alpha : ndarray, shape (M, 2)
    extents : ndarray, shape (M, 2)
        ``(s_min, s_max)`` along each landmark's tangent ``t = (−sin α, cos α)``, measured from
        the landmark's origin point (``s = (p − o)·t``); NaN: unknown (never a candidate).
    max_range_m : float
    alive : ndarray of bool, shape (M,), optional
    anchors : ndarray, shape (M, 2), optional
        Origin point of each landmark's ``s`` (default: the world origin).
    max_candidates : int, optional
        Keep only this many, the nearest.

    Returns
    -------
    ndarray of int
        Sorted indices.
    """
    lm = np.asarray(landmarks_r_alpha, dtype=float)
    ext = np.asarray(extents, dtype=float)
    if lm.shape[0] == 0:
        return np.zeros(0, dtype=np.intp)
    p = np.asarray(pose_world_laser, dtype=float)[:2]
    n = np.stack([np.cos(lm[:, 1]), np.sin(lm[:, 1])], -1)
    t = np.stack([-n[:, 1], n[:, 0]], -1)
    dist_normal = np.abs(n @ p - lm[:, 0])
    s_p = np.sum(t * (p[None, :] - _origins(anchors, lm.shape[0])), axis=1)
    s_clamped = np.clip(s_p, ext[:, 0], ext[:, 1])
    dist = np.hypot(dist_normal, s_p - s_clamped)
    ok = np.isfinite(ext).all(axis=1) & (dist <= max_range_m)
    if alive is not None:
        ok &= np.asarray(alive, dtype=bool)
    idx = np.flatnonzero(ok)
    if max_candidates is not None and idx.shape[0] > max_candidates:
        idx = np.sort(idx[np.argsort(dist[idx], kind="stable")[:max_candidates]])
    return idx


def segment_extents(endpoints_world: FloatArray, landmarks_r_alpha: FloatArray) -> FloatArray:
    """``(s_min, s_max)`` of segments along their lines' tangents, from the world origin.

    Parameters
    ----------
    endpoints_world : ndarray, shape (C, 2, 2)
        Each segment's two end points.
    landmarks_r_alpha : ndarray, shape (C, 2)
        The lines ``(r, α)`` they lie on.

    Returns
    -------
    ndarray, shape (C, 2)
        Extents as :func:`candidate_landmarks` and :func:`segment_gaps` take them (no anchors).
    """
    a = np.asarray(landmarks_r_alpha, dtype=float).reshape(-1, 2)[:, 1]
    t = np.stack([-np.sin(a), np.cos(a)], -1)
    s = np.einsum("cpd,cd->cp", np.asarray(endpoints_world, dtype=float), t)
    return np.stack([s.min(axis=-1), s.max(axis=-1)], axis=-1)


def segment_gaps(
    endpoints_world: FloatArray,
    landmarks_r_alpha: FloatArray,
    extents: FloatArray,
    anchors: FloatArray | None = None,
) -> FloatArray:
    """Gap (m) along each landmark between its extent and each measured segment.

    Parameters
    ----------
    endpoints_world : ndarray, shape (K, 2, 2)
        Measured segments' end points in the world.
    landmarks_r_alpha : ndarray, shape (C, 2)
    extents : ndarray, shape (C, 2)
        ``(s_min, s_max)`` along each landmark's tangent (see :func:`candidate_landmarks`).
    anchors : ndarray, shape (C, 2), optional
        Origin of each landmark's ``s`` (default: the world origin).

    Returns
    -------
    ndarray, shape (K, C)
        ``max(lo₁, lo₂) − min(hi₁, hi₂)``: negative when they overlap.
    """
    a = np.asarray(landmarks_r_alpha, dtype=float)[:, 1]
    t = np.stack([-np.sin(a), np.cos(a)], -1)  # (C, 2)
    o = _origins(anchors, a.shape[0])
    s = np.einsum("kpd,cd->kcp", np.asarray(endpoints_world, dtype=float), t)  # (K, C, 2)
    s = s - np.sum(o * t, axis=1)[None, :, None]
    lo, hi = s.min(axis=-1), s.max(axis=-1)
    ext = np.asarray(extents, dtype=float)
    return np.asarray(
        np.maximum(lo, ext[None, :, 0]) - np.minimum(hi, ext[None, :, 1]), dtype=float
    )


def build_problem(
    z: FloatArray,
    R: FloatArray,
    endpoints_laser: FloatArray,
    pose_world_laser: FloatArray,
    P: FloatArray,
    landmarks_r_alpha: FloatArray,
    extents: FloatArray,
    config: AssociationConfig,
    anchors: FloatArray | None = None,
) -> AssociationProblem:
    """Innovations, Jacobians and the overlap test for ``K`` lines against ``C`` candidates.

    Parameters
    ----------
    z : ndarray, shape (K, 2)
        Measured ``(r, α)``, laser frame.
    R : ndarray, shape (K, 2, 2)
    endpoints_laser : ndarray, shape (K, 2, 2)
        Measured segments' extreme end points, laser frame.
    pose_world_laser : ndarray, shape (3,)
        Predicted laser pose.
    P : ndarray, shape (3 + 2C, 3 + 2C)
        Joint covariance of the pose (right tangent space) and the candidates.
    landmarks_r_alpha : ndarray, shape (C, 2)
    extents : ndarray, shape (C, 2)
        Each candidate's extent along its line (see :func:`candidate_landmarks`).
    config : AssociationConfig
    anchors : ndarray, shape (C, 2), optional
        Origin of each candidate's extent coordinate (default: the world origin).

    Returns
    -------
    AssociationProblem
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    K = z.shape[0]
    lm = np.asarray(landmarks_r_alpha, dtype=float).reshape(-1, 2)
    C = lm.shape[0]
    P = np.asarray(P, dtype=float)
    if P.shape != (3 + 2 * C, 3 + 2 * C):
        raise InputError(f"joint covariance must be {(3 + 2 * C,) * 2}, got {P.shape}")
    pose = np.asarray(pose_world_laser, dtype=float).reshape(3)
    if not config.cross_covariances:
        P = _block_diagonal(P, C)
    z_pred, H_x, H_l = predict_line_measurement(lm[None, :, :], pose)  # (1, C, ...)
    z_pred = np.broadcast_to(z_pred, (K, C, 2))
    res, sign = line_residual(z_pred, z[:, None, :])
    H_x = np.array(np.broadcast_to(H_x, (K, C, 2, 3)))
    H_l = np.array(np.broadcast_to(H_l, (K, C, 2, 2)))
    H_x[..., 0, :] *= sign[..., None]
    H_l[..., 0, :] *= sign[..., None]
    allowed = overlap_mask(endpoints_laser, pose, P[:3, :3], lm, extents, config, anchors)
    return AssociationProblem(
        nu=-res, H_x=H_x, H_l=H_l, R=np.asarray(R, dtype=float), P=P, allowed=allowed
    )


def overlap_mask(
    endpoints_laser: FloatArray,
    pose_world_laser: FloatArray,
    P_pose: FloatArray,
    landmarks_r_alpha: FloatArray,
    extents: FloatArray,
    config: AssociationConfig,
    anchors: FloatArray | None = None,
) -> BoolArray:
    """Pairs whose measured segment comes within the margin of the landmark's extent.

    The margin is ``overlap_margin_m`` plus ``overlap_sigma_factor`` standard deviations of the
    segment's end points in the world (from the pose covariance ``P_pose``, right tangent
    space: ``√(λ_max(P_xy) + d²·P_θθ)`` with ``d`` the end point's distance from the laser).
    Needs only the pose covariance, so it can thin the candidates before their joint
    covariance is computed.

    Returns
    -------
    ndarray of bool, shape (K, C)
    """
    ep = np.asarray(endpoints_laser, dtype=float).reshape(-1, 2, 2)
    K = ep.shape[0]
    lm = np.asarray(landmarks_r_alpha, dtype=float).reshape(-1, 2)
    if K == 0 or lm.shape[0] == 0:
        return np.zeros((K, lm.shape[0]), dtype=bool)
    pose = np.asarray(pose_world_laser, dtype=float).reshape(3)
    Pp = np.asarray(P_pose, dtype=float)
    pts = np.concatenate([ep, np.zeros((K, 2, 1))], axis=-1)
    ep_world = pose_compose(np.broadcast_to(pose, pts.shape), pts)[..., :2]
    gaps = segment_gaps(ep_world, lm, extents, anchors)
    var_xy = float(np.max(np.linalg.eigvalsh(0.5 * (Pp[:2, :2] + Pp[:2, :2].T))))
    reach2 = np.max(np.sum(ep**2, axis=-1), axis=-1)  # (K,)
    sigma = np.sqrt(max(var_xy, 0.0) + reach2 * max(Pp[2, 2], 0.0))
    margin = config.overlap_margin_m + config.overlap_sigma_factor * sigma
    return np.asarray(gaps <= margin[:, None])


def _block_diagonal(P: FloatArray, C: int) -> FloatArray:
    out = np.zeros_like(P)
    out[:3, :3] = P[:3, :3]
    for c in range(C):
        sl = slice(3 + 2 * c, 5 + 2 * c)
        out[sl, sl] = P[sl, sl]
    return out


def nearest_neighbour(
    problem: AssociationProblem, gate_probability: float, d2: FloatArray | None = None
) -> IntArray:
    """Greedy nearest neighbour in order of ``D²``; each landmark used at most once.

    ``d2`` may pass :meth:`AssociationProblem.individual_d2` when already computed.

    Returns
    -------
    ndarray of int, shape (K,)
        Candidate index per measurement, or −1.
    """
    K = problem.n_measurements
    out = np.full(K, -1, dtype=np.intp)
    if K == 0 or problem.n_candidates == 0:
        return out
    gate = float(_chi2_ppf(gate_probability, 2))
    d2 = problem.individual_d2() if d2 is None else d2
    ks, cs = np.nonzero(d2 <= gate)
    used: set[int] = set()
    for i in np.argsort(d2[ks, cs], kind="stable"):
        k, c = int(ks[i]), int(cs[i])
        if out[k] < 0 and c not in used:
            out[k] = c
            used.add(c)
    return out


def jcbb(
    problem: AssociationProblem,
    gate_probability: float,
    joint_probability: float,
    max_nodes: int = 2000,
    d2: FloatArray | None = None,
) -> tuple[IntArray, bool]:
    """Joint compatibility branch and bound (Neira & Tardós 2001).

    Searches the interpretation tree over measurements (those with fewer individually
    compatible candidates first), pruning a branch when it cannot beat the best hypothesis's
    number of pairings; a pairing is added only if the enlarged hypothesis stays jointly
    compatible.  Ties in the number of pairings go to the smaller joint ``D²``.

    Returns
    -------
    assignment : ndarray of int, shape (K,)
        Candidate index per measurement, or −1.
    complete : bool
        False when ``max_nodes`` ran out (the best hypothesis found so far is returned).
    """
    K = problem.n_measurements
    best = np.full(K, -1, dtype=np.intp)
    if K == 0 or problem.n_candidates == 0:
        return best, True
    gate = float(_chi2_ppf(gate_probability, 2))
    d2 = problem.individual_d2() if d2 is None else d2
    cand = [
        [int(c) for c in np.argsort(d2[k], kind="stable") if d2[k, c] <= gate] for k in range(K)
    ]
    order = sorted((k for k in range(K) if cand[k]), key=lambda k: len(cand[k]))
    if not order:
        return best, True
    joint_gate = _chi2_ppf(joint_probability, 2 * np.arange(1, len(order) + 1))
    best_pairs: list[tuple[int, int]] = []
    best_d2 = np.inf
    nodes = 0
    complete = True

    def recurse(level: int, pairs: list[tuple[int, int]], d2_pairs: float) -> None:
        nonlocal best_pairs, best_d2, nodes, complete
        if nodes >= max_nodes:
            complete = False
            return
        nodes += 1
        if level == len(order):
            if len(pairs) > len(best_pairs) or (
                len(pairs) == len(best_pairs) and d2_pairs < best_d2
            ):
                best_pairs, best_d2 = list(pairs), d2_pairs
            return
        k = order[level]
        used = {c for _, c in pairs}
        for c in cand[k]:
            if c in used:
                continue
            trial = [*pairs, (k, c)]
            d2_joint = problem.joint_d2(trial)
            if d2_joint <= joint_gate[len(trial) - 1]:
                recurse(level + 1, trial, d2_joint)
        remaining = len(order) - level - 1
        if len(pairs) + remaining > len(best_pairs) or (
            len(pairs) + remaining == len(best_pairs) and d2_pairs < best_d2
        ):
            recurse(level + 1, pairs, d2_pairs)

    recurse(0, [], 0.0)
    for k, c in best_pairs:
        best[k] = c
    return best, complete


def associate(problem: AssociationProblem, config: AssociationConfig) -> AssociationResult:
    """Run the configured method on ``problem``."""
    d2 = problem.individual_d2()
    gate = float(_chi2_ppf(config.gate_probability, 2))
    n_compat = np.sum(d2 <= gate, axis=1).astype(np.intp)
    if config.method == "nn":
        nn = nearest_neighbour(problem, config.gate_probability, d2)
        return AssociationResult(nn, d2, n_compat)
    assignment, complete = jcbb(
        problem, config.gate_probability, config.joint_probability, config.jcbb_max_nodes, d2
    )
    return AssociationResult(assignment, d2, n_compat, complete)


def landmarks_compatible(
    l1: FloatArray,
    l2: FloatArray,
    P_joint: FloatArray,
    probability: float,
) -> tuple[bool, float]:
    """The paper's merge test (Eqs. 34-35) on two landmarks' joint marginal.

    ``δ = l₁ − l₂'`` with ``l₂'`` the representative of ``l₂`` closest to ``l₁``
    (:func:`slam.lines.align_representative`); its covariance is
    ``P₁₁ + F P₂₂ F − P₁₂ F − F P₂₁`` with ``F = diag(±1, 1)`` the representative flip, i.e.
    the correlation between the two estimates is accounted for (two landmarks seen from the same
    poses are strongly correlated; treating them as independent over-estimates the spread).

    Parameters
    ----------
    l1, l2 : ndarray, shape (2,)
        Landmarks ``(r, α)``.
    P_joint : ndarray, shape (4, 4)
        Joint covariance of ``(l₁, l₂)``.
    probability : float
        Gate probability (2 dof).

    Returns
    -------
    compatible : bool
    d2 : float
    """
    from slam.lines import align_representative, chi2_gate, mahalanobis2

    P = np.asarray(P_joint, dtype=float).reshape(4, 4)
    l1 = np.asarray(l1, dtype=float).reshape(2)
    l2a, _, flipped = align_representative(
        np.asarray(l2, dtype=float).reshape(2), P[2:, 2:], np.asarray(l1[1])
    )
    F = np.diag([-1.0 if bool(flipped) else 1.0, 1.0])
    cross = P[:2, 2:] @ F
    P_delta = P[:2, :2] + F @ P[2:, 2:] @ F - cross - cross.T
    P_delta = 0.5 * (P_delta + P_delta.T)
    d2 = float(mahalanobis2(l1, P_delta, l2a, np.zeros((2, 2))))
    return bool(d2 <= chi2_gate(probability)), d2
