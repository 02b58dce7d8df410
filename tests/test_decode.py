"""The vectorised CAN path (fdikit.io.decode) equals today's per-frame path, bit for bit.

Reference: python-can's BLFReader frame by frame (fdikit.io.can._read_frames) and cantools'
Message.decode frame by frame (decode_message_reference), on the real RAV4 log and on random
payloads of a generated DBC with every kind of signal.
"""

from pathlib import Path

import cantools
import numpy as np
import pytest

from fdikit.io import decode, read_log
from fdikit.io.can import _load_dbc, _read_frames
from fdikit.io.decode import (
    FramePayloads,
    decode_message,
    decode_message_reference,
    read_blf_table,
    set_signal,
    write_blf_table,
)
from fdikit.io.formats import series_to_grid

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "rav4-highway"
BLF, DBC = DATA / "drive.blf", DATA / "toyota_rav4.dbc"
needs_data = pytest.mark.skipif(not BLF.exists(), reason=f"real RAV4 data not found at {DATA}")
SIGNALS = ["KINEMATICS.YAW_RATE", "KINEMATICS.ACCEL_Y", "STEER_ANGLE_SENSOR.STEER_ANGLE",
           "STEER_ANGLE_SENSOR.STEER_FRACTION", "SPEED.SPEED", "WHEEL_SPEEDS.WHEEL_SPEED_FL",
           "WHEEL_SPEEDS.WHEEL_SPEED_RR", "BRAKE_MODULE.BRAKE_PRESSURE", "ENGINE_RPM.RPM"]


def same(a, b):
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


@pytest.fixture(scope="module")
def frames():
    if not BLF.exists():
        pytest.skip(f"real RAV4 data not found at {DATA}")
    return _read_frames(BLF)


@needs_data
def test_blf_table_equals_python_can(frames, monkeypatch):
    ts0, ids0, data0 = frames
    for uniform in (True, False):  # the 48-byte fast layout, and the general object-chain walk
        if not uniform:
            monkeypatch.setattr(decode, "_uniform_can", lambda buf: None)
        ts, ids, pay, header = read_blf_table(BLF)
        assert header == {"file_size": BLF.stat().st_size, "object_count": len(ts0)}
        assert np.array_equal(ts, ts0) and np.array_equal(ids, ids0)  # times bitwise
        assert len(pay) == len(data0) and all(pay[k] == data0[k] for k in range(len(data0)))


@needs_data
def test_every_rav4_signal_decodes_like_cantools(frames):
    _, ids, data = frames
    db = _load_dbc(DBC)
    pay = FramePayloads.from_bytes(data)
    n_sig = 0
    for msg in db.messages:
        idx = np.flatnonzero(ids == msg.frame_id)
        if idx.size == 0:
            continue
        names = [s.name for s in msg.signals]
        v, bad = decode_message(msg, names, pay.take(idx))
        v0, bad0 = decode_message_reference(msg, names, [data[k] for k in idx])
        assert same(v, v0), msg.name
        assert np.array_equal(bad, bad0), msg.name
        n_sig += len(names)
    assert n_sig > 50  # the log carries many messages of the DBC


@needs_data
def test_read_log_equals_the_per_frame_path(frames):
    """The whole loader (frames -> decoded series -> grid) against python-can + cantools per frame."""
    ts, ids, data = frames
    db = _load_dbc(DBC)
    series, units = {}, {}
    for s in SIGNALS:
        m, n = s.split(".")
        msg = db.get_message_by_name(m)
        idx = np.flatnonzero(ids == msg.frame_id)
        v, _ = decode_message_reference(msg, [n], [data[k] for k in idx])
        series[s] = (ts[idx] - ts[0], v[:, 0])
        units[s] = msg.get_signal_by_name(n).unit or ""
    ref = series_to_grid(series, units, 50.0, log_span=(0.0, ts[-1] - ts[0]))
    new = read_log(BLF, DBC, SIGNALS, 50.0)
    assert same(new.t, ref.t) and same(new.values, ref.values) and np.array_equal(new.valid, ref.valid)


