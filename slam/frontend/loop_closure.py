"""Loop-closure search: find the local submap's lines in the old map (numpy; one numba kernel).

After a long loop the drift between the robot and the walls it mapped long ago can be metres and
tens of degrees, far beyond what χ² gates on the current estimate can bridge safely.  This
module searches for the rigid correction ``T`` (rotation ``dθ`` about the robot's position
``c``, then translation ``t``) that lays the recent lines (*local*) onto the old ones, inside a
window ``|t| ≤ W``, ``|dθ| ≤ Θ``:

1. **Oriented lines.**  Each line carries the normal that points from where it was seen towards
   the wall (:class:`LoopLines`), so a wall and the other face of a thin wall are never
   confused and a pair of lines fixes the rotation without the ``π`` ambiguity.
2. **Rotation candidates**: a histogram of the angle differences ``α_old − α_local`` of all
   pairs within the window, weighted by the shorter line's length, smoothed over the angle
   tolerance; its highest peaks.
3. **Translation vote** per rotation: a pair ``(i, j)`` whose angles agree after the rotation
   constrains ``t`` to a line, ``n_j·t = r_j − r_i'`` (``r_i'`` the rotated local line's
   offset).  Each constraint votes, with the local line's length, into the cells of a grid over
   the window that it crosses (a local line votes at most once per cell); peaks are where
   constraints from different directions cross (a 2-D Hough transform of the line pairs;
   the sampling and counting are compiled, :func:`_constraint_votes`).
4. **Verification** of each peak: transform the local lines, pair each with the nearest old line
   within the angle and offset tolerances whose segment overlaps it, refine ``T`` by weighted
   least squares on the pairs (re-pairing in between), score = the overlapping length.  A
   hypothesis counts if it pairs at least ``min_matches`` lines of ``min_matched_length_m``
   total in two directions at least ``min_direction_angle_rad`` apart (otherwise a corridor
   slides along itself); the winner must beat every distinct runner-up by the factor
   ``1 / max_ambiguity`` (repeated structure: rows of identical doors or offices).

The caller (:class:`slam.line_slam.LineSlam`) merges the paired landmarks and keeps the closure only
if the optimised graph explains it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit
from numpy.typing import NDArray

from linefit.line import wrap_angle
from slam.geometry import pose_between, pose_inverse, wrap_angle_compiled

__all__ = [
    "LoopClosure",
    "LoopLines",
    "LoopSearch",
    "correction_chi2",
    "correction_covariance",
    "same_correction",
    "search_loop_closure",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class LoopConfig(Protocol):
    """The settings used here (:class:`slam.frontend.config.LoopClosureConfig`, read only)."""

    @property
    def cell_m(self) -> float: ...

    @property
    def angle_tolerance_rad(self) -> float: ...

    @property
    def offset_tolerance_m(self) -> float: ...

    @property
    def overlap_margin_m(self) -> float: ...

    @property
    def min_matched_length_m(self) -> float: ...

    @property
    def min_matches(self) -> int: ...

    @property
    def min_direction_angle_rad(self) -> float: ...

    @property
    def min_cross_length_m(self) -> float: ...

    @property
    def max_ambiguity(self) -> float: ...

    @property
    def corridor_closures(self) -> bool: ...


@dataclass(frozen=True, eq=False)
class LoopLines:
    """Oriented world lines ``{p : p·n(α) = r}`` with their seen extents.

    Attributes
    ----------
    alpha : ndarray, shape (K,)
        Normal angle; the normal points from the side the line was seen from towards it.
    r : ndarray, shape (K,)
        Offset along that normal (any sign).
    ends : ndarray, shape (K, 2, 2)
        World end points of the seen extent.
    """

    alpha: FloatArray
    r: FloatArray
    ends: FloatArray

    def __len__(self) -> int:
        return int(self.alpha.shape[0])

    @property
    def length(self) -> FloatArray:
        """Length of each extent (m)."""
        return np.asarray(np.linalg.norm(self.ends[:, 1] - self.ends[:, 0], axis=1))

    @classmethod
    def from_anchored(
        cls, rho_phi: FloatArray, anchors: FloatArray, extents: FloatArray, side: FloatArray
    ) -> LoopLines:
        """Oriented lines from anchored landmarks.

        Landmarks ``(ρ, φ)`` at ``anchors`` with extents ``(s_lo, s_hi)`` along
        ``t(φ)`` from the anchor, and ``side`` = +1 where ``n(φ)`` points away from the
        observer (−1: the other way).
        """
        v = np.asarray(rho_phi, dtype=float).reshape(-1, 2)
        c = np.asarray(anchors, dtype=float).reshape(-1, 2)
        phi = v[:, 1]
        n = np.stack([np.cos(phi), np.sin(phi)], -1)
        t = np.stack([-n[:, 1], n[:, 0]], -1)
        foot = c + v[:, 0:1] * n
        ext = np.asarray(extents, dtype=float).reshape(-1, 2)
        ends = foot[:, None, :] + ext[:, :, None] * t[:, None, :]
        sgn = np.asarray(side, dtype=float).reshape(-1)
        r = sgn * (np.sum(c * n, axis=1) + v[:, 0])
        alpha = np.asarray(wrap_angle(phi + np.where(sgn < 0, np.pi, 0.0)))
        return cls(alpha, r, ends)

    def transformed(self, correction: FloatArray, center: FloatArray) -> LoopLines:
        """The lines moved by ``p → R(dθ)(p − c) + c + t``, ``correction = (t_x, t_y, dθ)``."""
        tx, ty, dth = (float(v) for v in correction)
        c = np.asarray(center, dtype=float)
        cs, sn = np.cos(dth), np.sin(dth)
        Rm = np.array([[cs, -sn], [sn, cs]])
        ends = (self.ends - c) @ Rm.T + c + np.array([tx, ty])
        a = np.asarray(wrap_angle(self.alpha + dth))
        n_old = np.stack([np.cos(self.alpha), np.sin(self.alpha)], -1)
        n_new = np.stack([np.cos(a), np.sin(a)], -1)
        r = self.r - n_old @ c + n_new @ c + n_new @ np.array([tx, ty])
        return LoopLines(a, r, ends)


@dataclass(frozen=True, eq=False)
class LoopClosure:
    """A verified correction.

    Attributes
    ----------
    correction : ndarray, shape (3,)
        ``(t_x, t_y, dθ)``: ``p → R(dθ)(p − c) + c + t`` lays the local lines onto the old ones.
    pairs : list of (int, int)
        ``(local row, old row)`` of the paired lines.
    score : float
        Overlapping length of the pairs (m).
    runner_up : float
        Score of the best distinct other hypothesis.
    single_direction : bool
        All paired lines are (nearly) parallel: a corridor, where the position along it is not
        constrained (the correction's component along it is arbitrary).
    """

    correction: FloatArray
    pairs: list[tuple[int, int]]
    score: float
    runner_up: float
    single_direction: bool = False


@dataclass(frozen=True, eq=False)
class LoopSearch:
    """What a search found.

    Attributes
    ----------
    closure : LoopClosure or None
        The verified, unambiguous correction; None when there is none.
    reason : str
        Why there is none (``"too few lines"``, ``"no hypothesis"``, ``"none verified (…)"``,
        ``"ambiguous (winner vs runner-up)"``), or ``"found"``.
    """

    closure: LoopClosure | None
    reason: str


@njit(cache=True, nogil=True)
def _pairs_kernel(
    l_alpha: FloatArray,
    l_r: FloatArray,
    l_ends: FloatArray,
    o_alpha: FloatArray,
    o_r: FloatArray,
    o_ends: FloatArray,
    o_tangent: FloatArray,
    angle_tolerance: float,
    offset_tolerance: float,
    overlap_margin: float,
) -> tuple[IntArray, IntArray, FloatArray]:  # pragma: no cover - compiled
    """The pairing of :func:`_pairs_at` (compiled).

    ``o_tangent`` holds the old lines' tangents ``(−sin α, cos α)``.

    Per local line, over the old lines in order: the angle and offset differences, the
    overlap along the old line's tangent (each end point's coordinate summed as ``einsum``
    sums it) for those within the tolerances, and the first old line of least cost among
    those that overlap enough (``np.argmin``'s choice).
    """
    K, M = l_alpha.shape[0], o_alpha.shape[0]
    rows = np.empty(K, np.intp)
    cols = np.empty(K, np.intp)
    lengths = np.empty(K)
    n = 0
    for k in range(K):
        best = np.inf
        best_m = -1
        best_overlap = 0.0
        for m in range(M):
            da = abs(wrap_angle_compiled(l_alpha[k] - o_alpha[m]))
            dr = abs(l_r[k] - o_r[m])
            if not (da < angle_tolerance and dr < offset_tolerance):
                continue
            t0, t1 = o_tangent[m, 0], o_tangent[m, 1]
            a0 = 0.0 + l_ends[k, 0, 0] * t0 + l_ends[k, 0, 1] * t1
            a1 = 0.0 + l_ends[k, 1, 0] * t0 + l_ends[k, 1, 1] * t1
            b0 = 0.0 + o_ends[m, 0, 0] * t0 + o_ends[m, 0, 1] * t1
            b1 = 0.0 + o_ends[m, 1, 0] * t0 + o_ends[m, 1, 1] * t1
            overlap = min(max(a0, a1), max(b0, b1)) - max(min(a0, a1), min(b0, b1))
            if not overlap > -overlap_margin:
                continue
            cost = dr / offset_tolerance + da / angle_tolerance
            if cost < best:
                best, best_m, best_overlap = cost, m, overlap
        if best_m >= 0:
            rows[n], cols[n] = k, best_m
            lengths[n] = max(best_overlap, 0.0)
            n += 1
    return rows[:n], cols[:n], lengths[:n]


def _pairs_at(
    local: LoopLines, old: LoopLines, config: LoopConfig
) -> tuple[IntArray, IntArray, FloatArray]:
    """Best old line for each local line (already transformed): rows and overlap lengths.

    An old line pairs a local one within the angle and offset tolerances and when their
    segments overlap (along the old line) by more than ``-overlap_margin_m``; the best has the
    least ``dr / offset_tolerance + da / angle_tolerance`` (the first such old line on ties).
    """
    tangent = np.empty((len(old), 2))
    np.negative(np.sin(old.alpha), out=tangent[:, 0])
    np.cos(old.alpha, out=tangent[:, 1])
    f = np.ascontiguousarray
    return _pairs_kernel(
        f(local.alpha, dtype=float),
        f(local.r, dtype=float),
        f(local.ends, dtype=float),
        f(old.alpha, dtype=float),
        f(old.r, dtype=float),
        f(old.ends, dtype=float),
        tangent,
        float(config.angle_tolerance_rad),
        float(config.offset_tolerance_m),
        float(config.overlap_margin_m),
    )


def _correction_jacobian(alpha: FloatArray, c_t: FloatArray) -> FloatArray:
    """Jacobian of moved lines' ``(r, α)`` w.r.t. a small extra correction ``(δt, δθ)``.

    Lines of normal angles ``alpha`` ``(K,)``, already moved by a correction whose rotation
    centre is now ``c_t``: ``r' = r + n·δt + δθ·t·c_t``, ``α' = α + δθ`` (``t`` the line's
    direction).  Rows ``2k`` (offset) and ``2k + 1`` (angle), shape ``(2K, 3)``.
    """
    n = np.stack([np.cos(alpha), np.sin(alpha)], -1)
    tdir = np.stack([-n[:, 1], n[:, 0]], -1)
    A = np.zeros((2 * alpha.size, 3))
    A[0::2, :2] = n
    A[0::2, 2] = tdir @ c_t
    A[1::2, 2] = 1.0
    return A


def _refine(
    local: LoopLines,
    old: LoopLines,
    center: FloatArray,
    correction: FloatArray,
    config: LoopConfig,
    window: tuple[float, float] | None = None,
) -> tuple[FloatArray, IntArray, IntArray, FloatArray]:
    """Alternate pairing and weighted least squares on ``(t_x, t_y, dθ)``.

    ``window = (W, Θ)`` adds the search window as a weak zero-mean prior on the correction
    (standard deviations ``W``, ``W``, ``Θ``): when the pairs constrain only some directions
    (parallel lines: the position along them), the correction stays inside the window in the
    others instead of taking an arbitrary value from a near-singular system.
    """
    corr = np.asarray(correction, dtype=float).copy()
    prior = (
        np.diag([window[0] ** -2, window[0] ** -2, window[1] ** -2])
        if window is not None
        else np.zeros((3, 3))
    )
    i = j = np.zeros(0, np.intp)
    w = np.zeros(0)
    for _ in range(3):
        moved = local.transformed(corr, center)
        i, j, w = _pairs_at(moved, old, config)
        if i.size < 2:
            break
        # residuals of the moved lines against their old partners; Jacobians w.r.t. a small
        # extra correction (δt, δθ) applied after the current one
        c_t = np.asarray(center) + corr[:2]  # rotation centre after the current translation
        e_r = moved.r[i] - old.r[j]
        e_a = np.asarray(wrap_angle(moved.alpha[i] - old.alpha[j]))
        A = _correction_jacobian(moved.alpha[i], c_t)
        b = np.empty(2 * i.size)
        b[0::2] = -e_r
        b[1::2] = -e_a
        sig_r, sig_a = config.offset_tolerance_m / 3.0, config.angle_tolerance_rad / 3.0
        W = np.empty(2 * i.size)
        wl = np.maximum(w, 0.1)
        W[0::2] = wl / sig_r**2
        W[1::2] = wl / sig_a**2
        H = A.T @ (A * W[:, None]) + prior + 1e-9 * np.eye(3)
        step = np.linalg.solve(H, A.T @ (W * b) - prior @ corr)
        corr[:2] += step[:2]
        corr[2] += step[2]
    return corr, i, j, w


class _Hypothesis:
    """A refined correction with its pairs, score and constrained directions."""

    def __init__(
        self,
        corr: FloatArray,
        i: IntArray,
        j: IntArray,
        score: float,
        alpha: FloatArray,
        w: FloatArray,
        config: LoopConfig,
    ) -> None:
        self.corr, self.i, self.j, self.score = corr, i, j, score
        # translation information of the pairs: Σ w n nᵀ; one direction when the lines' normals
        # all lie within min_direction_angle of each other
        cross = 0.0
        if alpha.size:
            d = np.abs(np.sin(alpha[:, None] - alpha[None, :]))
            self.single = bool(d.max() < np.sin(config.min_direction_angle_rad))
            k = int(np.argmax(w))
            self.normal = np.array([np.cos(alpha[k]), np.sin(alpha[k])])
            # matched length across the dominant direction: what fixes the position along it
            across = np.abs(np.sin(alpha - alpha[k])) >= np.sin(config.min_direction_angle_rad)
            cross = float(w[across].sum())
        else:
            self.single = True
            self.normal = np.array([1.0, 0.0])
        need = config.min_matched_length_m * (1.0 if not self.single else 1.5)
        self.valid = (
            i.size >= config.min_matches
            and score >= need
            and (
                cross >= config.min_cross_length_m if not self.single else config.corridor_closures
            )
        )

    def distinct(self, other: _Hypothesis, config: LoopConfig) -> bool:
        """Whether ``other`` is a different solution (not this one moved along a corridor)."""
        if not self.single:
            return not same_correction(self.corr, other.corr, config)
        if abs(float(wrap_angle(other.corr[2] - self.corr[2]))) > 2.0 * config.angle_tolerance_rad:
            return True
        dt = other.corr[:2] - self.corr[:2]
        return bool(abs(dt @ self.normal) > 2.0 * config.offset_tolerance_m)


def correction_covariance(
    local: LoopLines,
    old: LoopLines,
    pairs: list[tuple[int, int]],
    center: FloatArray,
    correction: FloatArray,
    config: LoopConfig,
    window: tuple[float, float],
) -> FloatArray:
    """Covariance of a correction ``(t_x, t_y, dθ)`` from its paired lines.

    The least squares of :func:`_refine` at the correction, each pair's offset and angle with
    the search's own standard deviations (a third of ``offset_tolerance_m`` and of
    ``angle_tolerance_rad``, one pair one measurement, not weighted by its overlap) and the
    window ``(W, Θ)`` as the prior: ``(AᵀWA + diag(W⁻², W⁻², Θ⁻²))⁻¹``.  Along a corridor the
    position along the walls keeps the window's variance.
    """
    c = np.asarray(center, dtype=float).reshape(2)
    corr = np.asarray(correction, dtype=float)
    i = np.array([a for a, _ in pairs], dtype=np.intp)
    moved = local.transformed(corr, c)
    A = _correction_jacobian(moved.alpha[i], c + corr[:2])
    W = np.empty(2 * i.size)
    W[0::2] = (config.offset_tolerance_m / 3.0) ** -2
    W[1::2] = (config.angle_tolerance_rad / 3.0) ** -2
    prior = np.diag([window[0] ** -2, window[0] ** -2, window[1] ** -2])
    return np.asarray(np.linalg.inv(A.T @ (A * W[:, None]) + prior), dtype=float)


def same_correction(a: FloatArray, b: FloatArray, config: LoopConfig) -> bool:
    """Whether two corrections ``(t_x, t_y, dθ)`` are one solution.

    Within twice the angle and the offset tolerance of each other.
    """
    if abs(float(wrap_angle(b[2] - a[2]))) > 2.0 * config.angle_tolerance_rad:
        return False
    return bool(np.hypot(b[0] - a[0], b[1] - a[1]) <= 2.0 * config.offset_tolerance_m)


def correction_chi2(
    pose_old: FloatArray, pose_now: FloatArray, P_joint: FloatArray, correction: FloatArray
) -> float:
    """Squared Mahalanobis distance of a correction under two poses' joint covariance.

    The correction ``T = (t_x, t_y, dθ)`` (``p → R(dθ)(p − c) + c + t`` about the position
    ``c`` of ``pose_now``) moves ``pose_now`` by ``(t, dθ)`` and leaves ``pose_old``: in
    ``pose_now``'s frame a change ``δ = (R(θ)ᵀ t, dθ)`` of the relative pose
    ``r = pose_old⁻¹ ∘ pose_now``.  With right perturbations of both poses
    (``x ∘ Exp(ξ)``, GTSAM's convention) ``r`` moves by ``A [ξ_old; ξ_now]``,
    ``A = [−Ad(r⁻¹), I]``, so ``δ`` is compared with ``S = A P_joint Aᵀ``.

    Parameters
    ----------
    pose_old, pose_now : ndarray, shape (3,)
        ``(x, y, θ)`` in the world.
    P_joint : ndarray, shape (6, 6)
        Joint covariance of ``(pose_old, pose_now)``.
    correction : ndarray, shape (3,)

    Returns
    -------
    float
        ``δᵀ S⁻¹ δ``; ``inf`` when ``S`` is singular and ``δ`` is not zero.
    """
    r_inv = pose_inverse(pose_between(pose_old, pose_now))
    c, s = np.cos(r_inv[2]), np.sin(r_inv[2])
    ad = np.array([[c, -s, r_inv[1]], [s, c, -r_inv[0]], [0.0, 0.0, 1.0]])
    A = np.hstack([-ad, np.eye(3)])
    S = A @ np.asarray(P_joint, dtype=float) @ A.T
    t = np.asarray(correction, dtype=float)
    ct, st = np.cos(pose_now[2]), np.sin(pose_now[2])
    delta = np.array([ct * t[0] + st * t[1], -st * t[0] + ct * t[1], t[2]])
    try:
        return float(delta @ np.linalg.solve(S, delta))
    except np.linalg.LinAlgError:
        return 0.0 if not np.any(delta) else float("inf")


def _rotation_candidates(
    local: LoopLines, old: LoopLines, window_theta: float, tol: float, n_max: int
) -> list[float]:
    d = np.asarray(wrap_angle(old.alpha[None, :] - local.alpha[:, None])).ravel()
    w = np.minimum(local.length[:, None], old.length[None, :]).ravel()
    inside = np.abs(d) <= window_theta + tol
    d, w = d[inside], w[inside]
    if d.size == 0:
        return []
    bin_w = tol / 2.0
    nb = int(np.ceil((2 * (window_theta + tol)) / bin_w)) + 1
    edges0 = -(window_theta + tol)
    b = np.clip(((d - edges0) / bin_w).astype(int), 0, nb - 1)
    hist = np.bincount(b, weights=w, minlength=nb)
    k = 2  # smooth over ±tol
    kernel = np.ones(2 * k + 1)
    sm = np.convolve(hist, kernel, mode="same")
    out: list[float] = []
    # highest smoothed count first; among equal ones the fullest bin (exact data fill the
    # bins around a peak equally)
    order = np.lexsort((hist, sm))[::-1]
    for idx in order:
        if len(out) >= n_max or sm[idx] <= 0:
            break
        centre = edges0 + (idx + 0.5) * bin_w
        if abs(centre) > window_theta:
            continue
        if all(abs(centre - c) > 2 * tol for c in out):
            sel = np.abs(d - centre) <= tol
            out.append(float(np.average(d[sel], weights=w[sel])) if np.any(sel) else centre)
    return out


def _sample_ranges(
    b: FloatArray,
    n: FloatArray,
    tdir: FloatArray,
    s: FloatArray,
    lo: float,
    hi: float,
    margin: float,
) -> tuple[IntArray, IntArray]:
    """Per line, the samples ``s[q_lo:q_hi]`` whose points ``b·n + s·t`` may fall in ``[lo, hi)²``.

    The interval of ``s`` whose point lies in the square (widened by ``margin``); the caller
    tests the samples exactly.  ``q_hi < q_lo`` where there are none.
    """
    s_lo = np.full(b.shape[0], -np.inf)
    s_hi = np.full(b.shape[0], np.inf)
    for axis in (0, 1):
        base = b * n[:, axis]
        step = tdir[:, axis]
        moving = np.abs(step) > 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            a1 = (lo - margin - base) / step
            a2 = (hi + margin - base) / step
        s_lo = np.where(moving, np.maximum(s_lo, np.minimum(a1, a2)), s_lo)
        s_hi = np.where(moving, np.minimum(s_hi, np.maximum(a1, a2)), s_hi)
        outside = ~moving & ((base < lo - margin) | (base > hi + margin))
        s_hi = np.where(outside, -np.inf, s_hi)
    q_lo = np.searchsorted(s, s_lo - margin, side="left")
    q_hi = np.searchsorted(s, s_hi + margin, side="right")
    return q_lo, q_hi


def _samples_near_grid(
    b: FloatArray,
    n: FloatArray,
    tdir: FloatArray,
    s: FloatArray,
    lo: float,
    hi: float,
    margin: float,
) -> tuple[IntArray, IntArray]:
    """Indices ``(line, sample)`` of the points ``b·n + s·t`` that may fall in ``[lo, hi)²``.

    The samples of :func:`_sample_ranges`: rows in line order, samples ascending (the order of
    a full ``(P, S)`` grid).
    """
    q_lo, q_hi = _sample_ranges(b, n, tdir, s, lo, hi, margin)
    counts = np.maximum(q_hi - q_lo, 0)
    pp = np.repeat(np.arange(b.shape[0]), counts)
    start = np.cumsum(counts) - counts
    ss = q_lo[pp] + (np.arange(pp.shape[0]) - start[pp])
    return pp, ss


@njit(cache=True, nogil=True)
def _constraint_votes(
    line: IntArray,
    bn: FloatArray,
    tdir: FloatArray,
    weight: FloatArray,
    s: FloatArray,
    q_lo: IntArray,
    q_hi: IntArray,
    window: float,
    cell: float,
    nc: int,
) -> tuple[FloatArray, int]:  # pragma: no cover - compiled
    """The translation votes of the constraint lines (compiled; :func:`_translation_peaks`).

    Constraint ``p`` (of local line ``line[p]``, non-decreasing: the constraints come grouped by
    local line) is sampled at ``bn[p] + s[k]·tdir[p]`` for ``k`` in ``[q_lo[p], q_hi[p])``;
    a sample in the ``nc × nc`` grid of ``cell`` over ``[−window, −window + nc·cell)²`` votes
    for its cell.  Each local line gives each cell it reaches its largest weight there, and a
    cell's votes are summed over the local lines in ascending order from 0 (the order
    ``np.bincount`` over the sorted ``(line, cell)`` keys sums in).  Returns the votes
    (``nc²``, row ``x``, column ``y``) and how many samples fell in the grid.
    """
    n_cells = nc * nc
    votes = np.zeros(n_cells)
    best = np.zeros(n_cells)
    seen = np.zeros(n_cells, np.bool_)
    touched = np.empty(n_cells, np.int64)
    inside = 0
    P = line.shape[0]
    p = 0
    while p < P:
        current = line[p]
        n_touched = 0
        while p < P and line[p] == current:
            w = weight[p]
            for k in range(q_lo[p], q_hi[p]):
                px = bn[p, 0] + s[k] * tdir[p, 0]
                py = bn[p, 1] + s[k] * tdir[p, 1]
                cx = np.int64(np.floor((px + window) / cell))
                cy = np.int64(np.floor((py + window) / cell))
                if cx < 0 or cx >= nc or cy < 0 or cy >= nc:
                    continue
                inside += 1
                c = cx * nc + cy
                if not seen[c]:
                    seen[c] = True
                    best[c] = w
                    touched[n_touched] = c
                    n_touched += 1
                elif w > best[c]:
                    best[c] = w
            p += 1
        for i in range(n_touched):
            c = touched[i]
            votes[c] += best[c]
            seen[c] = False
    return votes, inside


@njit(cache=True, nogil=True)
def _smooth3(votes: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """Sum of each cell's 3×3 neighbourhood of the square grid ``votes`` (zero outside).

    Per cell, the neighbours are added in the order ``(dx, dy)`` = ``(−1, −1)``, then
    ``(−1, 0)``, ... ``(1, 1)`` (row by row), starting from the first: the order in which the
    shifted copies of a zero-padded grid would be summed.
    """
    nc = votes.shape[0]
    pad = np.zeros((nc + 2, nc + 2))
    pad[1 : nc + 1, 1 : nc + 1] = votes
    sm = np.empty((nc, nc))
    for x in range(nc):
        for y in range(nc):
            total = pad[x, y]
            total += pad[x, y + 1]
            total += pad[x, y + 2]
            total += pad[x + 1, y]
            total += pad[x + 1, y + 1]
            total += pad[x + 1, y + 2]
            total += pad[x + 2, y]
            total += pad[x + 2, y + 1]
            total += pad[x + 2, y + 2]
            sm[x, y] = total
    return sm


def _top_cells(values: FloatArray, k: int) -> IntArray:
    """Indices of the ``k`` largest positive ``values``, largest first, ties by index.

    (A full ``argsort`` costs ``O(n log n)`` and orders ties however the sort happens to;
    this is ``O(n)`` and the same on every machine.)
    """
    positive = np.flatnonzero(values > 0.0)
    if positive.size > k:
        cut = np.partition(values[positive], positive.size - k)[positive.size - k]
        positive = positive[values[positive] >= cut]  # the k largest and any ties with them
    order = np.lexsort((positive, -values[positive]))
    return positive[order][:k]


def _translation_peaks(
    local: LoopLines,
    old: LoopLines,
    center: FloatArray,
    dth: float,
    window_xy: float,
    config: LoopConfig,
    n_peaks: int,
) -> list[FloatArray]:
    rot = local.transformed(np.array([0.0, 0.0, dth]), center)
    da = np.abs(np.asarray(wrap_angle(old.alpha[None, :] - rot.alpha[:, None])))
    ii, jj = np.nonzero(da < config.angle_tolerance_rad)
    if ii.size == 0:
        return []
    n = np.stack([np.cos(old.alpha[jj]), np.sin(old.alpha[jj])], -1)
    tdir = np.stack([-n[:, 1], n[:, 0]], -1)
    b = old.r[jj] - rot.r[ii]
    keep = np.abs(b) <= window_xy * np.sqrt(2.0)
    ii, jj, n, tdir, b = ii[keep], jj[keep], n[keep], tdir[keep], b[keep]
    if ii.size == 0:
        return []
    cell = config.cell_m
    nc = int(np.ceil(2 * window_xy / cell))
    s = np.arange(-window_xy * np.sqrt(2.0), window_xy * np.sqrt(2.0) + cell, cell / 2.0)
    # each constraint line is sampled at b·n + s·t; only the samples near the grid are computed;
    # one vote per (local line, cell): the largest weight among its constraints there
    q_lo, q_hi = _sample_ranges(b, n, tdir, s, -window_xy, -window_xy + nc * cell, cell)
    bn = b[:, None] * n
    weight = np.minimum(rot.length[ii], old.length[jj])
    flat, inside = _constraint_votes(
        ii.astype(np.int64), bn, tdir, weight, s, q_lo, q_hi, window_xy, cell, nc
    )
    if inside == 0:
        return []
    sm = _smooth3(flat.reshape(nc, nc))  # a crossing may straddle cells
    peaks: list[FloatArray] = []
    min_sep = max(3, round(0.5 / cell))
    taken: list[tuple[int, int]] = []
    for f in _top_cells(sm.ravel(), 50 * n_peaks):
        x, y = divmod(int(f), nc)
        if sm[x, y] <= 0:
            break
        if any(abs(x - a) < min_sep and abs(y - c) < min_sep for a, c in taken):
            continue
        taken.append((x, y))
        peaks.append(np.array([(x + 0.5) * cell - window_xy, (y + 0.5) * cell - window_xy, dth]))
        if len(peaks) >= n_peaks:
            break
    return peaks


def search_loop_closure(
    local: LoopLines,
    old: LoopLines,
    center: FloatArray,
    window_xy: float,
    window_theta: float,
    config: LoopConfig,
    n_rotations: int = 3,
    n_peaks: int = 4,
    window_prior: bool = False,
    old_windows: tuple[FloatArray, FloatArray] | None = None,
) -> LoopSearch:
    """Search, verify and refine a correction of ``local`` onto ``old`` (module docstring).

    Parameters
    ----------
    local, old : LoopLines
    center : ndarray, shape (2,)
        Rotation centre (the robot's position).
    window_xy, window_theta : float
        Half-widths of the search window (m, rad).
    config : LoopClosureConfig
    n_rotations, n_peaks : int
        Rotation candidates, and translation peaks per rotation, that are verified.
    window_prior : bool
        Refine each hypothesis with the window as a weak prior on the correction
        (:func:`_refine`): parallel pairs then keep the position along them near the window
        instead of sliding out of it (the front end's relocalisation, whose window is centred
        on the odometry prediction).
    old_windows : (ndarray, ndarray), shape (M,) each, optional
        Each old line's own window half-widths (m, rad), from the path since it was seen (the
        search window is then the widest of them).  A hypothesis must lie within the window
        of the old lines it pairs (the median of theirs), not only within the window of the
        oldest line in reach: the drift since the walls it matches were seen bounds the
        correction.

    Returns
    -------
    LoopSearch
        Its ``closure`` is None when no hypothesis passes the verification or the best is
        ambiguous; ``reason`` says which.
    """
    if len(local) < 2 or len(old) < 2:
        return LoopSearch(None, "too few lines")
    c = np.asarray(center, dtype=float).reshape(2)
    hyps: list[_Hypothesis] = []
    for dth in _rotation_candidates(
        local, old, window_theta, config.angle_tolerance_rad, n_rotations
    ):
        for peak in _translation_peaks(local, old, c, dth, window_xy, config, n_peaks):
            corr, i, j, w = _refine(
                local, old, c, peak, config, (window_xy, window_theta) if window_prior else None
            )
            if np.hypot(corr[0], corr[1]) > window_xy * 1.5 or abs(corr[2]) > window_theta * 1.5:
                continue
            if (
                old_windows is not None
                and j.size
                and (
                    np.hypot(corr[0], corr[1]) > np.median(old_windows[0][j])
                    or abs(corr[2]) > np.median(old_windows[1][j])
                )
            ):
                continue
            hyps.append(_Hypothesis(corr, i, j, float(w.sum()), old.alpha[j], w, config))
    if not hyps:
        return LoopSearch(None, "no hypothesis")
    valid = [h for h in hyps if h.valid]
    if not valid:
        top = max(hyps, key=lambda h: h.score)
        return LoopSearch(
            None,
            f"none verified (best {top.score:.1f} m, {top.i.size} pairs, "
            f"{'one direction' if top.single else 'two directions'})",
        )
    best = max(valid, key=lambda h: h.score)
    runner = max((h.score for h in hyps if best.distinct(h, config)), default=0.0)
    if runner > config.max_ambiguity * best.score:
        return LoopSearch(None, f"ambiguous ({best.score:.1f} vs {runner:.1f})")
    pairs = [(int(a), int(b)) for a, b in zip(best.i, best.j, strict=True)]
    return LoopSearch(LoopClosure(best.corr, pairs, best.score, runner, best.single), "found")
