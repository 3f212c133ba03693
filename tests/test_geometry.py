"""SE(2) helpers and the line transforms (Eq. 30) against GTSAM and numerical derivatives."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from slam.geometry import (
    line_residual,
    line_to_child,
    line_to_parent,
    pose_between,
    pose_compose,
    pose_exp,
    pose_inverse,
    pose_log,
    pose_retract,
    predict_line_measurement,
)


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(-20, 20, (n, 2)), rng.uniform(-np.pi, np.pi, n)])


def random_lines(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack(
        [rng.uniform(0, 15, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(-5, 5, n)]
    )


def numeric_jacobian(f, x0: np.ndarray, plus, dim: int, eps: float = 1e-6) -> np.ndarray:
    """Central differences of f at x0 along ``plus(x0, δ)`` in a ``dim``-dim tangent space."""
    cols = []
    for k in range(dim):
        d = np.zeros(dim)
        d[k] = eps
        fp, fm = f(plus(x0, d)), f(plus(x0, -d))
        diff = fp - fm
        diff[..., 1] = np.arctan2(np.sin(diff[..., 1]), np.cos(diff[..., 1]))
        cols.append(diff / (2 * eps))
    return np.stack(cols, -1)


def test_pose_ops_match_gtsam(rng):
    a, b = random_poses(rng, 50), random_poses(rng, 50)
    for pa, pb, c, d, inv in zip(
        a, b, pose_compose(a, b), pose_between(a, b), pose_inverse(a), strict=True
    ):
        ga, gb = gtsam.Pose2(*pa), gtsam.Pose2(*pb)
        np.testing.assert_allclose(
            c,
            (ga * gb).vector()
            if hasattr(ga, "vector")
            else [(ga * gb).x(), (ga * gb).y(), (ga * gb).theta()],
            atol=1e-9,
        )
        gbt = ga.between(gb)
        np.testing.assert_allclose(d, [gbt.x(), gbt.y(), gbt.theta()], atol=1e-9)
        gi = ga.inverse()
        np.testing.assert_allclose(inv, [gi.x(), gi.y(), gi.theta()], atol=1e-9)


def test_exp_log_match_gtsam_and_round_trip(rng):
    xi = np.column_stack([rng.normal(0, 2, (40, 2)), rng.uniform(-3, 3, 40)])
    xi[0] = [1.0, -2.0, 0.0]
    xi[1] = [0.3, 0.1, 1e-12]
    poses = pose_exp(xi)
    for v, p in zip(xi, poses, strict=True):
        g = gtsam.Pose2.Expmap(v)
        np.testing.assert_allclose(p, [g.x(), g.y(), g.theta()], atol=1e-9)
    np.testing.assert_allclose(pose_log(poses), xi, atol=1e-9)
    base = random_poses(rng, 40)
    small = xi * 1e-2
    for b, v, r in zip(base, small, pose_retract(base, small), strict=True):
        g = gtsam.Pose2(*b).retract(v)
        np.testing.assert_allclose(r, [g.x(), g.y(), g.theta()], atol=1e-9)


@pytest.mark.parametrize("normal_form", [False, True])
def test_line_to_parent_jacobians(rng, normal_form):
    lines = random_lines(rng, 200)
    poses = random_poses(rng, 200)
    # include the awkward cases: r ≈ 0, α ≈ ±π, γ ≈ π
    lines[0] = [1e-9, np.pi - 1e-9, 0.3]
    lines[1] = [2.0, -np.pi + 1e-9, -1.0]
    poses[2, 2] = np.pi - 1e-9
    out, B, K = line_to_parent(lines, poses, normal_form=normal_form)
    for n in range(200):
        f_line = lambda L, n=n: line_to_parent(L, poses[n], normal_form=normal_form)[0]  # noqa: E731
        f_pose = lambda P, n=n: line_to_parent(lines[n], P, normal_form=normal_form)[0]  # noqa: E731
        if normal_form and abs(out[n, 0]) < 1e-5:
            continue  # the normal form is not differentiable on r = 0 itself
        B_num = numeric_jacobian(f_line, lines[n], lambda x, d: x + d, 3)
        K_num = numeric_jacobian(f_pose, poses[n], pose_retract, 3)
        np.testing.assert_allclose(B[n], B_num, atol=1e-6)
        np.testing.assert_allclose(K[n], K_num, atol=1e-6)


def test_line_round_trip_and_point_consistency(rng):
    lines = random_lines(rng, 100)
    poses = random_poses(rng, 100)
    back, _, _ = line_to_child(line_to_parent(lines, poses)[0], poses)
    # same line in normal form (inputs already have r >= 0)
    lines_nf = lines.copy()
    lines_nf[:, 1] = np.arctan2(np.sin(lines[:, 1]), np.cos(lines[:, 1]))
    np.testing.assert_allclose(back, lines_nf, atol=1e-9)
    # a point on the line in frame j, moved to frame i, lies on the transformed line at s_i
    out = line_to_parent(lines, poses)[0]
    n_j = np.column_stack([np.cos(lines[:, 1]), np.sin(lines[:, 1])])
    t_j = np.column_stack([-np.sin(lines[:, 1]), np.cos(lines[:, 1])])
    p_j = lines[:, :1] * n_j + lines[:, 2:3] * t_j
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    p_i = np.column_stack([c * p_j[:, 0] - s * p_j[:, 1], s * p_j[:, 0] + c * p_j[:, 1]])
    p_i += poses[:, :2]
    n_i = np.column_stack([np.cos(out[:, 1]), np.sin(out[:, 1])])
    t_i = np.column_stack([-np.sin(out[:, 1]), np.cos(out[:, 1])])
    np.testing.assert_allclose(np.sum(p_i * n_i, 1), out[:, 0], atol=1e-9)
    np.testing.assert_allclose(np.sum(p_i * t_i, 1), out[:, 2], atol=1e-9)


def test_line_to_child_jacobians(rng):
    lines = random_lines(rng, 100)
    poses = random_poses(rng, 100)
    _, J_line, J_pose = line_to_child(lines, poses, normal_form=False)
    for n in range(100):
        J_line_num = numeric_jacobian(
            lambda L, n=n: line_to_child(L, poses[n], normal_form=False)[0],
            lines[n],
            lambda x, d: x + d,
            3,
        )
        J_pose_num = numeric_jacobian(
            lambda P, n=n: line_to_child(lines[n], P, normal_form=False)[0],
            poses[n],
            pose_retract,
            3,
        )
        np.testing.assert_allclose(J_line[n], J_line_num, atol=1e-6)
        np.testing.assert_allclose(J_pose[n], J_pose_num, atol=1e-6)


def test_measurement_model_jacobians_and_residual(rng):
    lm = np.column_stack([rng.uniform(-10, 10, 100), rng.uniform(-np.pi, np.pi, 100)])
    lm[0] = [0.0, np.pi]  # a world line through the origin, at α = π
    lm[1] = [1e-12, -np.pi + 1e-12]
    poses = random_poses(rng, 100)
    z, H_pose, H_lm = predict_line_measurement(lm, poses)
    for n in range(100):
        Hp = numeric_jacobian(
            lambda P, n=n: predict_line_measurement(lm[n], P)[0], poses[n], pose_retract, 3
        )
        Hl = numeric_jacobian(
            lambda L, n=n: predict_line_measurement(L, poses[n])[0], lm[n], lambda x, d: x + d, 2
        )
        np.testing.assert_allclose(H_pose[n], Hp, atol=1e-6)
        np.testing.assert_allclose(H_lm[n], Hl, atol=1e-6)
    # the residual against the flipped representative of the same line is zero
    z_flipped = np.column_stack([-z[:, 0], z[:, 1] + np.pi])
    res, sign = line_residual(z, z_flipped)
    np.testing.assert_allclose(res, 0.0, atol=1e-9)
    assert np.all(sign == -1.0)
    res2, sign2 = line_residual(z, z + [0.01, 0.02])
    np.testing.assert_allclose(res2, np.tile([-0.01, -0.02], (100, 1)), atol=1e-9)
    assert np.all(sign2 == 1.0)


def test_single_pose_fast_path_equals_the_batch_path():
    """One pose goes through plain floats; the result equals the vectorised path's (rounding)."""
    rng = np.random.default_rng(12)
    for k in range(500):
        a = rng.normal(size=3) * [5.0, 5.0, 3.0]
        b = rng.normal(size=3) * [5.0, 5.0, 3.0]
        if k % 3 == 0:  # the small-angle branches of Exp / Log
            a[2], b[2] = rng.normal() * 1e-10, rng.normal() * 1e-12
        for f, args in [
            (pose_compose, (a, b)),
            (pose_between, (a, b)),
            (pose_retract, (a, b)),
            (pose_inverse, (a,)),
            (pose_exp, (a,)),
            (pose_log, (a,)),
        ]:
            one = f(*args)
            many = f(*[x[None, :] for x in args])[0]
            assert one.shape == (3,)
            np.testing.assert_allclose(one[:2], many[:2], rtol=0, atol=1e-12)
            assert abs(np.angle(np.exp(1j * (one[2] - many[2])))) < 1e-14
