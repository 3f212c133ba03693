"""Line factor: analytic Jacobians vs numerical derivatives, fast path vs CustomFactor, chart."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from slam.errors import DegenerateGeometryError
from slam.geometry import line_residual, pose_retract, predict_line_measurement
from slam.graph.custom_factor import line_custom_factor, values_from_arrays
from slam.graph.factors import (
    line_factor_costs,
    line_factor_residuals,
    linearize_line_factors,
    sqrt_information_2x2,
)
from slam.models.anchored import (
    anchored_from_r_alpha,
    anchored_jacobian,
    landmarks_normal_form,
    r_alpha_from_anchored,
    retract_landmarks,
)


def random_cases(rng: np.random.Generator, n: int):
    """Poses, anchored landmarks, anchors, measurements, covariances; awkward rows first."""
    poses = np.column_stack([rng.uniform(-20, 20, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    r_alpha = np.column_stack([rng.uniform(-15, 15, n), rng.uniform(-np.pi, np.pi, n)])
    anchors = rng.uniform(-20, 20, (n, 2))
    r_alpha[0] = [0.0, np.pi]  # world line through the origin, normal at +π
    r_alpha[1] = [1e-12, -np.pi + 1e-12]
    r_alpha[2] = [3.0, np.pi - 1e-9]
    anchors[:3] = 0.0  # anchor at the origin: the chart is plain (r, α) there
    anchors[3] = [50.0, -40.0]
    v = anchored_from_r_alpha(r_alpha, anchors)
    z_true, _, _ = predict_line_measurement(r_alpha, poses)
    z = z_true + rng.normal(0, [0.02, 0.01], (n, 2))
    z[:, 0] = np.abs(z[:, 0])  # any representative: the residual must not care
    flip = z_true[:, 0] < 0
    z[flip, 1] = z[flip, 1] + np.pi
    z[:, 1] = np.arctan2(np.sin(z[:, 1]), np.cos(z[:, 1]))
    sr, sa, rho = (
        rng.uniform(0.005, 0.05, n),
        rng.uniform(0.001, 0.02, n),
        rng.uniform(-0.8, 0.8, n),
    )
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sr**2, sa**2
    cov[:, 0, 1] = cov[:, 1, 0] = rho * sr * sa
    return poses, v, anchors, z, cov


def residual_fn(pose, v, c, z):
    zp, _, _ = predict_line_measurement(r_alpha_from_anchored(v, c), pose)
    return line_residual(zp, z)[0]


def numeric_jacobian(f, x0, plus, dim, eps=1e-6):
    cols = []
    for k in range(dim):
        d = np.zeros(dim)
        d[k] = eps
        diff = f(plus(x0, d)) - f(plus(x0, -d))
        diff[..., 1] = np.arctan2(np.sin(diff[..., 1]), np.cos(diff[..., 1]))
        cols.append(diff / (2 * eps))
    return np.stack(cols, -1)


def test_chart_round_trip_and_jacobian(rng):
    _poses, v, c, _, _ = random_cases(rng, 200)
    la = r_alpha_from_anchored(v, c)
    np.testing.assert_allclose(anchored_from_r_alpha(la, c), v, atol=1e-12)
    J = anchored_jacobian(v, c)
    for n in range(0, 200, 7):
        J_num = numeric_jacobian(
            lambda w, n=n: r_alpha_from_anchored(w, c[n]), v[n], lambda a, d: a + d, 2
        )
        np.testing.assert_allclose(J[n], J_num, atol=1e-6)
    # the anchor lies on the line it creates with ρ = 0
    on = anchored_from_r_alpha(np.column_stack([np.sum(c * [1, 0], 1), np.zeros(200)]), c)
    np.testing.assert_allclose(on[:, 0], 0.0, atol=1e-12)
    # retraction wraps φ and keeps the line continuous across ±π
    w = retract_landmarks(np.array([[0.5, np.pi - 1e-3]]), np.array([[0.0, 2e-3]]))
    assert -np.pi < w[0, 1] < -np.pi + 2e-3


def test_normal_form_flips_covariance_sign():
    lm = np.array([[-2.0, 0.3], [0.0, -np.pi], [1.0, np.pi]])
    cov = np.array([[[1.0, 0.2], [0.2, 0.5]]] * 3)
    out, cov_out = landmarks_normal_form(lm, cov)
    np.testing.assert_allclose(out[0], [2.0, 0.3 - np.pi])
    assert out[1, 1] == pytest.approx(np.pi)
    assert np.all(out[:, 0] >= 0) and np.all((out[:, 1] > -np.pi) & (out[:, 1] <= np.pi))
    assert cov_out is not None
    np.testing.assert_allclose(cov_out[0], [[1.0, -0.2], [-0.2, 0.5]])
    np.testing.assert_allclose(cov_out[2], cov[2])


def test_analytic_jacobians_match_numerical_derivatives(rng):
    poses, v, c, z, cov = random_cases(rng, 300)
    W = sqrt_information_2x2(cov)
    lin = linearize_line_factors(poses, v, c, z, W)
    checked = 0
    for n in range(300):
        zp, _, _ = predict_line_measurement(r_alpha_from_anchored(v[n], c[n]), poses[n])
        # the representative choice switches where the normals are 90° apart: not differentiable
        d_alpha = np.arctan2(np.sin(zp[1] - z[n, 1]), np.cos(zp[1] - z[n, 1]))
        if abs(abs(d_alpha) - np.pi / 2) < 1e-3:
            continue
        Hp = numeric_jacobian(
            lambda P, n=n: residual_fn(P, v[n], c[n], z[n]), poses[n], pose_retract, 3
        )
        Hl = numeric_jacobian(
            lambda w, n=n: residual_fn(poses[n], w, c[n], z[n]), v[n], retract_landmarks, 2
        )
        np.testing.assert_allclose(lin.A_pose[n], W[n] @ Hp, atol=1e-5 * np.abs(W[n]).max())
        np.testing.assert_allclose(lin.A_landmark[n], W[n] @ Hl, atol=1e-5 * np.abs(W[n]).max())
        checked += 1
    assert checked > 290
    # b is minus the whitened residual, and the cost is half its squared norm
    ew = line_factor_residuals(poses, v, c, z, W)
    np.testing.assert_allclose(lin.b, -ew, atol=1e-12)
    np.testing.assert_allclose(line_factor_costs(poses, v, c, z, W), 0.5 * np.sum(ew**2, 1))


def test_residual_is_continuous_for_awkward_lines(rng):
    """r ≈ 0 world lines and normals at ±π: tiny moves give tiny residual changes (no 2π or
    sign jumps); the bound is the move times the largest lever arm (≈ 40 m)."""
    poses, v, c, z, _cov = random_cases(rng, 20)
    for n in range(3):
        e0 = residual_fn(poses[n], v[n], c[n], z[n])
        for d in ([1e-7, 0], [-1e-7, 0], [0, 1e-7], [0, -1e-7], [0, 2 * np.pi]):
            e1 = residual_fn(poses[n], v[n] + np.array(d), c[n], z[n])
            assert np.max(np.abs(e1 - e0)) < 1e-5


def test_fast_path_equals_custom_factor_linearisation(rng):
    poses, v, c, z, cov = random_cases(rng, 60)
    lin = linearize_line_factors(poses, v, c, z, sqrt_information_2x2(cov))
    for n in range(60):
        f = line_custom_factor(X(0), L(0), c[n], z[n], cov[n])
        values = values_from_arrays([X(0)], poses[n : n + 1], [L(0)], v[n : n + 1])
        A, b = f.linearize(values).jacobian()
        np.testing.assert_allclose(
            A, np.hstack([lin.A_pose[n], lin.A_landmark[n]]), rtol=1e-12, atol=1e-9
        )
        np.testing.assert_allclose(b, lin.b[n], rtol=1e-12, atol=1e-9)
        assert f.error(values) == pytest.approx(0.5 * np.sum(lin.b[n] ** 2), rel=1e-12)


def test_sqrt_information_matches_gtsam_and_rejects_bad_covariances(rng):
    A = rng.normal(size=(50, 2, 2))
    cov = A @ np.swapaxes(A, 1, 2) + 1e-3 * np.eye(2)
    W = sqrt_information_2x2(cov)
    np.testing.assert_allclose(np.swapaxes(W, 1, 2) @ W, np.linalg.inv(cov), rtol=1e-9)
    for n in range(5):
        R = gtsam.noiseModel.Gaussian.Covariance(cov[n]).R()
        np.testing.assert_allclose(W[n], R, rtol=1e-9, atol=1e-9)
    for bad in ([[1.0, 1.0], [1.0, 1.0]], [[-1.0, 0.0], [0.0, 1.0]], [[np.nan, 0], [0, 1.0]]):
        with pytest.raises(DegenerateGeometryError):
            sqrt_information_2x2(np.array([np.eye(2), bad]))


def test_robust_weights_downweight_outliers(rng):
    poses, v, c, z, cov = random_cases(rng, 50)
    z_out = z.copy()
    z_out[10, 0] += 5.0  # a gross outlier
    W = sqrt_information_2x2(cov)
    for kernel in ("huber", "cauchy"):
        lin = linearize_line_factors(poses, v, c, z_out, W, kernel, 3.0)
        u = np.linalg.norm(lin.whitened_residual, axis=1)
        assert lin.weights[10] < 0.05
        assert np.all(lin.weights[u < 3.0] > 0.5)
        np.testing.assert_allclose(lin.b, -lin.whitened_residual * np.sqrt(lin.weights)[:, None])
