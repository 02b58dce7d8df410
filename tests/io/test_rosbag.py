"""The ROS bag reader (issue 28): ROS 1 ``.bag``, ROS 2 ``.db3`` and ``.mcap`` bags written with
rosbags' own writers round-trip; log time vs header stamps; flattened names; bad bags; fuzzing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import read_log, read_rosbag
from fdikit.io.formats import MultiRateSignals, detect_format

from .fuzzing import BIN_OPS, check_read, mutate

pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore

T0 = 1_700_000_000_000_000_000  # ns: UNIX time of the first message
IMU_NS = 5_000_000 * np.arange(120)  # 200 Hz, receive times relative to T0
ODOM_NS = 52_631_579 * np.arange(12) + 7_000_000  # 19 Hz
STAMP_LAG = 2_000_000  # header stamps 2 ms before receipt


def _messages(store):
    ts = get_typestore(store)
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]
    Vec = T["geometry_msgs/msg/Vector3"]
    Quat = T["geometry_msgs/msg/Quaternion"]
    Imu = T["sensor_msgs/msg/Imu"]
    F64 = T["std_msgs/msg/Float64"]
    rng = np.random.default_rng(1)
    imu, odom = [], []
    for k, rel in enumerate(IMU_NS):
        stamp = T0 + int(rel) - STAMP_LAG
        extra = {"seq": k} if store == Stores.ROS1_NOETIC else {}
        h = Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="imu", **extra)
        a = rng.normal(size=3)
        m = Imu(header=h, orientation=Quat(x=0.0, y=0.0, z=float(k), w=1.0),
                orientation_covariance=np.arange(9, dtype=np.float64),
                angular_velocity=Vec(x=0.1 * k, y=0.0, z=-0.1 * k),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=Vec(x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=np.zeros(9))
        imu.append((T0 + int(rel), m))
    for k, rel in enumerate(ODOM_NS):
        odom.append((T0 + int(rel), F64(data=float(k) * 1.5)))
    return ts, imu, odom


def write_bag(path: Path, kind: str) -> Path:
    """Write a small bag with rosbags' writers: kind ``"ros1"``, ``"db3"`` or ``"mcap"``."""
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        ts, imu, odom = _messages(Stores.ROS1_NOETIC)
        ser = ts.serialize_ros1
        w = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        ts, imu, odom = _messages(Stores.ROS2_HUMBLE)
        ser = ts.serialize_cdr
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        w = Writer(path, version=9, storage_plugin=plugin)
    with w:
        c_imu = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=ts)
        c_odom = w.add_connection("/speed", "std_msgs/msg/Float64", typestore=ts)
        items = ([(t, 0, k, m) for k, (t, m) in enumerate(imu)]
                 + [(t, 1, k, m) for k, (t, m) in enumerate(odom)])
        for t, which, _, m in sorted(items, key=lambda x: (x[0], x[1], x[2])):
            conn = c_imu if which == 0 else c_odom
            w.write(conn, t, ser(m, conn.msgtype))
    return path


@pytest.fixture(scope="module", params=["ros1", "db3", "mcap"])
def bag(request, tmp_path_factory):
    d = tmp_path_factory.mktemp(request.param)
    path = d / ("drive.bag" if request.param == "ros1" else "drive")
    write_bag(path, request.param)
    return request.param, path


