"""χ² merge test (Eqs. 34-35), maximum-likelihood fusion (Eqs. 36-37) and segment handling.

All functions are vectorised over leading dimensions (pairs of lines broadcast against each
other), work on lines ``(r, α)`` or ``(r, α, s)`` with covariances ordered the same way, and are
plain numpy so that the graph back-end can reuse them for data association and landmark fusion.

Representatives.  ``(r, α)`` and ``(−r, α + π)`` are the same infinite line (reading note 5).
Before any difference or fusion, the second line is brought to the representative whose normal
is closest to the first's (``|wrap(α₂ − α₁)| ≤ π/2``; ``r`` and ``s`` change sign, and so do the
covariance's ``r`` and ``s`` rows and columns).  This removes the 2π jump near ``α = ±π`` and the
sign jump of lines through the origin (``r ≈ 0``).  With ``same_side=True`` no flip is made and
lines whose normals point more than 90° apart are incompatible: a line stored with its normal
pointing away from the sensor that saw it (:func:`slam.lines.transform.transform_line` with
``normal_form=False``) then never merges with the other face of a thin wall.

Fusion.  Eq. 36-37 is the information-weighted mean.  It is computed in the equivalent gain
form ``x = x₁ + G (x₂ − x₁)``, ``G = P₁ (P₁ + P₂)⁻¹``, ``P = (I − G) P₁``, which needs only
``P₁ + P₂`` to be invertible (a line known exactly can be fused).  Only ``(r, α)`` are measured
in common: ``s`` of each line is the centroid of its *own* points, so the fused ``s`` is the
``1/P_ss``-weighted mean of the two centroids projected on the fused line (exactly what a single
fit of all the points gives, Eq. 21/23), not a Kalman update of ``(r, α)`` by the difference of
two centroids.  The weights are ``1/P_s|α`` (the variance of ``s`` given ``α``; ``1/P_ss`` when
they are uncorrelated, as in the paper's Eq. 25).  The 3×3 covariance is the first-order
propagation through that map.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slam.errors import ConfigError, DegenerateGeometryError, InputError
from slam.geometry import wrap_angle
from slam.lines.checks import check_covariance, inv2x2

__all__ = [
    "DEFAULT_GATE_PROBABILITY",
    "align_representative",
    "chi2_gate",
    "chi2_ppf",
    "extent_gap",
    "fuse",
    "fuse_many",
    "fuse_pair_unchecked",
    "is_compatible",
    "mahalanobis2",
    "mahalanobis2_unchecked",
    "to_normal_form",
    "unite_segments",
]

FloatArray = NDArray[np.float64]

DEFAULT_GATE_PROBABILITY = 0.9973
"""The paper's "3σ" gate (Sec. VI) for 2 dof: χ²₂ quantile 11.83."""


def chi2_gate(probability: float = DEFAULT_GATE_PROBABILITY, dof: int = 2) -> float:
    """χ² threshold for a gate of the given probability (default: 3σ, 2 dof → 11.83).

    The one χ² quantile of the gates: the map builder's merge test, :mod:`slam.association`
    (EKF, graph, registration) and the EKF's own landmark tests all take it from here.
    """
    if not (0.0 < probability < 1.0):
        raise ConfigError(f"gate probability must be in (0, 1), got {probability!r}")
    if dof < 1:
        raise ConfigError(f"dof must be >= 1, got {dof!r}")
    if dof == 2:
        return -2.0 * math.log1p(-float(probability))  # closed form for 2 dof
    from scipy.special import gammaincinv  # lighter than scipy.stats

    return float(2.0 * gammaincinv(dof / 2.0, probability))


def chi2_ppf(probability: float, dof: int) -> float:
    """``scipy.stats.chi2.ppf(probability, dof)`` for one probability and ``dof``, as a float.

    The function that ``scipy.stats.chi2.ppf`` evaluates, ``2 · gammaincinv(dof/2, p)``, taken
    from ``scipy.special`` (importing ``scipy.stats`` costs about half a second of start-up),
    with its values at the ends: ``0`` at ``p = 0``, ``inf`` at ``p = 1``, ``nan`` outside
    ``[0, 1]`` or for ``dof ≤ 0``.
    """
    p = float(probability)
    if not dof > 0 or not 0.0 <= p <= 1.0:
        return math.nan
    if p == 0.0:
        return 0.0
    if p == 1.0:
        return math.inf
    from scipy.special import gammaincinv  # lighter than scipy.stats

    return float(2.0 * gammaincinv(dof / 2.0, p))


