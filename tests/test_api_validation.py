"""Public API misuse raises the package's own errors, naming the argument.

The cases of the issue: unlimited ``1e300`` ranges, a dict as configuration, ``Scan`` with
lists, odometry of the wrong shape, lines that are not ``Line``, a NaN time stamp, bearings in
degrees; plus the run functions' configuration argument.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import REPO_ROOT

from linefit import LineFitConfig, extract_lines, extract_lines_batch
from slam.config import RunConfig
from slam.ekf import EkfSlam
from slam.errors import ConfigError, InputError, LineslamError
from slam.line_slam import LineSlam, SlamConfig
from slam.types import Scan

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
PHI = np.radians(np.arange(-90.0, 90.0))
WALL = 2.0 / np.clip(np.abs(np.cos(PHI)), 0.1, None)


def scan(**changes):
    fields = dict(
        index=0,
        timestamp=1.0,
        ranges=WALL,
        bearings=PHI,
        max_range_m=80.0,
        pose_odom_laser=np.zeros(3),
        source="run.clf:12",
    )
    fields.update(changes)
    return Scan(**fields)


def test_unlimited_huge_ranges_are_an_input_error():
    with pytest.raises(InputError, match=r"ranges: reading 0 of scan 0 is 1e\+300 m"):
        extract_lines(np.full(180, 1e300), PHI)
    with pytest.raises(InputError, match="reading 5 of scan 1"):
        d = np.tile(WALL, (2, 1))
        d[1, 5] = 1e300
        extract_lines_batch(d, PHI)
    # with a range limit they are no returns
    assert extract_lines(np.full(180, 1e300), PHI, max_range_m=80.0) == []
    assert extract_lines(np.full(180, 1e300), PHI, LineFitConfig(max_range_m=80.0)) == []


def test_a_dict_as_configuration_is_a_config_error():
    with pytest.raises(ConfigError, match="config must be a LineFitConfig, got dict"):
        extract_lines(WALL, PHI, {"grouping": "hough"})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="config must be a SlamConfig, got dict"):
        LineSlam({"backend": "batch"})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="linefit_config must be a LineFitConfig"):
        LineSlam(SlamConfig(), {})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="config must be an EkfConfig, got dict"):
        EkfSlam({})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="policy must be an InputPolicy"):
        EkfSlam(policy="base")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"RunConfig\.linefit must be a LineFitConfig"):
        RunConfig(linefit={})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="seed must be a whole number"):
        RunConfig(seed=1.5)  # type: ignore[arg-type]


def test_run_functions_check_their_configuration(tmp_path):
    from slam.mapping import run_map
    from slam.runner import run_ekf, run_slam

    for fn in (run_slam, run_ekf, run_map):
        with pytest.raises(ConfigError, match="config must be a RunConfig, got dict"):
            fn(DEMO_LOG, tmp_path / "o", {})  # type: ignore[arg-type]
    assert not (tmp_path / "o").exists()


def test_scan_accepts_lists_and_checks_its_fields():
    s = Scan(0, 1.0, [1.0, 2.0, 3.0], [0.0, 0.1, 0.2], pose_odom_base=[0, 0, 0])
    assert isinstance(s.ranges, np.ndarray) and s.ranges.dtype == np.float64
    assert s.valid_mask().tolist() == [True, True, True]
    assert s.pose_odom_base is not None and s.pose_odom_base.shape == (3,)
    float32 = np.ones(3, dtype=np.float32)
    assert Scan(0, 1.0, float32, float32).ranges is float32  # float arrays pass unchanged
    bad = {
        "pose_odom_base": (np.zeros(2), r"pose_odom_base must have shape \(3,\)"),
        "pose_odom_laser": ("abc", "pose_odom_laser must be three numbers"),
        "ranges": (np.ones((2, 90)), "ranges must be one-dimensional"),
        "bearings": (PHI[:10], r"ranges \(180\) and bearings \(10\) differ"),
        "timestamp": (float("nan"), "timestamp must be finite, got nan"),
        "max_range_m": (0.0, "max_range_m must be > 0"),
        "index": (1.5, "index must be a whole number"),
        "odometry_step_cov": (np.eye(2), r"odometry_step_cov must have shape \(3, 3\)"),
    }
    for name, (value, message) in bad.items():
        with pytest.raises(InputError, match=message) as info:
            scan(**{name: value})
        assert str(info.value).startswith("run.clf:12: Scan ")
    with pytest.raises(InputError, match="timestamp must be a number"):
        scan(timestamp="now")
    with pytest.raises(InputError, match="odometry_step_cov must be finite"):
        scan(odometry_step_cov=np.full((3, 3), np.nan))
    assert scan(odometry_step_cov=np.eye(3).tolist()).odometry_step_cov.shape == (3, 3)


@pytest.mark.parametrize("make", [LineSlam, EkfSlam])
def test_add_scan_names_bad_arguments(make):
    estimator = make()
    with pytest.raises(InputError, match=r"lines\[0\] must be a linefit\.Line, got int"):
        estimator.add_scan(scan(), [1, 2, 3])
    with pytest.raises(InputError, match=r"lines must be a sequence of linefit\.Line"):
        estimator.add_scan(scan(), 7)
    with pytest.raises(InputError, match=r"scan must be a slam\.types\.Scan, got dict"):
        estimator.add_scan({"ranges": WALL})
    # a good scan after the refused ones is processed normally
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a keyframe without lines: expected here
        report = estimator.add_scan(scan(), [])
    assert report is not None


def test_add_scans_names_the_bad_scan():
    with pytest.raises(InputError, match=r"scans\[1\] must be a slam\.types\.Scan"):
        LineSlam().add_scans([scan(), None])


def test_nan_time_stamp_cannot_reach_add_scan():
    with pytest.raises(InputError, match=r"run\.clf:12: Scan 0: timestamp must be finite"):
        LineSlam().add_scan(scan(timestamp=float("nan")), [])


def test_bearings_in_degrees_are_refused():
    with pytest.raises(InputError, match="degrees given for radians"):
        extract_lines(WALL, np.degrees(PHI))
    # a full 360-degree scanner in radians is fine
    full = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    assert extract_lines(np.full(720, 3.0), full) != []


def test_every_error_is_a_lineslam_error():
    for exc in (InputError, ConfigError):
        assert issubclass(exc, LineslamError)
