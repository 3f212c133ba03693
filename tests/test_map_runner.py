"""The ``lineslam map`` runner on a synthetic corridor (injected fitter), and the CLI end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_lines_mapbuilder import POSE_COV, WALLS, make_scans

from slam.config import RunConfig
from slam.lines.config import MapConfig
from slam.lines.mapio import read_map_json
from slam.mapping import build_map, compression, write_map_results
from slam.types import Scan


def ray_cast(pose: np.ndarray, n_beams: int = 361, max_range: float = 8.0) -> np.ndarray:
    """Ranges of a 180° scan from ``pose`` against the corridor walls (no noise)."""
    phi = np.linspace(-np.pi / 2, np.pi / 2, n_beams) + pose[2]
    d = np.stack([np.cos(phi), np.sin(phi)], -1)
    best = np.full(n_beams, np.inf)
    for pieces in WALLS.values():
        for a, b in pieces:
            a, b = np.asarray(a) - pose[:2], np.asarray(b) - pose[:2]
            e = b - a
            den = d[:, 0] * (-e[1]) - d[:, 1] * (-e[0])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (a[0] * (-e[1]) - a[1] * (-e[0])) / den
                u = (d[:, 0] * a[1] - d[:, 1] * a[0]) / den
            hit = (t > 0) & (u >= 0) & (u <= 1)
            best = np.where(hit & (t < best), t, best)
    return np.where(best < max_range, best, max_range)


def synthetic_scans(rng, n):
    data = make_scans(rng, n, POSE_COV)
    scans = []
    for k, (_, est, _) in enumerate(data):
        scans.append(
            Scan(
                index=k,
                timestamp=float(k),
                ranges=ray_cast(est),
                bearings=np.linspace(-np.pi / 2, np.pi / 2, 361),
                max_range_m=8.0,
                pose_odom_laser=est,
            )
        )
    scans.append(Scan(index=n, timestamp=float(n), ranges=np.ones(3), bearings=np.zeros(3)))
    lines = {k: d[0] for k, d in enumerate(data)}

    def fit(scan, config):
        return lines[scan.index], int(np.count_nonzero(scan.valid_mask()))

    return scans, fit


def test_runner_summary_map_and_figures(rng, tmp_path):
    scans, fit = synthetic_scans(rng, 8)
    # the runner uses one pose covariance for every scan: the one the poses were drawn with
    cfg = RunConfig(map=MapConfig(pose_sigma_xy_m=0.02, pose_sigma_theta_rad=0.003))
    run = build_map(scans, cfg, fit=fit)
    s = run.summary
    assert s["scans"] == 8 and s["scans_without_pose"] == 1
    assert s["points"] == sum(int(np.count_nonzero(sc.valid_mask())) for sc in scans[:8])
    assert s["lines_merged"] == 5 and s["segments_merged"] == 8
    assert s["compression"] == pytest.approx(1 - 2 * 8 / s["points"])
    assert s["compression_lines"] == pytest.approx(compression(s["points"], 5))
    assert s["candidate_pairs_tested"] > 0 and s["fusions"] == s["lines_fit"] - 5
    paths = write_map_results(tmp_path, run, title="synthetic")
    assert json.loads(paths["summary"].read_text())["lines_merged"] == 5
    assert len(read_map_json(paths["map"])) == 5
    assert paths["figure"].stat().st_size > 10_000
    # raw points of the first scan, in the world, lie on the walls (y = ±1, ±1.15 or x = 0/20)
    pts = run.figures.points[0].astype(float)
    on_wall = np.minimum.reduce(
        [
            np.abs(np.abs(pts[:, 1]) - 1.0),
            np.abs(pts[:, 1] - 1.15),
            np.abs(pts[:, 0]),
            np.abs(pts[:, 0] - 20),
        ]
    )
    # the pose is the noisy estimate (σ 2 cm, 0.003 rad): points within a few cm of a wall
    assert np.median(on_wall) < 0.05


def write_flaser_log(path, rng, n_poses=8):
    """A CARMEN log (FLASER, 361 beams over 180°) of the corridor, with the paper's noise."""
    data = make_scans(rng, n_poses, np.zeros((3, 3)))
    rows = []
    for k, (_, pose, _) in enumerate(data):
        ranges = ray_cast(pose, max_range=80.0)
        hit = ranges < 80.0
        ranges[hit] += rng.normal(0, 0.005, hit.sum())
        vals = " ".join(f"{r:.4f}" for r in ranges)
        p = " ".join(f"{v:.6f}" for v in pose)
        rows.append(f"FLASER 361 {vals} {p} {p} {1000.0 + k:.6f} nohost {1000.0 + k:.6f}")
    path.write_text("\n".join(rows) + "\n")
    return path


def test_cli_map_end_to_end(rng, tmp_path):
    import linefit

    pytest.importorskip("slam.io.carmen")
    if not hasattr(linefit, "extract_lines"):
        pytest.skip("linefit.extract_lines not merged yet")
    from slam.cli import main

    log = write_flaser_log(tmp_path / "corridor.clf", rng)
    out = tmp_path / "out"
    main(
        [
            "map",
            str(log),
            "--out",
            str(out),
            "--quiet",
            "--pose-sigma-xy",
            "0.01",
            "--pose-sigma-theta",
            "0.002",
        ]
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scans"] == 8 and summary["frame"] == "laser"
    assert summary["lines_merged"] < summary["lines_fit"]
    assert summary["compression"] > 0.98
    assert (out / "config.toml").is_file() and (out / "figures" / "map_panels.png").is_file()
    cfg = RunConfig.from_toml(out / "config.toml")
    assert cfg.map.pose_sigma_xy_m == 0.01
    m = read_map_json(out / "map.json")
    # the long walls are found with their door gaps: y = -1 (3 pieces), y = +1 (2 pieces)
    lower = [
        ln
        for ln in m.lines
        if abs(ln.r - 1.0) < 0.03 and abs(abs(ln.alpha) - np.pi / 2) < 0.01 and ln.length > 10
    ]
    assert any(ln.segments.shape[0] >= 2 for ln in lower)
    # bad input: a binary file gives a one-line error and exit status 2
    bad = tmp_path / "bad.clf"
    bad.write_bytes(b"\x00\x01\x02garbage")
    with pytest.raises(SystemExit) as info:
        main(["map", str(bad), "--out", str(tmp_path / "o2"), "--quiet"])
    assert info.value.code == 2
