"""Bad input: clear errors naming file and line instead of crashes or wrong numbers."""

from __future__ import annotations

import numpy as np
import pytest
from carmen_lines import flaser, odom, robotlaser

from slam.errors import LogFormatError
from slam.io import iter_scans
from slam.io.carmen import CarmenReader


def write(tmp_path, lines, name="log.clf"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


RANGES = np.full(180, 2.0)


@pytest.mark.parametrize(
    ("line", "field"),
    [
        (flaser(RANGES, [1e200, 0.0, 0.0], [0.0, 0.0, 0.0], 1.0), "x y theta odom_x"),
        (flaser(RANGES, [0.0, 0.0, 0.0], [0.0, -3e150, 0.0], 1.0), "x y theta odom_x"),
        (
            robotlaser(RANGES, -1.5, 0.0175, 80.0, [0.0, 0.0, 0.0], [2e9, 0.0, 0.0], 1.0),
            "laser and robot poses",
        ),
        (odom([1e200, 0.0, 0.0], 1.0), "ODOM: x y theta"),
    ],
)
def test_pose_coordinate_beyond_any_odometry_names_the_line(tmp_path, line, field):
    # 1e200 is finite, but its square overflows inside the scan matcher (numba LinAlgError)
    path = write(tmp_path, [odom([0.0, 0.0, 0.0], 0.5), line, odom([0.0, 0.0, 0.0], 1.5)])
    with pytest.raises(LogFormatError, match=rf"{path}:2: .*{field}.*beyond 1e\+08 m"):
        list(CarmenReader(path).messages())


def test_pose_coordinate_beyond_any_odometry_is_skipped_when_lenient(tmp_path):
    path = write(
        tmp_path,
        [
            flaser(RANGES, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 1.0),
            flaser(RANGES, [1e200, 0.0, 0.0], [0.0, 0.0, 0.0], 2.0),
            flaser(RANGES, [5e7, -5e7, 0.0], [5e7, -5e7, 0.0], 3.0),  # far, but a number
        ],
    )
    scans = list(iter_scans(path, lenient=True))
    assert [s.timestamp for s in scans] == [1.0, 3.0]
