"""Runners (``slam.runner``): the EKF through the same path as the graph, one summary write."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from slam.cli import main
from slam.config import RunConfig
from slam.geometry import pose_compose
from slam.inputs import InputPolicy, read_log_scans
from slam.io import read_tum

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
MOUNT = (0.3, 0.1, 0.2)  # (m, m, rad): large enough to move every pose visibly

CATALOGUE = """schema = 1

[datasets.mounted]
title = "the demo log, catalogued with a laser mounting missing from its laser poses"
log = "mounted/mounted.clf"
log_bytes = {size}
log_sha256 = "{sha}"
relations_frame = "{frame}"

[datasets.mounted.laser]
beams = 180
first_angle_deg = -90.0
step_deg = 1.0
max_range_m = 80.0
mount_x_m = {x}
mount_y_m = {y}
mount_theta_deg = {theta_deg}
mount_applied_in_log = false
"""


def _catalogued_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, frame: str) -> Path:
    """A copy of the demo log, catalogued (by its content) with :data:`MOUNT` and relations in
    ``frame``."""
    from slam.io.catalog import sha256_file

    catalogue = tmp_path / "catalog.toml"
    catalogue.write_text(
        CATALOGUE.format(
            x=MOUNT[0],
            y=MOUNT[1],
            theta_deg=np.degrees(MOUNT[2]),
            size=DEMO_LOG.stat().st_size,
            sha=sha256_file(DEMO_LOG),
            frame=frame,
        ),
        "utf-8",
    )
    monkeypatch.setenv("LINESLAM_CATALOG", str(catalogue))
    log = tmp_path / "mounted.clf"
    shutil.copyfile(DEMO_LOG, log)
    return log


@pytest.fixture
def mounted_log(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The demo log catalogued with :data:`MOUNT`, its relations relating base poses."""
    return _catalogued_copy(tmp_path, monkeypatch, "base")


def test_a_catalogued_log_is_reported_in_the_frame_of_its_relations(tmp_path, monkeypatch):
    """With relations of laser poses (``relations_frame = "laser"``) the default run still
    reads the odometry through the catalogued mounting but reports the laser: its poses are
    those of ``--frame base`` composed with the mounting."""
    log = _catalogued_copy(tmp_path, monkeypatch, "laser")
    n = 40
    runs = {}
    for name, extra in (("auto", []), ("base", ["--frame", "base"])):
        out = tmp_path / name
        main(["ekf", str(log), "--out", str(out), "--max-scans", str(n), "--quiet", *extra])
        summary = json.loads((out / "summary.json").read_text())
        assert summary["input"]["pose_base_laser"] == pytest.approx(list(MOUNT))
        runs[name] = (summary["frame"], read_tum(out / "trajectory.tum").poses)
    assert runs["auto"][0] == "laser" and runs["base"][0] == "base"
    laser = pose_compose(runs["base"][1], np.broadcast_to(MOUNT, runs["base"][1].shape))
    np.testing.assert_allclose(runs["auto"][1], laser, atol=1e-9)