RANDOM_DBC = '''VERSION ""
BO_ 100 MIX: 8 XXX
 SG_ LE_U12 : 3|12@1+ (0.5,-10) [0|0] "a" XXX
 SG_ LE_S7 : 17|7@1- (1,0) [0|0] "" XXX
 SG_ BE_U16 : 39|16@0+ (0.01,0) [0|0] "km/h" XXX
 SG_ BE_S10 : 55|10@0- (0.244,-125) [0|0] "deg/s" XXX
 SG_ LE_U1 : 58|1@1+ (1,0) [0|0] "" XXX
 SG_ INT_SCALE : 24|8@1+ (3,-7) [0|0] "" XXX
BO_ 101 WIDE: 8 XXX
 SG_ U64 : 0|64@1+ (1,0) [0|0] "" XXX
BO_ 102 FLT: 8 XXX
 SG_ F32 : 0|32@1- (1,0) [0|0] "" XXX
 SG_ F32B : 39|32@0- (2.5,1) [0|0] "" XXX
BO_ 103 S64: 8 XXX
 SG_ S64 : 7|64@0- (1e-3,0) [0|0] "" XXX
SIG_VALTYPE_ 102 F32 : 1;
SIG_VALTYPE_ 102 F32B : 1;
'''


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_payloads_decode_like_cantools(seed):
    """Little/big endian, signed, integer and float scaling, 1..64 bits, truncated and long payloads."""
    db = cantools.database.load_string(RANDOM_DBC, database_format="dbc", strict=False)
    rng = np.random.default_rng(seed)
    for msg in db.messages:
        n = 400
        lengths = rng.integers(0, 12, n)  # 0 (remote-like) .. 11 bytes (excess is ignored)
        data = [rng.integers(0, 256, k, dtype=np.uint8).tobytes() for k in lengths]
        names = [s.name for s in msg.signals]
        v, bad = decode_message(msg, names, data)
        v0, bad0 = decode_message_reference(msg, names, data)
        assert same(v, v0), msg.name
        assert np.array_equal(bad, bad0) and bad.sum() > 0, msg.name


def test_set_signal_round_trip_keeps_other_bits():
    db = cantools.database.load_string(RANDOM_DBC, database_format="dbc", strict=False)
    msg = db.get_message_by_name("MIX")
    rng = np.random.default_rng(5)
    data = [rng.integers(0, 256, 8, dtype=np.uint8).tobytes() for _ in range(50)]
    target = rng.uniform(-240, -1, 50)  # inside the raw range: -125 + 0.244 * [-512, 511]
    new = set_signal(msg, "BE_S10", data, target)
    v, _ = decode_message(msg, ["BE_S10"], new)
    assert np.all(np.abs(v[:, 0] - target) <= 0.122 + 1e-9)  # half a quantum
    others = [s.name for s in msg.signals if s.name != "BE_S10"]
    assert same(decode_message(msg, others, new)[0], decode_message(msg, others, data)[0])


def test_written_blf_reads_back_with_python_can(tmp_path):
    rng = np.random.default_rng(3)
    n = 7000  # spans several log containers
    ts = 1.7e9 + np.cumsum(rng.uniform(1e-5, 2e-3, n))
    ids = rng.choice([0x25, 0xB4, 0x18DAF110], n)
    data = [rng.integers(0, 256, rng.integers(0, 9), dtype=np.uint8).tobytes() for _ in range(n)]
    p = write_blf_table(tmp_path / "x.blf", ts, ids, data, container_bytes=50_000)
    t0, i0, d0 = _read_frames(p)
    t1, i1, d1, _ = read_blf_table(p)
    assert np.array_equal(t0, t1) and np.array_equal(i0, ids) and np.array_equal(i1, ids)
    assert [bytes(x) for x in d0] == data and [d1[k] for k in range(n)] == data
    assert np.max(np.abs(t0 - ts)) < 1e-6  # nanosecond ticks from a millisecond start time
