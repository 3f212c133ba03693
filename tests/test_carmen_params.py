"""A CARMEN log's ``PARAM`` lines: the laser's layout, range limit and mounting read from them."""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from carmen_lines import flaser, odom, robotlaser
from conftest import REPO_ROOT

from slam.errors import LogFormatError
from slam.geometry import pose_compose
from slam.inputs import InputWarning, ScannerConfig, open_log
from slam.io.carmen import CarmenReader, read_params
from slam.io.carmen_write import write_carmen
from slam.io.laser import guess_laser_geometry

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"


def param(name: str, value: str) -> str:
    return f"PARAM {name} {value} nohost 0"


def write_log(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def flaser_log(path: Path, params: list[str], n_beams: int, laser_from_base=None, n: int = 12):
    """``params`` then ODOM + FLASER lines of ``n_beams`` readings; the laser pose is the
    odometry pose composed with ``laser_from_base`` (``None``: the two poses are equal)."""
    lines = list(params)
    ranges = np.full(n_beams, 3.0)
    ranges[::7] = 50.0
    for k in range(n):
        base = np.array([0.3 * k, 0.1 * k, 0.05 * k])
        laser = base if laser_from_base is None else pose_compose(base, laser_from_base)
        lines += [odom(base, k + 0.0), flaser(ranges, laser, base, k + 0.5)]
    return write_log(path, lines)


@contextmanager
def no_input_warnings() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        yield


# -- reading them ------------------------------------------------------------------------------


def test_params_are_read_from_the_head_of_the_log(tmp_path):
    log = flaser_log(
        tmp_path / "a.clf",
        ["# header", param("laser_front_laser_resolution", "0.5"), param("robot_x", "on")],
        361,
    )
    p = read_params(log)
    assert p.values["laser_front_laser_resolution"] == ("0.5", 2)
    assert p.first_beams == {"FLASER": 361}
    assert p.number("laser_front_laser_resolution") == 0.5 and p.number("missing") is None
    assert p.stated("FLASER") == {"laser_front_laser_resolution": 0.5}
    # a PARAM line after max_other_lines lines of other kinds is not read
    late = write_log(tmp_path / "late.clf", [*log.read_text().splitlines(), param("robot_z", "1")])
    assert "robot_z" in read_params(late).values
    assert "robot_z" not in read_params(late, max_other_lines=5).values


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("laser_front_laser_resolution", "half", "not a finite number"),
        ("laser_front_laser_resolution", "nan", "not a finite number"),
        ("robot_front_laser_max", "-1", "must be > 0"),
        ("robot_frontlaser_angular_offset", "90", "radians expected"),
    ],
)
def test_a_bad_param_value_is_an_error_naming_its_line(tmp_path, name, value, message):
    log = flaser_log(tmp_path / "bad.clf", ["# c", "# c", param(name, value)], 180)
    with pytest.raises(LogFormatError, match=message) as info:
        open_log(log)
    assert info.value.line_number == 3 and str(log) in str(info.value)


# -- the beam layout and the range limit -------------------------------------------------------


def test_a_stated_resolution_and_range_limit_replace_carmens_rule(tmp_path):
    params = [
        param("laser_front_laser_fov", "180"),
        param("laser_front_laser_resolution", "0.5"),
        param("robot_front_laser_max", "50"),
    ]
    log = flaser_log(tmp_path / "half.clf", params, 361)
    with no_input_warnings():
        opened = open_log(log)
        scans = list(opened.scans())
    b = scans[0].bearings
    assert b[0] == pytest.approx(-math.pi / 2) and b[-1] == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(np.diff(b), math.radians(0.5))
    # readings at the stated limit are no return
    assert scans[0].max_range_m == 50.0
    assert not scans[0].valid_mask()[::7].any() and scans[0].valid_mask()[1::7].all()
    described = opened.describe()
    assert described["geometry"]["source"] == "param"
    assert described["params"]["robot_front_laser_max"] == 50.0
    # the reader's own default (no catalogue entry) reads them too
    reader_scan = next(CarmenReader(log).scans())
    np.testing.assert_array_equal(reader_scan.bearings, b)
    # without them: CARMEN's rule for 361 beams (the same bearings here), announced, 80 m
    plain = flaser_log(tmp_path / "plain.clf", [], 361)
    with pytest.warns(InputWarning, match="CARMEN's rule"):
        guessed = open_log(plain)
    (first, *_) = guessed.scans()
    assert first.max_range_m == 80.0 and guessed.describe()["geometry"]["source"] == "carmen-rule"


