"""CARMEN writer: write → read round trips (FLASER, ROBOTLASER1, a real log) and bad scans."""

from __future__ import annotations

from itertools import islice

import numpy as np
import pytest

from slam.errors import ConfigError, InputError
from slam.io.carmen import iter_odometry, iter_scans
from slam.io.carmen_write import flaser_bearings, write_carmen
from slam.types import Scan


def _scans(rng, n_scans=20, n_beams=180, bearings=None, max_range=80.0, offset=(0.1, 0.0, 0.0)):
    bearings = flaser_bearings(n_beams) if bearings is None else bearings
    heading = np.cumsum(rng.normal(0.0, 0.1, n_scans))
    xy = np.cumsum(rng.normal(0.0, 0.3, (n_scans, 2)), axis=0)
    out = []
    for k in range(n_scans):
        ranges = rng.uniform(0.02, 30.0, n_beams)
        ranges[rng.random(n_beams) < 0.05] = max_range
        base = np.array([xy[k, 0], xy[k, 1], np.angle(np.exp(1j * heading[k]))])
        c, s = np.cos(base[2]), np.sin(base[2])
        laser = base + [c * offset[0], s * offset[0], 0.0]
        out.append(
            Scan(
                index=k,
                timestamp=976052857.337530 + 0.2 * k + 1e-6 * k,
                ranges=ranges,
                bearings=bearings,
                max_range_m=max_range,
                pose_odom_base=base,
                pose_odom_laser=laser,
                source=f"test:{k}",
            )
        )
    return out


def _assert_same(read, written, decimals):
    assert len(read) == len(written)
    for a, b in zip(read, written, strict=True):
        np.testing.assert_allclose(a.ranges, b.ranges, rtol=0, atol=0.5 * 10.0**-decimals + 1e-12)
        np.testing.assert_allclose(a.bearings, b.bearings, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.pose_odom_base, b.pose_odom_base, rtol=0, atol=5.1e-7)
        np.testing.assert_allclose(a.pose_odom_laser, b.pose_odom_laser, rtol=0, atol=5.1e-7)
        assert f"{a.timestamp:.6f}" == f"{b.timestamp:.6f}"
        assert a.max_range_m == b.max_range_m
        assert (a.valid_mask() == b.valid_mask()).all()


def test_flaser_round_trip_with_odometry(tmp_path, rng):
    scans = _scans(rng)
    path = tmp_path / "log.clf"
    stats = write_carmen(path, iter(scans), range_decimals=4)
    assert (stats.scans, stats.odometry, stats.message) == (20, 20, "FLASER")
    text = path.read_text().splitlines()
    assert text[0] == "# CARMEN Logfile"
    flaser = [line.split() for line in text if line.startswith("FLASER")]
    assert len(flaser) == 20 and len(flaser[0]) == 2 + 180 + 6 + 3
    assert flaser[0][1] == "180" and flaser[0][-3] == flaser[0][-1] == "976052857.337530"
    _assert_same(list(iter_scans(path)), scans, 4)
    odom = list(iter_odometry(path))
    assert len(odom) == 20
    for o, s in zip(odom, scans, strict=True):
        np.testing.assert_allclose(o.pose_odom_base, s.pose_odom_base, atol=5.1e-7)
    # Velocities: forward displacement and heading change over the time step.
    p0, p1 = scans[0].pose_odom_base, scans[1].pose_odom_base
    dt = scans[1].timestamp - scans[0].timestamp
    forward = np.cos(p0[2]) * (p1[0] - p0[0]) + np.sin(p0[2]) * (p1[1] - p0[1])
    assert odom[0].tv_mps == 0.0
    assert odom[1].tv_mps == pytest.approx(forward / dt, abs=1e-6)
    assert odom[1].rv_radps == pytest.approx(np.angle(np.exp(1j * (p1[2] - p0[2]))) / dt, abs=1e-6)


