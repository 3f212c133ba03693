"""Eq. 8 point covariances and the RS-frame projections (Eqs. 9-16)."""

from __future__ import annotations

import numpy as np
import pytest

from linefit import InputError, SensorNoiseConfig, point_covariances
from linefit.noise import point_covariance_entries, range_sigma
from linefit.rsframe import rs_coordinates, rs_variances


def test_eq8_as_printed():
    d = np.array([0.5, 3.0, 25.0])
    phi = np.array([-1.0, 0.3, 2.5])
    sd, sp = 0.005, 1e-4
    Q = point_covariances(d, phi)
    for k in range(3):
        s2, c2, s = np.sin(phi[k]) ** 2, np.cos(phi[k]) ** 2, np.sin(2 * phi[k])
        printed = d[k] ** 2 * sp**2 / 2 * np.array([[2 * s2, -s], [-s, 2 * c2]]) + sd**2 / 2 * (
            np.array([[2 * c2, s], [s, 2 * s2]])
        )
        np.testing.assert_allclose(Q[k], printed, rtol=1e-12)


def test_eq8_matches_the_spread_of_simulated_points(rng):
    d, phi = 12.0, 0.7
    noise = SensorNoiseConfig(sigma_range_m=0.02, sigma_bearing_rad=2e-3)
    n = 200_000
    dd = d + rng.normal(0, 0.02, n)
    pp = phi + rng.normal(0, 2e-3, n)
    pts = np.stack([dd * np.cos(pp), dd * np.sin(pp)], axis=1)
    emp = np.cov(pts.T)
    np.testing.assert_allclose(emp, point_covariances([d], [phi], noise)[0], rtol=0.02, atol=1e-7)


def test_range_dependent_sigma_from_config_and_callable():
    d = np.array([1.0, 10.0])
    noise = SensorNoiseConfig(sigma_range_m=0.01, sigma_range_per_m=0.002)
    np.testing.assert_allclose(range_sigma(d, noise), [0.012, 0.03])
    np.testing.assert_allclose(range_sigma(d, noise, lambda r: 0.001 * r**2), [0.001, 0.1])
    q11, _, _ = point_covariance_entries(d, np.zeros(2), noise, lambda r: 0.001 * r**2)
    np.testing.assert_allclose(q11, [1e-6, 1e-2])
    np.testing.assert_allclose(range_sigma(d, noise, lambda r: 0.05), [0.05, 0.05])


@pytest.mark.parametrize("fn", [lambda r: -r, lambda r: np.full(3, 0.1), lambda r: r * np.nan])
def test_bad_sigma_callable_is_an_input_error(fn):
    with pytest.raises(InputError):
        range_sigma(np.array([1.0, 2.0]), None, fn)


def test_rs_frame_convention_and_projections():
    # a point straight along the tangent (−sin α, cos α) has u_S = d, u_R = 0
    alpha = 0.4
    x, y = -np.sin(alpha) * 3.0, np.cos(alpha) * 3.0
    u_r, u_s = rs_coordinates(x, y, alpha)
    assert u_r == pytest.approx(0.0, abs=1e-15) and u_s == pytest.approx(3.0)
    # u_S = d·sin(φ − α) (reading note 1)
    d, phi = 2.0, 1.3
    u_r, u_s = rs_coordinates(d * np.cos(phi), d * np.sin(phi), alpha)
    assert u_r == pytest.approx(d * np.cos(alpha - phi)) and u_s == pytest.approx(
        d * np.sin(phi - alpha)
    )
    Q = point_covariances([d], [phi])[0]
    n = np.array([np.cos(alpha), np.sin(alpha)])
    t = np.array([-np.sin(alpha), np.cos(alpha)])
    p_r, p_s, p_rs = rs_variances(Q[0, 0], Q[0, 1], Q[1, 1], alpha)
    assert p_r == pytest.approx(n @ Q @ n) and p_s == pytest.approx(t @ Q @ t)
    assert p_rs == pytest.approx(n @ Q @ t)