def test_round_trip(bag):
    kind, path = bag
    s = read_rosbag(path, rate=50.0)
    assert isinstance(s, MultiRateSignals) and s.causal
    assert s.topics["/speed"] == ["/speed.data"]
    imu = s.topics["/imu/data"]
    assert "/imu/data.linear_acceleration.x" in imu and "/imu/data.orientation_covariance[8]" in imu
    assert "/imu/data.header.stamp.sec" in imu and not any("frame_id" in c for c in imu)
    assert s.names[-2:] == ["/imu/data.__age__", "/speed.__age__"]
    assert s.time_origin.ticks == T0 and s.time_origin.exponent == 9 and s.t0 == T0 / 1e9
    # the held value is the last message at or before each grid time (independent computation)
    _, imu_m, odom_m = _messages(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    t_speed = ODOM_NS / 1e9
    i = np.searchsorted(t_speed, s.t + 1e-9, side="right") - 1
    np.testing.assert_array_equal(s["/speed.data"][0], [odom_m[k][1].data for k in i])
    np.testing.assert_allclose(s.age("/speed"), s.t - t_speed[i], atol=1e-12)
    t_imu = IMU_NS / 1e9
    j = np.searchsorted(t_imu, s.t + 1e-9, side="right") - 1
    np.testing.assert_array_equal(s["/imu/data.linear_acceleration.y"][0],
                                  [imu_m[k][1].linear_acceleration.y for k in j])
    np.testing.assert_array_equal(s["/imu/data.orientation_covariance[4]"][0], 4.0)
    assert s.valid.all()


def test_single_storage_file_and_detection(bag, tmp_path):
    kind, path = bag
    assert detect_format(path) == "rosbag"
    if kind == "ros1":
        q = tmp_path / "noext"
        q.write_bytes(path.read_bytes())
        assert detect_format(q) == "rosbag"
        with pytest.raises(DataError, match="rename it to 'noext.bag'"):
            read_rosbag(q)
        return
    f = next(path.glob(f"*.{kind}"))
    a = read_rosbag(f, ["/speed.data"], rate=20.0)  # the storage file alone, without metadata.yaml
    b = read_log(path, signals=["/speed.data"], rate=20.0)
    np.testing.assert_array_equal(a.values, b.values)
    assert detect_format(f) == "rosbag"


def test_header_time_and_selection(bag):
    _, path = bag
    s = read_rosbag(path, ["/imu/data.angular_velocity.z"], rate=100.0, time="header")
    assert s.names == ["/imu/data.angular_velocity.z", "/imu/data.__age__"]
    t_hdr = (IMU_NS - STAMP_LAG) / 1e9
    assert s.t[0] == t_hdr[0]
    k = np.searchsorted(t_hdr, s.t + 1e-9, side="right") - 1
    np.testing.assert_allclose(s[s.names[0]][0], -0.1 * k)
    with pytest.raises(DataError, match=r"topic '/speed' .* has no header.stamp"):
        read_rosbag(path, ["/speed"], time="header")
    with pytest.raises(DataError, match=r"no topic \['/gps'\]; topics: \['/imu/data', '/speed'\]"):
        read_rosbag(path, ["/gps.latitude"])
    with pytest.raises(DataError, match=r"no channel or topic '/imu/data.linear_acceleration.w'"):
        read_rosbag(path, ["/imu/data.linear_acceleration.w"])
    lin = read_rosbag(path, ["/speed.data"], rate=50.0, method="linear")
    assert lin.causal is False


def test_bad_bags(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        read_rosbag(tmp_path / "none.bag")
    (tmp_path / "x.bag").write_bytes(b"ULog\x01\x12\x35" + bytes(50))
    with pytest.raises(DataError, match="not a ROS bag"):
        read_rosbag(tmp_path / "x.bag")
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(DataError, match="empty"):
        read_rosbag(tmp_path / "empty.mcap")
    (tmp_path / "folder").mkdir()
    with pytest.raises(DataError, match="no metadata.yaml"):
        read_rosbag(tmp_path / "folder")
    with pytest.raises(DataError, match="time must be"):
        read_rosbag(tmp_path / "x.bag", time="stamp")


FUZZ = [(k, op, seed) for k in ("ros1", "mcap") for op in BIN_OPS for seed in range(4)]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize("kind,op,seed", FUZZ, ids=[f"{k}-{o}-{s}" for k, o, s in FUZZ])
def test_fuzzed_bag(tmp_path, kind, op, seed):
    src = write_bag(tmp_path / ("a.bag" if kind == "ros1" else "a"), kind)
    f = src if kind == "ros1" else next(src.glob("*.mcap"))
    q = tmp_path / ("fuzz" + f.suffix)
    q.write_bytes(mutate(f.read_bytes(), op, seed))
    check_read(lambda: read_rosbag(q, rate=50.0), "ROS bag 'fuzz")
