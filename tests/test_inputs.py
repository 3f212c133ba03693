"""slam.inputs: a log's geometry, mounting and frame; bags through the command line."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from carmen_lines import flaser, odom
from conftest import REPO_ROOT

from slam.cli import main
from slam.config import RunConfig
from slam.errors import ConfigError, LogFormatError
from slam.geometry import pose_compose, pose_inverse
from slam.inputs import InputWarning, ScannerConfig, open_log
from slam.io import iter_scans, read_tum

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
MOUNT = np.array([0.2, 0.05, 0.1])  # (m, m, rad)


def write_log(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def mounted_log(path: Path, mount: np.ndarray, n: int = 20, jitter: float = 0.0) -> Path:
    """FLASER lines whose laser pose is the odometry pose composed with ``mount``."""
    rng = np.random.default_rng(1)
    lines = []
    for k in range(n):
        base = np.array([0.3 * k, 0.1 * k, 0.05 * k])
        m = mount + (rng.normal(0, jitter, 3) if jitter else 0.0)
        laser = pose_compose(base, m)
        lines += [odom(base, k + 0.0), flaser(np.full(180, 3.0), laser, base, k + 0.5)]
    return write_log(path, lines)


# -- geometry ----------------------------------------------------------------------------------


def test_carmen_rule_is_announced_and_a_stated_step_replaces_it(tmp_path):
    log = write_log(tmp_path / "ninety.clf", [flaser(np.full(90, 2.0), [0, 0, 0], [0, 0, 0], 1.0)])
    with pytest.warns(InputWarning, match="CARMEN's rule for 90 beams .* step 2.022"):
        guessed = open_log(log)
    (scan,) = guessed.scans()
    assert np.diff(scan.bearings)[0] == pytest.approx(math.pi / 89)
    assert guessed.describe()["geometry"]["source"] == "carmen-rule"
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        stated = open_log(log, ScannerConfig(step_deg=2.0, max_range_m=40.0, min_range_m=0.5))
        (scan,) = stated.scans()
    np.testing.assert_allclose(np.diff(scan.bearings), math.radians(2.0))
    assert scan.bearings[0] == pytest.approx(-math.pi / 2) and scan.max_range_m == 40.0
    described = stated.describe()["geometry"]
    assert described["source"] == "config" and described["step_deg"] == pytest.approx(2.0)
    fov = open_log(log, ScannerConfig(fov_deg=178.0))
    (scan,) = fov.scans()
    assert scan.bearings[0] == pytest.approx(math.radians(-89.0))
    assert scan.bearings[-1] == pytest.approx(math.radians(89.0))
    with pytest.raises(LogFormatError, match="has 90 beams, \\[scanner\\] beams = 180"):
        list(open_log(log, ScannerConfig(beams=180, step_deg=1.0)).scans())


def test_min_range_marks_near_readings_as_no_measurement(tmp_path):
    ranges = np.full(180, 2.0)
    ranges[:10] = 0.1
    log = write_log(tmp_path / "near.clf", [flaser(ranges, [0, 0, 0], [0, 0, 0], 1.0)])
    (scan,) = open_log(log, ScannerConfig(min_range_m=0.15)).scans()
    assert not scan.valid_mask()[:10].any() and scan.valid_mask()[10:].all()


def test_scanner_config_validation():
    with pytest.raises(ConfigError, match="step_deg or fov_deg"):
        ScannerConfig(step_deg=1.0, fov_deg=180.0)
    with pytest.raises(ConfigError, match="min_range_m must be below"):
        ScannerConfig(min_range_m=5.0, max_range_m=2.0)
    with pytest.raises(ConfigError, match="output_frame"):
        ScannerConfig(output_frame="robot")  # type: ignore[arg-type]


# -- mounting ----------------------------------------------------------------------------------


def test_mounting_is_read_from_the_logs_laser_and_odometry_poses(tmp_path):
    log = mounted_log(tmp_path / "mounted.clf", MOUNT)
    opened = open_log(log)
    assert opened.mount_source == "log"
    np.testing.assert_allclose(opened.policy.pose_base_laser, MOUNT, atol=1e-6)
    assert opened.policy.output_frame == "base" and opened.policy.laser_odometry == "logged"
    # a stated mounting overrides the log's; the laser odometry is then base ∘ stated
    stated = open_log(log, ScannerConfig(pose_base_laser=(0.5, 0.0, 0.0)))
    assert stated.mount_source == "config" and stated.policy.laser_odometry == "base"
    assert stated.policy.pose_base_laser == (0.5, 0.0, 0.0)
    # an offset that varies over the log is no mounting: said, and the laser frame reported
    with pytest.warns(InputWarning, match="varies over the log"):
        varying = open_log(mounted_log(tmp_path / "varying.clf", MOUNT, jitter=0.05))
    assert varying.mount_source == "none" and varying.policy.output_frame == "laser"


def test_slam_reports_the_robot_centre_of_a_log_with_a_mounted_laser(tmp_path):
    """The demo log rewritten with the laser 0.2 m ahead of the robot centre (FLASER laser pose
    unchanged, odometry moved to the centre): the same laser estimate, reported for the centre."""
    centre = np.array([-0.2, 0.0, 0.0])
    lines_out = []
    for line in DEMO_LOG.read_text().splitlines():
        tok = line.split()
        if tok and tok[0] == "FLASER":
            n = int(tok[1])
            laser = np.array([float(v) for v in tok[n + 2 : n + 5]])
            tok[n + 5 : n + 8] = [f"{v:.9f}" for v in pose_compose(laser, centre)]
        elif tok and tok[0] == "ODOM":
            pose = np.array([float(v) for v in tok[1:4]])
            tok[1:4] = [f"{v:.9f}" for v in pose_compose(pose, centre)]
        lines_out.append(" ".join(tok))
    variant = write_log(tmp_path / "variant.clf", lines_out)
    n = 80
    main(["slam", str(DEMO_LOG), "--out", str(tmp_path / "a"), "--max-scans", str(n), "--quiet"])
    main(["slam", str(variant), "--out", str(tmp_path / "b"), "--max-scans", str(n), "--quiet"])
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["frame"] == "base" and summary["input"]["mount_source"] == "log"
    np.testing.assert_allclose(summary["input"]["pose_base_laser"], [0.2, 0, 0], atol=1e-6)
    laser = read_tum(tmp_path / "a" / "trajectory.tum").poses  # demo: laser = base
    centre_est = read_tum(tmp_path / "b" / "trajectory.tum").poses
    np.testing.assert_allclose(
        centre_est[:, :2],
        pose_compose(laser, np.broadcast_to(centre, laser.shape))[:, :2],
        atol=1e-5,
    )


# -- configuration files -----------------------------------------------------------------------


def test_an_older_config_with_input_keys_in_slam_is_migrated(tmp_path):
    RunConfig().to_toml(tmp_path / "new.toml")
    text = (tmp_path / "new.toml").read_text()
    start = text.index("[scanner]")
    text = text[:start] + text[text.index("[linefit]") :]  # the older files had no [scanner]
    old = text.replace(
        "[slam]\n",
        '[slam]\npose_base_laser = [0.04, 0.0, 0.0]\nmount_source = "config"\n'
        'laser_odometry = "logged"\noutput_frame = "laser"\nodometry_sign = "logged"\n',
        1,
    )
    (tmp_path / "old.toml").write_text(old)
    scanner = RunConfig.from_toml(tmp_path / "old.toml").scanner
    assert scanner.pose_base_laser == (0.04, 0.0, 0.0) and scanner.mount_source == "config"
    assert scanner.odometry_sign == "logged"
    # the old defaults give the new defaults
    assert scanner.laser_odometry == "auto" and scanner.output_frame == "auto"
    both = old + '\n[scanner]\nodometry_sign = "velocity"\n'
    (tmp_path / "both.toml").write_text(both)
    with pytest.raises(ConfigError, match="odometry_sign is given in \\[slam\\]"):
        RunConfig.from_toml(tmp_path / "both.toml")


def test_cli_scanner_options_reach_config_toml(tmp_path):
    out = tmp_path / "lines.jsonl"
    code = _run(
        ["extract", str(DEMO_LOG), "--out", str(out), "--limit", "3", "--quiet"]
        + ["--step", "1", "--max-range", "30", "--mount", "0.1,0,90", "--frame", "laser"]
    )
    assert code == 0
    scanner = RunConfig.from_toml(tmp_path / "lines.config.toml").scanner
    assert scanner.step_deg == 1.0 and scanner.max_range_m == 30.0
    np.testing.assert_allclose(scanner.pose_base_laser, [0.1, 0.0, math.pi / 2])
    assert scanner.output_frame == "laser"
    assert _run(["slam", str(DEMO_LOG), "--out", str(tmp_path / "x"), "--mount", "1,2"]) == 2


def _run(argv: list[str]) -> int:
    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


# -- ROS bags ----------------------------------------------------------------------------------


def write_demo_bag(
    path: Path,
    version: int,
    mount: np.ndarray,
    n: int,
    tf_odometry: bool,
    odometry: bool = True,
) -> None:
    """The first ``n`` scans of the demo log as a bag: scans in frame ``laser``, the odometry of
    the base (the logged laser pose ∘ mount⁻¹) on ``/odom`` or ``/tf`` (none without
    ``odometry``), the mount on ``/tf_static``."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:  # not in rosbags' ROS 1 store
        from rosbags.typesys import get_types_from_msg

        store.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    T = store.types
    ros1 = "seq" in T["std_msgs/msg/Header"].__dataclass_fields__

    def header(t: float, frame: str):  # type: ignore[no-untyped-def]
        sec = int(t)
        stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9))
        kw = {"seq": 0} if ros1 else {}
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame, **kw)

    def quat(yaw: float):  # type: ignore[no-untyped-def]
        return T["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        )

    def transform(t: float, parent: str, child: str, pose: np.ndarray):  # type: ignore[no-untyped-def]
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=pose[0], y=pose[1], z=0.0),
                rotation=quat(pose[2]),
            ),
        )

    scans = [s for _, s in zip(range(n), iter_scans(DEMO_LOG), strict=False)]
    inv = pose_inverse(mount)
    items = []
    t0 = scans[0].timestamp
    items.append(
        (
            t0 - 0.01,
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            T["tf2_msgs/msg/TFMessage"](transforms=[transform(t0, "base_link", "laser", mount)]),
        )
    )
    for s in scans:
        base = pose_compose(np.asarray(s.pose_odom_laser), inv)
        items.append(
            (
                s.timestamp,
                "/scan",
                "sensor_msgs/msg/LaserScan",
                T["sensor_msgs/msg/LaserScan"](
                    header=header(s.timestamp, "laser"),
                    angle_min=np.float32(s.bearings[0]),
                    angle_max=np.float32(s.bearings[-1]),
                    angle_increment=np.float32(s.bearings[1] - s.bearings[0]),
                    time_increment=np.float32(0),
                    scan_time=np.float32(0),
                    range_min=np.float32(0.0),
                    range_max=np.float32(s.max_range_m),
                    ranges=s.ranges.astype(np.float32),
                    intensities=np.zeros(0, np.float32),
                ),
            )
        )
        if not odometry:
            continue
        if tf_odometry:
            msg = T["tf2_msgs/msg/TFMessage"](
                transforms=[transform(s.timestamp, "odom", "base_link", base)]
            )
            items.append((s.timestamp, "/tf", "tf2_msgs/msg/TFMessage", msg))
        else:
            V3 = T["geometry_msgs/msg/Vector3"]
            msg = T["nav_msgs/msg/Odometry"](
                header=header(s.timestamp, "odom"),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=base[0], y=base[1], z=0.0),
                        orientation=quat(base[2]),
                    ),
                    covariance=np.zeros(36),
                ),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](
                        linear=V3(x=0.0, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)
                    ),
                    covariance=np.zeros(36),
                ),
            )
            items.append((s.timestamp, "/odom", "nav_msgs/msg/Odometry", msg))
    if version == 1:
        from rosbags.rosbag1 import Writer

        writer, serialize = Writer(path), store.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer

        writer, serialize = Writer(path, version=9), store.serialize_cdr
    with writer:
        conns = {}
        for _, topic, kind, _ in items:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, kind, typestore=store)
        for t, topic, kind, msg in sorted(items, key=lambda x: x[0]):
            writer.write(conns[topic], int(t * 1e9), serialize(msg, kind))


