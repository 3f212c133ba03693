"""Loop-closure search: known corrections on constructed rooms, grid sampling."""

from __future__ import annotations

import numpy as np
import pytest

from slam.frontend.config import LoopClosureConfig, RelocalisationConfig
from slam.frontend.loop_closure import (
    LoopLines,
    _constraint_votes,
    _refine,
    _sample_ranges,
    _samples_near_grid,
    _top_cells,
    correction_chi2,
    correction_covariance,
    search_loop_closure,
)


def room_lines(corners: list[tuple[float, float]]) -> LoopLines:
    """The walls of a closed polygon, seen from inside (normals point outwards)."""
    pts = np.asarray(corners, dtype=float)
    ends = np.stack([pts, np.roll(pts, -1, axis=0)], axis=1)  # (K, 2, 2)
    centre = pts.mean(axis=0)
    d = ends[:, 1] - ends[:, 0]
    n = np.stack([d[:, 1], -d[:, 0]], -1) / np.linalg.norm(d, axis=1)[:, None]
    r = np.einsum("kd,kd->k", n, ends[:, 0])
    # orient each normal from the room's inside towards the wall
    flip = (n @ centre) > r
    n[flip] *= -1.0
    r[flip] *= -1.0
    return LoopLines(np.arctan2(n[:, 1], n[:, 0]), r, ends)


ROOM = [(0.0, 0.0), (6.0, 0.0), (6.0, 2.0), (8.0, 2.0), (8.0, 5.0), (3.0, 5.0), (3.0, 4.0),
        (0.0, 4.0)]  # fmt: skip


@pytest.mark.parametrize("correction", [(0.8, -0.5, 0.06), (-2.0, 1.2, -0.15), (0.0, 0.0, 0.0)])
def test_search_recovers_a_known_correction(correction):
    """Old walls and the same walls seen after drift: the correction that undoes the drift."""
    old = room_lines(ROOM)
    center = np.array([4.0, 2.5])
    corr = np.asarray(correction)
    # the drifted local lines are the old ones moved by the inverse correction
    tx, ty, dth = corr
    c, s = np.cos(-dth), np.sin(-dth)
    Rinv = np.array([[c, -s], [s, c]])
    shift = -Rinv @ np.array([tx, ty])
    local = old.transformed(np.array([shift[0], shift[1], -dth]), center)
    found = search_loop_closure(local, old, center, 3.0, 0.3, LoopClosureConfig()).closure
    assert found is not None
    np.testing.assert_allclose(found.correction, corr, atol=0.02)
    assert sorted(found.pairs) == [(k, k) for k in range(len(old))]
    # and the corrected local walls lie on the old ones
    back = local.transformed(found.correction, center)
    np.testing.assert_allclose(back.ends, old.ends, atol=0.05)


def test_search_rejects_a_repeating_corridor_of_identical_rooms():
    """Two identical rooms side by side, the local view fits both: ambiguous, no closure."""
    old, na = two_identical_rooms()
    a = LoopLines(old.alpha[:na], old.r[:na], old.ends[:na])
    local = a.transformed(np.array([2.5, 0.0, 0.0]), np.zeros(2))  # halfway between the rooms
    search = search_loop_closure(local, old, np.array([4.5, 1.5]), 4.0, 0.2, LoopClosureConfig())
    assert search.closure is None
    assert search.reason.startswith("ambiguous")  # both rooms verified, not a failed search


@pytest.mark.parametrize(("room_window_m", "found"), [(1.0, False), (8.0, True)])
def test_a_correction_must_lie_within_the_window_of_the_walls_it_matches(room_window_m, found):
    """The local view matches a room 5 m away.  The search window is that of the oldest wall
    in reach (8 m); the room's walls were seen recently (window 1 m: drift since then cannot
    be 5 m), so the 5 m match is not a closure, however well it fits.  Seen long ago (8 m),
    it is one."""
    room, _ = two_identical_rooms()
    a = LoopLines(room.alpha[:4], room.r[:4], room.ends[:4])
    far = LoopLines(np.array([0.0]), np.array([30.0]), np.array([[[30.0, 0.0], [30.0, 4.0]]]))
    old = LoopLines(
        np.r_[a.alpha, far.alpha], np.r_[a.r, far.r], np.concatenate([a.ends, far.ends])
    )
    local = a.transformed(np.array([5.0, 0.0, 0.0]), np.zeros(2))
    windows = (np.r_[np.full(4, room_window_m), 8.0], np.r_[np.full(4, 0.1), 0.4])
    centre, cfg = np.array([7.0, 1.5]), LoopClosureConfig()
    search = search_loop_closure(local, old, centre, 8.0, 0.4, cfg, old_windows=windows)
    assert (search.closure is not None) == found
    plain = search_loop_closure(local, old, centre, 8.0, 0.4, cfg).closure
    assert plain is not None
    np.testing.assert_allclose(plain.correction, [-5.0, 0.0, 0.0], atol=0.02)


