"""The log variants of the robustness table and their scoring, on small constructed logs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from carmen_lines import flaser, odom

from slam.errors import ConfigError, EvaluationError, LogFormatError
from slam.experiments.robustness import (
    EXTRA_VARIANTS,
    VARIANTS,
    BiasOdometry,
    Chain,
    ClipRanges,
    CropFieldOfView,
    DecimateBeams,
    DecimateScans,
    MoveOdometryToCentre,
    NoisyOdometry,
    OdometryLag,
    RangeNoise,
    Variant,
    fill_dropped_scans,
    make_variant,
    rewrite_lines,
    score_run,
)
from slam.geometry import pose_between, pose_compose
from slam.io.carmen import CarmenReader, iter_odometry, iter_scans
from slam.io.catalog import load_catalog
from slam.io.relations import read_relations, relations_from_trajectory, write_relations
from slam.io.trajectory import Trajectory

ZERO = (0.0, 0.0, 0.0)


def _log(n_scans: int, poses: np.ndarray | None = None, ranges=None) -> list[str]:
    """ODOM, FLASER, ODOM, FLASER, ... with scan ``i`` at ``t = 10 + i`` and ODOM 0.5 s before."""
    lines = ["# CARMEN Logfile", "# test log"]
    for i in range(n_scans):
        pose = poses[i] if poses is not None else (0.1 * i, 0.0, 0.0)
        r = ranges if ranges is not None else [1.0 + 0.01 * i] * 4
        lines.append(odom(pose, 9.5 + i))
        lines.append(flaser(r, pose, pose, 10.0 + i))
    return lines


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(line if line.endswith("\n") else line + "\n" for line in lines))
    return path


def _laser_stamps(lines: list[str]) -> list[float]:
    return [float(line.split()[-3]) for line in lines if line.startswith("FLASER")]


# --------------------------------------------------------------------------------------------
# decimation of laser lines
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("every", "start"), [(3, 0), (4, 1), (4, 3), (1, 0)])
def test_decimation_keeps_every_kth_laser_line_from_start_and_all_odometry(every, start):
    src = _log(11)
    out = rewrite_lines(DecimateScans(every, start), src)
    kept = _laser_stamps(out)
    assert kept == [10.0 + i for i in range(start, 11, every)]
    odom_in = [line.split() for line in src if line.startswith("ODOM")]
    odom_out = [line.split() for line in out if line.startswith("ODOM")]
    assert odom_out == odom_in  # all 11, unchanged
    # kept laser lines are the source's lines, field for field
    src_lasers = {float(s.split()[-3]): s.split() for s in src if s.startswith("FLASER")}
    for line in out:
        if line.startswith("FLASER"):
            assert line.split() == src_lasers[float(line.split()[-3])]
    assert out[0] == "# CARMEN Logfile\n"


def test_decimation_rejects_a_start_outside_the_period():
    with pytest.raises(ConfigError):
        DecimateScans(4, 4)


def test_transforms_refuse_other_laser_messages():
    line = "ROBOTLASER1 0 -1.5 3.1 0.01 80 0 0 1 1.0 0 0 0 0 0 0 0 0 0 0 0 0 10.0 nohost 10.0"
    with pytest.raises(LogFormatError, match=":1"):
        rewrite_lines(DecimateScans(2), [line])


# --------------------------------------------------------------------------------------------
# readings above 8 m
# --------------------------------------------------------------------------------------------
def test_clipping_changes_exactly_the_readings_above_the_limit(tmp_path):
    ranges = np.array([0.5, 7.99, 8.0, 8.01, 12.34, 50.0, 3.0])
    poses = _wavy_poses(3)
    src = _log(3, poses, ranges=list(ranges))
    clip = ClipRanges(8.0, 50.0, -math.pi / 2, math.radians(30.0))
    path = _write(tmp_path / "clipped.clf", rewrite_lines(clip, src))
    reader = CarmenReader(path)
    scans = list(reader.scans())
    assert reader.stats.laser_type == "ROBOTLASER1" and reader.stats.odometry == 3
    expected = np.where(ranges > 8.0, 50.0, ranges)
    for i, scan in enumerate(scans):
        np.testing.assert_array_equal(scan.ranges, expected)
        assert scan.max_range_m == 50.0  # the log states its no-return value
        np.testing.assert_array_equal(scan.valid_mask(), ranges <= 8.0)
        np.testing.assert_allclose(scan.bearings, np.radians(-90.0 + 30.0 * np.arange(7)))
        assert scan.timestamp == 10.0 + i
        np.testing.assert_allclose(scan.pose_odom_laser, poses[i], atol=1e-6)
        np.testing.assert_allclose(scan.pose_odom_base, poses[i], atol=1e-6)
    # the ODOM lines pass unchanged
    assert [x for x in src if x.startswith("ODOM")] == [
        x.rstrip("\n") for x in rewrite_lines(clip, src) if x.startswith("ODOM")
    ]


def test_range_noise_has_its_stated_spread_and_keeps_no_returns_and_poses(tmp_path):
    # 30 scans of 200 beams: returns at 2 m and 7 m, no-returns (50.0) and zeros in between
    ranges = np.tile([2.0, 7.0, 50.0, 0.0], 50)
    poses = _wavy_poses(30)
    src = _log(30, poses, ranges=list(ranges))
    sigma = 0.02
    noise = RangeNoise(sigma, 50.0, -math.pi / 2, math.radians(0.5), seed=4)
    out = rewrite_lines(noise, src)
    assert out == rewrite_lines(noise, src)
    assert out != rewrite_lines(RangeNoise(sigma, 50.0, -math.pi / 2, math.radians(0.5)), src)
    reader = CarmenReader(_write(tmp_path / "noisy.clf", out))
    scans = list(reader.scans())
    assert reader.stats.laser_type == "ROBOTLASER1" and len(scans) == 30
    got = np.array([s.ranges for s in scans])
    returns = np.broadcast_to(ranges < 50.0, got.shape) & (got > 0)
    np.testing.assert_array_equal(got[:, ranges == 50.0], 50.0)
    np.testing.assert_array_equal(got[:, ranges == 0.0], 0.0)
    err = (got - ranges)[returns]
    assert err.size == 30 * 100
    # sample variance of n normal draws (rounded to the millimetre: + 1/12 mm²)
    var = np.mean(err**2)
    expected = sigma**2 + 1e-6 / 12
    assert abs(var / expected - 1.0) < 5 * math.sqrt(2.0 / err.size)
    assert abs(np.mean(err)) < 5 * sigma / math.sqrt(err.size)
    for i, scan in enumerate(scans):
        assert scan.max_range_m == 50.0 and scan.timestamp == 10.0 + i
        np.testing.assert_allclose(scan.pose_odom_laser, poses[i], atol=1e-6)
        np.testing.assert_allclose(scan.bearings[:2], np.radians([-90.0, -89.5]))


def test_range_noise_of_zero_keeps_every_reading_and_rejects_bad_parameters():
    src = _log(3, _wavy_poses(3), ranges=[1.25, 3.5, 80.0])
    out = rewrite_lines(RangeNoise(0.0, 80.0, -math.pi / 2, math.radians(1.0)), src)
    lasers = [line.split() for line in out if line.startswith("ROBOTLASER1")]
    assert [t[9:12] for t in lasers] == [["1.250", "3.500", "80.00"]] * 3  # no-return as logged
    with pytest.raises(ConfigError, match="sigma_m"):
        RangeNoise(-0.01, 80.0, 0.0, 0.01)
    with pytest.raises(ConfigError, match="no_return_m"):
        RangeNoise(0.01, 0.0, 0.0, 0.01)


# --------------------------------------------------------------------------------------------
# biased odometry
# --------------------------------------------------------------------------------------------
def _odometry_poses(lines: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    odo, base, laser = [], [], []
    for line in lines:
        t = line.split()
        if t[0] == "ODOM":
            odo.append([float(v) for v in t[1:4]])
        elif t[0] == "FLASER":
            n = int(t[1])
            laser.append([float(v) for v in t[2 + n : 5 + n]])
            base.append([float(v) for v in t[5 + n : 8 + n]])
    return np.array(odo), np.array(base), np.array(laser)


def test_bias_on_a_straight_line_scales_the_distance():
    poses = np.array([[1.0, 2.0, 0.0], [2.0, 2.0, 0.0], [4.0, 2.0, 0.0]])
    lines = [flaser([1.0], p, p, 10.0 + i) for i, p in enumerate(poses)]
    _, base, laser = _odometry_poses(rewrite_lines(BiasOdometry(1.02, 0.02), lines))
    np.testing.assert_allclose(base, [[1.0, 2.0, 0.0], [2.02, 2.0, 0.0], [4.06, 2.0, 0.0]])
    np.testing.assert_allclose(laser, base)


def test_bias_on_a_turn_adds_two_percent_of_each_heading_increment():
    # turn in place +0.1, +0.1, then -0.3 (bias +0.02*0.3 makes it -0.294), then 1 m forward
    poses = np.array(
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.1], [0.0, 0.0, 0.2], [0.0, 0.0, -0.1], [1.0, 0.0, -0.1]]
    )
    poses[4, :2] = [math.cos(-0.1), math.sin(-0.1)]  # 1 m along heading -0.1
    lines = [odom(p, 10.0 + i, tv=0.5, rv=-0.2) for i, p in enumerate(poses)]
    odo, _, _ = _odometry_poses(rewrite_lines(BiasOdometry(1.02, 0.02), lines))
    heading = [0.0, 0.102, 0.204, 0.204 - 0.294]
    np.testing.assert_allclose(odo[:4, 2], heading, atol=2e-6)
    np.testing.assert_allclose(odo[:4, :2], 0.0, atol=1e-6)
    # the forward step has no heading change: 1.02 m along the biased heading
    h = heading[3]
    np.testing.assert_allclose(odo[4], [1.02 * math.cos(h), 1.02 * math.sin(h), h], atol=2e-6)


def test_bias_on_an_arc_by_hand():
    # a quarter turn while moving 1 m forward, then 1 m straight on
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, math.pi / 2], [1.0, 1.0, math.pi / 2]])
    lines = [flaser([1.0], p, p, 10.0 + i) for i, p in enumerate(poses)]
    _, base, _ = _odometry_poses(rewrite_lines(BiasOdometry(1.02, 0.02), lines))
    th = 1.02 * math.pi / 2
    p1 = [1.02, 0.0, th]
    p2 = [1.02 + 1.02 * math.cos(th), 1.02 * math.sin(th), th]
    np.testing.assert_allclose(base, [[0.0, 0.0, 0.0], p1, p2], atol=2e-6)


def test_bias_chains_odom_lines_and_hangs_laser_lines_on_the_last_one():
    # ODOM 0, FLASER +0.1, ODOM 0: the ODOM chain turns by 0 (not +0.102 - 0.098)
    lines = [odom(ZERO, 9.0), flaser([1.0], (0, 0, 0.1), (0, 0, 0.1), 10.0), odom(ZERO, 11.0)]
    odo, base, laser = _odometry_poses(rewrite_lines(BiasOdometry(1.02, 0.02), lines))
    np.testing.assert_allclose(odo, np.zeros((2, 3)), atol=1e-9)
    np.testing.assert_allclose(base, [[0.0, 0.0, 0.102]], atol=1e-9)
    np.testing.assert_allclose(laser, base, atol=1e-9)


def test_bias_keeps_the_laser_offset_and_scales_the_velocities():
    offset = np.array([0.1, 0.0, 0.0])
    base = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]])
    lines = [odom(base[0], 9.0), flaser([1.0], pose_compose(base[1], offset), base[1], 10.0)]
    lines.append(odom(base[2], 11.0, tv=1.0, rv=-0.5))
    out = rewrite_lines(BiasOdometry(1.02, 0.02), lines)
    odo, b, laser = _odometry_poses(out)
    np.testing.assert_allclose(odo, [[0.0, 0.0, 0.0], [1.02, 0.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(b, [[0.51, 0.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(laser, [[0.61, 0.0, 0.0]], atol=1e-9)
    tv, rv = (float(v) for v in out[-1].split()[4:6])
    assert (tv, rv) == (pytest.approx(1.02), pytest.approx(-0.49))


def test_noise_of_zero_variance_keeps_every_pose_and_the_velocities_as_logged():
    # velocities logged with fewer decimals than the transforms write
    lines = [
        odom(p, 9.5 + i, tv=0.25, rv=-0.125).replace("0.250000 -0.125000", "0.25 -0.125")
        for i, p in enumerate(_wavy_poses(6))
    ]
    assert all(" 0.25 -0.125 " in line for line in lines)
    lines += [flaser([1.0], p, p, 10.0 + i) for i, p in enumerate(_wavy_poses(6))]
    out = rewrite_lines(NoisyOdometry(0.0, 0.0, 0.0, seed=3), lines)
    odo, base, laser = _odometry_poses(out)
    np.testing.assert_allclose(odo, _wavy_poses(6), atol=1e-6)
    np.testing.assert_allclose(base, _wavy_poses(6), atol=1e-6)
    np.testing.assert_allclose(laser, base, atol=1e-6)
    for before, after in zip(lines, out, strict=True):
        b, a = before.split(), after.split()
        assert len(a) == len(b) and a[0] == b[0] and a[-3:] == b[-3:]  # stamps kept
        if b[0] == "ODOM":
            assert a[4:] == b[4:]  # tv, rv (and the rest) as logged, not re-formatted


def test_noise_is_reproducible_from_its_seed():
    lines = _log(20, _wavy_poses(20))
    a = rewrite_lines(NoisyOdometry(1e-3, 1e-3, 1e-3, seed=1), lines)
    assert a == rewrite_lines(NoisyOdometry(1e-3, 1e-3, 1e-3, seed=1), lines)
    assert a != rewrite_lines(NoisyOdometry(1e-3, 1e-3, 1e-3, seed=2), lines)
    # the laser line keeps its pose on the rewritten odometry; the time stamps stay
    assert _laser_stamps(a) == _laser_stamps(lines)


@pytest.mark.parametrize("step_m", [0.02, 0.2])
def test_noise_variance_grows_with_the_path_not_with_the_number_of_increments(step_m):
    # a straight ODOM chain turning by 0.01 rad per step: each increment's error, in the frame
    # of the previous rewritten pose, has the stated variances whatever the step; summed over
    # 1 m of path (and its turn) they are the same for both step lengths
    n = 4000
    heading = 0.01 * np.arange(n)
    xy = np.cumsum(step_m * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    poses = np.column_stack([xy, heading])
    lines = [odom(p, 10.0 + 0.1 * i) for i, p in enumerate(poses)]
    v_xy, v_tm, v_tr = 4e-4, 2e-4, 5e-3
    odo, _, _ = _odometry_poses(rewrite_lines(NoisyOdometry(v_xy, v_tm, v_tr, seed=7), lines))
    d_true = pose_between(poses[:-1], poses[1:])
    d_new = pose_between(odo[:-1], odo[1:])
    err = d_new - d_true
    err[:, 2] = np.remainder(err[:, 2] + math.pi, 2 * math.pi) - math.pi
    expected = np.array([v_xy * step_m, v_xy * step_m, v_tm * step_m + v_tr * 0.01])
    var = np.mean(err**2, axis=0)
    # the sample variance of n - 1 normal draws: relative standard deviation sqrt(2 / n)
    np.testing.assert_allclose(var / expected, 1.0, atol=5 * math.sqrt(2.0 / n))
    assert abs(np.mean(err[:, 2])) < 5 * math.sqrt(expected[2] / n)


def test_noise_rejects_a_negative_or_infinite_variance():
    with pytest.raises(ConfigError, match="var_theta_per_m"):
        NoisyOdometry(1e-3, -1e-3, 0.0)
    with pytest.raises(ConfigError, match="var_xy_per_m"):
        NoisyOdometry(math.inf, 0.0, 0.0)


# --------------------------------------------------------------------------------------------
# laser ahead of the robot centre
# --------------------------------------------------------------------------------------------
def _wavy_poses(n: int) -> np.ndarray:
    k = np.arange(n)
    return np.column_stack([0.3 * k, 0.5 * np.sin(0.4 * k), 0.35 * np.sin(0.3 * k) + 0.2])


def test_mount_moves_odometry_to_the_centre_and_keeps_the_laser_pose():
    t = np.array([-0.2, 0.0, 0.0])
    laser = _wavy_poses(6)
    out = rewrite_lines(MoveOdometryToCentre((-0.2, 0.0, 0.0)), _log(6, laser))
    odo, base, laser_out = _odometry_poses(out)
    centre = pose_compose(laser, np.broadcast_to(t, laser.shape))
    np.testing.assert_allclose(laser_out, laser, atol=1e-6)  # as logged (6 decimals)
    np.testing.assert_allclose(base, centre, atol=1e-6)
    np.testing.assert_allclose(odo, centre, atol=1e-6)  # ODOM lines carried the laser pose
    # 0.2 m behind the laser, along its heading
    np.testing.assert_allclose(np.hypot(*(laser[:, :2] - base[:, :2]).T), 0.2, atol=1e-6)


def test_mount_relations_round_trip_equals_relations_of_the_centre_trajectory():
    transform = MoveOdometryToCentre((-0.2, 0.0, 0.0))
    t = np.array([-0.2, 0.0, 0.0])
    laser = _wavy_poses(12)
    centre = pose_compose(laser, np.broadcast_to(t, laser.shape))
    stamps = 10.0 + np.arange(12)
    pairs = [(0, 1), (0, 5), (3, 11), (7, 2), (10, 11)]
    rel_laser = relations_from_trajectory(stamps, laser, pairs)
    rel_centre = relations_from_trajectory(stamps, centre, pairs)
    rewritten = transform.relations(rel_laser)
    np.testing.assert_allclose(rewritten.poses, rel_centre.poses, atol=1e-12)
    np.testing.assert_array_equal(rewritten.t1, rel_laser.t1)
    # and they differ from the laser relations (the lever arm matters on turns)
    assert np.abs(rel_laser.poses - rel_centre.poses).max() > 0.01


def test_mount_refuses_a_log_whose_laser_pose_is_not_its_odometry():
    line = flaser([1.0], (0.1, 0.0, 0.0), ZERO, 10.0)
    with pytest.raises(LogFormatError, match="differ"):
        rewrite_lines(MoveOdometryToCentre((-0.2, 0.0, 0.0)), [line])


# --------------------------------------------------------------------------------------------
# fewer beams, written as ROBOTLASER1
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("every", "n_kept"), [(4, 90), (2, 180)])
def test_beam_decimation_reads_back_with_its_geometry(tmp_path, every, n_kept):
    ranges = [1.0 + 0.01 * i for i in range(360)]
    laser = _wavy_poses(3)
    src = _log(3, laser, ranges=ranges)
    step = math.radians(0.5)
    transform = DecimateBeams(every, -math.pi / 2, step, 81.91)
    path = _write(tmp_path / "beams.clf", rewrite_lines(transform, src))
    reader = CarmenReader(path)
    scans = list(reader.scans())
    assert reader.stats.laser_type == "ROBOTLASER1"
    assert reader.stats.odometry == 3
    assert len(scans) == 3
    for i, scan in enumerate(scans):
        assert scan.n_beams == n_kept
        assert scan.bearings[0] == pytest.approx(-math.pi / 2, abs=1e-12)
        np.testing.assert_allclose(np.diff(scan.bearings), every * step, atol=1e-12)
        np.testing.assert_allclose(scan.ranges, np.round(ranges, 2)[::every])
        assert scan.max_range_m == 81.91
        assert scan.timestamp == 10.0 + i
        np.testing.assert_allclose(scan.pose_odom_laser, laser[i], atol=1e-6)
        np.testing.assert_allclose(scan.pose_odom_base, laser[i], atol=1e-6)
    assert scans[0].bearings[-1] == pytest.approx(math.radians(-90 + every * 0.5 * (n_kept - 1)))


@pytest.mark.parametrize(("fov_deg", "n_kept"), [(60.0, 121), (90.0, 181)])
def test_field_of_view_crop_reads_back_with_its_geometry(tmp_path, fov_deg, n_kept):
    """The beams within ±fov/2 of straight ahead, their readings and bearings as logged."""
    ranges = [1.0 + 0.01 * i for i in range(360)]
    laser = _wavy_poses(3)
    src = _log(3, laser, ranges=ranges)
    step = math.radians(0.5)
    transform = CropFieldOfView(math.radians(fov_deg), -math.pi / 2, step, 81.91)
    path = _write(tmp_path / "fov.clf", rewrite_lines(transform, src))
    reader = CarmenReader(path)
    scans = list(reader.scans())
    assert reader.stats.laser_type == "ROBOTLASER1"
    assert len(scans) == 3
    first = 180 - (n_kept - 1) // 2  # the source's beam at −fov/2
    for i, scan in enumerate(scans):
        assert scan.n_beams == n_kept
        assert scan.bearings[0] == pytest.approx(-math.radians(fov_deg) / 2, abs=1e-9)
        assert scan.bearings[-1] == pytest.approx(math.radians(fov_deg) / 2, abs=1e-9)
        np.testing.assert_allclose(np.diff(scan.bearings), step, atol=1e-12)
        np.testing.assert_allclose(scan.ranges, np.round(ranges, 2)[first : first + n_kept])
        assert scan.max_range_m == 81.91
        np.testing.assert_allclose(scan.pose_odom_laser, laser[i], atol=1e-6)


def test_field_of_view_crop_refuses_a_field_narrower_than_two_beams():
    narrow = CropFieldOfView(math.radians(0.6), -math.pi / 2, math.radians(0.5), 81.91)
    with pytest.raises(LogFormatError, match="keeps 1 of 360 beams"):
        rewrite_lines(narrow, _log(1, ranges=[1.0] * 360))
    with pytest.raises(ConfigError, match="fov_rad > 0"):
        CropFieldOfView(0.0, -math.pi / 2, math.radians(0.5), 81.91)


# --------------------------------------------------------------------------------------------
# chains of transforms
# --------------------------------------------------------------------------------------------
def test_chain_of_two_decimations_is_one_with_the_product_period():
    src = _log(23)
    chained = rewrite_lines(Chain((DecimateScans(2, 1), DecimateScans(3, 2))), src)
    # kept laser lines 1, 3, 5, ...; of those every 3rd from the third: 5, 11, 17
    assert chained == rewrite_lines(DecimateScans(6, 5), src)
    assert _laser_stamps(chained) == [15.0, 21.0, 27.0]


def test_chain_applies_each_step_to_the_previous_output(tmp_path):
    laser = _wavy_poses(9)
    ranges = [1.0 + 0.01 * i for i in range(360)]
    src = _log(9, laser, ranges=ranges)
    mount = MoveOdometryToCentre((-0.22, 0.0, 0.0))
    beams = DecimateBeams(2, -math.pi / 2, math.radians(0.5), 81.91)
    chain = Chain((DecimateScans(4), mount, beams))
    by_hand = rewrite_lines(beams, rewrite_lines(mount, rewrite_lines(DecimateScans(4), src)))
    assert rewrite_lines(chain, src) == by_hand
    scans = list(iter_scans(_write(tmp_path / "chain.clf", by_hand)))
    assert [s.timestamp for s in scans] == [10.0, 14.0, 18.0]
    assert scans[0].n_beams == 180
    # the relations go through the mount, and the odometry baseline is read in its frame
    assert chain.relations_frame == "base"
    assert Chain((DecimateScans(4), beams)).relations_frame == "laser"
    stamps = 10.0 + np.arange(9)
    rel = relations_from_trajectory(stamps, laser, [(0, 4), (2, 7)])
    np.testing.assert_array_equal(chain.relations(rel).poses, mount.relations(rel).poses)


def test_chain_refuses_robotlaser_output_before_its_last_step():
    beams = DecimateBeams(2, -math.pi / 2, math.radians(0.5), 81.91)
    with pytest.raises(ConfigError, match="only the last step"):
        Chain((beams, DecimateScans(2)))
    with pytest.raises(ConfigError, match="at least two"):
        Chain((DecimateScans(2),))


def test_chain_parameters_key_the_cache_in_order():
    a = Chain((DecimateScans(2), MoveOdometryToCentre((-0.2, 0.0, 0.0))))
    b = Chain((MoveOdometryToCentre((-0.2, 0.0, 0.0)), DecimateScans(2)))
    assert a.params()["steps"][0]["kind"] == "decimate-scans"
    assert a.params() != b.params()


# --------------------------------------------------------------------------------------------
# scoring: dropped scans filled in by odometry
# --------------------------------------------------------------------------------------------
def test_fill_in_reproduces_the_trajectory_when_odometry_is_perfect():
    truth = _wavy_poses(20)
    # perfect odometry in another frame: a fixed transform of the truth
    origin = np.array([5.0, -3.0, 1.2])
    odometry = pose_compose(np.broadcast_to(origin, truth.shape), truth)
    stamps = 100.0 + np.arange(20) * 0.25
    kept = np.arange(2, 20, 4)  # the first two scans come before any kept scan
    estimate = Trajectory(stamps[kept], truth[kept])
    filled = fill_dropped_scans(estimate, Trajectory(stamps, odometry))
    np.testing.assert_array_equal(filled.timestamps, stamps)
    np.testing.assert_allclose(filled.poses, truth, atol=1e-12)


def test_fill_in_carries_the_last_kept_scan_on_by_odometry():
    odometry = Trajectory(np.array([1.0, 2.0, 3.0]), np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.5]]))
    estimate = Trajectory(np.array([1.0]), np.array([[10.0, 0.0, math.pi / 2]]))
    filled = fill_dropped_scans(estimate, odometry)
    np.testing.assert_allclose(
        filled.poses,
        [[10, 0, math.pi / 2], [10, 1, math.pi / 2], [10, 2, math.pi / 2 + 0.5]],
        atol=1e-12,
    )


def test_fill_in_rejects_a_trajectory_of_another_log():
    odometry = Trajectory(np.array([1.0, 2.0]), np.zeros((2, 3)))
    with pytest.raises(EvaluationError, match="not scans of the log"):
        fill_dropped_scans(Trajectory(np.array([1.5]), np.zeros((1, 3))), odometry)


# --------------------------------------------------------------------------------------------
# making and scoring a variant of a (small, fake) catalogued log
# --------------------------------------------------------------------------------------------
@pytest.fixture
def fake_root(tmp_path):
    """A data root whose ``aces`` is a 30-scan log with perfect odometry and its relations."""
    root = tmp_path / "data"
    (root / "aces").mkdir(parents=True)
    truth = _wavy_poses(30)
    stamps = 10.0 + np.arange(30)
    _write(root / "aces" / "aces.clf", _log(30, truth, ranges=[2.0] * 180))
    pairs = [(i, j) for i in range(30) for j in (i + 1, i + 13) if j < 30]
    rel = relations_from_trajectory(stamps, truth, pairs)
    write_relations(root / "aces" / "aces.relations", rel.t1, rel.t2, rel.poses)
    return root, stamps, truth


def _rotated(poses: np.ndarray) -> np.ndarray:
    """The same trajectory in another world frame (the metric is relative)."""
    frame = np.array([-2.0, 7.0, 2.5])
    return pose_compose(np.broadcast_to(frame, poses.shape), poses)


def test_decimated_variant_is_cached_and_scored_on_every_relation(fake_root, tmp_path):
    root, stamps, truth = fake_root
    variant = Variant("aces-every4", "aces", 0.08, DecimateScans(4, 1))
    files = make_variant(variant, tmp_path / "cache", root=root)
    assert files.log.name == "aces-every4.clf"  # not a name the catalogue knows
    assert files.source_log == root / "aces" / "aces.clf"
    assert len(list(iter_scans(files.log))) == 8  # scans 1, 5, ..., 29
    assert len(list(iter_odometry(files.log))) == 30
    mtime = files.log.stat().st_mtime_ns
    again = make_variant(variant, tmp_path / "cache", root=root)
    assert again.log == files.log and again.log.stat().st_mtime_ns == mtime
    named = make_variant(variant, tmp_path / "cache", root=root, catalogued_name=True)
    assert named.log.name == "aces.clf" and named.log.parent != files.log.parent

    kept = np.arange(1, 30, 4)
    score = score_run(Trajectory(stamps[kept], _rotated(truth[kept])), "laser", files)
    n_rel = len(read_relations(files.relations))
    assert score.lineslam.n_used == n_rel and score.lineslam.n_unmatched == 0
    assert score.lineslam.abs_trans_m.mean == pytest.approx(0.0, abs=1e-5)
    assert score.odometry.abs_trans_m.mean == pytest.approx(0.0, abs=1e-5)
    assert score.scans_filled == 22
    assert score.lineslam_short is not None and score.lineslam_short.n_used == 29

    # a wrong pose of one kept scan shows up in its relations and the scans filled from it
    bad = truth[kept].copy()
    bad[3, 0] += 0.5
    worse = score_run(Trajectory(stamps[kept], bad), "laser", files)
    assert worse.lineslam.abs_trans_m.mean > 0.01


def test_mount_variant_penalises_a_trajectory_in_the_wrong_frame(fake_root, tmp_path):
    root, stamps, truth = fake_root
    variant = Variant("aces-mount", "aces", 0.05, MoveOdometryToCentre((-0.2, 0.0, 0.0)))
    files = make_variant(variant, tmp_path / "cache", root=root)
    centre = pose_compose(truth, np.broadcast_to([-0.2, 0.0, 0.0], truth.shape))
    right = score_run(Trajectory(stamps, _rotated(centre)), "base", files)
    assert right.lineslam.abs_trans_m.mean == pytest.approx(0.0, abs=1e-5)
    assert right.odometry_frame == "base"
    assert right.odometry.abs_trans_m.mean == pytest.approx(0.0, abs=1e-5)
    wrong = score_run(Trajectory(stamps, _rotated(truth)), "laser", files)
    assert wrong.lineslam.abs_trans_m.mean > 0.01


def test_relations_of_other_variants_are_the_sources(fake_root, tmp_path):
    root, _, _ = fake_root
    variant = Variant("aces-max8m", "aces", 0.08, ClipRanges(8.0, 50.0, -math.pi / 2, 0.01))
    files = make_variant(variant, tmp_path / "cache", root=root)
    assert files.relations.read_bytes() == (root / "aces" / "aces.relations").read_bytes()


def test_unmodified_rows_use_the_source_log(fake_root, tmp_path):
    root, _, _ = fake_root
    files = make_variant(Variant("aces", "aces", 0.045, None), tmp_path / "cache", root=root)
    assert files.log == root / "aces" / "aces.clf"
    assert not (tmp_path / "cache").exists()


# --------------------------------------------------------------------------------------------
# the table's parameters agree with the catalogue
# --------------------------------------------------------------------------------------------
def test_table_parameters_match_the_catalogue():
    catalog = load_catalog()
    names = [v.name for v in VARIANTS + EXTRA_VARIANTS]
    assert len(set(names)) == len(names)
    rows = [(v, v.transform) for v in VARIANTS + EXTRA_VARIANTS]
    steps = [(v, s) for v, t in rows if isinstance(t, Chain) for s in t.steps]
    for v, t in rows + steps:
        laser = catalog[v.dataset].laser
        if isinstance(t, ClipRanges):
            assert t.limit_m == (5.6 if v.name.endswith("-max5.6m") else 8.0)
        if isinstance(t, ClipRanges | RangeNoise):
            assert t.no_return_m == laser.max_range_m
        if isinstance(t, ClipRanges | CropFieldOfView | DecimateBeams | RangeNoise):
            assert t.first_angle_rad == pytest.approx(math.radians(laser.first_angle_deg))
            assert t.step_rad == pytest.approx(math.radians(laser.step_deg))
        if isinstance(t, CropFieldOfView | DecimateBeams):
            assert t.max_range_m == laser.max_range_m
        if isinstance(t, DecimateBeams):
            assert laser.beams % t.every == 0
    assert {v.name for v in VARIANTS if v.transform is None} == {"intel", "aces", "fr079"}


# --------------------------------------------------------------------------------------------
# the real logs
# --------------------------------------------------------------------------------------------
@pytest.mark.realdata
def test_real_decimated_variant_keeps_its_odometry_baseline(shared_data, tmp_path):
    variant = next(v for v in VARIANTS if v.name == "aces-every4")
    files = make_variant(variant, tmp_path / "cache", root=shared_data)
    reader = CarmenReader(files.log)
    assert sum(1 for _ in reader.scans()) == 1844  # ceil(7374 / 4)
    assert reader.stats.odometry == 7375
    odometry = Trajectory(
        np.array([s.timestamp for s in iter_scans(files.source_log)]),
        np.array([s.pose_odom_laser for s in iter_scans(files.source_log)]),
    )
    kept = iter_scans(files.log)
    first = [s for _, s in zip(range(3), kept, strict=False)]
    assert [s.timestamp for s in first] == list(odometry.timestamps[[0, 4, 8]])
    # the odometry itself as the "run": every relation matched, the README's odometry error
    ours = Trajectory(
        np.array([s.timestamp for s in iter_scans(files.log)]),
        np.array([s.pose_odom_laser for s in iter_scans(files.log)]),
    )
    score = score_run(ours, "laser", files)
    assert score.lineslam.n_used == 1279
    assert score.lineslam.abs_trans_m.mean == pytest.approx(0.5636, abs=1e-4)
    assert score.odometry.abs_trans_m.mean == pytest.approx(0.5636, abs=1e-4)


# --------------------------------------------------------------------------------------------
# odometry a few laser lines late
# --------------------------------------------------------------------------------------------
def _reversing_log() -> list[str]:
    """Laser lines on a wavy path with an offset laser, ODOM lines between them, two of them
    reversing (tv < 0 while the logged pose moves forwards, as fr079 logs it)."""
    base = _wavy_poses(8)
    offset = np.array([0.2, 0.05, 0.1])
    lines = ["# CARMEN Logfile"]
    for i, p in enumerate(base):
        tv = -0.3 if i in (4, 5) else 0.3
        mid = pose_compose(base[i - 1], 0.5 * pose_between(base[i - 1], p)) if i else p
        lines.append(odom(mid, 9.5 + i, tv=tv, rv=0.01 * i))
        lines.append(flaser([1.0, 2.0], pose_compose(p, offset), p, 10.0 + i))
    return lines


def test_odometry_lag_of_zero_keeps_every_line():
    lines = _reversing_log()
    out = rewrite_lines(OdometryLag(0), lines)
    assert [x.split() for x in out] == [x.split() for x in lines]


@pytest.mark.parametrize("scans", [1, 2, 3])
def test_odometry_lag_gives_each_laser_line_an_earlier_lines_odometry(scans):
    lines = _reversing_log()
    out = rewrite_lines(OdometryLag(scans), lines)
    odo_in, base_in, laser_in = _odometry_poses(lines)
    odo, base, laser = _odometry_poses(out)
    k = np.maximum(np.arange(len(base_in)) - scans, 0)
    np.testing.assert_allclose(base, base_in[k], atol=1e-6)
    # the laser keeps its logged offset from the odometry pose
    np.testing.assert_allclose(
        pose_between(base, laser), pose_between(base_in, laser_in), atol=2e-6
    )
    # the ODOM line before laser line i carries the one before laser line i - scans
    np.testing.assert_allclose(odo, odo_in[k], atol=1e-6)
    tv_in = [x.split()[4] for x in lines if x.startswith("ODOM")]
    tv = [x.split()[4] for x in out if x.startswith("ODOM")]
    assert tv == [tv_in[j] for j in k]
    # time stamps, ranges and the order of the lines stay
    for before, after in zip(lines, out, strict=True):
        b, a = before.split(), after.split()
        assert a[0] == b[0] and a[-3:] == b[-3:]
        if b[0] == "FLASER":
            assert a[:4] == b[:4]


@pytest.mark.parametrize("scans", [1, 2])
def test_odometry_lag_read_as_the_estimators_read_it_is_the_delayed_reading(tmp_path, scans):
    # the velocity-signed reading (fr079's reversing repaired) of the delayed log is the
    # reading of the log itself, delayed: both streams are delayed alike
    from slam.io.carmen import velocity_signed_scans

    lines = _reversing_log()
    src = _write(tmp_path / "src.clf", lines)
    lagged = _write(tmp_path / "lagged.clf", rewrite_lines(OdometryLag(scans), lines))
    read = [s.pose_odom_base for s in velocity_signed_scans(CarmenReader(src).messages())]
    read_lagged = [s.pose_odom_base for s in velocity_signed_scans(CarmenReader(lagged).messages())]
    k = np.maximum(np.arange(len(read)) - scans, 0)
    assert not np.allclose(np.array(read)[:, :2], np.array(_odometry_poses(lines)[1])[:, :2])
    np.testing.assert_allclose(np.array(read_lagged), np.array(read)[k], atol=1e-5)


def test_odometry_lag_rejects_a_negative_lag():
    with pytest.raises(ConfigError, match="scans must be >= 0"):
        OdometryLag(-1)


def test_arithmetic_is_recorded_and_a_difference_is_named():
    import json

    from slam.experiments.robustness import arithmetic, arithmetic_difference

    here = arithmetic()
    assert set(here) == {"cpu", "blas", "numpy_loops"}
    assert here["blas"] and all(isinstance(a, str) and a for a in here["blas"])
    # the same arithmetic: nothing to say; a JSON round trip keeps it the same
    assert arithmetic_difference(json.loads(json.dumps(here)), here) is None
    # each difference is named, with both sides
    other = {**here, "numpy_loops": ["X86_V3", "X86_V4"], "cpu": "another CPU"}
    said = arithmetic_difference(other, here)
    assert said is not None and "numpy's loops" in said and "CPU another CPU →" in said
    assert "BLAS" not in said
    assert "does not record" in str(arithmetic_difference(None, here))
