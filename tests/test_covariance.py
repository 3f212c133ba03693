"""Monte-Carlo consistency of the line covariance (R, α, S) and of the endpoint variances.

Each case observes one wall 4000 times (vectorised: the trials are fitted as 2000 lines at
once).  Requirements (issue 3): variances of R and α within 10 % of the empirical ones, mean
NEES of (R, α) inside the 99 % interval of its χ²₂ mean; the same for the endpoints (χ²₁).
S: variance within 10 %; the full 3×3 NEES for the "reading" model (for "beam" the 3×3 matrix is
nearly singular — each point's error lies along its beam — so its NEES is not informative).
"""

from __future__ import annotations

import numpy as np
import pytest
from _mc import fit_trials, mean_nees, nees_bounds
from _synthetic import wall_scan

from linefit import LineFitConfig, SensorNoiseConfig

N_TRIALS = 4000  # ≥ 2000 (issue 3); 4000 keeps the 10 % variance check ≥ 4.5 σ of sampling noise

# name: (r, α, first and last incidence angle (deg), beams)  — beams evenly spaced in bearing
CASES = {
    "0.5 m, centred": (0.5, 0.4, -30.0, 30.0, 61),
    "2 m side wall (S 2-8 m)": (2.0, -0.3, 45.0, 76.0, 60),
    "10 m, oblique 40-50°": (10.0 * np.cos(np.radians(45.0)), 1.1, 40.0, 50.0, 40),
    "30 m, grazing 70-75°": (30.0 * np.cos(np.radians(72.5)), 2.0, 70.0, 75.0, 40),
    "8 m, grazing 75-80°": (8.0 * np.cos(np.radians(77.5)), -2.5, 75.0, 80.0, 30),
    "2 m long wall, ±78°": (2.0, 0.0, -78.0, 78.0, 157),
}
# First-order S is not valid where α's uncertainty is comparable to the width of the P_S weight
# peak at normal incidence (D σ_φ / σ_d rad): a short wall 0.5 m ahead.  See docs/linefit.md.
S_NONLINEAR = {"0.5 m, centred"}


def run_case(name: str, model: str, seed: int = 2003, **cfg_kwargs):
    r, alpha, t0, t1, n = CASES[name]
    s = r * np.tan(np.radians(np.linspace(t0, t1, n)))
    cfg = LineFitConfig(noise=SensorNoiseConfig(bearing_error=model), **cfg_kwargs)
    obs = wall_scan(r, alpha, s, N_TRIALS, np.random.default_rng(seed), model=model)
    return fit_trials(obs, r, alpha, cfg)


@pytest.mark.parametrize("model", ["beam", "reading"])
@pytest.mark.parametrize("name", list(CASES))
def test_line_covariance_matches_monte_carlo(name, model):
    tr = run_case(name, model)
    P = tr.cov.cov
    emp = tr.errors.var(axis=0)
    pred = np.diag(P.mean(axis=0))
    np.testing.assert_allclose(emp[:2] / pred[:2], 1.0, atol=0.10, err_msg=name)
    lo, hi = nees_bounds(2, N_TRIALS)
    assert lo <= mean_nees(tr.errors[:, :2], P[:, :2, :2]) <= hi
    if name not in S_NONLINEAR:
        assert abs(emp[2] / pred[2] - 1.0) <= 0.10
        if model == "reading":
            lo3, hi3 = nees_bounds(3, N_TRIALS)
            assert lo3 <= mean_nees(tr.errors, P) <= hi3


@pytest.mark.parametrize("model", ["beam", "reading"])
@pytest.mark.parametrize("name", list(CASES))
def test_endpoint_variances_match_monte_carlo(name, model):
    tr = run_case(name, model)
    emp = tr.end_errors.var(axis=0)
    pred = tr.end_var.mean(axis=0)
    np.testing.assert_allclose(emp / pred, 1.0, atol=0.10)
    lo, hi = nees_bounds(1, N_TRIALS)
    for k in range(2):
        assert lo <= np.mean(tr.end_errors[:, k] ** 2 / tr.end_var[:, k]) <= hi


def test_s_cross_terms_are_not_negligible():
    # distant oblique wall: S moves with α (∂S/∂α ≈ −R), the empirical correlation is strong
    tr = run_case("10 m, oblique 40-50°", "beam")
    emp = np.corrcoef(tr.errors.T)
    P = tr.cov.cov.mean(axis=0)
    pred = P / np.sqrt(np.outer(np.diag(P), np.diag(P)))
    assert abs(emp[1, 2]) > 0.5
    np.testing.assert_allclose(pred[[0, 1], 2], emp[[0, 1], 2], atol=0.05)


def test_printed_prop3_is_overconfident_for_a_side_wall():
    """Reading note 8: P_RR = 1/Σ(1/P_R) (Eq. 22) is the variance of R given α."""
    tr = run_case("2 m side wall (S 2-8 m)", "beam")
    fit = tr.fit
    g = np.repeat(np.arange(tr.n_trials), tr.n_points)
    p_rr_printed = 1.0 / np.bincount(g, weights=fit.w_r)
    ratio = tr.errors[:, 0].var() / p_rr_printed.mean()
    assert ratio > 5.0  # the printed form underestimates var(R) several times here
    assert abs(tr.errors[:, 0].var() / tr.cov.cov[:, 0, 0].mean() - 1.0) < 0.10


def test_paper_endpoint_variance_misses_the_sliding_hit_point():
    """Reading note 9: P_S of the extreme point (Eq. 15) is too small at grazing incidence."""
    tr = run_case("30 m, grazing 70-75°", "beam")
    p_s = tr.fit.p_s.reshape(tr.n_trials, tr.n_points)[:, -1]
    assert tr.end_errors[:, 1].var() / p_s.mean() > 2.0
    assert abs(tr.end_errors[:, 1].var() / tr.end_var[:, 1].mean() - 1.0) < 0.10


def test_unweighted_fit_covariance_is_the_sandwich():
    tr = run_case("2 m side wall (S 2-8 m)", "beam", weighted=False)
    emp = tr.errors.var(axis=0)
    pred = np.diag(tr.cov.cov.mean(axis=0))
    np.testing.assert_allclose(emp / pred, 1.0, atol=0.10)
    lo, hi = nees_bounds(2, N_TRIALS)
    assert lo <= mean_nees(tr.errors[:, :2], tr.cov.cov[:, :2, :2]) <= hi


@pytest.mark.parametrize("sigma_per_m", [0.0, 0.002])
def test_weighted_fit_beats_unweighted_on_a_heteroscedastic_wall(sigma_per_m):
    """A wall from 1 m to 20 m: the ML weights lower the mean squared error of R and α."""
    r, alpha = 1.0, 0.3
    s = r * np.tan(np.radians(np.linspace(0.0, 87.1, 120)))  # ranges 1 m ... 19.8 m
    noise = SensorNoiseConfig(sigma_range_per_m=sigma_per_m)
    obs = wall_scan(r, alpha, s, N_TRIALS, np.random.default_rng(3), sigma_per_m=sigma_per_m)
    mse = {}
    for weighted in (True, False):
        tr = fit_trials(obs, r, alpha, LineFitConfig(noise=noise, weighted=weighted))
        mse[weighted] = np.mean(tr.errors[:, :2] ** 2, axis=0)
    assert np.all(mse[True] < 0.9 * mse[False]), mse
