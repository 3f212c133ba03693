"""``lineslam slam`` end to end on the demo log (a few dozen scans), files per INTERFACES.md."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO_ROOT

import slam.blas
from slam.cli import main
from slam.config import RunConfig
from slam.geometry import pose_between, pose_log
from slam.io import read_tum
from slam.lines.mapio import read_map_json

DEMO = REPO_ROOT / "datasets" / "sim" / "demo"


def run(args, capsys):
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("backend", ["isam2", "batch"])
def test_slam_writes_the_results_folder(tmp_path, capsys, backend):
    out = tmp_path / "run"
    code, stdout, _ = run(
        [
            "slam",
            str(DEMO / "log.clf"),
            "--out",
            str(out),
            "--backend",
            backend,
            "--max-scans",
            "60",
            "--quiet",
        ],
        capsys,
    )
    assert code == 0 and stdout == ""
    for name in ("trajectory.tum", "map.json", "summary.json", "config.toml"):
        assert (out / name).is_file()
    traj = read_tum(out / "trajectory.tum")
    assert len(traj.timestamps) == 60
    lines = (out / "trajectory.tum").read_text().splitlines()
    assert all(len(line.split()) == 8 for line in lines)
    # time stamps as in the log, and the estimate close to the simulator's truth
    truth = read_tum(DEMO / "ground_truth.tum")
    np.testing.assert_allclose(traj.timestamps, truth.timestamps[:60], atol=1e-6)
    err = pose_log(pose_between(truth.poses[:60], traj.poses))
    assert np.abs(err[:, :2]).max() < 0.02
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scans", "points", "lines_fit", "lines_merged", "compression", "runtime_s"):
        assert key in summary
    assert summary["frame"] == "base" and summary["scans"] == 60
    assert summary["backend"]["backend"] == backend
    assert {"read", "estimate", "optimize", "write", "total"} <= set(summary["runtime_s"])
    # the BLAS kernels the run used, as loaded in this process (slam.blas)
    assert summary["blas"]["selection"] == slam.blas.selection
    assert summary["blas"]["libraries"] and all(
        lib["architecture"] for lib in summary["blas"]["libraries"]
    )
    assert summary["blas"]["numpy_selection"] == slam.blas.numpy_selection
    assert isinstance(summary["blas"]["numpy_loops"], list)
    line_map = read_map_json(out / "map.json")
    assert len(line_map) == summary["lines_merged"] > 5
    assert all(ln.r >= 0 and -np.pi < ln.alpha <= np.pi for ln in line_map.lines)
    cfg = RunConfig.from_toml(out / "config.toml")
    assert cfg.slam.backend == backend


def test_slam_plot_and_bad_input(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, _ = run(
        [
            "slam",
            str(DEMO / "log.clf"),
            "--out",
            str(out),
            "--max-scans",
            "10",
            "--plot",
            "--quiet",
        ],
        capsys,
    )
    assert code == 0 and (out / "figures" / "trajectory_map.png").stat().st_size > 1000
    code, _, err = run(
        ["slam", str(tmp_path / "missing.clf"), "--out", str(out), "--quiet"], capsys
    )
    assert code == 2 and "missing.clf" in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.clf"
    bad.write_text("FLASER 3 1.0 2.0 oops\n")
    code, _, err = run(["slam", str(bad), "--out", str(out), "--quiet"], capsys)
    assert code == 2 and "bad.clf" in err
    code, _, err = run(
        ["slam", str(DEMO / "log.clf"), "--out", str(out), "--backend", "ekf", "--quiet"], capsys
    )
    assert code != 0 and "backend" in err


def test_raw_points_are_placed_by_the_estimated_poses():
    from slam.plotting.trajectory_map import raw_points_world
    from slam.types import Scan

    bearings = np.array([0.0, np.pi / 2, 1.0])
    scans = [
        Scan(0, 0.0, np.array([2.0, 1.0, np.inf]), bearings, max_range_m=10.0),
        Scan(1, 0.1, np.array([3.0, 0.0, 10.0]), bearings, max_range_m=10.0),  # 0, max: skipped
        Scan(2, 0.2, np.array([5.0, 5.0, 5.0]), bearings, max_range_m=10.0),  # not kept
    ]
    poses = np.array([[1.0, 1.0, np.pi / 2], [0.0, 0.0, np.pi], [0.0, 0.0, 0.0]])
    points = raw_points_world(scans, poses, np.array([True, True, False]))
    np.testing.assert_allclose(points, [[1.0, 3.0], [0.0, 1.0], [-3.0, 0.0]], atol=1e-12)


def _demo_metrics(tmp_path, capsys, name, extra=()):
    out = tmp_path / name
    code, _, _ = run(["slam", str(DEMO / "log.clf"), "--out", str(out), "--quiet", *extra], capsys)
    assert code == 0
    args = ["evaluate", str(out), "--relations", str(DEMO / "relations.txt"), "--quiet"]
    args += ["--ground-truth", str(DEMO / "ground_truth.tum")]
    assert run(args, capsys)[0] == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, json.loads((out / "metrics.json").read_text())


def test_default_demo_run_is_consistent_with_the_estimated_model_error(tmp_path, capsys):
    """The whole demo log with the defaults: the lines' model error estimated from the run is
    about zero (simulated walls), and the relations NEES lies inside its 95 % bounds, the pose
    NEES inside the interval of one run (its poses correlated).  With the fixed model error of
    real walls the same run is far under-confident and less accurate."""
    summary, metrics = _demo_metrics(tmp_path, capsys, "estimated")
    est = summary["line_model_error"]
    assert est["updates"] >= 1 and est["sigma_offset_m"] < 1e-3 and est["sigma_angle_rad"] < 5e-4
    nees = metrics["relations_nees"]
    lo, hi = nees["one_run"]["bounds_95"]
    assert nees["consistent"] and lo <= nees["mean"] <= hi
    assert lo <= nees["bounds_95"][0] and nees["bounds_95"][1] <= hi  # wider than independent
    pose = metrics["nees"]
    lo, hi = pose["one_run"]["bounds"]
    assert pose["consistent"] and lo <= pose["one_run"]["mean"] <= hi
    assert pose["one_run"]["effective_dof"] < 0.1 * 3 * pose["n"]  # far from independent
    error = metrics["relations"]["abs_trans_m"]["mean"]
    assert error < 0.003
    # simulated walls are the fits' straight lines: passes along them agree as the factors say
    walls = metrics["walls_between_passes"]
    assert walls["pairs"] >= 10 and walls["fraction_beyond_95"] < 0.2
    assert 0.2 < walls["median_ratio"] < 2.5
    fixed = tmp_path / "fixed.toml"
    fixed.write_text('[slam]\nline_model_error = "fixed"\n')
    summary, metrics = _demo_metrics(tmp_path, capsys, "fixed", ["--config", str(fixed)])
    assert "line_model_error" not in summary
    assert metrics["relations_nees"]["mean"] < 1.0
    assert metrics["nees"]["one_run"]["mean"] < metrics["nees"]["one_run"]["bounds"][0]
    assert metrics["relations"]["abs_trans_m"]["mean"] > 2.0 * error


def test_the_pass_error_changes_the_covariances_not_the_estimate(tmp_path, capsys, monkeypatch):
    """A simulated laboratory driven through more than once (``lab``, seed 11): its walls
    have no pass error, and with ``line_pass_error = "estimated"`` (the default) none is
    estimated (its pairs of passes disagree no more than chance allows): the covariances are
    those of ``"off"``.  Estimated without the significance test (a pass error of about
    1 mm), the walls seen in several passes get linked passes in ``graph.g2o`` and the
    covariances differ from those with ``"off"``, the trajectory and the map do not;
    ``lineslam evaluate`` reads the linked graph."""
    from slam.line_slam import passes

    sim = tmp_path / "lab"
    assert run(["simulate", "lab", "--seed", "11", "--out", str(sim), "--quiet"], capsys)[0] == 0
    option = tmp_path / "off.toml"
    option.write_text('[slam]\nline_pass_error = "off"\n')
    runs = {}
    for name, extra in (("off", ["--config", str(option)]), ("default", []), ("passes", [])):
        if name == "passes":
            monkeypatch.setattr(passes, "SIGNIFICANCE", 0.5)  # any excess at all
        out = tmp_path / name
        args = ["slam", str(sim / "log.clf"), "--out", str(out), "--quiet", *extra]
        assert run(args, capsys)[0] == 0
        runs[name] = out
    default = json.loads((runs["default"] / "summary.json").read_text())["line_pass_error"]
    assert default["pairs"] >= 20 and default["linked_passes"] == 0
    assert default["sigma_offset_m"] == 0.0 and default["sigma_angle_rad"] == 0.0
    np.testing.assert_array_equal(
        np.loadtxt(runs["default"] / "trajectory_covariance.txt"),
        np.loadtxt(runs["off"] / "trajectory_covariance.txt"),
    )
    summary = json.loads((runs["passes"] / "summary.json").read_text())
    est = summary["line_pass_error"]
    assert est["pairs"] >= 20 and est["linked_passes"] > 0
    assert "line_pass_error" not in json.loads((runs["off"] / "summary.json").read_text())
    a = read_tum(runs["off"] / "trajectory.tum")
    b = read_tum(runs["passes"] / "trajectory.tum")
    np.testing.assert_array_equal(a.poses, b.poses)
    map_a = read_map_json(runs["off"] / "map.json").lines
    map_b = read_map_json(runs["passes"] / "map.json").lines
    assert [(m.r, m.alpha) for m in map_a] == [(m.r, m.alpha) for m in map_b]
    g2o = (runs["passes"] / "graph.g2o").read_text()
    assert g2o.count("LINESLAM_EDGE_LINE2D_LINK") == est["linked_passes"]
    assert "LINESLAM_EDGE_LINE2D_LINK" not in (runs["off"] / "graph.g2o").read_text()
    cov_a = np.loadtxt(runs["off"] / "trajectory_covariance.txt")
    cov_b = np.loadtxt(runs["passes"] / "trajectory_covariance.txt")
    assert not np.allclose(cov_a, cov_b)
    args = ["evaluate", str(runs["passes"]), "--relations", str(sim / "relations.txt"), "--quiet"]
    assert run(args, capsys)[0] == 0
    assert json.loads((runs["passes"] / "metrics.json").read_text())["relations_nees"]["n"] > 0


def test_a_pass_error_that_cannot_be_estimated_leaves_the_run_as_without(
    tmp_path, capsys, monkeypatch
):
    from slam.errors import EstimationError
    from slam.line_slam import pipeline

    def fail(self):
        raise EstimationError("information matrix of the graph is singular: test")

    monkeypatch.setattr(pipeline.LineSlam, "_pass_model", fail)
    out = tmp_path / "run"
    args = ["slam", str(DEMO / "log.clf"), "--out", str(out), "--quiet"]
    assert run(args, capsys)[0] == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "singular: test" in summary["line_pass_error"]["skipped"]
    assert "LINESLAM_EDGE_LINE2D_LINK" not in (out / "graph.g2o").read_text()
    assert np.isfinite(np.loadtxt(out / "trajectory_covariance.txt")).all()
