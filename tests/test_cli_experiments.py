"""``lineslam compare`` and ``lineslam consistency`` end to end on the line-level simulator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slam.cli import main
from slam.config import RunConfig


def test_compare_on_a_simulated_loop_writes_report_and_variant_folders(tmp_path):
    out = tmp_path / "cmp"
    main(
        [
            "compare",
            "sim:corridor_loop:0.5:3",
            "--out",
            str(out),
            "--quiet",
            "--variants",
            "ekf=ekf-nn,jcbb=ekf-jcbb,odometry",
        ]
    )
    report = json.loads((out / "report.json").read_text())
    rows = {r["variant"]: r for r in report["variants"]}
    assert set(rows) == {"ekf", "jcbb", "odometry"}
    assert rows["ekf"]["ate_rmse_m"] < 0.1 * rows["odometry"]["ate_rmse_m"]
    assert rows["ekf"]["landmarks"] >= 8 and rows["odometry"]["landmarks"] == 0
    for name in rows:
        traj = np.loadtxt(out / name / "trajectory.tum")
        assert traj.shape == (rows[name]["scans"], 8)
        assert (out / name / "map.json").is_file() and (out / name / "summary.json").is_file()
    md = (out / "report.md").read_text()
    assert "| ekf |" in md and "nees.png" in md
    for fig in report["figures"]:
        assert (out / fig).stat().st_size > 1000
    assert RunConfig.from_toml(out / "config.toml") == RunConfig()


def test_consistency_command_writes_summary(tmp_path):
    out = tmp_path / "mc"
    main(
        [
            "consistency",
            "--out",
            str(out),
            "--runs",
            "3",
            "--loops",
            "0.5",
            "--quiet",
            "--estimators",
            "odometry",
        ]
    )
    doc = json.loads((out / "consistency.json").read_text())
    odo = doc["estimators"]["odometry"]
    assert odo["n_runs"] == 3 and len(odo["run_mean_nees"]) == 3
    assert (out / "nees.png").is_file() and (out / "error.png").is_file()


def test_consistency_long_run_reports_the_anees_per_loop(tmp_path):
    """A tiny long run: the simulator's noise set from the command line (the estimators told
    the same), the ANEES per loop in the table and in consistency.json."""
    from slam.experiments.linesim import SIM_ODOMETRY

    out = tmp_path / "long"
    argv = ["consistency", "--out", str(out), "--runs", "2", "--loops", "2", "--quiet"]
    argv += ["--estimators", "ekf,odometry", "--odometry-scale", "2"]
    argv += ["--line-range-sigma", "0.05", "--line-point-spacing", "0.25"]
    main(argv)
    doc = json.loads((out / "consistency.json").read_text())
    assert doc["linesim"]["sigma_range_m"] == 0.05 and doc["linesim"]["point_spacing_m"] == 0.25
    odo = doc["linesim"]["odometry"]
    assert odo["sigma_theta_per_rad"] == pytest.approx(2 * SIM_ODOMETRY.sigma_theta_per_rad)
    assert odo["sigma_xy_min_m"] == SIM_ODOMETRY.sigma_xy_min_m  # floors kept
    for est in doc["estimators"].values():
        per_loop = est["anees_per_loop"]
        assert len(per_loop) == 2
        assert np.mean(per_loop) == pytest.approx(est["mean_anees"], rel=0.05)
        heading = est["anees_heading_per_loop"]
        assert len(heading) == 2
        assert np.mean(heading) == pytest.approx(est["mean_anees_heading"], rel=0.05)
        assert np.all(np.array(heading) < np.array(per_loop))
    assert (out / "nees.png").stat().st_size > 1000
    assert (out / "nees_heading.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "argv, message",
    [
        (["compare", "sim:moon", "--out", "X"], "unknown simulated world"),
        (
            ["compare", "sim:corridor_loop", "--out", "X", "--variants", "a=kalman"],
            "unknown estimator",
        ),
        (["consistency", "--out", "X", "--runs", "0"], "n_runs"),
    ],
)
def test_bad_arguments_give_one_line_errors(tmp_path, capsys, argv, message):
    argv = [a if a != "X" else str(tmp_path / "o") for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


DEMO = Path(__file__).resolve().parents[1] / "datasets" / "sim" / "demo"


def test_ekf_command_on_the_demo_log_beats_odometry(tmp_path):
    from slam.evaluation import relations_metric
    from slam.io import read_relations, read_tum

    out = tmp_path / "ekf"
    main(["ekf", str(DEMO / "log.clf"), "--out", str(out), "--quiet"])
    traj = read_tum(out / "trajectory.tum")
    odo = read_tum(DEMO / "odometry.tum")
    assert len(traj) == len(odo) == 383
    np.testing.assert_array_equal(traj.timestamps, odo.timestamps)  # the log's stamps, exactly
    rel = read_relations(DEMO / "relations.txt")
    m_ekf, m_odo = relations_metric(traj, rel), relations_metric(odo, rel)
    assert m_ekf.abs_trans_m.mean < 0.01 < m_odo.abs_trans_m.mean
    assert m_ekf.abs_trans_m.mean < 0.1 * m_odo.abs_trans_m.mean
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scans"] == 383 and summary["lines_fit"] > 0 and summary["frame"] == "base"
    assert 0.9 < summary["compression"] < 1.0
    assert RunConfig.from_toml(out / "config.toml") == RunConfig()


def compare_demo(tmp_path, config_toml, *options):
    """``lineslam compare`` on the demo log with a configuration; report rows and markdown."""
    out = tmp_path / "cmp"
    (tmp_path / "run.toml").write_text(config_toml)
    main(
        ["compare", str(DEMO / "log.clf"), "--out", str(out), "--quiet"]
        + ["--config", str(tmp_path / "run.toml"), *options]
    )
    rows = {r["variant"]: r for r in json.loads((out / "report.json").read_text())["variants"]}
    return out, rows, (out / "report.md").read_text()


def test_compare_on_the_demo_log_evaluates_relations_ground_truth_and_nees(tmp_path):
    # the simulated fits' covariances are exact: no model-error floor, so NEES means something
    out, rows, md = compare_demo(
        tmp_path,
        "[ekf]\nline_sigma_extra = [0.0, 0.0]\n",
        "--max-scans",
        "200",
        "--variants",
        "ekf=ekf-nn,unweighted=ekf-nn/unweighted,odometry",
    )
    for name in ("ekf", "unweighted"):
        assert rows[name]["rel_trans_mean_m"] < 0.2 * rows["odometry"]["rel_trans_mean_m"]
        assert rows[name]["ate_rmse_m"] < 0.2 * rows["odometry"]["ate_rmse_m"]
        assert rows[name]["scans_processed"] == 200
        assert 0.5 < rows[name]["nees_mean"] < 10.0
    assert "relations trans. (m)" in md and "ATE RMSE (m)" in md
    assert "* ekf: ran to the end (200 scans)" in md and "stopped at" not in md
    assert list((out / ".cache").glob("lines-*.pkl"))  # weighted and unweighted fits cached
    assert len(list((out / ".cache").glob("lines-*.pkl"))) == 2


def test_compare_report_says_where_the_ekf_stopped(tmp_path):
    _, rows, md = compare_demo(
        tmp_path,
        "[ekf]\nmax_landmarks = 5\n",
        "--no-figures",
        "--max-scans",
        "150",
        "--time-budget",
        "0.05",  # far below what the graph needs for 150 scans on any machine (~0.5 s here)
        "--variants",
        "ekf=ekf-nn,graph=graph-isam2",
    )
    ekf = rows["ekf"]
    assert ekf["stopped_at_scan"] is not None and ekf["scans_processed"] < 150
    assert f"* ekf: **stopped at scan {ekf['stopped_at_scan']} of 150**" in md
    assert "max_landmarks=5" in md
    graph = rows["graph"]
    assert graph["stopped_at_scan"] is not None and 0 < graph["scans_processed"] < 150
    assert f"* graph: **stopped at scan {graph['stopped_at_scan']} of 150**" in md
    assert "time budget of 0.05 s" in md


def test_compare_reports_the_logs_warnings_once_as_every_command_does(tmp_path, capsys):
    """An input warning (here: a log that does not state its beam layout) comes out as one
    ``lineslam: warning: N x ...`` line, not as Python's warning with its source line."""
    log = tmp_path / "plain.clf"
    log.write_text(
        "".join(
            line
            for line in (DEMO / "log.clf").read_text().splitlines(keepends=True)
            if not line.startswith("PARAM")
        )
    )
    main(
        ["compare", str(log), "--out", str(tmp_path / "cmp"), "--quiet", "--max-scans", "30"]
        + ["--variants", "odometry", "--relations", str(DEMO / "relations.txt")]
    )
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "CARMEN's rule" in line]
    assert len(lines) == 1 and lines[0].startswith("lineslam: warning: 1 x InputWarning: ")


@pytest.mark.parametrize("command", ["consistency", "compare"])
def test_the_help_names_every_estimator(command, capsys):
    """The estimator names in ``--help`` are exactly :data:`ESTIMATORS` (kept in step by hand:
    the CLI does not import the experiments to print its help)."""
    import re

    from slam.experiments.estimators import ESTIMATORS

    try:
        main([command, "--help"])
    except SystemExit as exc:  # typer may exit 0 after printing the help
        assert exc.code in (0, None)
    text = " ".join(capsys.readouterr().out.split())
    listed = set(re.findall(r"\b(?:ekf(?:-[a-z]+)?|graph-[a-z0-9]+|odometry)\b", text))
    assert set(ESTIMATORS) <= listed, set(ESTIMATORS) - listed