@pytest.mark.parametrize(("version", "tf_odometry"), [(1, False), (2, True)])
def test_slam_on_a_bag_reads_the_mounting_from_tf_static(tmp_path, version, tf_odometry):
    pytest.importorskip("rosbags")
    n = 60
    bag = tmp_path / ("run.bag" if version == 1 else "run_bag")
    write_demo_bag(bag, version, MOUNT, n, tf_odometry)
    out = tmp_path / "bag"
    args = ["slam", str(bag), "--out", str(out), "--quiet"]
    assert _run(args + (["--odometry", "tf"] if tf_odometry else [])) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frame"] == "base" and summary["input"]["format"] == "rosbag"
    assert summary["input"]["mount_source"] == "tf" and summary["scans"] == n
    np.testing.assert_allclose(summary["input"]["pose_base_laser"], MOUNT, atol=1e-6)
    assert summary["input"]["odometry"] == (
        "tf odom -> base_link" if tf_odometry else "topic /odom"
    )
    # the same laser estimate as from the CARMEN log: base poses ∘ mount = the laser poses
    ref = tmp_path / "carmen"
    main(["slam", str(DEMO_LOG), "--out", str(ref), "--max-scans", str(n), "--quiet"])
    laser = read_tum(ref / "trajectory.tum").poses
    base = read_tum(out / "trajectory.tum").poses
    got = pose_compose(base, np.broadcast_to(MOUNT, base.shape))
    np.testing.assert_allclose(got[:, :2], laser[:, :2], atol=2e-3)
    assert (out / "graph.g2o").is_file()


