"""Log anomalies: counted in summary.json, one warning line per kind, errors with --strict.

Kinds (``slam.io.anomalies``): time going backwards beyond the tolerance, repeated stamps,
odometry jumps the time step cannot explain, a last line cut short, unknown message types,
junk lines, malformed lines skipped when lenient.  The catalogued logs (Intel with its 631
small backward steps, ACES, fr079) have none and pass ``--strict``; a log joined from two
trips the time and odometry checks at the join.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from carmen_lines import flaser
from conftest import REPO_ROOT

from slam.cli import main
from slam.errors import LogFormatError
from slam.io import CarmenStats, iter_scans
from slam.io.anomalies import (
    JUMP_SLACK_M,
    MAX_SPEED_M_S,
    TIME_BACKWARD_TOLERANCE_S,
)
from slam.io.carmen import CarmenReader

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
RANGES = np.full(180, 3.0)
GEOMETRY = ["--first-angle", "-90", "--step", "1"]
"""The demo log's beams, stated: the log is not catalogued, and without them the run also warns
that it took CARMEN's rule for the geometry (slam.inputs); the anomaly lines are then alone."""


def run(args, capsys):
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def write(tmp_path, lines, name="log.clf", newline=True):
    path = tmp_path / name
    path.write_text("\n".join(lines) + ("\n" if newline else ""))
    return path


def scan_line(x: float, t: float, theta: float = 0.0) -> str:
    return flaser(RANGES, [x, 0.0, theta], [x, 0.0, theta], t)


def read(path, **kwargs) -> tuple[list, CarmenStats]:
    stats = CarmenStats()
    scans = list(iter_scans(path, stats=stats, **kwargs))
    return scans, stats


def counts(stats: CarmenStats) -> dict[str, int]:
    return {k: v for k, v in stats.anomalies.counts.items() if v}


DEMO_PART = DEMO_LOG.read_text().splitlines()[:120]  # the header and about 50 scans


@pytest.fixture
def joined(tmp_path):
    """The start of the demo log twice, end to end (time goes back, the odometry jumps)."""
    path = tmp_path / "joined.clf"
    path.write_text("\n".join(DEMO_PART + DEMO_PART) + "\n")
    return path


# ---------------------------------------------------------------------------------------------
# time
# ---------------------------------------------------------------------------------------------
def test_small_backward_steps_are_tolerated_large_ones_counted(tmp_path):
    stamps = [10.0, 10.1, 9.2, 9.4, 9.5, 9.6 - TIME_BACKWARD_TOLERANCE_S - 0.5, 9.7]
    path = write(tmp_path, [scan_line(0.01 * k, t) for k, t in enumerate(stamps)])
    scans, stats = read(path)
    assert [s.timestamp for s in scans] == stamps  # file order kept, nothing dropped
    assert counts(stats) == {"time_backwards": 1}
    line, detail = stats.anomalies.first["time_backwards"]
    assert line == 6 and "more than the 2 s tolerated" in detail
    with pytest.raises(LogFormatError, match=r"log\.clf:6: time goes backwards: .*--strict"):
        read(path, strict=True)


def test_repeated_stamps_all_zero(tmp_path):
    path = write(tmp_path, [scan_line(0.01 * k, 0.0) for k in range(5)])
    _, stats = read(path)
    assert counts(stats) == {"repeated_stamps": 4}
    with pytest.raises(LogFormatError, match=r":2: repeated time stamp"):
        read(path, strict=True)


# ---------------------------------------------------------------------------------------------
# odometry jumps
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("step_m", "dt_s", "turn_rad", "jump"),
    [
        (0.3, 0.2, 0.0, False),  # 1.5 m/s
        (MAX_SPEED_M_S * 1.0 + JUMP_SLACK_M - 0.01, 1.0, 0.0, False),  # just inside
        (MAX_SPEED_M_S * 1.0 + JUMP_SLACK_M + 0.01, 1.0, 0.0, True),  # just outside
        (0.09, 0.001, 0.17, False),  # Intel's stamp jitter
        (0.0, 0.1, 1.5, True),  # 86 degrees in 0.1 s
        (62.0, -2692.0, 2.5, True),  # two logs joined
    ],
)
def test_odometry_jump_bound(tmp_path, step_m, dt_s, turn_rad, jump):
    t0 = 5000.0
    path = write(
        tmp_path,
        [scan_line(0.0, t0), scan_line(step_m, t0 + dt_s, turn_rad), scan_line(step_m, t0 + 5)],
    )
    _, stats = read(path)
    assert stats.anomalies.counts["odometry_jumps"] == int(jump)


