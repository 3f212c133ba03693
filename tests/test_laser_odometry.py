"""Logs without odometry: laser odometry from the scans, and when a log needs it."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from carmen_lines import flaser, odom

from slam.config import RunConfig
from slam.errors import ConfigError
from slam.experiments.robustness import FreezeOdometry, rewrite_lines
from slam.frontend.laser_odometry import LaserOdometry, LaserOdometryConfig
from slam.geometry import pose_between, pose_compose, pose_exp, pose_log
from slam.inputs import InputWarning, ScannerConfig, open_log
from slam.io.tum import read_tum
from slam.line_slam.config import KeyframeConfig
from slam.line_slam.keyframes import KeyframeTrack
from slam.runner import run_slam
from slam.sim.raycast import cast_scan
from slam.sim.world import WorldBuilder
from slam.types import Scan

REPO_ROOT = Path(__file__).resolve().parents[1]
DEMO = REPO_ROOT / "datasets" / "sim" / "demo"


def _relative_errors(poses: np.ndarray, truth: np.ndarray, k: int) -> np.ndarray:
    """Translation error (m) of every relative pose ``k`` scans apart."""
    e = pose_log(
        pose_between(pose_between(truth[:-k], truth[k:]), pose_between(poses[:-k], poses[k:]))
    )
    return np.hypot(e[:, 0], e[:, 1])


def _demo_flaser_rewritten(path: Path, edit: Callable[[list[str], int], None]) -> Path:
    """The demo log at ``path``, ``edit(tokens, n_beams)`` applied to each FLASER line."""
    lines = []
    for line in DEMO.joinpath("log.clf").read_text().splitlines():
        tokens = line.split()
        if tokens and tokens[0] == "FLASER":
            edit(tokens, int(tokens[1]))
            line = " ".join(tokens)
        lines.append(line + "\n")
    path.write_text("".join(lines))
    return path


def _frozen_demo(tmp_path: Path) -> Path:
    lines = DEMO.joinpath("log.clf").read_text().splitlines()
    path = tmp_path / "frozen.clf"
    path.write_text("".join(rewrite_lines(FreezeOdometry(), lines, "log.clf")))
    return path


def test_laser_odometry_on_the_demo_beats_its_odometry_against_the_ground_truth():
    """The scans alone give the demo's motion to millimetres, where its wheels drift by 1 %."""
    log = open_log(DEMO / "log.clf", ScannerConfig(odometry_source="log"))
    laser = LaserOdometry()
    poses = np.array([laser.add(scan) for scan in log.scans()])
    truth = read_tum(DEMO / "ground_truth.tum").poses
    wheels = read_tum(DEMO / "odometry.tum").poses
    assert laser.unmatched == 0
    for k in (1, 10):
        ours = _relative_errors(poses, truth, k).mean()
        theirs = _relative_errors(wheels, truth, k).mean()
        assert ours < 0.01
        assert ours < 0.5 * theirs


def test_last_points_are_the_points_the_scan_was_matched_with():
    """``last_points`` (what :mod:`slam.inputs` tests the overlap with) are the points of the
    scan just added, as :meth:`LaserOdometry.points` makes them, and None before any scan."""
    log = open_log(DEMO / "log.clf", ScannerConfig(odometry_source="log"))
    laser = LaserOdometry()
    assert laser.last_points is None
    for i, scan in enumerate(log.scans()):
        laser.add(scan)
        got, want = laser.last_points, laser.points(scan)
        assert got is not None
        np.testing.assert_array_equal(got.xy, want.xy)
        np.testing.assert_array_equal(got.normals, want.normals)
        if i == 3:
            break


def test_laser_odometry_config_is_validated():
    with pytest.raises(ConfigError, match="sigma_xy_m"):
        LaserOdometryConfig(sigma_xy_m=0.0)


def test_freeze_odometry_keeps_the_first_pose_and_the_laser_offset():
    base = [(0.1 * i, 0.02 * i, 0.05 * i) for i in range(4)]
    laser = [tuple(pose_compose(np.array(b), np.array([0.2, 0.0, 0.0]))) for b in base]
    src = []
    for i in range(4):
        src.append(odom(base[i], 9.5 + i, tv=0.3, rv=0.1))
        src.append(flaser([1.0] * 5, laser[i], base[i], 10.0 + i))
    out = rewrite_lines(FreezeOdometry(), src)
    for line in out:
        tokens = line.split()
        if tokens[0] == "ODOM":
            assert [float(v) for v in tokens[1:6]] == [0.0, 0.0, 0.0, 0.0, 0.0]
        else:
            np.testing.assert_allclose([float(v) for v in tokens[7:13]], [0.2, 0, 0, 0, 0, 0])
            assert len(tokens) == 16


