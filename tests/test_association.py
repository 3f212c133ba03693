"""Data association: χ² gate with the right innovation covariance, NN, JCBB, overlap, fusion."""

from __future__ import annotations

import numpy as np
import pytest

from slam.association import (
    AssociationConfig,
    associate,
    build_problem,
    candidate_landmarks,
    individual_gate,
    jcbb,
    landmarks_compatible,
    nearest_compatible,
    nearest_neighbour,
    segment_extents,
    segment_gaps,
)
from slam.errors import ConfigError
from slam.geometry import line_residual, pose_retract, predict_line_measurement


def scene(rng, n_lm=6, sigma=0.02):
    """A pose, landmarks around it and their exact measurements (laser frame)."""
    pose = np.array([1.0, -2.0, 0.4])
    alpha = np.linspace(-np.pi, np.pi, n_lm, endpoint=False) + 0.1
    lm = np.column_stack(
        [pose[0] * np.cos(alpha) + pose[1] * np.sin(alpha) + rng.uniform(2, 5, n_lm), alpha]
    )
    z, _, _ = predict_line_measurement(lm, pose)
    ext = np.tile([-3.0, 3.0], (n_lm, 1))
    # segment end points in the laser frame: the foot of the normal ± 1 m
    n = np.column_stack([np.cos(z[:, 1]), np.sin(z[:, 1])])
    t = np.column_stack([-n[:, 1], n[:, 0]])
    foot = z[:, :1] * n
    # extents measured from the world foot point of each landmark
    ep = np.stack([foot - t, foot + t], 1)
    R = np.tile(np.diag([sigma**2, (sigma / 4) ** 2]), (n_lm, 1, 1))
    return pose, lm, z, ep, ext, R


def test_innovation_covariance_is_consistent_monte_carlo(rng):
    """Sample pose and landmark errors from P, measurement noise from R: the D² of the true
    pairings averages 2 and its spread matches χ²₂ (so the gate has its nominal size)."""
    pose, lm, _, ep, ext, R = scene(rng, n_lm=3)
    C = lm.shape[0]
    A = rng.normal(size=(3 + 2 * C, 3 + 2 * C)) * 0.01
    P = A @ A.T + np.diag([1e-4, 1e-4, 1e-5] + [1e-5] * (2 * C))
    trials = 3000
    d2 = np.empty((trials, C))
    cfg = AssociationConfig(overlap_margin_m=100.0)
    for k in range(trials):
        e = rng.multivariate_normal(np.zeros(3 + 2 * C), P)
        true_pose = pose_retract(pose, e[:3])
        true_lm = lm + e[3:].reshape(C, 2)
        z, _, _ = predict_line_measurement(true_lm, true_pose)
        z = z + np.einsum("kij,kj->ki", np.linalg.cholesky(R), rng.standard_normal((C, 2)))
        prob = build_problem(z, R, ep, pose, P, lm, ext, cfg)
        d2[k] = np.diagonal(prob.individual_d2())
    assert d2.mean() == pytest.approx(2.0, rel=0.08)
    assert np.mean(d2 > 13.8155) < 0.004  # χ²₂(0.999)
    # ignoring the cross-covariances makes D² wrong (here: too large or too small on average)
    cfg_blk = AssociationConfig(overlap_margin_m=100.0, cross_covariances=False)
    prob_blk = build_problem(z, R, ep, pose, P, lm, ext, cfg_blk)
    assert not np.allclose(prob_blk.innovation_covariances(), prob.innovation_covariances())


def test_nn_and_jcbb_find_the_true_pairing(rng):
    pose, lm, z, ep, ext, R = scene(rng)
    P = np.diag([1e-3, 1e-3, 1e-4] + [1e-5] * 12)
    zn = z + rng.normal(0, [0.01, 0.003], z.shape)
    perm = rng.permutation(6)
    prob = build_problem(zn[perm], R[perm], ep[perm], pose, P, lm, ext, AssociationConfig())
    for method in ("nn", "jcbb"):
        res = associate(prob, AssociationConfig(method=method))
        np.testing.assert_array_equal(res.assignment, perm)
        assert res.complete