def _as_line(line: FloatArray, name: str) -> FloatArray:
    arr = np.asarray(line, dtype=float)
    if arr.shape[-1:] not in ((2,), (3,)):
        raise InputError(f"{name}: expected (..., 2) or (..., 3) lines, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError(f"{name}: line parameters contain NaN or inf")
    return arr


def align_representative(
    line: FloatArray, cov: FloatArray, reference_alpha: FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Choose for each line the representative whose normal is closest to ``reference_alpha``.

    Parameters
    ----------
    line : ndarray, shape (..., d), d = 2 or 3
        ``(r, α[, s])``.
    cov : ndarray, shape (..., d, d)
    reference_alpha : ndarray, shape (...)
        Normal angles to align to.

    Returns
    -------
    line, cov : ndarray
        ``(−r, α + π, −s)`` where ``|wrap(α − reference)| > π/2``; ``α`` is wrapped to
        within ``π/2`` of the reference *without* a 2π jump (``α = ref + wrap(α − ref)``), so
        differences and weighted means of angles are safe.
    flipped : ndarray of bool, shape (...)
    """
    line = np.asarray(line, dtype=float)
    cov = np.asarray(cov, dtype=float)
    ref = np.asarray(reference_alpha, dtype=float)
    d_alpha = np.asarray(wrap_angle(line[..., 1] - ref))
    flipped = np.abs(d_alpha) > np.pi / 2.0
    sign = np.where(flipped, -1.0, 1.0)
    d_alpha = np.asarray(wrap_angle(np.where(flipped, d_alpha + np.pi, d_alpha)))
    out = line * np.ones_like(sign)[..., None]
    out = np.array(out, copy=True)
    out[..., 0] = sign * line[..., 0]
    out[..., 1] = ref + d_alpha
    if line.shape[-1] == 3:
        out[..., 2] = sign * line[..., 2]
    d = line.shape[-1]
    row = np.ones((*sign.shape, d))
    row[..., 0] = sign
    if d == 3:
        row[..., 2] = sign
    cov_out = cov * row[..., :, None] * row[..., None, :]
    return out, cov_out, flipped


def _difference(
    l1: FloatArray, P1: FloatArray, l2: FloatArray, P2: FloatArray, same_side: bool
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """``δ = (r₁ − r₂', wrap(α₁ − α₂'))``, ``S = P₁ + P₂'`` on the (r, α) blocks, opposite mask."""
    l1 = _as_line(l1, "l1")
    l2 = _as_line(l2, "l2")
    P1 = check_covariance(np.asarray(P1)[..., :2, :2], 2, "P1")
    P2 = check_covariance(np.asarray(P2)[..., :2, :2], 2, "P2")
    return _difference_unchecked(l1, P1, l2, P2, same_side)


def _difference_unchecked(
    l1: FloatArray, P1: FloatArray, l2: FloatArray, P2: FloatArray, same_side: bool
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    a1, r1 = l1[..., 1], l1[..., 0]
    P1 = P1[..., :2, :2]
    P2 = P2[..., :2, :2]
    if same_side:
        d_alpha = np.asarray(wrap_angle(a1 - l2[..., 1]))
        opposite = np.abs(d_alpha) > np.pi / 2.0
        delta = np.stack(np.broadcast_arrays(r1 - l2[..., 0], d_alpha), -1)
        P2a = P2
    else:
        l2a, P2a, _ = align_representative(l2[..., :2], P2, a1)
        delta = np.stack(np.broadcast_arrays(r1 - l2a[..., 0], a1 - l2a[..., 1]), -1)
        opposite = np.zeros(delta.shape[:-1], dtype=bool)
    return delta, P1 + P2a, opposite


def mahalanobis2_unchecked(
    l1: FloatArray, P1: FloatArray, l2: FloatArray, P2: FloatArray, same_side: bool = False
) -> FloatArray:
    """:func:`mahalanobis2` without input validation (for inner loops on validated arrays)."""
    delta, S, opposite = _difference_unchecked(l1, P1, l2, P2, same_side)
    Si = inv2x2(S, "P1 + P2")
    d2 = np.einsum("...i,...ij,...j->...", delta, Si, delta)
    return np.where(opposite, np.inf, d2)


def mahalanobis2(
    l1: FloatArray,
    P1: FloatArray,
    l2: FloatArray,
    P2: FloatArray,
    same_side: bool = False,
) -> FloatArray:
    """Squared Mahalanobis distance of Eq. 34 on ``(r, α)``, vectorised over pairs.

    ``D² = δᵀ (P₁ + P₂)⁻¹ δ`` with the 2×2 ``(r, α)`` blocks of the covariances (reading note 4),
    ``δ = (r₁ − r₂, wrap(α₁ − α₂))`` after bringing line 2 to line 1's representative.

    Parameters
    ----------
    l1, l2 : ndarray, shape (..., 2) or (..., 3)
        Lines; only ``(r, α)`` are used.  Leading shapes broadcast (e.g. ``(N, 1, 3)`` against
        ``(1, M, 3)`` for all pairs).
    P1, P2 : ndarray, shape (..., 2, 2) or (..., 3, 3)
        Their covariances.
    same_side : bool
        Do not flip representatives; pairs whose normals are more than 90° apart get ``inf``.

    Returns
    -------
    ndarray, shape (...)
        ``D²`` of every pair.

    Raises
    ------
    DegenerateGeometryError
        ``P₁ + P₂`` singular for some pair, or a covariance that is not one.
    """
    delta, S, opposite = _difference(l1, P1, l2, P2, same_side)
    Si = inv2x2(S, "P1 + P2")
    d2 = np.einsum("...i,...ij,...j->...", delta, Si, delta)
    return np.where(opposite, np.inf, d2)


def is_compatible(
    l1: FloatArray,
    P1: FloatArray,
    l2: FloatArray,
    P2: FloatArray,
    probability: float = DEFAULT_GATE_PROBABILITY,
    same_side: bool = False,
) -> NDArray[np.bool_]:
    """Merge criterion of Eq. 35: ``D² ≤ χ²₂(probability)`` (vectorised over pairs)."""
    return np.asarray(mahalanobis2(l1, P1, l2, P2, same_side) <= chi2_gate(probability))


def _s_weight_variance(P: FloatArray) -> FloatArray:
    """Variance of ``s`` given ``α`` (Schur complement), the basis of the centroid weights.

    A fitted line's ``P_ss`` mostly reflects its rotation (``s`` moves by ``−r δα``); the part
    that tells how many and how precise the points along the line are is the variance left
    when ``α`` is known: ``P_ss − P_sα²/P_αα`` (``= 1/Σ(1/P_S)``, Eq. 23, when ``s`` and ``α``
    are uncorrelated).  Weighting the centroids by its inverse makes the fused ``s`` the
    weighted centroid of all the points (tested against a joint fit).
    """
    Pss = P[..., 2, 2]
    Paa = P[..., 1, 1]
    Psa = P[..., 2, 1]
    safe = np.where(Paa > 0.0, Paa, 1.0)
    cond = np.where(Paa > 0.0, Pss - Psa**2 / safe, Pss)
    return np.asarray(np.maximum(cond, 1e-12 * Pss))


def fuse(
    l1: FloatArray,
    P1: FloatArray,
    l2: FloatArray,
    P2: FloatArray,
    normal_form: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Maximum-likelihood combination of two estimates of the same line (Eqs. 36-37).

    Parameters
    ----------
    l1, l2 : ndarray, shape (..., 3) or (..., 2)
        ``(r, α, s)`` (or just ``(r, α)``) in a common frame.
    P1, P2 : ndarray, shape (..., 3, 3) or (..., 2, 2)
        Covariances; only ``P₁ + P₂`` (on ``(r, α)``) needs to be invertible.
    normal_form : bool
        True: the result has ``r ≥ 0``, ``α ∈ (−π, π]``.  False: the result keeps line 1's
        representative (its normal direction).

    Returns
    -------
    line : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
        ``(r, α)``: Eqs. 36-37 (gain form).  ``s``: the ``1/P_s|α``-weighted mean of both
        centroids projected on the fused line (``P_s|α = P_ss − P_sα²/P_αα``), covariance by
        first-order propagation (for uncorrelated ``s``: ``1/(1/P_ss₁ + 1/P_ss₂)`` plus the
        effect of the fused line's rotation); see the module docstring.

    Raises
    ------
    DegenerateGeometryError
        ``P₁ + P₂`` is singular, or an input is not a covariance.
    InputError
        Mismatched dimensions.
    """
    l1 = _as_line(l1, "l1")
    l2 = _as_line(l2, "l2")
    d = l1.shape[-1]
    if l2.shape[-1] != d:
        raise InputError(f"fuse: lines of different sizes {l1.shape} and {l2.shape}")
    P1 = check_covariance(P1, d, "P1")
    P2 = check_covariance(P2, d, "P2")
    l2a, P2a, _ = align_representative(l2, P2, l1[..., 1])
    lead = np.broadcast_shapes(l1.shape[:-1], l2a.shape[:-1], P1.shape[:-2], P2a.shape[:-2])
    l1b = np.broadcast_to(l1, (*lead, d))
    l2a = np.broadcast_to(l2a, (*lead, d))
    P1b = np.broadcast_to(P1, (*lead, d, d))
    P2a = np.broadcast_to(P2a, (*lead, d, d))

    A1 = P1b[..., :2, :2]
    A2 = P2a[..., :2, :2]
    Si = inv2x2(A1 + A2, "P1 + P2")
    G = A1 @ Si  # gain on (r, α)
    x1, x2 = l1b[..., :2], l2a[..., :2]
    xm = x1 + np.einsum("...ij,...j->...i", G, x2 - x1)
    eye = np.broadcast_to(np.eye(2), G.shape)
    W1, W2 = eye - G, G  # ∂x_m/∂x_1, ∂x_m/∂x_2
    Pm_ra = W1 @ A1  # (I − G) P₁ = (P₁⁻¹ + P₂⁻¹)⁻¹

    if d == 2:
        line = xm
        cov = 0.5 * (Pm_ra + np.swapaxes(Pm_ra, -1, -2))
    else:
        r_m, a_m = xm[..., 0], xm[..., 1]
        n_m = np.stack([np.cos(a_m), np.sin(a_m)], -1)
        t_m = np.stack([-np.sin(a_m), np.cos(a_m)], -1)
        v1 = _s_weight_variance(P1b)
        v2 = _s_weight_variance(P2a)
        # weights 1/P_ss (a line with P_ss = 0 pins s; two such lines: plain mean)
        both_zero = (v1 <= 0.0) & (v2 <= 0.0)
        w1 = np.where(both_zero, 0.5, np.where(v1 <= 0.0, 1.0, 0.0))
        w1 = np.where((v1 > 0.0) & (v2 > 0.0), v2 / np.where(v1 + v2 > 0, v1 + v2, 1.0), w1)
        w1 = np.where((v1 > 0.0) & (v2 <= 0.0), 0.0, w1)
        w2 = 1.0 - w1

        def centroid(l: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            n = np.stack([np.cos(l[..., 1]), np.sin(l[..., 1])], -1)
            t = np.stack([-np.sin(l[..., 1]), np.cos(l[..., 1])], -1)
            c = l[..., 0:1] * n + l[..., 2:3] * t
            return c, n, t

        c1, n1, t1 = centroid(l1b)
        c2, n2, t2 = centroid(l2a)
        cbar = w1[..., None] * c1 + w2[..., None] * c2
        s_m = np.sum(cbar * t_m, axis=-1)
        # Jacobian of s_m wrt (r_k, α_k, s_k), direct part, then through α_m
        dsm_dam = -np.sum(cbar * n_m, axis=-1)

        def direct(c: FloatArray, n: FloatArray, t: FloatArray, l: FloatArray) -> FloatArray:
            dr = np.sum(n * t_m, -1)
            da = np.sum((l[..., 0:1] * t - l[..., 2:3] * n) * t_m, -1)
            ds = np.sum(t * t_m, -1)
            return np.stack([dr, da, ds], -1)

        row1 = w1[..., None] * direct(c1, n1, t1, l1b)
        row2 = w2[..., None] * direct(c2, n2, t2, l2a)
        row1[..., :2] += dsm_dam[..., None] * W1[..., 1, :]
        row2[..., :2] += dsm_dam[..., None] * W2[..., 1, :]
        # full 3×6 Jacobian; (r, α) rows carry the gain, no dependence on s_k
        shape = G.shape[:-2]
        J1 = np.zeros((*shape, 3, 3))
        J2 = np.zeros((*shape, 3, 3))
        J1[..., :2, :2] = W1
        J2[..., :2, :2] = W2
        J1[..., 2, :] = row1
        J2[..., 2, :] = row2
        cov = J1 @ P1b @ np.swapaxes(J1, -1, -2) + J2 @ P2a @ np.swapaxes(J2, -1, -2)
        cov[..., :2, :2] = Pm_ra  # identical to first order; exact Eq. 37 form
        cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        line = np.stack([r_m, a_m, s_m], -1)

    if normal_form:
        return to_normal_form(line, cov)
    line = np.array(line, copy=True)
    line[..., 1] = np.asarray(wrap_angle(line[..., 1]))
    return line, cov


def fuse_pair_unchecked(
    l1: FloatArray, P1: FloatArray, l2: FloatArray, P2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`fuse` of one pair of ``(r, α, s)`` lines, no validation, line 1's representative.

    Same result as ``fuse(l1, P1, l2, P2, normal_form=False)`` (tested), about 20× faster:
    for inner loops (map building) on arrays that were validated once.
    """
    r1, a1, s1 = float(l1[0]), float(l1[1]), float(l1[2])
    r2, a2, s2 = float(l2[0]), float(l2[1]), float(l2[2])
    d = (a2 - a1 + np.pi) % (2.0 * np.pi) - np.pi
    if abs(d) > np.pi / 2.0:
        r2, s2 = -r2, -s2
        d = (d + 2.0 * np.pi) % (2.0 * np.pi) - np.pi
        flip = np.array([-1.0, 1.0, -1.0])
        P2 = P2 * flip[:, None] * flip[None, :]
    a2 = a1 + d
    A1, A2 = P1[:2, :2], P2[:2, :2]
    S = A1 + A2
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    if not (S[0, 0] > 0.0 and S[1, 1] > 0.0 and det > 1e-14 * S[0, 0] * S[1, 1]):
        raise DegenerateGeometryError("P1 + P2 is singular or not positive definite")
    Si = np.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det
    G = A1 @ Si
    W1 = np.eye(2) - G
    r_m, a_m = np.array([r1, a1]) + G @ np.array([r2 - r1, a2 - a1])
    v1, v2 = float(_s_weight_variance(P1)), float(_s_weight_variance(P2))
    if v1 > 0.0 and v2 > 0.0:
        w1 = v2 / (v1 + v2)
    elif v1 <= 0.0 and v2 <= 0.0:
        w1 = 0.5
    else:
        w1 = 1.0 if v1 <= 0.0 else 0.0
    w2 = 1.0 - w1
    cm, sm = np.cos(a_m), np.sin(a_m)
    c1, sn1, c2, sn2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
    # centroids c_k = r_k n_k + s_k t_k and their weighted mean
    cx = w1 * (r1 * c1 - s1 * sn1) + w2 * (r2 * c2 - s2 * sn2)
    cy = w1 * (r1 * sn1 + s1 * c1) + w2 * (r2 * sn2 + s2 * c2)
    s_m = -cx * sm + cy * cm
    dsm_dam = -(cx * cm + cy * sm)
    # ∂(c_k·t_m)/∂(r_k, α_k, s_k): (n_k·t_m, (r_k t_k − s_k n_k)·t_m, t_k·t_m)
    nt1, tt1 = -c1 * sm + sn1 * cm, sn1 * sm + c1 * cm
    nt2, tt2 = -c2 * sm + sn2 * cm, sn2 * sm + c2 * cm
    row1 = w1 * np.array([nt1, r1 * tt1 - s1 * nt1, tt1])
    row2 = w2 * np.array([nt2, r2 * tt2 - s2 * nt2, tt2])
    row1[:2] += dsm_dam * W1[1]
    row2[:2] += dsm_dam * G[1]
    J1 = np.zeros((3, 3))
    J2 = np.zeros((3, 3))
    J1[:2, :2], J2[:2, :2] = W1, G
    J1[2], J2[2] = row1, row2
    cov = J1 @ P1 @ J1.T + J2 @ P2 @ J2.T
    cov[:2, :2] = W1 @ A1
    cov = 0.5 * (cov + cov.T)
    a_m = (a_m + np.pi) % (2.0 * np.pi) - np.pi
    if a_m == -np.pi:
        a_m = np.pi
    return np.array([r_m, a_m, s_m]), cov


def to_normal_form(line: FloatArray, cov: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Lines ``(..., d)`` and covariances ``(..., d, d)`` in normal form (``r ≥ 0``, α wrapped).

    Where ``r < 0`` the line becomes ``(−r, α + π, −s)`` and the covariance's ``r`` and ``s``
    rows and columns change sign.
    """
    line = np.array(line, dtype=float, copy=True)
    cov = np.asarray(cov, dtype=float)
    d = line.shape[-1]
    flip = line[..., 0] < 0.0
    sign = np.where(flip, -1.0, 1.0)
    row = np.ones((*sign.shape, d))
    row[..., 0] = sign
    line[..., 0] *= sign
    line[..., 1] = np.asarray(wrap_angle(line[..., 1] + np.where(flip, np.pi, 0.0)))
    if d == 3:
        line[..., 2] *= sign
        row[..., 2] = sign
    return line, cov * row[..., :, None] * row[..., None, :]


def fuse_many(
    lines: FloatArray, covs: FloatArray, normal_form: bool = True
) -> tuple[FloatArray, FloatArray]:
    """Fuse ``n`` estimates of one line (sequential :func:`fuse`; order-independent result).

    Parameters
    ----------
    lines : ndarray, shape (n, d)
    covs : ndarray, shape (n, d, d)

    Returns
    -------
    line : ndarray, shape (d,)
    cov : ndarray, shape (d, d)
    """
    lines = _as_line(lines, "lines")
    if lines.ndim != 2 or lines.shape[0] == 0:
        raise InputError(f"fuse_many: expected (n, d) lines with n >= 1, got {lines.shape}")
    line, cov = lines[0], np.asarray(covs[0], dtype=float)
    for k in range(1, lines.shape[0]):
        line, cov = fuse(line, cov, lines[k], covs[k], normal_form=False)
    if normal_form:
        return to_normal_form(line, cov)
    return line, cov


# ---------------------------------------------------------------------------------------------
# Segments along a line
# ---------------------------------------------------------------------------------------------
def extent_gap(extent1: FloatArray, extent2: FloatArray) -> FloatArray:
    """Gap (m) between intervals ``(lo, hi)`` along a line; ``< 0`` means they overlap.

    Vectorised: ``(..., 2)`` against ``(..., 2)``.
    """
    e1 = np.asarray(extent1, dtype=float)
    e2 = np.asarray(extent2, dtype=float)
    return np.asarray(
        np.maximum(e1[..., 0], e2[..., 0]) - np.minimum(e1[..., 1], e2[..., 1]), dtype=float
    )


def unite_segments(
    segments_s: FloatArray,
    segments_var: FloatArray,
    gap_tolerance_m: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Unite overlapping intervals along a line; keep separate ones (multi-segment line).

    Intervals whose gap is at most ``gap_tolerance_m`` are united into one segment from the
    smallest start to the largest end; each end keeps the variance of the end-measurement that
    defines it (Sec. V: "maxima and minima of the end-measurements").

    Parameters
    ----------
    segments_s : ndarray, shape (k, 2)
        ``(s_start, s_end)`` rows, any order, all in the same line's tangent coordinate.
    segments_var : ndarray, shape (k, 2)
        Variances of the ends.
    gap_tolerance_m : float
        Largest gap bridged (m); 0 unites only touching or overlapping segments.

    Returns
    -------
    segments_s, segments_var : ndarray, shape (k', 2)
        Disjoint, sorted by start.
    """
    seg = np.asarray(segments_s, dtype=float).reshape(-1, 2)
    var = np.asarray(segments_var, dtype=float).reshape(-1, 2)
    if seg.shape[0] == 0:
        return seg.copy(), var.copy()
    if seg.shape[0] == 1:
        if seg[0, 0] <= seg[0, 1]:
            return seg.copy(), var.copy()
        return seg[:, ::-1].copy(), var[:, ::-1].copy()
    lo = np.minimum(seg[:, 0], seg[:, 1])
    hi = np.maximum(seg[:, 0], seg[:, 1])
    order = np.argsort(lo, kind="stable")
    lo, hi, var = lo[order], hi[order], var[order]
    run_hi = np.maximum.accumulate(hi)
    new_group = np.ones(lo.shape[0], dtype=bool)
    new_group[1:] = lo[1:] > run_hi[:-1] + gap_tolerance_m
    starts = np.flatnonzero(new_group)
    group = np.cumsum(new_group) - 1
    out_lo = lo[starts]
    out_lo_var = var[starts, 0]
    out_hi = np.maximum.reduceat(hi, starts)
    # variance of the end that attains the group's maximum (last one on ties)
    is_max = hi == out_hi[group]
    idx = np.arange(lo.shape[0])
    best = np.full(starts.shape[0], -1)
    np.maximum.at(best, group[is_max], idx[is_max])
    out_hi_var = var[best, 1]
    return np.column_stack([out_lo, out_hi]), np.column_stack([out_lo_var, out_hi_var])
