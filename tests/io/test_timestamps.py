"""Absolute timestamps at full precision (issue 16, item 3): UNIX-epoch seconds, ms, us and ROS
nanoseconds read to the same relative time axis as the same log starting at 0, exactly where the
text was exact, with the absolute origin kept; a nanosecond log never builds a huge grid."""

from __future__ import annotations

import resource
from decimal import Decimal

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import read_csv, read_log, read_parquet
from fdikit.io.timebase import TimeOrigin, times_to_seconds

N = 2001  # 20 s at 100 Hz
EPOCH_NS = 1_700_000_000_123_456_789
RNG = np.random.default_rng(16)
X = RNG.normal(0.0, 1.0, N)
Y = np.cumsum(RNG.normal(0.0, 0.01, N))


def _cell(x: float) -> str:
    return repr(float(x))


def write(path, times: list[str], tname: str = "t"):
    lines = [f"{tname},x,y"] + [f"{t},{_cell(a)},{_cell(b)}" for t, a, b in zip(times, X, Y, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def ticks_10ms():
    return np.arange(N, dtype=np.int64)


def texts(unit: str, origin_ns: int) -> list[str]:
    """The 100 Hz log's timestamps as exact text in one unit, starting at ``origin_ns``."""
    ns = origin_ns + ticks_10ms() * 10_000_000
    if unit == "ns":
        return [str(int(v)) for v in ns]
    if unit == "us":
        return [str(int(v) // 1000) for v in ns]
    if unit == "ms":
        return [str(int(v) // 1_000_000) for v in ns]
    # seconds as exact decimal text (9 decimals)
    return [str(Decimal(int(v)).scaleb(-9)) for v in ns]


@pytest.fixture(scope="module")
def zero_based(tmp_path_factory):
    p = write(tmp_path_factory.mktemp("ts") / "zero.csv", [f"{k / 100:.2f}" for k in range(N)])
    return read_csv(p)


def test_zero_based_log_is_kept_as_written(zero_based):
    assert zero_based.t0 == 0.0 and zero_based.time_origin is None
    assert np.array_equal(zero_based.t, np.array([float(f"{k / 100:.2f}") for k in range(N)]))


@pytest.mark.parametrize(
    "unit, origin_ns",
    [
        ("s", 1_700_000_000_000_000_000),
        ("s", EPOCH_NS),
        ("ms", 1_700_000_000_123_000_000),
        ("us", 1_700_000_000_123_456_000),
        ("ns", EPOCH_NS),
        ("ns", 1_600_000_000_000_000_001),
    ],
)
@pytest.mark.parametrize("how", ["explicit", "auto"])
def test_epoch_log_reads_to_the_zero_based_grid_exactly(tmp_path, zero_based, unit, origin_ns, how):
    p = write(tmp_path / f"epoch_{unit}.csv", texts(unit, origin_ns))
    s = read_csv(p, time_unit=unit if how == "explicit" else "auto")
    # the relative axis is bit-for-bit the one of the log written from 0 (0.01 is the float of "0.01")
    assert np.array_equal(s.t, zero_based.t)
    assert np.array_equal(s.values, zero_based.values) and s.valid.all()
    o = s.time_origin
    assert isinstance(o, TimeOrigin) and o.rebased and o.unit == unit
    first = texts(unit, origin_ns)[0]
    exact = Decimal(first).scaleb(-{"s": 0, "ms": 3, "us": 6, "ns": 9}[unit])
    assert Decimal(o.text) == exact  # the exact origin, not a rounded float
    assert s.t0 == float(exact)
    # absolute time of an event at t = 12.34 s, exactly
    assert Decimal(o.absolute(s.t[1234])) == exact + Decimal("12.34")


@pytest.mark.parametrize("unit", ["ms", "ns"])
def test_gridded_epoch_log_equals_gridded_zero_based_log(tmp_path, unit):
    a = read_csv(write(tmp_path / "a.csv", [f"{k / 100:.2f}" for k in range(N)]), rate=50.0)
    b = read_csv(write(tmp_path / "b.csv", texts(unit, EPOCH_NS)), rate=50.0, time_unit=unit)
    assert (
        np.array_equal(a.t, b.t) and np.array_equal(a.values, b.values) and np.array_equal(a.valid, b.valid)
    )
    assert b.t0 == float(Decimal(texts(unit, EPOCH_NS)[0]).scaleb(-{"ms": 3, "ns": 9}[unit])) and a.t0 == 0.0


def test_nanosecond_log_with_a_rate_builds_a_small_grid(tmp_path):
    """Issue 16: a ROS nanosecond log made read_csv allocate 9.6 TiB (the ns time column taken as
    seconds: a grid of 2e10 s at 100 Hz). Now it reads as ns (auto), and taken as seconds on
    purpose it is refused before any allocation, with a hint at the unit."""
    p = write(tmp_path / "ros.csv", texts("ns", EPOCH_NS), tname="stamp")
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    s = read_csv(p, time="stamp", rate=100.0)
    assert s.n_samples == N and np.allclose(np.diff(s.t), 0.01, rtol=0, atol=1e-12)
    with pytest.raises(DataError, match=r"too large.*time_unit"):
        read_csv(p, time="stamp", rate=100.0, time_unit="s")
    grown_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown_kib < 500_000  # well below half a GiB


def test_table_readers_take_time_unit(tmp_path, zero_based):
    import pyarrow as pa
    import pyarrow.parquet as pq

    ns = EPOCH_NS + ticks_10ms() * 10_000_000
    pq.write_table(pa.table({"t": pa.array(ns, pa.int64()), "x": X, "y": Y}), tmp_path / "ros.parquet")
    s = read_parquet(tmp_path / "ros.parquet", rate=100.0)
    assert s.time_origin.ticks == EPOCH_NS and s.time_origin.exponent == 9
    assert np.allclose(s.t, zero_based.t, rtol=0, atol=1e-12)
    ref = read_log(write(tmp_path / "z.csv", [f"{k / 100:.2f}" for k in range(N)]), rate=100.0)
    c = read_log(write(tmp_path / "ros.csv", texts("ns", EPOCH_NS)), rate=100.0, time_unit="ns")
    assert np.array_equal(c.t, ref.t) and np.array_equal(c.values, ref.values)
    assert c.t0 == pytest.approx(EPOCH_NS / 1e9, abs=1e-6) and ref.t0 == 0.0
    # a float epoch column: its shortest decimals are rebased exactly
    pq.write_table(pa.table({"t": 1.7e9 + np.arange(N) / 100, "x": X}), tmp_path / "f.parquet")
    f = read_parquet(tmp_path / "f.parquet", rate=100.0)
    assert np.max(np.abs(f.t - ref.t)) < 1e-6 and f.time_origin.text.startswith("1700000000")


def test_duplicate_nanoseconds_are_distinct_not_merged(tmp_path):
    # 1 ns apart: a float of 1.7e18 cannot tell them apart, the integers can
    p = tmp_path / "ns.csv"
    p.write_text("t,x\n1700000000000000000,1\n1700000000000000001,2\n1700000000010000000,3\n")
    s = read_csv(p, time_unit="ns")
    assert s.t.tolist() == [0.0, 1e-9, 0.01]
    p.write_text("t,x\n1700000000000000000,1\n1700000000000000000,2\n")
    with pytest.raises(DataError, match="not strictly increasing at data row 1"):
        read_csv(p)


def test_rebase_rule_and_overrides(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("t,x\n12.5,1\n12.6,2\n")
    s = read_csv(p)
    assert s.t.tolist() == [12.5, 12.6] and s.t0 == 0.0  # relative clock: kept
    s = read_csv(p, rebase=True)
    assert s.t.tolist() == [0.0, 0.1] and s.t0 == 12.5 and s.time_origin.text == "12.5"
    p.write_text("t,x\n0,1\n10,2\n20,3\n")
    s = read_csv(p, time_unit="ms")  # a relative ms clock needs its unit; kept relative
    assert s.t.tolist() == [0.0, 0.01, 0.02] and s.t0 == 0.0
    with pytest.raises(DataError, match="time_unit must be one of"):
        read_csv(p, time_unit="minutes")


def test_times_to_seconds_names_bad_cells():
    with pytest.raises(DataError, match=r"data row 1 \(line 3\) is not a number: 'x'"):
        times_to_seconds(["1", "x"], line_offset=2)
    with pytest.raises(DataError, match="not finite at data row 0"):
        times_to_seconds(["inf", "1"])
    t, o = times_to_seconds(np.array([EPOCH_NS, EPOCH_NS + 5]), "ns")
    assert t.tolist() == [0.0, 5e-9] and o.ticks == EPOCH_NS


# ------------------------------------------------------------------ one gap, batch and follow gridding
SPEED_DBC = (
    'VERSION ""\nBO_ 180 SPEED: 8 XXX\n SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
    'BO_ 170 WHEELS: 8 XXX\n SG_ FL : 7|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
)


@pytest.mark.parametrize("method", ["linear", "previous"])
@pytest.mark.parametrize("gap", [(2.0, 2.5), (0.3, 4.0), (5.0, 5.04)])
def test_a_gap_looks_the_same_in_batch_and_follow_gridding(tmp_path, method, gap):
    """An epoch-stamped candump log at 100 Hz with one message missing over ``gap``: the batch
    loader and the FrameGridder (follow mode) flag the same grid samples, give the same values
    elsewhere, name the gap, and never hold or bridge a value across it."""
    import cantools

    from fdikit.io import FrameGridder, parse_candump_line, read_candump

    db = cantools.database.load_string(SPEED_DBC, database_format="dbc")
    lines = []
    for k in range(600):
        t = 1_700_000_000 + k / 100
        lines.append(f"({t:.6f}) can0 0AA#{(k * 7 % 60000):04X}000000000000")
        if not gap[0] < k / 100 < gap[1]:
            lines.append(f"({t + 0.001:.6f}) can0 0B4#0000000000{(k * 3 % 60000):04X}00")
    p = tmp_path / "gap.log"
    p.write_text("\n".join(lines) + "\n")
    sig = ["SPEED.SPEED", "WHEELS.FL"]
    batch = read_candump(p, db, sig, rate=100.0, method=method)
    g = FrameGridder(db, sig, 100.0, method=method)
    out = []
    for i, ln in enumerate(lines):
        t, bus, fid, data = parse_candump_line(ln, i + 1)
        out += g.push(t, fid, data, bus)
    out += g.flush()
    assert g.t0 == batch.t0 == pytest.approx(1_700_000_000.0)
    n = min(len(out), batch.n_samples)
    assert batch.n_samples - n <= 1  # the stream cannot release a sample after the last frame
    assert np.array_equal([o[0] for o in out[:n]], batch.t[:n])
    bad_stream = np.array([o[2] is not None for o in out[:n]])
    bad_batch = ~batch.valid[0, :n].all(axis=1)
    assert np.array_equal(bad_stream, bad_batch)
    V = np.array([[o[1][s] for s in sig] for o in out[:n]])
    assert np.array_equal(V[~bad_batch], batch.values[0, :n][~bad_batch])
    # nothing held or bridged: every grid sample more than max_gap periods from a SPEED frame is invalid
    tf = np.array([float(x.split(")")[0][1:]) for x in lines if "0B4#" in x]) - 1_700_000_000
    dist = np.array([np.min(np.abs(tf - t)) for t in batch.t])
    far = dist > 3 * 0.01 + 1e-6
    assert far.any() == (gap != (5.0, 5.04))
    assert not batch.valid[0, far, 0].any()
    if far.any():
        k = int(np.flatnonzero(far)[0])
        assert "gap" in batch.invalid_reason(k) and "SPEED.SPEED" in batch.invalid_reason(k)
        assert "SPEED.SPEED" in out[k][2]


@pytest.mark.parametrize("unit", ["s", "ms", "us", "ns"])
def test_stream_times_equal_the_batch_reader(tmp_path, unit):
    """Follow mode's clock (StreamTimes, one stamp at a time) equals read_csv on the same lines."""
    from fdikit.io import StreamTimes

    stamps = texts(unit, EPOCH_NS)
    batch = read_csv(write(tmp_path / "b.csv", stamps))
    st = StreamTimes()
    got = np.array([st(x) for x in stamps])
    assert np.array_equal(got, batch.t) and st.t0 == batch.t0
    st2 = StreamTimes()
    st2.restore(st.state())  # a checkpoint of the clock resumes exactly
    assert [st2(x) for x in stamps[100:110]] == batch.t[100:110].tolist()
    rel = StreamTimes()
    assert [rel("0.5"), rel("0.75")] == [0.5, 0.75] and rel.t0 == 0.0
    with pytest.raises(DataError, match="not a number"):
        rel("12:00")


def test_hypothesis_integer_stamps_are_rebased_exactly():
    from fractions import Fraction

    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=60, deadline=None)
    @given(
        origin=st.integers(10**15, 4 * 10**18),
        steps=st.lists(st.integers(1, 10**12), min_size=1, max_size=20),
        unit=st.sampled_from(["us", "ns"]),
    )
    def check(origin, steps, unit):
        ticks = np.cumsum([origin, *steps]).tolist()
        t, o = times_to_seconds([str(x) for x in ticks], unit)
        scale = {"us": 10**6, "ns": 10**9}[unit]
        want = [float(Fraction(x - ticks[0], scale)) for x in ticks]  # correctly rounded
        assert t.tolist() == want and o.ticks == ticks[0] and o.rebased

    check()