def test_a_corrupt_huge_pose_is_refused_in_a_readable_number(tmp_path):
    """A pose of 1e300 m (a corrupt field) is a malformed line, named in one short number."""
    t0 = 5000.0
    path = write(tmp_path, [scan_line(0.0, t0), scan_line(1e300, t0 + 0.2), scan_line(0.1, t0 + 5)])
    with pytest.raises(LogFormatError, match=r"log\.clf:2: .*1e\+300.* beyond ") as info:
        read(path)
    assert len(str(info.value)) < 250, str(info.value)
    scans, stats = read(path, lenient=True)
    assert len(scans) == 2 and stats.malformed == 1
    assert counts(stats) == {"malformed_lines": 1}


def test_joined_logs_are_counted_warned_and_refused_with_strict(tmp_path, joined, capsys):
    out = tmp_path / "run"
    code, _, err = run(["slam", joined, "--out", out, "--quiet", *GEOMETRY], capsys)
    assert code == 0, err
    anomalies = json.loads((out / "summary.json").read_text())["log_anomalies"]
    assert anomalies["time_backwards"]["count"] == 1
    assert anomalies["odometry_jumps"]["count"] == 1
    first_line = anomalies["time_backwards"]["first_line"]
    first_scan = next(k for k, ln in enumerate(DEMO_PART, 1) if ln.startswith("FLASER"))
    assert first_line == len(DEMO_PART) + first_scan  # the first scan of the second copy
    warnings = [ln for ln in err.splitlines() if ln.startswith("lineslam: warning:")]
    assert len(warnings) == 2  # one line per kind
    assert "backward time step" in warnings[0] and f"line {first_line}" in warnings[0]
    assert "odometry jump" in warnings[1]
    code, _, err = run(["slam", joined, "--out", tmp_path / "strict", "--strict"], capsys)
    assert code == 2 and f"joined.clf:{first_line}: time goes backwards" in err
    assert not (tmp_path / "strict").exists()
    code, _, err = run(["extract", joined, "--out", tmp_path / "l.jsonl", "--strict"], capsys)
    assert code == 2 and not (tmp_path / "l.jsonl").exists()


@pytest.mark.parametrize("cmd", ["ekf", "map", "extract"])
def test_every_log_command_warns_and_counts(tmp_path, joined, capsys, cmd):
    out = tmp_path / ("o.jsonl" if cmd == "extract" else "o")
    extra = ["--no-plot"] if cmd == "map" else []
    code, _, err = run([cmd, joined, "--out", out, "--quiet", *GEOMETRY, *extra], capsys)
    assert code == 0, err
    assert sum(ln.startswith("lineslam: warning:") for ln in err.splitlines()) == 2
    if cmd != "extract":
        anomalies = json.loads((out / "summary.json").read_text())["log_anomalies"]
        assert {k for k, v in anomalies.items() if v["count"]} == {
            "time_backwards",
            "odometry_jumps",
        }


