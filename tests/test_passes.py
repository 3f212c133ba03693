"""Between-pass consistency of walls (slam.evaluation.passes): known answers on built graphs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam.errors import EvaluationError
from slam.evaluation.passes import pass_consistency
from slam.geometry import predict_line_measurement, wrap_angle
from slam.graph.problem import LineGraph
from slam.models.anchored import r_alpha_from_anchored

R = np.diag([0.01**2, 0.005**2])  # each factor's (r, α) covariance
VIEWS = 6  # observations per pass
PASS_GAP_S = 100.0


def _views(rng: np.random.Generator) -> np.ndarray:
    return np.column_stack([rng.uniform(-1.0, 1.0, (VIEWS, 2)), rng.uniform(-np.pi, np.pi, VIEWS)])


def _pass_covariance(v: np.ndarray, c: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """``(Σ Jᵀ R⁻¹ J)⁻¹`` with ``J = ∂z/∂(ρ, φ)`` by central differences (independent of the
    module's linearisation)."""
    info = np.zeros((2, 2))
    for pose in poses:
        J = np.zeros((2, 2))
        for k in range(2):
            h = np.zeros(2)
            h[k] = 1e-6
            zp = predict_line_measurement(r_alpha_from_anchored(v + h, c), pose)[0]
            zm = predict_line_measurement(r_alpha_from_anchored(v - h, c), pose)[0]
            J[:, k] = [(zp[0] - zm[0]) / 2e-6, wrap_angle(zp[1] - zm[1]) / 2e-6]
        info += J.T @ np.linalg.inv(R) @ J
    return np.linalg.inv(info)


def _graph(seed: int, pass_scale: float, n_landmarks: int = 300, passes: int = 2):
    """Walls each seen in ``passes`` passes of the same ``VIEWS`` poses (exact, at the truth),
    every measurement with noise ``N(0, R)``; each pass also sees its wall moved by ``δ ~ N(0,
    pass_scale · C_p)`` in the landmark's chart (``C_p`` the pass's own covariance): the
    median of ``t`` is then ``(1 + pass_scale)`` times χ²₂'s."""
    rng = np.random.default_rng(seed)
    g = LineGraph()
    stamps = []
    for j in range(n_landmarks):
        alpha = rng.uniform(-np.pi, np.pi)
        r = rng.uniform(2.0, 5.0)
        n = np.array([math.cos(alpha), math.sin(alpha)])
        c = r * n + rng.uniform(-2.0, 2.0) * np.array([-n[1], n[0]])
        lm = g.add_landmarks(np.array([[r, alpha]]), c[None])
        v = np.array([0.0, alpha])  # the landmark's anchored (ρ, φ): the anchor lies on it
        poses = _views(rng)
        C_p = _pass_covariance(v, c, poses)
        for s in range(passes):
            delta = rng.multivariate_normal(np.zeros(2), pass_scale * C_p) if pass_scale else 0.0
            seen = r_alpha_from_anchored(v + delta, c)
            for i, pose in enumerate(poses):
                p = g.add_pose(pose)
                stamps.append(1000.0 * j + PASS_GAP_S * s + i)
                z = predict_line_measurement(seen, pose)[0] + rng.multivariate_normal(
                    np.zeros(2), R
                )
                g.add_line_factors(p, lm, z[None], R[None], np.zeros((1, 2, 2)))
    return g, np.array(stamps)


@pytest.mark.parametrize(("pass_scale", "ratio"), [(0.0, 1.0), (1.0, 2.0), (3.0, 4.0)])
def test_the_median_ratio_is_the_passes_excess_variance(pass_scale, ratio):
    g, stamps = _graph(5, pass_scale)
    res = pass_consistency(g, stamps, gap_s=30.0)
    assert res.landmarks == 300 and res.pairs == 300
    # the sample median of 300 χ²₂ values: relative standard deviation about 8 %
    assert res.median_ratio == pytest.approx(ratio, rel=0.25)
    assert res.median_ratio_angle == pytest.approx(ratio, rel=0.3)
    if pass_scale == 0.0:
        assert 0.02 < res.fraction_beyond_95 < 0.09


def test_passes_are_split_by_the_time_gap():
    g, stamps = _graph(6, 0.0, n_landmarks=40, passes=3)
    # three passes per landmark: three pairs each
    assert pass_consistency(g, stamps, gap_s=30.0).pairs == 40 * 3
    # a gap longer than the passes' separation: one pass, nothing to compare
    one = pass_consistency(g, stamps, gap_s=PASS_GAP_S + 10.0)
    assert one.pairs == 0 and one.landmarks == 0 and math.isnan(one.median_ratio)
    # passes of fewer observations than asked for are left out
    assert pass_consistency(g, stamps, gap_s=30.0, min_observations=VIEWS + 1).pairs == 0


def test_a_robust_kernel_weighs_down_a_wrong_pass_factor():
    g, stamps = _graph(7, 0.0, n_landmarks=200)
    plain = pass_consistency(g, stamps)
    # one factor of every landmark's first pass 20 cm off: the Gaussian t blows up, Cauchy's
    # weights (width 1 in whitened units) leave the median near its value
    z = g.factor_z
    z[:: 2 * VIEWS, 0] += 0.2
    assert pass_consistency(g, stamps).median_ratio > 5.0 * plain.median_ratio
    robust = pass_consistency(g, stamps, ("cauchy", 1.0))
    assert robust.median_ratio < 2.0 * plain.median_ratio


def test_bad_arguments_are_named():
    g, stamps = _graph(8, 0.0, n_landmarks=2)
    with pytest.raises(EvaluationError, match="gap_s"):
        pass_consistency(g, stamps, gap_s=0.0)
    with pytest.raises(EvaluationError, match="time stamps"):
        pass_consistency(g, stamps[:-1])