def test_jcbb_rejects_a_jointly_incompatible_pairing():
    """Two parallel walls 0.5 m apart, two measurements, a large pose uncertainty across the walls:
    each measurement is individually compatible with both walls, but only the consistent pairing
    is jointly compatible (the pose error is common to both)."""
    pose = np.array([0.0, 0.0, 0.0])
    lm = np.array([[2.0, 0.0], [2.5, 0.0], [1.0, np.pi / 2]])  # walls x = 2, x = 2.5, y = 1
    z_true, _, _ = predict_line_measurement(lm, pose)
    # the robot is really at x = +0.25: both x-walls appear 0.25 closer
    z = z_true.copy()
    z[0, 0] -= 0.25
    z[1, 0] -= 0.25
    R = np.tile(np.diag([1e-4, 1e-6]), (3, 1, 1))
    P = np.zeros((9, 9))
    P[:3, :3] = np.diag([0.3**2, 1e-6, 1e-8])
    P[3:, 3:] = 1e-8 * np.eye(6)
    ep = np.array([[[z[k, 0] * np.cos(z[k, 1]), 0], [0, 0]] for k in range(3)], dtype=float)
    ep[:, 1] = ep[:, 0] + [[0, 1], [0, 1], [1, 0]]
    prob = build_problem(z, R, ep, pose, P, lm, np.tile([-50.0, 50.0], (3, 1)), AssociationConfig())
    d2 = prob.individual_d2()
    assert d2[0, 1] < 13.8 and d2[0, 0] < 13.8  # ambiguous individually
    assignment, complete = jcbb(prob, 0.999, 0.999)
    assert complete
    np.testing.assert_array_equal(assignment, [0, 1, 2])
    # a hypothesis that swaps the two walls is jointly incompatible
    assert prob.joint_d2([(0, 1), (1, 0)]) > prob.joint_d2([(0, 0), (1, 1)]) + 10


def test_overlap_gate_keeps_collinear_walls_of_other_rooms_out(rng):
    pose, lm, z, ep, ext, R = scene(rng, n_lm=2)
    P = np.diag([1e-4, 1e-4, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6])
    ext_far = ext + 20.0  # same infinite lines, 20 m further along
    prob = build_problem(z, R, ep, pose, P, lm, ext_far, AssociationConfig())
    assert not prob.allowed.any()
    assert np.all(np.isinf(prob.individual_d2()))
    assert np.all(nearest_neighbour(prob, 0.999) == -1)
    # segment_gaps: overlapping intervals have negative gap, disjoint ones their distance
    ep_w = np.array([[[0.0, 1.0], [0.0, 3.0]]])
    lm_x = np.array([[0.0, 0.0]])  # the y axis; tangent (0, 1)
    assert segment_gaps(ep_w, lm_x, np.array([[2.0, 5.0]]))[0, 0] == pytest.approx(-1.0)
    assert segment_gaps(ep_w, lm_x, np.array([[4.5, 5.0]]))[0, 0] == pytest.approx(1.5)
    # anchors shift the origin of the extents
    gap = segment_gaps(ep_w, lm_x, np.array([[1.5, 2.0]]), anchors=np.array([[0.0, 3.0]]))
    assert gap[0, 0] == pytest.approx(max(1.0, 4.5) - min(3.0, 5.0))


def test_candidates_by_distance_and_limit():
    lm = np.array([[1.0, 0.0], [10.0, 0.0], [50.0, 0.0], [2.0, np.pi / 2]])
    ext = np.array([[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], [np.nan, np.nan]])
    pose = np.array([0.0, 0.0, 0.0])
    np.testing.assert_array_equal(candidate_landmarks(pose, lm, ext, 20.0), [0, 1])
    alive = np.array([False, True, True, True])
    np.testing.assert_array_equal(candidate_landmarks(pose, lm, ext, 100.0, alive), [1, 2])
    np.testing.assert_array_equal(candidate_landmarks(pose, lm, ext, 100.0, max_candidates=1), [0])


