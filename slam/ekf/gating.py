"""χ² gating, nearest neighbour and JCBB for the EKF (interim, own interface).

The shared association module (``slam.association``) is written with the graph back-end; until
it lands the EKF uses this small, self-contained one.  The interface is one
:class:`AssociationProblem` per scan: ``K`` measured lines against ``C`` candidate landmarks,
with the innovations, their Jacobians and the joint covariance of the pose and the candidates,
which is what both nearest neighbour (individual compatibility) and JCBB (joint compatibility,
Neira & Tardós 2001) need.

Individual compatibility of measurement ``k`` with landmark ``c``:
``D²_kc = ν_kcᵀ S_kc⁻¹ ν_kc < χ²₂(p)``, ``S_kc = H_kc P_c H_kcᵀ + R_k`` where ``P_c`` is the
joint covariance of the pose and landmark ``c``.  Joint compatibility of a hypothesis
``{(k, c_k)}``: the stacked innovation against ``H P Hᵀ + R`` (all cross-covariances) below
``χ²_{2h}(p)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

__all__ = [
    "AssociationProblem",
    "chi2_gate",
    "innovation_covariances",
    "jcbb",
    "mahalanobis2_2x2",
    "nearest_neighbour",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


@lru_cache(maxsize=256)
def chi2_gate(probability: float, dof: int) -> float:
    """``χ²_dof`` quantile at ``probability`` (cached: scipy's ppf is slow per call)."""
    return float(chi2.ppf(probability, dof))


def innovation_covariances(
    H_x: FloatArray,
    H_l: FloatArray,
    P_xx: FloatArray,
    P_xl: FloatArray,
    P_ll: FloatArray,
    R: FloatArray,
) -> FloatArray:
    """``S_kc = [H_x H_l] [[P_xx, P_xl], [P_lx, P_ll]] [H_x H_l]ᵀ + R_k``, vectorised.

    Parameters
    ----------
    H_x : ndarray, shape (K, C, 2, 3)
    H_l : ndarray, shape (K, C, 2, 2)
    P_xx : ndarray, shape (3, 3)
    P_xl : ndarray, shape (C, 3, 2)
        Cross-covariance of the pose with each landmark.
    P_ll : ndarray, shape (C, 2, 2)
        Marginal covariance of each landmark.
    R : ndarray, shape (K, 2, 2)

    Returns
    -------
    ndarray, shape (K, C, 2, 2)
    """
    HxT = np.swapaxes(H_x, -1, -2)
    HlT = np.swapaxes(H_l, -1, -2)
    cross = H_x @ P_xl[None] @ HlT
    S = H_x @ P_xx @ HxT + cross + np.swapaxes(cross, -1, -2) + H_l @ P_ll[None] @ HlT
    return S + R[:, None, :, :]


def mahalanobis2_2x2(nu: FloatArray, S: FloatArray) -> tuple[FloatArray, BoolArray]:
    """``νᵀ S⁻¹ ν`` for stacked 2-vectors and 2×2 matrices; ``inf`` where ``S`` is not positive."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    ok = (det > 0.0) & (a > 0.0)
    det_safe = np.where(ok, det, 1.0)
    n0, n1 = nu[..., 0], nu[..., 1]
    d2 = (d * n0 * n0 - (b + c) * n0 * n1 + a * n1 * n1) / det_safe
    return np.where(ok, d2, np.inf), ok


@dataclass(frozen=True, eq=False)
class AssociationProblem:
    """Candidates for one scan: ``K`` measurements against ``C`` landmarks.

    Attributes
    ----------
    nu : ndarray, shape (K, C, 2)
        Innovations ``z_k − h_c`` (same representative, angle wrapped).
    H_x : ndarray, shape (K, C, 2, 3)
        Jacobians w.r.t. the pose (with the representative's sign on the ``r`` row).
    H_l : ndarray, shape (K, C, 2, 2)
        Jacobians w.r.t. landmark ``c``.
    R : ndarray, shape (K, 2, 2)
        Measurement covariances.
    P : ndarray, shape (3 + 2C, 3 + 2C)
        Joint covariance of the pose (first 3) and the candidate landmarks (2 each).
    allowed : ndarray of bool, shape (K, C)
        Pairs that pass the non-statistical tests (e.g. segment overlap).
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

    def individual_d2(self) -> FloatArray:
        """``D²_kc`` of each pair, ``inf`` where not allowed or ``S`` is not positive."""
        C = self.n_candidates
        if C == 0:
            return np.full((self.n_measurements, 0), np.inf)
        P_xx = self.P[:3, :3]
        P_xl = np.stack([self.P[:3, 3 + 2 * c : 5 + 2 * c] for c in range(C)])
        P_ll = np.stack([self.P[3 + 2 * c : 5 + 2 * c, 3 + 2 * c : 5 + 2 * c] for c in range(C)])
        S = innovation_covariances(self.H_x, self.H_l, P_xx, P_xl, P_ll, self.R)
        d2, _ = mahalanobis2_2x2(self.nu, S)
        return np.where(self.allowed, d2, np.inf)

    def joint_d2(self, pairs: list[tuple[int, int]]) -> float:
        """Joint Mahalanobis distance of a hypothesis ``[(k, c), …]`` (all cross-covariances)."""
        h = len(pairs)
        if h == 0:
            return 0.0
        H = np.zeros((2 * h, self.P.shape[0]))
        nu = np.empty(2 * h)
        R = np.zeros((2 * h, 2 * h))
        for i, (k, c) in enumerate(pairs):
            H[2 * i : 2 * i + 2, :3] = self.H_x[k, c]
            H[2 * i : 2 * i + 2, 3 + 2 * c : 5 + 2 * c] = self.H_l[k, c]
            nu[2 * i : 2 * i + 2] = self.nu[k, c]
            R[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = self.R[k]
        S = H @ self.P @ H.T + R
        try:
            return float(nu @ np.linalg.solve(S, nu))
        except np.linalg.LinAlgError:
            return float("inf")


def nearest_neighbour(problem: AssociationProblem, gate_probability: float) -> IntArray:
    """Nearest neighbour with the individual χ² gate; each landmark is used at most once.

    Pairs are accepted greedily in order of increasing ``D²`` (so a landmark claimed by two
    measurements goes to the closer one; the other is left unmatched).

    Returns
    -------
    ndarray of int, shape (K,)
        Candidate index matched to each measurement, or −1.
    """
    K = problem.n_measurements
    out = np.full(K, -1, dtype=np.intp)
    if K == 0 or problem.n_candidates == 0:
        return out
    gate = chi2_gate(gate_probability, 2)
    d2 = problem.individual_d2()
    ks, cs = np.nonzero(d2 < gate)
    order = np.argsort(d2[ks, cs], kind="stable")
    used: set[int] = set()
    for i in order:
        k, c = int(ks[i]), int(cs[i])
        if out[k] < 0 and c not in used:
            out[k] = c
            used.add(c)
    return out


def jcbb(
    problem: AssociationProblem,
    gate_probability: float,
    joint_probability: float,
    max_nodes: int = 5000,
) -> tuple[IntArray, bool]:
    """Joint compatibility branch and bound (Neira & Tardós, 2001).

    Finds the hypothesis with the most pairings (ties: the smallest joint ``D²``) whose stacked
    innovation is jointly compatible at ``χ²_{2h}(joint_probability)``; candidate pairs must
    pass the individual gate first.

    Parameters
    ----------
    problem : AssociationProblem
    gate_probability : float
        Individual gate (2 dof).
    joint_probability : float
        Joint gate (``2h`` dof).
    max_nodes : int
        Budget of visited nodes; when it runs out the best hypothesis found so far is returned.

    Returns
    -------
    assignment : ndarray of int, shape (K,)
        Candidate index per measurement, or −1.
    complete : bool
        False when the node budget ran out before the search finished.
    """
    K = problem.n_measurements
    best = np.full(K, -1, dtype=np.intp)
    if K == 0 or problem.n_candidates == 0:
        return best, True
    gate = chi2_gate(gate_probability, 2)
    d2 = problem.individual_d2()
    candidates = [
        [int(c) for c in np.argsort(d2[k], kind="stable") if d2[k, c] < gate] for k in range(K)
    ]
    joint_gates = [chi2_gate(joint_probability, 2 * h) for h in range(1, K + 1)]
    best_pairs: list[tuple[int, int]] = []
    best_d2 = np.inf
    nodes = 0
    complete = True

    def recurse(k: int, pairs: list[tuple[int, int]], d2_pairs: float) -> None:
        nonlocal best_pairs, best_d2, nodes, complete
        if nodes >= max_nodes:
            complete = False
            return
        nodes += 1
        if k == K:
            if len(pairs) > len(best_pairs) or (
                len(pairs) == len(best_pairs) and d2_pairs < best_d2
            ):
                best_pairs, best_d2 = list(pairs), d2_pairs
            return
        used = {c for _, c in pairs}
        for c in candidates[k]:
            if c in used:
                continue
            trial = [*pairs, (k, c)]
            d2_joint = problem.joint_d2(trial)
            if d2_joint < joint_gates[len(trial) - 1]:
                recurse(k + 1, trial, d2_joint)
        # leave measurement k unmatched only if that can still beat the best hypothesis
        remaining = sum(1 for j in range(k + 1, K) if candidates[j])
        if len(pairs) + remaining > len(best_pairs) or (
            len(pairs) + remaining == len(best_pairs) and d2_pairs < best_d2
        ):
            recurse(k + 1, pairs, d2_pairs)

    recurse(0, [], 0.0)
    for k, c in best_pairs:
        best[k] = c
    return best, complete
