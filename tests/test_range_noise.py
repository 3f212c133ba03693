"""The scans' noise against Eq. 8 (``ScanPoints.noise_ratio``) and the run's check of it."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest

from linefit.config import SensorNoiseConfig
from slam.frontend.scan_match import ScanMatchConfig, scan_points
from slam.line_slam.range_noise import (
    MIN_KEYFRAMES,
    WARN_SIGMA_RATIO,
    RangeNoiseCheck,
)

BEARINGS = np.deg2rad(np.arange(-90.0, 90.0, 1.0))


def room_ranges(bearings: np.ndarray) -> np.ndarray:
    """Ranges from (0.7, -0.4) to the walls of the room |x| <= 3, |y| <= 2 (m)."""
    cx, cy, half_w, half_h = 0.7, -0.4, 3.0, 2.0
    c, s = np.cos(bearings), np.sin(bearings)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (half_w - cx) / c, np.where(c < 0, (-half_w - cx) / c, np.inf))
        ty = np.where(s > 0, (half_h - cy) / s, np.where(s < 0, (-half_h - cy) / s, np.inf))
    return np.minimum(tx, ty)


def sigma_ratio_of_scans(k: float, seed: int, n_scans: int = 20) -> float:
    """The check's ratio over scans of the room with range noise ``k`` times Eq. 8's."""
    rng = np.random.default_rng(seed)
    noise = SensorNoiseConfig()
    check = RangeNoiseCheck(noise.sigma_range_m)
    truth = room_ranges(BEARINGS)
    for _ in range(max(n_scans, MIN_KEYFRAMES)):
        ranges = truth + rng.normal(0.0, k * noise.sigma_range_m, truth.size)
        check.add(scan_points(ranges, BEARINGS, 80.0, noise, ScanMatchConfig()))
    ratio = check.sigma_ratio
    assert ratio is not None
    return ratio


@pytest.mark.parametrize("k", [1.0, 3.0])
def test_the_ratio_reads_the_range_noise_the_scans_were_made_with(k: float) -> None:
    # noise as Eq. 8 says reads about 1; three times the noise about 3 (20 scans of 180
    # beams: the median's spread is a few per cent)
    assert sigma_ratio_of_scans(k, seed=5) == pytest.approx(k, rel=0.12)


def test_the_ratio_does_not_depend_on_the_beam_spacing() -> None:
    # at 0.5 degrees the local line spans five points (2 degrees), with its own chi-square
    rng = np.random.default_rng(8)
    noise = SensorNoiseConfig()
    bearings = np.deg2rad(np.arange(-90.0, 90.0, 0.5))
    truth = room_ranges(bearings)
    ratios = [
        scan_points(
            truth + rng.normal(0.0, 2.0 * noise.sigma_range_m, truth.size),
            bearings,
            80.0,
            noise,
            ScanMatchConfig(),
        ).noise_ratio
        for _ in range(20)
    ]
    assert math.sqrt(float(np.median(ratios))) == pytest.approx(2.0, rel=0.12)


def test_no_ratio_without_local_lines_or_straight_windows() -> None:
    noise = SensorNoiseConfig()
    truth = room_ranges(BEARINGS)
    matched_only = scan_points(truth, BEARINGS, 80.0, noise, ScanMatchConfig(), False)
    assert math.isnan(matched_only.noise_ratio)
    # every neighbour further than max_neighbour_gap_m: no window to measure
    sparse = replace(ScanMatchConfig(), max_neighbour_gap_m=1e-3)
    assert math.isnan(scan_points(truth, BEARINGS, 80.0, noise, sparse).noise_ratio)
    check = RangeNoiseCheck(noise.sigma_range_m)
    check.add(matched_only)
    assert check.keyframes == 0


def test_the_check_reports_after_enough_keyframes_and_warns_once_above_its_limit() -> None:
    noise = SensorNoiseConfig()
    quiet = RangeNoiseCheck(noise.sigma_range_m)
    noisy = RangeNoiseCheck(noise.sigma_range_m)
    rng = np.random.default_rng(2)
    truth = room_ranges(BEARINGS)
    for _ in range(MIN_KEYFRAMES):
        assert quiet.sigma_ratio is None  # a median of fewer keyframes is not reported
        assert noisy.warning() is None
        for check, k in ((quiet, 1.0), (noisy, 2.0 * WARN_SIGMA_RATIO)):
            ranges = truth + rng.normal(0.0, k * noise.sigma_range_m, truth.size)
            check.add(scan_points(ranges, BEARINGS, 80.0, noise, ScanMatchConfig()))
    assert quiet.warning() is None
    summary = quiet.summary()
    assert summary["keyframes"] == MIN_KEYFRAMES
    assert summary["sigma_ratio"] == pytest.approx(1.0, rel=0.2)
    message = noisy.warning()
    assert message is not None and "sigma_range_m were 0.0" in message
    assert noisy.warning() is None  # once


def test_the_ratio_is_the_square_root_of_the_median_of_every_keyframe_so_far() -> None:
    """Read after every keyframe, in any order of arrival, odd and even counts, NaN left out:
    the square root of ``np.median`` of the finite ratios added, to the bit."""
    noise = SensorNoiseConfig()
    check = RangeNoiseCheck(noise.sigma_range_m)
    points = scan_points(room_ranges(BEARINGS), BEARINGS, 80.0, noise, ScanMatchConfig())
    rng = np.random.default_rng(4)
    added: list[float] = []
    for i in range(3 * MIN_KEYFRAMES + 1):
        ratio = float("nan") if i % 7 == 3 else float(rng.gamma(2.0, 1.0))
        check.add(replace(points, noise_ratio=ratio))
        if math.isfinite(ratio):
            added.append(ratio)
        if len(added) < MIN_KEYFRAMES:
            assert check.sigma_ratio is None
        else:
            assert check.sigma_ratio == math.sqrt(float(np.median(added)))
    assert check.keyframes == len(added)


def test_a_run_reports_its_range_noise_and_warns_when_the_scans_are_noisier() -> None:
    from slam.line_slam.config import KeyframeConfig, SlamConfig
    from slam.line_slam.pipeline import LineSlam
    from slam.line_slam.report import SlamWarning
    from slam.types import Scan

    def run(k: float) -> tuple[dict[str, object], list[str]]:
        rng = np.random.default_rng(4)
        # every scan a keyframe (5 cm apart)
        slam = LineSlam(SlamConfig(keyframes=KeyframeConfig(min_distance_m=0.04)))
        noise = SensorNoiseConfig()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for i in range(40):
                # the robot drives 5 cm per scan along the room's long axis
                x = -1.0 + 0.05 * i
                c, s = np.cos(BEARINGS), np.sin(BEARINGS)
                ranges = np.minimum(
                    np.where(c > 0, (3.0 - x) / c, np.where(c < 0, (-3.0 - x) / c, np.inf)),
                    np.where(s > 0, 2.4 / s, np.where(s < 0, -1.6 / s, np.inf)),
                )
                ranges = ranges + rng.normal(0.0, k * noise.sigma_range_m, ranges.size)
                pose = np.array([x, 0.0, 0.0])
                slam.add_scan(Scan(i, 0.1 * i, ranges, BEARINGS, 80.0, pose, pose.copy(), "room"))
            stats = slam.result().stats
        return stats["range_noise"], [
            str(w.message) for w in caught if issubclass(w.category, SlamWarning)
        ]

    summary, warned = run(1.0)
    assert summary["sigma_ratio"] == pytest.approx(1.0, rel=0.2)
    assert not any("scatter" in m for m in warned)
    summary, warned = run(5.0)
    assert summary["sigma_ratio"] == pytest.approx(5.0, rel=0.2)
    assert sum("scatter" in m for m in warned) == 1


def test_the_real_logs_read_as_their_ranges_are_written(shared_data):
    # ACES's ranges are written in steps of 2.5-5 cm: its points scatter several times as
    # much as Eq. 8 with 5 mm says; Intel's (whole centimetres) about as Eq. 8 says.  Every
    # 10th of the first 3,000 scans, as the check counts keyframes.
    from itertools import islice

    from slam.inputs import InputPolicy, read_log_scans
    from slam.io.catalog import resolve_log

    noise = SensorNoiseConfig()
    ratio = {}
    for name in ("intel", "aces"):
        check = RangeNoiseCheck(noise.sigma_range_m)
        log = resolve_log(name, root=shared_data).log
        for scan in islice(read_log_scans(log, InputPolicy()), 0, 3000, 10):
            check.add(
                scan_points(scan.ranges, scan.bearings, scan.max_range_m, noise, ScanMatchConfig())
            )
        ratio[name] = check.sigma_ratio
    assert ratio["intel"] is not None and ratio["intel"] < 1.5
    assert ratio["aces"] is not None and ratio["aces"] > WARN_SIGMA_RATIO
