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


def test_round_trip_of_every_extraction_setting(tmp_path):
    cfg = LineFitConfig(
        noise=SensorNoiseConfig(sigma_range_per_m=0.001, bearing_error="reading"),
        alpha_update="prop2",
        hough_angle_step_rad=0.02,
        hough_recover=False,
        merge_collinear=False,
        max_missing_beams=0,
        outlier_chi2=6.63,
    )
    path = tmp_path / "c.toml"
    cfg.to_toml(path)
    assert LineFitConfig.from_toml(path) == cfg


@pytest.mark.parametrize(
    "kwargs",
    [
        {"alpha_update": "newton"},
        {"hough_angle_step_rad": 0.0},
        {"hough_angle_step_rad": 1.0},
        {"hough_range_step_m": -0.1},
        {"outlier_chi2": float("nan")},
        {"breakpoint_lambda_rad": 2.0},
        {"max_refits": -1},
        {"min_segment_points": 0},
        {"hough_min_votes": 1},
        {"merge_chi2": 0.0},
        {"weighted": 1},
        {"max_iterations": 2.5},
    ],
)
def test_invalid_extraction_settings_are_rejected(kwargs):
    with pytest.raises(ConfigError):
        LineFitConfig(**kwargs)


def test_sensor_noise_override_keeps_the_bearing_error_model():
    from slam.config import RunConfig

    run = RunConfig(
        linefit=LineFitConfig(noise=SensorNoiseConfig(bearing_error="reading"))
    ).with_sensor_noise(0.02, None)
    assert run.linefit.noise.bearing_error == "reading"
    assert run.linefit.noise.sigma_range_m == 0.02
    with pytest.raises(ConfigError):
        SensorNoiseConfig(bearing_error="both")


def test_a_renamed_key_names_its_replacement(tmp_path):
    from slam.config import RunConfig

    path = tmp_path / "old.toml"
    path.write_text("[slam.isam2]\nrelinearize_threshold = 0.02\n")
    with pytest.raises(
        ConfigError, match=r"old\.toml.*relinearize_threshold: split into .*_m and "
    ):
        RunConfig.from_toml(path)
    path.write_text("[slam.loop_closure]\nmax_chi2_per_factor = 6.0\n")
    with pytest.raises(ConfigError, match=r"max_chi2_per_factor: removed .*delete the line"):
        RunConfig.from_toml(path)
    path.write_text(
        "[slam.isam2]\nrelinearize_threshold_m = 0.02\nrelinearize_threshold_rad = 0.02\n"
    )
    isam2 = RunConfig.from_toml(path).slam.isam2
    assert (isam2.relinearize_threshold_m, isam2.relinearize_threshold_rad) == (0.02, 0.02)
