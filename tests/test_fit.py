"""The ML fit: Prop. 1, Prop. 2 against scipy's optimum of Eq. 20, total least squares."""

from __future__ import annotations

import numpy as np
import pytest
from _synthetic import wall_scan

from linefit import LineFitConfig
from linefit.fit import PointSet, fit_alpha_numerical, fit_groups, tls_groups
from linefit.readings import scan_points
from linefit.rsframe import rs_coordinates, rs_variances

GEOMETRIES = {
    "centred": (2.0, 0.3, -60.0, 60.0, 100),
    "side wall": (2.0, 0.3, 45.0, 76.0, 100),
    "far grazing": (30.0 * np.cos(np.radians(72.5)), -2.0, 70.0, 75.0, 40),
    "near": (0.5, 1.2, -30.0, 30.0, 61),
    "heteroscedastic 1-20 m": (1.0, 2.5, 0.0, 87.0, 150),
}


def one_line(name: str, seed: int = 1) -> tuple[PointSet, float]:
    r, alpha, t0, t1, n = GEOMETRIES[name]
    s = r * np.tan(np.radians(np.linspace(t0, t1, n)))
    obs = wall_scan(r, alpha, s, 1, np.random.default_rng(seed))
    pts = scan_points(obs["ranges"][0], obs["bearings"][0], np.arange(n), LineFitConfig())
    return pts, alpha


def fit_one(pts: PointSet, alpha0: float, **kw):
    n = len(pts)
    return fit_groups(pts, np.arange(n), np.zeros(n, dtype=np.intp), 1, np.array([alpha0]), **kw)


@pytest.mark.parametrize("step", ["prop2", "gauss_newton"])
@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_prop2_reaches_the_numerical_optimum_of_eq20(name, step):
    pts, alpha = one_line(name)
    # start from a poor grouping estimate (2° off)
    fit = fit_one(
        pts, alpha + np.radians(2.0), alpha_step=step, max_iterations=500, tolerance_rad=1e-13
    )
    assert fit.converged[0]
    a_num = fit_alpha_numerical(pts, alpha + np.radians(2.0))
    assert abs(fit.alpha[0] - a_num) < 1e-9


def test_gauss_newton_step_converges_faster_than_printed_prop2_on_a_side_wall():
    pts, alpha = one_line("side wall")
    it = {}
    for step in ("prop2", "gauss_newton"):
        fit = fit_one(pts, alpha + 0.01, alpha_step=step, max_iterations=500)
        it[step] = int(fit.iterations[0])
    assert it["gauss_newton"] <= 6 < it["prop2"]


def test_printed_eq10_sign_makes_prop2_diverge():
    """Reading note 1: with u_S = d·sin(α − φ) the Eq. 24 step moves away from the optimum."""
    pts, alpha = one_line("side wall")
    fit = fit_one(pts, alpha, tolerance_rad=1e-14, max_iterations=100)
    a_opt = float(fit.alpha[0])
    a = a_opt + 0.01
    for _ in range(5):
        u_r, u_s = rs_coordinates(pts.x, pts.y, a)
        u_s = -u_s  # Eq. 10 as printed
        p_r, p_s, _ = rs_variances(pts.q11, pts.q12, pts.q22, a)
        R = np.sum(u_r / p_r) / np.sum(1 / p_r)
        S = np.sum(u_s / p_s) / np.sum(1 / p_s)
        d_r, d_s = u_r - R, u_s - S
        a += -np.sum(d_r * d_s / p_r) / np.sum(d_s * d_s / p_r)
    assert abs(a - a_opt) > 0.01


def test_prop1_r_and_s_are_the_weighted_means():
    pts, alpha = one_line("side wall")
    fit = fit_one(pts, alpha)
    a = fit.alpha[0]
    u_r, u_s = rs_coordinates(pts.x, pts.y, a)
    p_r, p_s, _ = rs_variances(pts.q11, pts.q12, pts.q22, a)
    assert fit.r[0] == pytest.approx(np.sum(u_r / p_r) / np.sum(1 / p_r), abs=1e-12)
    assert fit.s[0] == pytest.approx(np.sum(u_s / p_s) / np.sum(1 / p_s), abs=1e-12)
    # the fixed point: Σ δ_R u_S / P_R = 0 (Eq. 24's numerator)
    assert abs(np.sum((u_r - fit.r[0]) * u_s / p_r)) < 1e-6 * np.sum(np.abs(u_s) / np.sqrt(p_r))


def test_unweighted_fit_is_total_least_squares():
    pts, alpha = one_line("heteroscedastic 1-20 m")
    fit = fit_one(pts, alpha, weighted=False)
    xy = np.stack([pts.x, pts.y], axis=1)
    centred = xy - xy.mean(axis=0)
    normal = np.linalg.svd(centred)[2][-1]
    if normal @ xy.mean(axis=0) < 0:
        normal = -normal
    assert np.arctan2(normal[1], normal[0]) == pytest.approx(
        np.arctan2(np.sin(fit.alpha[0]), np.cos(fit.alpha[0])), abs=1e-10
    )
    assert fit.r[0] == pytest.approx(normal @ xy.mean(axis=0), abs=1e-10)
    assert fit.s[0] == pytest.approx(
        np.mean(-pts.x * np.sin(fit.alpha[0]) + pts.y * np.cos(fit.alpha[0]))
    )


def test_lines_fitted_together_equal_lines_fitted_alone():
    a, alpha_a = one_line("side wall", seed=3)
    b, alpha_b = one_line("far grazing", seed=4)
    both = PointSet(
        *(np.concatenate([getattr(a, f), getattr(b, f)]) for f in ("x", "y", "q11", "q12", "q22")),
        beam=np.arange(len(a) + len(b)),
    )
    gidx = np.repeat([0, 1], [len(a), len(b)])
    together = fit_groups(both, np.arange(len(gidx)), gidx, 2, np.array([alpha_a, alpha_b]))
    alone_a = fit_one(a, alpha_a)
    alone_b = fit_one(b, alpha_b)
    np.testing.assert_allclose(together.alpha, [alone_a.alpha[0], alone_b.alpha[0]], atol=1e-12)
    np.testing.assert_allclose(together.r, [alone_a.r[0], alone_b.r[0]], atol=1e-10)


def test_iteration_cap_flags_non_convergence():
    pts, alpha = one_line("side wall")
    fit = fit_one(pts, alpha + 0.1, alpha_step="prop2", max_iterations=2)
    assert not fit.converged[0]


def test_tls_groups_reports_degenerate_groups():
    pts = PointSet(np.ones(3), np.ones(3), *(np.full(3, 1e-4) for _ in range(3)), beam=np.arange(3))
    _, _, ratio = tls_groups(pts, np.arange(3), np.zeros(3, dtype=np.intp), 1)
    assert not np.isfinite(ratio[0])
