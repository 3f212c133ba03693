"""Dense scan matching (``slam.frontend.scan_match``): known answers, slips, a corridor, NEES,
bad input, and the pipeline with ``[slam.frontend.scan_matching] enabled = true``.

The scans are ray cast (:func:`slam.sim.raycast.cast_scan`) in small worlds built here: a
closed L-shaped room with three boxes (no symmetry), and a corridor of two long parallel walls.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT
from scipy import integrate, stats

from linefit.config import SensorNoiseConfig
from linefit.noise import point_covariance_entries
from slam.config import RunConfig
from slam.errors import ConfigError
from slam.evaluation.relations_metric import relations_metric
from slam.frontend.scan_match import (
    CAUCHY_DPSI,
    CAUCHY_PSI2,
    ScanMatch,
    ScanMatchConfig,
    ScanPoints,
    _chi2_99,
    _chi2_median,
    _Matcher,
    _OdometryPrior,
    contradicted_covariance,
    match_any_heading,
    match_scans,
    normal_half_window,
    refine_scan,
    scale_points_information,
    scan_points,
    slip_covariance,
    visible_points,
)
from slam.geometry import pose_between, pose_compose, pose_log
from slam.io import read_tum
from slam.io.carmen import scan_trajectory
from slam.io.relations import read_relations
from slam.io.results import read_covariances
from slam.models import MotionNoiseConfig
from slam.runner import run_slam
from slam.sim.raycast import cast_scan
from slam.sim.world import World, WorldBuilder

DEMO = REPO_ROOT / "datasets" / "sim" / "demo"
MAX_RANGE_M = 30.0
FULL = np.deg2rad(np.arange(360.0) - 180.0)  # 360 beams over 360°
HALF = np.deg2rad(np.linspace(-90.0, 90.0, 181))  # 181 beams over 180°
NOISE = SensorNoiseConfig()  # the paper's: σ_d = 5 mm, σ_φ = 1e-4 rad
POSE_A = np.array([3.0, 3.0, 0.2])  # reference laser in the room
TRUE_DELTA = np.array([0.4, 0.1, 0.3])  # current laser in the reference laser's frame


def _room() -> World:
    """An L-shaped room (10 m × 8 m, a 4 m × 4 m corner cut off) with three boxes."""
    b = WorldBuilder()
    b.polyline([(0, 0), (10, 0), (10, 4), (6, 4), (6, 8), (0, 8)], closed=True)
    b.box(2.0, 1.0, 1.0, 0.6)
    b.rotated_box(7.5, 2.0, 0.8, 0.5, 0.4, "box")
    b.box(1.0, 5.5, 0.7, 1.2)
    return b.build("room")


def _corridor() -> World:
    """Two parallel walls along x, 2.2 m apart, far longer than the laser's range."""
    b = WorldBuilder()
    b.segment((-200.0, -1.2), (200.0, -1.2))
    b.segment((-200.0, 1.0), (200.0, 1.0))
    return b.build("corridor")


ROOM = _room()
CORRIDOR = _corridor()


def _ranges(world: World, pose: np.ndarray, bearings: np.ndarray) -> np.ndarray:
    return cast_scan(pose, bearings, world, MAX_RANGE_M)[0]


def _pair(
    world: World,
    bearings: np.ndarray,
    config: ScanMatchConfig,
    pose_a: np.ndarray = POSE_A,
    delta: np.ndarray = TRUE_DELTA,
    noise: SensorNoiseConfig = NOISE,
) -> tuple[ScanPoints, ScanPoints]:
    """Noise-free points of the reference scan at ``pose_a``, the current at ``pose_a ∘ delta``."""
    ra = _ranges(world, pose_a, bearings)
    rb = _ranges(world, pose_compose(pose_a, delta), bearings)
    return (
        scan_points(ra, bearings, MAX_RANGE_M, noise, config),
        scan_points(rb, bearings, MAX_RANGE_M, noise, config),
    )


def _odometry_cov(delta0: np.ndarray) -> np.ndarray:
    """The pipeline's prior: the default motion model's covariance of the odometry step."""
    return MotionNoiseConfig().covariance(np.asarray(delta0, dtype=float))


