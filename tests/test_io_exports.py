"""g2o (read back with gtsam.readG2o), GeoJSON, results folders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from slam.errors import InputError, LogFormatError
from slam.geometry import pose_between, wrap_angle
from slam.io.g2o import odometry_pose_graph, read_g2o, write_g2o
from slam.io.geojson import line_map_to_geojson, write_geojson
from slam.io.results import read_results, write_metrics, write_results


def random_walk(rng, n):
    steps = np.column_stack([rng.uniform(0, 0.5, n), rng.normal(0, 0.05, n), rng.normal(0, 0.2, n)])
    poses = np.zeros((n, 3))
    for k in range(1, n):
        c, s = np.cos(poses[k - 1, 2]), np.sin(poses[k - 1, 2])
        poses[k] = poses[k - 1] + [
            c * steps[k, 0] - s * steps[k, 1],
            s * steps[k, 0] + c * steps[k, 1],
            0,
        ]
        poses[k, 2] = wrap_angle(poses[k - 1, 2] + steps[k, 2])
    return poses


def random_information(rng, m):
    a = rng.normal(0, 1, (m, 3, 3))
    return a @ np.swapaxes(a, 1, 2) + 3 * np.eye(3)


def test_g2o_round_trip_through_gtsam(tmp_path, rng):
    gtsam = pytest.importorskip("gtsam")
    poses = random_walk(rng, 40)
    info = random_information(rng, 39)
    graph = odometry_pose_graph(poses, info)
    path = tmp_path / "odom.g2o"
    write_g2o(path, graph)
    factors, values = gtsam.readG2o(str(path), False)
    assert values.size() == 40
    for k in range(40):
        p = values.atPose2(k)
        np.testing.assert_allclose([p.x(), p.y(), p.theta()], poses[k], atol=1e-8)
    between = [
        factors.at(i)
        for i in range(factors.size())
        if isinstance(factors.at(i), gtsam.BetweenFactorPose2)
    ]
    assert len(between) == 39
    for f in between:
        i, j = f.keys()
        m = f.measured()
        np.testing.assert_allclose(
            [m.x(), m.y(), m.theta()], pose_between(poses[i], poses[j]), atol=1e-8
        )
        R = f.noiseModel().R()
        np.testing.assert_allclose(R.T @ R, info[i], rtol=1e-7)
    # and our own reader
    back = read_g2o(path)
    np.testing.assert_allclose(back.information, info, rtol=1e-8)
    np.testing.assert_allclose(back.measurements, graph.measurements, atol=1e-9)
    assert back.fixed == (0,)


def test_g2o_bad_input(tmp_path):
    path = tmp_path / "bad.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0\n")
    with pytest.raises(LogFormatError, match=r"bad\.g2o:2: .*EDGE_SE2"):
        read_g2o(path)
    path.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n")
    with pytest.raises(LogFormatError, match="vertex id that is not in the graph"):
        read_g2o(path)
    with pytest.raises(InputError, match="symmetric"):
        odometry_pose_graph(np.zeros((3, 3)), np.array([[1, 2, 0], [0, 1, 0], [0, 0, 1.0]]))


MAP = {
    "frame": "world",
    "lines": [
        {
            "id": 3,
            "r": 4.2,
            "alpha": 1.57,
            "cov": [[1e-4, 0], [0, 1e-5]],
            "segments": [[[0, 4.2], [2, 4.2]], [[3, 4.2], [5, 4.2]]],
            "n_observations": 12,
        },
        {"id": 7, "r": 1.0, "alpha": 0.0, "segments": [[[1, -1], [1, 1]]]},
    ],
}


def test_geojson_of_a_map(tmp_path):
    fc = line_map_to_geojson(MAP)
    assert fc["type"] == "FeatureCollection" and len(fc["features"]) == 2
    first = fc["features"][0]
    assert first["geometry"]["type"] == "MultiLineString"
    assert first["geometry"]["coordinates"] == MAP["lines"][0]["segments"]
    assert first["properties"]["n_observations"] == 12 and first["id"] == 3
    assert line_map_to_geojson(MAP["lines"])["features"][1]["properties"]["r"] == 1.0
    path = tmp_path / "map.geojson"
    write_geojson(path, MAP)
    assert json.loads(path.read_text()) == fc
    bad = {"lines": [{"id": 1, "r": 1.0, "alpha": 0.0, "segments": [[[0, 0], [1, float("nan")]]]}]}
    with pytest.raises(InputError, match="line 1: segment end points must be finite"):
        line_map_to_geojson(bad)
    with pytest.raises(InputError, match="missing 'segments'"):
        line_map_to_geojson([{"id": 2, "r": 1.0, "alpha": 0.0}])


def test_results_folder_round_trip(tmp_path, rng):
    poses = random_walk(rng, 30)
    stamps = np.round(1000.0 + np.arange(30) * 0.1, 6)
    cov = random_information(rng, 30) * 1e-3
    out = write_results(
        tmp_path / "run",
        stamps,
        poses,
        {"scans": 30, "runtime_s": {"all": np.float64(1.5)}},
        covariances=cov,
    )
    res = read_results(out)
    np.testing.assert_array_equal(res.trajectory.timestamps, stamps)
    np.testing.assert_allclose(res.trajectory.poses, poses, atol=1e-8)
    np.testing.assert_allclose(res.covariances, cov, rtol=1e-8)
    assert res.frame == "laser" and res.summary["scans"] == 30
    assert res.summary["runtime_s"]["all"] == 1.5
    path = write_metrics(out, {"ate": {"rmse_m": np.float64(0.1), "bad": float("nan")}})
    assert json.loads(path.read_text()) == {"ate": {"rmse_m": 0.1, "bad": None}}
    with pytest.raises(InputError, match=r"no trajectory\.tum"):
        read_results(tmp_path)
    (out / "summary.json").write_text("{not json")
    with pytest.raises(LogFormatError, match="not valid JSON"):
        read_results(out)
