"""map.json round trip and bad input; the [map] table of config.toml."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_lines_mapbuilder import POSE_COV, build, make_scans

from slam.config import RunConfig
from slam.errors import ConfigError, DegenerateGeometryError, InputError
from slam.lines.config import MapConfig
from slam.lines.mapio import read_map_json, write_map_json


def test_map_json_round_trip_and_interface_fields(rng, tmp_path):
    m = build(make_scans(rng, 4, POSE_COV), POSE_COV).line_map()
    path = write_map_json(tmp_path / "map.json", m)
    doc = json.loads(path.read_text())
    assert doc["frame"] == "world"
    for item, ln in zip(doc["lines"], m.lines, strict=True):
        assert set(item) >= {"id", "r", "alpha", "cov", "segments", "n_observations"}
        assert item["r"] >= 0 and -np.pi < item["alpha"] <= np.pi
        assert np.shape(item["cov"]) == (2, 2)
        # every segment end lies on the line
        ends = np.asarray(item["segments"]).reshape(-1, 2)
        n = np.array([np.cos(item["alpha"]), np.sin(item["alpha"])])
        np.testing.assert_allclose(ends @ n, item["r"], atol=1e-9)
        assert item["id"] == ln.id
    back = read_map_json(path)
    assert len(back) == len(m)
    for a, b in zip(m.lines, back.lines, strict=True):
        assert (a.id, a.n_observations) == (b.id, b.n_observations)
        np.testing.assert_allclose([a.r, a.alpha, a.s], [b.r, b.alpha, b.s])
        np.testing.assert_allclose(a.cov, b.cov)
        np.testing.assert_allclose(a.segments, b.segments)
    # a minimal file (interface fields only) reads too
    for item in doc["lines"]:
        for key in ("s", "cov_ras", "segments_var"):
            del item[key]
    (tmp_path / "min.json").write_text(json.dumps(doc))
    np.testing.assert_allclose(
        read_map_json(tmp_path / "min.json").lines[0].cov_r_alpha, m.lines[0].cov_r_alpha
    )


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{not json", "not valid JSON"),
        ('{"frame": "world"}', "not a line map"),
        ('{"lines": [{"r": 1, "alpha": 0, "cov": [[1, 0], [0, 1]], "segments": []}]}', "id"),
        (
            '{"lines": [{"id": 1, "r": "x", "alpha": 0, "cov": [[1,0],[0,1]], "segments": []}]}',
            "finite number",
        ),
        (
            '{"lines": [{"id": 1, "r": 1, "alpha": 0, "cov": [[1,0.5],[0,1]],'
            ' "segments": [[[0,0],[1,0]]]}]}',
            "not symmetric",
        ),
    ],
)
def test_bad_map_files_name_the_file(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises((InputError, DegenerateGeometryError), match=match) as info:
        read_map_json(path)
    assert "bad.json" in str(info.value)
    with pytest.raises(InputError, match="no such file"):
        read_map_json(tmp_path / "missing.json")


def test_map_config_toml_round_trip_and_validation(tmp_path):
    cfg = RunConfig(map=MapConfig(max_gap_m=float("inf"), pose_sigma_xy_m=0.1, same_side=False))
    cfg.to_toml(tmp_path / "config.toml")
    assert RunConfig.from_toml(tmp_path / "config.toml") == cfg
    for bad in ({"gate_probability": 1.0}, {"max_gap_m": -1.0}, {"pose_sigma_xy_m": float("nan")}):
        with pytest.raises(ConfigError):
            MapConfig(**bad)  # type: ignore[arg-type]
