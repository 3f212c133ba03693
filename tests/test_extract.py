"""extract_lines end to end: a simulated room, segments, batches, bad input, the public fits."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from _synthetic import cast, noisy_scan, room, segment_line_in_sensor
from hypothesis import given, settings
from hypothesis import strategies as st

import linefit.extract
from linefit import (
    DegenerateGeometryError,
    InputError,
    LineFitConfig,
    extract_lines,
    extract_lines_batch,
    fit_line,
    fit_scan_line,
    point_covariances,
    wrap_angle,
)
from slam.geometry import line_to_parent

POSES = [(0.0, 0.0, 0.0), (-3.0, 2.0, 0.7), (3.5, -2.5, 2.5), (-1.0, -3.0, -1.2), (4.0, 3.0, 3.9)]
SCANNERS = {"360° / 0.5°": (2 * np.pi, 720), "180° / 1° (Intel-like)": (np.pi, 180)}


@pytest.mark.parametrize("grouping", ["hough", "split_merge"])
@pytest.mark.parametrize("scanner", list(SCANNERS))
def test_simulated_room_every_face_found_and_nothing_spurious(grouping, scanner):
    """Walls, two boxes and a pillar, 5 poses, σ_d = 5 mm, σ_φ = 1e-4 ("beam" noise).

    Every face hit by ≥ 10 beams is found; every line lies on one face (≥ 80 % of its points),
    within 1° of its angle and with its segment within 2 cm of the face; its (r, α) error is
    consistent with its covariance (χ²₂ < 13.8, 99.9 %); no face gets two lines.  (r itself is
    within 2 cm wherever the line's own σ_r allows it: a short or grazing piece seen far from the
    foot of its normal can have σ_r ≥ 2 cm, e.g. 6 points at 85° incidence on a wall 6 m away.)
    """
    world = room()
    fov, n = SCANNERS[scanner]
    bearings = -fov / 2 + np.arange(n) * fov / n
    rng = np.random.default_rng(11)
    cfg = LineFitConfig(grouping=grouping)
    for pose in map(np.array, POSES):
        ranges, phi, hit = noisy_scan(world, pose, bearings, rng)
        lines = extract_lines(ranges, phi, cfg, max_range_m=80.0)
        counts = np.bincount(hit[hit >= 0], minlength=world.n_segments + 1)
        matched: list[int] = []
        for line in lines:
            ids = hit[line.indices]
            face = int(np.bincount(ids[ids >= 0]).argmax())
            if face >= world.n_segments:  # the pillar: short arcs are locally straight
                continue
            where = (tuple(pose), face)
            assert np.mean(ids == face) >= 0.8, where  # no points of other surfaces
            r_true, a_true = segment_line_in_sensor(world, face, pose)
            err = np.array([line.r - r_true, wrap_angle(line.alpha - a_true)])
            assert abs(err[1]) < np.radians(1.0), where
            gap = np.abs(line.endpoints @ [np.cos(a_true), np.sin(a_true)] - r_true)
            assert np.all(gap < 0.02), (where, gap)
            assert abs(err[0]) < max(0.02, 3.0 * np.sqrt(line.cov[0, 0])), where
            assert err @ np.linalg.solve(line.cov[:2, :2], err) < 13.8, where
            matched.append(face)
        assert len(matched) == len(set(matched)), f"a face found twice at {pose}"
        missing = [k for k in range(world.n_segments) if counts[k] >= 10 and k not in matched]
        assert not missing, f"faces {missing} not found at {pose}"


def _wall_with_door() -> tuple[np.ndarray, np.ndarray]:
    phi = np.radians(np.arange(-60.0, 60.5, 0.5))
    d = 3.0 / np.cos(phi)
    door = (np.tan(phi) * 3.0 > 0.5) & (np.tan(phi) * 3.0 < 1.4)
    d[door] = 6.0 / np.cos(phi[door])  # through the door: the far wall of the next room
    return d, phi


@pytest.mark.parametrize("grouping", ["hough", "split_merge"])
def test_a_wall_broken_by_a_door_is_one_line_with_two_segments(grouping):
    d, phi = _wall_with_door()
    lines = extract_lines(d, phi, LineFitConfig(grouping=grouping))
    wall = [ln for ln in lines if abs(ln.r - 3.0) < 0.01]
    assert len(wall) == 1
    seg = wall[0].segments_s
    assert seg.shape == (2, 2)
    assert seg[0, 1] < 0.5 + 0.03 and seg[1, 0] > 1.4 - 0.03  # the gap is the door
    assert wall[0].length == pytest.approx(np.sum(seg[:, 1] - seg[:, 0]))
    assert np.all(wall[0].segments_var > 0)


def test_lines_are_in_normal_form_and_sorted_by_first_beam(rng):
    world = room()
    bearings = -np.pi + np.arange(720) * np.pi / 360
    ranges, phi, _ = noisy_scan(world, np.array([1.0, 0.5, 2.0]), bearings, rng)
    lines = extract_lines(ranges, phi)
    assert len(lines) >= 4
    assert all(ln.r >= 0 and -np.pi < ln.alpha <= np.pi for ln in lines)
    firsts = [int(ln.indices[0]) for ln in lines]
    assert firsts == sorted(firsts)
    for ln in lines:
        assert np.all(np.diff(ln.indices) > 0) and ln.n_points == ln.indices.shape[0]
        np.testing.assert_allclose(ln.cov, ln.cov.T)
        assert np.all(np.linalg.eigvalsh(ln.cov) > 0)
        assert np.all(np.diff(ln.segments_s[:, 0]) > 0)


@pytest.mark.parametrize("grouping", ["hough", "split_merge"])
def test_batch_equals_one_scan_at_a_time(grouping):
    world = room()
    bearings = -np.pi / 2 + np.arange(180) * np.pi / 180
    rng = np.random.default_rng(5)
    scans = [noisy_scan(world, np.array(p), bearings, rng)[0] for p in POSES]
    scans[2][:] = np.nan  # a scan without readings in the middle of the batch
    cfg = LineFitConfig(grouping=grouping)
    batch = extract_lines_batch(np.stack(scans), bearings, cfg, max_range_m=80.0)
    for ranges, lines in zip(scans, batch, strict=True):
        single = extract_lines(ranges, bearings, cfg, max_range_m=80.0)
        assert len(single) == len(lines)
        for a, b in zip(single, lines, strict=True):
            # equal to the convergence tolerance (a line refitted alongside new ones of another
            # scan may take one more step of < 1e-10 rad)
            assert a.r == pytest.approx(b.r, abs=1e-9) and a.alpha == pytest.approx(
                b.alpha, abs=1e-9
            )
            np.testing.assert_allclose(a.cov, b.cov, rtol=1e-6)
            np.testing.assert_array_equal(a.indices, b.indices)


def test_invalid_readings_never_enter_a_fit():
    phi = np.radians(np.arange(-40.0, 41.0))
    d = 2.0 / np.cos(phi)
    bad = np.arange(0, 81, 7)
    d[bad] = [np.nan, np.inf, -np.inf, 0.0, -1.0, 80.0, 81.83, 100.0, np.nan, 0.0, np.inf, 80.0][
        : bad.shape[0]
    ]
    (line,) = extract_lines(d, phi, max_range_m=80.0)
    assert not set(bad.tolist()) & set(line.indices.tolist())
    assert line.r == pytest.approx(2.0, abs=1e-9)
    # max range from the configuration cuts as well (the smaller applies)
    near = extract_lines(d, phi, LineFitConfig(max_range_m=2.2), max_range_m=80.0)
    assert all(np.all(d[ln.indices] < 2.2) for ln in near)


@pytest.mark.parametrize(
    ("ranges", "bearings"),
    [
        (np.zeros(0), np.zeros(0)),  # empty scan
        (np.full(90, 80.0), np.radians(np.arange(90.0))),  # all max range
        (np.full(90, np.nan), np.radians(np.arange(90.0))),  # all NaN
        (np.array([1.0, 1.0]), np.array([0.0, 0.1])),  # two points
        (np.array([1.0, 2.0]), np.array([0.3, 0.3 + np.pi])),  # collinear with the sensor
    ],
)
def test_scans_without_lines_give_an_empty_list(ranges, bearings):
    assert extract_lines(ranges, bearings, max_range_m=80.0) == []


@pytest.mark.parametrize(
    ("ranges", "bearings", "match"),
    [
        (np.ones(5), np.arange(4.0), "differ in length"),
        (np.ones((2, 5)), np.arange(5.0), "one-dimensional"),
        (np.ones(5), np.array([0, 1, np.nan, 3, 4.0]), "finite"),
        (np.ones(5), np.array([0, 1, 1, 3, 4.0]), "strictly"),
        (np.ones(5), np.array([0, 2, 1, 3, 4.0]), "strictly"),
        (["a"] * 5, np.arange(5.0), "numbers"),
    ],
)
def test_malformed_input_is_an_input_error(ranges, bearings, match):
    with pytest.raises(InputError, match=match):
        extract_lines(ranges, bearings)


def test_decreasing_and_wrapping_bearings_are_accepted():
    phi = np.radians(np.arange(150.0, 211.0)) - 2 * np.pi * (np.arange(150.0, 211.0) > 180)
    d = 3.0 / np.abs(np.cos(phi))  # the wall x = −3 seen through ±180°
    (line,) = extract_lines(d, phi)
    assert line.r == pytest.approx(3.0, abs=1e-9) and abs(line.alpha) == pytest.approx(np.pi)
    (rev,) = extract_lines(d[::-1], phi[::-1])
    assert rev.r == pytest.approx(line.r) and rev.n_points == line.n_points


def test_fit_scan_line_errors():
    with pytest.raises(DegenerateGeometryError, match="through the sensor"):
        fit_scan_line([1.0, 2.0, 3.0], [0.5, 0.5, 0.5])
    with pytest.raises(DegenerateGeometryError, match="two points"):
        fit_scan_line([1.0], [0.5])
    with pytest.raises(InputError):
        fit_scan_line([1.0, np.nan], [0.1, 0.2])
    with pytest.raises(InputError):
        fit_scan_line([1.0, 2.0], [0.1])


def test_fit_line_errors():
    p = np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]])
    C = np.tile(np.eye(2) * 1e-4, (3, 1, 1))
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        fit_line(np.ones((3, 2)), C)
    with pytest.raises(DegenerateGeometryError):
        fit_line(p[:1], C[:1])
    with pytest.raises(InputError, match="positive definite"):
        fit_line(p, -C)
    with pytest.raises(InputError, match="shape"):
        fit_line(p, C[:2])
    with pytest.raises(InputError, match="finite"):
        fit_line(np.where(p == 2.0, np.inf, p), C)
    line = fit_line(p, C)
    assert line.r == pytest.approx(1.0) and line.alpha == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(line.segments_s, [[0.0, 2.0]], atol=1e-12)


def test_fit_scan_line_equals_extract_on_a_clean_wall():
    phi = np.radians(np.arange(-40.0, 41.0))
    d = 2.0 / np.cos(phi - 0.2) + 0.003 * np.sin(7 * phi)
    (a,) = extract_lines(d, phi)
    b = fit_scan_line(d, phi)
    assert a.r == pytest.approx(b.r, abs=1e-12) and a.alpha == pytest.approx(b.alpha, abs=1e-12)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9)


def test_fit_line_of_scan_points_with_eq8_covariances_matches_fit_scan_line():
    phi = np.radians(np.arange(20.0, 70.0))
    d = 4.0 / np.cos(phi - 0.9) + 0.004 * np.cos(5 * phi)
    cfg = LineFitConfig()
    cfg_reading = LineFitConfig(noise=cfg.noise.__class__(bearing_error="reading"))
    a = fit_scan_line(d, phi, cfg_reading)
    b = fit_line(np.stack([d * np.cos(phi), d * np.sin(phi)], 1), point_covariances(d, phi))
    assert a.r == pytest.approx(b.r, abs=1e-12) and a.alpha == pytest.approx(b.alpha, abs=1e-12)
    # (R, α) identical; the S row differs only by the weight-derivative terms of scan points
    np.testing.assert_allclose(a.cov[:2, :2], b.cov[:2, :2], rtol=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-20, 20),
    y=st.floats(-20, 20),
    gamma=st.floats(-np.pi, np.pi),
    r=st.floats(0.3, 15.0),
    alpha=st.floats(-np.pi, np.pi),
    s0=st.floats(-10.0, 10.0),
    length=st.floats(0.5, 8.0),
    seed=st.integers(0, 2**31),
)
def test_rigid_motion_moves_the_fitted_line_accordingly(x, y, gamma, r, alpha, s0, length, seed):
    """Fit in frame j; move points and covariances to frame i: the fit is Eq. 30 of the first."""
    rng = np.random.default_rng(seed)
    n_vec = np.array([np.cos(alpha), np.sin(alpha)])
    t_vec = np.array([-np.sin(alpha), np.cos(alpha)])
    s = np.linspace(s0, s0 + length, 25)
    pts = r * n_vec + s[:, None] * t_vec
    d, phi = np.hypot(pts[:, 0], pts[:, 1]), np.arctan2(pts[:, 1], pts[:, 0])
    C = point_covariances(d, phi)
    pts = pts + np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.normal(size=(25, 2)))
    line_j = fit_line(pts, C)
    c, sn = np.cos(gamma), np.sin(gamma)
    rot = np.array([[c, -sn], [sn, c]])
    line_i = fit_line(pts @ rot.T + [x, y], rot @ C @ rot.T)
    pose = np.array([x, y, gamma])
    expect, B, _ = line_to_parent(np.array([line_j.r, line_j.alpha, line_j.s]), pose)
    got = np.array([line_i.r, line_i.alpha, line_i.s])
    scale = 1.0 + abs(x) + abs(y) + r + abs(s0) + length
    assert abs(got[0] - expect[0]) < 1e-9 * scale
    assert abs(wrap_angle(got[1] - expect[1])) < 1e-9
    assert abs(got[2] - expect[2]) < 1e-9 * scale
    np.testing.assert_allclose(line_i.cov, B @ line_j.cov @ B.T, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(line_i.length, line_j.length, rtol=1e-9)


def test_rotating_the_sensor_rotates_the_lines():
    world = room()
    bearings = -np.pi / 2 + np.arange(181) * np.pi / 180
    ranges, _ = cast(world, np.array([0.5, 0.3, 0.4]), bearings)
    a = extract_lines(ranges, bearings, max_range_m=80.0)
    b = extract_lines(ranges, bearings + 0.3, max_range_m=80.0)
    assert len(a) == len(b) >= 2
    for la, lb in zip(a, b, strict=True):
        assert lb.r == pytest.approx(la.r, abs=1e-9)
        assert wrap_angle(lb.alpha - la.alpha - 0.3) == pytest.approx(0.0, abs=1e-9)


def test_docstring_examples():
    failures, _ = doctest.testmod(linefit.extract)
    assert failures == 0