def test_a_log_whose_odometry_never_moves_gets_laser_odometry(tmp_path):
    frozen = _frozen_demo(tmp_path)
    log = open_log(frozen)
    with pytest.warns(InputWarning, match="never moves while its scans move"):
        poses = np.array([log.policy.pose_odom_laser(s) for s in log.scans()])
    assert log.describe()["odometry_source"] == "scan_matching"
    truth = read_tum(DEMO / "ground_truth.tum").poses
    assert _relative_errors(poses, truth, 10).mean() < 0.01
    # told to take the log's odometry as it is, the scans stay where the log puts them
    as_logged = open_log(frozen, ScannerConfig(odometry_source="log"))
    still = np.array([as_logged.policy.pose_odom_laser(s) for s in as_logged.scans()])
    assert np.ptp(still, axis=0).max() == 0.0
    assert as_logged.describe()["odometry_source"] == "log"


def test_a_log_with_odometry_reads_the_same_whatever_the_source_setting():
    """``auto`` holds back the first scans while the odometry stands still, then passes all."""
    auto = open_log(DEMO / "log.clf")
    logged = open_log(DEMO / "log.clf", ScannerConfig(odometry_source="log"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        a = list(auto.scans())
    b = list(logged.scans())
    assert len(a) == len(b)
    for s, t in zip(a, b, strict=True):
        assert s.index == t.index
        np.testing.assert_array_equal(s.pose_odom_laser, t.pose_odom_laser)
        np.testing.assert_array_equal(s.ranges, t.ranges)
    assert auto.describe()["odometry_source"] == "log"


def test_slam_on_a_laser_only_log(tmp_path):
    """The demo with its odometry frozen: lineslam on its scans alone stays near the truth."""
    frozen = _frozen_demo(tmp_path)
    run_slam(frozen, tmp_path / "out", RunConfig())
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert any("never moves" in str(w) for w in summary["warnings"])
    assert summary["input"]["odometry_source"] == "scan_matching"
    assert summary["input"]["laser_odometry_scans"]["unmatched"] == 0
    assert summary["input"]["laser_odometry_scans"]["rescued"] == 0
    poses = read_tum(tmp_path / "out" / "trajectory.tum").poses
    truth = read_tum(DEMO / "ground_truth.tum").poses
    assert _relative_errors(poses, truth, 10).mean() < 0.01
    # the frozen odometry as it is leaves every scan at the first pose: far from the truth
    assert _relative_errors(np.zeros_like(truth), truth, 10).mean() > 0.1


def test_a_log_whose_laser_poses_stand_still_reads_its_odometry_poses(tmp_path):
    """FLASER ``x y θ`` all zero, ``odom_x odom_y odom_θ`` moving: the odometry poses are read."""

    def still(tokens: list[str], n: int) -> None:
        tokens[2 + n : 5 + n] = ["0.000000"] * 3

    path = _demo_flaser_rewritten(tmp_path / "still_laser.clf", still)
    log = open_log(path)
    with pytest.warns(InputWarning, match="laser poses never move while its odometry"):
        poses = np.array([log.policy.pose_odom_laser(s) for s in log.scans()])
    demo = open_log(DEMO / "log.clf")
    expected = np.array([demo.policy.pose_odom_laser(s) for s in demo.scans()])
    np.testing.assert_allclose(poses, expected, atol=1e-9)  # the demo's laser is its base
    described = log.describe()
    assert described["odometry_source"] == "log"
    assert described["laser_odometry"] == "base"


def _mirrored_demo(tmp_path: Path) -> Path:
    """The demo with every scan's readings in reverse order (a scanner mounted upside down)."""

    def reverse(tokens: list[str], n: int) -> None:
        tokens[2 : 2 + n] = tokens[2 : 2 + n][::-1]

    return _demo_flaser_rewritten(tmp_path / "mirrored.clf", reverse)


def test_scans_that_turn_against_the_odometry_are_reported_and_a_negative_step_reads_them(
    tmp_path,
):
    mirrored = _mirrored_demo(tmp_path)
    run_slam(mirrored, tmp_path / "as_is", RunConfig())
    summary = json.loads((tmp_path / "as_is" / "summary.json").read_text())
    assert any("turn against the odometry" in str(w) for w in summary["warnings"])
    turns, against = summary["scan_match_turns"], summary["scan_match_turns_against"]
    assert turns >= 10 and against > 0.9 * turns
    # stated as it is (reversed, the first beam is the demo's last, at +89°, clockwise): the
    # demo's own result
    stated = RunConfig(scanner=ScannerConfig(first_angle_deg=89.0, step_deg=-1.0))
    run_slam(mirrored, tmp_path / "stated", stated)
    summary = json.loads((tmp_path / "stated" / "summary.json").read_text())
    assert not any("turn against the odometry" in str(w) for w in summary["warnings"])
    assert summary["scan_match_turns_against"] < 0.1 * summary["scan_match_turns"]
    poses = read_tum(tmp_path / "stated" / "trajectory.tum").poses
    truth = read_tum(DEMO / "ground_truth.tum").poses
    assert _relative_errors(poses, truth, 10).mean() < 0.01


def test_a_zero_step_is_refused():
    with pytest.raises(ConfigError, match="step_deg must not be 0"):
        ScannerConfig(step_deg=0.0)


def test_a_bag_without_odometry_gets_laser_odometry(tmp_path):
    from test_inputs import write_demo_bag

    bag = tmp_path / "no_odometry.bag"
    write_demo_bag(bag, 1, np.zeros(3), 60, tf_odometry=False, odometry=False)
    with pytest.warns(InputWarning, match="no odometry .*laser odometry"):
        log = open_log(bag)
    with pytest.warns(InputWarning, match="is absent while its scans move"):
        poses = np.array([log.policy.pose_odom_laser(s) for s in log.scans()])
    assert log.describe()["odometry_source"] == "scan_matching"
    truth = read_tum(DEMO / "ground_truth.tum").poses[: len(poses)]
    assert len(poses) == 60
    assert _relative_errors(poses, truth, 10).mean() < 0.01


def _room_scans(turn_rad: float, gap_s: float) -> tuple[list[Scan], np.ndarray]:
    """Scans of a 360° scanner in an L-shaped room: ten steps forward 10 scans/s, then after
    ``gap_s`` a scan turned in place by ``turn_rad``, then ten steps forward again."""
    b = WorldBuilder()
    b.polyline([(0, 0), (10, 0), (10, 4), (6, 4), (6, 8), (0, 8)], closed=True)
    b.box(2.0, 1.0, 1.0, 0.6)
    b.rotated_box(7.5, 2.0, 0.8, 0.5, 0.4, "box")
    b.box(1.0, 5.5, 0.7, 1.2)
    world = b.build("room")
    bearings = np.deg2rad(np.arange(360.0) - 180.0)
    forward = np.array([0.05, 0.0, 0.02])
    poses, times = [np.array([3.0, 3.0, 0.2])], [0.0]
    for i in range(21):
        step, dt = (np.array([0.0, 0.0, turn_rad]), gap_s) if i == 10 else (forward, 0.1)
        poses.append(pose_compose(poses[-1], step))
        times.append(times[-1] + dt)
    scans = [
        Scan(i, t, cast_scan(p, bearings, world, 30.0)[0], bearings, max_range_m=30.0)
        for i, (p, t) in enumerate(zip(poses, times, strict=True))
    ]
    return scans, np.array(poses)


def test_a_turn_across_a_gap_is_found_over_every_heading():
    """3 s without scans, during which the robot turned 80° in place: beyond the search
    around the constant-velocity prediction, so the scan would stay at the prediction, 80°
    off from there on; the search over every heading registers it (the room has one
    solution) and the laser odometry keeps the true motion to the end.  With the search off
    (``any_heading_probability = 1``) the heading is lost."""
    scans, truth = _room_scans(1.4, 3.0)
    laser = LaserOdometry()
    poses = np.array([laser.add(s) for s in scans])
    assert laser.rescued == 1 and laser.unmatched == 0
    end = pose_log(pose_between(pose_between(truth[0], truth[-1]), poses[-1]))
    assert np.hypot(end[0], end[1]) < 0.01 and abs(end[2]) < 0.005
    blind = LaserOdometry(LaserOdometryConfig(any_heading_probability=1.0))
    poses = np.array([blind.add(s) for s in scans])
    assert blind.rescued == 0 and blind.unmatched >= 1
    end = pose_log(pose_between(pose_between(truth[0], truth[-1]), poses[-1]))
    assert abs(end[2]) > 0.5


def test_a_corridor_seen_both_ways_after_a_gap_is_not_rescued():
    """In a corridor a turn of a quarter fits every point as well as its half-turn twin: the
    search around the prediction reaches neither, the search over every heading finds both,
    neither probable enough, and the scan stays at the prediction."""
    b = WorldBuilder()
    b.segment((-200.0, -1.1), (200.0, -1.1))
    b.segment((-200.0, 1.1), (200.0, 1.1))
    world = b.build("corridor")
    bearings = np.deg2rad(np.arange(360.0) - 180.0)
    poses = [np.array([0.0, 0.0, 0.0]), np.array([0.1, 0.0, 0.0]), np.array([0.2, 0.0, 1.57])]
    scans = [
        Scan(i, t, cast_scan(p, bearings, world, 30.0)[0], bearings, max_range_m=30.0)
        for i, (p, t) in enumerate(zip(poses, (0.0, 0.1, 3.1), strict=True))
    ]
    laser = LaserOdometry()
    for s in scans:
        laser.add(s)
    assert laser.unmatched == 1 and laser.rescued == 0


def _door_corridor_scans(
    seed: int, quantum_m: float, n: int = 200, step_m: float = 0.15
) -> tuple[list[Scan], np.ndarray]:
    """A robot driving along a corridor 2.2 m wide with a door recess every few metres.

    180 beams at 1°, ranges with 5 mm of noise, written in steps of ``quantum_m`` (as ACES's
    are, in steps of about 5 cm); steps of ``step_m`` ± 20 %, 5 scans/s.
    """
    rng = np.random.default_rng(seed)
    b = WorldBuilder()
    for side in (-1.0, 1.0):
        y, x = 1.1 * side, -5.0
        corners = [(x, y)]
        k = 0 if side < 0 else 1
        while x < 45.0:
            x0 = x + (3.7 if k % 2 == 0 else 1.85)
            corners += [(x0, y), (x0, y + 0.3 * side), (x0 + 0.9, y + 0.3 * side), (x0 + 0.9, y)]
            x, k = x0 + 0.9, k + 1
        corners.append((50.0, y))
        b.polyline(corners)
    world = b.build("corridor with doors")
    bearings = np.deg2rad(np.arange(-89.5, 90.0, 1.0))
    poses = [np.zeros(3)]
    for i in range(1, n):
        x = poses[-1][0] + step_m * (1.0 + 0.2 * rng.standard_normal())
        poses.append(np.array([x, 0.1 * np.sin(0.05 * i), 0.02 * np.cos(0.05 * i)]))
    scans = []
    for i, p in enumerate(poses):
        r = cast_scan(p, bearings, world, 30.0)[0] + rng.normal(0.0, 0.005, bearings.size)
        r = np.round(r / quantum_m) * quantum_m + 0.01
        scans.append(Scan(i, 0.2 * i, r, bearings, max_range_m=30.0))
    return scans, np.array(poses)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_corridor_in_coarse_ranges_is_followed_against_the_local_map(seed):
    """Ranges written in 5 cm steps along a corridor: scan to scan, with each point's line
    through its nearest few points, the steps read as walls across the corridor and the
    laser odometry stalls and jumps (0.4-0.8 m of error over 10 scans); against the local
    map of the last metre of key scans with lines extended along the walls (the defaults) it
    keeps to about a centimetre.  Either alone errs at least half as much again (0.03-0.56 m
    on these two seeds)."""
    scans, truth = _door_corridor_scans(seed, quantum_m=0.05)

    def drift(config: LaserOdometryConfig) -> float:
        laser = LaserOdometry(config)
        poses = np.array([laser.add(s) for s in scans])
        return float(np.sqrt(np.mean(_relative_errors(poses, truth, 10) ** 2)))

    ours = drift(LaserOdometryConfig())
    scan_to_scan = drift(LaserOdometryConfig(map_path_m=0.0, map_turn_rad=0.0, normal_length_m=0.0))
    short_lines = drift(LaserOdometryConfig(normal_length_m=0.0))
    one_scan = drift(LaserOdometryConfig(map_path_m=0.0, map_turn_rad=0.0))
    assert ours < 0.03
    assert scan_to_scan > 0.2
    assert min(short_lines, one_scan) > 1.5 * ours


def test_the_local_map_loses_nothing_on_fine_ranges():
    """The same corridor with ranges written to the micrometre: both keep to millimetres."""
    scans, truth = _door_corridor_scans(0, quantum_m=1e-6)
    errors = []
    for config in (
        LaserOdometryConfig(),
        LaserOdometryConfig(map_path_m=0.0, map_turn_rad=0.0, normal_length_m=0.0),
    ):
        laser = LaserOdometry(config)
        poses = np.array([laser.add(s) for s in scans])
        errors.append(float(np.sqrt(np.mean(_relative_errors(poses, truth, 10) ** 2))))
    assert errors[0] < 0.01
    assert errors[0] < 1.2 * errors[1]


def test_the_runs_settings_reach_the_laser_odometry(tmp_path):
    """``[scanner.scan_odometry]``, the run's sensor noise and its scan-matcher settings are the
    laser odometry's: a run that asks every match to see all of its points leaves nearly every
    scan at the constant-velocity prediction (the default run leaves none), and the noise and
    matcher settings it is given are those of the run's configuration (with the laser
    odometry's own ``min_overlap`` and ``normal_length_m``)."""
    from dataclasses import replace

    from linefit.config import SensorNoiseConfig
    from slam.config import open_run_log
    from slam.frontend.scan_match import ScanMatchConfig

    frozen = _frozen_demo(tmp_path)
    base = RunConfig()
    strict = replace(
        base,
        scanner=replace(base.scanner, scan_odometry=LaserOdometryConfig(min_overlap=1.0)),
    )
    run_slam(frozen, tmp_path / "strict", strict)
    summary = json.loads((tmp_path / "strict" / "summary.json").read_text())
    counts = summary["input"]["laser_odometry_scans"]
    # (the simulated walls show every point of a few scans: those still match)
    assert counts["unmatched"] > 0.9 * summary["scans"]
    # the config file of the run holds the table and gives it back
    assert RunConfig.from_toml(tmp_path / "strict" / "config.toml") == strict

    noise = SensorNoiseConfig(sigma_range_m=0.02, sigma_bearing_rad=5e-4)
    matching = ScanMatchConfig(rotation_window_rad=0.5, slip_probability=0.05)
    config = replace(
        base,
        linefit=replace(base.linefit, noise=noise),
        slam=replace(base.slam, frontend=replace(base.slam.frontend, scan_matching=matching)),
    )
    opened = open_run_log(frozen, config)
    with pytest.warns(InputWarning, match="never moves"):
        for _ in opened.scans():
            pass
    laser = opened._laser_odometry
    assert laser is not None and laser.matched > 0
    assert laser.noise == noise
    own = LaserOdometryConfig()
    assert laser.matching == replace(
        matching, min_overlap=own.min_overlap, normal_length_m=own.normal_length_m
    )
    # opened without them, the defaults
    plain = open_log(frozen)
    with pytest.warns(InputWarning, match="never moves"):
        for _ in plain.scans():
            pass
    assert plain._laser_odometry.noise == SensorNoiseConfig()


def test_a_robot_standing_in_a_corridor_keeps_its_logged_odometry(shared_data, tmp_path):
    """Intel's first 143 scans, the robot standing in a corridor, with readings beyond 8 m
    removed: the corridor's ends are out of sight, nothing holds the laser odometry along it
    and its constant-velocity prediction carries it more than 0.5 m while the wheels stand
    still.  The first scan still registers every later one where it was, so the log is read
    with its own odometry (taking the drift for motion read the whole log with laser
    odometry: 1.27 m against 0.025 m on the robustness table's row)."""
    import math
    import warnings as warnings_module

    from slam.experiments.robustness import ClipRanges

    lines = (shared_data / "intel" / "intel.clf").read_text().splitlines()[:1200]
    clipped = rewrite_lines(ClipRanges(8.0, 81.83, -math.pi / 2, math.radians(1.0)), lines)
    path = tmp_path / "intel-max8m-start.clf"
    path.write_text("\n".join(clipped) + "\n")
    scans = list(open_log(path, ScannerConfig(odometry_source="log")).scans())
    odometry = np.array([s.pose_odom_laser for s in scans])
    still = int(np.flatnonzero(np.any(np.abs(odometry - odometry[0]) > 1e-9, axis=1))[0])
    assert still >= 100  # the wheels stand still that long
    laser = LaserOdometry()
    drift = max(float(np.hypot(*laser.add(s)[:2])) for s in scans[:still])
    assert drift > 0.5  # the laser odometry alone would have taken it for motion

    opened = open_log(path)
    with warnings_module.catch_warnings():
        warnings_module.simplefilter("error", InputWarning)
        read = list(opened.scans())
    assert opened.odometry_source == "log"
    np.testing.assert_array_equal(
        np.array([s.pose_odom_laser for s in read]), odometry[: len(read)]
    )


def test_the_steps_covariances_compose_to_the_keyframes_as_monte_carlo_says():
    """The keyframe track composes the scans' step covariances (right perturbation, each
    earlier error carried through the later steps): against 20,000 seeded draws of noisy
    steps composed, the covariance of the motion since the keyframe agrees within 5 %."""
    steps = [np.array([0.12, 0.01, 0.25]), np.array([0.10, -0.02, -0.15]), np.array([0.2, 0, 0.4])]
    covs = [np.diag([0.02, 0.01, 0.03]) ** 2, np.diag([0.01, 0.03, 0.02]) ** 2]
    covs.append(np.array([[4e-4, 1e-4, 0.0], [1e-4, 2e-4, 5e-5], [0.0, 5e-5, 9e-4]]))
    track = KeyframeTrack(KeyframeConfig(min_distance_m=10.0, min_angle_rad=10.0))
    pose = np.zeros(3)
    track.end_keyframe(track.step(pose))
    for step, cov in zip(steps, covs, strict=True):
        pose = pose_compose(pose, step)
        out = track.step(pose, cov)
    assert out.cov is not None and not out.keyframe
    rng = np.random.default_rng(7)
    n = 20_000
    drawn = np.zeros((n, 3))
    for step, cov in zip(steps, covs, strict=True):
        noise = rng.multivariate_normal(np.zeros(3), cov, size=n)
        drawn = pose_compose(drawn, pose_compose(np.broadcast_to(step, (n, 3)), pose_exp(noise)))
    errors = pose_log(pose_between(np.broadcast_to(pose, (n, 3)), drawn))
    empirical = np.cov(errors.T)
    scale = np.sqrt(np.outer(np.diag(out.cov), np.diag(out.cov)))
    assert np.max(np.abs(empirical - out.cov) / scale) < 0.05, (empirical, out.cov)
    # a scan without a stated covariance leaves the motion model to give the keyframe's
    pose = pose_compose(pose, steps[0])
    assert track.step(pose).cov is None
    assert track.step(pose_compose(pose, steps[1]), covs[1]).cov is None


def test_laser_odometry_states_each_steps_covariance_and_logged_odometry_none(tmp_path):
    """Scans given the laser odometry's poses carry their match's covariance (positive
    definite, in centimetres and milliradians on the demo's walls); scans whose odometry
    is the log's carry none (the motion model then gives it)."""
    log = open_log(_frozen_demo(tmp_path))
    with pytest.warns(InputWarning, match="never moves while its scans move"):
        scans = list(log.scans())
    covs = [s.odometry_step_cov for s in scans[1:]]
    assert all(c is not None and c.shape == (3, 3) for c in covs)
    sigmas = np.sqrt(np.array([np.diag(c) for c in covs if c is not None]))
    assert np.all(np.linalg.eigvalsh(np.array(covs)) > 0.0)
    assert np.median(sigmas[:, :2]) < 0.05 and np.median(sigmas[:, 2]) < 0.02, np.median(sigmas, 0)
    logged = open_log(DEMO / "log.clf")
    assert all(s.odometry_step_cov is None for s in logged.scans())
