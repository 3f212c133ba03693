"""simulate → files: ground truth vs its relations, determinism, the CLI, the demo dataset."""

from __future__ import annotations

import filecmp
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slam.cli import main
from slam.evaluation import relations_metric
from slam.io.carmen import iter_scans
from slam.io.relations import read_relations
from slam.io.tum import read_tum
from slam.sim import (
    LaserConfig,
    LaserNoiseConfig,
    SimConfig,
    TrajectoryConfig,
    cast_scan,
    get_world,
    read_world,
)
from slam.sim.simulate import simulate
from slam.sim.write import SIM_FILES, write_simulation

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "datasets" / "sim" / "demo"
SMALL = ["--spacing", "0.6"]  # a quicker log for the CLI tests


def test_ground_truth_scores_zero_against_its_own_relations(tmp_path):
    config = SimConfig(world="lab", laser=LaserConfig(pose_base_laser=(0.2, 0.05, 0.1)))
    log = simulate(get_world("lab"), None, config, seed=4)
    paths = write_simulation(log, tmp_path)
    assert set(paths) == set(SIM_FILES)
    relations = read_relations(paths["relations"])
    assert len(relations) == len(log.relation_pairs) > 100
    truth = relations_metric(read_tum(paths["ground_truth"]), relations)
    assert truth.n_unmatched == 0 and truth.n_used == len(relations)
    assert truth.abs_trans_m.mean < 1e-8 and truth.abs_rot_deg.mean < 1e-6
    odometry = relations_metric(read_tum(paths["odometry"]), relations)
    assert odometry.abs_trans_m.mean > 1e-3  # the odometry is not the truth
    # The log's scans were cast from the true laser poses (mounting offset applied).
    scans = list(iter_scans(paths["log"]))
    assert len(scans) == log.n_scans
    gt = read_tum(paths["ground_truth"])
    ranges, _ = cast_scan(gt.poses[10], scans[10].bearings, log.world, 80.0)
    assert np.abs(scans[10].ranges - ranges).max() < 6 * 0.005 + 1e-3
    np.testing.assert_allclose(gt.poses, log.poses_world_laser, atol=1e-8)
    hits = np.load(paths["beam_hits"])
    assert hits.dtype == np.int32 and hits.shape == (log.n_scans, log.n_beams)
    np.testing.assert_array_equal(hits, log.hit_ids)
    assert SimConfig.from_toml(paths["config"]) == log.config
    np.testing.assert_array_equal(read_world(paths["world"]).segments, log.world.segments)


def test_noise_free_simulation_is_the_exact_geometry():
    config = SimConfig(
        world="hallway",
        noise=LaserNoiseConfig(sigma_range_m=0.0, sigma_bearing_rad=0.0),
        trajectory=TrajectoryConfig(scan_spacing_m=2.0),
    )
    log = simulate(get_world("hallway"), None, config, seed=0)
    for k in range(0, log.n_scans, 5):
        ranges, ids = cast_scan(log.poses_world_laser[k], log.bearings_rad, log.world, 80.0)
        np.testing.assert_array_equal(log.ranges_m[k], ranges)
        np.testing.assert_array_equal(log.hit_ids[k], ids)
    assert (log.hit_ids >= 0).all()  # a closed world: every beam returns


def test_same_seed_same_streams_other_seed_other_noise():
    world = get_world("lab")
    a = simulate(world, None, SimConfig(world="lab"), seed=8)
    b = simulate(world, None, SimConfig(world="lab"), seed=8)
    c = simulate(world, None, SimConfig(world="lab"), seed=9)
    for name in ("ranges_m", "hit_ids", "poses_odom_base", "relation_pairs"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.ranges_m, c.ranges_m)
    # Independent streams: other odometry noise, same laser readings.
    odo = replace(SimConfig(world="lab").odometry, sigma_trans_per_m=0.1)
    d = simulate(world, None, replace(SimConfig(world="lab"), odometry=odo), seed=8)
    np.testing.assert_array_equal(a.ranges_m, d.ranges_m)
    assert not np.array_equal(a.poses_odom_base, d.poses_odom_base)


def _run(*args: str) -> None:
    main(list(args))


