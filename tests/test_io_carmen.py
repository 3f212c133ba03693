"""CARMEN reader: messages, geometry, streaming order, bad input (constructed logs)."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest
from carmen_lines import flaser, odom, rawlaser, robotlaser
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slam.errors import ConfigError, InputError, LogFormatError
from slam.io import CarmenReader, CarmenStats, LaserGeometry, iter_odometry, iter_scans
from slam.io.carmen import scan_trajectory


def write(tmp_path, lines, name="log.clf"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_flaser_fields_map_to_scan(tmp_path, rng):
    ranges = rng.uniform(0.5, 20.0, 180).round(2)
    path = write(
        tmp_path,
        [
            "# a comment",
            odom([0.0, 0.0, 0.1], 10.0),
            flaser(ranges, [1.0, 2.0, 0.3], [1.5, 2.5, 0.4], 10.25),
            "",
            "PARAM robot_length 0.5",
            "TRUEPOS 1 2 3 4 5 6 7 nohost 8",
            "PARAM robot_width 0.4",
        ],
    )
    stats = CarmenStats()
    scans = list(iter_scans(path, stats=stats))
    assert len(scans) == 1
    scan = scans[0]
    np.testing.assert_array_equal(scan.ranges, ranges)
    np.testing.assert_array_equal(scan.pose_odom_laser, [1.0, 2.0, 0.3])
    np.testing.assert_array_equal(scan.pose_odom_base, [1.5, 2.5, 0.4])
    assert scan.timestamp == 10.25
    assert scan.index == 0
    assert scan.source == f"{path}:3"
    # CARMEN's guess for 180 beams: -90 deg, 1 deg steps
    np.testing.assert_allclose(scan.bearings[[0, 1, -1]], np.radians([-90.0, -89.0, 89.0]))
    assert scan.max_range_m == 80.0
    assert stats.scans == 1 and stats.odometry == 1 and stats.comments == 1
    assert stats.blank == 1 and stats.unknown == 3
    assert stats.unknown_types == {"PARAM": 2, "TRUEPOS": 1}


@pytest.mark.parametrize(
    ("n", "step_deg", "first_deg"),
    [(180, 1.0, -90.0), (360, 0.5, -90.0), (181, 1.0, -90.0), (361, 0.5, -90.0)],
)
def test_carmen_guess_fov_rule(tmp_path, n, step_deg, first_deg):
    path = write(tmp_path, [flaser(np.full(n, 3.0), [0, 0, 0], [0, 0, 0], 1.0)])
    (scan,) = iter_scans(path)
    np.testing.assert_allclose(np.diff(scan.bearings), math.radians(step_deg), atol=1e-12)
    assert scan.bearings[0] == pytest.approx(math.radians(first_deg))


def test_geometry_argument_and_beam_count_check(tmp_path):
    path = write(tmp_path, [flaser(np.full(10, 3.0), [0, 0, 0], [0, 0, 0], 1.0)])
    geometry = LaserGeometry(-0.5, 0.1, n_beams=10, max_range_m=5.0)
    (scan,) = iter_scans(path, geometry=geometry)
    np.testing.assert_allclose(scan.bearings, -0.5 + 0.1 * np.arange(10))
    assert scan.max_range_m == 5.0
    with pytest.raises(LogFormatError, match=r"log\.clf:1: .*10 readings.*says 11"):
        list(iter_scans(path, geometry=LaserGeometry(-0.5, 0.1, n_beams=11)))


def test_a_file_named_like_a_catalogued_log_gets_no_catalogue_geometry(tmp_path):
    # the catalogue recognises its logs by content: a small aces.clf is not ACES (no 50 m
    # clipping), a 181-beam fr079.clf is read by CARMEN's rule, not fr079's 360 beams
    path = write(tmp_path, [flaser(np.full(180, 50.0), [0, 0, 0], [0, 0, 0], 1.0)], name="aces.clf")
    (scan,) = iter_scans(path)
    assert scan.max_range_m == 80.0
    assert scan.valid_mask().all()
    other = write(
        tmp_path, [flaser(np.full(181, 5.0), [0, 0, 0], [0, 0, 0], 1.0)], name="fr079.clf"
    )
    (scan,) = iter_scans(other)
    np.testing.assert_allclose(np.diff(scan.bearings), np.pi / 180)


def test_robotlaser_and_rawlaser_use_their_own_geometry(tmp_path, rng):
    ranges = rng.uniform(0.5, 4.0, 7).round(2)
    path = write(
        tmp_path,
        [
            rawlaser(ranges, -1.0, 0.25, 4.5, 5.0),
            robotlaser(ranges, -1.0, 0.25, 4.5, [1, 2, 3], [4, 5, 6], 5.0, remissions=[1, 2]),
            odom([1, 2, 3], 5.1),
        ],
    )
    stats = CarmenStats()
    (scan,) = iter_scans(path, stats=stats)  # auto: ROBOTLASER1 preferred, RAWLASER1 counted
    assert stats.laser_type == "ROBOTLASER1" and stats.other_laser == 1
    np.testing.assert_allclose(scan.bearings, -1.0 + 0.25 * np.arange(7))
    assert scan.max_range_m == 4.5
    np.testing.assert_array_equal(scan.pose_odom_laser, [1, 2, 3])
    np.testing.assert_array_equal(scan.pose_odom_base, [4, 5, 6])
    np.testing.assert_array_equal(scan.ranges, ranges)
    (raw,) = iter_scans(path, laser="RAWLASER1")
    assert raw.pose_odom_base is None and raw.timestamp == 5.0
    np.testing.assert_array_equal(raw.ranges, ranges)


def test_file_order_is_kept_and_odometry_is_read(tmp_path):
    stamps = [5.0, 4.0, 6.0, 5.5]  # going backwards, as Intel's
    lines = []
    for k, t in enumerate(stamps):
        lines.append(odom([k, 0, 0], t - 0.01))
        lines.append(flaser(np.full(180, 2.0), [k, 0, 0], [k, 0, 0], t))
    path = write(tmp_path, lines)
    scans = list(iter_scans(path))
    assert [s.timestamp for s in scans] == stamps
    assert [s.index for s in scans] == [0, 1, 2, 3]
    odo = list(iter_odometry(path))
    assert [o.pose_odom_base[0] for o in odo] == [0, 1, 2, 3]
    assert odo[0].tv_mps == pytest.approx(0.1) and odo[0].rv_radps == pytest.approx(0.01)
    kinds = [type(m).__name__ for m in CarmenReader(path).messages()]
    assert kinds == ["Odometry", "Scan"] * 4
    trajectory = scan_trajectory(path)
    np.testing.assert_array_equal(trajectory.timestamps, stamps)


def test_gzip_log_reads_like_plain(tmp_path):
    lines = [flaser(np.full(180, 2.0), [0, 0, 0], [0, 0, 0], 1.0)]
    plain = write(tmp_path, lines)
    packed = tmp_path / "log.clf.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    (a,) = iter_scans(plain)
    (b,) = iter_scans(packed)
    np.testing.assert_array_equal(a.ranges, b.ranges)


GOOD = flaser(np.full(180, 2.5), [0.1, 0.2, 0.3], [0.1, 0.2, 0.3], 100.0)
GOOD_TOKENS = GOOD.split()

MALFORMED = {
    "truncated": " ".join(GOOD_TOKENS[:100]),
    "count says more": GOOD.replace("FLASER 180", "FLASER 181", 1),
    "extra fields": GOOD + " 1 2 3",
    "text in range": GOOD.replace(" 2.50 ", " abc ", 1),
    "nan range": GOOD.replace(" 2.50 ", " nan ", 1),
    "negative range": GOOD.replace(" 2.50 ", " -2.50 ", 1),
    "text in pose": " ".join(GOOD_TOKENS[:-7] + ["x"] + GOOD_TOKENS[-6:]),
    "nan stamp": " ".join(GOOD_TOKENS[:-3] + ["nan"] + GOOD_TOKENS[-2:]),
    "bad count": GOOD.replace("FLASER 180", "FLASER 1.5e2", 1),
    "odom truncated": "ODOM 1 2 3",
    "odom text": "ODOM 1 2 3 0 0 0 t nohost 4",
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_line_names_file_and_line_or_is_counted(tmp_path, case):
    path = write(tmp_path, ["# header", GOOD, MALFORMED[case], GOOD])
    with pytest.raises(LogFormatError) as info:
        list(CarmenReader(path).messages())
    assert info.value.line_number == 3
    assert str(path) in str(info.value)
    stats = CarmenStats()
    scans = list(iter_scans(path, lenient=True, stats=stats))
    assert stats.malformed == 1 and stats.malformed_lines[0][0] == 3
    assert [s.index for s in scans] == [0, 1]
    assert [s.source.rsplit(":", 1)[1] for s in scans] == ["2", "4"]


@pytest.mark.parametrize("cut", [20, 60, -30, -25])
def test_truncated_robotlaser_line(tmp_path, cut):
    good = robotlaser([1.0] * 5, -1, 0.1, 5, [0, 0, 0], [0, 0, 0], 1.0, remissions=[3, 4])
    path = write(tmp_path, [good, good[:cut], good])
    with pytest.raises(LogFormatError) as info:
        list(iter_scans(path))
    assert info.value.line_number == 2
    stats = CarmenStats()
    assert len(list(iter_scans(path, lenient=True, stats=stats))) == 2
    assert stats.malformed == 1


def test_inf_range_is_a_no_return_not_an_error(tmp_path):
    path = write(tmp_path, [GOOD.replace(" 2.50 ", " inf ", 1)])
    (scan,) = iter_scans(path)
    assert np.isinf(scan.ranges).sum() == 1 and (~scan.valid_mask()).sum() == 1


def test_empty_binary_and_foreign_files(tmp_path, rng):
    empty = tmp_path / "empty.clf"
    empty.write_bytes(b"")
    with pytest.raises(LogFormatError, match="empty file"):
        list(iter_scans(empty))
    binary = tmp_path / "bin.clf"
    binary.write_bytes(b"FLASER 1 2\n" + rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
    with pytest.raises(LogFormatError, match=r"bin\.clf:2: (binary|bytes)"):
        list(iter_scans(binary))
    latin = tmp_path / "latin.clf"
    latin.write_bytes(b"\xff\xfe\xfa not utf-8\n")
    with pytest.raises(LogFormatError, match=r"latin\.clf:1: bytes that are not UTF-8"):
        list(iter_scans(latin))
    text = write(tmp_path, ["hello world", "this is not a log"], name="notes.txt")
    with pytest.raises(LogFormatError, match="not a CARMEN log"):
        list(iter_scans(text))
    with pytest.raises(InputError, match="no such file"):
        list(iter_scans(tmp_path / "missing.clf"))
    with pytest.raises(InputError, match="directory"):
        list(iter_scans(tmp_path))
    truncated_gz = tmp_path / "cut.clf.gz"
    many = [flaser(rng.uniform(1, 9, 180), [0, 0, 0], [0, 0, 0], k) for k in range(50)]
    packed = gzip.compress("\n".join(many).encode())
    truncated_gz.write_bytes(packed[: len(packed) // 2])
    with pytest.raises(LogFormatError, match="cannot read"):
        list(iter_scans(truncated_gz))


_MUTATIONS = st.one_of(
    st.tuples(st.just("truncate"), st.integers(0, len(GOOD_TOKENS) - 1)),
    st.tuples(
        st.just("replace"),
        st.integers(0, len(GOOD_TOKENS) - 1),
        st.sampled_from(["nan", "-1", "abc", "1e400", "-inf", "", "0", "1,5", "FLASER"]),
    ),
    st.tuples(st.just("drop"), st.integers(0, len(GOOD_TOKENS) - 1)),
    st.tuples(st.just("duplicate"), st.integers(0, len(GOOD_TOKENS) - 1)),
)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(mutation=_MUTATIONS)
def test_fuzzed_lines_give_a_clear_error_or_a_counted_skip(tmp_path, mutation):
    tokens = list(GOOD_TOKENS)
    kind, index = mutation[0], mutation[1]
    if kind == "truncate":
        tokens = tokens[: index + 1]
    elif kind == "replace":
        tokens[index] = mutation[2]
    elif kind == "drop":
        del tokens[index]
    else:
        tokens.insert(index, tokens[index])
    path = write(tmp_path, [GOOD, " ".join(tokens)], name="fuzz.clf")
    try:
        scans = list(iter_scans(path))
    except LogFormatError as exc:
        assert exc.line_number in (1, 2) and "fuzz.clf" in str(exc)
        if exc.line_number == 1:  # the good line can only fail as "no CARMEN message"
            pytest.fail(str(exc))
    else:
        # accepted: every number in it must be sane
        for scan in scans:
            assert (scan.ranges >= 0).all() and np.isfinite(scan.timestamp)
            assert scan.pose_odom_base is not None and np.isfinite(scan.pose_odom_base).all()
    stats = CarmenStats()
    lenient = list(iter_scans(path, lenient=True, stats=stats))
    assert len(lenient) + stats.malformed + stats.unknown + stats.other_laser == 2


def test_bad_arguments_are_config_errors(tmp_path):
    from slam.errors import ConfigError

    path = write(tmp_path, [GOOD])
    with pytest.raises(ConfigError, match="laser must be"):
        list(iter_scans(path, laser="SONAR"))
    with pytest.raises(ConfigError, match="frame must be"):
        scan_trajectory(path, frame="world")


def test_velocity_signed_scans_negate_forward_increments_while_reversing(tmp_path):
    from slam.io.carmen import velocity_signed_scans

    # the robot (heading 0) drives forward 1 m, then backward 1 m; the log integrates |tv|,
    # so its pose keeps moving forward (x = 0, 1, 2) while tv < 0 in the second half
    lines = [
        odom((0.0, 0.0, 0.0), 0.0, tv=0.0),
        flaser([1.0] * 5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.05),
        odom((1.0, 0.0, 0.0), 1.0, tv=0.5),
        flaser([1.0] * 5, (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.05),
        odom((1.5, 0.0, 0.1), 2.0, tv=-0.5),
        flaser([1.0] * 5, (1.75, 0.0, 0.1), (1.75, 0.0, 0.1), 2.05),
        odom((2.0, 0.0, 0.1), 3.0, tv=-0.5),
        flaser([1.0] * 5, (2.0, 0.0, 0.1), (2.0, 0.0, 0.1), 3.05),
    ]
    path = write(tmp_path, lines)
    logged = list(iter_scans(path))
    scans = list(velocity_signed_scans(CarmenReader(path).messages()))
    for k in (0, 1):  # untouched before reversing
        np.testing.assert_array_equal(scans[k].pose_odom_base, logged[k].pose_odom_base)
    # mean tv of (0.5, -0.5) is 0: the ODOM step 1 -> 1.5 stays forward; after it, backward
    # (the logged steps run along +x: negated, they run along -x)
    np.testing.assert_allclose(scans[2].pose_odom_base, [1.25, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(scans[3].pose_odom_base, [1.0, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(scans[3].pose_odom_laser, scans[3].pose_odom_base, atol=1e-12)


def test_velocity_signed_scans_leave_logs_without_negative_speed_alone(tmp_path):
    from slam.io.carmen import velocity_signed_scans

    lines = [odom((0.1 * k, 0.0, 0.01 * k), float(k), tv=0.0) for k in range(3)]
    lines += [flaser([1.0] * 5, (0.3, 0.0, 0.0), (0.3, 0.0, 0.0), 3.5)]
    path = write(tmp_path, lines)
    logged = list(iter_scans(path))
    scans = list(velocity_signed_scans(CarmenReader(path).messages()))
    assert len(scans) == 1 and scans[0] is not None
    np.testing.assert_array_equal(scans[0].pose_odom_base, logged[0].pose_odom_base)


def test_iter_log_scans_chooses_the_odometry(tmp_path):
    from slam.io.carmen import iter_log_scans

    lines = [
        odom((0.0, 0.0, 0.0), 0.0, tv=0.0),
        odom((1.0, 0.0, 0.0), 1.0, tv=-0.5),
        flaser([1.0] * 5, (1.5, 0.0, 0.0), (1.5, 0.0, 0.0), 1.5),
    ]
    path = write(tmp_path, lines)
    logged = next(iter(iter_log_scans(path, "logged")))
    raw = next(iter(iter_scans(path)))
    np.testing.assert_array_equal(logged.pose_odom_base, raw.pose_odom_base)
    # reversing: the logged +x steps run along -x
    velocity = list(iter_log_scans(path))
    np.testing.assert_allclose(velocity[0].pose_odom_base, [-1.5, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ConfigError, match="odometry_sign"):
        list(iter_log_scans(path, "absolute"))
    # scan_trajectory reads either odometry the same way
    np.testing.assert_allclose(
        scan_trajectory(path, odometry_sign="velocity").poses[0], velocity[0].pose_odom_base
    )
    np.testing.assert_array_equal(scan_trajectory(path).poses[0], raw.pose_odom_base)