def test_a_clean_log_has_zero_counts_and_no_warning(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["map", DEMO_LOG, "--out", out, "--quiet", "--strict", "--no-plot", *GEOMETRY]
    code, _, err = run(args, capsys)
    assert code == 0 and "warning" not in err
    anomalies = json.loads((out / "summary.json").read_text())["log_anomalies"]
    assert anomalies and all(v == {"count": 0} for v in anomalies.values())


# ---------------------------------------------------------------------------------------------
# truncated, unknown, junk, malformed
# ---------------------------------------------------------------------------------------------
def test_last_line_cut_inside_its_time_stamp(tmp_path, capsys):
    good = [scan_line(0.01 * k, 1000000000.0 + 0.5 * k) for k in range(4)]
    last = scan_line(0.05, 1000000286.5)
    cut = last[: last.index("1000000286.5") + 5]  # "... 10000": the stamp cut short
    path = write(tmp_path, [*good, cut], newline=False)
    scans, stats = read(path)
    assert len(scans) == 4 and all(s.timestamp >= 1e9 for s in scans)
    assert counts(stats) == {"truncated_lines": 1}
    assert stats.anomalies.first["truncated_lines"][0] == 5
    with pytest.raises(LogFormatError, match=r":5: last line cut short"):
        read(path, strict=True)
    code, _, err = run(["extract", path, "--out", tmp_path / "l.jsonl", "--quiet"], capsys)
    assert code == 0 and "last line cut short" in err
    assert len((tmp_path / "l.jsonl").read_text().splitlines()) == 4


def test_last_line_cut_mid_readings_is_skipped_not_fatal(tmp_path):
    good = [scan_line(0.01 * k, 100.0 + k) for k in range(3)]
    path = write(tmp_path, [*good, good[0][:200]], newline=False)
    scans, stats = read(path)
    assert len(scans) == 3 and counts(stats) == {"truncated_lines": 1}


def test_complete_last_line_without_newline_is_fine(tmp_path):
    path = write(tmp_path, [scan_line(0.01 * k, 100.0 + k) for k in range(3)], newline=False)
    scans, stats = read(path)
    assert len(scans) == 3 and counts(stats) == {}


def test_unknown_and_known_carmen_messages(tmp_path):
    lines = [
        "PARAM robot_width 0.5",
        "SYNC 1 2",
        scan_line(0.0, 1.0),
        "FOOBAR 1 2 3",
        "FOOBAR 4 5 6",
        "WHATEVER 1",
        scan_line(0.01, 2.0),
    ]
    _, stats = read(write(tmp_path, lines))
    assert counts(stats) == {"unknown_messages": 3}
    assert stats.anomalies.unknown_types == {"FOOBAR": 2, "WHATEVER": 1}
    assert stats.unknown == 5  # every skipped line is still counted in CarmenStats
    message = stats.anomalies.messages()[0]
    assert "3 line(s) of unknown message types" in message and "FOOBAR: 2" in message
    with pytest.raises(LogFormatError, match=r":4: unknown message type: FOOBAR"):
        read(write(tmp_path, lines), strict=True)


def test_a_5_mb_junk_line_is_counted(tmp_path, rng):
    junk = rng.choice(np.frombuffer(b"abc{}<>;=xyz0123 ", np.uint8), 5_000_000).tobytes().decode()
    path = write(tmp_path, [scan_line(0.0, 1.0), "x" + junk, scan_line(0.01, 2.0)])
    scans, stats = read(path)
    assert len(scans) == 2 and counts(stats) == {"junk_lines": 1}
    line, detail = stats.anomalies.first["junk_lines"]
    assert line == 2 and "5000001 characters" in detail and len(detail) < 100
    with pytest.raises(LogFormatError, match=r":2: not a CARMEN message"):
        read(path, strict=True)


def test_lenient_skips_are_counted_as_anomalies(tmp_path):
    path = write(tmp_path, [scan_line(0.0, 1.0), "FLASER 3 1 2 x", scan_line(0.01, 2.0)])
    scans, stats = read(path, lenient=True)
    assert len(scans) == 2 and counts(stats) == {"malformed_lines": 1}


# ---------------------------------------------------------------------------------------------
# clear messages
# ---------------------------------------------------------------------------------------------
def test_flaser_with_zero_readings_names_file_and_line(tmp_path):
    path = write(tmp_path, [scan_line(0.0, 1.0), "FLASER 0 0 0 0 0 0 0 2.0 nohost 2.0"])
    with pytest.raises(LogFormatError, match=r"log\.clf:2: FLASER has 0 readings"):
        read(path)


def test_one_reading_too_few_says_so(tmp_path):
    tokens = scan_line(0.0, 1.0).split()
    del tokens[5]
    path = write(tmp_path, [scan_line(0.0, 0.5), " ".join(tokens)])
    with pytest.raises(LogFormatError) as info:
        read(path)
    text = str(info.value)
    assert "log.clf:2:" in text and "'nohost'" in text
    assert "fewer readings than num_readings" in text


def test_nan_reading_is_shown_as_nan(tmp_path):
    line = scan_line(0.0, 1.0).replace(" 3.00 ", " nan ", 1)
    with pytest.raises(LogFormatError) as info:
        read(write(tmp_path, [line]))
    assert "is nan" in str(info.value) and "np.float64" not in str(info.value)


# ---------------------------------------------------------------------------------------------
# the catalogued logs
# ---------------------------------------------------------------------------------------------
@pytest.mark.realdata
@pytest.mark.parametrize("name", ["intel", "aces", "fr079"])
def test_catalogued_logs_have_no_anomaly_and_pass_strict(shared_data, name):
    path = shared_data / name / f"{name}.clf"
    reader = CarmenReader(path, strict=True)
    stamps = [m.timestamp for m in reader.scans()]
    assert reader.stats.anomalies.total == 0
    backward = int(np.sum(np.diff(stamps) < 0))
    if name == "intel":  # small backward steps are there, and tolerated
        assert backward == 631
        assert -float(np.min(np.diff(stamps))) < TIME_BACKWARD_TOLERANCE_S
    assert math.isfinite(stamps[-1])


@pytest.mark.realdata
def test_intel_joined_to_itself_trips_time_and_odometry(shared_data, tmp_path):
    text = (shared_data / "intel" / "intel.clf").read_text()
    path = tmp_path / "intel2.clf"
    path.write_text(text + text)
    reader = CarmenReader(path)
    for _ in reader.scans():
        pass
    assert counts(reader.stats) == {"time_backwards": 1, "odometry_jumps": 1}
    _, detail = reader.stats.anomalies.first["time_backwards"]
    assert "2691." in detail
