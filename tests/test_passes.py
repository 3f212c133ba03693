"""Between-pass consistency of walls (slam.line_slam.passes): known answers on built graphs."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from slam.errors import DegenerateGeometryError, EvaluationError, InputError, LogFormatError
from slam.geometry import pose_between, predict_line_measurement, wrap_angle
from slam.graph.batch import BatchSolver
from slam.graph.config import SolverConfig
from slam.graph.linear import keys_of
from slam.graph.problem import LineGraph
from slam.graph.relative import RunCovariances, line_graph_from_file
from slam.io.g2o import read_line_graph_g2o, write_line_graph_g2o
from slam.line_slam.line_noise import excess_is_significant
from slam.line_slam.passes import (
    MIN_PAIRS,
    PassError,
    estimate_pass_error,
    find_passes,
    fitted_pairs,
    pass_consistency,
    with_pass_links,
)
from slam.models.anchored import r_alpha_from_anchored
from slam.models.motion import MotionNoiseConfig

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
    res = pass_consistency(g, stamps, gap_s=30.0, fitted=False)
    assert res.landmarks == 300 and res.pairs == 300
    # the sample median of 300 χ²₂ values: relative standard deviation about 8 %
    assert res.median_ratio == pytest.approx(ratio, rel=0.25)
    assert res.median_ratio_angle == pytest.approx(ratio, rel=0.3)
    if pass_scale == 0.0:
        assert 0.02 < res.fraction_beyond_95 < 0.09


def test_passes_are_split_by_the_time_gap():
    g, stamps = _graph(6, 0.0, n_landmarks=40, passes=3)
    # three passes per landmark: three pairs each
    assert pass_consistency(g, stamps, gap_s=30.0, fitted=False).pairs == 40 * 3
    # a gap longer than the passes' separation: one pass, nothing to compare
    one = pass_consistency(g, stamps, gap_s=PASS_GAP_S + 10.0, fitted=False)
    assert one.pairs == 0 and one.landmarks == 0 and math.isnan(one.median_ratio)
    # passes of fewer observations than asked for are left out
    assert pass_consistency(g, stamps, None, 30.0, VIEWS + 1, fitted=False).pairs == 0


def test_a_robust_kernel_weighs_down_a_wrong_pass_factor():
    g, stamps = _graph(7, 0.0, n_landmarks=200)
    plain = pass_consistency(g, stamps, fitted=False)
    # one factor of every landmark's first pass 20 cm off: the Gaussian t blows up, Cauchy's
    # weights (width 1 in whitened units) leave the median near its value
    z = g.factor_z
    z[:: 2 * VIEWS, 0] += 0.2
    assert pass_consistency(g, stamps, fitted=False).median_ratio > 5.0 * plain.median_ratio
    robust = pass_consistency(g, stamps, ("cauchy", 1.0), fitted=False)
    assert robust.median_ratio < 2.0 * plain.median_ratio


def test_bad_arguments_are_named():
    g, stamps = _graph(8, 0.0, n_landmarks=2)
    with pytest.raises(EvaluationError, match="gap_s"):
        pass_consistency(g, stamps, gap_s=0.0)
    with pytest.raises(EvaluationError, match="time stamps"):
        pass_consistency(g, stamps[:-1])


# --------------------------------------------------------------------------------------------
# a solved graph: the fitted covariances, the pass error, the linked graph
# --------------------------------------------------------------------------------------------
LAPS = 4
PER_LAP = 60
WALLS = 24
Q = np.diag([0.01**2, 0.01**2, 0.003**2])  # odometry noise per step


def _laps(seed: int, sigma_o: float, sigma_a: float):
    """A robot circling ``LAPS`` times (radius 4 m, one pose a second) inside ``WALLS`` walls
    tangent to a circle of 7 m; each pose sees the four walls nearest its heading's normal;
    each lap sees every wall moved by its own ``(σ_o along the normal, σ_a about the foot of
    the circle's centre)``.  Returns the graph solved from the truth, and its time stamps."""
    rng = np.random.default_rng(seed)
    g = LineGraph()
    n = LAPS * PER_LAP
    s = 2.0 * np.pi * np.arange(n) / PER_LAP
    truth = np.column_stack([4.0 * np.cos(s), 4.0 * np.sin(s), s + np.pi / 2])
    alpha = 2.0 * np.pi * np.arange(WALLS) / WALLS
    walls = np.column_stack([np.full(WALLS, 7.0), alpha])
    feet = 7.0 * np.column_stack([np.cos(alpha), np.sin(alpha)])
    lms = g.add_landmarks(walls, feet)
    for k in range(n):
        g.add_pose(truth[k])
    g.set_prior(truth[0], np.diag([1e-8, 1e-8, 1e-10]))
    for k in range(1, n):
        step = pose_between(truth[k - 1], truth[k])
        g.add_odometry(k - 1, k, step + rng.multivariate_normal(np.zeros(3), Q), Q)
    shift = rng.normal(0.0, [sigma_o or 1e-12, sigma_a or 1e-12], (LAPS, WALLS, 2))
    for k in range(n):
        lap = k // PER_LAP
        near = np.argsort(np.abs(wrap_angle(alpha - s[k])))[:4]
        for j in near:
            seen = np.array([7.0 + shift[lap, j, 0], alpha[j] + shift[lap, j, 1]])
            z = predict_line_measurement(seen, truth[k])[0] + rng.multivariate_normal(
                np.zeros(2), R
            )
            g.add_line_factors(k, lms[j : j + 1], z[None], R[None], np.zeros((1, 2, 2)))
    BatchSolver(SolverConfig(max_iterations=20)).solve(g)
    return g, np.arange(n, dtype=float)


def test_the_fitted_ratio_is_about_one_where_the_model_holds():
    g, stamps = _laps(21, 0.0, 0.0)
    res = pass_consistency(g, stamps, gap_s=30.0)
    assert res.pairs >= WALLS * LAPS * (LAPS - 1) // 2 - WALLS  # a wall in view across a lap start
    # against C_p + C_q alone, the fit pulls the passes together; with it, about χ²₂
    shrunk = pass_consistency(g, stamps, gap_s=30.0, fitted=False)
    assert shrunk.median_ratio < 0.8 * res.median_ratio
    assert 0.7 < res.median_ratio < 1.4
    # no pass error to find: judged with the one estimated, about the same
    assert res.pass_error_sigma_offset_m < 0.005 and res.pass_error_sigma_angle_rad < 0.002
    assert 0.6 < res.median_ratio_with_pass_error <= res.median_ratio


def test_the_pass_error_is_found_and_linked():
    g, stamps = _laps(22, 0.02, 0.005)
    res = pass_consistency(g, stamps, gap_s=30.0)
    assert res.median_ratio > 3.0
    # judged with the pass error estimated from the same pairs, about χ²₂ again
    assert 0.7 < res.median_ratio_with_pass_error < 1.4
    assert res.fraction_beyond_95_with_pass_error < 0.12
    # too few pairs for a pass error: none is reported
    few = pass_consistency(g, stamps, gap_s=30.0, max_pairs=MIN_PAIRS - 1)
    assert few.pairs == MIN_PAIRS - 1 and math.isnan(few.median_ratio_with_pass_error)
    passes = find_passes(g, stamps, gap_s=30.0)
    err = estimate_pass_error(passes, fitted_pairs(g, passes))
    # the part of the passes' errors the fit absorbs is allowed for: the truth comes back
    assert err.sigma_offset_m == pytest.approx(0.02, rel=0.2)
    assert err.sigma_angle_rad == pytest.approx(0.005, rel=0.2)
    # with the poses taken as known the fit's share is missed: a lower bound
    naive = estimate_pass_error(passes)
    assert naive.sigma_offset_m < 0.8 * err.sigma_offset_m
    assert naive.sigma_angle_rad < 0.9 * err.sigma_angle_rad
    linked, k = with_pass_links(g, passes, err)
    assert k >= WALLS * (LAPS - 1) and linked.n_landmark_links == k
    assert linked.n_landmarks == g.n_landmarks + k
    assert linked.observation_counts()[:WALLS].sum() == 0  # the walls hold no factor now
    # judged on its walls, the linked graph gives the same consistency, with the poses as if
    # known and at the walls' fit alike
    again = pass_consistency(linked, stamps, gap_s=30.0, fitted=False)
    assert again.median_ratio == pytest.approx(
        pass_consistency(g, stamps, gap_s=30.0, fitted=False).median_ratio
    )
    fitted = pass_consistency(linked, stamps, gap_s=30.0)
    assert fitted.median_ratio == pytest.approx(res.median_ratio)
    assert fitted.median_ratio_angle == pytest.approx(res.median_ratio_angle)
    # the same estimate minimises the linked graph's cost near where it is (the passes at their
    # walls): a solve moves the poses by less than the odometry's noise
    before = linked.poses.copy()
    BatchSolver(SolverConfig(max_iterations=20, linear_solver="gtsam")).solve(linked)
    assert np.abs(linked.poses[:, :2] - before[:, :2]).max() < 0.05
    # the pass error makes the poses of different laps less certain of each other
    plain = BatchSolver().marginals(g)
    passed = BatchSolver().marginals(linked)
    keys = keys_of("x", np.array([10, 10 + 2 * PER_LAP]))
    var_plain = np.linalg.det(plain.jointMarginalCovariance(keys).fullMatrix())
    var_passed = np.linalg.det(passed.jointMarginalCovariance(keys).fullMatrix())
    assert var_passed > 1.5 * var_plain


def test_without_a_pass_error_the_estimate_is_small():
    g, stamps = _laps(24, 0.0, 0.0)
    passes = find_passes(g, stamps, gap_s=30.0)
    err = estimate_pass_error(passes, fitted_pairs(g, passes))
    # against the 1 cm / 5 mrad of each factor and 2 cm of the pass error above
    assert err.sigma_offset_m < 0.004 and err.sigma_angle_rad < 0.0015


def test_without_a_pass_error_none_is_estimated_in_most_runs():
    # the moment estimate alone is positive in most runs where the walls have none (14 of
    # these 20); the significance test leaves most at exactly zero (2 of 20: the pairs share
    # passes, so they are fewer independent pairs than they count)
    nonzero = 0
    for seed in range(30, 50):
        g, stamps = _laps(seed, 0.0, 0.0)
        passes = find_passes(g, stamps, gap_s=30.0)
        err = estimate_pass_error(passes, fitted_pairs(g, passes))
        nonzero += err.sigma_offset_m > 0.0 or err.sigma_angle_rad > 0.0
    assert nonzero <= 4


def test_the_excess_test_holds_its_level_and_finds_an_excess():
    rng = np.random.default_rng(12)
    # residuals with exactly their variances: significant about 1 % of the time
    false_alarms = sum(
        excess_is_significant(rng.normal(0.0, 1.0, 100) ** 2, np.ones(100), 0.99)
        for _ in range(2000)
    )
    assert 5 <= false_alarms <= 40
    # variance half again as large as the residuals' own, 300 of them: found
    found = sum(
        excess_is_significant(rng.normal(0.0, math.sqrt(1.5), 300) ** 2, np.ones(300), 0.99)
        for _ in range(200)
    )
    assert found >= 190
    assert not excess_is_significant(np.zeros(0), np.zeros(0), 0.99)


def test_no_pass_error_links_nothing():
    g, stamps = _laps(23, 0.0, 0.0)
    passes = find_passes(g, stamps, gap_s=30.0)
    same, k = with_pass_links(g, passes, PassError(30.0, 0.0, 0.0, 10))
    assert same is g and k == 0


def test_landmark_links_are_checked_and_cost_what_they_say():
    g = LineGraph()
    anchor = np.array([[1.0, 1.0], [1.0, 1.0], [0.0, 0.0]])
    lms = g.add_landmarks(np.array([[2.0, 0.1], [2.05, 0.12], [2.0, 0.1]]), anchor)
    g.add_pose(np.zeros(3))
    g.set_prior(np.zeros(3), np.eye(3) * 1e-6)
    solver = BatchSolver()
    before = solver.cost(g, g.poses, g.landmarks)
    cov = np.diag([0.01**2, 0.02**2])
    g.add_landmark_links(lms[:1], lms[1:2], cov[None])
    d = g.landmarks[0] - g.landmarks[1]
    expected = 0.5 * (d[0] ** 2 / cov[0, 0] + d[1] ** 2 / cov[1, 1])
    assert solver.cost(g, g.poses, g.landmarks) - before == pytest.approx(expected, rel=1e-9)
    assert g.n_landmark_links == 1 and set(solver.active_landmarks(g)) == {0, 1}
    with pytest.raises(InputError, match="anchor"):
        g.add_landmark_links(lms[:1], lms[2:], cov[None])
    with pytest.raises(InputError, match="invalid landmarks"):
        g.add_landmark_links(lms[:1], lms[:1], cov[None])
    with pytest.raises(DegenerateGeometryError):
        g.add_landmark_links(lms[:1], lms[1:2], np.zeros((1, 2, 2)))


def test_a_linked_graph_round_trips_through_g2o_with_its_covariances(tmp_path):
    g, stamps = _laps(22, 0.02, 0.005)
    passes = find_passes(g, stamps, gap_s=30.0)
    linked, k = with_pass_links(g, passes, estimate_pass_error(passes))
    assert k > 0
    result = SimpleNamespace(
        timestamps=stamps,
        is_keyframe=np.ones(g.n_poses, bool),
        keyframe_of_scan=np.arange(g.n_poses),
    )
    path = write_line_graph_g2o(
        tmp_path / "graph.g2o", linked, result, scan_offsets=np.zeros((g.n_poses, 3)),
        motion_noise=MotionNoiseConfig(), robust_kernel=("none", 1.0),
    )  # fmt: skip
    back = read_line_graph_g2o(path)
    assert back.line_links is not None and back.line_links.shape == (k, 7)
    again = line_graph_from_file(back)
    assert again.n_landmark_links == k
    keys = keys_of("x", np.array([10, 10 + 2 * PER_LAP]))
    want = BatchSolver().marginals(linked).jointMarginalCovariance(keys).fullMatrix()
    got = BatchSolver().marginals(again).jointMarginalCovariance(keys).fullMatrix()
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-12)
    # the relative covariances of a linked graph come from the information's LU: the same
    # joint marginals as GTSAM's
    rc = RunCovariances.from_file(path)
    pairs = np.array([[3, 70], [10, 130], [5, 6], [40, 200]])
    fast = rc.joint_covariances_from_information(pairs)
    for a, b in pairs.tolist():
        np.testing.assert_allclose(fast[(a, b)], rc._joint(a, b), rtol=1e-6, atol=1e-14)
    # without the links the file reads back to different covariances
    plain = BatchSolver().marginals(g).jointMarginalCovariance(keys).fullMatrix()
    assert not np.allclose(plain, want, rtol=0.1)
    # a link with information that is not positive definite is refused with its line
    text = path.read_text().splitlines()
    i = next(n for n, line in enumerate(text) if line.startswith("LINESLAM_EDGE_LINE2D_LINK"))
    fields = text[i].split()
    fields[-3] = "-1"
    text[i] = " ".join(fields)
    bad = tmp_path / "bad.g2o"
    bad.write_text("\n".join(text) + "\n")
    with pytest.raises(LogFormatError, match=f"{i + 1}"):
        read_line_graph_g2o(bad)
