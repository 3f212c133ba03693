"""The compiled extraction path (linefit.kernel) against the numpy reference path."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from linefit import Line, LineFitConfig, SensorNoiseConfig, extract_lines, extract_lines_batch
from linefit.batch import extract_lines_batch_numpy

# walls of a room with a box and a pillar (segments a -> b, metres)
WALLS = np.array(
    [
        [[-5.0, -3.0], [5.0, -3.0]],
        [[5.0, -3.0], [5.0, 3.0]],
        [[5.0, 3.0], [1.0, 3.0]],  # a door between x = 0 and x = 1
        [[0.0, 3.0], [-5.0, 3.0]],
        [[-5.0, 3.0], [-5.0, -3.0]],
        [[1.5, -1.0], [2.5, -1.0]],
        [[2.5, -1.0], [2.5, 0.2]],
        [[2.5, 0.2], [1.5, 0.2]],
        [[1.5, 0.2], [1.5, -1.0]],
        [[-2.0, 1.0], [-1.8, 1.0]],
        [[-1.8, 1.0], [-1.8, 1.2]],
    ]
)


def room_scans(n_scans: int, n_beams: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Noisy ranges of ``n_scans`` scans from random poses in the room (NaN dropouts)."""
    rng = np.random.default_rng(seed)
    bearings = np.linspace(-np.pi / 2, np.pi / 2, n_beams)
    a = WALLS[:, 0]
    e = WALLS[:, 1] - a
    out = np.empty((n_scans, n_beams))
    for k in range(n_scans):
        pos = np.array([rng.uniform(-4.5, 0.5), rng.uniform(-2.5, 2.5)])
        heading = rng.uniform(-np.pi, np.pi)
        d = np.stack([np.cos(bearings + heading), np.sin(bearings + heading)], axis=1)
        # pos + t d = a + u e  for every beam and wall
        w = a[None, :, :] - pos
        den = d[:, None, 0] * -e[None, :, 1] + d[:, None, 1] * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[..., 0] * -e[None, :, 1] + w[..., 1] * e[None, :, 0]) / den
            u = (d[:, None, 0] * w[..., 1] - d[:, None, 1] * w[..., 0]) / den
        t = np.where((u >= 0.0) & (u <= 1.0) & (t > 0.0), t, np.inf)
        r = t.min(axis=1) + rng.normal(0.0, 0.005, n_beams)
        r[rng.random(n_beams) < 0.03] = np.nan
        out[k] = np.where(np.isfinite(r), r, 40.0)  # no hit: max range
    return out, bearings


def assert_same_lines(got: list[list[Line]], want: list[list[Line]], rtol: float = 1e-9) -> int:
    """Same lines (count, points, segments), values to rounding; returns the number of lines."""
    assert len(got) == len(want)
    n = 0
    for scan, (ga, wa) in enumerate(zip(got, want, strict=True)):
        assert len(ga) == len(wa), f"scan {scan}: {len(ga)} lines, want {len(wa)}"
        for x, y in zip(ga, wa, strict=True):
            assert x.n_points == y.n_points
            np.testing.assert_array_equal(x.indices, y.indices)
            assert x.segments_s.shape == y.segments_s.shape
            np.testing.assert_allclose([x.r, x.alpha, x.s], [y.r, y.alpha, y.s], rtol, 1e-12)
            scale = np.sqrt(np.outer(np.diag(y.cov), np.diag(y.cov)))
            assert np.all(np.abs(x.cov - y.cov) <= rtol * scale)
            np.testing.assert_allclose(x.segments_s, y.segments_s, rtol, 1e-12)
            np.testing.assert_allclose(x.segments_var, y.segments_var, rtol, 0.0)
            n += 1
    return n


CONFIGS = {
    "default": LineFitConfig(),
    "split_merge": LineFitConfig(grouping="split_merge"),
    "matched": LineFitConfig(min_points=9, min_length_m=0.5, max_range_m=30.0),
    "unweighted": LineFitConfig(weighted=False),
    "prop2": LineFitConfig(alpha_update="prop2", max_iterations=200),
    "reading": LineFitConfig(noise=SensorNoiseConfig(bearing_error="reading")),
    "pure hough": LineFitConfig(hough_recover=False, merge_collinear=False),
    "range noise": LineFitConfig(noise=SensorNoiseConfig(sigma_range_per_m=0.002)),
}


@pytest.mark.parametrize("name", list(CONFIGS))
def test_compiled_matches_numpy_on_constructed_scans(name: str) -> None:
    ranges, bearings = room_scans(40, 181, seed=3)
    cfg = CONFIGS[name]
    got = extract_lines_batch(ranges, bearings, cfg, max_range_m=40.0)
    want = extract_lines_batch_numpy(ranges, bearings, cfg, max_range_m=40.0)
    assert assert_same_lines(got, want) > 40  # several lines per scan were compared


