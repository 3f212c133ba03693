"""χ² merge test, ML fusion and segment union: known answers, Monte Carlo, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slam.errors import ConfigError, DegenerateGeometryError, InputError
from slam.geometry import wrap_angle
from slam.lines import (
    align_representative,
    chi2_gate,
    chi2_ppf,
    extent_gap,
    fuse,
    fuse_many,
    fuse_pair_unchecked,
    is_compatible,
    mahalanobis2,
    unite_segments,
)


def spd(rng: np.random.Generator, n: int, d: int, scale: np.ndarray) -> np.ndarray:
    A = rng.normal(size=(n, d, d)) * scale[None, :, None]
    return A @ np.swapaxes(A, -1, -2) + np.diag(scale**2) * 0.1


def test_gate_is_the_papers_three_sigma():
    assert chi2_gate() == pytest.approx(11.829, abs=1e-3)
    assert chi2_gate(0.95, 2) == pytest.approx(5.991, abs=1e-3)
    for p, k in ((0.9973, 1), (0.99, 3), (0.5, 5)):
        assert chi2_gate(p, k) == pytest.approx(chi2.ppf(p, k), rel=1e-10)
    with pytest.raises(ConfigError):
        chi2_gate(1.0)


def test_chi2_ppf_equals_scipy_stats_bit_for_bit():
    for k in (1, 2, 3, 5, np.int64(2)):
        for p in (1e-9, 0.01, 0.5, 0.6827, 0.9, 0.95, 0.99, 0.9973, 0.999, 1 - 1e-9):
            assert chi2_ppf(p, k) == float(chi2.ppf(p, k))
    assert chi2_ppf(0.0, 2) == 0.0 and chi2_ppf(1.0, 2) == np.inf
    assert np.isnan(chi2_ppf(1.5, 2)) and np.isnan(chi2_ppf(0.5, 0))


def test_mahalanobis_vectorised_matches_pairwise_and_is_representative_invariant(rng):
    n, m = 7, 9
    l1 = np.column_stack([rng.uniform(0, 5, n), rng.uniform(-np.pi, np.pi, n)])
    l2 = np.column_stack([rng.uniform(0, 5, m), rng.uniform(-np.pi, np.pi, m)])
    P1, P2 = spd(rng, n, 2, np.array([0.1, 0.05])), spd(rng, m, 2, np.array([0.1, 0.05]))
    D = mahalanobis2(l1[:, None], P1[:, None], l2[None], P2[None])
    assert D.shape == (n, m)
    for i in range(n):
        for j in range(m):
            l2a, P2a, _ = align_representative(l2[j], P2[j], l1[i, 1])
            d = np.array([l1[i, 0] - l2a[0], wrap_angle(l1[i, 1] - l2a[1])])
            assert D[i, j] == pytest.approx(d @ np.linalg.solve(P1[i] + P2a, d), rel=1e-10)
    # the other representative of every l2 gives the same distances
    other = np.column_stack([-l2[:, 0], wrap_angle(l2[:, 1] + np.pi)])
    flipP2 = P2 * np.array([[1, -1], [-1, 1]])
    D2 = mahalanobis2(l1[:, None], P1[:, None], other[None], flipP2[None])
    np.testing.assert_allclose(D, D2, rtol=1e-10)
    np.testing.assert_array_equal(
        is_compatible(l1[:, None], P1[:, None], l2[None], P2[None]), chi2_gate() >= D
    )


def test_alpha_near_pi_and_r_near_zero_are_compatible():
    P = np.diag([1e-4, 1e-5])
    # α just below π and just above −π: the same line
    assert mahalanobis2([3.0, np.pi - 1e-3], P, [3.0, -np.pi + 1e-3], P) == pytest.approx(
        (2e-3) ** 2 / 2e-5
    )
    # a line through the origin seen with opposite normals (r ≈ 0 flips sign)
    d2 = mahalanobis2([0.002, 0.3], P, [0.001, 0.3 - np.pi], P)
    assert d2 == pytest.approx((0.003) ** 2 / 2e-4, rel=1e-9)
    # same_side refuses opposite normals, accepts aligned ones
    assert np.isinf(mahalanobis2([0.002, 0.3], P, [0.001, 0.3 - np.pi], P, same_side=True))
    assert mahalanobis2([3.0, 0.3], P, [3.0, 0.3], P, same_side=True) == 0.0


def test_fusion_monte_carlo_nees_and_covariance(rng):
    truth = np.array([2.5, -2.8, 0.4])
    P1 = np.array([[4e-4, 1e-4, 2e-4], [1e-4, 1e-4, 5e-5], [2e-4, 5e-5, 1e-2]])
    P2 = np.array([[1e-4, -3e-5, 0.0], [-3e-5, 4e-4, -1e-4], [0.0, -1e-4, 4e-2]])
    m = 20_000
    e1 = rng.normal(size=(m, 3)) @ np.linalg.cholesky(P1).T
    e2 = rng.normal(size=(m, 3)) @ np.linalg.cholesky(P2).T
    l1 = truth + e1
    l2 = truth + e2
    l2[::2] = np.column_stack([-l2[::2, 0], wrap_angle(l2[::2, 1] + np.pi), -l2[::2, 2]])
    P2s = np.broadcast_to(P2, (m, 3, 3)).copy()
    P2s[::2] *= np.outer([-1, 1, -1], [-1, 1, -1])
    lm, Pm = fuse(l1, np.broadcast_to(P1, (m, 3, 3)), l2, P2s)
    err = lm[:, :2] - truth[:2]
    err[:, 1] = wrap_angle(err[:, 1])
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(Pm[:, :2, :2]), err)
    # mean NEES of a 2-dof consistent estimator: 2 ± 3·sqrt(4/m)
    assert abs(nees.mean() - 2.0) < 3 * np.sqrt(4.0 / m)
    np.testing.assert_allclose(np.cov(err.T), Pm[0, :2, :2], rtol=0.05)
    np.testing.assert_allclose(
        Pm[0, :2, :2], np.linalg.inv(np.linalg.inv(P1[:2, :2]) + np.linalg.inv(P2[:2, :2]))
    )
    # s: the 1/P_ss weighted mean, variance 1/(1/P1ss + 1/P2ss) to first order
    w1 = P2[2, 2] / (P1[2, 2] + P2[2, 2])
    np.testing.assert_allclose(np.mean(lm[:, 2]), truth[2], atol=4 * np.sqrt(Pm[0, 2, 2] / m))
    np.testing.assert_allclose(
        np.var(lm[:, 2]), w1**2 * P1[2, 2] + (1 - w1) ** 2 * P2[2, 2], rtol=0.05
    )
    np.testing.assert_allclose(np.var(lm[:, 2]), np.median(Pm[:, 2, 2]), rtol=0.05)
    cross = np.mean((lm[:, 2] - lm[:, 2].mean())[:, None] * err, axis=0)
    np.testing.assert_allclose(cross, Pm[0, 2, :2], atol=0.05 * np.sqrt(Pm[0, 2, 2] * 1e-4))


def test_fusion_commutes_and_identical_lines(rng):
    l1, l2 = np.array([1.0, 3.1, -0.5]), np.array([1.02, -3.12, 2.0])
    P1 = spd(rng, 1, 3, np.array([0.05, 0.02, 0.3]))[0]
    P2 = spd(rng, 1, 3, np.array([0.03, 0.03, 0.5]))[0]
    a, Pa = fuse(l1, P1, l2, P2)
    b, Pb = fuse(l2, P2, l1, P1)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(Pa, Pb, atol=1e-12)
    assert a[0] >= 0 and -np.pi < a[1] <= np.pi
    c, Pc = fuse(l1, P1, l1, P1)
    np.testing.assert_allclose(c, l1, atol=1e-12)
    np.testing.assert_allclose(Pc[:2, :2], P1[:2, :2] / 2, atol=1e-15)
    assert mahalanobis2(l1, P1, l1, P1) == 0.0
    # many: order does not matter
    ls = np.array([l1, l2, [0.99, 3.13, 0.0]])
    Ps = np.stack([P1, P2, P1 * 2])
    f1, F1 = fuse_many(ls, Ps)
    f2, F2 = fuse_many(ls[::-1], Ps[::-1])
    np.testing.assert_allclose(f1[:2], f2[:2], atol=1e-12)
    np.testing.assert_allclose(F1[:2, :2], F2[:2, :2], atol=1e-15)


def test_fused_s_is_the_weighted_centroid_of_collinear_pieces():
    # wall x = 2 (α = 0): piece A around s = −3, piece B around s = +1, B twice as precise
    PA = np.diag([1e-4, 1e-5, 2e-3])
    PB = np.diag([1e-4, 1e-5, 1e-3])
    lm, Pm = fuse([2.0, 0.0, -3.0], PA, [2.0, 0.0, 1.0], PB)
    assert lm[2] == pytest.approx((-3.0 / 2e-3 + 1.0 / 1e-3) / (1 / 2e-3 + 1 / 1e-3))
    # 1/(1/P_A + 1/P_B), plus the rotation of the centroids about the fused foot point:
    # ∂s/∂α_k = w_k·r − r·∂α_m/∂α_k = r·(w_k − 1/2) with equal α variances
    rot = 2.0**2 * ((1 / 3 - 0.5) ** 2 + (2 / 3 - 0.5) ** 2) * 1e-5
    assert Pm[2, 2] == pytest.approx(1 / (1 / 2e-3 + 1 / 1e-3) + rot, rel=1e-9)


def test_singular_and_malformed_covariances():
    l = np.array([1.0, 0.5, 0.0])
    P = np.diag([1e-4, 1e-5, 1e-3])
    exact = np.zeros((3, 3))
    # a line known exactly wins the fusion
    lm, Pm = fuse(l, exact, l + [0.01, 0.002, 0.3], P)
    np.testing.assert_allclose(lm[:2], l[:2], atol=1e-15)
    np.testing.assert_allclose(Pm[:2, :2], 0.0, atol=1e-20)
    with pytest.raises(DegenerateGeometryError, match="singular"):
        fuse(l, exact, l, exact)
    with pytest.raises(DegenerateGeometryError, match="singular"):
        mahalanobis2(l, np.diag([1e-4, 0, 0]), l, np.diag([1e-4, 0, 0]))
    bad = P.copy()
    bad[0, 1] = 1e-5
    with pytest.raises(DegenerateGeometryError, match="not symmetric"):
        fuse(l, bad, l, P)
    with pytest.raises(DegenerateGeometryError, match="not symmetric"):
        mahalanobis2(l, bad, l, P)
    with pytest.raises(InputError, match="NaN"):
        fuse(l, P, [np.nan, 0.1, 0.0], P)
    with pytest.raises(InputError):
        fuse(l, P, l[:2], P[:2, :2])


def test_extent_gap_and_unite_segments_known_answers():
    assert extent_gap([0, 2], [3, 5]) == 1.0
    assert extent_gap([0, 4], [3, 5]) == -1.0
    seg = np.array([[3.0, 5.0], [0.0, 2.0], [1.5, 2.5], [7.0, 8.0]])
    var = np.array([[0.3, 0.5], [0.0, 0.2], [0.15, 0.25], [0.7, 0.8]])
    s, v = unite_segments(seg, var)
    np.testing.assert_array_equal(s, [[0, 2.5], [3, 5], [7, 8]])
    np.testing.assert_array_equal(v, [[0, 0.25], [0.3, 0.5], [0.7, 0.8]])
    s, v = unite_segments(seg, var, gap_tolerance_m=0.6)
    np.testing.assert_array_equal(s, [[0, 5], [7, 8]])
    np.testing.assert_array_equal(v, [[0, 0.5], [0.7, 0.8]])
    s, v = unite_segments(seg, var, gap_tolerance_m=10)
    np.testing.assert_array_equal(s, [[0, 8]])
    np.testing.assert_array_equal(v, [[0, 0.8]])
    # a contained segment does not move the ends
    s, v = unite_segments(np.array([[0.0, 10.0], [2.0, 3.0]]), np.array([[1, 2], [3, 4.0]]))
    np.testing.assert_array_equal(s, [[0, 10]])
    np.testing.assert_array_equal(v, [[1, 2]])


def test_chi2_gate_false_alarm_rate(rng):
    """Two independent estimates of one line pass the 3σ gate 99.73 % of the time."""
    truth = np.array([4.0, 1.0])
    P1, P2 = np.array([[2e-4, 5e-5], [5e-5, 1e-4]]), np.array([[1e-4, 0], [0, 3e-4]])
    m = 50_000
    l1 = truth + rng.normal(size=(m, 2)) @ np.linalg.cholesky(P1).T
    l2 = truth + rng.normal(size=(m, 2)) @ np.linalg.cholesky(P2).T
    rate = is_compatible(l1, P1, l2, P2).mean()
    p = 0.9973
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / m)
    d2 = mahalanobis2(l1, P1, l2, P2)
    assert abs(np.mean(d2 <= chi2.ppf(0.5, 2)) - 0.5) < 0.01


def test_fast_pair_fusion_equals_vectorised_fusion(rng):
    n = 300
    l1 = np.column_stack(
        [rng.uniform(-3, 3, n), rng.uniform(-np.pi, np.pi, n), rng.normal(0, 2, n)]
    )
    l2 = l1 + rng.normal(0, [0.05, 0.02, 1.0], (n, 3))
    l2[::3] = np.column_stack([-l2[::3, 0], wrap_angle(l2[::3, 1] + np.pi), -l2[::3, 2]])
    l1[:5, 1] = np.pi - 1e-4  # near the ±π seam
    P1 = spd(rng, n, 3, np.array([0.02, 0.01, 0.3]))
    P2 = spd(rng, n, 3, np.array([0.03, 0.02, 0.5]))
    P2[::7, 2, 2] = 0.0
    P2[::7, 2, :2] = P2[::7, :2, 2] = 0.0
    ref, Pref = fuse(l1, P1, l2, P2, normal_form=False)
    for k in range(n):
        x, P = fuse_pair_unchecked(l1[k], P1[k], l2[k], P2[k])
        d = x - ref[k]
        d[1] = wrap_angle(d[1])
        np.testing.assert_allclose(d, 0.0, atol=1e-12)
        np.testing.assert_allclose(P, Pref[k], rtol=1e-9, atol=1e-15)
    with pytest.raises(DegenerateGeometryError):
        fuse_pair_unchecked(l1[0], np.zeros((3, 3)), l1[0], np.zeros((3, 3)))