def test_ekf_command_applies_the_catalogued_mounting(tmp_path, mounted_log):
    """``lineslam ekf`` on a catalogued log whose laser poses lack the mounting reads the laser
    odometry as base odometry ∘ mounting and reports base poses, as ``lineslam slam`` does; with
    ``mount_source = "config"`` and ``output_frame = "laser"`` it reports the logged laser
    poses' frame."""
    n = 40
    out = tmp_path / "catalog"
    main(["ekf", str(mounted_log), "--out", str(out), "--max-scans", str(n), "--quiet"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frame"] == "base" and summary["dataset"] == "mounted"
    traj = read_tum(out / "trajectory.tum")
    scans = list(read_log_scans(mounted_log, InputPolicy()))[:n]
    base0 = np.asarray(scans[0].pose_odom_base, dtype=float)
    laser0 = np.asarray(scans[0].pose_odom_laser, dtype=float)
    # the filter starts at the first scan's odometry: reported for the base, that is the base's
    np.testing.assert_allclose(traj.poses[0], base0, atol=1e-9)

    # the same run with the mounting given explicitly instead of by the catalogue
    cfg = RunConfig()
    explicit = replace(
        cfg,
        scanner=replace(
            cfg.scanner,
            mount_source="config",
            pose_base_laser=MOUNT,
            laser_odometry="base",
            output_frame="base",
        ),
    )
    explicit.to_toml(tmp_path / "explicit.toml")
    out_explicit = tmp_path / "explicit"
    main(
        ["ekf", str(mounted_log), "--out", str(out_explicit), "--max-scans", str(n), "--quiet"]
        + ["--config", str(tmp_path / "explicit.toml")]
    )
    assert (out_explicit / "trajectory.tum").read_bytes() == (out / "trajectory.tum").read_bytes()

    # without the catalogue's mounting: the logged laser poses, reported for the laser
    plain = replace(cfg, scanner=replace(cfg.scanner, mount_source="config", output_frame="laser"))
    plain.to_toml(tmp_path / "plain.toml")
    out_plain = tmp_path / "plain"
    main(
        ["ekf", str(mounted_log), "--out", str(out_plain), "--max-scans", str(n), "--quiet"]
        + ["--config", str(tmp_path / "plain.toml")]
    )
    assert json.loads((out_plain / "summary.json").read_text())["frame"] == "laser"
    plain_traj = read_tum(out_plain / "trajectory.tum")
    np.testing.assert_allclose(plain_traj.poses[0], laser0, atol=1e-9)
    assert not np.allclose(plain_traj.poses[:, :2], traj.poses[:, :2], atol=0.05)
    # the catalogued run's laser poses are its base poses composed with the mounting
    laser_of_base = pose_compose(traj.poses, np.broadcast_to(MOUNT, traj.poses.shape))
    assert np.max(np.abs(laser_of_base[:, :2] - traj.poses[:, :2])) > 0.2


@pytest.mark.parametrize("runner_name", ["run_slam", "run_ekf"])
def test_summary_json_is_written_once_with_the_run_times(tmp_path, monkeypatch, runner_name):
    import slam.runner

    writes: list[str] = []
    original = Path.write_text

    def counting_write_text(self: Path, *args, **kwargs):  # type: ignore[no-untyped-def]
        writes.append(self.name)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", counting_write_text)
    out = tmp_path / "run"
    runner = getattr(slam.runner, runner_name)
    returned = runner(DEMO_LOG, out, RunConfig(), max_scans=25)
    assert writes.count("summary.json") == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary == json.loads(json.dumps(returned))
    assert summary["scans"] == 25 and summary["dataset"] == "log"
    stages = {"read", "estimate", "optimize", "write", "total"}
    assert stages <= set(summary["runtime_s"])
    assert runner_name == "run_slam" or summary["runtime_s"]["extract"] > 0.0
    assert (out / "trajectory_covariance.txt").is_file() and (out / "map.json").is_file()


def test_the_runner_feeds_no_scans_to_a_stopped_filter(tmp_path):
    from slam.runner import run_ekf

    cfg = RunConfig()
    cfg = replace(cfg, ekf=replace(cfg.ekf, max_landmarks=15, on_max_landmarks="stop"))
    summary = run_ekf(DEMO_LOG, tmp_path, cfg, max_scans=200)
    stop = summary["stopped_at_scan"]
    assert 0 < stop < 199 and "max_landmarks=15" in summary["stop_reason"]
    assert summary["scans"] == stop + 1 and "scans_after_stop" not in summary
    assert len(read_tum(tmp_path / "trajectory.tum")) == stop + 1


def test_the_ekf_runner_gives_the_filter_fed_scan_by_scan(tmp_path):
    """``run_ekf`` = reading the log with the policy, batched extraction, ``add_scan``."""
    from slam.ekf import EkfSlam
    from slam.extraction import iter_scan_lines
    from slam.runner import run_ekf

    cfg = RunConfig()
    run_ekf(DEMO_LOG, tmp_path, cfg, max_scans=50)
    ekf = EkfSlam(cfg.ekf, cfg.linefit, InputPolicy.of(cfg.scanner))
    scans = list(read_log_scans(DEMO_LOG, InputPolicy.of(cfg.scanner)))[:50]
    for scan, lines in iter_scan_lines(scans, cfg.linefit):
        ekf.add_scan(scan, lines)
    res = ekf.result()
    traj = read_tum(tmp_path / "trajectory.tum")
    np.testing.assert_array_equal(traj.timestamps, res.timestamps)
    np.testing.assert_allclose(traj.poses[:, :2], res.poses_world_laser[:, :2], atol=1e-9)
    m = json.loads((tmp_path / "map.json").read_text())
    keep = res.landmark_n_observations >= cfg.ekf.min_landmark_observations
    assert len(m["lines"]) == int(np.count_nonzero(keep)) > 0