def test_compiled_matches_numpy_with_sigma_range_fn() -> None:
    ranges, bearings = room_scans(10, 361, seed=4)

    def sigma(d: np.ndarray) -> np.ndarray:
        return 0.004 + 0.001 * d * d

    got = extract_lines_batch(ranges, bearings, max_range_m=40.0, sigma_range_fn=sigma)
    want = extract_lines_batch_numpy(ranges, bearings, max_range_m=40.0, sigma_range_fn=sigma)
    assert assert_same_lines(got, want) > 10


def test_batch_invariant_bit_for_bit() -> None:
    """A scan's lines do not depend on the other scans of its batch, to the last bit."""
    ranges, bearings = room_scans(12, 181, seed=5)
    far = ranges.copy()
    far[0, :20] = 39.0  # a long range in another scan changes the numpy path's Hough extent
    for cfg in (CONFIGS["default"], CONFIGS["split_merge"]):
        batch = extract_lines_batch(far, bearings, cfg, max_range_m=40.0)
        for k in range(1, far.shape[0]):
            alone = extract_lines(far[k], bearings, cfg, max_range_m=40.0)
            assert len(alone) == len(batch[k])
            for x, y in zip(alone, batch[k], strict=True):
                assert (x.r, x.alpha, x.s) == (y.r, y.alpha, y.s)
                assert np.array_equal(x.cov, y.cov)
                assert np.array_equal(x.segments_s, y.segments_s)
                assert np.array_equal(x.segments_var, y.segments_var)


def test_compiled_finds_the_walls() -> None:
    """Independent of the numpy path: the walls in view are found, in normal form."""
    ranges, bearings = room_scans(1, 361, seed=6)
    ranges[0] = np.nan_to_num(ranges[0], nan=40.0)
    lines = extract_lines(ranges[0], bearings, max_range_m=40.0)
    assert lines
    for line in lines:
        assert line.r >= 0.0 and -np.pi < line.alpha <= np.pi
        assert np.all(np.diff(line.indices) > 0)
        assert np.all(line.segments_s[:, 1] > line.segments_s[:, 0])
    firsts = [int(line.indices[0]) for line in lines]
    assert firsts == sorted(firsts)


def test_empty_and_degenerate_scans() -> None:
    bearings = np.linspace(-1.0, 1.0, 50)
    ranges = np.full((3, 50), np.nan)
    ranges[1, :2] = 2.0  # too few points (two: no residual to test)
    ranges[2] = 3.0  # an arc: no line
    for cfg in (CONFIGS["default"], CONFIGS["split_merge"]):
        got = extract_lines_batch(ranges, bearings, cfg)
        want = extract_lines_batch_numpy(ranges, bearings, cfg)
        assert [len(g) for g in got] == [len(w) for w in want]
        assert got[0] == [] and got[1] == []


@pytest.mark.realdata
def test_compiled_matches_numpy_on_intel() -> None:
    from slam.io import iter_scans, resolve_log

    try:
        log = resolve_log("intel").log
    except Exception as exc:  # pragma: no cover - data not present
        pytest.skip(f"intel log not available: {exc}")
    scans = [s for _, s in zip(range(300), iter_scans(log), strict=False)]
    ranges = np.stack([s.ranges for s in scans])
    max_range = np.array([s.max_range_m for s in scans])
    bearings = scans[0].bearings
    for cfg in (CONFIGS["default"], replace(CONFIGS["matched"], max_range_m=81.0)):
        got = extract_lines_batch(ranges, bearings, cfg, max_range_m=max_range)
        want = []
        for k in range(0, len(scans), 64):
            want += extract_lines_batch_numpy(
                ranges[k : k + 64], bearings, cfg, max_range_m=max_range[k : k + 64]
            )
        assert assert_same_lines(got, want) > 500


def test_hough_votes_counted_by_sorting_give_the_same_lines(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A scan whose dense Hough accumulator would be too large counts its votes by sorting."""
    from linefit import kernel

    ranges, bearings = room_scans(12, 181, seed=7)
    for cfg in (CONFIGS["default"], CONFIGS["pure hough"]):
        dense = extract_lines_batch(ranges, bearings, cfg, max_range_m=40.0)
        monkeypatch.setattr(kernel, "DENSE_CELLS", 0)
        sparse = extract_lines_batch(ranges, bearings, cfg, max_range_m=40.0)
        monkeypatch.undo()
        assert sum(map(len, dense)) > 12
        for a, b in zip(dense, sparse, strict=True):
            assert len(a) == len(b)
            for x, y in zip(a, b, strict=True):
                assert (x.r, x.alpha, x.s) == (y.r, y.alpha, y.s)
                assert np.array_equal(x.indices, y.indices)
                assert np.array_equal(x.cov, y.cov)
