"""Hough accumulator and peaks, split-and-merge, breakpoints."""

from __future__ import annotations

import numpy as np
import pytest
from _synthetic import World, box, cast

from linefit.hough import hough_accumulator, hough_groups
from linefit.segments import breakpoint_mask
from linefit.split_merge import split_merge_groups


def square_scan(n: int = 360) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    world = World(box(0.3, -0.2, 6.0, 4.0, 0.25))
    bearings = -np.pi + np.arange(n) * 2 * np.pi / n
    ranges, hit = cast(world, np.zeros(3), bearings)
    return ranges * np.cos(bearings), ranges * np.sin(bearings), hit


def test_accumulator_counts_every_valid_point_once_per_angle():
    x, y, _ = square_scan()
    valid = np.ones(x.shape, dtype=bool)
    valid[::7] = False
    acc, cells, betas, r_max = hough_accumulator(x[None], y[None], valid[None], np.radians(2), 0.1)
    assert acc.sum() == valid.sum() * betas.shape[0]
    assert np.all((betas >= 0) & (betas < np.pi))
    # the cell of each vote holds the exact ℛ = x cos β + y sin β
    n_rho = acc.shape[1] // betas.shape[0]
    j, i = np.divmod(cells[0], n_rho)
    assert np.all(j == np.arange(betas.shape[0])[:, None])
    rho = x[None, :] * np.cos(betas)[:, None] + y[None, :] * np.sin(betas)[:, None]
    lo = i * 0.1 - r_max
    assert np.all((rho >= lo - 1e-5) & (rho < lo + 0.1 + 1e-5))


def test_hough_peaks_give_the_four_walls_with_disjoint_points():
    x, y, hit = square_scan()
    grouping, gscan = hough_groups(
        x[None],
        y[None],
        np.ones((1, x.shape[0]), dtype=bool),
        angle_step_rad=np.radians(2),
        range_step_m=0.1,
        min_votes=5,
        gather_m=0.05,
        max_peaks=20,
    )
    assert np.all(gscan == 0)
    assert np.unique(grouping.pidx).shape[0] == grouping.pidx.shape[0]  # points removed
    faces = {int(np.bincount(hit[grouping.pidx[grouping.gidx == g]]).argmax()) for g in range(4)}
    assert faces == {0, 1, 2, 3}
    # the four largest groups are the walls, each almost all of its wall's points
    sizes = np.bincount(grouping.gidx)
    assert np.sort(sizes)[-4:].sum() >= 0.97 * x.shape[0]
    normals = np.sort(np.mod(grouping.alpha0[np.argsort(sizes)[-4:]], np.pi / 2))
    np.testing.assert_allclose(normals, 0.25, atol=np.radians(0.5))


def test_split_merge_splits_at_corners_and_gives_each_corner_to_one_face():
    x, y, hit = square_scan()
    n = x.shape[0]
    grouping = split_merge_groups(
        x,
        y,
        np.arange(n),
        np.full(n, 0.005),
        split_threshold_m=0.03,
        split_threshold_sigma=4.0,
        max_missing_beams=2,
        lambda_rad=np.radians(10),
        sigma_factor=3.0,
        min_points=3,
    )
    assert np.unique(grouping.pidx).shape[0] == grouping.pidx.shape[0]
    seen = set()
    for g in range(grouping.n_groups):
        faces = hit[grouping.pidx[grouping.gidx == g]]
        assert np.all(faces == faces[0]), "a piece spans two faces"
        seen.add(int(faces[0]))
    assert seen == {0, 1, 2, 3}
    # few pieces: the wall crossing ±π is cut at the scan's ends, and near a corner the part
    # seen at more than 80° incidence is cut off by the breakpoint rule
    assert grouping.n_groups <= 6


def test_breakpoints():
    phi = np.radians(np.arange(0.0, 10.0))
    d = np.full(10, 3.0)
    d[5:] = 3.5  # range jump between beams 4 and 5
    x, y = d * np.cos(phi), d * np.sin(phi)
    beam = np.arange(10)
    beam[8:] += 3  # three missing beams between beams 7 and 8
    brk = breakpoint_mask(
        x,
        y,
        beam,
        np.full(10, 0.005),
        max_missing_beams=2,
        lambda_rad=np.radians(10),
        sigma_factor=3.0,
    )
    assert np.flatnonzero(brk).tolist() == [4, 7]


@pytest.mark.parametrize(("incidence_deg", "broken"), [(75.0, False), (84.0, True)])
def test_breakpoint_lambda_limits_grazing_walls(incidence_deg, broken):
    # consecutive beams 1° apart on a wall seen at the given incidence
    th = np.radians(incidence_deg + np.array([0.0, 1.0]))
    r = 2.0
    d = r / np.cos(th)
    x, y = d * np.cos(th), d * np.sin(th)
    brk = breakpoint_mask(
        x,
        y,
        np.arange(2),
        np.zeros(2),
        max_missing_beams=2,
        lambda_rad=np.radians(10),
        sigma_factor=0.0,
    )
    assert bool(brk[0]) is broken
