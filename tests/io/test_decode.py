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

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rav4-highway"
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


# ---------------------------------------------------------------------------------- on-demand BLF path
def _loaded_state(s):
    """Everything a loader returns, for bitwise comparison (floats by their bytes, info by repr)."""
    return (s.t.tobytes(), s.values.tobytes(), s.valid.tobytes(), s.names, s.units, repr(s.t0),
            repr(s.time_origin), s.reasons, repr(s.info), s.source.n_records)


def _via_frames(path, dbc, signals, rate=None, **kw):
    """The reference: python-can's frames (fdikit.io.can._read_frames) into frames_to_signals."""
    from fdikit.io.formats import SourceReport, frames_to_signals

    ts, ids, data = _read_frames(Path(path))
    src, where = SourceReport("blf", str(path), ts.size), f"BLF file {Path(path).name!r}"
    return frames_to_signals(ts, ids, data, dbc, signals, rate, source=src, where=where, **kw)


def _gappy_blf(tmp_path, seed=0):
    """A generated BLF of the RAV4 messages: jittered rates, a gap, short payloads, other ids."""
    db = _load_dbc(DBC)
    rng = np.random.default_rng(seed)
    ts, ids, data = [], [], []
    for name, period in (("KINEMATICS", 0.01), ("SPEED", 0.02), ("WHEEL_SPEEDS", 0.012),
                         ("STEER_ANGLE_SENSOR", 0.0125)):
        msg = db.get_message_by_name(name)
        t = np.arange(0.0, 20.0, period) + rng.uniform(0, 1e-3)
        t = t[(t < 7.0) | (t > 7.4)] if name == "SPEED" else t  # a gap longer than max_gap periods
        t += rng.normal(0, 2e-4, t.size)
        pay = [rng.integers(0, 256, 8, dtype=np.uint8).tobytes() for _ in t]
        if name == "STEER_ANGLE_SENSOR":  # stuck stretches (longest_constant) and short frames (NaN)
            pay = [pay[(k // 50) * 50] for k in range(len(pay))]
            for k in rng.integers(0, len(pay), 15):
                pay[k] = pay[k][:1]
        ts.append(t)
        ids.append(np.full(t.size, msg.frame_id))
        data += pay
    ts, ids = np.concatenate(ts), np.concatenate(ids)
    extra = rng.uniform(0, 20, 3000)  # frames of other messages, among them an extended id
    ts, ids = np.r_[ts, extra], np.r_[ids, rng.choice([0x3B7, 0x18DAF110, 0x7E8], extra.size)]
    data += [rng.integers(0, 256, rng.integers(0, 9), dtype=np.uint8).tobytes() for _ in extra]
    order = np.argsort(ts, kind="stable")
    ts = 1.7e9 + ts[order]
    return write_blf_table(tmp_path / f"gappy{seed}.blf", ts, ids[order], [data[k] for k in order],
                           container_bytes=40_000)


ALL_OPTIONS = [{}, {"span": "log"}, {"method": "previous"}, {"units": "si", "max_gap": 1.5},
               {"span": "log", "method": "previous", "stuck_after": 0.3}]


@pytest.mark.parametrize("kw", ALL_OPTIONS)
def test_on_demand_blf_path_equals_python_can_frames(tmp_path, kw):
    """read_log on a BLF (frames read on demand, channels of a message resampled together) gives
    bit for bit what python-can's frames give through frames_to_signals: values, grid, flags, t0,
    time origin, invalid reasons and every SignalQuality field."""
    sig = ["STEER_ANGLE_SENSOR.STEER_ANGLE", "SPEED.SPEED", "KINEMATICS.YAW_RATE",
           "STEER_ANGLE_SENSOR.STEER_FRACTION", "WHEEL_SPEEDS.WHEEL_SPEED_FL", "KINEMATICS.ACCEL_Y",
           "WHEEL_SPEEDS.WHEEL_SPEED_RR"]
    paths = [_gappy_blf(tmp_path, 0), _gappy_blf(tmp_path, 1)] + ([BLF] if BLF.exists() else [])
    for p in paths:
        assert decode.read_blf_frames(p) is not None  # the on-demand path is the one tested
        for rate in (50.0, None):
            new = read_log(p, DBC, sig, rate, **kw)
            ref = _via_frames(p, DBC, sig, rate, **kw)
            assert _loaded_state(new) == _loaded_state(ref), (p, rate)
    gappy = read_log(paths[0], DBC, sig, 50.0, **kw)
    assert gappy.reasons and not gappy.valid.all()  # the generated log exercises the gap path
    assert gappy.info["STEER_ANGLE_SENSOR.STEER_ANGLE"].n_undecodable > 0


def test_on_demand_blf_frames_equal_the_table(tmp_path):
    paths = [_gappy_blf(tmp_path, 2)] + ([BLF] if BLF.exists() else [])
    for p in paths:
        ts, ids, pay, header = read_blf_table(p)
        frames = decode.read_blf_frames(p)
        assert frames.n_frames == ts.size and frames.header == header and frames.times_ordered()
        assert np.array_equal(frames.times(), ts) and np.array_equal(frames.ids, ids)
        for fid in np.unique(ids):
            idx = frames.select(int(fid))
            assert np.array_equal(idx, np.flatnonzero(ids == fid))
            assert np.array_equal(frames.times(idx), ts[idx])
            sub, ref = frames.payloads(idx), pay.take(idx)
            assert np.array_equal(sub.matrix, ref.matrix) and np.array_equal(sub.lengths, ref.lengths)


def test_on_demand_blf_time_going_back_is_the_same_error(tmp_path):
    rng = np.random.default_rng(4)
    n = 3000
    ts = 1.7e9 + np.r_[0.0, np.cumsum(rng.uniform(1e-4, 2e-3, n - 1))]  # starts on a millisecond
    ts[1000], ts[1001] = ts[1001], ts[1000]  # two frames swapped: time goes back at frame 1001
    ids = rng.choice([0xB4, 0x25], n)
    data = [rng.integers(0, 256, 8, dtype=np.uint8).tobytes() for _ in range(n)]
    p = write_blf_table(tmp_path / "back.blf", ts, ids, data)
    assert not decode.read_blf_frames(p).times_ordered()
    from fdikit.errors import DataError

    with pytest.raises(DataError) as new:
        read_log(p, DBC, ["SPEED.SPEED"], 50.0)
    with pytest.raises(DataError) as ref:
        _via_frames(p, DBC, ["SPEED.SPEED"], 50.0)
    assert str(new.value) == str(ref.value) and "frame 1001" in str(new.value)


def test_longest_constant_rows_equals_per_row():
    from fdikit.io.formats import _longest_constant, _longest_constant_rows

    rng = np.random.default_rng(6)
    for n in (1, 2, 3, 10, 200):
        t = np.cumsum(rng.uniform(0.001, 0.1, n))
        v = rng.integers(0, 3, (4, n)).astype(float)
        v[1] = 7.0  # constant all along
        v[2, rng.integers(0, n, 3)] = np.nan
        v[3] = np.arange(n)  # never constant
        got = _longest_constant_rows(t, v)
        want = [_longest_constant(t, row) for row in v]
        assert got.tobytes() == np.array(want).tobytes()


def test_inflate_paths_give_zlib_bytes_and_fall_back_on_a_wrong_size():
    """libdeflate (with the container's stated size), ISA-L and zlib give the same bytes; a stated
    size that does not match, or a truncated stream, goes to the slower paths and behaves as zlib
    itself (a truncated stream gives what zlib's decompressobj gives)."""
    import zlib

    from fdikit.io import decode

    rng = np.random.default_rng(5)
    data = rng.integers(0, 40, 200_000).astype(np.uint8).tobytes()
    body = zlib.compress(data, 6)
    assert decode._libdeflate is not None  # a dependency of fdikit
    assert decode._inflate(body, len(data)) == data
    for wrong in (len(data) - 1, len(data) + 7, 0, None):
        assert decode._inflate(body, wrong) == data
    cut = body[: len(body) // 2]
    assert decode._inflate(cut, len(data)) == zlib.decompressobj().decompress(cut)
    with pytest.raises(zlib.error):
        decode._inflate(b"\x78\x9c" + b"\xff" * 40, 1000)
