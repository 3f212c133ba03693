"""Exact ray casting: known distances, grazing rays, corners, misses, ids."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import InputError
from slam.sim import World, WorldBuilder, cast_rays, cast_scan


def _world(*segments: tuple[tuple[float, float], tuple[float, float]], ids=None) -> World:
    seg = np.array(segments, dtype=float)
    ids = np.arange(len(segments)) if ids is None else np.asarray(ids)
    return World(seg, ids, ("wall",) * len(segments))


def test_perpendicular_wall_exact_distance_at_many_angles():
    world = _world(((3.0, -10.0), (3.0, 10.0)), ids=[7])
    angles = np.deg2rad(np.linspace(-70.0, 70.0, 141))
    ranges, ids = cast_rays((0.0, 0.0), angles, world)
    np.testing.assert_allclose(ranges, 3.0 / np.cos(angles), rtol=1e-14, atol=0)
    assert (ids == 7).all()
    assert ranges[70] == 3.0  # straight ahead: exactly the wall distance


def test_oblique_walls_match_the_normal_form_distance(rng):
    # Random infinite-looking walls {p : p·n = c} and rays that hit them: t = (c − o·n)/(d·n).
    for _ in range(20):
        alpha = rng.uniform(-np.pi, np.pi)
        n = np.array([np.cos(alpha), np.sin(alpha)])
        tangent = np.array([-n[1], n[0]])
        c = rng.uniform(0.5, 20.0)
        foot = c * n
        world = _world((tuple(foot - 500 * tangent), tuple(foot + 500 * tangent)))
        origin = rng.uniform(-0.3, 0.3, 2)
        angles = alpha + rng.uniform(-1.2, 1.2, 50)
        d = np.column_stack([np.cos(angles), np.sin(angles)])
        expected = (c - origin @ n) / (d @ n)
        ranges, ids = cast_rays(origin, angles, world)
        np.testing.assert_allclose(ranges, expected, rtol=1e-12)
        assert (ids == 0).all()


def test_grazing_ray_along_a_long_wall():
    # The wall y = 1 seen at 1e-3 rad: t = 1 / sin(1e-3) ≈ 1000 m.
    world = _world(((0.0, 1.0), (2000.0, 1.0)))
    for eps in (1e-3, 1e-2, 0.1):
        ranges, ids = cast_rays((0.0, 0.0), [eps], world, max_range_m=5000.0)
        assert ranges[0] == pytest.approx(1.0 / np.sin(eps), rel=1e-12)
        assert ids[0] == 0


def test_ray_exactly_along_a_wall_hits_what_stands_at_its_end():
    # Wall B runs along y = 3 and ends in the corner (3, 3) on wall A (x = 3).
    world = _world(((3.0, -2.0), (3.0, 3.0)), ((3.0, 3.0), (-2.0, 3.0)), ids=[10, 11])
    ranges, ids = cast_rays((-5.0, 3.0), [0.0], world)
    assert ranges[0] == 8.0 and ids[0] == 10


def test_ray_through_a_corner_never_slips_between_the_walls():
    world = _world(((3.0, -2.0), (3.0, 3.0)), ((3.0, 3.0), (-2.0, 3.0)), ids=[10, 11])
    angles = np.pi / 4 + np.array([-1e-15, -1e-16, 0.0, 1e-16, 1e-15])
    ranges, ids = cast_rays((0.0, 0.0), angles, world)
    np.testing.assert_allclose(ranges, 3.0 * np.sqrt(2.0), rtol=1e-14)
    assert set(ids.tolist()) <= {10, 11}
    # A dense fan through the corner: every ray hits one of the two walls at the right range.
    fan = np.pi / 4 + np.linspace(-1e-6, 1e-6, 2001)
    ranges, ids = cast_rays((0.0, 0.0), fan, world)
    expected = np.where(ids == 10, 3.0 / np.cos(fan), 3.0 / np.sin(fan))
    assert (ids >= 0).all()
    np.testing.assert_allclose(ranges, expected, rtol=1e-13)


def test_miss_and_beyond_max_range_read_max_range_with_id_minus_one():
    world = _world(((3.0, -1.0), (3.0, 1.0)), ((-50.0, -5.0), (50.0, -5.0)), ids=[4, 5])
    ranges, ids = cast_rays((0.0, 0.0), [np.pi / 2, 0.0, -np.pi / 2, np.pi], world, 4.0)
    np.testing.assert_array_equal(ranges, [4.0, 3.0, 4.0, 4.0])
    np.testing.assert_array_equal(ids, [-1, 4, -1, -1])  # the wall at 5 m is beyond 4 m


def test_nearest_wall_wins_and_walls_behind_are_not_hit():
    world = _world(
        ((2.0, -1.0), (2.0, 1.0)), ((5.0, -1.0), (5.0, 1.0)), ((-1.0, -1.0), (-1.0, 1.0))
    )
    ranges, ids = cast_rays((0.0, 0.0), [0.0, np.pi], world)
    np.testing.assert_array_equal(ranges, [2.0, 1.0])
    np.testing.assert_array_equal(ids, [0, 2])
    # From between the two front walls, looking forward, the far one.
    ranges, ids = cast_rays((3.0, 0.0), [0.0], world)
    assert ranges[0] == 2.0 and ids[0] == 1


def test_cast_scan_matches_rays_in_the_world_frame_and_chunks_agree(rng):
    b = WorldBuilder()
    b.box(-4.0, -3.0, 8.0, 6.0, label="wall")
    b.polygon(1.0, 0.5, 0.4, 8, label="pillar")
    world = b.build("room")
    pose = np.array([-1.0, -0.5, 0.3])
    bearings = np.deg2rad(np.arange(-90.0, 90.0, 0.25))
    r1, i1 = cast_scan(pose, bearings, world)
    r2, i2 = cast_rays(pose[:2], pose[2] + bearings, world)
    np.testing.assert_array_equal(r1, r2)
    np.testing.assert_array_equal(i1, i2)
    # End points lie on the segment they report.
    pts = pose[:2] + r1[:, None] * np.column_stack(
        [np.cos(pose[2] + bearings), np.sin(pose[2] + bearings)]
    )
    seg = world.segments[i1]
    e = seg[:, 1] - seg[:, 0]
    cross = e[:, 0] * (pts[:, 1] - seg[:, 0, 1]) - e[:, 1] * (pts[:, 0] - seg[:, 0, 0])
    np.testing.assert_allclose(cross / np.linalg.norm(e, axis=1), 0.0, atol=1e-12)
    # Many rays (several chunks) give the same answers as one at a time.
    origins = rng.uniform(-3.0, 3.0, (3000, 2))
    origins = origins[np.linalg.norm(origins - [1.0, 0.5], axis=1) > 0.5]
    angles = rng.uniform(-np.pi, np.pi, origins.shape[0])
    import slam.sim.raycast as rc

    big_r, big_i = cast_rays(origins, angles, world)
    old = rc._CHUNK_PAIRS
    try:
        rc._CHUNK_PAIRS = 7 * len(world)
        small_r, small_i = cast_rays(origins, angles, world)
    finally:
        rc._CHUNK_PAIRS = old
    np.testing.assert_array_equal(big_r, small_r)
    np.testing.assert_array_equal(big_i, small_i)
    assert (big_i >= 0).all()  # inside a closed room every ray hits something


def test_bad_rays_are_rejected():
    world = _world(((3.0, -1.0), (3.0, 1.0)))
    with pytest.raises(InputError):
        cast_rays((0.0, 0.0), [np.nan], world)
    with pytest.raises(InputError):
        cast_rays((0.0, np.inf), [0.0], world)
    with pytest.raises(InputError):
        cast_rays((0.0, 0.0), [0.0], world, max_range_m=0.0)
    with pytest.raises(InputError):
        cast_scan((0.0, 0.0), [0.0], world)
