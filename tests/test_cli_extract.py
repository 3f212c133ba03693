"""``lineslam extract``: INTERFACES.md output, configuration beside the output, plots, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _synthetic import noisy_scan, room, segment_line_in_sensor

from linefit import wrap_angle
from slam.cli import main
from slam.cli.cmd_extract import config_path_for
from slam.config import RunConfig

POSES = [(0.0, 0.0, 0.0), (-3.0, 2.0, 0.7), (3.5, -2.5, 2.5)]


@pytest.fixture
def sim_log(tmp_path):
    """A small CARMEN log of the simulated room (FLASER, 180 beams over 180°)."""
    world = room()
    bearings = -np.pi / 2 + np.arange(180) * np.pi / 180
    rng = np.random.default_rng(4)
    rows, hits = [], []
    for k, pose in enumerate(POSES):
        ranges, _, hit = noisy_scan(world, np.array(pose), bearings, rng, max_range=50.0)
        hits.append(np.bincount(hit[hit >= 0], minlength=world.n_segments))
        ranges = np.round(ranges, 4)
        t = 1000.0 + 0.1 * k
        p = " ".join(f"{v:.6f}" for v in pose)
        rows.append(
            f"FLASER 180 {' '.join(f'{r:.4f}' for r in ranges)} {p} {p} {t:.6f} sim {t:.6f}"
        )
    path = tmp_path / "room.clf"
    path.write_text("\n".join(rows) + "\n")
    return path, world, hits


def test_extract_writes_one_object_per_scan_and_the_config(sim_log, tmp_path):
    log, world, hits = sim_log
    out = tmp_path / "res" / "lines.jsonl"
    main(["extract", str(log), "--out", str(out), "--quiet", "--sigma-d", "0.006"])
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["scan"] for r in records] == [0, 1, 2]
    assert records[1]["t"] == pytest.approx(1000.1)
    for rec, pose, hit in zip(records, POSES, hits, strict=True):
        assert rec["lines"], "every scan of the room holds lines"
        for ln in rec["lines"]:
            assert set(ln) >= {"r", "alpha", "s", "cov", "endpoints", "n_points"}
            assert ln["r"] >= 0 and -np.pi < ln["alpha"] <= np.pi
            cov = np.array(ln["cov"])
            assert cov.shape == (3, 3) and np.allclose(cov, cov.T)
            assert np.array(ln["endpoints"]).shape == (2, 2)
            assert ln["n_points"] >= RunConfig().linefit.min_points
        # each of the room's walls hit by ≥ 10 beams is there, once
        for k in np.flatnonzero(hit[:4] >= 10):
            r_t, a_t = segment_line_in_sensor(world, int(k), np.array(pose))
            close = [
                ln
                for ln in rec["lines"]
                if abs(ln["r"] - r_t) < 0.05 and abs(wrap_angle(ln["alpha"] - a_t)) < 0.02
            ]
            assert len(close) == 1, (pose, k)
    cfg_path = config_path_for(out)
    assert cfg_path == tmp_path / "res" / "lines.config.toml"
    cfg = RunConfig.from_toml(cfg_path)
    assert cfg.linefit.noise.sigma_range_m == 0.006


def test_extract_plots_and_overrides(sim_log, tmp_path):
    log, _, _ = sim_log
    out = tmp_path / "lines.jsonl"
    plots = tmp_path / "plots"
    main(
        [
            "extract",
            str(log),
            "--out",
            str(out),
            "--plot",
            str(plots),
            "--plot-every",
            "2",
            "--grouping",
            "split_merge",
            "--limit",
            "2",
            "--quiet",
        ]
    )
    assert sorted(p.name for p in plots.iterdir()) == ["scan_000000.png"]
    assert len(out.read_text().splitlines()) == 2
    assert RunConfig.from_toml(config_path_for(out)).linefit.grouping == "split_merge"


def test_extract_bad_log_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.clf"
    bad.write_bytes(b"\x00\x01\x02 not a log")
    with pytest.raises(SystemExit) as exc:
        main(["extract", str(bad), "--out", str(tmp_path / "x.jsonl"), "--quiet"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lineslam: error:") and "bad.clf" in err and "\n" not in err
    with pytest.raises(SystemExit):
        main(["extract", str(tmp_path / "missing.clf"), "--out", str(tmp_path / "y.jsonl")])


@pytest.mark.realdata
def test_extract_intel_head(shared_data, tmp_path, monkeypatch):
    monkeypatch.setenv("LINESLAM_DATA", str(shared_data))
    out = tmp_path / "intel.jsonl"
    main(["extract", "intel", "--out", str(out), "--limit", "200", "--quiet"])
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(records) == 200
    n_lines = [len(r["lines"]) for r in records]
    assert np.mean(n_lines) > 2.0
    # the corridor walls at the start of the log: a line ~1.07 m to the right of the robot
    assert any(abs(ln["r"] - 1.07) < 0.05 for ln in records[0]["lines"])
