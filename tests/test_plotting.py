"""The shared figure shapes (ellipses, bands) and the figure files they end up in."""

from __future__ import annotations

import numpy as np
import pytest

from slam.plotting.shapes import band_polygon, band_polygons, ellipse_polygons


def random_covariances(rng, m):
    a = rng.normal(0.0, 1.0, (m, 2, 2))
    return a @ np.swapaxes(a, 1, 2) + 0.01 * np.eye(2)


@pytest.mark.parametrize("k", [1.0, 3.0, 150.0])
def test_ellipse_points_lie_on_the_k_sigma_contour(rng, k):
    centres = rng.normal(0.0, 5.0, (6, 2))
    cov = random_covariances(rng, 6)
    poly = ellipse_polygons(centres, cov, k, n=24)
    assert poly.shape == (6, 24, 2)
    d = poly - centres[:, None, :]
    q = np.einsum("mni,mij,mnj->mn", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(q, k**2, rtol=1e-9)
    # n distinct vertices, evenly around: consecutive ones never coincide, the last is not
    # the first again
    assert np.min(np.linalg.norm(np.diff(poly, axis=1), axis=-1)) > 0.0
    assert np.all(np.linalg.norm(poly[:, 0] - poly[:, -1], axis=-1) > 0.0)


def test_ellipse_axes_follow_the_eigenvectors():
    # variance 4 along (1, 1)/√2, 1 along (1, −1)/√2: semi-axes 2k and k
    u = np.array([1.0, 1.0]) / np.sqrt(2.0)
    v = np.array([1.0, -1.0]) / np.sqrt(2.0)
    cov = 4.0 * np.outer(u, u) + np.outer(v, v)
    poly = ellipse_polygons(np.array([[1.0, -2.0]]), cov[None], 3.0, n=400)[0] - [1.0, -2.0]
    assert np.max(np.abs(poly @ u)) == pytest.approx(6.0, rel=1e-4)
    assert np.max(np.abs(poly @ v)) == pytest.approx(3.0, rel=1e-4)


def test_band_half_width_is_k_sigma_of_the_distance_across_the_line():
    r, alpha = 2.0, 0.3
    P = np.array([[1e-4, 2e-5], [2e-5, 4e-5]])
    poly = band_polygon(r, alpha, P, -1.0, 3.0, 3.0, n=9)
    normal = np.array([np.cos(alpha), np.sin(alpha)])
    tangent = np.array([-np.sin(alpha), np.cos(alpha)])
    upper, lower = poly[:9], poly[9:][::-1]
    s = np.linspace(-1.0, 3.0, 9)
    np.testing.assert_allclose(upper @ tangent, s, atol=1e-12)
    np.testing.assert_allclose(lower @ tangent, s, atol=1e-12)
    sigma = np.sqrt(P[0, 0] - 2.0 * s * P[0, 1] + s**2 * P[1, 1])
    np.testing.assert_allclose(upper @ normal - r, 3.0 * sigma, rtol=1e-9)
    np.testing.assert_allclose(r - lower @ normal, 3.0 * sigma, rtol=1e-9)
    # narrowest where σ(s)² is smallest, s = P_rα / P_αα = 0.5, not at the ends
    assert np.argmin(upper @ normal) == 3


def test_bands_follow_the_segments_given_by_end_points():
    r_alpha = np.array([[1.0, 0.0], [2.0, np.pi / 2]])
    cov = np.tile(np.diag([1e-4, 1e-6]), (2, 1, 1))
    # line 0 is x = 1 (s along +y); line 1 is y = 2 (s along −x), two pieces
    segments = [
        np.array([[[1.0, -1.0], [1.0, 2.0]]]),
        np.array([[[0.0, 2.0], [-1.0, 2.0]], [[-3.0, 2.0], [-4.0, 2.0]]]),
    ]
    polys = band_polygons(r_alpha, cov, segments, 3.0, n=5)
    assert len(polys) == 3
    np.testing.assert_allclose(polys[0][:5, 1], np.linspace(-1.0, 2.0, 5), atol=1e-12)
    assert np.all(polys[0][:5, 0] > 1.0) and np.all(polys[0][5:, 0] < 1.0)
    np.testing.assert_allclose(polys[2][:5, 0], np.linspace(-3.0, -4.0, 5), atol=1e-12)


def test_nees_axis_leaves_out_the_gauge_poses_near_zero():
    """The anchored first pose's NEES (~1e-30) does not set the log axis: the range covers the
    χ² band and the curves from their 1st percentile up."""
    from slam.plotting.compare import nees_axis_limits

    curve = np.r_[1e-30, np.linspace(0.5, 8.0, 99)]
    lo, hi = nees_axis_limits({"a": curve}, (2.0, 4.0))
    assert 0.2 < lo < 0.5 and hi == 16.0
    lo, hi = nees_axis_limits({"a": np.r_[0.0, np.full(20, 3.0)]}, (2.0, 4.0))
    assert (lo, hi) == (1.0, 8.0)


def test_comparison_figures_are_written(tmp_path):
    from slam.plotting.compare import (
        plot_errors_over_time,
        plot_nees_over_time,
        plot_runtime_per_scan,
        plot_trajectories,
    )

    t = np.linspace(0.0, 6.0, 50)
    traj = np.column_stack([np.cos(t), np.sin(t), t])
    segs = [np.array([[[-1.0, -1.0], [1.0, -1.0]]])]
    curves = {"a": np.linspace(1.0, 2.0, 50), "b": np.linspace(2.0, 3.0, 50)}
    paths = [
        plot_trajectories({"a": traj}, tmp_path / "t.png", segs, traj),
        plot_errors_over_time(curves, tmp_path / "e.png"),
        plot_nees_over_time(curves, (1.0, 5.0), tmp_path / "sub" / "n.png"),
        plot_runtime_per_scan(curves, tmp_path / "r.png", {"a": np.arange(50.0)}),
    ]
    for path in paths:
        assert path.stat().st_size > 1000
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
