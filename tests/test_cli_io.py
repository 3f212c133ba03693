"""``lineslam datasets`` and ``lineslam evaluate`` end to end (in-process and as a program)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from slam.cli import main
from slam.io import relations_from_trajectory, write_relations, write_tum
from slam.io.results import write_results


def run(args, capsys):
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def make_run(tmp_path, rng, noise=0.0):
    n = 200
    stamps = np.round(5000.0 + np.arange(n) * 0.2, 6)
    truth = np.column_stack([np.arange(n) * 0.3, np.sin(np.arange(n) / 20.0), np.zeros(n)])
    estimate = truth + rng.normal(0, noise, truth.shape) if noise else truth
    write_results(tmp_path / "run", stamps, estimate, {"scans": n})
    write_tum(tmp_path / "gt.tum", stamps, truth)
    rel = relations_from_trajectory(
        stamps, truth, np.column_stack([np.arange(n - 5), np.arange(5, n)])
    )
    write_relations(tmp_path / "gt.relations", rel.t1, rel.t2, rel.poses)
    return tmp_path / "run"


def test_evaluate_writes_metrics(tmp_path, rng, capsys):
    run_dir = make_run(tmp_path, rng, noise=0.01)
    code, out, _ = run(
        [
            "evaluate",
            str(run_dir),
            "--relations",
            str(tmp_path / "gt.relations"),
            "--ground-truth",
            str(tmp_path / "gt.tum"),
            "--rpe-delta",
            "1",
            "--rpe-delta",
            "5",
        ],
        capsys,
    )
    assert code == 0
    assert "abs trans (m)" in out and "ATE rmse (m)" in out
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["relations"]["n_used"] == 195
    assert 0.005 < metrics["ate"]["rmse_m"] < 0.02
    assert [r["delta_m"] for r in metrics["rpe"]] == [1.0, 5.0]


def test_evaluate_bad_input_is_one_line_and_exit_2(tmp_path, rng, capsys):
    run_dir = make_run(tmp_path, rng)
    code, _, err = run(["evaluate", str(tmp_path / "nope"), "--relations", "x"], capsys)
    assert code == 2 and err.startswith("lineslam: error:") and err.count("\n") == 1
    shifted = tmp_path / "shifted.relations"
    shifted.write_text("1.0 2.0 0 0 0 0 0 0\n")
    code, _, err = run(["evaluate", str(run_dir), "--relations", str(shifted)], capsys)
    assert code == 2 and "time stamp" in err
    code, _, err = run(["evaluate", str(run_dir)], capsys)
    assert code != 0


def test_datasets_lists_the_catalogue(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("LINESLAM_DATA", str(tmp_path))
    code, out, _ = run(["datasets", "--json"], capsys)
    assert code == 0
    data = json.loads(out)
    assert [d["name"] for d in data["datasets"]] == ["intel", "aces", "fr079"]
    assert all(not d["present"] for d in data["datasets"])
    code, out, _ = run(["datasets"], capsys)
    assert out.count("missing") >= 3


@pytest.mark.realdata
def test_odometry_of_intel_evaluated_by_the_program(tmp_path, shared_data):
    """The installed program, on the real log: the README's odometry baseline."""
    from slam.io import resolve_log, scan_trajectory

    trajectory = scan_trajectory(resolve_log("intel", root=shared_data).log)
    write_results(tmp_path / "odo", trajectory.timestamps, trajectory.poses, {}, frame="base")
    env = {**os.environ, "LINESLAM_DATA": str(shared_data)}
    done = subprocess.run(
        [sys.executable, "-m", "slam", "evaluate", str(tmp_path / "odo"), "--relations", "intel"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert "7.37298 +/- 14.45872" in done.stdout
    metrics = json.loads((tmp_path / "odo" / "metrics.json").read_text())
    assert metrics["frame"] == "base" and metrics["relations"]["n_used"] == 2984


@pytest.mark.parametrize(
    "command",
    [
        "datasets",
        "extract",
        "map",
        "slam",
        "ekf",
        "evaluate",
        "simulate",
        "compare",
        "consistency",
    ],
)
def test_every_command_prints_its_help(command, capsys):
    """``--help`` renders (rich markup in a help text, e.g. an unescaped ``[...]``, broke it)."""
    try:
        main([command, "--help"])
    except SystemExit as exc:  # pragma: no cover - typer may exit 0 after the help
        assert exc.code in (0, None)
    out = capsys.readouterr().out
    assert "Usage" in out and "--help" in out