def _angle(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


def _pose_error(match: ScanMatch, truth: np.ndarray) -> tuple[float, float]:
    """(position error (m), |heading error| (rad)) of a match."""
    e = match.delta - truth
    return float(np.hypot(e[0], e[1])), abs(_angle(float(e[2])))


# --------------------------------------------------------------------------------------------
# scan_points


@pytest.mark.parametrize(
    ("step_deg", "h"), [(0.25, 4), (0.5, 2), (1.0, 1), (1.0056, 1), (2.0, 1), (4.0, 1)]
)
def test_local_line_window_covers_two_degrees_whatever_the_beam_spacing(step_deg, h):
    """``2h + 1`` points: the nearest whole number of beam steps to 1° on each side, at
    least one; the steps' median decides (a missing beam does not)."""
    bearings = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    bearings = np.delete(bearings, 7)
    assert normal_half_window(bearings, ScanMatchConfig()) == h
    assert normal_half_window(bearings[::-1], ScanMatchConfig()) == h
    assert normal_half_window(bearings[:1], ScanMatchConfig()) == 1


def test_scan_points_drop_invalid_readings_and_find_the_walls_local_lines():
    """Two walls at different depths (a depth jump between them), with invalid readings
    mixed in: the valid readings' points in beam order with their Eq. 8 covariances, the
    walls' normals, one segment per wall, no local line across the jump."""
    b = WorldBuilder()
    b.segment((2.0, -3.0), (2.0, 0.0))  # wall x = 2 m below the x axis
    b.segment((4.0, 0.0), (4.0, 3.0))  # wall x = 4 m above it
    world = b.build("step")
    bearings = np.deg2rad(np.linspace(-50.0, 35.0, 86))
    ranges = _ranges(world, np.zeros(3), bearings)
    assert np.all(ranges < MAX_RANGE_M)
    bad = np.zeros(bearings.size, dtype=bool)
    bad[[3, 40, 80]] = True
    ranges[3], ranges[40], ranges[80] = np.nan, 0.0, MAX_RANGE_M
    cfg = ScanMatchConfig()
    pts = scan_points(ranges, bearings, MAX_RANGE_M, NOISE, cfg)
    d, phi = ranges[~bad], bearings[~bad]
    assert len(pts) == d.size
    np.testing.assert_allclose(pts.xy, np.column_stack([d * np.cos(phi), d * np.sin(phi)]))
    want = point_covariance_entries(d, phi, NOISE)
    for got, expected in zip((pts.q11, pts.q12, pts.q22), want, strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=0.0)
    # local lines: on each wall, normal ±x; none at the two ends of the scan or over the jump
    h = normal_half_window(bearings, cfg)
    assert h == 1  # 1° beam steps, the default 2° window: three points
    assert not pts.has_normal[:h].any() and not pts.has_normal[-h:].any()
    wall = np.where(pts.xy[:, 0] < 3.0, 0, 1)
    jump = int(np.flatnonzero(np.diff(wall))[0])  # last point of the first wall
    assert not pts.has_normal[jump - h + 1 : jump + h + 1].any()
    ok = pts.has_normal
    assert ok.sum() == len(pts) - 4 * h
    np.testing.assert_allclose(np.abs(pts.normals[ok, 0]), 1.0, atol=1e-9)
    np.testing.assert_allclose(pts.normals[~ok], 0.0)
    # one segment per wall, −1 where there is no local line
    assert np.all(pts.segment[~ok] == -1)
    assert set(pts.segment[ok & (wall == 0)]) == {0} and set(pts.segment[ok & (wall == 1)]) == {1}


def _corner_normal_errors(
    sigma_range_m: float, normal_length_m: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Angle between each local line's normal and its wall's, two walls meeting in a corner
    2 m away (0.5° beams, seeded range noise), and each point's distance to the corner."""
    b = WorldBuilder()
    b.segment((2.0, -3.0), (2.0, 2.0))
    b.segment((2.0, 2.0), (-3.0, 2.0))
    world = b.build("corner")
    bearings = np.deg2rad(np.arange(-55.0, 145.0, 0.5))
    ranges = _ranges(world, np.zeros(3), bearings)
    ranges += sigma_range_m * np.random.default_rng(seed).standard_normal(ranges.size)
    cfg = ScanMatchConfig(normal_length_m=normal_length_m)
    pts = scan_points(ranges, bearings, MAX_RANGE_M, NOISE, cfg)
    xy, n = pts.xy[pts.has_normal], pts.normals[pts.has_normal]
    on_x = np.abs(xy[:, 0] - 2.0) < np.abs(xy[:, 1] - 2.0)
    true = np.where(on_x[:, None], [1.0, 0.0], [0.0, 1.0])
    sin = np.abs(n[:, 0] * true[:, 1] - n[:, 1] * true[:, 0])
    return np.arcsin(np.clip(sin, 0.0, 1.0)), np.hypot(xy[:, 0] - 2.0, xy[:, 1] - 2.0)


@pytest.mark.parametrize(("sigma_range_m", "gain"), [(0.005, 5.0), (0.02, 2.0)])
def test_local_lines_extended_along_the_wall_but_not_round_its_corner(sigma_range_m, gain):
    """Two walls and their corner with the paper's 5 mm range noise and with 2 cm (the
    scan's noise four times what Eq. 8 is told; the extension's χ² test scales it from the
    short lines' own spread): the normals of lines extended over a metre of wall are several
    times closer to the walls' (RMS tilt) than the five-point lines', and none bends round
    the corner (points within 0.6 m of it no worse than the short lines' worst)."""
    for seed in range(5):
        short, _ = _corner_normal_errors(sigma_range_m, 0.0, seed)
        long, to_corner = _corner_normal_errors(sigma_range_m, 1.0, seed)
        rms_short, rms_long = np.sqrt(np.mean(short**2)), np.sqrt(np.mean(long**2))
        assert rms_long * gain < rms_short, (seed, rms_long, rms_short)
        near = to_corner < 0.6
        assert near.sum() >= 10
        assert long[near].max() <= short.max(), (seed, long[near].max(), short.max())
    # noise-free: every normal is its wall's, the extended ones exactly
    long, _ = _corner_normal_errors(0.0, 1.0, 0)
    assert long.max() < 1e-6


def test_chi2_quantiles_of_the_extension_test():
    """The extension's χ² quantiles (Wilson-Hilferty) within 1 % of scipy's."""
    for dof in range(1, 400):
        assert _chi2_99(dof) == pytest.approx(stats.chi2.ppf(0.99, dof), rel=0.01)
        assert _chi2_median(dof) == pytest.approx(stats.chi2.median(dof), rel=0.01)


# --------------------------------------------------------------------------------------------
# 1. known answer, noise-free


def _reversed_delta() -> np.ndarray:
    """The reference laser's pose in the current laser's frame."""
    return pose_between(pose_compose(POSE_A, TRUE_DELTA), POSE_A)


@pytest.mark.parametrize("swap", [False, True], ids=["forward", "swapped"])
@pytest.mark.parametrize("bearings", [FULL, HALF], ids=["360beams-360deg", "181beams-180deg"])
def test_noise_free_match_returns_the_true_relative_pose(bearings, swap):
    """Odometry off by (3 cm, −2 cm, 2°); ``delta`` is the current laser's pose in the
    reference laser's frame (swapping the scans gives the inverse pose).

    * Only exactly straight local lines (``max_line_thickness = 1e-6``) and a flat prior (the
      motion model's covariance × 1e4): the true pose to 1e-6 (measured ≤ 4.3e-8), with or
      without a model error.
    * The same lines, no model error, the motion model's prior: the posterior mode is pulled
      towards the odometry by ~1e-5 (measured ≤ 3.7e-5 m, 6.6e-6 rad).
    * The defaults: within 1e-3 m and 3e-4 rad (measured ≤ 2.7e-4 m, 9.9e-5 rad with the
      181 beams).  The model error (2 cm) lets the prior pull harder, and a few windows that
      straddle a corner pass ``max_line_thickness = 0.05`` and leave residuals of up to 1 cm
      at the true pose.
    """
    truth = _reversed_delta() if swap else TRUE_DELTA
    delta0 = truth + np.array([0.03, -0.02, np.deg2rad(2.0)])
    prior = _odometry_cov(delta0)
    exact = ScanMatchConfig(model_sigma_m=0.0, max_line_thickness=1e-6)
    cases = [
        (exact, 1e4, 1e-6, 1e-6),
        (replace(exact, model_sigma_m=0.02), 1e4, 1e-6, 1e-6),
        (exact, 1.0, 1e-4, 2e-5),
        (ScanMatchConfig(), 1.0, 1e-3, 3e-4),
    ]
    for cfg, widen, tol_m, tol_rad in cases:
        ref, cur = _pair(ROOM, bearings, cfg)
        if swap:
            ref, cur = cur, ref
        m = match_scans(ref, cur, delta0, widen * prior, cfg)
        err_m, err_rad = _pose_error(m, truth)
        assert err_m < tol_m and err_rad < tol_rad, (m.delta - truth, cfg, widen)
        visible = visible_points(ref, cur, m.delta)
        assert m.accepted and m.overlap > 0.6 and m.inliers == round(m.overlap * visible)
        # (a rotated start may win the search when it converges to the same pose)
        assert np.all(np.isfinite(m.cov)) and np.all(np.linalg.eigvalsh(m.cov) > 0.0)
        assert np.all(np.diag(m.cov) < np.diag(widen * prior))
        assert m.cov[2, 2] < 0.05 * prior[2, 2]  # the walls fix the rotation


# --------------------------------------------------------------------------------------------
# 1b. the overlap counts the points the reference could see


def test_visible_points_of_a_half_scanner_turned_by_a_right_angle():
    """A 180° scanner: unmoved, every point is visible; turned by +90°, the points whose
    bearing was at most 0 (the half that stays in the reference's view); a 360° scanner
    sees every point whatever the turn; beam order (clockwise) does not matter."""
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, HALF, cfg, delta=np.zeros(3))
    assert visible_points(ref, cur, np.zeros(3)) == len(cur)
    turned = np.array([0.0, 0.0, math.pi / 2])
    bearing = np.arctan2(cur.xy[:, 1], cur.xy[:, 0])
    assert visible_points(ref, cur, turned) == np.count_nonzero(bearing <= 1e-9)
    flipped = ScanPoints(ref.xy[::-1], ref.q11, ref.q12, ref.q22, ref.normals, ref.has_normal,
                         ref.segment)  # fmt: skip
    assert visible_points(flipped, cur, turned) == visible_points(ref, cur, turned)
    ref360, cur360 = _pair(ROOM, FULL, cfg, delta=np.zeros(3))
    for theta in (0.0, 1.0, 2.5, -3.0):
        assert visible_points(ref360, cur360, np.array([0.0, 0.0, theta])) == len(cur360)
    # farther than the reference's farthest point: not visible
    far = np.array([np.max(np.hypot(ref360.xy[:, 0], ref360.xy[:, 1])) + 1.0, 0.0, 0.0])
    assert visible_points(ref360, cur360, far) < len(cur360)
    empty = scan_points(np.zeros(0), np.zeros(0), MAX_RANGE_M, NOISE, cfg)
    assert visible_points(ref360, empty, np.zeros(3)) == 0
    assert visible_points(empty, cur360, np.zeros(3)) == 0


def test_a_sharp_turn_is_matched_though_half_the_scan_left_the_view():
    """A 180° scanner turning 86° (the odometry 12° off): fewer than half of the current
    points can pair at all, but nearly all that the reference could see do; the match is
    used and right."""
    truth = np.array([0.1, 0.05, 1.5])
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, HALF, cfg, delta=truth)
    delta0 = truth + np.array([0.0, 0.0, math.radians(12.0)])
    m = match_scans(ref, cur, delta0, _odometry_cov(delta0), cfg)
    err_m, err_rad = _pose_error(m, truth)
    assert err_m < 1e-3 and err_rad < 1e-3
    assert m.inliers / len(cur) < cfg.min_overlap  # of all points: too few
    assert m.accepted and m.overlap > 0.8


# --------------------------------------------------------------------------------------------
# 2. a slip


@pytest.mark.parametrize("slip_deg", [-30.0, -25.0, 28.0])
def test_rotation_search_recovers_an_odometry_slip(slip_deg):
    """The odometry's heading off by tens of degrees (10-20 σ of the motion model; its
    translation right): the multi-start search finds the true pose (within 1e-3) from a
    rotated start; without the search (``rotation_window_rad = 0``) the match stays in a
    wrong minimum and is rejected."""
    delta0 = TRUE_DELTA + np.array([0.0, 0.0, np.deg2rad(slip_deg)])
    prior = _odometry_cov(delta0)
    assert 0.01 < math.sqrt(prior[2, 2]) < 0.06  # σθ of one to a few degrees
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, FULL, cfg)
    m = match_scans(ref, cur, delta0, prior, cfg)
    err_m, err_rad = _pose_error(m, TRUE_DELTA)
    assert err_m < 1e-3 and err_rad < 1e-3, m.delta - TRUE_DELTA
    assert m.accepted and m.overlap > 0.8
    assert np.sign(m.start_offset_rad) == -np.sign(slip_deg)  # refined from a rotated start
    no_search = replace(cfg, rotation_window_rad=0.0)
    m0 = match_scans(ref, cur, delta0, prior, no_search)
    assert m0.start_offset_rad == 0.0
    assert _pose_error(m0, TRUE_DELTA)[1] > np.deg2rad(10.0)
    assert not m0.accepted and m0.overlap < 0.2


