"""The laser odometry's local map: key scans merged into the newest one's frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linefit.config import SensorNoiseConfig
from slam.errors import ConfigError
from slam.frontend.local_map import LocalMap, transform_points
from slam.frontend.scan_match import (
    ScanMatchConfig,
    ScanPoints,
    scan_points,
    scan_view,
    visible_points,
)
from slam.geometry import pose_between, pose_compose


def _wall_scan(seed: int = 0, n: int = 181) -> ScanPoints:
    """Points of a scan of two walls meeting in a corner, with Eq. 8 noise."""
    rng = np.random.default_rng(seed)
    bearings = np.linspace(-math.pi / 2, math.pi / 2, n)
    # a wall at x = 4 and one at y = 3 (a corner ahead and to the left)
    with np.errstate(divide="ignore"):
        to_front = np.where(np.cos(bearings) > 1e-9, 4.0 / np.cos(bearings), np.inf)
        to_left = np.where(np.sin(bearings) > 1e-9, 3.0 / np.sin(bearings), np.inf)
    ranges = np.minimum(to_front, to_left) + rng.normal(0.0, 0.005, n)
    return scan_points(ranges, bearings, 30.0, SensorNoiseConfig(), ScanMatchConfig())


def test_points_moved_and_moved_back_are_the_same():
    points = _wall_scan()
    pose = np.array([0.7, -1.2, 2.1])
    back = transform_points(transform_points(points, pose), pose_between(pose, np.zeros(3)))
    np.testing.assert_allclose(back.xy, points.xy, atol=1e-12)
    np.testing.assert_allclose(back.normals, points.normals, atol=1e-12)
    for name in ("q11", "q12", "q22"):
        np.testing.assert_allclose(getattr(back, name), getattr(points, name), atol=1e-18)
    np.testing.assert_array_equal(back.segment, points.segment)


def test_covariances_turn_with_the_points():
    """A quarter turn swaps the variances and flips the sign of the covariance."""
    points = _wall_scan()
    turned = transform_points(points, np.array([1.0, 2.0, math.pi / 2]))
    np.testing.assert_allclose(turned.q11, points.q22, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(turned.q22, points.q11, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(turned.q12, -points.q12, rtol=1e-9, atol=1e-18)
    # each point's turned covariance is R Q Rᵀ, also for a general angle
    theta = 0.4
    moved = transform_points(points, np.array([0.0, 0.0, theta]))
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    i = 37
    Q = np.array([[points.q11[i], points.q12[i]], [points.q12[i], points.q22[i]]])
    np.testing.assert_allclose(
        R @ Q @ R.T,
        [[moved.q11[i], moved.q12[i]], [moved.q12[i], moved.q22[i]]],
        rtol=1e-9,
        atol=1e-18,
    )


def test_the_map_keeps_the_key_scans_within_its_travel_and_turning():
    points = _wall_scan()
    local = LocalMap(path_m=1.0, turn_rad=0.5)
    pose = np.zeros(3)
    for _ in range(8):  # steps of 0.3 m: the newest and the three before it are within 1 m
        local.add(pose, points)
        pose = pose_compose(pose, np.array([0.3, 0.0, 0.0]))
    assert len(local) == 4
    for _ in range(5):  # turning on the spot by 0.2 rad: three key scans within 0.5 rad
        local.add(pose, points)
        pose = pose_compose(pose, np.array([0.0, 0.0, 0.2]))
    assert len(local) == 3
    local.reset()
    assert len(local) == 0
    with pytest.raises(ConfigError, match="path_m"):
        LocalMap(path_m=-1.0, turn_rad=0.5)


def test_the_merged_points_lie_where_each_scan_saw_them_and_see_what_the_newest_sees():
    """Two scans of the same walls from two poses merge onto the same walls."""
    first = _wall_scan(seed=1)
    # the same corner seen 0.5 m further on and turned by 0.1 rad: made from the first's walls
    pose_second = np.array([0.5, 0.2, 0.1])
    second = transform_points(first, pose_between(pose_second, np.zeros(3)))
    second = ScanPoints(
        second.xy, second.q11, second.q12, second.q22, second.normals, second.has_normal,
        second.segment,
    )  # fmt: skip
    local = LocalMap(path_m=2.0, turn_rad=1.0)
    local.add(np.zeros(3), first)
    local.add(pose_second, second)
    merged = local.points
    assert len(merged) == 2 * len(first)
    # in the newest scan's frame, the first scan's points coincide with the second's
    n = len(first)
    np.testing.assert_allclose(merged.xy[n:], merged.xy[:n], atol=1e-12)
    # segments of the two scans are distinct
    assert set(merged.segment[:n][merged.segment[:n] >= 0]).isdisjoint(
        merged.segment[n:][merged.segment[n:] >= 0]
    )
    # what the map could see is the newest scan's view
    assert merged.view == pytest.approx(scan_view(second))
    assert visible_points(merged, second, np.zeros(3)) == visible_points(
        second, second, np.zeros(3)
    )
