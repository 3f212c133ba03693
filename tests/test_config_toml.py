"""Configuration dataclasses: validation and TOML round trip."""

from __future__ import annotations

import pytest

from linefit import ConfigError, LineFitConfig, SensorNoiseConfig


def test_round_trip(tmp_path):
    cfg = LineFitConfig(
        noise=SensorNoiseConfig(sigma_range_m=0.01, sigma_bearing_rad=2e-4),
        grouping="split_merge",
        min_points=7,
        max_range_m=50.0,
    )
    path = tmp_path / "c.toml"
    cfg.to_toml(path)
    assert LineFitConfig.from_toml(path) == cfg
    LineFitConfig().to_toml(path)
    assert LineFitConfig.from_toml(path) == LineFitConfig()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"min_points": 1},
        {"grouping": "ransac"},
        {"noise": SensorNoiseConfig.__new__(SensorNoiseConfig)},
        {"max_range_m": -1.0},
    ],
)
def test_invalid_values_are_rejected(kwargs):
    if "noise" in kwargs:
        with pytest.raises(ConfigError):
            SensorNoiseConfig(sigma_range_m=-0.01)
        return
    with pytest.raises(ConfigError):
        LineFitConfig(**kwargs)


def test_unknown_key_and_bad_type_name_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("min_pointz = 3\n")
    with pytest.raises(ConfigError, match=r"bad\.toml.*min_pointz"):
        LineFitConfig.from_toml(path)
    path.write_text("[noise]\nsigma_range_m = 'five'\n")
    with pytest.raises(ConfigError, match=r"noise\.sigma_range_m"):
        LineFitConfig.from_toml(path)
    path.write_bytes(b"\x00\xff\xfe binary")
    with pytest.raises(ConfigError, match=r"bad\.toml"):
        LineFitConfig.from_toml(path)