def test_a_range_limit_alone_keeps_carmens_layout(tmp_path):
    log = flaser_log(tmp_path / "max.clf", [param("robot_front_laser_max", "50")], 180)
    with no_input_warnings():
        (scan, *_) = open_log(log).scans()
    np.testing.assert_array_equal(scan.bearings, guess_laser_geometry(180).bearings(180))
    assert scan.max_range_m == 50.0


def test_a_layout_that_does_not_fit_the_beams_is_said_and_not_used(tmp_path):
    params = [param("laser_front_laser_resolution", "1.0"), param("robot_front_laser_max", "40")]
    log = flaser_log(tmp_path / "misfit.clf", params, 361)
    with pytest.warns(InputWarning, match="do not fit the 361 beams"):
        opened = open_log(log)
    (scan, *_) = opened.scans()
    np.testing.assert_array_equal(scan.bearings, guess_laser_geometry(361).bearings(361))
    assert scan.max_range_m == 40.0


def test_stated_geometry_in_the_config_wins_over_the_params(tmp_path):
    log = flaser_log(tmp_path / "cfg.clf", [param("laser_front_laser_resolution", "0.5")], 361)
    opened = open_log(log, ScannerConfig(step_deg=0.25, first_angle_deg=-45.0))
    (scan, *_) = opened.scans()
    np.testing.assert_allclose(np.diff(scan.bearings), math.radians(0.25))
    assert opened.describe()["geometry"]["source"] == "config"


# -- the mounting ------------------------------------------------------------------------------

MOUNT = (0.2, 0.05, 0.1)
MOUNT_PARAMS = [
    param("robot_frontlaser_offset", "0.2"),
    param("robot_frontlaser_side_offset", "0.05"),
    param("robot_frontlaser_angular_offset", "0.1"),
]


def test_a_stated_mounting_the_laser_poses_lack_is_applied_to_the_odometry(tmp_path):
    log = flaser_log(tmp_path / "unapplied.clf", MOUNT_PARAMS, 180, laser_from_base=None)
    with no_input_warnings():
        opened = open_log(log, ScannerConfig(step_deg=1.0))
    assert opened.mount_source == "param" and opened.policy.pose_base_laser == MOUNT
    assert opened.policy.laser_odometry == "base" and opened.policy.output_frame == "base"
    # the laser odometry the estimators get is the base pose composed with the mounting
    scan = next(iter(opened.scans()))
    np.testing.assert_allclose(
        opened.policy.pose_odom_laser(scan),
        pose_compose(scan.pose_odom_base, np.array(MOUNT)),
        atol=1e-12,
    )


def test_a_stated_mounting_the_laser_poses_hold_keeps_the_logged_laser_pose(tmp_path):
    log = flaser_log(tmp_path / "applied.clf", MOUNT_PARAMS, 180, laser_from_base=np.array(MOUNT))
    with no_input_warnings():
        opened = open_log(log, ScannerConfig(step_deg=1.0))
    assert opened.mount_source == "param" and opened.policy.laser_odometry == "logged"
    np.testing.assert_allclose(opened.policy.pose_base_laser, MOUNT)


def test_laser_poses_with_another_offset_are_said_and_the_params_win(tmp_path):
    log = flaser_log(
        tmp_path / "other.clf", MOUNT_PARAMS, 180, laser_from_base=np.array([0.4, 0.0, 0.0])
    )
    with pytest.warns(InputWarning, match="PARAM lines mount the laser at .* differ"):
        opened = open_log(log, ScannerConfig(step_deg=1.0))
    assert opened.mount_source == "param" and opened.policy.laser_odometry == "base"
    # a stated mounting wins over both
    stated = open_log(log, ScannerConfig(step_deg=1.0, pose_base_laser=(0.4, 0.0, 0.0)))
    assert stated.mount_source == "config"


