"""TUM and relations files: round trips, exact time stamps, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import InputError, LogFormatError
from slam.geometry import pose_between, wrap_angle
from slam.io import (
    read_relations,
    read_tum,
    relations_from_trajectory,
    write_relations,
    write_tum,
)


def random_poses(rng, n):
    return np.column_stack([rng.normal(0, 20, n), rng.normal(0, 20, n), rng.uniform(-4, 4, n)])


def test_tum_round_trip_keeps_stamps_exactly(tmp_path, rng):
    stamps = 976052857.0 + np.round(rng.uniform(0, 3000, 500), 6)
    poses = random_poses(rng, 500)
    path = tmp_path / "trajectory.tum"
    write_tum(path, stamps, poses, header="frame: laser")
    text = path.read_text().splitlines()
    assert text[0] == "# frame: laser"
    assert text[1].split()[0] == f"{stamps[0]:.6f}"
    fields = text[1].split()
    assert float(fields[3]) == 0.0 and float(fields[4]) == 0.0 and float(fields[5]) == 0.0
    back = read_tum(path)
    np.testing.assert_array_equal(back.timestamps, stamps)
    np.testing.assert_allclose(back.poses[:, :2], poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(back.poses[:, 2] - poses[:, 2]), 0.0, atol=1e-8)


def test_tum_more_decimals_and_rejects_fewer(tmp_path):
    path = tmp_path / "t.tum"
    write_tum(path, [1.123456789], [[0, 0, 0]], decimals=9)
    assert path.read_text().split()[0] == "1.123456789"
    with pytest.raises(InputError, match="decimals"):
        write_tum(path, [1.0], [[0, 0, 0]], decimals=3)
    with pytest.raises(InputError, match="shape"):
        write_tum(path, [1.0, 2.0], [[0, 0, 0]])
    with pytest.raises(InputError, match="NaN"):
        write_tum(path, [1.0], [[0, np.nan, 0]])


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("1.0 0 0 0 0 0 0", "7 fields, expected 8"),
        ("1.0 0 0 0 0 0 0 1 9", "9 fields"),
        ("1.0 0 zero 0 0 0 0 1", "'zero' is not a number"),
        ("1.0 0 nan 0 0 0 0 1", "NaN"),
        ("1.0 0 0 0 0 0 0 2", "norm"),
        ("1.0 0 0 0 0.7071068 0 0 0.7071068", "not planar"),
    ],
)
def test_tum_bad_lines_name_the_line(tmp_path, line, match):
    path = tmp_path / "bad.tum"
    path.write_text("# stamp x y z qx qy qz qw\n0.5 0 0 0 0 0 0 1\n" + line + "\n")
    with pytest.raises(LogFormatError, match=match) as info:
        read_tum(path)
    assert info.value.line_number == 3 and "bad.tum" in str(info.value)


def test_empty_and_binary_tum(tmp_path):
    empty = tmp_path / "e.tum"
    empty.write_text("# only a comment\n")
    with pytest.raises(LogFormatError, match=r"no TUM pose .* rows in the file"):
        read_tum(empty)
    binary = tmp_path / "b.tum"
    binary.write_bytes(bytes(range(256)))
    with pytest.raises(LogFormatError, match="binary"):
        read_tum(binary)


def test_relations_round_trip_and_definition(tmp_path, rng):
    stamps = np.round(100.0 + np.cumsum(rng.uniform(0.1, 0.3, 200)), 6)
    poses = random_poses(rng, 200)
    pairs = rng.integers(0, 200, (300, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]  # a relation of a pose to itself is refused
    rel = relations_from_trajectory(stamps, poses, pairs)
    np.testing.assert_allclose(rel.poses, pose_between(poses[pairs[:, 0]], poses[pairs[:, 1]]))
    path = tmp_path / "x.relations"
    write_relations(path, rel.t1, rel.t2, rel.poses)
    assert path.read_text().startswith("# t1 t2 x y z roll pitch yaw")
    back = read_relations(path)
    np.testing.assert_array_equal(back.t1, stamps[pairs[:, 0]])
    np.testing.assert_array_equal(back.t2, stamps[pairs[:, 1]])
    np.testing.assert_allclose(back.poses[:, :2], rel.poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(back.poses[:, 2] - rel.poses[:, 2]), 0, atol=1e-9)
    assert not back.z.any() and not back.roll.any() and not back.pitch.any()
    assert back.line_numbers[0] == 2


def test_relations_read_kuemmerle_file_without_header(tmp_path):
    path = tmp_path / "k.relations"
    path.write_text(
        "976052905.167303 976052911.885496 -0.056990 -0.128430 0.000000 0.000000 0.000000 "
        "-1.682210\n"
    )
    rel = read_relations(path)
    assert rel.t1[0] == 976052905.167303 and rel.poses[0, 2] == -1.682210
    path.write_text("1 2 3 4 5 6 7\n")
    with pytest.raises(LogFormatError, match=r"k\.relations:1: .*7 fields"):
        read_relations(path)
