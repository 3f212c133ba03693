"""The front end's drift accumulator and the odometry-noise estimator (slam.line_slam)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.optimize import lsq_linear
from scipy.stats import chi2

from slam.frontend.config import FrontendConfig
from slam.geometry import pose_between, pose_compose, pose_exp, pose_log
from slam.line_slam.drift import DriftAccumulator
from slam.line_slam.front_end import correction_consistency
from slam.line_slam.odometry_noise import MotionNoiseEstimator, bounded_least_squares
from slam.models.motion import MotionNoiseConfig

FloatArray = NDArray[np.float64]


def test_drift_sums_step_variances_and_a_systematic_part():
    d = DriftAccumulator(xy_per_m=0.01, theta_per_m=0.002)
    steps = [np.diag([0.0, 0.0, 0.0]), np.diag([4e-4, 1e-4, 1e-6]), np.diag([1e-4, 9e-4, 4e-6])]
    for k, C in enumerate(steps):
        d.add_step(C, path_m=2.0 * k, step_pose=np.array([2.0, 0.0, 0.0]))
    sxy, sth = d.between(0, 2)
    # larger eigenvalue of each xy block: 4e-4 + 9e-4; heading 1e-6 + 4e-6; path 4 m
    assert float(sxy) == pytest.approx(np.sqrt(13e-4 + (0.01 * 4.0) ** 2))
    assert float(sth) == pytest.approx(np.sqrt(5e-6 + (0.002 * 4.0) ** 2))
    assert np.allclose(d.between(2, 0), d.between(0, 2))
    sxy1, _ = d.since(np.array([1]))
    assert float(sxy1[0]) == pytest.approx(np.sqrt(9e-4 + 0.02**2))
    # the chain of the front end's steps
    np.testing.assert_allclose(d.relative(0, 2), [4.0, 0.0, 0.0], atol=1e-12)


def test_drift_scale_learns_from_closures_larger_than_predicted(rng):
    d = DriftAccumulator()
    for _ in range(3):
        d.add_step(np.diag([1e-3, 1e-3, 1e-4]), 0.0, np.zeros(3))
    sigma_xy, sigma_th = 0.1, 0.01
    for _ in range(400):
        t = rng.normal(0.0, 2.0 * np.array([sigma_xy, sigma_xy, sigma_th]))
        d.observe_closure(t, sigma_xy, sigma_th, single_direction=False)
    # closures twice as large as predicted: the scale becomes about 2 (never below 1)
    assert d.scale_xy == pytest.approx(2.0, rel=0.15)
    assert d.scale_theta == pytest.approx(2.0, rel=0.15)
    e = DriftAccumulator()
    for _ in range(100):
        e.observe_closure(np.zeros(3) + 1e-4, sigma_xy, sigma_th, single_direction=False)
    assert e.scale_xy == 1.0 and e.scale_theta == 1.0


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def _map_step(rng, P0, P_L):
    """A prediction error from P0 and a lines-only measurement error from P_L: the MAP correction
    and its posterior covariance."""
    x_err = rng.multivariate_normal(np.zeros(3), P0)  # prediction minus truth
    l_err = rng.multivariate_normal(np.zeros(3), P_L)  # lines-only estimate minus truth
    I0, IL = np.linalg.inv(P0), np.linalg.inv(P_L)
    post = np.linalg.inv(I0 + IL)
    # MAP relative to the prediction: post (IL (l − x))
    c = post @ (IL @ (l_err - x_err))
    return c, post


def test_registration_correction_is_chi2_distributed(rng):
    """Monte Carlo: under the models the correction's squared distance is χ² with as many
    degrees of freedom as the lines constrain (NEES mean ≈ dof, 99.9 % point respected)."""
    P0 = np.diag([0.03**2, 0.02**2, 0.02**2])
    for P_L, dof in ((np.diag([0.01**2, 0.015**2, 0.004**2]), 3), (None, 2)):
        d2 = []
        for _ in range(3000):
            if P_L is None:
                # parallel walls: nothing along x (the lines' information has rank 2)
                IL = np.diag([0.0, 1.0 / 0.01**2, 1.0 / 0.004**2])
                I0 = np.linalg.inv(P0)
                post = np.linalg.inv(I0 + IL)
                x_err = rng.multivariate_normal(np.zeros(3), P0)
                noise = np.array([0.0, rng.normal(0, 0.01), rng.normal(0, 0.004)])
                c = post @ (IL @ (noise - x_err))
            else:
                c, post = _map_step(rng, P0, P_L)
            value, k = correction_consistency(c, P0, post)
            assert k == dof
            d2.append(value)
        d2 = np.asarray(d2)
        assert abs(d2.mean() - dof) < 0.15 * dof
        assert np.mean(d2 > chi2.ppf(0.999, dof)) < 0.004


def test_odometry_noise_estimator_recovers_the_model(rng):
    """Registrations of a simulated run whose odometry is noisier than configured: the fitted
    model finds the true noise from the residuals (the prior far off)."""
    true = MotionNoiseConfig(
        sigma_xy_per_m=0.12, sigma_xy_per_rad=0.02, sigma_theta_per_m=0.06, sigma_theta_per_rad=0.1
    )
    prior = MotionNoiseConfig()
    est = MotionNoiseEstimator(prior, prior_weight=30.0, min_samples=30, update_every=25)
    floor = FrontendConfig().prior_sigma_xy_m
    P_L = np.diag([0.004**2, 0.004**2, 0.0015**2])
    for _ in range(1500):
        delta = np.array([rng.uniform(0.1, 0.6), rng.normal(0, 0.02), rng.normal(0, 0.3)])
        Q = prior.covariance(delta)
        P0 = Q + np.diag([floor**2, floor**2, 0.01**2])
        x_err = rng.multivariate_normal(np.zeros(3), true.covariance(delta))
        l_err = rng.multivariate_normal(np.zeros(3), P_L)
        I0, IL = np.linalg.inv(P0), np.linalg.inv(P_L)
        post = np.linalg.inv(I0 + IL)
        c = post @ (IL @ (l_err - x_err))
        est.add(delta, c, P0, post)
        est.keyframe()
    m = est.model
    assert est.fits > 10
    assert m.sigma_xy_per_m == pytest.approx(true.sigma_xy_per_m, rel=0.2)
    assert m.sigma_theta_per_m == pytest.approx(true.sigma_theta_per_m, rel=0.25)
    assert m.sigma_theta_per_rad == pytest.approx(true.sigma_theta_per_rad, rel=0.2)


def _span_run(rng, bias: FloatArray | None, n_keyframes: int = 4000) -> MotionNoiseEstimator:
    """Samples of a run whose odometry errs as ``model`` says (plus ``bias`` on every step);
    one keyframe in five gives no sample, so the runs of consecutive samples are short."""
    model = MotionNoiseConfig(
        sigma_xy_min_m=0.002,
        sigma_xy_per_m=0.03,
        sigma_theta_min_rad=0.001,
        sigma_theta_per_rad=0.05,
    )
    # the model is the one fitted: a prior that outweighs the samples keeps it
    est = MotionNoiseEstimator(model, prior_weight=1e9)
    P_L = np.diag([0.002**2, 0.002**2, 0.0005**2])
    for _ in range(n_keyframes):
        if rng.random() < 0.8:
            delta = np.array([rng.uniform(0.2, 0.5), 0.0, rng.normal(0.0, 0.2)])
            nu = rng.multivariate_normal(np.zeros(3), model.covariance(delta) + P_L)
            if bias is not None:
                nu = nu + bias
            est.add_error(delta, nu, P_L)
        est.keyframe()
    return est


def test_span_consistency_of_independent_errors_is_chi2_at_every_length(rng):
    """Errors independent from step to step, as the model says: over 1 to 16 consecutive
    keyframes the mean NEES is 3 within the 99 % band of its mean (fewer spans, wider band)."""
    report = _span_run(rng, None).span_consistency()
    assert [r["keyframes"] for r in report] == [1, 2, 4, 8, 16]
    for r in report:
        n = int(r["spans"])
        lo, hi = chi2.ppf([0.005, 0.995], 3 * n) / n
        assert lo < r["nees"] < hi, r


def test_span_consistency_rises_with_a_bias(rng):
    """A bias of 2 cm sideways on every step (about a step's σ): one step's NEES rises a
    little, eight steps' far more, beyond the 99 % band of a mean of χ²₃, as the bias adds up
    along the span and the noise only as its square root."""
    report = _span_run(rng, np.array([0.0, 0.02, 0.0])).span_consistency()
    by_length = {int(r["keyframes"]): r for r in report}
    one, eight = by_length[1], by_length[8]
    assert one["nees"] < 5.0
    assert eight["nees"] > 1.5 * one["nees"]
    n = int(eight["spans"])
    assert eight["nees"] > chi2.ppf(0.995, 3 * n) / n


def test_odometry_noise_estimator_ignores_weakly_constrained_registrations():
    est = MotionNoiseEstimator(MotionNoiseConfig())
    P0 = np.diag([0.03**2, 0.03**2, 0.02**2])
    # posterior barely tighter than the prior in x (parallel walls): not a sample
    post = np.diag([0.029**2, 0.005**2, 0.002**2])
    assert not est.add(np.array([0.3, 0.0, 0.1]), np.array([0.01, 0.0, 0.0]), P0, post)
    assert est.n_samples == 0


def test_front_end_chain_is_the_composition_of_its_steps(rng):
    d = DriftAccumulator()
    poses = [np.zeros(3)]
    d.add_step(np.zeros((3, 3)), 0.0, None)  # the first keyframe
    for _ in range(20):
        step = np.array([rng.uniform(0, 0.5), rng.normal(0, 0.05), rng.normal(0, 0.3)])
        poses.append(pose_compose(poses[-1], step))
        d.add_step(np.eye(3) * 1e-4, 0.0, step)
    np.testing.assert_allclose(d.relative(3, 17), pose_between(poses[3], poses[17]), atol=1e-12)


def test_bounded_least_squares_is_the_constrained_minimum():
    """The face-by-face solution against scipy's iterative bounded least squares (tight
    tolerance) on random problems, with bounds active and inactive: never a higher cost, the
    bounds held; and an unconstrained minimum inside the box is returned as is."""
    rng = np.random.default_rng(7)
    active = 0
    for k in range(300):
        m = int(rng.integers(3, 60))
        A = rng.standard_normal((m, 3)) * rng.uniform(0.01, 3.0, 3)
        b = rng.standard_normal(m)
        lower = rng.standard_normal(3) * 0.3 if k % 2 else np.array([1e-4, 0.0, 0.0])
        ref = lsq_linear(A, b, bounds=(lower, np.inf), tol=1e-14).x
        p = bounded_least_squares(A, b, lower)
        assert np.all(p >= lower)
        cost, cost_ref = np.sum((A @ p - b) ** 2), np.sum((A @ ref - b) ** 2)
        assert cost <= cost_ref * (1 + 1e-9) + 1e-12
        np.testing.assert_allclose(p, ref, atol=1e-6)
        active += int(np.any(np.isclose(p, lower)))
    assert 50 < active < 300  # both cases occurred
    A = rng.standard_normal((20, 3))
    x = np.array([0.5, 1.0, 2.0])
    np.testing.assert_allclose(bounded_least_squares(A, A @ x, np.zeros(3)), x, atol=1e-12)


def _chain_draws(steps, perturb, a, b):
    """Relative poses ``a → b`` of chains whose steps are moved by ``perturb(i)`` (right)."""
    poses = [np.zeros(3)]
    for i, s in enumerate(steps):
        poses.append(pose_compose(poses[-1], pose_compose(s, pose_exp(perturb(i)))))
    return pose_between(poses[a], poses[b])


@pytest.mark.parametrize("a, b", [(2, 27), (27, 2)])
def test_chain_covariance_is_the_composed_steps_with_their_lever_arms(rng, a, b):
    # a curving chain of 30 steps, each with its own covariance; Monte Carlo of the relative
    # pose against relative_cov (either direction): the heading errors' lever arms included
    n = 30
    steps = [np.array([0.5, 0.0, 0.12]) for _ in range(n)]
    covs = []
    for _ in range(n):
        L = rng.normal(0.0, 1.0, (3, 3)) * np.array([0.01, 0.01, 0.004])[:, None]
        covs.append(L @ L.T + np.diag([1e-5, 1e-5, 1e-6]))
    d = DriftAccumulator()
    d.add_step(np.zeros((3, 3)), 0.0, None)
    for k, (s, C) in enumerate(zip(steps, covs, strict=True)):
        d.add_step(C, 0.5 * (k + 1), s)
    nominal = d.relative(a, b)
    chol = [np.linalg.cholesky(C) for C in covs]
    draws = 8000
    errors = np.empty((draws, 3))
    for k in range(draws):
        z = rng.normal(size=(n, 3))
        # step i ends at keyframe i + 1
        F = _chain_draws(steps, lambda i, z=z: chol[i] @ z[i], a, b)
        errors[k] = pose_log(pose_between(nominal, F))
    empirical = np.cov(errors.T)
    predicted = d.relative_cov(a, b)
    # the isotropic sums (no lever arm) fall well short of the spread of the translation
    assert float(d.between(a, b)[0]) < 0.75 * np.sqrt(max(empirical[0, 0], empirical[1, 1]))
    np.testing.assert_allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(predicted)), rtol=0.06)
    corr_e = empirical / np.sqrt(np.outer(np.diag(empirical), np.diag(empirical)))
    corr_p = predicted / np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
    np.testing.assert_allclose(corr_e, corr_p, atol=0.05)


def test_chain_covariance_carries_a_systematic_heading_rate(rng):
    # no random part: every step turns by κ_θ · (its length) · u, one u ~ N(0, 1) per chain
    kappa = 0.01
    steps = [np.array([0.4, 0.0, 0.1 * np.sin(0.3 * k)]) for k in range(25)]
    d = DriftAccumulator(theta_per_m=kappa)
    d.add_step(np.zeros((3, 3)), 0.0, None)
    for k, s in enumerate(steps):
        d.add_step(np.zeros((3, 3)), 0.4 * (k + 1), s)
    nominal = d.relative(0, 25)
    errors = []
    for u in rng.normal(size=4000):
        F = _chain_draws(steps, lambda i, u=u: np.array([0.0, 0.0, kappa * 0.4 * u]), 0, 25)
        errors.append(pose_log(pose_between(nominal, F)))
    empirical = np.cov(np.asarray(errors).T)
    predicted = d.relative_cov(0, 25)
    np.testing.assert_allclose(predicted[2, 2], (kappa * 10.0) ** 2, rtol=1e-9)
    np.testing.assert_allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(predicted)), rtol=0.08)