def test_map_and_extract_read_a_bag(tmp_path):
    pytest.importorskip("rosbags")
    bag = tmp_path / "run.bag"
    write_demo_bag(bag, 1, MOUNT, 30, False)
    assert _run(["map", str(bag), "--out", str(tmp_path / "map"), "--no-plot", "--quiet"]) == 0
    summary = json.loads((tmp_path / "map" / "summary.json").read_text())
    assert summary["scans"] == 30 and summary["lines_merged"] > 0
    assert _run(["extract", str(bag), "--out", str(tmp_path / "l.jsonl"), "--quiet"]) == 0
    assert len((tmp_path / "l.jsonl").read_text().splitlines()) == 30


@pytest.mark.realdata
def test_intel_bag_first_scans(tmp_path, shared_data):
    """The real Intel bag: geometry from its messages, identity mount from its tf_static, the
    relations inside a run over its first 1500 scans scored."""
    out = tmp_path / "intel_bag"
    bag = shared_data / "intel" / "intel.bag"
    assert _run(["slam", str(bag), "--out", str(out), "--max-scans", "1500", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["partial"] and summary["scans_in_log"] == 13631
    geometry = summary["input"]["geometry"]
    assert geometry["source"] == "log" and geometry["beams"] == 180
    assert geometry["step_deg"] == pytest.approx(math.degrees(0.017550798), rel=1e-6)
    assert summary["input"]["mount_source"] == "tf" and summary["frame"] == "base"
    rel = shared_data / "intel" / "intel.relations"
    assert _run(["evaluate", str(out), "--relations", str(rel), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial_run"]["relations_inside_run"] == metrics["relations"]["n_used"] > 100
    assert metrics["relations"]["abs_trans_m"]["mean"] < 0.06