def test_a_turn_beyond_the_search_is_found_over_every_heading():
    """After a gap the scan has turned 86° where the prediction says it stood still: the
    matcher's search around the prediction does not reach it and the match is not used; the
    search over every heading finds the true pose, the only solution of the L-shaped room."""
    truth = np.array([0.1, 0.05, 1.5])
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, FULL, cfg, delta=truth)
    delta0 = np.zeros(3)
    near = match_scans(ref, cur, delta0, _odometry_cov(delta0), cfg)
    assert not near.accepted
    m, probability = match_any_heading(ref, cur, delta0, 0.5, cfg)
    err_m, err_rad = _pose_error(m, truth)
    assert err_m < 1e-3 and err_rad < 1e-3
    assert m.accepted and probability > 0.999


def test_a_corridor_seen_both_ways_is_ambiguous_over_every_heading():
    """Two parallel walls look the same after a half turn: both headings fit every point,
    and neither is the more probable by much."""
    truth = np.array([0.3, 0.05, 3.0])
    cfg = ScanMatchConfig()
    ref, cur = _pair(CORRIDOR, FULL, cfg, pose_a=np.array([0.0, 0.0, 0.0]), delta=truth)
    m, probability = match_any_heading(ref, cur, np.zeros(3), 0.5, cfg)
    assert m.accepted
    off = _angle(float(m.delta[2] - truth[2]))
    assert min(abs(off), abs(_angle(off + math.pi))) < 1e-3
    assert probability < 0.9


@pytest.mark.parametrize("slip_deg", [-25.0, 28.0])
def test_slip_mixture_flags_a_slip_and_widens_the_odometry_rotation(slip_deg):
    """With ``slip_probability`` the odometry's rotation is a mixture of its Gaussian and a
    slip (``slip_sigma_rad`` more spread).  A step whose heading is off by tens of degrees is
    found and flagged as a slip, its rotation the points'; the same step without the slip is
    not flagged and matches as it does without the mixture."""
    cfg = ScanMatchConfig(slip_probability=0.01)
    ref, cur = _pair(ROOM, FULL, cfg)
    delta0 = TRUE_DELTA + np.array([0.0, 0.0, np.deg2rad(slip_deg)])
    prior = _odometry_cov(delta0)
    m = match_scans(ref, cur, delta0, prior, cfg)
    err_m, err_rad = _pose_error(m, TRUE_DELTA)
    assert err_m < 1e-3 and err_rad < 1e-3, m.delta - TRUE_DELTA
    assert m.accepted and m.slip
    # the rotation is the points' alone: far below the slip's spread, near the Gaussian case's
    assert m.cov[2, 2] < 0.05 * prior[2, 2]
    # no slip: not flagged, the same match as without the mixture
    delta1 = TRUE_DELTA + np.array([0.01, -0.01, np.deg2rad(1.0)])
    prior1 = _odometry_cov(delta1)
    m1 = match_scans(ref, cur, delta1, prior1, cfg)
    m0 = match_scans(ref, cur, delta1, prior1, replace(cfg, slip_probability=0.0))
    assert not m1.slip and not m0.slip
    np.testing.assert_allclose(m1.delta, m0.delta, atol=1e-7)
    np.testing.assert_allclose(m1.cov, m0.cov, rtol=1e-6)


def test_slip_mixture_flags_no_slip_under_the_motion_model(rng):
    """No slip: odometry drawn from its own Gaussian, ranges with the Eq. 8 noise (σ_d = 1 cm,
    twice the paper's).  In 60 seeded matches none is flagged as a slip (at ``slip_probability =
    0.01`` a step is a slip when it is ~4 σ off) and every match is within 1 cm and 0.2° of
    the truth."""
    noise = replace(NOISE, sigma_range_m=0.01)
    cfg = ScanMatchConfig(slip_probability=0.01)
    pa = POSE_A
    pb = pose_compose(POSE_A, TRUE_DELTA)
    flagged = 0
    for _ in range(60):
        ra = _ranges(ROOM, pa, FULL) + rng.normal(0.0, noise.sigma_range_m, FULL.size)
        rb = _ranges(ROOM, pb, FULL) + rng.normal(0.0, noise.sigma_range_m, FULL.size)
        ref = scan_points(ra, FULL, MAX_RANGE_M, noise, cfg)
        cur = scan_points(rb, FULL, MAX_RANGE_M, noise, cfg)
        prior = _odometry_cov(TRUE_DELTA)
        delta0 = TRUE_DELTA + rng.multivariate_normal(np.zeros(3), prior)
        m = match_scans(ref, cur, delta0, prior, cfg)
        flagged += int(m.slip)
        err_m, err_rad = _pose_error(m, TRUE_DELTA)
        assert m.accepted and err_m < 0.01 and err_rad < np.deg2rad(0.2)
    assert flagged == 0


@pytest.mark.parametrize("slip_deg", [-25.0, 28.0])
def test_a_rejected_match_that_finds_a_slip_contradicts_the_odometry(slip_deg):
    """A match that is not used (here: ``min_overlap = 1``, above these overlaps) but
    whose best solution lies in the slip component is flagged ``contradicted``: the points
    say the odometry's heading slipped, without being trusted to say by how much.  The same
    step without the slip is not flagged, and neither is an accepted slip."""
    cfg = ScanMatchConfig(slip_probability=0.01, min_overlap=1.0)
    ref, cur = _pair(ROOM, FULL, cfg)
    delta0 = TRUE_DELTA + np.array([0.0, 0.0, np.deg2rad(slip_deg)])
    m = match_scans(ref, cur, delta0, _odometry_cov(delta0), cfg)
    assert not m.accepted and not m.slip and m.contradicted
    delta1 = TRUE_DELTA + np.array([0.01, -0.01, np.deg2rad(1.0)])
    m1 = match_scans(ref, cur, delta1, _odometry_cov(delta1), cfg)
    assert not m1.accepted and not m1.contradicted
    used = match_scans(ref, cur, delta0, _odometry_cov(delta0), replace(cfg, min_overlap=0.5))
    assert used.accepted and used.slip and not used.contradicted


def _driven(length_m: float, turn_rad: float, n: int = 4000) -> np.ndarray:
    """Relative pose after driving ``length_m`` while turning uniformly by ``turn_rad``."""
    s = (np.arange(n) + 0.5) / n
    return np.array(
        [
            length_m * np.mean(np.cos(turn_rad * s)),
            length_m * np.mean(np.sin(turn_rad * s)),
            turn_rad,
        ]
    )


@pytest.mark.parametrize(
    ("length_m", "turn_rad"), [(0.5, 0.0), (0.6, 0.1), (0.3, -0.15), (0.3, 0.6)]
)
def test_slip_covariance_spreads_the_translation_along_the_heading_slip(length_m, turn_rad):
    """A slip: the wheels misreport the heading by ``φ`` accrued over the step, and the
    odometry integrates its translation along that heading.  To first order the true step
    differs from the odometry's by ``φ v``, ``v = (−t_y/2, t_x/2, 1)`` (in the step's start
    frame; rotated by ``−dθ`` in its end frame, the odometry factor's): the slip component is
    ``Q + σ_slip² v vᵀ``.  Checked against the step driven with and without the slip."""
    cfg = ScanMatchConfig()
    phi = 1e-3
    odo = _driven(length_m, turn_rad)
    true = _driven(length_m, turn_rad + phi)
    Q = _odometry_cov(odo)
    for body in (False, True):
        v = (slip_covariance(Q, cfg, odo, body=body) - Q) / cfg.slip_sigma_rad**2
        e = pose_log(pose_between(odo, true)) if body else true - odo
        measured = e / phi
        predicted = v[:, 2]  # the column of v vᵀ with v[2] = 1
        np.testing.assert_allclose(v, np.outer(predicted, predicted), atol=1e-15)
        # exact for a straight step; a turning one bends its lever arm (about L·|dθ|/12),
        # far less than the other frame's vector would be off
        tol = 0.002 + 0.1 * abs(turn_rad) * length_m
        np.testing.assert_allclose(measured, predicted, atol=tol, rtol=0.0)
    # without the step: the heading only; the argument is not modified
    wide = slip_covariance(Q, cfg)
    np.testing.assert_array_equal(wide - Q, np.diag([0.0, 0.0, cfg.slip_sigma_rad**2]))
    assert Q[2, 2] == _odometry_cov(odo)[2, 2]


