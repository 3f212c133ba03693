"""The odometry's delay against the scans: its estimate, the shift, and how a log applies them."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slam.config import RunConfig
from slam.errors import ConfigError, InputError
from slam.experiments.robustness import OdometryLag, rewrite_lines
from slam.frontend.odometry_delay import (
    estimate_odometry_delay,
    median_interval,
    scan_slots,
    shift_odometry,
)
from slam.inputs import DELAY_CHI2_99, ScannerConfig, open_log
from slam.types import Scan

REPO_ROOT = Path(__file__).resolve().parents[1]
DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"


def _scans(poses: np.ndarray, with_base: bool = True) -> list[Scan]:
    bearings = np.linspace(-np.pi / 2, np.pi / 2, 5)
    return [
        Scan(
            index=k,
            timestamp=0.2 * k,
            ranges=np.full(5, 2.0),
            bearings=bearings,
            max_range_m=80.0,
            pose_odom_base=np.asarray(p, dtype=float) if with_base else None,
            pose_odom_laser=np.asarray(p, dtype=float) + np.array([0.1, 0.0, 0.0]),
        )
        for k, p in enumerate(poses)
    ]


def _base(scan: Scan) -> np.ndarray:
    assert scan.pose_odom_base is not None
    return scan.pose_odom_base


def _laser(scan: Scan) -> np.ndarray:
    assert scan.pose_odom_laser is not None
    return scan.pose_odom_laser


def _demo_scans(path: Path = DEMO_LOG) -> list[Scan]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return list(open_log(path, ScannerConfig(odometry_delay="off")).scans())


def _demo_scans_of_text(text: str) -> list[Scan]:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "log.clf"
        path.write_text(text)
        return _demo_scans(path)


def _lagged_demo(tmp_path: Path, lines: int) -> Path:
    text = DEMO_LOG.read_text().splitlines()
    path = tmp_path / f"lag{lines}.clf"
    path.write_text("".join(rewrite_lines(OdometryLag(lines), text, "log.clf")))
    return path


# -- the shift -------------------------------------------------------------------------------
def test_a_shift_reads_each_pose_between_the_scans_it_falls_between():
    k = np.arange(8, dtype=float)
    poses = np.column_stack([k, 0.5 * k, 0.1 * k])
    for delay in (0.5, 1.0, 2.25, -0.75, -2.0):
        out = list(shift_odometry(_scans(poses), delay))
        assert [s.index for s in out] == list(range(8))
        for s in out:
            at = float(np.clip(s.index + delay, 0, 7))
            expected = np.array([at, 0.5 * at, 0.1 * at])
            assert np.allclose(_base(s), expected, atol=1e-12)
            assert np.allclose(_laser(s), expected + [0.1, 0.0, 0.0], atol=1e-12)


def test_a_shift_interpolates_the_heading_along_the_shorter_arc():
    poses = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [0.0, 0.0, -2.9]])
    out = list(shift_odometry(_scans(poses), 0.5))
    # from 3.0 to −3.0 is 0.283 rad anticlockwise through π, not 6 rad clockwise
    assert math.isclose(abs(_base(out[0])[2]), math.pi, abs_tol=1e-9)
    assert math.isclose(_base(out[1])[2], -2.95, abs_tol=1e-12)


def test_no_delay_passes_the_scans_themselves_and_a_missing_pose_stays_missing():
    poses = np.zeros((4, 3))
    scans = _scans(poses, with_base=False)
    assert all(a is b for a, b in zip(shift_odometry(scans, 0.0), scans, strict=True))
    out = list(shift_odometry(scans, 1.0))
    assert all(s.pose_odom_base is None for s in out)
    with pytest.raises(InputError, match="finite"):
        list(shift_odometry(scans, float("nan")))


def test_a_shift_and_its_opposite_give_the_poses_back_inside_the_log():
    rng = np.random.default_rng(3)
    poses = np.cumsum(rng.normal(0.0, 0.1, (30, 3)), axis=0)
    there = list(shift_odometry(_scans(poses), 2.0))
    back = list(shift_odometry(there, -2.0))
    for s, p in zip(back[2:-2], poses[2:-2], strict=True):
        assert np.allclose(_base(s)[:2], p[:2], atol=1e-12)
        assert math.isclose(math.remainder(_base(s)[2] - p[2], 2 * math.pi), 0.0, abs_tol=1e-12)


def test_a_gap_counts_as_long_as_it_lasted_and_stamps_that_go_back_count_scans():
    stamps = [0.0, 0.2, 0.4, 2.4, 2.6, 3.0, 3.2]  # a 2 s gap; one scan missing at 2.8 s
    interval = median_interval(stamps)
    assert interval is not None and math.isclose(interval, 0.2)
    assert np.allclose(scan_slots(stamps, interval), [0.0, 1.0, 2.0, 12.0, 13.0, 14.0, 15.0])
    assert np.array_equal(scan_slots(stamps, None), np.arange(7.0))
    # a stamp that goes back or stands still: the stamps cannot tell the time between scans
    assert median_interval([0.0, 0.2, 0.1, 0.3]) is None
    assert median_interval([0.0, 0.2, 0.2, 0.4]) is None
    assert median_interval([1.0]) is None


def test_a_shift_reads_a_fraction_of_a_scan_not_of_the_gap_after_it():
    # the robot turns 1 rad over a 2 s gap (ten of the scans' 0.2 s intervals)
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.1], [0.0, 0.0, 1.1], [0.0, 0.0, 1.2]])
    scans = [
        replace(s, timestamp=t) for s, t in zip(_scans(poses), [0.0, 0.2, 2.2, 2.4], strict=True)
    ]
    out = list(shift_odometry(scans, 0.5, interval_s=0.2))
    assert np.allclose([_base(s)[2] for s in out], [0.05, 0.15, 1.15, 1.2], atol=1e-12)
    early = list(shift_odometry(scans, -0.5, interval_s=0.2))
    assert np.allclose([_base(s)[2] for s in early], [0.0, 0.05, 1.05, 1.15], atol=1e-12)
    # without the interval every scan counts as one, the gap too
    by_index = list(shift_odometry(scans, 0.5))
    assert math.isclose(_base(by_index[1])[2], 0.6, abs_tol=1e-12)


# -- the estimate ----------------------------------------------------------------------------
def test_the_demo_odometry_is_in_step_with_its_scans():
    est = estimate_odometry_delay(_demo_scans())
    assert est is not None and est.pairs >= 20
    assert abs(est.scans) < 0.1
    assert est.chi2 < DELAY_CHI2_99


@pytest.mark.parametrize("lines", [1, 2])
def test_a_logger_late_by_whole_lines_is_found(tmp_path, lines):
    est = estimate_odometry_delay(_demo_scans(_lagged_demo(tmp_path, lines)))
    assert est is not None
    assert abs(est.scans - lines) < 0.1
    assert abs(est.scans - lines) < 4.0 * est.sd_scans + 0.05
    assert est.chi2 > DELAY_CHI2_99


def test_odometry_early_by_a_line_is_found_as_a_negative_delay():
    est = estimate_odometry_delay(shift_odometry(_demo_scans(), 1.0))
    assert est is not None
    assert abs(est.scans + 1.0) < 0.1


def test_odometry_that_never_turns_gives_no_estimate():
    scans = _demo_scans()
    frozen = [
        Scan(
            index=s.index,
            timestamp=s.timestamp,
            ranges=s.ranges,
            bearings=s.bearings,
            max_range_m=s.max_range_m,
            pose_odom_base=np.zeros(3),
            pose_odom_laser=np.zeros(3),
        )
        for s in scans
    ]
    assert estimate_odometry_delay(frozen) is None


# -- how a log applies it --------------------------------------------------------------------
def test_the_odometry_is_read_as_logged_unless_asked():
    assert ScannerConfig().odometry_delay == "off"
    raw = _demo_scans()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = open_log(DEMO_LOG, ScannerConfig())
        read = list(log.scans())
    assert log.describe()["odometry_delay"] == {
        "source": "off",
        "scans": 0.0,
        "interval_s": None,
        "estimate": None,
    }
    for a, b in zip(read, raw, strict=True):
        assert np.array_equal(_laser(a), _laser(b))


def test_the_delay_settings_are_validated():
    with pytest.raises(ConfigError, match="odometry_delay"):
        ScannerConfig(odometry_delay="auto")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="odometry_delay_scans"):
        ScannerConfig(odometry_delay_scans=5.0)
    with pytest.raises(ConfigError, match="odometry_delay_scans"):
        ScannerConfig(odometry_delay_scans=float("inf"))


def test_the_delay_settings_round_trip_through_toml(tmp_path):
    config = RunConfig(scanner=ScannerConfig(odometry_delay="estimated", odometry_delay_scans=-0.5))
    path = tmp_path / "config.toml"
    config.to_toml(path)
    back = RunConfig.from_toml(path)
    assert back.scanner.odometry_delay == "estimated"
    assert back.scanner.odometry_delay_scans == -0.5


def test_a_lagged_log_is_read_in_step_and_says_so(tmp_path):
    path = _lagged_demo(tmp_path, 1)
    raw = _demo_scans()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = open_log(path, ScannerConfig(odometry_delay="estimated"))
        read = list(log.scans())
    info = log.describe()["odometry_delay"]
    assert info["source"] == "estimated"
    assert abs(info["scans"] - 1.0) < 0.1
    assert info["estimate"]["chi2_against_none"] > DELAY_CHI2_99
    # the lagged log read at the estimate is the log in step, to the estimate's fraction
    errors = [
        np.hypot(*(_laser(a)[:2] - _laser(b)[:2]))
        for a, b in zip(read[2:-2], raw[2:-2], strict=True)
    ]
    steps = [
        np.hypot(*(_laser(a)[:2] - _laser(b)[:2]))
        for a, b in zip(raw[3:-1], raw[2:-2], strict=True)
    ]
    assert np.median(errors) < 0.15 * np.median(steps)


def test_a_stated_delay_is_used_as_it_is_and_off_reads_the_log_as_logged():
    raw = _demo_scans()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stated = open_log(DEMO_LOG, ScannerConfig(odometry_delay_scans=1.0))
        read = list(stated.scans())
        off = open_log(DEMO_LOG, ScannerConfig(odometry_delay="off"))
        as_logged = list(off.scans())
    assert stated.describe()["odometry_delay"] == {
        "source": "config",
        "scans": 1.0,
        "interval_s": float(np.median(np.diff([s.timestamp for s in raw]))),
        "estimate": None,
    }
    for a, b in zip(read[:-1], raw[1:], strict=True):
        assert a.pose_odom_laser is not None and b.pose_odom_laser is not None
        assert np.array_equal(_laser(a), _laser(b))
    for a, b in zip(as_logged, raw, strict=True):
        assert a.pose_odom_laser is not None and b.pose_odom_laser is not None
        assert np.array_equal(_laser(a), _laser(b))
    assert off.describe()["odometry_delay"]["source"] == "off"


def test_scans_that_turn_against_the_odometry_give_no_estimate():
    # every scan's readings in reverse order: a scanner mounted upside down, not stated so
    lines = []
    for line in DEMO_LOG.read_text().splitlines():
        tokens = line.split()
        if tokens and tokens[0] == "FLASER":
            n = int(tokens[1])
            tokens[2 : 2 + n] = tokens[2 : 2 + n][::-1]
            line = " ".join(tokens)
        lines.append(line + "\n")
    scans = _demo_scans_of_text("".join(lines))
    assert estimate_odometry_delay(scans) is None


def test_the_script_estimates_a_lagged_log_read_with_the_delay_applied_in_its_config(tmp_path):
    # the log one line late, and a configuration that would already apply a delay: the
    # script reads the poses as logged, so it finds the whole line
    path = _lagged_demo(tmp_path, 1)
    config = tmp_path / "config.toml"
    RunConfig(scanner=ScannerConfig(odometry_delay="estimated")).to_toml(config)
    out = tmp_path / "delay.json"
    done = subprocess.run(
        [sys.executable, str(REPO_ROOT / "scripts" / "odometry_delay.py"), str(path),
         "--config", str(config), "--json", str(out)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "scans late" in done.stdout
    result = json.loads(out.read_text())
    assert abs(result["estimate"]["scans"] - 1.0) < 0.1
    assert result["applied_when_estimated"] is True