def test_refine_keeps_an_unconstrained_direction_inside_the_window():
    """Two parallel walls (a corridor) fix the offset and rotation but not the position along
    them; with slightly inconsistent fitted angles the plain least squares moved metres along
    the corridor (out of the window: the hypothesis was dropped, fr079 relocalisation "no
    hypothesis"); the window as a weak prior keeps that component small."""
    old = LoopLines(
        np.array([-np.pi / 2, np.pi / 2]),
        np.array([0.0, 2.0]),
        np.array([[[-4.0, 0.0], [4.0, 0.0]], [[-4.0, 2.0], [4.0, 2.0]]]),
    )
    local = LoopLines(
        np.array([-np.pi / 2 + 0.02, np.pi / 2 + 0.01]),
        np.array([0.03, 2.0]),
        np.array([[[1.0, 0.0], [3.0, 0.04]], [[1.0, 2.0], [3.0, 2.02]]]),
    )
    centre, cfg = np.array([0.0, 1.0]), RelocalisationConfig()
    free, _, _, _ = _refine(local, old, centre, np.zeros(3), cfg)
    assert abs(free[0]) > 1.0  # the near-singular system (the behaviour this guards against)
    corr, i, j, _ = _refine(local, old, centre, np.zeros(3), cfg, (0.5, 0.4))
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 0), (1, 1)]
    assert abs(corr[0]) < 0.1  # along the corridor: stays near the start
    assert corr[1] == pytest.approx(0.015, abs=0.01)  # across: the mean offset
    assert corr[2] == pytest.approx(-0.015, abs=0.01)  # rotation: the mean angle error


