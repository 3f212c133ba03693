"""slam.extraction: the batch path equals one extract_lines call per scan, max range honoured."""

from __future__ import annotations

import numpy as np

from linefit import LineFitConfig, extract_lines
from slam.extraction import extract_scan_lines, iter_scan_lines
from slam.types import Scan


def room_scan(index: int, n_beams: int, max_range: float, rng: np.random.Generator) -> Scan:
    """A wall 3 m ahead on the right half; the left half sees nothing (max-range readings)."""
    bearings = np.linspace(-np.pi / 2, np.pi / 2, n_beams)
    ranges = np.full(n_beams, max_range)
    right = bearings < -0.1
    ranges[right] = 3.0 / np.cos(bearings[right] + 0.6) + rng.normal(0, 0.005, right.sum())
    ranges[right & (ranges > max_range)] = max_range
    return Scan(index, float(index), ranges, bearings, max_range_m=max_range)


def test_batches_equal_single_calls_and_skip_no_return_readings():
    rng = np.random.default_rng(3)
    scans = [room_scan(i, 180 if i < 5 else 361, 81.83, rng) for i in range(9)]
    cfg = LineFitConfig()
    out = list(iter_scan_lines(iter(scans), cfg, batch_size=4))
    assert [s.index for s, _ in out] == list(range(9))
    for scan, lines in out:
        single = extract_lines(scan.ranges, scan.bearings, cfg, max_range_m=scan.max_range_m)
        assert len(lines) == len(single) >= 1
        for a, b in zip(lines, single, strict=True):
            np.testing.assert_allclose([a.r, a.alpha], [b.r, b.alpha], atol=1e-9)
        # no line is made of the max-range arc: every supporting reading is a real return
        for line in lines:
            assert np.all(scan.ranges[line.indices] < scan.max_range_m)
        np.testing.assert_allclose(
            [ln.r for ln in extract_scan_lines(scan, cfg)], [ln.r for ln in lines], atol=1e-12
        )


def test_a_scans_lines_do_not_depend_on_the_rest_of_its_batch(shared_data):
    # ACES scans 3328-3583 as one batch (the runner's chunk): before the Hough bin centres
    # were computed from the bin's signed index, the batch's largest range (here 44 m, scan
    # 3328, against 19.6 m for scan 3451 alone) shifted their rounding and scans 3395, 3451
    # and 3457 got other lines in the batch than alone; on the whole log 5 scans differed,
    # enough to change which loop closures the graph accepted.
    from itertools import islice

    from linefit import extract_lines_batch
    from slam.io.carmen import iter_scans

    config = LineFitConfig()
    scans = list(islice(iter_scans(shared_data / "aces" / "aces.clf"), 3328, 3584))
    batch = extract_lines_batch(
        np.stack([s.ranges for s in scans]),
        scans[0].bearings,
        config,
        max_range_m=scans[0].max_range_m,
    )
    for scan, in_batch in zip(scans, batch, strict=True):
        alone = extract_lines(scan.ranges, scan.bearings, config, max_range_m=scan.max_range_m)
        # the same groups of points (fits equal to rounding: sums run in another order)
        assert [ln.n_points for ln in alone] == [ln.n_points for ln in in_batch], scan.index
        for a, b in zip(alone, in_batch, strict=True):
            assert abs(a.r - b.r) < 1e-9 and abs(a.alpha - b.alpha) < 1e-9, scan.index