def test_landmarks_compatible_uses_the_joint_marginal():
    """Two estimates of one wall made from the same poses are strongly correlated: their
    difference is small compared with their marginals.  With the correlation the test is right;
    treating them as independent would wave through a real 6 cm offset."""
    l1 = np.array([3.0, 0.5])
    l2 = np.array([3.06, 0.5])
    sig = np.diag([0.05**2, 0.01**2])
    P_corr = np.block([[sig, 0.99 * sig], [0.99 * sig, sig]])
    P_indep = np.block([[sig, np.zeros((2, 2))], [np.zeros((2, 2)), sig]])
    ok_corr, d2_corr = landmarks_compatible(l1, l2, P_corr, 0.9973)
    ok_ind, _ = landmarks_compatible(l1, l2, P_indep, 0.9973)
    assert not ok_corr and ok_ind
    assert d2_corr == pytest.approx(0.06**2 / (2 * 0.01 * 0.05**2), rel=1e-6)
    # the other representative of the same line is the same line
    ok, d2 = landmarks_compatible(l1, np.array([-3.0, 0.5 + np.pi]), P_indep, 0.9973)
    assert ok and d2 == pytest.approx(0.0, abs=1e-12)


def test_residual_sign_convention_of_the_problem(rng):
    pose, lm, z, ep, ext, R = scene(rng, n_lm=2)
    P = np.eye(7) * 1e-6
    prob = build_problem(z + [0.01, 0.0], R, ep, pose, P, lm, ext, AssociationConfig())
    zp, _, _ = predict_line_measurement(lm, pose)
    res, _ = line_residual(zp, z + [0.01, 0.0])
    np.testing.assert_allclose(np.diagonal(prob.nu, axis1=0, axis2=1).T, -res, atol=1e-12)


def test_individual_gate_matches_the_problem_and_the_chi2_quantile(rng):
    pose, lm, z, ep, ext, R = scene(rng)
    P = np.diag(rng.uniform(1e-4, 1e-2, 3 + 2 * len(lm)))
    prob = build_problem(z + 0.05, R, ep, pose, P, lm, ext, AssociationConfig())
    S = prob.innovation_covariances()
    d2 = prob.individual_d2()
    gate = -2.0 * np.log(1.0 - 0.9)  # χ²₂(0.9) = 4.605
    gated = individual_gate(prob.nu, S, 0.9, prob.allowed)
    inside = np.isfinite(d2) & (d2 <= gate)
    assert inside.any() and (~inside).any()
    np.testing.assert_array_equal(np.isfinite(gated), inside)
    np.testing.assert_allclose(gated[inside], d2[inside], rtol=1e-12)
    # D² by an explicit inverse; a negative definite S is never compatible
    k, c = np.argwhere(inside)[0]
    nu = prob.nu[k, c]
    assert gated[k, c] == pytest.approx(nu @ np.linalg.solve(S[k, c], nu), rel=1e-12)
    assert np.isinf(individual_gate(nu, -S[k, c], 0.9))


def test_nearest_compatible_lets_a_landmark_serve_several_measurements():
    d2 = np.array([[3.0, 1.0, np.inf], [np.inf, 0.5, 2.0], [np.inf, np.inf, np.inf]])
    np.testing.assert_array_equal(nearest_compatible(d2), [1, 1, -1])
    assert nearest_compatible(np.zeros((2, 0))).tolist() == [-1, -1]


def test_segment_extents_round_trip_through_the_gaps(rng):
    alpha = rng.uniform(-np.pi, np.pi, 5)
    t = np.column_stack([-np.sin(alpha), np.cos(alpha)])
    n = np.column_stack([np.cos(alpha), np.sin(alpha)])
    r = rng.uniform(-3, 3, 5)
    s0, s1 = rng.uniform(-4, 0, 5), rng.uniform(0.5, 4, 5)
    ends = r[:, None, None] * n[:, None] + np.stack([s0, s1], 1)[:, :, None] * t[:, None]
    ext = segment_extents(ends[:, ::-1], np.column_stack([r, alpha]))
    np.testing.assert_allclose(ext, np.column_stack([s0, s1]), atol=1e-12)
    gaps = segment_gaps(ends, np.column_stack([r, alpha]), ext)
    np.testing.assert_allclose(np.diag(gaps), -(s1 - s0), atol=1e-12)  # overlaps itself


def test_config_validation():
    with pytest.raises(ConfigError):
        AssociationConfig(method="greedy")  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        AssociationConfig(gate_probability=1.0)
    with pytest.raises(ConfigError):
        AssociationConfig(max_candidates=0)
