"""Every path problem of the command line: one line naming the path, exit status 2, no change.

The cases of the issue "Never lose a user's data": ``--out`` the input itself, an existing
file, ``/dev/null``, a file as parent, ``/proc/x``, ``''``, ``.``; ``--config`` a folder; a
folder that is not a results folder; an ODOM-only log; the status of ``typer.Exit``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from conftest import REPO_ROOT

from slam.cli import main

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
COMMANDS = ["slam", "ekf", "map", "extract"]


def run(args, capsys):
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_error(code: int, err: str, *names: str) -> None:
    assert code == 2, err
    assert err.startswith("lineslam: error: ") and err.count("\n") == 1, err
    for name in names:
        assert name in err, err


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def log(tmp_path) -> Path:
    path = tmp_path / "x.clf"
    path.write_bytes(DEMO_LOG.read_bytes())
    return path


@pytest.mark.parametrize("cmd", COMMANDS)
def test_out_is_the_input_log(cmd, log, capsys, monkeypatch, tmp_path):
    before = digest(log)
    code, _, err = run([cmd, log, "--out", log, "--quiet"], capsys)
    one_line_error(code, err, str(log))
    assert digest(log) == before
    monkeypatch.chdir(tmp_path)  # the same file by a relative name
    code, _, err = run([cmd, "x.clf", "--out", "./x.clf", "--quiet"], capsys)
    one_line_error(code, err, "x.clf")
    assert digest(log) == before


@pytest.mark.parametrize("cmd", ["slam", "ekf", "map"])
def test_out_holding_the_input_is_refused(cmd, log, capsys, tmp_path):
    (tmp_path / "config.toml").write_text("# lineslam run configuration\n")
    code, _, err = run([cmd, log, "--out", tmp_path, "--quiet"], capsys)
    one_line_error(code, err, str(tmp_path), "input")
    assert log.is_file()


@pytest.mark.parametrize("cmd", ["slam", "ekf", "map", "compare", "simulate"])
def test_out_an_existing_file_or_dev_null(cmd, log, capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("keep me\n")
    for target in (afile, Path("/dev/null")):
        args = [cmd, "loop" if cmd == "simulate" else log, "--out", target, "--quiet"]
        code, _, err = run(args, capsys)
        one_line_error(code, err, str(target), "not a folder")
    assert afile.read_text() == "keep me\n"


def test_extract_out_dev_null_writes_nothing_beside_it(log, capsys):
    code, _, err = run(["extract", log, "--out", "/dev/null", "--quiet"], capsys)
    one_line_error(code, err, "/dev/null", "not a regular file")
    assert not Path("/dev/null.config.toml").exists()


@pytest.mark.parametrize("cmd", COMMANDS)
def test_parent_is_a_file(cmd, log, capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("")
    code, _, err = run([cmd, log, "--out", afile / "sub", "--quiet"], capsys)
    one_line_error(code, err, str(afile / "sub"), "not a folder")


@pytest.mark.parametrize("cmd", COMMANDS)
def test_out_under_proc(cmd, log, capsys):
    code, _, err = run([cmd, log, "--out", "/proc/lineslam-x", "--quiet"], capsys)
    one_line_error(code, err, "/proc/lineslam-x")


@pytest.mark.parametrize("cmd", [*COMMANDS, "compare", "simulate", "consistency"])
def test_empty_out_is_refused(cmd, log, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = [cmd] if cmd == "consistency" else [cmd, "loop" if cmd == "simulate" else log]
    code, _, err = run([*args, "--out", "", "--quiet"], capsys)
    one_line_error(code, err, "''", "empty path")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.clf"]


@pytest.mark.parametrize("cmd", ["slam", "ekf", "map"])
def test_current_folder_is_refused(cmd, log, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "config.toml").write_text("# lineslam run configuration\n")
    code, _, err = run([cmd, "/dev/null/no", "--out", ".", "--quiet"], capsys)
    one_line_error(code, err, "current folder")
    code, _, err = run([cmd, log, "--out", tmp_path.parent, "--quiet"], capsys)
    one_line_error(code, err, str(tmp_path.parent))


def test_a_folder_that_is_not_a_results_folder_is_not_replaced(log, capsys, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work\n")
    code, _, err = run(["slam", log, "--out", mine, "--quiet", "--max-scans", "5"], capsys)
    one_line_error(code, err, str(mine), "not a lineslam results folder")
    assert (mine / "thesis.tex").read_text() == "years of work\n"
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run(["slam", log, "--out", empty, "--quiet", "--max-scans", "5"], capsys)
    assert code == 0, err
    assert (empty / "trajectory.tum").is_file()


def test_config_a_folder_or_missing(log, capsys, tmp_path):
    for cmd in COMMANDS:
        code, _, err = run([cmd, log, "--out", tmp_path / "o", "--config", tmp_path], capsys)
        one_line_error(code, err, str(tmp_path), "folder")
        code, _, err = run(
            [cmd, log, "--out", tmp_path / "o", "--config", tmp_path / "none.toml"], capsys
        )
        one_line_error(code, err, "none.toml")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("cmd", COMMANDS)
def test_odometry_only_log_fails_in_every_command(cmd, capsys, tmp_path):
    odom = tmp_path / "odom.clf"
    lines = [ln for ln in DEMO_LOG.read_text().splitlines() if ln.startswith("ODOM")]
    odom.write_text("\n".join(lines[:30]) + "\n")
    out = tmp_path / ("o.jsonl" if cmd == "extract" else "o")
    code, _, err = run([cmd, odom, "--out", out, "--quiet"], capsys)
    one_line_error(code, err, str(odom), "no laser scans", "30 ODOM")
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["odom.clf"]


def test_a_returned_exit_status_is_kept(monkeypatch, capsys):
    """``typer`` returns (not raises) an ``Exit`` status in non-standalone mode: it is kept."""
    import slam.cli

    monkeypatch.setattr(slam.cli, "app", lambda **kwargs: 3)
    code, _, _ = run(["anything"], capsys)
    assert code == 3
    monkeypatch.setattr(slam.cli, "app", lambda **kwargs: 130)  # typer's KeyboardInterrupt
    code, _, err = run(["anything"], capsys)
    assert code == 130 and err == "lineslam: interrupted (SIGINT)\n"