def two_identical_rooms() -> tuple[LoopLines, int]:
    """Rooms ``a`` (rows ``0..3``) and ``b`` (rows ``4..7``), 5 m apart along x."""
    a = room_lines([(0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (0.0, 3.0)])
    b = room_lines([(5.0, 0.0), (9.0, 0.0), (9.0, 3.0), (5.0, 3.0)])
    old = LoopLines(
        np.concatenate([a.alpha, b.alpha]),
        np.concatenate([a.r, b.r]),
        np.concatenate([a.ends, b.ends]),
    )
    return old, len(a)


def test_grid_samples_cover_every_sample_inside_the_square():
    """The per-line sample interval never drops a sample that falls in the grid."""
    rng = np.random.default_rng(5)
    P = 400
    ang = rng.uniform(-np.pi, np.pi, P)
    ang[:20] = np.round(ang[:20] / (np.pi / 2)) * (np.pi / 2)  # axis-parallel lines too
    n = np.stack([np.cos(ang), np.sin(ang)], -1)
    tdir = np.stack([-n[:, 1], n[:, 0]], -1)
    b = rng.uniform(-5.0, 5.0, P)
    w, cell = 3.0, 0.1
    s = np.arange(-w * np.sqrt(2.0), w * np.sqrt(2.0) + cell, cell / 2.0)
    nc = int(np.ceil(2 * w / cell))
    pts = b[:, None, None] * n[:, None, :] + s[None, :, None] * tdir[:, None, :]
    c = np.floor((pts + w) / cell)
    inside = np.all((c >= 0) & (c < nc), axis=-1)
    pp, ss = _samples_near_grid(b, n, tdir, s, -w, -w + nc * cell, cell)
    got = np.zeros_like(inside)
    got[pp, ss] = True
    assert np.all(got[inside])  # nothing inside is missed
    assert got.sum() < 1.5 * inside.sum()  # and few outside are computed
    # in the order of the full grid: line by line, samples ascending
    order = pp * s.shape[0] + ss
    assert np.all(np.diff(order) > 0)


def test_top_cells_are_the_largest_in_order_with_ties_by_index():
    rng = np.random.default_rng(2)
    values = np.round(rng.uniform(-1.0, 3.0, 5000), 1)  # many ties
    got = _top_cells(values, 40)
    ref = sorted(np.flatnonzero(values > 0), key=lambda i: (-values[i], i))[:40]
    assert got.tolist() == ref
    assert _top_cells(np.array([0.0, -1.0]), 5).size == 0
    assert _top_cells(np.array([0.5, 2.0, 0.5]), 5).tolist() == [1, 0, 2]


@pytest.mark.parametrize(
    "kwargs",
    [
        {"large_correction_m": -0.1},
        {"large_correction_rad": float("nan")},
        {"local_keyframes": 0},
        {"judge_max_pair_chi2": 0.0},
        {"judge_max_pair_chi2": float("nan")},
        {"consistency_probability": 1.0},
        {"consistency_probability": float("nan")},
        {"confirmations": -1},
        {"judge_max_f": 0.0},
        {"window_sigmas": -1.0},
        {"min_cross_length_m": -0.5},
    ],
)
def test_invalid_loop_closure_settings_are_rejected(kwargs):
    from linefit import ConfigError

    with pytest.raises(ConfigError, match=next(iter(kwargs))):
        LoopClosureConfig(**kwargs)


def _exp(xi: np.ndarray) -> np.ndarray:
    """SE(2) exponential ``(vx, vy, ω) → (x, y, θ)``."""
    vx, vy, w = xi
    if abs(w) < 1e-12:
        return np.array([vx, vy, w])
    s, c = np.sin(w), np.cos(w)
    return np.array([(s * vx - (1 - c) * vy) / w, ((1 - c) * vx + s * vy) / w, w])


def test_correction_chi2_is_chi2_distributed_monte_carlo():
    """Perturb two poses by right perturbations drawn from their joint covariance (correlated);
    the correction that moves the newer pose to the perturbed relative pose (about its own
    position, the old pose held) has the χ²(3) distribution under ``correction_chi2``."""
    from slam.geometry import pose_between, pose_compose

    rng = np.random.default_rng(5)
    x_old = np.array([2.0, -1.0, 0.7])
    x_now = np.array([14.0, 6.0, -2.3])
    L = rng.normal(size=(6, 6)) * np.array([0.02, 0.02, 0.004, 0.05, 0.05, 0.01])[:, None]
    P = L @ L.T + np.diag([1e-4, 1e-4, 1e-6, 4e-4, 4e-4, 1e-5])
    C = np.linalg.cholesky(P)
    n = 4000
    d2 = np.empty(n)
    for k in range(n):
        xi = C @ rng.normal(size=6)
        r = pose_between(pose_compose(x_old, _exp(xi[:3])), pose_compose(x_now, _exp(xi[3:])))
        x_corr = pose_compose(x_old, r)  # where the perturbed relative pose puts the new pose
        t = np.r_[x_corr[:2] - x_now[:2], x_corr[2] - x_now[2]]
        d2[k] = correction_chi2(x_old, x_now, P, t)
    # mean of n χ²(3) draws: 3 ± 3·√(6/n)
    assert abs(d2.mean() - 3.0) < 3.0 * np.sqrt(6.0 / n)
    assert abs(np.mean(d2 > 7.815) - 0.05) < 3.0 * np.sqrt(0.05 * 0.95 / n)  # 95 % quantile


def test_correction_chi2_known_answers():
    """The old pose exact: the correction, in the new pose's frame, against its covariance."""
    Q = np.diag([0.04, 0.01, 0.0025])
    P = np.zeros((6, 6))
    P[3:, 3:] = Q
    x_now = np.array([1.0, 2.0, np.pi / 2])
    # 0.2 m along world x is 0.2 m to the robot's right (its −y): (0.2/0.1)² = 4
    assert correction_chi2(np.zeros(3), x_now, P, np.array([0.2, 0.0, 0.0])) == pytest.approx(4.0)
    assert correction_chi2(np.zeros(3), x_now, P, np.array([0.0, 0.0, 0.1])) == pytest.approx(4.0)
    # a singular covariance: no correction is possible, none needed is
    assert correction_chi2(np.zeros(3), x_now, np.zeros((6, 6)), np.array([0.1, 0, 0])) == np.inf
    assert correction_chi2(np.zeros(3), x_now, np.zeros((6, 6)), np.zeros(3)) == 0.0


@pytest.mark.parametrize(("cross_m", "verified"), [(0.3, False), (2.0, True)])
def test_two_direction_closure_needs_metres_of_wall_across_the_corridor(cross_m, verified):
    """A corridor's two long walls and one short cross wall: the position along the corridor
    rests on the cross wall alone, so a hypothesis counts in two directions only if that wall
    matches at least ``min_cross_length_m`` (metres of wall, not a number of lines)."""
    walls = [
        ((0.0, 0.0), (3.0, 0.0)),
        ((0.0, 2.0), (3.0, 2.0)),
        ((3.0, 1.0 - cross_m / 2), (3.0, 1.0 + cross_m / 2)),
    ]
    ends = np.array(walls)
    inside = np.array([1.5, 1.0])
    d = ends[:, 1] - ends[:, 0]
    n = np.stack([d[:, 1], -d[:, 0]], -1) / np.linalg.norm(d, axis=1)[:, None]
    r = np.einsum("kd,kd->k", n, ends[:, 0])
    flip = (n @ inside) > r
    n[flip] *= -1.0
    r[flip] *= -1.0
    old = LoopLines(np.arctan2(n[:, 1], n[:, 0]), r, ends)
    local = old.transformed(np.array([0.3, 0.0, 0.0]), inside)
    config = LoopClosureConfig(
        corridor_closures=False, min_cross_length_m=1.0, min_matched_length_m=4.0
    )
    found = search_loop_closure(local, old, inside, 1.0, 0.1, config).closure
    assert (found is not None) == verified
    if verified:
        assert found is not None and len(found.pairs) == 3
        np.testing.assert_allclose(found.correction, [-0.3, 0.0, 0.0], atol=0.02)


def test_compiled_votes_equal_the_sorted_count():
    """The compiled vote count equals counting the sorted ``(local line, cell)`` keys with
    ``np.bincount``, bit for bit (per cell the largest weight of each local line, summed over
    the lines in order), with ties of weights and constraints that leave the grid."""
    rng = np.random.default_rng(7)
    P = 300
    line = np.sort(rng.integers(0, 25, P)).astype(np.int64)
    ang = rng.uniform(-np.pi, np.pi, P)
    n = np.stack([np.cos(ang), np.sin(ang)], -1)
    tdir = np.stack([-n[:, 1], n[:, 0]], -1)
    b = rng.uniform(-4.0, 4.0, P)
    weight = np.round(rng.uniform(0.1, 3.0, P), 1)  # ties
    w, cell = 3.0, 0.05
    nc = int(np.ceil(2 * w / cell))
    s = np.arange(-w * np.sqrt(2.0), w * np.sqrt(2.0) + cell, cell / 2.0)
    q_lo, q_hi = _sample_ranges(b, n, tdir, s, -w, -w + nc * cell, cell)
    votes, inside = _constraint_votes(
        line, b[:, None] * n, tdir, weight, s, q_lo, q_hi, w, cell, nc
    )
    # the reference: every sample, then one vote per (line, cell) with its largest weight
    pp, ss = _samples_near_grid(b, n, tdir, s, -w, -w + nc * cell, cell)
    px = b[pp] * n[pp, 0] + s[ss] * tdir[pp, 0]
    py = b[pp] * n[pp, 1] + s[ss] * tdir[pp, 1]
    cx = np.floor((px + w) / cell).astype(np.int64)
    cy = np.floor((py + w) / cell).astype(np.int64)
    ok = (cx >= 0) & (cx < nc) & (cy >= 0) & (cy < nc)
    key = line[pp[ok]] * (nc * nc) + (cx * nc + cy)[ok]
    wt = weight[pp[ok]]
    order = np.lexsort((-wt, key))
    key_s = key[order]
    first = np.r_[True, key_s[1:] != key_s[:-1]]
    ref = np.bincount(key_s[first] % (nc * nc), weights=wt[order][first], minlength=nc * nc)
    assert inside == np.count_nonzero(ok) > 0
    np.testing.assert_array_equal(votes, ref)


def test_correction_covariance_known_answers():
    """Each pair is one offset and one angle measurement with a third of the search's
    tolerances as standard deviations, the window the prior: two walls across x, two across y
    (through the centre, so the rotation does not move the offsets) give ``σ_r²/2`` on each
    translation and ``σ_a²/4`` on the rotation (with the window's prior); three parallel walls
    (a corridor) leave the position along them at the window's variance."""
    cfg = LoopClosureConfig()
    s_r, s_a = cfg.offset_tolerance_m / 3.0, cfg.angle_tolerance_rad / 3.0
    W, T = 0.8, 0.1
    box = LoopLines(
        np.array([0.0, np.pi, np.pi / 2, -np.pi / 2]),
        np.array([2.0, 2.0, 1.0, 1.0]),
        np.array([[[2, -1], [2, 1]], [[-2, -1], [-2, 1]], [[-2, 1], [2, 1]], [[-2, -1], [2, -1]]]),
    )
    pairs = [(k, k) for k in range(4)]
    got = correction_covariance(box, box, pairs, np.zeros(2), np.zeros(3), cfg, (W, T))
    want = np.diag(1.0 / np.array([2 / s_r**2 + W**-2, 2 / s_r**2 + W**-2, 4 / s_a**2 + T**-2]))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-18)
    corridor = LoopLines(
        np.full(3, np.pi / 2),
        np.array([1.0, 1.3, 1.6]),
        np.array([[[-3.0, y], [3.0, y]] for y in (1.0, 1.3, 1.6)]),
    )
    pairs = [(k, k) for k in range(3)]
    got = correction_covariance(corridor, corridor, pairs, np.zeros(2), np.zeros(3), cfg, (W, T))
    assert got[0, 0] == pytest.approx(W**2, rel=1e-12)  # along the walls: the window's
    assert got[1, 1] == pytest.approx(1.0 / (3 / s_r**2 + W**-2), rel=1e-12)
    assert got[2, 2] == pytest.approx(1.0 / (3 / s_a**2 + T**-2), rel=1e-12)