def test_cli_is_deterministic_and_reloads_its_config(tmp_path, capsys):
    one, two, three, other = (tmp_path / n for n in ("one", "two", "three", "other"))
    _run("simulate", "hallway", "--out", str(one), "--seed", "5", "--quiet", *SMALL)
    _run("simulate", "hallway", "--out", str(two), "--seed", "5", "--quiet", *SMALL)
    _run("simulate", "--config", str(one / "config.toml"), "--out", str(three), "--quiet")
    _run("simulate", "hallway", "--out", str(other), "--seed", "6", "--quiet", *SMALL)
    names = sorted(SIM_FILES.values())
    assert sorted(p.name for p in one.iterdir()) == names
    for d in (two, three):
        _, mismatch, errors = filecmp.cmpfiles(one, d, names, shallow=False)
        assert mismatch == [] and errors == [], d
    _, mismatch, _ = filecmp.cmpfiles(one, other, names, shallow=False)
    assert "log.clf" in mismatch and "world.json" not in mismatch
    assert capsys.readouterr().out == ""  # --quiet


def test_cli_options_and_summary(tmp_path, capsys):
    out = tmp_path / "paper"
    _run(
        "simulate",
        "lab",
        "--out",
        str(out),
        "--paper-laser",
        "--sigma-d",
        "0.01",
        "--sigma-phi",
        "0",
        "--no-beam-hits",
        *SMALL,
    )
    printed = capsys.readouterr().out
    assert "scans x 720 beams" in printed and "relations" in printed
    config = SimConfig.from_toml(out / "config.toml")
    assert config.laser.n_beams == 720 and config.noise.sigma_range_m == 0.01
    assert config.noise.sigma_bearing_rad == 0.0 and config.trajectory.scan_spacing_m == 0.6
    assert not (out / "beam_hits.npy").exists()
    first = next(iter_scans(out / "log.clf"))
    assert first.n_beams == 720
    np.testing.assert_allclose(np.rad2deg(first.bearings[[0, 1, -1]]), [-90.0, -89.75, 89.75])
    # A world.json path works as WORLD.
    again = tmp_path / "again"
    _run("simulate", str(out / "world.json"), "--out", str(again), "--quiet", *SMALL)
    assert (again / "log.clf").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["atlantis"], "unknown world"),
        (["lab", "--sigma-d", "-1"], "sigma_range_m"),
        (["lab", "--beams", "0"], "n_beams"),
        (["lab", "--seed", "-2"], "seed"),
        (["lab", "--config", "missing.toml"], "not found"),
        ([], "give a WORLD"),
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    with pytest.raises(SystemExit) as info:
        main(["simulate", *args, "--out", str(tmp_path / "x"), "--quiet"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_demo_dataset_is_committed_small_and_regenerates_identically(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "make_demo", REPO / "scripts" / "make_demo_dataset.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    log = module.make_demo(tmp_path)
    committed = ["log.clf", "ground_truth.tum", "relations.txt", "world.json", "config.toml"]
    _, mismatch, errors = filecmp.cmpfiles(DEMO, tmp_path, committed, shallow=False)
    assert mismatch == [] and errors == []
    assert sum((DEMO / n).stat().st_size for n in committed) < 1_000_000
    assert 300 <= log.n_scans <= 600 and log.n_beams == 180
    # Something for SLAM to correct: metres of drift, tens of cm of relation error.
    drift = np.linalg.norm(log.poses_odom_base[:, :2] - log.poses_world_base[:, :2], axis=1)
    assert 2.0 < drift.max() < 10.0
    odometry = relations_metric(
        read_tum(DEMO / "odometry.tum"), read_relations(DEMO / "relations.txt")
    )
    assert 0.1 < odometry.abs_trans_m.mean < 1.0


def test_config_names_the_world_that_was_simulated(tmp_path):
    # A world passed in that is not the config's world: config.toml points at world.json.
    log = simulate(get_world("lab"), None, SimConfig(world="loop"), seed=1)
    paths = write_simulation(log, tmp_path / "a", beam_hits=False)
    config = SimConfig.from_toml(paths["config"])
    assert config.world == str(paths["world"])
    main(["simulate", "--config", str(paths["config"]), "--out", str(tmp_path / "b"), "--quiet"])
    assert filecmp.cmp(paths["log"], tmp_path / "b" / "log.clf", shallow=False)
    # The config's own world: its name is kept.
    log = simulate(get_world("lab"), None, SimConfig(world="lab"), seed=1)
    paths = write_simulation(log, tmp_path / "c", beam_hits=False)
    assert SimConfig.from_toml(paths["config"]).world == "lab"