def test_the_rear_laser_reads_the_rear_params(tmp_path):
    lines = [param("robot_frontlaser_offset", "0.2"), param("robot_rearlaser_offset", "-0.3")]
    for k in range(5):
        base = np.array([0.3 * k, 0.0, 0.0])
        lines += [odom(base, k), flaser(np.full(180, 3.0), base, base, k + 0.5, kind="RLASER")]
    opened = open_log(write_log(tmp_path / "rear.clf", lines), ScannerConfig(step_deg=1.0))
    assert opened.policy.pose_base_laser == (-0.3, 0.0, 0.0)


def test_robotlaser_lines_keep_their_own_layout_and_check_the_mounting(tmp_path):
    lines = [param("laser_front_laser_resolution", "1.0"), *MOUNT_PARAMS]
    for k in range(5):
        base = np.array([0.3 * k, 0.0, 0.0])
        laser = pose_compose(base, np.array(MOUNT))
        lines += [odom(base, k), robotlaser(np.full(90, 3.0), -1.0, 0.02, 30.0, laser, base, k)]
    with no_input_warnings():
        opened = open_log(write_log(tmp_path / "rl.clf", lines))
        (scan, *_) = opened.scans()
    assert scan.bearings[0] == pytest.approx(-1.0) and scan.max_range_m == 30.0
    assert opened.describe()["geometry"]["source"] == "log"
    assert opened.mount_source == "param" and opened.policy.laser_odometry == "logged"


# -- writing them ------------------------------------------------------------------------------