@pytest.mark.parametrize(("length_m", "turn_rad", "phi"), [(0.4, 0.0, 0.2), (0.3, 0.6, -0.5)])
def test_a_contradicted_step_spreads_as_far_as_the_odometry(length_m, turn_rad, phi):
    """A contradicted match ``φ`` away from the odometry's heading: by default the step's
    covariance has the slip component's shape with the spread ``|φ|`` (not
    ``slip_sigma_rad``), so that the odometry's step, the match moved back along the slip,
    lies about one standard deviation from the centre, where the fixed spread (the slip
    component's covariance, ``contradicted_spread = "slip"``) puts a disagreement below it at
    a fraction of one and one above it at more."""
    cfg = ScanMatchConfig()
    assert cfg.contradicted_spread == "disagreement"
    fixed = ScanMatchConfig(contradicted_spread="slip")
    odo = _driven(length_m, turn_rad)
    match = _driven(length_m, turn_rad + phi)
    Q = _odometry_cov(odo)
    for body in (False, True):
        slip = contradicted_covariance(Q, fixed, odo, match, body=body)
        np.testing.assert_array_equal(slip, slip_covariance(Q, cfg, odo, body=body))
        cov = contradicted_covariance(Q, cfg, odo, match, body=body)
        d = pose_log(pose_between(odo, match)) if body else match - odo
        np.testing.assert_allclose(
            cov, slip_covariance(Q, cfg, odo, body=body, sigma_rad=abs(phi)), rtol=1e-9
        )
        m2 = float(d @ np.linalg.solve(cov, d))
        assert 0.8 < m2 < 1.2, m2  # Q shortens it; the slip's curvature lengthens it a little
        wide = float(d @ np.linalg.solve(slip_covariance(Q, cfg, odo, body=body), d))
        assert wide < 0.7 * m2 if abs(phi) < cfg.slip_sigma_rad else wide > m2


def test_overconfidence_of_the_summed_cost():
    """κ = tr(H C)/3 (:meth:`_Matcher.overconfidence`), by which the points' summed cost
    overstates their evidence.  Noise-free points without a model error: the cost's curvature
    at zero residuals against the Cauchy M-estimator's sandwich gives E[ψ²]/E[ψ']² (1.31) to
    within 5 %.  With the 2 cm model error shared by the points of a wall, the 360 points of
    the room weigh as its 14 walls: κ is of the order of points per wall (25.7)."""
    for model_sigma_m, low, high in [(0.0, 0.95, 1.05), (0.02, 0.5 * 360 / 14, 2.0 * 360 / 14)]:
        cfg = ScanMatchConfig(model_sigma_m=model_sigma_m)
        ref, cur = _pair(ROOM, FULL, cfg)
        assert len(cur) == 360 and int(ref.segment.max()) + 1 == 14
        prior = _OdometryPrior(TRUE_DELTA, _odometry_cov(TRUE_DELTA), cfg)
        matcher = _Matcher(ref, cur, cfg, TRUE_DELTA, prior.info, prior.cost)
        kappa = matcher.overconfidence(TRUE_DELTA)
        if model_sigma_m == 0.0:
            kappa /= CAUCHY_PSI2 / CAUCHY_DPSI**2
        assert low < kappa < high, (model_sigma_m, kappa)


# --------------------------------------------------------------------------------------------
# 3. corridor


def _corridor_match(
    rng: np.random.Generator | None,
    sigma_range_m: float,
    cfg: ScanMatchConfig | None = None,
) -> tuple[ScanMatch, np.ndarray, np.ndarray]:
    """A match in the corridor: odometry off by (8 cm, −3 cm, 2°), prior σ (5 cm, 4 cm, 3°)."""
    cfg = cfg or ScanMatchConfig()
    pose_a = np.zeros(3)
    ra = _ranges(CORRIDOR, pose_a, FULL)
    rb = _ranges(CORRIDOR, pose_compose(pose_a, TRUE_DELTA), FULL)
    if rng is not None:
        ra = ra + sigma_range_m * rng.standard_normal(ra.size)
        rb = rb + sigma_range_m * rng.standard_normal(rb.size)
    ref = scan_points(ra, FULL, MAX_RANGE_M, NOISE, cfg)
    cur = scan_points(rb, FULL, MAX_RANGE_M, NOISE, cfg)
    delta0 = TRUE_DELTA + np.array([0.08, -0.03, np.deg2rad(2.0)])
    prior = np.diag([0.05**2, 0.04**2, np.deg2rad(3.0) ** 2])
    return match_scans(ref, cur, delta0, prior, cfg), delta0, prior


def test_corridor_leaves_the_position_along_it_to_the_odometry():
    """Two parallel walls, noise-free: along the corridor the estimate stays at the odometry's
    and so does the variance (within 10 %); across it and in rotation the points decide."""
    m, delta0, prior = _corridor_match(None, 0.0)
    assert m.accepted
    assert abs(m.delta[0] - delta0[0]) < 1e-6
    assert abs(m.delta[1] - TRUE_DELTA[1]) < 1e-3 and abs(m.delta[2] - TRUE_DELTA[2]) < 1e-4
    assert 0.9 < m.cov[0, 0] / prior[0, 0] < 1.1
    assert m.cov[1, 1] < 0.2 * prior[1, 1] and m.cov[2, 2] < 0.01 * prior[2, 2]
    # across it: each wall's model error is one offset shared by all its points, so the two
    # walls give σ_m²/2, fused with the prior (the points' own 5 mm noise adds < 1 %)
    sigma_m = ScanMatchConfig().model_sigma_m
    across = 1.0 / (2.0 / sigma_m**2 + 1.0 / prior[1, 1])
    assert 0.97 < m.cov[1, 1] / across < 1.05


@pytest.mark.parametrize("normal_length_m", [1.0, 0.0])
def test_corridor_with_range_noise_leaves_the_position_along_it_to_the_odometry(normal_length_m):
    """As above with the paper's 5 mm range noise (10 seeded runs): the scene carries no
    information along the corridor, so neither the estimate nor its variance there may move
    much from the odometry's, and the error along it must stay within 3 σ of the stated
    variance.  With the local lines only three points long (``normal_length_m = 0``, 1° beams)
    their random tilts read as information along the corridor: the variance there falls to a
    few per cent of the odometry's and the error is many of those σ.  With the lines extended
    over a metre of wall a few points still keep short lines (next to a stray reading), so
    one run in a few keeps 75-85 % of the odometry's variance; the others 99 %."""
    moved, ratio, z = [], [], []
    cfg = ScanMatchConfig(normal_length_m=normal_length_m)
    for seed in range(10):
        m, delta0, prior = _corridor_match(np.random.default_rng(500 + seed), 0.005, cfg)
        moved.append(m.delta[0] - delta0[0])
        ratio.append(m.cov[0, 0] / prior[0, 0])
        z.append((m.delta[0] - TRUE_DELTA[0]) / math.sqrt(m.cov[0, 0]))
    if normal_length_m == 0.0:
        assert max(ratio) < 0.2 and np.max(np.abs(z)) > 5.0, (ratio, z)
        return
    assert np.sqrt(np.mean(np.square(moved))) < 0.005, moved
    assert np.median(ratio) > 0.95 and min(ratio) > 0.7, ratio
    assert np.max(np.abs(z)) < 3.0, z


# --------------------------------------------------------------------------------------------
# 4. Monte-Carlo consistency

N_MC = 200
SIGMA_MC = 0.01  # σ_d = 1 cm (σ_φ = 0: the simulated noise is exactly the Eq. 8 model's)


@pytest.fixture(scope="module")
def mc_nees() -> np.ndarray:
    """NEES of :func:`match_scans` over ``N_MC`` seeded runs in the room (:func:`_mc_nees`)."""
    return _mc_nees(match_scans)


