"""lineslam export (occupancy grid, GeoJSON, SVG, g2o, TUM) read back with real readers;
evaluate on partial runs; compare --relations; warnings counted; one set of world names."""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from slam.cli import main
from slam.io import read_tum

DEMO = REPO_ROOT / "datasets" / "sim" / "demo"
DEMO_LOG = DEMO / "log.clf"


def run(argv: list[str]) -> int:
    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("demo") / "run"
    assert run(["slam", str(DEMO_LOG), "--out", str(out), "--max-scans", "150", "--quiet"]) == 0
    return out


def test_occupancy_grid_is_a_map_server_map_with_the_walls_occupied(demo_run, tmp_path):
    from PIL import Image

    yaml = pytest.importorskip("yaml")
    assert (
        run(
            [
                "export",
                str(demo_run),
                "--format",
                "occupancy",
                "--out",
                str(tmp_path / "m"),
                "--resolution",
                "0.1",
                "--quiet",
            ]
        )
        == 0
    )
    meta = yaml.safe_load((tmp_path / "m.yaml").read_text())
    assert set(meta) == {
        "image",
        "resolution",
        "origin",
        "negate",
        "occupied_thresh",
        "free_thresh",
    }
    assert meta["image"] == "m.pgm" and meta["resolution"] == 0.1 and meta["negate"] == 0
    image = np.asarray(Image.open(tmp_path / meta["image"]))
    assert image.dtype == np.uint8 and set(np.unique(image)) <= {0, 205, 254}
    rows = image.shape[0]

    def pixel(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        col = np.floor((xy[:, 0] - meta["origin"][0]) / meta["resolution"]).astype(int)
        row = rows - 1 - np.floor((xy[:, 1] - meta["origin"][1]) / meta["resolution"]).astype(int)
        return row, col

    # the robot's path is free; the true walls it saw are occupied (the demo's odometry, and so
    # the run's world frame, starts at the true first pose)
    traj = read_tum(demo_run / "trajectory.tum").poses
    np.testing.assert_allclose(traj[0], read_tum(DEMO / "ground_truth.tum").poses[0], atol=1e-6)
    r, c = pixel(traj[:, :2])
    assert np.mean(image[r, c] == 254) > 0.95
    world = json.loads((DEMO / "world.json").read_text())
    pts = [
        np.array(seg["p1"]) + t * (np.array(seg["p2"]) - np.array(seg["p1"]))
        for seg in world["segments"]
        for t in np.linspace(0, 1, 50)
    ]
    r, c = pixel(np.array(pts))
    inside = (r >= 0) & (r < rows) & (c >= 0) & (c < image.shape[1])
    seen = image[r[inside], c[inside]] != 205
    near_wall = image[r[inside], c[inside]][seen]
    assert seen.sum() > 200 and np.mean(near_wall == 0) > 0.6


def test_geojson_svg_tum_and_g2o_exports(demo_run, tmp_path):
    geojson = pytest.importorskip("geojson")
    gtsam = pytest.importorskip("gtsam")
    lines = json.loads((demo_run / "map.json").read_text())["lines"]
    n_segments = sum(len(line["segments"]) for line in lines)

    assert (
        run(
            [
                "export",
                str(demo_run),
                "--format",
                "geojson",
                "--out",
                str(tmp_path / "m.geojson"),
                "--quiet",
            ]
        )
        == 0
    )
    doc = geojson.loads((tmp_path / "m.geojson").read_text())
    assert doc.is_valid and len(doc["features"]) == len(lines)

    assert (
        run(
            [
                "export",
                str(demo_run),
                "--format",
                "svg",
                "--out",
                str(tmp_path / "m.svg"),
                "--quiet",
            ]
        )
        == 0
    )
    root = ET.parse(tmp_path / "m.svg").getroot()
    ns = {"s": "http://www.w3.org/2000/svg"}
    assert len(root.findall(".//s:line", ns)) == n_segments
    assert root.find(".//s:polyline[@id='trajectory']", ns) is not None

    assert (
        run(
            [
                "export",
                str(demo_run),
                "--format",
                "tum",
                "--out",
                str(tmp_path / "t.tum"),
                "--quiet",
            ]
        )
        == 0
    )
    assert read_tum(tmp_path / "t.tum").timestamps.shape == (150,)

    assert (
        run(
            [
                "export",
                str(demo_run),
                "--format",
                "g2o",
                "--out",
                str(tmp_path / "g.g2o"),
                "--quiet",
            ]
        )
        == 0
    )
    graph, values = gtsam.readG2o(str(tmp_path / "g.g2o"), False)
    summary = json.loads((demo_run / "summary.json").read_text())
    assert values.size() == summary["keyframes"]
    assert graph.size() >= summary["keyframes"] - 1  # the odometry chain (and more)
    from slam.io.g2o import read_line_graph_g2o

    back = read_line_graph_g2o(tmp_path / "g.g2o")
    traj = read_tum(demo_run / "trajectory.tum")
    kf = np.isin(traj.timestamps, back.timestamps)
    np.testing.assert_allclose(back.pose_graph.poses[:, :2], traj.poses[kf, :2], atol=1e-6)
    assert back.factor_z.shape[0] > 5 * back.lines_r_alpha.shape[0] > 0
    assert set(back.factor_line) <= set(back.line_ids)
    pose0 = values.atPose2(0)
    np.testing.assert_allclose([pose0.x(), pose0.y()], back.pose_graph.poses[0, :2], atol=1e-9)

    ekf = tmp_path / "ekf"
    assert run(["ekf", str(DEMO_LOG), "--out", str(ekf), "--max-scans", "20", "--quiet"]) == 0
    assert run(["export", str(ekf), "--format", "g2o", "--out", str(tmp_path / "e.g2o")]) == 2


def test_export_is_whole_or_not_at_all_and_refuses_bad_targets(demo_run, tmp_path, capsys):
    """A failed export leaves an earlier file as it was and no temporary file; an --out that is
    a folder or one of the files the export reads is refused in one line, status 2."""
    earlier = tmp_path / "map.g2o"
    earlier.write_text("earlier\n")
    no_graph = tmp_path / "no-graph"
    no_graph.mkdir()
    (no_graph / "map.json").write_text((demo_run / "map.json").read_text())
    assert run(["export", str(no_graph), "--format", "g2o", "--out", str(earlier)]) == 2
    assert earlier.read_text() == "earlier\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.g2o", "no-graph"]
    capsys.readouterr()
    trajectory = demo_run / "trajectory.tum"
    before = trajectory.read_bytes()
    for fmt, out in (("tum", trajectory), ("svg", tmp_path), ("geojson", "")):
        assert run(["export", str(demo_run), "--format", fmt, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("lineslam: error: ") and err.count("\n") == 1, err
    assert trajectory.read_bytes() == before
    assert run(["export", str(demo_run), "--format", "tum", "--out", str(earlier)]) == 0
    assert earlier.read_bytes() == before


def test_evaluate_scores_a_partial_run_on_the_relations_inside_it(demo_run, tmp_path, capsys):
    assert json.loads((demo_run / "summary.json").read_text())["partial"] is True
    rel = DEMO / "relations.txt"
    assert run(["evaluate", str(demo_run), "--relations", str(rel)]) == 0
    assert "lie inside it" in capsys.readouterr().out
    metrics = json.loads((demo_run / "metrics.json").read_text())
    total = sum(1 for line in rel.read_text().splitlines() if line and line[0] != "#")
    inside = metrics["partial_run"]["relations_inside_run"]
    assert 0 < inside < total and metrics["partial_run"]["relations_in_file"] == total
    assert metrics["relations"]["n_used"] == inside
    # forced complete: the strict check calls the missing relations a time stamp mistake
    assert run(["evaluate", str(demo_run), "--relations", str(rel), "--complete"]) == 2


def test_compare_takes_relations_and_ground_truth_for_any_log(tmp_path, capsys):
    log = tmp_path / "mine.clf"  # no relations.txt beside it
    shutil.copyfile(DEMO_LOG, log)
    base = ["compare", str(log), "--variants", "odometry", "--workers", "1", "--no-figures"]
    base += ["--max-scans", "100", "--quiet"]
    assert run([*base, "--out", str(tmp_path / "none")]) == 0
    assert "no relations or ground truth" in capsys.readouterr().err
    args = [
        "--relations",
        str(DEMO / "relations.txt"),
        "--ground-truth",
        str(DEMO / "ground_truth.tum"),
    ]
    assert run([*base, "--out", str(tmp_path / "with"), *args]) == 0
    report = json.loads((tmp_path / "with" / "report.json").read_text())
    text = json.dumps(report)
    assert "relations_used" in text and "ate" in text.lower()


def test_compare_and_simulate_share_the_world_names(tmp_path):
    from slam.experiments.linesim import sim_world_names, world_and_trajectory
    from slam.experiments.variants import parse_source

    for name in ("loop", "hallway", "lab", "corridor_loop", "grid2x2"):
        world, truth = world_and_trajectory(name)
        assert world.walls.shape[0] > 3 and truth.shape[0] > 10
        assert parse_source(f"sim:{name}").name == name
    assert {"loop", "corridor_loop"} <= set(sim_world_names())
    out = tmp_path / "sim"
    assert run(["simulate", "corridor_loop", "--out", str(out), "--quiet"]) == 0
    assert (out / "log.clf").is_file()


def test_warnings_are_counted_not_printed_with_source_lines(tmp_path, capfd):
    # the demo log without the PARAM lines that state its beam layout: CARMEN's rule, said
    log = tmp_path / "plain.clf"
    lines = DEMO_LOG.read_text().splitlines(keepends=True)
    log.write_text("".join(line for line in lines if not line.startswith("PARAM")))
    out = tmp_path / "run"
    assert run(["slam", str(log), "--out", str(out), "--max-scans", "30", "--quiet"]) == 0
    err = capfd.readouterr().err
    assert "1 x InputWarning: " in err and "warnings.warn" not in err
    summary = json.loads((out / "summary.json").read_text())
    (item,) = [w for w in summary["warnings"] if w["category"] == "InputWarning"]
    assert item["count"] == 1 and "CARMEN's rule" in item["message"]


def test_occupancy_of_one_beam_is_a_free_ray_and_an_occupied_end():
    from slam.io.occupancy import FREE, OCCUPIED, UNKNOWN, occupancy_grid
    from slam.types import Scan

    # four looks: log-odds with P_MISS = 0.4 call a cell free after four misses (p = 0.165)
    scan = Scan(0, 0.0, np.array([2.0, 90.0]), np.array([0.0, 0.5]), max_range_m=80.0)
    poses = np.tile([0.05, 0.05, 0.0], (4, 1))
    grid = occupancy_grid(poses, [scan] * 4, resolution_m=0.1, margin_m=0.5)
    image = grid.image()[::-1]  # row 0 at the bottom again
    row, col = grid.cell_of(np.array([[1.0, 0.05], [2.05, 0.05], [0.05, 0.5]]))
    assert image[row[0], col[0]] == FREE and image[row[1], col[1]] == OCCUPIED
    assert image[row[2], col[2]] == UNKNOWN  # the no-return beam marks nothing
    assert grid.misses.sum() == 4 * 20 and grid.hits.sum() == 4  # 20 cells before the end
