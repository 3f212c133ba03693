"""Rules both estimators share: keyframe threshold, line support, well-posed lines, model error."""

from __future__ import annotations

import numpy as np

from linefit import LineFitConfig, extract_lines
from slam.lines.lineset import LineSet, supported_lines
from slam.models import model_error_covariance, moved_enough


def test_moved_enough_by_distance_or_by_angle():
    assert not moved_enough(np.array([0.1, 0.1, 0.05]), 0.2, 0.1)  # 0.141 m, 0.05 rad
    assert moved_enough(np.array([0.0, -0.2, 0.0]), 0.2, 0.1)  # exactly 0.2 m
    assert moved_enough(np.array([0.0, 0.0, -0.1]), 0.2, 0.1)  # turning either way
    assert not moved_enough(np.array([0.0, 0.0, 0.0999]), 0.2, 0.1)


def _scan_lines() -> list:
    bearings = np.radians(np.arange(-90.0, 90.0, 1.0))
    # a wall 2 m ahead seen over ±60°
    ranges = 2.0 / np.maximum(np.cos(bearings), 1e-3)
    ranges = np.where(np.abs(bearings) < np.radians(60.0), ranges, np.inf)
    return list(extract_lines(ranges, bearings, LineFitConfig()))


def test_supported_lines_needs_both_enough_points_and_length():
    lines = _scan_lines()
    assert len(lines) >= 1
    n_points = np.array([ln.n_points for ln in lines])
    length = np.array([ln.length for ln in lines])
    np.testing.assert_array_equal(supported_lines(lines, 1, 0.0), np.ones(len(lines), bool))
    mask = supported_lines(lines, int(n_points.max()), 0.0)
    np.testing.assert_array_equal(mask, n_points >= n_points.max())
    assert not supported_lines(lines, 1, float(length.max()) + 0.01).any()
    assert supported_lines([], 5, 0.3).shape == (0,)


def test_well_posed_rejects_non_finite_and_singular_lines():
    good = np.diag([1e-4, 1e-5])
    cov = np.array(
        [
            good,
            np.zeros((2, 2)),  # singular
            np.diag([1e-4, -1e-5]),  # negative variance
            [[1e-4, 1e-3], [1e-3, 1e-5]],  # indefinite
            np.full((2, 2), np.nan),
            good,
            good,
        ]
    )
    r_alpha = np.array([[1.0, 0.0]] * 7)
    r_alpha[5, 1] = np.inf
    ends = np.zeros((7, 2, 2))
    ends[6, 0, 0] = np.nan
    lines = LineSet(r_alpha, cov, ends, np.arange(7))
    np.testing.assert_array_equal(lines.well_posed(), [True] + [False] * 6)
    assert LineSet.empty().well_posed().shape == (0,)


def test_model_error_is_added_only_when_asked():
    ends = np.array([[[2.0, -1.0], [2.0, 3.0]]])
    lines = LineSet(np.array([[2.0, 0.0]]), np.diag([1e-4, 1e-5])[None], ends, np.arange(1))
    assert lines.with_model_error(0.0, 0.0) is lines
    out = lines.with_model_error(0.02, 0.01)
    extra = model_error_covariance(lines.r_alpha, ends, 0.02, 0.01)
    np.testing.assert_array_equal(out.cov, lines.cov + extra)
    # the angle error acts about the segment's mid-point (s = 1 m): r gains s²σ_α²
    np.testing.assert_allclose(out.cov[0, 0, 0], 1e-4 + 0.02**2 + 1.0 * 0.01**2)
    np.testing.assert_array_equal(out.r_alpha, lines.r_alpha)