def _mc_nees(match) -> np.ndarray:
    """NEES of ``delta − true`` against ``cov`` over ``N_MC`` seeded runs in the room.

    Both scans get N(0, σ_d²) range noise, ``model_sigma_m = 0`` (the walls are exact) and the
    odometry is drawn from N(true, prior) each run.
    """
    cfg = ScanMatchConfig(model_sigma_m=0.0)
    noise = SensorNoiseConfig(sigma_range_m=SIGMA_MC, sigma_bearing_rad=0.0)
    prior = np.diag([0.05**2, 0.05**2, np.deg2rad(3.0) ** 2])
    chol = np.linalg.cholesky(prior)
    ra0 = _ranges(ROOM, POSE_A, FULL)
    rb0 = _ranges(ROOM, pose_compose(POSE_A, TRUE_DELTA), FULL)
    nees = np.empty(N_MC)
    for k in range(N_MC):
        rng = np.random.default_rng(1000 + k)
        ra = ra0 + SIGMA_MC * rng.standard_normal(ra0.size)
        rb = rb0 + SIGMA_MC * rng.standard_normal(rb0.size)
        ref = scan_points(ra, FULL, MAX_RANGE_M, noise, cfg)
        cur = scan_points(rb, FULL, MAX_RANGE_M, noise, cfg)
        delta0 = TRUE_DELTA + chol @ rng.standard_normal(3)
        m = match(ref, cur, delta0, prior, cfg)
        assert m.accepted
        e = m.delta - TRUE_DELTA
        e[2] = _angle(float(e[2]))
        nees[k] = e @ np.linalg.solve(m.cov, e)
    return nees


def _chi2_band(n: int) -> tuple[float, float]:
    """99 % band of the mean of ``n`` independent χ²₃ values."""
    return stats.chi2.ppf(0.005, 3 * n) / n, stats.chi2.ppf(0.995, 3 * n) / n


def test_cauchy_moments_of_the_sandwich():
    """The constants of the sandwich, ``E[ψ']`` and ``E[ψ²]`` of the Cauchy score for standard
    normal residuals, against an independent numerical integration."""

    def mean(f):  # E[f(z)], z ~ N(0, 1)
        return integrate.quad(lambda z: f(z) * stats.norm.pdf(z), -np.inf, np.inf)[0]

    e_dpsi = mean(lambda z: (1.0 - z * z) / (1.0 + z * z) ** 2)
    e_psi2 = mean(lambda z: z * z / (1.0 + z * z) ** 2)
    assert abs(CAUCHY_DPSI - e_dpsi) < 1e-8 * e_dpsi
    assert abs(CAUCHY_PSI2 - e_psi2) < 1e-8 * e_psi2


def test_monte_carlo_nees_is_in_the_chi2_band(mc_nees):
    """The mean NEES of ``N_MC`` runs lies in the 99 % band of the mean of χ²₃ values."""
    lo, hi = _chi2_band(N_MC)
    assert lo < mc_nees.mean() < hi, mc_nees.mean()


def test_refinement_from_the_odometry_alone_has_its_nees_in_the_chi2_band():
    """:func:`refine_scan` (a scan between keyframes: no search, the Gaussian prior) on the
    same runs: its covariance is as consistent as the full match's."""
    nees = _mc_nees(refine_scan)
    lo, hi = _chi2_band(N_MC)
    assert lo < nees.mean() < hi, nees.mean()


def test_refinement_matches_the_search_where_the_odometry_is_close():
    """From an odometry 5 cm and 2° off, the refinement lands where the full match does."""
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, FULL, cfg)
    delta0 = TRUE_DELTA + np.array([0.05, -0.03, np.deg2rad(2.0)])
    prior = _odometry_cov(delta0)
    full = match_scans(ref, cur, delta0, prior, cfg)
    lean = refine_scan(ref, cur, delta0, prior, cfg)
    assert full.accepted and lean.accepted and not lean.slip
    np.testing.assert_allclose(lean.delta, full.delta, atol=1e-6)
    np.testing.assert_allclose(lean.cov, full.cov, rtol=1e-6, atol=1e-12)
    assert _pose_error(lean, TRUE_DELTA) < (1e-3, 1e-4)


def test_current_scan_needs_no_local_lines():
    """A scan only matched (never a reference) can skip its local lines: the same points, the
    same covariances, the same match."""
    cfg = ScanMatchConfig()
    ref, cur = _pair(ROOM, FULL, cfg)
    rb = _ranges(ROOM, pose_compose(POSE_A, TRUE_DELTA), FULL)
    bare = scan_points(rb, FULL, MAX_RANGE_M, NOISE, cfg, with_normals=False)
    assert not bare.has_normal.any() and (bare.segment == -1).all() and cur.has_normal.any()
    for name in ("xy", "q11", "q12", "q22"):
        np.testing.assert_array_equal(getattr(bare, name), getattr(cur, name))
    delta0 = TRUE_DELTA + np.array([0.03, 0.02, -0.02])
    a = refine_scan(ref, cur, delta0, _odometry_cov(delta0), cfg)
    b = refine_scan(ref, bare, delta0, _odometry_cov(delta0), cfg)
    np.testing.assert_array_equal(a.delta, b.delta)
    np.testing.assert_array_equal(a.cov, b.cov)
    assert (a.overlap, a.inliers, a.accepted) == (b.overlap, b.inliers, b.accepted)


def test_refinement_of_an_empty_reference_is_rejected():
    cfg = ScanMatchConfig()
    empty = scan_points(np.full(HALF.size, np.nan), HALF, MAX_RANGE_M, NOISE, cfg)
    _, cur = _pair(ROOM, HALF, cfg)
    m = refine_scan(empty, cur, TRUE_DELTA, _odometry_cov(TRUE_DELTA), cfg)
    assert not m.accepted
    np.testing.assert_array_equal(m.delta, TRUE_DELTA)


# --------------------------------------------------------------------------------------------
# 5. bad input

BAD_SCANS = {
    "nan": np.full(HALF.size, np.nan),
    "inf": np.full(HALF.size, np.inf),
    "-inf": np.full(HALF.size, -np.inf),
    "zero": np.zeros(HALF.size),
    "negative": np.full(HALF.size, -1.0),
    "max-range": np.full(HALF.size, MAX_RANGE_M),
    "beyond-max-range": np.full(HALF.size, 2.0 * MAX_RANGE_M),
    "two-valid": np.where(np.isin(np.arange(HALF.size), [10, 50]), 2.0, np.nan),
    # fewer than the three points of a local line at 1° beam steps
    "two-adjacent": np.where(np.isin(np.arange(HALF.size), [10, 11]), 2.0, np.nan),
}


@pytest.mark.parametrize("name", list(BAD_SCANS))
def test_bad_scans_give_no_usable_points_and_rejected_matches(name):
    cfg = ScanMatchConfig()
    pts = scan_points(BAD_SCANS[name], HALF, MAX_RANGE_M, NOISE, cfg)
    n_valid = {"two-valid": 2, "two-adjacent": 2}.get(name, 0)
    assert (
        len(pts) == n_valid and pts.xy.shape == (n_valid, 2) and pts.normals.shape == (n_valid, 2)
    )
    for field in (pts.q11, pts.q12, pts.q22, pts.has_normal, pts.segment):
        assert field.shape == (n_valid,)
    assert not pts.has_normal.any() and np.all(pts.segment == -1)
    assert np.all(np.isfinite(pts.xy))
    good, _ = _pair(ROOM, HALF, cfg)
    delta0 = np.array([0.3, -0.1, 0.2])
    prior = _odometry_cov(delta0)
    for ref, cur in ((pts, good), (good, pts), (pts, pts)):
        m = match_scans(ref, cur, delta0, prior, cfg)
        assert not m.accepted and m.inliers == 0 and m.overlap == 0.0
        np.testing.assert_array_equal(m.cov, prior)
        assert m.cov is not prior  # a copy
        assert np.all(np.isfinite(m.delta))


def test_empty_reference_rejects_the_match():
    cfg = ScanMatchConfig()
    empty = scan_points(np.empty(0), np.empty(0), MAX_RANGE_M, NOISE, cfg)
    assert len(empty) == 0 and empty.xy.shape == (0, 2)
    _, cur = _pair(ROOM, FULL, cfg)
    delta0 = TRUE_DELTA.copy()
    prior = _odometry_cov(delta0)
    m = match_scans(empty, cur, delta0, prior, cfg)
    assert not m.accepted and m.overlap == 0.0
    np.testing.assert_array_equal(m.cov, prior)
    np.testing.assert_allclose(m.delta, delta0)  # only the prior: its mode