def test_written_flaser_logs_state_their_layout_and_read_back_bit_identical(tmp_path):
    """The writer's PARAM lines give the bearings of CARMEN's rule to the last bit (so a run
    on a written log is the run on the scans), and the reader no longer has to guess."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        scans = list(open_log(DEMO_LOG).scans(max_scans=5))
    for n_beams in (180, 361):
        src = [s for s in scans] if n_beams == 180 else [_resampled(s, n_beams) for s in scans]
        out = tmp_path / f"w{n_beams}.clf"
        write_carmen(out, src)
        assert read_params(out).number("laser_front_laser_resolution") == 180 / (
            n_beams if n_beams == 180 else n_beams - 1
        )
        with no_input_warnings():
            back = list(open_log(out).scans())
        assert all(np.array_equal(a.bearings, b.bearings) for a, b in zip(src, back, strict=True))
    # the demo log itself states its layout: no warning when it is run
    with no_input_warnings():
        demo = open_log(DEMO_LOG)
    assert demo.describe()["geometry"]["source"] == "param"


def _resampled(scan, n_beams: int):
    from dataclasses import replace

    g = guess_laser_geometry(n_beams)
    return replace(
        scan,
        ranges=np.full(n_beams, 3.0),
        bearings=np.array(g.bearings(n_beams)),
        max_range_m=80.0,
    )


# -- scans without a pose of their own (RAWLASER) ----------------------------------------------


def test_rawlaser_scans_take_the_odom_pose_at_their_time_stamp():
    from slam.io.carmen import Odometry, with_odom_poses
    from slam.types import Scan

    def scan(t: float) -> Scan:
        return Scan(0, t, np.full(3, 2.0), np.array([-0.1, 0.0, 0.1]), max_range_m=80.0)

    def odo(t: float, pose) -> Odometry:
        return Odometry(0, t, np.array(pose, dtype=float), 0.0, 0.0, "")

    a, b = odo(10.0, [0.0, 0.0, 3.0]), odo(11.0, [1.0, 2.0, -3.0])  # the heading crosses ±π
    messages = [scan(9.5), scan(8.0), a, scan(10.25), scan(10.0), b, scan(11.5), scan(13.0)]
    out = list(with_odom_poses(iter(messages)))
    assert [type(m).__name__ for m in out] == [type(m).__name__ for m in messages]  # file order
    poses = [m.pose_odom_base for m in out if isinstance(m, Scan)]
    np.testing.assert_allclose(poses[0], [0.0, 0.0, 3.0])  # before the first: within 1 s
    assert poses[1] is None  # 2 s before it: none
    dtheta = math.remainder(-3.0 - 3.0, math.tau)  # +0.283 rad, through π
    expected = [0.25, 0.5, math.remainder(3.0 + 0.25 * dtheta, math.tau)]
    np.testing.assert_allclose(poses[2], expected, atol=1e-12)
    np.testing.assert_allclose(poses[3], [0.0, 0.0, 3.0])
    np.testing.assert_allclose(poses[4], [1.0, 2.0, -3.0])  # after the last: within 1 s
    assert poses[5] is None
    # scans with a pose of their own pass unchanged
    posed = replace_pose(scan(10.5))
    assert next(iter(with_odom_poses(iter([posed, a])))) is posed


def replace_pose(scan):
    from dataclasses import replace

    return replace(scan, pose_odom_base=np.zeros(3), pose_odom_laser=np.zeros(3))


def rawlaser_demo(path: Path, drop_odom_before: float | None = None) -> Path:
    """The demo log with its FLASER lines as RAWLASER1 lines (no pose; the same bearings to
    the last bit), its ODOM lines kept (optionally those before a time left out)."""
    step = repr(math.pi / 180.0)
    lines = []
    for line in DEMO_LOG.read_text().splitlines():
        t = line.split()
        if not t or t[0] in ("#", "PARAM"):
            continue
        if t[0] == "FLASER":
            n = int(t[1])
            stamp = t[n + 8]
            lines.append(
                f"RAWLASER1 0 {-math.pi / 2!r} {math.pi!r} {step} 80 0.01 0 {n} "
                f"{' '.join(t[2 : 2 + n])} 0 {stamp} nohost {stamp}"
            )
        elif drop_odom_before is None or float(t[7]) >= drop_odom_before:
            lines.append(line)
    return write_log(path, lines)


def b_first_odom(log: Path) -> np.ndarray:
    line = next(x for x in log.read_text().splitlines() if x.startswith("ODOM"))
    return np.array([float(v) for v in line.split()[1:4]])


def test_a_rawlaser_log_runs_as_the_flaser_log_it_came_from(tmp_path):
    from slam.cli import main
    from slam.io import read_tum

    n = 60
    raw = rawlaser_demo(tmp_path / "raw.clf")
    # the FLASER run with its laser odometry as the RAWLASER run gets it, the ODOM pose
    # composed with the (zero) mounting: the logged laser pose differs from it by 1e-16 rad
    (tmp_path / "base.toml").write_text('[scanner]\nlaser_odometry = "base"\n')
    options = ["--max-scans", str(n), "--quiet"]
    main(["slam", str(DEMO_LOG), "--out", str(tmp_path / "a"), *options]
         + ["--config", str(tmp_path / "base.toml")])  # fmt: skip
    main(["slam", str(raw), "--out", str(tmp_path / "b"), *options])
    a = read_tum(tmp_path / "a" / "trajectory.tum")
    b = read_tum(tmp_path / "b" / "trajectory.tum")
    np.testing.assert_array_equal(a.timestamps, b.timestamps)
    np.testing.assert_array_equal(b.poses, a.poses)
    # the first ODOM lines left out (scans every 0.75 s): the first scan, 1.5 s before the
    # first ODOM line kept, is left out and said; the second, 0.75 s before, takes its pose
    stamps = [float(line.split()[7]) for line in raw.read_text().splitlines()[:6:2]]
    late = rawlaser_demo(tmp_path / "late.clf", drop_odom_before=stamps[2])
    with pytest.warns(InputWarning, match="1 scan\\(s\\) lie more than 1 s outside"):
        kept = list(open_log(late).scans(max_scans=10))
    assert kept[0].timestamp == stamps[1] and [s.index for s in kept] == list(range(10))
    np.testing.assert_array_equal(kept[0].pose_odom_base, b_first_odom(late))
