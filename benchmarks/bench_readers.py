"""Benchmark: the topic-log readers (ULog, ROS 1 bag, ROS 2 MCAP bag, topic folder) in MB/s on
generated files of a few MB, against each library's own export (pyulog's ``data_list`` to pandas,
rosbags' deserialisation loop, pandas ``read_csv``).

Prints one line per reader, then one JSON object as the last line.
"""

from __future__ import annotations

import json
import struct
import tempfile
import time
from pathlib import Path

import numpy as np

from fdikit.io import read_rosbag, read_topic_folder, read_ulog


def _best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def write_ulog(path: Path, seconds: float) -> Path:
    """A ULog (spec version 1) of two 250 Hz IMU instances (6 floats) and a 5 Hz GPS (3 doubles)."""

    def msg(kind, body):
        return struct.pack("<HB", len(body), ord(kind)) + body

    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
    out += msg("B", bytes(40))
    out += msg("F", b"sensor_combined:uint64_t timestamp;float[3] gyro;float[3] accel;")
    out += msg("F", b"vehicle_gps_position:uint64_t timestamp;double lat;double lon;double alt;")
    topics = [(0, 0, "sensor_combined", 4000, 6, "<f4"), (1, 1, "sensor_combined", 4000, 6, "<f4"),
              (2, 0, "vehicle_gps_position", 200_000, 3, "<f8")]
    rng = np.random.default_rng(0)
    recs = []
    for msg_id, multi, name, period, n_f, ty in topics:
        out += msg("A", struct.pack("<BH", multi, msg_id) + name.encode())
        n = int(seconds * 1e6 / period)
        dt = np.dtype([("size", "<u2"), ("type", "u1"), ("id", "<u2"), ("ts", "<u8"), ("v", ty, (n_f,))])
        r = np.zeros(n, dt)
        r["size"], r["type"], r["id"] = dt.itemsize - 3, ord("D"), msg_id
        r["ts"] = 1000 + np.arange(n, dtype=np.uint64) * period + 500 * multi
        r["v"] = rng.normal(size=(n, n_f))
        recs.append((r["ts"], [bytes(x) for x in r]))
    ts = np.concatenate([t for t, _ in recs])
    blobs = [b for _, bs in recs for b in bs]
    for i in np.argsort(ts, kind="stable"):
        out += blobs[i]
    path.write_bytes(bytes(out))
    return path


def write_bag(path: Path, kind: str, seconds: float) -> Path:
    """A ROS 1 bag or ROS 2 MCAP bag of a 200 Hz Imu and a 19 Hz Float64, by rosbags' writers."""
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        w, ser, extra = Writer(path), ts.serialize_ros1, {"seq": 0}
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        ts = get_typestore(Stores.ROS2_HUMBLE)
        w, ser, extra = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP), ts.serialize_cdr, {}
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Vec = T["geometry_msgs/msg/Vector3"]
    Quat, Imu, F64 = T["geometry_msgs/msg/Quaternion"], T["sensor_msgs/msg/Imu"], T["std_msgs/msg/Float64"]
    t0 = 1_700_000_000_000_000_000
    items = [(t0 + k * 5_000_000, 0) for k in range(int(seconds * 200))]
    items += [(t0 + k * 52_631_579 + 1, 1) for k in range(int(seconds * 19))]
    rng = np.random.default_rng(0)
    with w:
        c_imu = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        c_v = w.add_connection("/speed", "std_msgs/msg/Float64", typestore=ts)
        for t, which in sorted(items):
            if which == 0:
                a = rng.normal(size=6)
                m = Imu(header=Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id="imu", **extra),
                        orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                        angular_velocity=Vec(x=a[0], y=a[1], z=a[2]), angular_velocity_covariance=np.zeros(9),
                        linear_acceleration=Vec(x=a[3], y=a[4], z=a[5]),
                        linear_acceleration_covariance=np.zeros(9))
                w.write(c_imu, t, ser(m, c_imu.msgtype))
            else:
                w.write(c_v, t, ser(F64(data=float(t % 1000)), c_v.msgtype))
    return path


def write_topics(d: Path, seconds: float) -> Path:
    d.mkdir()
    rng = np.random.default_rng(0)
    for topic, hz, n_c in (("imu", 200.0, 6), ("odom", 19.0, 4), ("battery", 2.9, 2), ("gps", 2.5, 3)):
        n = int(seconds * hz)
        t = np.arange(n) / hz
        v = rng.normal(size=(n, n_c))
        np.savetxt(d / f"{topic}.csv", np.c_[t, v], delimiter=",", fmt="%.9g",
                   header=",".join(["timestamp"] + [f"c{i}" for i in range(n_c)]), comments="")
    return d


def _size(p: Path) -> int:
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else p.stat().st_size


def main(repeats: int = 3) -> dict:
    import pandas as pd
    from pyulog import ULog
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out: dict = {"benchmark": "readers", "repeats": repeats}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {"ulog": write_ulog(tmp / "f.ulg", 400.0), "ros1": write_bag(tmp / "b.bag", "ros1", 50.0),
                 "mcap": write_bag(tmp / "m", "mcap", 50.0), "topics": write_topics(tmp / "topics", 600.0)}

        def lib_ulog(p):
            return [pd.DataFrame(d.data) for d in ULog(str(p)).data_list]

        def lib_bag(p):
            with AnyReader([p], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
                return sum(1 for c, _, raw in r.messages() if r.deserialize(raw, c.msgtype) is not None)

        def lib_csv(p):
            return [pd.read_csv(f) for f in sorted(p.glob("*.csv"))]

        ours = {"ulog": lambda p: read_ulog(p, rate=100.0), "ros1": lambda p: read_rosbag(p, rate=100.0),
                "mcap": lambda p: read_rosbag(p, rate=100.0),
                "topics": lambda p: read_topic_folder(p, rate=100.0)}
        lib = {"ulog": lib_ulog, "ros1": lib_bag, "mcap": lib_bag, "topics": lib_csv}
        for k, p in files.items():
            mb = _size(p) / 1e6
            t_ours = _best(lambda k=k, p=p: ours[k](p), repeats)
            t_lib = _best(lambda k=k, p=p: lib[k](p), repeats)
            out[k] = {"mb": round(mb, 3), "fdikit_s": round(t_ours, 4), "library_s": round(t_lib, 4),
                      "fdikit_mb_s": round(mb / t_ours, 2), "library_mb_s": round(mb / t_lib, 2)}
            print(f"{k:7s} {mb:6.2f} MB  fdikit {mb / t_ours:7.2f} MB/s ({t_ours:.3f} s)   "
                  f"library export {mb / t_lib:7.2f} MB/s ({t_lib:.3f} s)")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
