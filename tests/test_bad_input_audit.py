"""Bad input: clear errors naming file and line instead of crashes or wrong numbers."""

from __future__ import annotations

import numpy as np
import pytest
from carmen_lines import flaser, odom, rawlaser, robotlaser

from slam.errors import ConfigError, LogFormatError
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


def _trajectory_and_relations():
    from slam.io.relations import Relations
    from slam.io.trajectory import Trajectory

    stamps = np.array([10.0, 11.0, 12.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    relations = Relations.planar([10.0, 11.0], [11.0, 12.0], [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    return Trajectory(stamps, poses), relations


@pytest.mark.parametrize("tolerance", [-1.0, float("nan")])
def test_relations_metric_refuses_a_negative_or_nan_time_tolerance(tolerance):
    from slam.evaluation.relations_metric import relations_metric
    from slam.evaluation.timestamps import associate

    trajectory, relations = _trajectory_and_relations()
    with pytest.raises(ConfigError, match="time tolerance must be >= 0 s"):
        relations_metric(trajectory, relations, tolerance_s=tolerance)
    with pytest.raises(ConfigError, match="time tolerance must be >= 0 s"):
        associate(trajectory, trajectory, tolerance_s=tolerance)


@pytest.mark.parametrize("fraction", [-0.1, 2.0, float("nan")])
def test_relations_metric_refuses_an_unmatched_fraction_outside_0_1(fraction):
    # a NaN fraction would never fail: every relation could be unmatched but one
    from slam.evaluation.relations_metric import relations_metric
    from slam.evaluation.timestamps import associate

    trajectory, relations = _trajectory_and_relations()
    with pytest.raises(ConfigError, match=r"max_unmatched_fraction must be in \[0, 1\]"):
        relations_metric(trajectory, relations, max_unmatched_fraction=fraction)
    with pytest.raises(ConfigError, match=r"max_unmatched_fraction must be in \[0, 1\]"):
        associate(trajectory, trajectory, max_unmatched_fraction=fraction)


def test_evaluate_cli_refuses_a_nan_max_unmatched(tmp_path, capsys):
    from slam.cli import main

    run = tmp_path / "run"
    run.mkdir()
    (run / "trajectory.tum").write_text(
        "10.000000 0 0 0 0 0 0 1\n11.000000 1 0 0 0 0 0 1\n12.000000 2 0 0 0 0 0 1\n"
    )
    rel = tmp_path / "rel.txt"
    rel.write_text("10.0 11.0 1 0 0 0 0 0\n11.0 12.0 1 0 0 0 0 0\n")
    with pytest.raises(SystemExit) as exit_:
        main(["evaluate", str(run), "--relations", str(rel), "--max-unmatched", "nan"])
    assert exit_.value.code == 2
    assert "max_unmatched_fraction must be in [0, 1], got nan" in capsys.readouterr().err
    assert not (run / "metrics.json").exists()


def _bare(line: str) -> str:
    """The line without ``hostname logger_timestamp``: it ends in its ipc_timestamp."""
    return line.rsplit(" ", 2)[0]


@pytest.mark.parametrize("keep", [5, 9])  # "...0002.2" and "10000000"
@pytest.mark.parametrize("kind", ["FLASER", "ODOM"])
def test_last_line_cut_inside_a_final_time_stamp_is_skipped(tmp_path, keep, kind):
    # a log without the hostname fields: the field count of a line cut inside its
    # ipc_timestamp is right, and the stamp was read as 1000000002.2 or 10000000
    def line(k, t):
        if kind == "ODOM":
            return _bare(odom([0.1 * k, 0.0, 0.0], t))
        return _bare(flaser(RANGES, [0.1 * k, 0.0, 0.0], [0.1 * k, 0.0, 0.0], t))

    lines = [line(k, 1000000000.0 + 0.75 * k) for k in range(4)]
    path = tmp_path / "log.clf"
    path.write_text("\n".join(lines)[:-keep])  # no newline at the end
    reader = CarmenReader(path)
    stamps = [m.timestamp for m in reader.messages()]
    assert stamps == [1000000000.0, 1000000000.75, 1000000001.5]
    assert reader.stats.anomalies.counts["truncated_lines"] == 1
    assert reader.stats.anomalies.first["truncated_lines"][0] == 4


def test_complete_last_line_ending_in_its_time_stamp_is_kept(tmp_path):
    lines = [_bare(odom([0.0, 0.0, 0.0], 1.0 + k)) for k in range(3)]
    path = tmp_path / "log.clf"
    path.write_text("\n".join(lines))  # no newline at the end, nothing cut
    reader = CarmenReader(path)
    assert [m.timestamp for m in reader.messages()] == [1.0, 2.0, 3.0]
    assert not reader.stats.anomalies.counts.get("truncated_lines")


@pytest.mark.parametrize("which", ["ranges", "bearings"])
def test_extract_lines_refuses_complex_arrays(which):
    from linefit import InputError, extract_lines

    phi = np.radians(np.arange(-30.0, 31.0))
    d = 2.0 / np.cos(phi)
    args = {"ranges": d, "bearings": phi}
    args[which] = args[which] + 1j
    with pytest.raises(InputError, match=f"{which} must be real numbers"):
        extract_lines(args["ranges"], args["bearings"])


def test_a_relation_of_a_time_stamp_to_itself_names_its_line(tmp_path):
    from slam.io.relations import read_relations

    path = tmp_path / "r.relations"
    path.write_text("# t1 t2 x y z roll pitch yaw\n1.0 2.0 0.1 0 0 0 0 0.01\n3.5 3.5 0 0 0 0 0 0\n")
    with pytest.raises(LogFormatError, match=rf"{path}:3: .*itself"):
        read_relations(path)
    path.write_text("1.0 2.0 0.1 0 0 0 0 0.01\n3.5 3.6 0 0 0 0 0 0\n")
    assert len(read_relations(path).t1) == 2


def _tum_line(t, x, y, yaw):
    return f"{t:.6f} {x} {y} 0 0 0 {np.sin(yaw / 2):.9f} {np.cos(yaw / 2):.9f}"


def test_ground_truth_giving_one_time_stamp_two_poses_names_both_lines(tmp_path):
    from slam.io.tum import read_ground_truth, read_tum

    path = tmp_path / "gt.tum"
    lines = [_tum_line(1.0, 0, 0, 0), _tum_line(2.0, 1, 0, 0.1), _tum_line(1.0, 0, 0.5, 0)]
    path.write_text("# ground truth\n" + "\n".join(lines) + "\n")
    with pytest.raises(LogFormatError, match=rf"{path}:4: .*two poses.*line 2"):
        read_ground_truth(path)
    assert len(read_tum(path)) == 3  # a run's own trajectory may repeat a stamp
    # the same pose twice (a log that repeats a scan) is one pose
    lines[2] = _tum_line(1.0, 0, 0, 0)
    path.write_text("\n".join(lines) + "\n")
    assert len(read_ground_truth(path)) == 3


@pytest.mark.parametrize(
    "line",
    [
        flaser(RANGES, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 1e200),
        robotlaser(RANGES, -1.5, 0.0175, 80.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], -3e15),
        odom([0.0, 0.0, 0.0], 2e11),
    ],
)
def test_a_time_stamp_beyond_any_clock_names_the_line(tmp_path, line):
    # finite, but its microseconds are lost and the trajectory would be written with it
    path = write(tmp_path, [odom([0.0, 0.0, 0.0], 0.5), line, odom([0.0, 0.0, 0.0], 1.5)])
    with pytest.raises(LogFormatError, match=rf"{path}:2: .*ipc_timestamp .*beyond 1e\+11 s"):
        list(CarmenReader(path).messages())


def test_a_results_folder_is_evaluated_from_any_working_directory(tmp_path, monkeypatch):
    # the run names its log relatively; summary.json keeps the absolute path, so that
    # evaluate finds the log's odometry (the relations' scatter) from elsewhere
    import json
    import shutil
    from pathlib import Path

    from slam.config import RunConfig
    from slam.runner import run_slam

    demo = Path(__file__).resolve().parents[1] / "datasets" / "sim" / "demo"
    (tmp_path / "data").mkdir()
    shutil.copy(demo / "log.clf", tmp_path / "data" / "log.clf")
    monkeypatch.chdir(tmp_path / "data")
    summary = run_slam("log.clf", tmp_path / "out", RunConfig(), max_scans=30)
    assert summary["log"] == str(tmp_path / "data" / "log.clf")
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert written["log"] == written["input"]["log"] == str(tmp_path / "data" / "log.clf")


def _with_fov(line: str, fov: float, resolution: float | None = None) -> str:
    """A ROBOTLASER1/RAWLASER line with its field_of_view (and resolution) replaced."""
    tokens = line.split()
    tokens[3] = f"{fov:.6f}"
    if resolution is not None:
        tokens[4] = f"{resolution:.6f}"
    return " ".join(tokens)


RES = np.pi / 180.0
_FLAT = [0.0, 0.0, 0.0]


@pytest.mark.parametrize("kind", ["ROBOTLASER1", "RAWLASER1"])
def test_beams_sweeping_more_than_a_full_turn_name_the_line(tmp_path, kind):
    # the resolution written in degrees: 180 beams 1 rad apart
    if kind == "ROBOTLASER1":
        line = robotlaser(RANGES, -np.pi / 2.0, 1.0, 80.0, _FLAT, _FLAT, 1.0)
    else:
        line = rawlaser(RANGES, -np.pi / 2.0, 1.0, 80.0, 1.0)
    path = write(tmp_path, [odom(_FLAT, 0.5), line])
    with pytest.raises(LogFormatError, match=rf"{path}:2: {kind}: 180 readings .* full turn"):
        list(CarmenReader(path).messages())
    reader = CarmenReader(path, lenient=True)
    assert list(reader.scans()) == []
    assert reader.stats.malformed == 1
    assert reader.stats.malformed_lines[0][0] == 2


@pytest.mark.parametrize("fov", [np.pi / 2.0, 2.0 * np.pi])  # half, twice the beams' sweep
@pytest.mark.parametrize("kind", ["ROBOTLASER1", "RAWLASER1"])
def test_a_field_of_view_not_fitting_the_beams_is_an_anomaly_naming_the_line(tmp_path, kind, fov):
    # e.g. a driver that caps the beam count but writes the configured field of view: the
    # bearings follow the start angle and resolution, and the user hears of the mismatch
    if kind == "ROBOTLASER1":
        line = robotlaser(RANGES, -np.pi / 2.0, RES, 80.0, _FLAT, _FLAT, 1.0)
    else:
        line = rawlaser(RANGES, -np.pi / 2.0, RES, 80.0, 1.0)
    path = write(tmp_path, [odom(_FLAT, 0.5), _with_fov(line, fov)])
    with pytest.raises(LogFormatError, match=rf"{path}:2: field of view .*{kind}: field_of_view"):
        list(CarmenReader(path, strict=True).messages())
    reader = CarmenReader(path)
    (scan,) = reader.scans()
    np.testing.assert_allclose(scan.bearings, -np.pi / 2.0 + RES * np.arange(180), atol=1e-4)
    assert reader.stats.anomalies.counts["fov_mismatch"] == 1
    assert reader.stats.anomalies.first["fov_mismatch"][0] == 2
    assert reader.stats.malformed == 0


@pytest.mark.parametrize(
    "fov",
    [
        179 * RES,  # CARMEN's SICK driver: (n - 1)·resolution
        180 * RES,  # n·resolution
        180 * RES + 0.4 * RES,  # a Hokuyo's field of view cut to whole beams
        178.5 * RES,
        0.0,  # not stated
        -1.0,
    ],
)
def test_a_field_of_view_within_a_beam_of_the_beams_sweep_is_read(tmp_path, fov):
    line = robotlaser(RANGES, -np.pi / 2.0, RES, 80.0, _FLAT, _FLAT, 1.0)
    path = write(tmp_path, [_with_fov(line, fov)])
    reader = CarmenReader(path, strict=True)
    (scan,) = reader.scans()
    # the line's numbers are written with 6 decimals
    np.testing.assert_allclose(scan.bearings, -np.pi / 2.0 + RES * np.arange(180), atol=1e-4)


@pytest.mark.parametrize("which", ["ranges", "bearings", "max_range_m"])
def test_extract_lines_batch_refuses_complex_arrays(which):
    # numpy would drop the imaginary part with only a warning, and the lines be of the real part
    from linefit import InputError, extract_lines_batch
    from linefit.batch import extract_lines_batch_numpy

    phi = np.radians(np.arange(-30.0, 31.0))
    d = np.tile(2.0 / np.cos(phi), (2, 1))
    args = {"ranges": d, "bearings": np.tile(phi, (2, 1)), "max_range_m": np.array([8.0, 8.0])}
    args[which] = args[which] + 1j
    for extract in (extract_lines_batch, extract_lines_batch_numpy):
        with pytest.raises(InputError, match=f"{which} must be real numbers"):
            extract(args["ranges"], args["bearings"], max_range_m=args["max_range_m"])


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (1e200, "1e+200"),
        (2e5, "200000"),
        (np.nan, "nan"),
        (np.inf, "inf"),
        (0.0, "0"),
        (-0.01, "-0.01"),
    ],
)
@pytest.mark.parametrize("batch", [False, True])
def test_a_sigma_range_fn_value_that_is_no_standard_deviation_is_named(value, shown, batch):
    # 1e200 squared overflows: numpy warned and the scan had no line
    import re
    import warnings

    from linefit import InputError, extract_lines, extract_lines_batch

    phi = np.radians(np.arange(-30.0, 31.0))
    d = 2.0 / np.cos(phi)

    def sigma(r):  # fine up to 2.2 m, the bad value beyond (the first beam, 2.3094 m)
        return np.where(r > 2.2, value, 0.01)

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning on the way
        with pytest.raises(
            InputError, match=rf"sigma_range_fn returned {re.escape(shown)} m for range 2\.3094 m"
        ):
            if batch:
                extract_lines_batch(d[None, :], phi, sigma_range_fn=sigma)
            else:
                extract_lines(d, phi, sigma_range_fn=sigma)
        # within the bound: lines, as before
        assert (
            len(extract_lines(d, phi, sigma_range_fn=lambda r: np.where(r > 2.2, 1e5, 0.01))) == 1
        )
