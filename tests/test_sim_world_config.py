"""Worlds (JSON round trip, bad files), named worlds and their paths, SimConfig validation/TOML."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from linefit.errors import ConfigError
from slam.errors import InputError
from slam.geometry import wrap_angle
from slam.sim import (
    WORLD_NAMES,
    LaserConfig,
    LaserNoiseConfig,
    OdometryNoiseConfig,
    RelationsConfig,
    SimConfig,
    TrajectoryConfig,
    cast_scan,
    get_world,
    load_world,
    read_world,
    trajectory_from_waypoints,
    write_world,
)
from slam.sim.relations import relation_pairs


# ---------------------------------------------------------------------------------------------
# Worlds
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", WORLD_NAMES)
def test_world_json_round_trip(tmp_path, name):
    world = get_world(name)
    path = tmp_path / "world.json"
    write_world(world, path)
    again = read_world(path)
    np.testing.assert_array_equal(again.segments, world.segments)
    np.testing.assert_array_equal(again.ids, world.ids)
    np.testing.assert_array_equal(again.waypoints, world.waypoints)
    assert again.labels == world.labels and again.name == name
    assert load_world(str(path)).name == name and load_world(name).name == name


def _segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    a = segments[:, 0]
    e = segments[:, 1] - a
    q = points[:, None, :] - a[None]
    u = np.clip((q * e[None]).sum(-1) / (e * e).sum(-1)[None], 0.0, 1.0)
    return np.linalg.norm(q - u[..., None] * e[None], axis=-1).min(axis=1)


@pytest.mark.parametrize("name", WORLD_NAMES)
def test_default_paths_are_drivable(name):
    """Clear of every wall by 0.4 m, speeds ≤ cruise, yaw rate ≤ limit, headings along the path."""
    world = get_world(name)
    config = TrajectoryConfig()
    traj = trajectory_from_waypoints(world.waypoints, config)
    p = traj.poses_world_base
    assert 150 <= len(traj) <= 600
    assert _segment_distance(p[:, :2], world.segments).min() >= 0.4
    dt = np.diff(traj.timestamps)
    np.testing.assert_allclose(dt, config.scan_period_s, atol=1.5e-6)
    step = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1)
    dtheta = np.asarray(wrap_angle(np.diff(p[:, 2])))
    assert (step <= config.speed_m_s * dt + 1e-9).all()
    assert (np.abs(dtheta) <= config.max_turn_rate_rad_s * dt + 1e-9).all()
    # On straights the heading points along the displacement.
    straight = np.abs(dtheta) < 1e-12
    direction = np.arctan2(np.diff(p[:, 1]), np.diff(p[:, 0]))
    assert np.abs(np.asarray(wrap_angle(direction - p[:-1, 2])))[straight].max() < 1e-9
    np.testing.assert_allclose(p[0, :2], world.waypoints[0], atol=1e-12)
    # Every beam of a scan from the path hits something (closed worlds, no max-range readings).
    bearings = LaserConfig().bearings_rad()
    for pose in p[::10]:
        _, ids = cast_scan(pose, bearings, world, 80.0)
        assert (ids >= 0).all()


def test_corners_turn_on_the_spot_when_there_is_no_room_and_reversals_are_rejected():
    config = TrajectoryConfig(speed_m_s=0.5, scan_spacing_m=0.05, max_turn_rate_rad_s=0.5)
    traj = trajectory_from_waypoints([(0, 0), (1, 0), (1, 1e-4)], config)
    p = traj.poses_world_base
    turning = p[:, 2] > 0
    # Scans every 0.1 s: the 90° turn at 0.5 rad/s takes π s, on the spot at (1, 0).
    assert turning.sum() == int(np.floor((np.pi + 1e-4 / 0.5) / 0.1))
    np.testing.assert_allclose(p[turning, :2], np.tile([1.0, 0.0], (turning.sum(), 1)), atol=1e-4)
    assert (np.diff(p[turning, 2]) > 0).all() and p[-1, 2] <= np.pi / 2
    with pytest.raises(InputError, match="reverses"):
        trajectory_from_waypoints([(0, 0), (2, 0), (1, 0)])
    with pytest.raises(InputError, match="coincide"):
        trajectory_from_waypoints([(0, 0), (0, 0), (1, 0)])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{not json", "not valid JSON"),
        ('{"segments": []}', "non-empty"),
        ('{"segments": [{"p1": [0, 0], "p2": [0, 0]}]}', "zero length"),
        ('{"segments": [{"p1": [0, 0]}]}', "segment 0"),
        ('{"segments": [{"p1": [0, NaN], "p2": [1, 1]}]}', "not finite"),
        (
            '{"segments": [{"id": 1, "p1": [0, 0], "p2": [1, 0]},'
            ' {"id": 1, "p1": [0, 1], "p2": [1, 1]}]}',
            "unique",
        ),
        ('{"segments": [{"id": -3, "p1": [0, 0], "p2": [1, 0]}]}', ">= 0"),
        ('{"segments": [{"id": "a", "p1": [0, 0], "p2": [1, 0]}]}', "integer"),
        ('{"format": "geojson", "segments": []}', "not a lineslam world"),
        ("[1, 2]", "JSON object"),
    ],
)
def test_bad_world_files_name_the_file(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        read_world(path)
    assert str(path) in str(info.value)


def test_binary_missing_and_unknown_worlds(tmp_path):
    binary = tmp_path / "w.json"
    binary.write_bytes(b"\x00\xff\xfe\x00" * 10)
    with pytest.raises(InputError, match="not a text file"):
        read_world(binary)
    with pytest.raises(InputError, match="not found"):
        read_world(tmp_path / "missing.json")
    with pytest.raises(InputError, match="unknown world"):
        load_world("atlantis")


# ---------------------------------------------------------------------------------------------
# Relation pairs
# ---------------------------------------------------------------------------------------------
def test_relation_pairs_follow_the_documented_rules():
    world = get_world("loop")
    traj = trajectory_from_waypoints(world.waypoints)
    p = traj.poses_world_base
    config = RelationsConfig()
    pairs = relation_pairs(p, config, np.random.default_rng(5))
    assert (pairs[:, 0] < pairs[:, 1]).all()
    assert np.unique(pairs, axis=0).shape == pairs.shape
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))])
    path_gap = s[pairs[:, 1]] - s[pairs[:, 0]]
    dist = np.linalg.norm(p[pairs[:, 1], :2] - p[pairs[:, 0], :2], axis=1)
    dtheta = np.abs(np.asarray(wrap_angle(p[pairs[:, 1], 2] - p[pairs[:, 0], 2])))
    revisit = (
        (path_gap >= config.revisit_min_path_m)
        & (dist <= config.revisit_max_distance_m)
        & (dtheta <= np.deg2rad(config.revisit_max_angle_deg))
    )
    assert revisit.sum() >= config.n_revisits  # the loop closes: enough revisits to draw from
    short = np.zeros(len(pairs), bool)
    for d in config.short_distances_m:
        i = pairs[:, 0]
        j = np.searchsorted(s, s[i] + d)
        short |= (j == pairs[:, 1]) & (i % config.short_stride == 0)
    n_short = sum(
        int((np.searchsorted(s, s[::2] + d) < len(s)).sum()) for d in config.short_distances_m
    )
    assert short.sum() == n_short
    assert len(pairs) <= n_short + config.n_revisits + config.n_random
    assert len(pairs) >= n_short + config.n_revisits
    # Seeded: same generator seed, same pairs; another seed, other revisits.
    np.testing.assert_array_equal(pairs, relation_pairs(p, config, np.random.default_rng(5)))
    assert not np.array_equal(pairs, relation_pairs(p, config, np.random.default_rng(6)))


# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------
def test_sim_config_toml_round_trip(tmp_path):
    config = SimConfig(
        world="hallway",
        seed=17,
        laser=LaserConfig.paper(),
        noise=LaserNoiseConfig(sigma_range_m=0.01, sigma_bearing_rad=2e-4, sigma_range_per_m=1e-3),
        odometry=OdometryNoiseConfig(scale_bias=0.01, heading_drift_rad_per_m=-0.001),
        trajectory=TrajectoryConfig(speed_m_s=0.5, scan_spacing_m=0.25),
        relations=RelationsConfig(short_distances_m=(0.5,), n_random=0),
    )
    path = tmp_path / "config.toml"
    config.to_toml(path)
    assert SimConfig.from_toml(path) == config
    assert LaserConfig.paper().bearings_rad().shape == (720,)
    np.testing.assert_allclose(
        np.rad2deg(LaserConfig.paper().bearings_rad()[[0, -1]]), [-90, 89.75]
    )
    assert config.with_sensor_noise(0.02, None).noise.sigma_range_m == 0.02
    assert config.with_sensor_noise(None, 0.0).noise.sigma_bearing_rad == 0.0


@pytest.mark.parametrize(
    "make",
    [
        lambda: LaserConfig(n_beams=0),
        lambda: LaserConfig(step_deg=0.0),
        lambda: LaserConfig(step_deg=float("nan")),
        lambda: LaserConfig(n_beams=721, step_deg=0.5),
        lambda: LaserConfig(max_range_m=-1.0),
        lambda: LaserConfig(max_range_m=float("inf")),
        lambda: LaserConfig(pose_base_laser=(0.0, 0.0)),
        lambda: LaserConfig(range_decimals=0),
        lambda: LaserNoiseConfig(sigma_range_m=-0.001),
        lambda: LaserNoiseConfig(sigma_bearing_rad=float("nan")),
        lambda: LaserNoiseConfig(sigma_bearing_rad=0.1),
        lambda: OdometryNoiseConfig(sigma_trans_per_m=-1.0),
        lambda: OdometryNoiseConfig(scale_bias=0.7),
        lambda: OdometryNoiseConfig(heading_drift_rad_per_m=float("inf")),
        lambda: TrajectoryConfig(speed_m_s=0.0),
        lambda: TrajectoryConfig(scan_spacing_m=-0.3),
        lambda: TrajectoryConfig(max_turn_rate_rad_s=0.0),
        lambda: RelationsConfig(short_stride=0),
        lambda: RelationsConfig(short_distances_m=(1.0, -2.0)),
        lambda: RelationsConfig(n_revisits=-1),
        lambda: SimConfig(seed=-1),
        lambda: SimConfig(world=""),
    ],
)
def test_bad_config_values_are_rejected(make):
    with pytest.raises(ConfigError):
        make()


def test_bad_config_files_are_rejected(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('world = "loop"\n[laser]\nn_beams = 180\nbeams_typo = 3\n')
    with pytest.raises(ConfigError, match="beams_typo"):
        SimConfig.from_toml(path)
    path.write_text("[noise]\nsigma_range_m = -0.1\n")
    with pytest.raises(ConfigError, match="sigma_range_m"):
        SimConfig.from_toml(path)
    path.write_text('[laser]\nn_beams = "many"\n')
    with pytest.raises(ConfigError, match="integer"):
        SimConfig.from_toml(path)
    assert replace(SimConfig(), seed=3).seed == 3


# ---------------------------------------------------------------------------------------------
# Fuzz: any text or bytes as world.json gives an InputError or a valid world, nothing else
# ---------------------------------------------------------------------------------------------

_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=20,
)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    data=st.one_of(
        st.binary(max_size=200),
        st.text(max_size=200).map(str.encode),
        _json_values.map(lambda v: json.dumps({"segments": v}).encode()),
        st.lists(
            st.fixed_dictionaries(
                {
                    "id": st.integers(-2, 3),
                    "p1": st.lists(st.floats(), max_size=3),
                    "p2": st.just([1, 1]),
                }
            ),
            max_size=3,
        ).map(lambda v: json.dumps({"segments": v}).encode()),
    )
)
def test_fuzzed_world_files_give_input_errors(tmp_path, data):
    path = tmp_path / "fuzz.json"
    path.write_bytes(data)
    try:
        world = read_world(path)
    except InputError as exc:
        assert str(path) in str(exc)
    else:
        assert len(world) >= 1 and np.isfinite(world.segments).all()
