"""The lines' model-error estimator (slam.line_slam.line_noise): known answers."""

from __future__ import annotations

import numpy as np
import pytest

from slam.geometry import predict_line_measurement, wrap_angle
from slam.graph.problem import LineGraph
from slam.line_slam.line_noise import LineModelErrorEstimator, midpoint_residuals
from slam.models.anchored import model_error_covariance

FIT_COV = np.array([[4e-6, 0.0], [0.0, 1e-6]])  # the fit's (r, α) covariance at the foot point


def _graph(rng, sigma_o, sigma_a, n_landmarks=40, per_landmark=12, outliers=0.0, laplace=False):
    """Walls seen from exact poses; each measured line perturbed by the fit's noise plus a model
    error (σ_o along the normal at the segment's mid-point, σ_a about it); ``laplace``: the
    noise Laplace-distributed with that covariance (heavier tails).  The estimate is the
    truth, so each factor's residual is its measurement noise.  Returns (graph, fit_cov)."""
    g = LineGraph()
    alpha = rng.uniform(-np.pi, np.pi, n_landmarks)
    r = rng.uniform(1.0, 8.0, n_landmarks)
    normals = np.stack([np.cos(alpha), np.sin(alpha)], axis=-1)
    tangents = np.stack([-np.sin(alpha), np.cos(alpha)], axis=-1)
    anchors = r[:, None] * normals + rng.uniform(-3.0, 3.0, (n_landmarks, 1)) * tangents
    lms = g.add_landmarks(np.stack([r, alpha], axis=-1), anchors)
    fit_cov = []
    for j in range(n_landmarks):
        for _ in range(per_landmark):
            pose = np.array([*rng.uniform(-2.0, 2.0, 2), rng.uniform(-np.pi, np.pi)])
            p = g.add_pose(pose)
            z_true, _, _ = predict_line_measurement(np.array([[r[j], alpha[j]]]), pose[None])
            z_true = z_true[0]
            # a segment of 1-3 m, its mid-point up to 4 m along the line from the foot point
            s_m = rng.uniform(-4.0, 4.0)
            half = rng.uniform(0.5, 1.5)
            n = np.array([np.cos(z_true[1]), np.sin(z_true[1])])
            t = np.array([-np.sin(z_true[1]), np.cos(z_true[1])])
            ep = np.stack([z_true[0] * n + (s_m - half) * t, z_true[0] * n + (s_m + half) * t])
            cov = FIT_COV + model_error_covariance(z_true[None], ep[None], sigma_o, sigma_a)[0]
            noise = rng.multivariate_normal(np.zeros(2), cov)
            if laplace:
                noise = np.linalg.cholesky(cov) @ rng.laplace(0.0, np.sqrt(0.5), 2)
            if rng.random() < outliers:
                noise = noise + rng.normal(0.0, [0.3, 0.1])
            z = np.array([z_true[0] + noise[0], wrap_angle(z_true[1] + noise[1])])
            g.add_line_factors(p, lms[j : j + 1], z[None], cov[None], ep[None])
            fit_cov.append(FIT_COV)
    return g, np.array(fit_cov)


@pytest.mark.parametrize(("sigma_o", "sigma_a"), [(0.02, 0.01), (0.05, 0.003), (0.0, 0.0)])
def test_the_estimate_recovers_the_model_error(sigma_o, sigma_a):
    rng = np.random.default_rng(11)
    g, fit_cov = _graph(rng, sigma_o, sigma_a)
    est = LineModelErrorEstimator(0.1, 0.1)
    assert est.update(g, fit_cov)
    s_o, s_a = est.sigmas
    if sigma_o == 0.0:
        # the fit's noise alone: the model error found is small against the fit's σ (2 mm, 1 mrad)
        assert s_o < 1.5e-3 and s_a < 7e-4
    else:
        assert s_o == pytest.approx(sigma_o, rel=0.15)
        assert s_a == pytest.approx(sigma_a, rel=0.15)
    assert est.summary()["samples"] == fit_cov.shape[0]


def test_a_few_wrong_associations_do_not_move_the_estimate():
    rng = np.random.default_rng(12)
    g, fit_cov = _graph(rng, 0.02, 0.01, outliers=0.05)
    est = LineModelErrorEstimator(0.1, 0.1)
    assert est.update(g, fit_cov)
    assert est.sigmas[0] == pytest.approx(0.02, rel=0.2)
    assert est.sigmas[1] == pytest.approx(0.01, rel=0.2)


def test_heavy_tailed_residuals_give_their_variance():
    """Laplace-distributed residuals (variance σ², tails heavier than Gaussian): the estimate is
    their standard deviation, where matching the median of χ²₁ gives about 0.8 σ."""
    rng = np.random.default_rng(14)
    g, fit_cov = _graph(rng, 0.02, 0.01, n_landmarks=60, laplace=True)
    est = LineModelErrorEstimator(0.1, 0.1)
    assert est.update(g, fit_cov)
    assert est.sigmas[0] == pytest.approx(0.02, rel=0.12)
    assert est.sigmas[1] == pytest.approx(0.01, rel=0.12)


def test_midpoint_residuals_are_the_offset_and_angle_at_the_segment_midpoint():
    """A measured line rotated by δ about its segment's mid-point: offset 0, angle δ."""
    g = LineGraph()
    lm = g.add_landmarks(np.array([[2.0, 0.3]]), np.array([[2.0 * np.cos(0.3), 2.0 * np.sin(0.3)]]))
    p = g.add_pose(np.zeros(3))
    n = np.array([np.cos(0.3), np.sin(0.3)])
    t = np.array([-np.sin(0.3), np.cos(0.3)])
    mid = 2.0 * n + 3.0 * t
    delta = 0.01
    # the line through mid with normal angle 0.3 + δ
    a = 0.3 + delta
    r = float(mid @ np.array([np.cos(a), np.sin(a)]))
    ep = np.stack([mid - 0.5 * t, mid + 0.5 * t])
    g.add_line_factors(p, lm, np.array([[r, a]]), np.eye(2)[None] * 1e-4, ep[None])
    e, var = midpoint_residuals(g, np.array([0]), np.eye(2)[None] * 1e-4)
    assert abs(e[0, 0]) < 3e-4  # second order in δ only (the first-order change of r: 0.03 m)
    assert abs(e[0, 1]) == pytest.approx(delta, rel=1e-6)
    assert var[0, 1] == pytest.approx(1e-4)
    assert var[0, 0] > 1e-4  # the angle's variance moved along the line adds to the offset's


def test_too_few_samples_keep_the_configured_values():
    rng = np.random.default_rng(13)
    g, fit_cov = _graph(rng, 0.02, 0.01, n_landmarks=3, per_landmark=6)
    est = LineModelErrorEstimator(0.07, 0.03, min_samples=50)
    assert not est.update(g, fit_cov)
    assert est.sigmas == (0.07, 0.03) and est.updates == 0
