"""The PX4 ULog reader (issue 28): round trip of a ULog written per the format spec, pyulog's own
writer, multi-instance names, the causal zero-order hold and its age channel, bad files, fuzzing."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import read_log, read_ulog
from fdikit.io.formats import MultiRateSignals, detect_format

from .fuzzing import BIN_OPS, check_read, mutate

pytest.importorskip("pyulog")

_FMT = {"uint64_t": "Q", "float": "f", "double": "d", "int32_t": "i", "uint8_t": "B", "bool": "?",
        "int16_t": "h"}


def _msg(kind: str, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), ord(kind)) + body


def write_ulog(path, topics, start_us=1_000_000, info=True):
    """Write a ULog file per the spec (docs.px4.io ULog file format), version 1.

    ``topics``: list of ``(name, multi_id, [(type, field), ...], timestamps_us, rows)``; the
    ``timestamp`` field is first and implicit.
    """
    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", start_us))
    out += _msg("B", bytes(16) + bytes(24))  # flag bits: no flags, no appended data
    seen = set()
    for name, _, fields, _, _ in topics:
        if name in seen:
            continue
        seen.add(name)
        fmt = f"{name}:uint64_t timestamp;" + "".join(f"{ty} {f};" for ty, f in fields)
        out += _msg("F", fmt.encode())
    if info:
        key = b"char[4] sys_name"
        out += _msg("I", bytes([len(key)]) + key + b"PX4_")
    items = []
    for msg_id, (name, multi, fields, ts, rows) in enumerate(topics):
        out += _msg("A", struct.pack("<BH", multi, msg_id) + name.encode())
        pack = "<HQ" + "".join(_FMT[ty] for ty, _ in fields)
        for k, (tt, row) in enumerate(zip(ts, rows)):
            items.append((int(tt), msg_id, k, _msg("D", struct.pack(pack, msg_id, int(tt), *row))))
    items.sort()
    for *_, b in items:
        out += b
    Path(path).write_bytes(bytes(out))
    return path


def _example(tmp_path, name="f.ulg"):
    rng = np.random.default_rng(0)
    t_imu = 1_000_000 + np.arange(200) * 4000 + 137  # 250 Hz
    t_gps = 1_000_000 + np.arange(13) * 400_000 + 90_001  # 2.5 Hz
    imu = rng.normal(size=(200, 3)).astype(np.float32)
    gps = np.c_[rng.normal(size=13), rng.integers(0, 20, 13)]
    topics = [
        ("sensor_accel", 0, [("float", "x"), ("float", "y"), ("float", "z")], t_imu, imu.tolist()),
        ("sensor_accel", 1, [("float", "x"), ("float", "y"), ("float", "z")], t_imu + 1000,
         (imu * 2).tolist()),
        ("vehicle_gps_position", 0, [("double", "lat"), ("uint8_t", "satellites_used")], t_gps,
         [(a, int(b)) for a, b in gps]),
    ]
    return write_ulog(tmp_path / name, topics), topics


def test_round_trip_names_values_and_time(tmp_path):
    p, topics = _example(tmp_path)
    s = read_ulog(p, rate=100.0)
    assert isinstance(s, MultiRateSignals) and s.causal and s.method == "previous"
    data = [n for n in s.names if not n.endswith(".__age__")]
    assert data == ["sensor_accel.x", "sensor_accel.y", "sensor_accel.z", "sensor_accel[1].x",
                    "sensor_accel[1].y", "sensor_accel[1].z", "vehicle_gps_position.lat",
                    "vehicle_gps_position.satellites_used"]
    assert [n for n in s.names if n.endswith(".__age__")] == [
        "sensor_accel.__age__", "sensor_accel[1].__age__", "vehicle_gps_position.__age__"]
    assert s.t0 == 1.0 and s.time_origin.ticks == 1_000_000 and s.source.format == "ulog"
    # every grid value is the last message at or before the grid time (independent computation)
    for name, multi, fields, ts, rows in topics:
        topic = name if multi == 0 else f"{name}[{multi}]"
        tt = (np.asarray(ts) - 1_000_000) / 1e6
        for j, (_, f) in enumerate(fields):
            v = s[f"{topic}.{f}"][0]
            col = np.array([r[j] for r in rows], float)
            for k, g in enumerate(s.t):
                i = np.searchsorted(tt, g + 1e-9, side="right") - 1
                assert v[k] == col[i]
            age = s.age(topic)
            i = np.searchsorted(tt, s.t + 1e-9, side="right") - 1
            np.testing.assert_allclose(age, s.t - tt[i], atol=1e-12)
    assert s.valid.all()  # span common: every topic has a message at the grid start


def test_selection_instance_alias_and_whole_message(tmp_path):
    p, _ = _example(tmp_path)
    a = read_ulog(p, ["sensor_accel[0].y", "sensor_accel[1].x"], rate=50.0)
    assert a.names == ["sensor_accel.y", "sensor_accel[1].x", "sensor_accel.__age__",
                       "sensor_accel[1].__age__"]
    b = read_ulog(p, ["vehicle_gps_position"], rate=50.0, age=False)
    assert b.names == ["vehicle_gps_position.lat", "vehicle_gps_position.satellites_used"]
    assert b.topics == {"vehicle_gps_position": b.names}
    c = read_log(p, signals=["sensor_accel.y", "sensor_accel[1].x"], rate=50.0)
    np.testing.assert_array_equal(c.values, a.values)
    assert detect_format(p) == "ulog"
    q = tmp_path / "noext"
    q.write_bytes(p.read_bytes())
    assert detect_format(q) == "ulog"


def test_pyulog_writer_round_trip(tmp_path):
    """pyulog reads our file and writes it again with its own writer: the same grid."""
    from pyulog import ULog

    p, _ = _example(tmp_path)
    q = tmp_path / "rewritten.ulg"
    ULog(str(p)).write_ulog(str(q))
    a, b = read_ulog(p, rate=100.0), read_ulog(q, rate=100.0)
    assert a.names == b.names
    np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.t, b.t)


def test_linear_is_marked_non_causal(tmp_path):
    p, _ = _example(tmp_path)
    s = read_ulog(p, ["vehicle_gps_position.lat"], rate=10.0, method="linear")
    assert s.causal is False and s.method == "linear"
    assert s.select(["vehicle_gps_position.lat"]).causal is False
    assert s.window(0.5, 2.0).causal is False


def test_max_age_marks_stale_holds(tmp_path):
    p, _ = _example(tmp_path)
    s = read_ulog(p, ["vehicle_gps_position.lat"], rate=100.0, max_age=0.25)
    age = s.age("vehicle_gps_position")
    ok = s.valid[0, :, 0]
    np.testing.assert_array_equal(ok, age <= 0.25)
    k = int(np.flatnonzero(~ok)[0])
    assert "stale" in s.invalid_reason(k)


def test_bad_files(tmp_path):
    p, _ = _example(tmp_path)
    with pytest.raises(DataError, match="does not exist"):
        read_ulog(tmp_path / "missing.ulg")
    (tmp_path / "empty.ulg").write_bytes(b"")
    with pytest.raises(DataError, match="empty"):
        read_ulog(tmp_path / "empty.ulg")
    (tmp_path / "other.ulg").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    with pytest.raises(DataError, match="not a ULog file"):
        read_ulog(tmp_path / "other.ulg")
    (tmp_path / "short.ulg").write_bytes(p.read_bytes()[:10])
    with pytest.raises(DataError, match="truncated"):
        read_ulog(tmp_path / "short.ulg")
    (tmp_path / "defs.ulg").write_bytes(p.read_bytes()[:120])
    with pytest.raises(DataError, match="truncated or corrupt"):
        read_ulog(tmp_path / "defs.ulg")
    with pytest.raises(DataError, match="no logged data"):
        read_ulog(tmp_path / "defs.ulg", strict=False)
    with pytest.raises(DataError, match=r"no data of message.*'battery_status'.*logged.*sensor_accel\[1\]"):
        read_ulog(p, ["battery_status.voltage_v"])
    with pytest.raises(DataError, match=r"no channel or topic 'sensor_accel.w'.*sensor_accel.x"):
        read_ulog(p, ["sensor_accel.w"])
    with pytest.raises(DataError, match="unknown resampling method"):
        read_ulog(p, method="cubic")


@pytest.mark.parametrize("op", BIN_OPS)
@pytest.mark.parametrize("seed", range(6))
def test_fuzzed_ulog(tmp_path, op, seed):
    p, _ = _example(tmp_path)
    q = tmp_path / "fuzz.ulg"
    q.write_bytes(mutate(p.read_bytes(), op, seed))
    check_read(lambda: read_ulog(q, rate=50.0), "ULog file")
    check_read(lambda: read_ulog(q, rate=50.0, strict=False), "ULog file")
    if op == "truncate":  # a log cut short is the log up to the cut (ULog has no index)
        out = check_read(lambda: read_ulog(q, ["sensor_accel.x"], rate=50.0, span="log"), "ULog file")
        if not isinstance(out, str):
            full = read_ulog(p, ["sensor_accel.x"], rate=50.0, span="log")
            n = out.n_samples
            np.testing.assert_array_equal(out.values[0, :n, 0][out.valid[0, :n, 0]],
                                          full.values[0, :n, 0][out.valid[0, :n, 0]])
