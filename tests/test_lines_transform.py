"""Eq. 31 with derived Jacobians and pose compounding: derivatives, Monte Carlo, round trips."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import DegenerateGeometryError, InputError
from slam.geometry import pose_between, pose_compose, pose_exp, pose_inverse, pose_log, wrap_angle
from slam.lines import (
    adjoint,
    align_representative,
    between_poses,
    compose_chain,
    compound_poses,
    invert_pose,
    line_from_world,
    line_to_world,
    transform_line,
    transform_line_to_child,
    transform_segments,
)


def perturb(pose: np.ndarray, xi: np.ndarray) -> np.ndarray:
    return pose_compose(pose, pose_exp(xi))


def tangent_error(ref: np.ndarray, samples: np.ndarray) -> np.ndarray:
    return pose_log(pose_compose(pose_inverse(ref), samples))


def line_error(ref: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """Difference in the representative of ``ref`` (a sample may flip to ``(−r, α+π, −s)``)."""
    aligned, _, _ = align_representative(samples, np.zeros((*samples.shape, 3)), ref[..., 1])
    d = aligned - ref
    d[..., 1] = wrap_angle(d[..., 1])
    return d


def assert_cov_close(emp: np.ndarray, pred: np.ndarray, rtol: float) -> None:
    """Compare covariances through correlation-normalised entries (scale-free)."""
    sd = np.sqrt(np.diag(pred))
    np.testing.assert_allclose(emp / np.outer(sd, sd), pred / np.outer(sd, sd), atol=rtol)


def test_adjoint_conjugates_exp(rng):
    poses = np.column_stack([rng.uniform(-5, 5, (20, 2)), rng.uniform(-np.pi, np.pi, 20)])
    xi = rng.normal(0, 0.3, (20, 3))
    lhs = pose_compose(pose_compose(poses, pose_exp(xi)), pose_inverse(poses))
    rhs = pose_exp(np.einsum("nij,nj->ni", adjoint(poses), xi))
    np.testing.assert_allclose(lhs, rhs, atol=1e-10)


def numeric_jac_pose(f, dim: int = 3, eps: float = 1e-6) -> np.ndarray:
    cols = []
    for k in range(dim):
        d = np.zeros(dim)
        d[k] = eps
        cols.append((f(d) - f(-d)) / (2 * eps))
    return np.stack(cols, -1)


def test_compound_and_between_jacobians_match_numerical_derivatives(rng):
    a = np.array([1.0, -2.0, 0.7])
    b = np.array([3.0, 0.5, -2.1])
    c = pose_compose(a, b)
    # ξ_c as a function of ξ_a: Jacobian must be Ad(b⁻¹); of ξ_b: identity
    Ja = numeric_jac_pose(
        lambda d: pose_log(pose_compose(pose_inverse(c), pose_compose(perturb(a, d), b)))
    )
    np.testing.assert_allclose(Ja, adjoint(pose_inverse(b)), atol=1e-8)
    Jb = numeric_jac_pose(
        lambda d: pose_log(pose_compose(pose_inverse(c), pose_compose(a, perturb(b, d))))
    )
    Pa, Pb = np.diag([0.01, 0.02, 0.003]), np.diag([0.04, 0.01, 0.001])
    _, cov = compound_poses(a, Pa, b, Pb)
    np.testing.assert_allclose(cov, Ja @ Pa @ Ja.T + Jb @ Pb @ Jb.T, atol=1e-9)
    np.testing.assert_allclose(Jb, np.eye(3), atol=1e-8)
    d = pose_between(a, b)
    Ka = numeric_jac_pose(
        lambda e: pose_log(pose_compose(pose_inverse(d), pose_between(perturb(a, e), b)))
    )
    Kb = numeric_jac_pose(
        lambda e: pose_log(pose_compose(pose_inverse(d), pose_between(a, perturb(b, e))))
    )
    d2, cov_d = between_poses(a, Pa, b, Pb)
    np.testing.assert_allclose(d2, d, atol=1e-12)
    np.testing.assert_allclose(cov_d, Ka @ Pa @ Ka.T + Kb @ Pb @ Kb.T, atol=1e-9)
    inv, cov_inv = invert_pose(a, Pa)
    Ki = numeric_jac_pose(
        lambda e: pose_log(pose_compose(pose_inverse(inv), pose_inverse(perturb(a, e))))
    )
    np.testing.assert_allclose(cov_inv, Ki @ Pa @ Ki.T, atol=1e-9)


def test_compound_poses_monte_carlo_with_cross_covariance(rng):
    a = np.array([2.0, 1.0, 0.4])
    b = np.array([1.5, -0.7, 1.1])
    L = np.diag([0.05, 0.05, 0.02, 0.04, 0.03, 0.03]) @ (np.eye(6) + 0.3 * np.tri(6, k=-1))
    joint = L @ L.T
    xi = rng.normal(size=(100_000, 6)) @ L.T
    samples = pose_compose(perturb(a, xi[:, :3]), perturb(b, xi[:, 3:]))
    pose_ab, cov = compound_poses(a, joint[:3, :3], b, joint[3:, 3:], cross=joint[:3, 3:])
    emp = np.cov(tangent_error(pose_ab, samples).T)
    assert_cov_close(emp, cov, 0.03)
    # without the cross term the prediction is measurably wrong for this correlation
    _, cov_indep = compound_poses(a, joint[:3, :3], b, joint[3:, 3:])
    sd = np.sqrt(np.diag(cov))
    assert np.max(np.abs((cov_indep - emp) / np.outer(sd, sd))) > 0.1


def test_compose_chain_matches_recursion_and_monte_carlo(rng):
    n = 12
    inc = np.column_stack([rng.uniform(0.2, 0.6, n), rng.normal(0, 0.05, n), rng.normal(0, 0.3, n)])
    C = np.diag([0.02, 0.01, 0.01]) ** 2
    poses, covs = compose_chain(inc, C)
    p, P = np.zeros(3), np.zeros((3, 3))
    for k in range(n):
        p, P = compound_poses(p, P, inc[k], C)
        np.testing.assert_allclose(poses[k + 1], p, atol=1e-12)
        np.testing.assert_allclose(covs[k + 1], P, atol=1e-14)
    # Monte Carlo on the end pose
    m = 40_000
    Lc = np.linalg.cholesky(C)
    pose = np.zeros((m, 3))
    for k in range(n):
        pose = pose_compose(pose, perturb(inc[k], rng.normal(size=(m, 3)) @ Lc.T))
    emp = np.cov(tangent_error(poses[-1], pose).T)
    assert_cov_close(emp, covs[-1], 0.04)
    # start pose and covariance are honoured
    p0 = np.array([1.0, 2.0, -0.5])
    P0 = np.diag([0.1, 0.2, 0.05])
    poses2, covs2 = compose_chain(inc[:1], C, p0, P0)
    np.testing.assert_allclose(poses2[0], p0)
    np.testing.assert_allclose(covs2[0], P0, atol=1e-14)
    np.testing.assert_allclose(covs2[1], compound_poses(p0, P0, inc[0], C)[1], atol=1e-14)


@pytest.mark.parametrize("normal_form", [True, False])
def test_transform_line_covariance_monte_carlo(rng, normal_form):
    """Large displacement + rotational pose variance: B P Bᵀ + K P Kᵀ matches Monte Carlo."""
    line_j = np.array([2.0, 0.7, 1.5])
    P_line = np.array([[4e-4, -1e-4, 0.0], [-1e-4, 2e-4, 0.0], [0.0, 0.0, 1e-3]])
    pose = np.array([4.0, -3.0, 0.5])
    P_pose = np.array([[0.01, 0.002, 0.0], [0.002, 0.02, 0.001], [0.0, 0.001, 0.004]])
    line_i, cov_i = transform_line(line_j, P_line, pose, P_pose, normal_form=normal_form)
    m = 100_000
    lines = line_j + rng.normal(size=(m, 3)) @ np.linalg.cholesky(P_line).T
    poses = perturb(pose, rng.normal(size=(m, 3)) @ np.linalg.cholesky(P_pose).T)
    li, _ = transform_line(lines, np.broadcast_to(P_line, (m, 3, 3)), poses, None, normal_form)
    emp = np.cov(line_error(line_i, li).T)
    assert_cov_close(emp, cov_i, 0.03)
    # the printed Eqs. 32-33 (angle α_j, no γ column, zero ∂S/∂α) are clearly off here
    x, y, _ = pose
    a = line_j[1]
    B_p = np.array([[1, -x * np.sin(a) + y * np.cos(a), 0], [0, 1, 0], [0, 0, 1]])
    K_p = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    printed = B_p @ P_line @ B_p.T + K_p @ P_pose @ K_p.T
    assert abs(printed[0, 0] - emp[0, 0]) / emp[0, 0] > 0.3


def test_round_trip_is_identity_including_covariance(rng):
    n = 200
    lines = np.column_stack(
        [rng.uniform(0, 10, n), rng.uniform(-np.pi, np.pi, n), rng.normal(0, 3, n)]
    )
    lines[:10, 0] = rng.uniform(0, 1e-6, 10)  # lines through the origin
    lines[10:20, 1] = np.pi - rng.uniform(0, 1e-6, 10)
    A = rng.normal(size=(n, 3, 3)) * 0.01
    covs = A @ np.swapaxes(A, -1, -2)
    poses = np.column_stack([rng.uniform(-8, 8, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    li, ci = transform_line_to_child(lines, covs, poses)
    back, cback = transform_line(li, ci, poses)
    d = line_error(lines, back)
    np.testing.assert_allclose(d, 0.0, atol=1e-9)
    np.testing.assert_allclose(cback, covs, atol=1e-12)
    # world helpers are the same maps
    w, cw = line_to_world(li, ci, poses)
    np.testing.assert_allclose(line_error(w, back), 0.0, atol=1e-12)
    lw, clw = line_from_world(w, cw, poses)
    np.testing.assert_allclose(line_error(lw, li), 0.0, atol=1e-9)
    np.testing.assert_allclose(clw, ci, atol=1e-12)


def test_transform_segments_agree_with_transformed_points(rng):
    for _ in range(20):
        line_j = np.array([rng.uniform(0.1, 5), rng.uniform(-np.pi, np.pi), 0.3])
        seg = np.array([[-2.0, -0.5], [0.4, 1.7]])
        var = np.full((2, 2), 1e-4)
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        cov = np.diag([1e-4, 1e-5, 1e-3])
        line_i, _ = transform_line(line_j, cov, pose)
        seg_i, var_i = transform_segments(seg, var, line_j, cov, pose)
        n_j = np.array([np.cos(line_j[1]), np.sin(line_j[1])])
        t_j = np.array([-np.sin(line_j[1]), np.cos(line_j[1])])
        pts_j = line_j[0] * n_j + seg.reshape(-1, 1) * t_j
        c, s = np.cos(pose[2]), np.sin(pose[2])
        pts_i = pts_j @ np.array([[c, s], [-s, c]]) + pose[:2]
        t_i = np.array([-np.sin(line_i[1]), np.cos(line_i[1])])
        s_pts = np.sort((pts_i @ t_i).reshape(2, 2), axis=1)
        s_pts = s_pts[np.argsort(s_pts[:, 0])]
        np.testing.assert_allclose(seg_i, s_pts, atol=1e-9)
        assert np.all(seg_i[:, 0] < seg_i[:, 1])
        assert np.all(var_i >= var)


def test_bad_covariances_raise_clear_errors():
    line = np.array([1.0, 0.2, 0.0])
    with pytest.raises(DegenerateGeometryError, match="not symmetric"):
        transform_line(line, np.array([[1e-4, 5e-5, 0], [0, 1e-4, 0], [0, 0, 1e-4]]), np.zeros(3))
    with pytest.raises(DegenerateGeometryError, match="negative variance"):
        transform_line(line, np.diag([1e-4, -1e-6, 1e-4]), np.zeros(3))
    with pytest.raises(InputError, match="NaN"):
        transform_line(line, np.diag([np.nan, 1e-6, 1e-4]), np.zeros(3))
    with pytest.raises(InputError, match="shape"):
        transform_line(line, np.eye(2), np.zeros(3))
    # round-off asymmetry is accepted and removed
    P = np.diag([1e-4, 1e-5, 1e-3])
    P[0, 1] = 1e-6
    P[1, 0] = 1e-6 * (1 + 1e-12)
    _, cov = transform_line(line, P, np.array([1.0, 2.0, 0.3]), np.diag([1e-3, 1e-3, 1e-4]))
    np.testing.assert_array_equal(cov, cov.T)
