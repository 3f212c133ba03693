"""ROS 1 / ROS 2 bags written here with rosbags, read back as scans with odometry."""

from __future__ import annotations

import numpy as np
import pytest

from slam.errors import InputError, LogFormatError

rosbags = pytest.importorskip("rosbags")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from slam.io.rosbag import iter_rosbag_scans, read_rosbag_odometry  # noqa: E402


def make_messages(typestore, rng, n_scans=5, n_beams=31):
    T = typestore.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]

    ros1 = "seq" in Header.__dataclass_fields__

    def header(t, frame):
        sec = int(t)
        stamp = Time(sec=sec, nanosec=round((t - sec) * 1e9))
        if ros1:
            return Header(seq=0, stamp=stamp, frame_id=frame)
        return Header(stamp=stamp, frame_id=frame)

    scans, odoms = [], []
    ranges = rng.uniform(0.5, 10.0, (n_scans, n_beams)).astype(np.float32)
    ranges[0, 3] = np.inf
    for k in range(n_scans):
        t = 100.0 + 0.2 * k + 0.1
        scans.append(
            (
                t,
                T["sensor_msgs/msg/LaserScan"](
                    header=header(t, "laser"),
                    angle_min=np.float32(-1.5),
                    angle_max=np.float32(1.5),
                    angle_increment=np.float32(0.1),
                    time_increment=np.float32(0.0),
                    scan_time=np.float32(0.1),
                    range_min=np.float32(0.1),
                    range_max=np.float32(30.0),
                    ranges=ranges[k],
                    intensities=np.zeros(0, np.float32),
                ),
            )
        )
    for k in range(2 * n_scans + 2):
        t = 100.0 + 0.1 * k
        yaw = 0.05 * k
        P = T["geometry_msgs/msg/Point"](x=0.5 * k, y=0.1 * k, z=0.0)
        Q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2))
        pose = T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=P, orientation=Q),
            covariance=np.zeros(36),
        )
        V3 = T["geometry_msgs/msg/Vector3"]
        twist = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=V3(x=0.0, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)
            ),
            covariance=np.zeros(36),
        )
        odoms.append(
            (
                t,
                T["nav_msgs/msg/Odometry"](
                    header=header(t, "odom"), child_frame_id="base", pose=pose, twist=twist
                ),
            )
        )
    return scans, odoms, ranges


def write_bag(path, version, typestore, scans, odoms):
    if version == 1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
        serialize = typestore.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer

        writer = Writer(path, version=9)
        serialize = typestore.serialize_cdr
    with writer:
        c_scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=typestore)
        c_odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=typestore)
        items = [(t, c_scan, m, "sensor_msgs/msg/LaserScan") for t, m in scans]
        items += [(t, c_odom, m, "nav_msgs/msg/Odometry") for t, m in odoms]
        for t, conn, msg, kind in sorted(items, key=lambda x: x[0]):
            writer.write(conn, int(t * 1e9), serialize(msg, kind))


@pytest.mark.parametrize("version", [1, 2])
def test_bag_round_trip(tmp_path, rng, version):
    store = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    scans, odoms, ranges = make_messages(store, rng)
    path = tmp_path / ("run.bag" if version == 1 else "run_bag")
    write_bag(path, version, store, scans, odoms)
    got = list(iter_rosbag_scans(path))
    assert len(got) == len(scans)
    for k, scan in enumerate(got):
        assert scan.index == k
        assert scan.timestamp == pytest.approx(scans[k][0], abs=1e-9)
        np.testing.assert_array_equal(scan.ranges, ranges[k].astype(np.float64))
        np.testing.assert_allclose(scan.bearings, -1.5 + 0.1 * np.arange(31), atol=1e-6)
        assert scan.max_range_m == pytest.approx(30.0)
        # odometry x = 5 t', y = t', yaw = 0.5 t' with t' = t - 100: linear, so exact
        tp = scan.timestamp - 100.0
        np.testing.assert_allclose(scan.pose_odom_base, [5 * tp, tp, 0.5 * tp], atol=1e-6)
    assert not got[0].valid_mask()[3]
    odometry = read_rosbag_odometry(path)
    assert len(odometry) == len(odoms)
    np.testing.assert_allclose(odometry.poses[-1], [0.5 * 11, 0.1 * 11, 0.05 * 11], atol=1e-9)


def test_not_a_bag_and_wrong_topic(tmp_path, rng):
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all\n")
    with pytest.raises(LogFormatError, match="not a readable ROS bag"):
        list(iter_rosbag_scans(junk))
    store = get_typestore(Stores.ROS2_HUMBLE)
    scans, odoms, _ = make_messages(store, rng, n_scans=2)
    path = tmp_path / "bag2"
    write_bag(path, 2, store, scans, odoms)
    with pytest.raises(InputError, match="no sensor_msgs/msg/LaserScan topic '/front'"):
        list(iter_rosbag_scans(path, scan_topic="/front"))


def test_an_odometry_pose_beyond_any_odometry_names_the_message(tmp_path, rng):
    store = get_typestore(Stores.ROS2_HUMBLE)
    scans, odoms, _ = make_messages(store, rng, n_scans=3)
    odoms[4][1].pose.pose.position.x = 1e200  # finite, but no odometry drifts that far
    path = tmp_path / "bag2"
    write_bag(path, 2, store, scans, odoms)
    with pytest.raises(LogFormatError, match=r"/odom: odometry message 4: .*beyond 1e\+08 m"):
        read_rosbag_odometry(path)
    with pytest.raises(LogFormatError, match="odometry message 4"):
        list(iter_rosbag_scans(path))