@pytest.mark.parametrize(
    "bad",
    [
        {"normal_span_rad": 0.0},
        {"normal_span_rad": -0.01},
        {"normal_length_m": -0.1},
        {"normal_length_m": math.nan},
        {"slip_probability": 1.0},
        {"slip_probability": -0.01},
        {"slip_sigma_rad": 0.0},
        {"min_overlap": 1.5},
        {"min_overlap": -0.1},
        {"inlier_m": 0.0},
        {"inlier_m": math.nan},
        {"model_sigma_m": -0.01},
        {"max_line_thickness": 0.0},
        {"max_line_thickness": 1.0},
        {"max_neighbour_gap_m": 0.0},
        {"max_correspondence_m": math.inf},
        {"rotation_window_rad": -0.1},
        {"rotation_step_rad": 0.0},
        {"coarse_iterations": 0},
        {"max_iterations": 0},
        {"contradicted_spread": "wide"},
    ],
)
def test_bad_config_values_raise_config_error(bad):
    with pytest.raises(ConfigError):
        ScanMatchConfig(**bad)


def test_bad_scan_matching_table_in_a_config_file_raises_config_error(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[slam.frontend.scan_matching]\nenabled = true\nmin_overlap = 2.0\n")
    with pytest.raises(ConfigError, match="min_overlap"):
        RunConfig.from_toml(path)
    path.write_text('[slam.frontend.scan_matching]\ncontradicted_spread = "both"\n')
    with pytest.raises(ConfigError, match="contradicted_spread"):
        RunConfig.from_toml(path)
    # the opt-in is read from a file
    path.write_text('[slam.frontend.scan_matching]\ncontradicted_spread = "slip"\n')
    cfg = RunConfig.from_toml(path)
    assert cfg.slam.frontend.scan_matching.contradicted_spread == "slip"
    # the former key says what replaced it
    path.write_text("[slam.frontend.scan_matching]\nenabled = true\nnormal_points = 5\n")
    with pytest.raises(ConfigError, match=r"normal_points.*replaced by normal_span_rad"):
        RunConfig.from_toml(path)


# --------------------------------------------------------------------------------------------
# 6. pipeline


def _with_scan_matching(**changes: float | str) -> RunConfig:
    """The defaults with ``[slam.frontend.scan_matching]`` values changed."""
    cfg = RunConfig()
    sm = replace(cfg.slam.frontend.scan_matching, **changes)
    return replace(
        cfg, slam=replace(cfg.slam, frontend=replace(cfg.slam.frontend, scan_matching=sm))
    )


def _without_scan_matching(tmp_path: Path) -> RunConfig:
    """The defaults with scan matching off, read from a file as a user writes it."""
    path = tmp_path / "no_scan_matching.toml"
    path.write_text("[slam.frontend.scan_matching]\nenabled = false\n")
    config = RunConfig.from_toml(path)
    assert config.slam.frontend.scan_matching == ScanMatchConfig(enabled=False)
    return config


def _relations_error_m(out: Path) -> float:
    traj = read_tum(out / "trajectory.tum")
    metric = relations_metric(traj, read_relations(DEMO / "relations.txt"))
    assert metric.n_unmatched == 0
    return metric.abs_trans_m.mean


def test_demo_log_with_scan_matching(tmp_path):
    """The defaults match every keyframe after the first against the previous one (the demo's
    scans are all keyframes), few matches are rejected, none finds a slip (the demo's odometry
    has none), and the relations error stays at about 9 mm."""
    assert RunConfig().slam.frontend.scan_matching.enabled
    summary = run_slam(DEMO / "log.clf", tmp_path / "sm", RunConfig())
    assert summary["scan_matches"] == summary["keyframes"] - 1 > 300
    assert summary["scan_matches_rejected"] <= 0.05 * summary["scan_matches"]
    assert summary["scan_match_slips"] == 0
    assert _relations_error_m(tmp_path / "sm") < 0.02


def _nonkeyframe_errors(out: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position and heading errors of the scans that are not keyframes, and their NEES."""
    est = read_tum(out / "trajectory.tum")
    truth = read_tum(DEMO / "ground_truth.tum")
    assert np.allclose(est.timestamps, truth.timestamps)
    keyframe = np.zeros(len(est.timestamps), dtype=bool)
    for line in (out / "graph.g2o").read_text().splitlines():
        if line.startswith("LINESLAM_SCAN "):
            keyframe[np.argmin(np.abs(est.timestamps - float(line.split()[2])))] = True
    _, cov = read_covariances(out / "trajectory_covariance.txt")
    e = pose_log(pose_between(truth.poses, est.poses))[~keyframe]
    nees = np.einsum("ni,ni->n", e, np.linalg.solve(cov[~keyframe], e[..., None])[..., 0])
    return np.hypot(e[:, 0], e[:, 1]), np.abs(e[:, 2]), nees


def test_scans_between_keyframes_matched_against_their_keyframe(tmp_path):
    """With keyframes every 0.6 m, most demo scans are not keyframes.  Matched against their
    keyframe (``between_keyframes``) they end closer to the ground truth than composed from it
    with the odometry (the demo: 4 against 12 mm, 0.4 against 2 mrad)."""
    keyframes = {"min_distance_m": 0.6, "min_angle_rad": 0.45}
    on = RunConfig()  # the default
    assert on.slam.frontend.scan_matching.between_keyframes
    on = replace(on, slam=replace(on.slam, keyframes=replace(on.slam.keyframes, **keyframes)))
    off = _with_scan_matching(between_keyframes=False)
    off = replace(off, slam=replace(off.slam, keyframes=on.slam.keyframes))
    s_off = run_slam(DEMO / "log.clf", tmp_path / "off", off)
    s_on = run_slam(DEMO / "log.clf", tmp_path / "on", on)
    assert s_off["scan_matches_between"] == 0
    n_between = s_on["scans"] - s_on["keyframes"]
    assert s_on["keyframes"] == s_off["keyframes"] and n_between > 150
    assert s_on["scan_matches_between"] + s_on["scan_matches_between_rejected"] == n_between
    assert s_on["scan_matches_between"] >= 0.9 * n_between
    xy_off, th_off, nees_off = _nonkeyframe_errors(tmp_path / "off")
    xy_on, th_on, nees_on = _nonkeyframe_errors(tmp_path / "on")
    assert xy_on.mean() < 0.5 * xy_off.mean() and th_on.mean() < 0.5 * th_off.mean()
    # the simulator's walls are exact: the matches' 2 cm model error (model_sigma_m) makes
    # their covariances conservative, as the odometry's are here; never over-confident
    assert 0.2 < nees_on.mean() < 3.0 and 0.2 < nees_off.mean() < 3.0, (nees_on, nees_off)


def test_scaling_the_points_information_of_a_posterior():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    info_points = a @ a.T + 0.1 * np.eye(3)
    prior = np.linalg.inv(b @ b.T + 0.1 * np.eye(3))
    post = np.linalg.inv(info_points + np.linalg.inv(prior))
    for factor in (0.5, 1.0):  # the points are not said to scatter less than modelled
        np.testing.assert_array_equal(scale_points_information(post, prior, factor), post)
    scaled = scale_points_information(post, prior, 4.0)
    expected = np.linalg.inv(info_points / 4.0 + np.linalg.inv(prior))
    np.testing.assert_allclose(scaled, expected, rtol=1e-9)
    np.testing.assert_allclose(scaled, scaled.T, rtol=0, atol=1e-15)
    # between the posterior and the prior
    assert np.all(np.linalg.eigvalsh(scaled - post) > 0)
    assert np.all(np.linalg.eigvalsh(prior - scaled) > 0)


def test_scans_between_keyframes_carry_the_points_noise_the_run_measures(tmp_path, monkeypatch):
    """With the fits' range noise stated at half the simulator's, the demo's points scatter
    about twice as much as the noise model says (``range_noise``); the matched scans between
    keyframes then carry the points' information divided by that ratio squared, and their
    NEES is lower than with the match's covariance as computed."""
    import slam.line_slam.pipeline as pipeline

    keyframes = {"min_distance_m": 0.6, "min_angle_rad": 0.45}
    cfg = _with_scan_matching(between_keyframes=True)
    noise = replace(cfg.linefit.noise, sigma_range_m=0.5 * cfg.linefit.noise.sigma_range_m)
    cfg = replace(
        cfg,
        linefit=replace(cfg.linefit, noise=noise),
        slam=replace(cfg.slam, keyframes=replace(cfg.slam.keyframes, **keyframes)),
    )
    s_scaled = run_slam(DEMO / "log.clf", tmp_path / "scaled", cfg)
    assert s_scaled["range_noise"]["sigma_ratio"] > 1.5
    monkeypatch.setattr(pipeline, "scale_points_information", lambda post, prior, f: post)
    s_plain = run_slam(DEMO / "log.clf", tmp_path / "plain", cfg)
    assert s_plain["scan_matches_between"] == s_scaled["scan_matches_between"] > 150
    xy_s, _, nees_scaled = _nonkeyframe_errors(tmp_path / "scaled")
    xy_p, _, nees_plain = _nonkeyframe_errors(tmp_path / "plain")
    np.testing.assert_array_equal(xy_s, xy_p)  # the estimates are the same
    assert nees_scaled.mean() < 0.9 * nees_plain.mean(), (nees_scaled.mean(), nees_plain.mean())


def test_scan_matching_can_be_turned_off(tmp_path):
    summary = run_slam(
        DEMO / "log.clf", tmp_path / "off", _without_scan_matching(tmp_path), max_scans=40
    )
    assert summary["scan_matches"] == 0 and summary["scan_matches_rejected"] == 0
    assert summary["scan_match_slips"] == 0


# --------------------------------------------------------------------------------------------
# 7. a slip in a log


def _slipped_log(source: Path, target: Path, at_scan: int, angle_rad: float) -> None:
    """``source`` with every odometry pose after the ``at_scan``-th ``FLASER`` line rotated by
    ``angle_rad`` about the robot's position at that scan (an odometry heading slip)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    centre: tuple[float, float] | None = None

    def rotated(tokens: list[str], start: int) -> None:
        assert centre is not None
        x, y, th = (float(v) for v in tokens[start : start + 3])
        dx, dy = x - centre[0], y - centre[1]
        new = (centre[0] + c * dx - s * dy, centre[1] + s * dx + c * dy, th + angle_rad)
        tokens[start : start + 3] = [f"{v:.6f}" for v in new]

    scan = -1
    out = []
    for line in source.read_text().splitlines():
        tokens = line.split()
        if tokens and tokens[0] == "FLASER":
            scan += 1
            n = int(tokens[1])
            if scan == at_scan:  # laser pose at 2 + n, odometry pose at 5 + n
                centre = (float(tokens[5 + n]), float(tokens[6 + n]))
            elif centre is not None:
                rotated(tokens, 2 + n)
                rotated(tokens, 5 + n)
                line = " ".join(tokens)
        elif tokens and tokens[0] == "ODOM" and centre is not None:
            rotated(tokens, 1)
            line = " ".join(tokens)
        out.append(line)
    assert centre is not None
    target.write_text("\n".join(out) + "\n")


def _final_heading_error_rad(out: Path) -> float:
    """Heading change start → end of the run against the ground truth's (frame-free)."""
    traj = read_tum(out / "trajectory.tum")
    truth = read_tum(DEMO / "ground_truth.tum")
    np.testing.assert_allclose(traj.timestamps, truth.timestamps)
    turned = traj.poses[-1, 2] - traj.poses[0, 2]
    return abs(_angle(float(turned - (truth.poses[-1, 2] - truth.poses[0, 2]))))


def test_scan_matching_corrects_a_heading_slip_in_the_demo_log(tmp_path):
    """A 20° odometry slip at scan 200 (of 383; before the loop is closed): without scan
    matching the slip goes uncorrected, the loop is not closed and the run ends 20° off; with
    it the points see the slip and the final heading error stays at the clean run's (0.01°).
    (A slip at scan 100 or 300 is repaired by the loop closure even without scan matching.)"""
    log = tmp_path / "slip.clf"
    _slipped_log(DEMO / "log.clf", log, at_scan=200, angle_rad=np.deg2rad(20.0))
    run_slam(log, tmp_path / "without", _without_scan_matching(tmp_path))
    summary = run_slam(log, tmp_path / "with", RunConfig())
    assert summary["scan_match_slips"] == 1  # that step's factor is the match
    without = _final_heading_error_rad(tmp_path / "without")
    with_sm = _final_heading_error_rad(tmp_path / "with")
    assert without > np.deg2rad(10.0)
    assert with_sm < np.deg2rad(0.2)


def test_a_slip_the_points_do_not_settle_centres_the_step_with_the_slip_spread(tmp_path):
    """The demo's 20° slip at scan 200 with no match trusted (``min_overlap = 0.99``: 359 of
    382 matches rejected).  The slip's step is the only one whose rejected match finds a
    slip (``contradicted``); its odometry factor is centred on the match with the slip
    component's covariance: the run ends within 0.2° of the truth's heading, where without the
    slip mixture (``slip_probability = 0``: nothing is flagged, the step keeps the odometry)
    it ends 20° off."""
    log = tmp_path / "slip.clf"
    _slipped_log(DEMO / "log.clf", log, at_scan=200, angle_rad=np.deg2rad(20.0))
    summary = run_slam(log, tmp_path / "doubted", _with_scan_matching(min_overlap=0.99))
    assert summary["scan_matches_rejected"] > 0.9 * summary["scan_matches"]
    assert summary["scan_match_slips"] == 0
    assert summary["scan_match_contradictions"] == 1
    assert _final_heading_error_rad(tmp_path / "doubted") < np.deg2rad(0.2)
    cfg0 = _with_scan_matching(min_overlap=0.99, slip_probability=0.0)
    assert run_slam(log, tmp_path / "trusted", cfg0)["scan_match_contradictions"] == 0
    assert _final_heading_error_rad(tmp_path / "trusted") > np.deg2rad(10.0)


def test_a_scan_between_keyframes_whose_refinement_fails_is_searched(tmp_path, monkeypatch):
    """The demo's odometry slipping 30° at scan 200, with keyframes every 0.6 m or 1 rad.
    The two scans between the slip and the next keyframe start their refinement 30° off,
    beyond its reach, and it is not accepted; each is then searched as a keyframe is and ends
    within 0.5° of the ground truth's heading (the demo: 0.1°; without any search, placed with
    the odometry and the next keyframe's correction shared along the stretch, 17° and 9°).
    The next keyframe's slip does not search them again."""
    import slam.line_slam.pipeline as pipeline

    log = tmp_path / "slip.clf"
    _slipped_log(DEMO / "log.clf", log, at_scan=200, angle_rad=np.deg2rad(30.0))
    cfg = RunConfig()
    kf = replace(cfg.slam.keyframes, min_distance_m=0.6, min_angle_rad=1.0)
    cfg = replace(cfg, slam=replace(cfg.slam, keyframes=kf))
    truth = read_tum(DEMO / "ground_truth.tum")

    def heading_errors_deg(out: Path) -> np.ndarray:
        est = read_tum(out / "trajectory.tum")
        return np.rad2deg(np.abs(pose_log(pose_between(truth.poses, est.poses))[:, 2]))

    summary = run_slam(log, tmp_path / "default", cfg)
    assert (summary["scan_match_slips"], summary["scan_matches_between_searched"]) == (1, 2)
    assert np.all(heading_errors_deg(tmp_path / "default")[201:203] < 0.5)
    # the two were searched when their refinement failed, not after the slip was found
    monkeypatch.setattr(pipeline.LineSlam, "_research_stretch", lambda self: None)
    summary = run_slam(log, tmp_path / "no_research", cfg)
    assert summary["scan_matches_between_searched"] == 2
    np.testing.assert_array_equal(
        read_tum(tmp_path / "no_research" / "trajectory.tum").poses,
        read_tum(tmp_path / "default" / "trajectory.tum").poses,
    )


def test_scans_between_keyframes_are_searched_again_after_fr079s_slip(shared_data, monkeypatch):
    """fr079 from 2195 to 2212.5 s, fed to :class:`LineSlam` (80 scans): the wheel odometry
    misreports the turns of two relations by 18° (``FR079_SLIPS``).  The scans between the
    keyframes are refined from the odometry and accepted, 18° off; the next keyframe's match
    finds the slip, and matched again with the search they are within 1° of both relations'
    heading change (fr079: 21.7° against 21.6°, −35.9° against −36.2°); without the second
    search 3.9° and −18.1°."""
    import slam.line_slam.pipeline as pipeline
    from slam.io.carmen import iter_scans

    log = shared_data / "fr079" / "fr079.clf"
    rows = read_relations(shared_data / "fr079" / "fr079.relations")
    scans = [s for s in iter_scans(log) if 2195.0 < s.timestamp < 2212.5]

    def heading_errors_deg() -> list[float]:
        slam = pipeline.LineSlam()
        for scan in scans:
            slam.add_scan(scan)
        result = slam.result()
        stamps, poses = result.timestamps, result.poses_world_laser
        errors = []
        for t0, t1 in (FR079_SLIPS[0], FR079_SLIPS[1]):
            i, j = (int(np.argmin(abs(stamps - t))) for t in (t0, t1))
            (row,) = np.flatnonzero(np.isclose(rows.t1, t0) & np.isclose(rows.t2, t1))
            turned = pose_between(poses[i], poses[j])[2]
            errors.append(abs(np.rad2deg(_angle(turned - rows.poses[row, 2]))))
        return errors

    assert max(heading_errors_deg()) < 1.0
    monkeypatch.setattr(pipeline.LineSlam, "_research_stretch", lambda self: None)
    assert min(heading_errors_deg()) > 10.0


# fr079: three relations over which the wheel odometry misreports a turn (t1, t2)
FR079_SLIPS = [
    (2203.410566, 2205.330253),  # odometry +3.3°, relation +21.6°
    (2207.250364, 2211.940507),  # odometry −22.4°, relation −36.2°
    (2211.940507, 2213.010825),  # odometry −12.9°, relation −35.6°
]


def test_slip_mixture_recovers_the_turns_fr079s_odometry_misreports(shared_data):
    """Three relations of fr079 where the wheel odometry misreports a turn by 14-23°.  The
    scans at the two ends matched with the odometry as the prior: with the slip mixture each
    is flagged as a slip and within 1° of the relation's heading change; with the Gaussian
    prior alone (``slip_probability = 0``) the first stays within 4° of the odometry."""
    from slam.io.carmen import iter_scans

    rows = read_relations(shared_data / "fr079" / "fr079.relations")
    log = shared_data / "fr079" / "fr079.clf"
    scans = [s for s in iter_scans(log) if 2203.0 < s.timestamp < 2214.0]
    stamps = np.array([s.timestamp for s in scans])
    cfg = ScanMatchConfig(slip_probability=0.01)
    motion = MotionNoiseConfig()

    def points(scan):
        return scan_points(scan.ranges, scan.bearings, scan.max_range_m, NOISE, cfg)

    for k, (t0, t1) in enumerate(FR079_SLIPS):
        (row,) = np.flatnonzero(np.isclose(rows.t1, t0) & np.isclose(rows.t2, t1))
        turned = float(rows.poses[row, 2])
        a = scans[int(np.argmin(abs(stamps - t0)))]
        b = scans[int(np.argmin(abs(stamps - t1)))]
        assert abs(a.timestamp - t0) < 1e-3 and abs(b.timestamp - t1) < 1e-3
        delta0 = pose_between(a.pose_odom_laser, b.pose_odom_laser)
        assert abs(_angle(delta0[2] - turned)) > np.deg2rad(13.0)  # the odometry's slip
        prior = motion.covariance(delta0)
        m = match_scans(points(a), points(b), delta0, prior, cfg)
        assert m.accepted and m.slip
        assert abs(_angle(m.delta[2] - turned)) < np.deg2rad(1.0), np.rad2deg(m.delta[2])
        if k == 0:
            g = match_scans(points(a), points(b), delta0, prior, replace(cfg, slip_probability=0.0))
            assert abs(_angle(g.delta[2] - delta0[2])) < np.deg2rad(4.0)


def _odometry_edges(out: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The run's odometry factors from ``graph.g2o``: time stamps of both keyframes ``(m, 2)``,
    measurements ``(m, 3)`` and the heading's standard deviation ``(m,)``."""
    stamps: dict[int, float] = {}
    edges = []
    for line in (out / "graph.g2o").read_text().splitlines():
        f = line.split()
        if f[0] == "LINESLAM_SCAN":
            stamps[int(f[1])] = float(f[2])
        elif f[0] == "EDGE_SE2":
            edges.append([float(v) for v in f[1:]])
    e = np.array(edges)
    info = np.zeros((e.shape[0], 3, 3))
    iu = np.triu_indices(3)
    info[:, iu[0], iu[1]] = e[:, 5:]
    info = info + np.triu(info, 1).transpose(0, 2, 1)
    sigma_theta = np.sqrt(np.linalg.inv(info)[:, 2, 2])
    t = np.array([[stamps[int(i)], stamps[int(j)]] for i, j in e[:, :2]])
    return t, e[:, 2:5], sigma_theta


@pytest.mark.parametrize(("spread", "slip_deg"), [("slip", 20.0), ("disagreement", 11.0)])
def test_a_contradicted_step_is_the_match_in_the_graph(tmp_path, spread, slip_deg):
    """The same slip and untrusted matches: of the run's odometry factors exactly one turns
    more than 10° away from the logged odometry, the contradicted step's; it turns as the
    ground truth does (within 1°, where the log is 20° (11°) off), centred where the points
    put it, by default with a heading spread as wide as its disagreement with the odometry
    (:func:`contradicted_covariance`: the odometry's heading one standard deviation away), or
    with ``contradicted_spread = "slip"`` the slip component's (at least ``slip_sigma_rad``,
    0.35 rad: as uncertain as a slip)."""
    log = tmp_path / "slip.clf"
    _slipped_log(DEMO / "log.clf", log, at_scan=200, angle_rad=np.deg2rad(slip_deg))
    cfg = _with_scan_matching(min_overlap=0.99, contradicted_spread=spread)
    summary = run_slam(log, tmp_path / "doubted", cfg)
    assert summary["scan_match_contradictions"] == 1
    t, z, sigma_theta = _odometry_edges(tmp_path / "doubted")
    truth, logged = read_tum(DEMO / "ground_truth.tum"), scan_trajectory(log, frame="laser")

    def turn(traj, when):
        i = np.searchsorted(traj.timestamps, when - 1e-6)
        np.testing.assert_allclose(traj.timestamps[i], when, atol=1e-5)
        return pose_between(traj.poses[i[:, 0]], traj.poses[i[:, 1]])[:, 2]

    off_log = np.abs(np.remainder(z[:, 2] - turn(logged, t) + np.pi, 2.0 * np.pi) - np.pi)
    (k,) = np.flatnonzero(off_log > np.deg2rad(10.0))
    assert off_log[k] == pytest.approx(np.deg2rad(slip_deg), abs=np.deg2rad(1.0))
    assert abs(_angle(float(z[k, 2] - turn(truth, t)[k]))) < np.deg2rad(1.0)
    spread_rad = (
        RunConfig().slam.frontend.scan_matching.slip_sigma_rad
        if spread == "slip"
        else float(off_log[k])
    )
    assert spread_rad <= sigma_theta[k] < 1.1 * spread_rad
    assert np.all(np.delete(sigma_theta, k) < 0.5 * spread_rad)


def test_a_robot_standing_still_keeps_a_bounded_stretch_of_scans():
    """A robot that stands still makes no keyframe: its scans between keyframes are matched,
    and the points kept for a search after a slip are the latest ``MAX_STRETCH_SCANS``."""
    import slam.line_slam.pipeline as pipeline
    from slam.io.carmen import iter_scans

    first = next(iter(iter_scans(DEMO / "log.clf")))
    slam = pipeline.LineSlam()
    n = pipeline.MAX_STRETCH_SCANS + 40
    for k in range(n + 1):
        slam.add_scan(replace(first, timestamp=first.timestamp + 0.1 * k))
    assert slam.counters["scan_matches_between"] == n  # every one matched, none a keyframe
    assert len(slam._stretch) == pipeline.MAX_STRETCH_SCANS
    assert slam._stretch[-1].scan_no == n  # the latest kept


def test_grid_nearest_point_is_the_brute_force_nearest_within_reach():
    """The grid's query (cells of side ``cell``, reach ``d_max ≤ cell``) finds the point a
    search over all points finds, and none when no point is within reach, wherever the
    points and queries lie (columns empty, outside the grid, many points in one cell)."""
    from slam.frontend.scan_match import _grid, _nearest

    rng = np.random.default_rng(7)
    checked = found = 0
    for trial in range(300):
        m = int(rng.integers(1, 150))
        spread = [0.2, 2.0, 40.0][trial % 3]
        p = rng.normal(0.0, spread, (m, 2)) + rng.normal(0.0, 30.0, 2)
        cell = float(rng.choice([0.05, 0.3, 1.0]))
        keys, order, columns = _grid(p, cell)
        queries = p[rng.integers(0, m, 20)] + rng.normal(0.0, cell, (20, 2))
        for qx, qy in queries:
            for d_max in (cell, 0.4 * cell):
                d = np.hypot(p[:, 0] - qx, p[:, 1] - qy)
                expected = int(np.argmin(d)) if d.min() <= d_max else -1
                got = _nearest(qx, qy, p, keys, order, columns, cell, d_max)
                assert got == expected, (trial, qx, qy, d_max)
                checked += 1
                found += got >= 0
    assert 0.2 * checked < found < checked  # both outcomes exercised