@pytest.mark.parametrize(
    ("n_beams", "first_deg", "step_deg", "max_range"),
    [(720, -90.0, 0.25, 80.0), (180, -90.0, 1.0, 30.0), (361, -90.0, 0.5, 81.91)],
)
def test_robotlaser_when_flaser_cannot_carry_the_geometry(
    tmp_path, rng, n_beams, first_deg, step_deg, max_range
):
    bearings = np.deg2rad(first_deg + step_deg * np.arange(n_beams))
    scans = _scans(rng, 5, n_beams, bearings, max_range)
    path = tmp_path / "log.clf"
    assert write_carmen(path, scans, range_decimals=3).message == "ROBOTLASER1"
    _assert_same(list(iter_scans(path)), scans, 3)


def test_infinite_readings_become_max_range_and_flaser_can_be_forced(tmp_path, rng):
    scans = _scans(rng, 3)
    inf_scan = Scan(
        0,
        1.0,
        np.where(np.arange(180) % 7 == 0, np.inf, 2.0),
        flaser_bearings(180),
        80.0,
        np.zeros(3),
        None,
    )
    path = tmp_path / "log.clf"
    write_carmen(path, [inf_scan], message="FLASER", odometry=False)
    (read,) = iter_scans(path)
    assert (read.ranges[::7] == 80.0).all() and not read.valid_mask()[::7].any()
    np.testing.assert_array_equal(read.pose_odom_laser, np.zeros(3))  # laser pose := base pose
    assert not any(line.startswith("ODOM") for line in path.read_text().splitlines())
    assert write_carmen(path, scans, message="ROBOTLASER1").message == "ROBOTLASER1"
    _assert_same(list(iter_scans(path)), scans, 4)


def test_bad_scans_are_errors_naming_the_scan(tmp_path, rng):
    path = tmp_path / "log.clf"
    good = _scans(rng, 2)
    bad_range = Scan(0, 1.0, np.array([1.0, np.nan]), np.array([0.0, 0.1]), 80.0, np.zeros(3))
    with pytest.raises(InputError, match="NaN or negative"):
        write_carmen(path, [bad_range])
    no_pose = Scan(0, 1.0, np.ones(180), flaser_bearings(180), 80.0, source="x.clf:7")
    with pytest.raises(InputError, match=r"x\.clf:7.*without an odometry pose"):
        write_carmen(path, [no_pose])
    ragged = Scan(5, 2.0, np.ones(181), flaser_bearings(181), 80.0, np.zeros(3))
    with pytest.raises(InputError, match="one beam count"):
        write_carmen(path, [*good, ragged], message="FLASER")
    uneven = Scan(0, 1.0, np.ones(3), np.array([0.0, 0.1, 0.3]), 30.0, np.zeros(3))
    with pytest.raises(InputError, match="evenly spaced"):
        write_carmen(path, [uneven])
    with pytest.raises(ConfigError):
        write_carmen(path, good, message="RAWLASER1")  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        write_carmen(path, good, range_decimals=0)
    with pytest.raises(ConfigError):
        write_carmen(path, good, hostname="two words")


@pytest.mark.realdata
def test_real_log_round_trip(tmp_path, shared_data):
    log = shared_data / "intel" / "intel.clf"
    scans = list(islice(iter_scans(log), 60))
    path = tmp_path / "intel_part.clf"
    write_carmen(path, scans, range_decimals=2)
    again = list(iter_scans(path))
    for a, b in zip(again, scans, strict=True):
        np.testing.assert_array_equal(a.ranges, b.ranges)  # Intel's ranges have 2 decimals
        np.testing.assert_allclose(a.bearings, b.bearings, atol=1e-12)
        assert f"{a.timestamp:.6f}" == f"{b.timestamp:.6f}"
        np.testing.assert_allclose(a.pose_odom_base, b.pose_odom_base, atol=5.1e-7)
