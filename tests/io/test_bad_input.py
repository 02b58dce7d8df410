"""Bad input into the loaders (issue 9, item 6): table-driven cases, fuzzing of every format and
hypothesis-generated inputs.

Every case must end in one of two ways:

* a :class:`fdikit.errors.DataError` whose message names the problem (checked by a pattern), or
* a :class:`fdikit.io.formats.LoadedSignals` where ``valid`` is exactly ``isfinite(values)`` (no NaN
  outside a flagged sample), and -- for the fuzzed files -- every sample the file holds of a
  requested channel is accounted for in ``info`` (``n_samples + n_duplicates + n_conflicts``),
  counted independently of the reader (regular expressions on text lines, pyarrow / csv / asammdf
  on tables), so nothing is dropped silently.

Any other exception type is a crash and fails the case. The data are the first 3 s of the real
RAV4 log (``../shared/data/rav4-highway``), converted in the test to BLF, ASC, candump, MDF4 (raw
CAN bus logging and decoded channels), Parquet and CSV.
"""

from __future__ import annotations

import csv
import random
import re
from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io.formats import LoadedSignals, read_log, series_to_grid

hypothesis = pytest.importorskip("hypothesis")
# asammdf's MDF4.__del__ complains about a file it failed to open (after raising); that noise is not ours
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
from hypothesis import HealthCheck, event, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rav4-highway"
BLF = DATA / "drive.blf"
DBC = DATA / "toyota_rav4.dbc"
needs_data = pytest.mark.skipif(not BLF.exists(), reason=f"real RAV4 data not found at {DATA}")

SIG = ["KINEMATICS.YAW_RATE", "SPEED.SPEED", "WHEEL_SPEEDS.WHEEL_SPEED_FL"]
IDS = {"KINEMATICS.YAW_RATE": 0x24, "SPEED.SPEED": 0xB4, "WHEEL_SPEEDS.WHEEL_SPEED_FL": 0xAA}
RATE = 100.0
EXCERPT = 3.0  # seconds of the real log
FRAME_FORMATS = ["blf", "asc", "candump", "mf4bus"]
TABLE_FORMATS = ["parquet", "csv", "mf4dec"]
ALL_FORMATS = FRAME_FORMATS + TABLE_FORMATS
SUFFIX = {"blf": ".blf", "asc": ".asc", "candump": ".log", "mf4bus": ".mf4", "parquet": ".parquet",
          "csv": ".csv", "mf4dec": ".mf4"}


# ------------------------------------------------------------------ writers
def write_frames(fmt, msgs, path):
    import can

    if fmt == "mf4bus":
        from asammdf import MDF, Signal
        from asammdf.blocks import v4_constants as v4c
        from asammdf.blocks.source_utils import Source

        n = len(msgs)
        dt = np.dtype([("CAN_DataFrame.BusChannel", "u1"), ("CAN_DataFrame.ID", "<u4"),
                       ("CAN_DataFrame.IDE", "u1"), ("CAN_DataFrame.DLC", "u1"),
                       ("CAN_DataFrame.DataLength", "u1"), ("CAN_DataFrame.DataBytes", "u1", (8,))])
        rec = np.zeros(n, dt)
        rec["CAN_DataFrame.BusChannel"] = [(m.channel or 0) + 1 for m in msgs]
        rec["CAN_DataFrame.ID"] = [m.arbitration_id for m in msgs]
        rec["CAN_DataFrame.DLC"] = [len(m.data) for m in msgs]
        rec["CAN_DataFrame.DataLength"] = [len(m.data) for m in msgs]
        rec["CAN_DataFrame.DataBytes"] = np.frombuffer(
            b"".join(bytes(m.data).ljust(8, b"\0")[:8] for m in msgs), "u1").reshape(n, 8)
        src = Source(name="CAN1", path="CAN1", comment="", source_type=v4c.SOURCE_BUS,
                     bus_type=v4c.BUS_TYPE_CAN)
        mdf = MDF(version="4.10")
        mdf.append([Signal(rec, np.array([m.timestamp for m in msgs]), name="CAN_DataFrame", source=src)],
                   acq_name="CAN1", acq_source=src)
        mdf.save(str(path), overwrite=True)
        mdf.close()
        return path
    cls = {"blf": can.BLFWriter, "asc": can.ASCWriter, "candump": can.CanutilsLogWriter}[fmt]
    with cls(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)
    return path


def write_table(fmt, series, path):
    """series: name -> (t, v); tables are sparse (null where a channel has no sample at that time)."""
    if fmt == "mf4dec":
        from asammdf import MDF, Signal

        mdf = MDF(version="4.10")
        for s, (t, v) in series.items():
            mdf.append([Signal(np.asarray(v, float), np.asarray(t, float), name=s, unit="")])
        mdf.save(str(path), overwrite=True)
        mdf.close()
        return path
    rows = sorted({(float(t), i, s, float(v)) for s, (tt, vv) in series.items()
                   for i, (t, v) in enumerate(zip(tt, vv, strict=True))}, key=lambda r: (r[0], r[1]))
    # one row per sample; rows of different channels at one time are separate (allowed: t repeats)
    if fmt == "parquet":  # pyarrow keeps a NaN value apart from a null (pandas would merge them)
        import pyarrow as pa
        import pyarrow.parquet as pq

        cols = {"t": pa.array([r[0] for r in rows], pa.float64())}
        for s in series:
            cols[s] = pa.array([r[3] if r[2] == s else 0.0 for r in rows], pa.float64(),
                               mask=np.array([r[2] != s for r in rows]))
        pq.write_table(pa.table(cols), path, write_page_checksum=True)
    else:
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", *series])
            for r in rows:
                w.writerow([repr(r[0])] + [_cell(r[3]) if r[2] == s else "" for s in series])
    return path


def _cell(x):
    return "nan" if np.isnan(x) else ("inf" if x == np.inf else ("-inf" if x == -np.inf else repr(x)))


def read(fmt, path, signals=SIG, **kw):
    """Read with the campaign's grid: linear interpolation (``method="linear"``, non-causal,
    on request), whose cell-by-cell rules the cases below check; the causal default is checked
    by ``test_default_grid_*`` at the end."""
    dbc = kw.pop("dbc", DBC)
    kw.setdefault("method", "linear")
    return read_log(path, dbc if fmt in FRAME_FORMATS else None, signals, rate=kw.pop("rate", RATE), **kw)


# ------------------------------------------------------------------ the invariant every case checks
def check(call, *, error: str | None = None):
    """Run a loader call; either a DataError matching ``error`` (when given) or sound data."""
    try:
        s = call()
    except DataError as exc:
        msg = str(exc)
        assert len(msg) >= 15, msg
        if error is not None:
            assert re.search(error, msg), f"error {msg!r} does not match {error!r}"
        return msg
    assert error is None, f"expected a DataError matching {error!r}, got data"
    assert isinstance(s, LoadedSignals)
    assert s.values.shape == (1, s.t.size, len(s.names))
    assert np.array_equal(s.valid, np.isfinite(s.values)), "NaN outside a flagged sample"
    assert np.all(np.diff(s.t) > 0)
    for c, n in enumerate(s.names):
        assert s.info[n].n_invalid == int((~s.valid[0, :, c]).sum())
    return s


def accounted(s, name):
    i = s.info[name]
    return i.n_samples + i.n_duplicates + i.n_conflicts


# ------------------------------------------------------------------ clean data
@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    if not BLF.exists():
        pytest.skip(f"real RAV4 data not found at {DATA}")
    import can
    import cantools

    d = tmp_path_factory.mktemp("bad")
    msgs = []
    t0 = None
    for m in can.LogReader(str(BLF)):
        t0 = m.timestamp if t0 is None else t0
        if m.timestamp - t0 > EXCERPT:
            break
        msgs.append(m)
    db = cantools.database.load_file(str(DBC), strict=False)
    series = {s: ([], []) for s in SIG}
    for m in msgs:
        for s in SIG:
            if m.arbitration_id == IDS[s]:
                dec = db.get_message_by_frame_id(IDS[s]).decode(bytes(m.data), decode_choices=False)
                series[s][0].append(m.timestamp - t0)
                series[s][1].append(float(dec[s.split(".")[1]]))
    series = {s: (np.array(a), np.array(b)) for s, (a, b) in series.items()}
    files = {}
    for fmt in FRAME_FORMATS:
        files[fmt] = write_frames(fmt, msgs, d / f"clean_{fmt}{SUFFIX[fmt]}")
    for fmt in TABLE_FORMATS:
        files[fmt] = write_table(fmt, series, d / f"clean_{fmt}{SUFFIX[fmt]}")
    clean = {fmt: read(fmt, files[fmt]) for fmt in ALL_FORMATS}
    return {"dir": d, "msgs": msgs, "series": series, "files": files, "clean": clean, "db": db, "t0": t0}


_n = [0]


def newpath(ctx, fmt, tag=""):
    _n[0] += 1
    return ctx["dir"] / f"case{_n[0]}{tag}{SUFFIX[fmt]}"


def mutate_frames(ctx, fmt, fn):
    return write_frames(fmt, fn(list(ctx["msgs"])), newpath(ctx, fmt))


def mutate_series(ctx, fmt, fn):
    series = {s: (t.copy(), v.copy()) for s, (t, v) in ctx["series"].items()}
    fn(series)
    return write_table(fmt, series, newpath(ctx, fmt))


def _copy_msg(m, **kw):
    import can

    a = {"timestamp": m.timestamp, "arbitration_id": m.arbitration_id, "data": bytes(m.data),
         "is_extended_id": m.is_extended_id, "channel": m.channel}
    a.update(kw)
    return can.Message(**a)


# ================================================================== A. NaN / inf values
def _bad_value_case(ctx, fmt, value, how="value"):
    s = "SPEED.SPEED"
    k = 60
    t_bad = ctx["series"][s][0][k]

    def fn(series):
        series[s][1][k] = value

    if how == "invalidation":
        from asammdf import MDF, Signal

        path = newpath(ctx, fmt)
        mdf = MDF(version="4.10")
        for name, (t, v) in ctx["series"].items():
            inv = np.zeros(t.size, bool)
            if name == s:
                inv[k] = True
            mdf.append([Signal(v, t, name=name, invalidation_bits=inv if name == s else None)])
        mdf.save(str(path), overwrite=True)
        mdf.close()
    else:
        path = mutate_series(ctx, fmt, fn)
    out = check(lambda: read(fmt, path))
    clean = ctx["clean"][fmt]
    t = ctx["series"][s][0]
    spoiled = (out.t > t[k - 1]) & (out.t < t[k + 1])  # grid samples interpolated with sample k
    c = out.names.index(s)
    assert np.array_equal(~out.valid[0, :, c], spoiled)
    assert np.array_equal(out.values[0, ~spoiled], clean.values[0, ~spoiled])
    assert out.info[s].n_nonfinite == 1 and out.info[s].n_samples == t.size
    assert t[k - 1] < t_bad < t[k + 1]


@needs_data
@pytest.mark.parametrize("fmt,value", [(f, v) for f in TABLE_FORMATS for v in (np.nan, np.inf, -np.inf)])
def test_nonfinite_value_is_flagged_at_its_neighbours_only(ctx, fmt, value):
    _bad_value_case(ctx, fmt, value)


@needs_data
def test_mdf_invalidation_bit_is_a_bad_sample(ctx):
    _bad_value_case(ctx, "mf4dec", 0.0, how="invalidation")


# ================================================================== B. dropouts and gaps
GAP = (1.0, 1.5)


@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_dropout_is_flagged_not_bridged(ctx, fmt):
    s = "WHEEL_SPEEDS.WHEEL_SPEED_FL"
    if fmt in FRAME_FORMATS:
        t0 = ctx["t0"]
        path = mutate_frames(ctx, fmt, lambda ms: [m for m in ms if not (
            m.arbitration_id == IDS[s] and GAP[0] <= m.timestamp - t0 <= GAP[1])])
    else:
        def fn(series):
            t, v = series[s]
            keep = ~((t >= GAP[0]) & (t <= GAP[1]))
            series[s] = (t[keep], v[keep])
        path = mutate_series(ctx, fmt, fn)
    out = check(lambda: read(fmt, path))
    c = out.names.index(s)
    t = ctx["series"][s][0]
    before, after = t[t < GAP[0]][-1], t[t > GAP[1]][0]
    inside = (out.t > before) & (out.t < after)
    assert np.array_equal(~out.valid[0, :, c], inside)
    assert out.valid[0, :, [i for i in range(3) if i != c]].all()
    assert out.info[s].n_gaps == 1
    assert out.info[s].n_samples == t.size - int(((t >= GAP[0]) & (t <= GAP[1])).sum())


# ================================================================== C. duplicated time stamps
@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_exact_duplicate_is_merged_and_counted(ctx, fmt):
    s = "SPEED.SPEED"
    if fmt in FRAME_FORMATS:
        def fn(ms):
            k = [i for i, m in enumerate(ms) if m.arbitration_id == IDS[s]][40]
            return [*ms[:k + 1], _copy_msg(ms[k]), *ms[k + 1:]]
        path = mutate_frames(ctx, fmt, fn)
    else:
        def fn(series):
            t, v = series[s]
            series[s] = (np.insert(t, 40, t[40]), np.insert(v, 40, v[40]))
        path = mutate_series(ctx, fmt, fn)
    out = check(lambda: read(fmt, path))
    assert out.info[s].n_duplicates == 1 and out.info[s].n_conflicts == 0
    clean = ctx["clean"][fmt]
    assert np.array_equal(out.values, clean.values) and out.valid.all()


@needs_data
@pytest.mark.parametrize("fmt", ["blf", "candump", "mf4bus", "parquet", "csv", "mf4dec"])
def test_same_time_different_value_is_a_flagged_conflict(ctx, fmt):
    s = "SPEED.SPEED"
    k = 40
    if fmt in FRAME_FORMATS:
        def fn(ms):
            i = [j for j, m in enumerate(ms) if m.arbitration_id == IDS[s]][k]
            other = bytearray(ms[i].data)
            other[5] ^= 0x10
            return [*ms[:i + 1], _copy_msg(ms[i], data=bytes(other)), *ms[i + 1:]]
        path = mutate_frames(ctx, fmt, fn)
    else:
        def fn(series):
            t, v = series[s]
            series[s] = (np.insert(t, k + 1, t[k]), np.insert(v, k + 1, v[k] + 40.96))
        path = mutate_series(ctx, fmt, fn)
    out = check(lambda: read(fmt, path))
    assert out.info[s].n_conflicts == 1
    t = ctx["series"][s][0]
    c = out.names.index(s)
    assert np.array_equal(~out.valid[0, :, c], (out.t > t[k - 1]) & (out.t < t[k + 1]))


# ================================================================== D. non-monotonic time
def _swap_text_lines(path, out, pick):
    lines = Path(path).read_text().splitlines(keepends=True)
    i = pick(lines)
    lines[i], lines[i + 1] = lines[i + 1], lines[i]
    Path(out).write_text("".join(lines))
    return out


@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_time_going_backwards_is_refused(ctx, fmt):
    if fmt in ("asc", "candump"):
        pat = re.compile(r"^\s*\d+\.\d+\s+1\s+" if fmt == "asc" else r"^\(")
        src = ctx["files"][fmt]

        def pick(lines):
            frames = [i for i, ln in enumerate(lines) if pat.match(ln)]
            for i in frames[500:]:  # two consecutive frames with different times
                if lines[i].split()[0] != lines[i + 1].split()[0]:
                    return i
            raise AssertionError("no pair")

        path = _swap_text_lines(src, newpath(ctx, fmt), pick)
        error = r"goes backwards at frame \d+ \(line \d+\)"
    elif fmt in FRAME_FORMATS:
        def fn(ms):
            for i in range(500, len(ms)):
                if ms[i + 1].timestamp > ms[i].timestamp:
                    ms[i], ms[i + 1] = ms[i + 1], ms[i]
                    return ms
        path = mutate_frames(ctx, fmt, fn)
        error = "goes backwards"
    elif fmt == "csv":
        path = _swap_text_lines(ctx["files"][fmt], newpath(ctx, fmt), lambda lines: 300)
        error = r"time column 't' goes backwards at row 300"
    elif fmt == "parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(ctx["files"][fmt])
        order = np.arange(table.num_rows)
        order[[300, 301]] = [301, 300]
        path = newpath(ctx, fmt)
        pq.write_table(table.take(order), path)
        error = r"time column 't' goes backwards at row 301"
    else:
        def fn(series):
            t, _v = series["SPEED.SPEED"]
            t[[30, 31]] = t[[31, 30]]
        path = mutate_series(ctx, fmt, fn)
        error = "time of signal 'SPEED.SPEED' goes backwards at sample 31"
    check(lambda: read(fmt, path), error=error)


# ================================================================== E. a missing channel
@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_missing_channel_is_refused_by_name(ctx, fmt):
    if fmt in FRAME_FORMATS:
        path = mutate_frames(ctx, fmt, lambda ms: [m for m in ms if m.arbitration_id != 0xB4])
        error = r"no frame of message 'SPEED'"
    else:
        path = mutate_series(ctx, fmt, lambda series: series.pop("SPEED.SPEED"))
        error = r"no channel 'SPEED.SPEED'"
    check(lambda: read(fmt, path), error=error)
    # a typo gets close matches
    check(lambda: read(fmt, ctx["files"][fmt], ["SPEED.SPEEED"]),
          error=r"did you mean \['SPEED'\]|did you mean \['SPEED.SPEED'\]")


# ================================================================== F. a stuck signal
@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_stuck_signal_is_reported_in_info(ctx, fmt):
    s = "KINEMATICS.YAW_RATE"
    window = (0.5, 2.2)
    if fmt in FRAME_FORMATS:
        t0 = ctx["t0"]

        def fn(ms):
            frozen = None
            out = []
            for m in ms:
                if m.arbitration_id == IDS[s] and window[0] <= m.timestamp - t0 <= window[1]:
                    frozen = frozen or bytes(m.data)
                    m = _copy_msg(m, data=frozen)
                out.append(m)
            return out
        path = mutate_frames(ctx, fmt, fn)
    else:
        def fn(series):
            t, v = series[s]
            w = (t >= window[0]) & (t <= window[1])
            v[w] = v[w][0]
        path = mutate_series(ctx, fmt, fn)
    out = check(lambda: read(fmt, path, stuck_after=1.5))
    assert out.info[s].stuck and out.info[s].longest_constant >= 1.65
    assert out.valid.all()
    assert not ctx["clean"][fmt].info[s].longest_constant >= 1.5  # the real yaw rate moves


# ================================================================== G. wrong units
@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_impossible_unit_conversion_is_refused(ctx, fmt):
    kw = {"source_units": {"SPEED.SPEED": "km/h"}} if fmt in ("parquet", "csv") else {}
    if fmt == "mf4dec":
        from asammdf import MDF, Signal

        path = newpath(ctx, fmt)
        mdf = MDF(version="4.10")
        t, v = ctx["series"]["SPEED.SPEED"]
        mdf.append([Signal(v, t, name="SPEED.SPEED", unit="km/h")])
        mdf.save(str(path), overwrite=True)
        mdf.close()
    else:
        path = ctx["files"][fmt]
    check(lambda: read(fmt, path, ["SPEED.SPEED"], units={"SPEED.SPEED": "rad"}, **kw),
          error=r"cannot convert channel 'SPEED.SPEED' from unit 'km/h' to 'rad'")


@needs_data
def test_unit_conventions(ctx, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t, v = ctx["series"]["SPEED.SPEED"]
    table = pa.table({"t": t, "speed": v}).cast(pa.schema([
        pa.field("t", pa.float64()), pa.field("speed", pa.float64(), metadata={"unit": "mph"})]))
    pq.write_table(table, tmp_path / "mph.parquet")
    out = check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], rate=RATE, units="si"))
    raw = check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], rate=RATE))
    assert out.units == ["m/s"] and raw.units == ["mph"]
    np.testing.assert_allclose(out.values, raw.values * 0.44704, rtol=1e-15)
    check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], units={"speed": "furlong/fortnight"}),
          error="cannot convert")
    check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], units={"other": "m/s"}),
          error="not a requested signal")
    check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], units="imperial"),
          error="units must be 'si' or a mapping")
    check(lambda: read_log(tmp_path / "mph.parquet", signals=["speed"], source_units={"nope": "m"}),
          error="'nope', which is not a column")
    # a table without units: a requested conversion cannot be guessed
    check(lambda: read("csv", ctx["files"]["csv"], ["SPEED.SPEED"], units={"SPEED.SPEED": "m/s"}),
          error=r"cannot convert channel 'SPEED.SPEED' from unit '' to 'm/s'")
    # an option of another format is refused by name, not a TypeError
    check(lambda: read("candump", ctx["files"]["candump"], time="t"),
          error=r"option\(s\) \['time'\] do not apply to a candump log")


# ================================================================== H. truncated, corrupt, empty, not a log
def _bytes_case(ctx, fmt, fn, tag):
    data = Path(ctx["files"][fmt]).read_bytes()
    p = newpath(ctx, fmt, tag)
    p.write_bytes(fn(data))
    return p


TRUNC_ERRORS = {
    "blf": r"truncated|corrupt|not a valid BLF",
    "asc": r"truncated|line \d+",
    "mf4bus": r"not a readable MDF|damaged|cannot be read",
    "mf4dec": r"not a readable MDF|damaged|cannot be read",
    "parquet": r"not a readable Parquet",
}


@needs_data
@pytest.mark.parametrize("fmt", list(TRUNC_ERRORS))
@pytest.mark.parametrize("frac", [0.5, 0.9, 0.01])
def test_truncated_file_is_refused(ctx, fmt, frac):
    p = _bytes_case(ctx, fmt, lambda b: b[: int(len(b) * frac)], "trunc")
    check(lambda: read(fmt, p), error=TRUNC_ERRORS[fmt])


@needs_data
def test_truncated_text_tables_and_candump(ctx):
    # CSV cut inside a line: the last row has too few fields
    data = Path(ctx["files"]["csv"]).read_text()
    cut = data.rindex("\n", 0, len(data) - 2) + 5
    p = newpath(ctx, "csv")
    p.write_text(data[:cut])
    check(lambda: read("csv", p), error=r"line \d+ has \d+ fields, the header has 4")
    # candump cut inside the data of a frame: a short payload, flagged, never zero-padded
    lines = Path(ctx["files"]["candump"]).read_text().splitlines(keepends=True)
    i = max(k for k, ln in enumerate(lines) if " 0B4#" in ln)
    p = newpath(ctx, "candump")
    p.write_text("".join(lines[:i]) + lines[i][: lines[i].index("#") + 7])
    out = check(lambda: read("candump", p, span="log"))
    assert out.info["SPEED.SPEED"].n_undecodable == 1
    assert not out.valid[0, -1, out.names.index("SPEED.SPEED")]
    # candump cut at a line boundary is a valid shorter log (nothing to detect): it reads, shorter
    p = newpath(ctx, "candump")
    p.write_text("".join(lines[: len(lines) // 2]))
    out = check(lambda: read("candump", p))
    assert out.t[-1] < ctx["clean"]["candump"].t[-1] - 1.0


@needs_data
@pytest.mark.parametrize("fmt", ALL_FORMATS)
def test_empty_file_is_refused(ctx, fmt):
    p = newpath(ctx, fmt, "empty")
    p.write_bytes(b"")
    check(lambda: read(fmt, p), error=r"is empty \(0 bytes\)")


@needs_data
@pytest.mark.parametrize("case", ["missing", "directory", "garbage.asc", "garbage.log", "garbage.blf",
                                  "garbage.mf4", "garbage.parquet", "latin1.asc", "header-only.csv",
                                  "text-cell.csv", "no-time.parquet", "string-column.parquet"])
def test_not_a_log(ctx, case, tmp_path):
    p = tmp_path / case
    if case == "missing":
        p = tmp_path / "nothing.blf"
        error = "does not exist"
    elif case == "directory":
        p = tmp_path / "dir.asc"
        p.mkdir()
        error = "is a directory"
    elif case.startswith("garbage"):
        p.write_bytes(bytes(random.Random(1).randrange(256) for _ in range(5000)))
        error = r"not a valid BLF|not text|not a readable|cannot be parsed|neither a CAN frame|line 1"
    elif case == "latin1.asc":
        text = Path(ctx["files"]["asc"]).read_text().splitlines(keepends=True)
        text.insert(3, "// Fahrt über die Brücke\n")
        p.write_bytes("".join(text).encode("latin-1"))
        error = r"not utf-8 text: undecodable byte b'\\xfc' at offset \d+, line 4"
    elif case == "header-only.csv":
        p.write_text("t,SPEED.SPEED\n")
        error = "no rows"
    elif case == "text-cell.csv":
        p.write_text("t,SPEED.SPEED\n0.0,1.0\n0.1,fast\n0.2,3.0\n")
        error = r"line 3, column 'SPEED.SPEED': 'fast' is not a number"
    elif case == "no-time.parquet":
        import pandas as pd

        pd.DataFrame({"when": [0.0, 1.0], "SPEED.SPEED": [1.0, 2.0]}).to_parquet(p)
        error = r"no time column .*pass time="
    else:
        import pandas as pd

        pd.DataFrame({"t": [0.0, 1.0], "SPEED.SPEED": ["a", "b"]}).to_parquet(p)
        error = "not numeric"
    dbc = DBC if Path(case).suffix in (".asc", ".log", ".blf", ".mf4") else None
    check(lambda: read_log(p, dbc, ["SPEED.SPEED"], rate=RATE), error=error)
    if case == "latin1.asc":  # with its encoding named, the same file reads
        s = check(lambda: read_log(p, dbc, ["SPEED.SPEED"], rate=RATE, encoding="latin-1", method="linear"))
        assert s.equals(read("asc", ctx["files"]["asc"], ["SPEED.SPEED"]))


@needs_data
@pytest.mark.parametrize("fmt", ["blf", "asc", "mf4bus", "parquet"])
def test_corrupt_file_is_refused(ctx, fmt):
    if fmt == "blf":  # one flipped byte inside the compressed container: zlib's check fails
        p = _bytes_case(ctx, fmt, lambda b: b[:3000] + bytes([b[3000] ^ 0xFF]) + b[3001:], "flip")
        error = r"corrupt"
    elif fmt == "asc":  # a frame line whose direction is damaged
        lines = Path(ctx["files"]["asc"]).read_text().splitlines(keepends=True)
        lines[200] = lines[200].replace("Rx", "R#")
        p = newpath(ctx, fmt)
        p.write_text("".join(lines))
        error = r"line 201 is neither a CAN frame"
    elif fmt == "mf4bus":  # the identification block
        p = _bytes_case(ctx, fmt, lambda b: b"XXXXXXXX" + b[8:], "id")
        error = r"not a readable MDF"
    else:  # the footer's magic
        p = _bytes_case(ctx, fmt, lambda b: b[:-4] + b"PAR2", "magic")
        error = r"not a readable Parquet"
    check(lambda: read(fmt, p), error=error)


# ================================================================== I. a DBC that lacks a signal
@pytest.fixture(scope="module")
def dbc_no_yaw(tmp_path_factory):
    if not DBC.exists():
        pytest.skip("no DBC")
    text = DBC.read_text()
    lines = [ln for ln in text.splitlines() if not ln.strip().startswith("SG_ YAW_RATE ")]
    p = tmp_path_factory.mktemp("dbc") / "no_yaw.dbc"
    p.write_text("\n".join(lines) + "\n")
    return p


@needs_data
@pytest.mark.parametrize("fmt", FRAME_FORMATS)
def test_dbc_without_the_signal(ctx, fmt, dbc_no_yaw):
    check(lambda: read(fmt, ctx["files"][fmt], dbc=dbc_no_yaw),
          error=r"message 'KINEMATICS' \(id 0x24\) has no signal 'YAW_RATE'; its signals are .*ACCEL_X")
    out = check(lambda: read(fmt, ctx["files"][fmt], ["KINEMATICS.ACCEL_X"], dbc=dbc_no_yaw))
    assert out.names == ["KINEMATICS.ACCEL_X"] and out.valid.all()


@needs_data
@pytest.mark.parametrize("fmt", FRAME_FORMATS)
def test_unknown_message_and_bad_dbc(ctx, fmt, tmp_path):
    check(lambda: read(fmt, ctx["files"][fmt], ["KINEMATIC.YAW_RATE"]),
          error=r"no message 'KINEMATIC'.*KINEMATICS")
    check(lambda: read(fmt, ctx["files"][fmt], dbc=tmp_path / "none.dbc"), error="DBC file .* does not exist")
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a DBC\n SG_ ???\n")
    check(lambda: read(fmt, ctx["files"][fmt], dbc=bad), error=r"cannot parse DBC|no message")


# ================================================================== J. payloads too short
@needs_data
@pytest.mark.parametrize("fmt", FRAME_FORMATS)
def test_short_payload_is_flagged(ctx, fmt):
    s = "SPEED.SPEED"
    k = 50

    def fn(ms):
        i = [j for j, m in enumerate(ms) if m.arbitration_id == IDS[s]][k]
        ms[i] = _copy_msg(ms[i], data=bytes(ms[i].data)[:4], dlc=4)
        return ms

    path = mutate_frames(ctx, fmt, fn)
    out = check(lambda: read(fmt, path))
    # (the MDF stores 8 data bytes with DataLength 4: asammdf would decode all 8; the reader must not)
    t = ctx["series"][s][0]
    c = out.names.index(s)
    assert out.info[s].n_undecodable == 1
    assert np.array_equal(~out.valid[0, :, c], (out.t > t[k - 1]) & (out.t < t[k + 1]))


# ================================================================== J2. two buses in one log
@needs_data
@pytest.mark.parametrize("fmt", ["asc", "candump", "mf4bus"])
def test_two_buses_are_never_mixed(ctx, fmt):
    both = sorted([_copy_msg(m, channel=0) for m in ctx["msgs"]]
                  + [_copy_msg(m, channel=1, timestamp=m.timestamp + 1e-4) for m in ctx["msgs"]],
                  key=lambda m: m.timestamp)
    path = write_frames(fmt, both, newpath(ctx, fmt))
    check(lambda: read(fmt, path), error=r"on (several|more than one CAN) bus.*pass channel=")
    first = {"asc": 1, "candump": "can0", "mf4bus": 1}[fmt]
    second = {"asc": 2, "candump": "can1", "mf4bus": 2}[fmt]
    a = check(lambda: read(fmt, path, channel=first))
    assert np.array_equal(a.values, ctx["clean"][fmt].values) and np.array_equal(a.t, ctx["clean"][fmt].t)
    b = check(lambda: read(fmt, path, channel=second))
    for n in SIG:  # the second bus: same frames 0.1 ms later
        assert b.info[n].n_samples == a.info[n].n_samples
        assert b.info[n].t_first == pytest.approx(a.info[n].t_first + 1e-4, abs=1e-6)
    if fmt != "mf4bus":
        check(lambda: read(fmt, path, channel="can7"), error="no frame on channel 'can7'")


# ================================================================== K. bad arguments
BAD_ARGS = [
    ({"rate": 0.0}, "positive number of Hz"), ({"rate": -5.0}, "positive number of Hz"),
    ({"rate": float("nan")}, "positive number of Hz"), ({"rate": "fast"}, "positive number of Hz"),
    ({"max_gap": 0.0}, "max_gap must be a positive"),
    ({"max_gap": float("inf")}, "max_gap must be a positive"),
    ({"method": "cubic"}, "unknown resampling method"), ({"span": "all"}, "span must be 'common' or 'log'"),
    ({"signals": []}, "no signals requested"),
    ({"signals": ["SPEED.SPEED", "SPEED.SPEED"]}, "requested twice"),
    ({"signals": [3]}, "must be strings"),
]


@needs_data
@pytest.mark.parametrize("fmt", ["candump", "parquet"])
@pytest.mark.parametrize("kw,error", BAD_ARGS,
                         ids=[f"{next(iter(k))}={next(iter(k.values()))!r}" for k, _ in BAD_ARGS])
def test_bad_arguments(ctx, fmt, kw, error):
    kw = dict(kw)
    signals = kw.pop("signals", SIG)
    check(lambda: read(fmt, ctx["files"][fmt], signals, **kw), error=error)


# ================================================================== L. fuzzing every format
def _count_independent(fmt, path, name):
    """Samples of ``name`` that the file holds, counted without fdikit's reader."""
    fid = IDS[name]
    if fmt == "asc":
        pat = re.compile(rf"^\s*\d+\.\d+\s+\d+\s+{fid:X}\s+Rx\s+d\s")
        return sum(1 for ln in Path(path).read_text().splitlines() if pat.match(ln))
    if fmt == "candump":
        pat = re.compile(rf"^\(\S+\)\s+\S+\s+{fid:03X}#[0-9A-Fa-f]*\s")
        return sum(1 for ln in Path(path).read_text().splitlines() if pat.match(ln + " "))
    if fmt == "blf":
        import can

        return sum(1 for m in can.BLFReader(str(path)) if m.arbitration_id == fid)
    if fmt == "mf4bus":
        from asammdf import MDF

        with MDF(str(path)) as m:
            return int(np.sum((m.get("CAN_DataFrame.ID").samples & 0x1FFFFFFF) == fid))
    if fmt == "mf4dec":
        from asammdf import MDF

        with MDF(str(path)) as m:
            return int(m.get(name).samples.size)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        col = pq.read_table(path).column(name)
        return len(col) - col.null_count
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    j = rows[0].index(name)
    return sum(1 for r in rows[1:] if r[j].strip())


def _fuzz(data: bytes, op: str, seed: int, text: bool) -> bytes:
    r = random.Random(seed)
    if op == "truncate":
        return data[: r.randrange(1, len(data))]
    if op == "corrupt":
        b = bytearray(data)
        for _ in range(r.choice([1, 3, 20])):
            b[r.randrange(len(b))] = r.randrange(256)
        return bytes(b)
    if op == "zero-block":
        b = bytearray(data)
        a = r.randrange(len(b))
        b[a: a + r.randrange(8, 512)] = bytes(min(len(b) - a, 512))[: len(b[a: a + 512])]
        return bytes(b)
    if op == "append-garbage":
        return data + bytes(r.randrange(256) for _ in range(r.randrange(1, 200)))
    lines = data.decode().splitlines(keepends=True)
    i = r.randrange(1, len(lines) - 2)
    if op == "swap-lines":
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
    elif op == "shuffle-block":
        blk = lines[i: i + 20]
        r.shuffle(blk)
        lines[i: i + 20] = blk
    elif op == "drop-line":
        del lines[i]
    elif op == "duplicate-line":
        lines.insert(i, lines[i])
    elif op == "corrupt-char":
        ln = lines[i]
        if len(ln) > 2:
            k = r.randrange(len(ln) - 1)
            lines[i] = ln[:k] + r.choice("0123456789ABCDEFxg#.-() \t") + ln[k + 1:]
    return "".join(lines).encode()


TEXT_OPS = ["truncate", "corrupt-char", "swap-lines", "shuffle-block", "drop-line", "duplicate-line"]
BIN_OPS = ["truncate", "corrupt", "zero-block", "append-garbage"]
FUZZ = ([(f, op, seed) for f in ("asc", "candump", "csv") for op in TEXT_OPS for seed in range(3)]
        + [(f, op, seed) for f in ("blf", "mf4bus", "mf4dec", "parquet") for op in BIN_OPS
           for seed in range(4)])


@needs_data
@pytest.mark.parametrize("fmt,op,seed", FUZZ, ids=[f"{f}-{o}-{s}" for f, o, s in FUZZ])
def test_fuzzed_file(ctx, fmt, op, seed):
    data = Path(ctx["files"][fmt]).read_bytes()
    p = newpath(ctx, fmt, f"fuzz-{op}")
    p.write_bytes(_fuzz(data, op, seed, fmt in ("asc", "candump", "csv")))
    out = check(lambda: read(fmt, p, span="log"))
    if isinstance(out, str):
        return
    for name in SIG:  # nothing dropped silently: every sample in the file is accounted for
        assert accounted(out, name) == _count_independent(fmt, p, name), name


# ================================================================== M. hypothesis-generated inputs
HYP = settings(max_examples=60, deadline=None, derandomize=True, database=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _merge(t, v):
    """Same-time samples: equal -> one, different -> one NaN (the documented rule), by a loop."""
    tt, vv = [], []
    for a, b in zip(t, v, strict=True):
        if tt and a == tt[-1]:
            same = (b == vv[-1]) or (np.isnan(b) and np.isnan(vv[-1]))
            vv[-1] = vv[-1] if same else np.nan
        else:
            tt.append(a)
            vv.append(b)
    return np.array(tt), np.array(vv)


def _brute_grid(t, v, grid, max_gap, method):
    """Validity and value of each grid sample by a plain loop over the source samples."""
    n = t.size
    period = float(np.median(np.diff(t))) if n > 1 else np.inf
    lim = max_gap * period
    val = np.full(grid.size, np.nan)
    tol = 1e-9 * max(1.0, abs(grid[-1]))  # documented: 1 ns outside the samples is the end sample
    for g_i, g0 in enumerate(grid):
        g = t[-1] if 0 < g0 - t[-1] <= tol else (t[0] if 0 < t[0] - g0 <= tol else g0)
        prev = [i for i in range(n) if t[i] <= (g + 1e-9 if method == "previous" else g)]
        if not prev:
            continue
        i = prev[-1]
        if method == "previous":
            if g - t[i] <= lim and np.isfinite(v[i]):
                val[g_i] = v[i]
            continue
        if g > t[-1]:
            continue
        if i == n - 1:
            val[g_i] = v[i] if np.isfinite(v[i]) else np.nan
            continue
        span = t[i + 1] - t[i]
        if span > lim and t[i] != g:
            continue
        w = (g - t[i]) / span
        if not np.isfinite(v[i]) or (w > 0 and not np.isfinite(v[i + 1])):
            continue
        val[g_i] = v[i] if w == 0 else v[i] + w * (v[i + 1] - v[i])
    return val


_values = st.one_of(st.floats(-1e3, 1e3, allow_nan=False), st.floats(-1e3, 1e3, allow_nan=False),
                    st.floats(-1e3, 1e3, allow_nan=False), st.floats(-1e3, 1e3, allow_nan=False),
                    st.just(np.nan), st.just(np.inf), st.just(-np.inf))


@st.composite
def _series(draw):
    n = draw(st.integers(1, 40))
    steps = draw(st.lists(st.sampled_from([0.0, 0.01, 0.01, 0.01, 0.02, 0.05, 0.3]), min_size=n - 1,
                          max_size=n - 1))
    t = np.round(np.concatenate([[0.0], np.cumsum(steps)]), 6)
    v = np.array(draw(st.lists(_values, min_size=n, max_size=n)), float)
    return t, v


@HYP
@given(_series(), st.sampled_from([10.0, 50.0, 100.0, 33.3]), st.sampled_from([1.5, 3.0, 10.0]),
       st.sampled_from(["linear", "previous"]))
def test_hypothesis_series_to_grid_equals_brute_force(ser, rate, max_gap, method):
    t, v = ser
    call = lambda: series_to_grid({"x": (t, v)}, {"x": ""}, rate, max_gap=max_gap,  # noqa: E731
                                  method=method, span="log")
    tm, vm = _merge(t, v)
    event(f"nonfinite={not np.isfinite(v).all()}, repeats={bool(np.any(np.diff(t) == 0))}")
    out = check(call)
    ref = _brute_grid(tm, vm, out.t, max_gap, method)
    assert np.array_equal(np.isfinite(ref), out.valid[0, :, 0])
    np.testing.assert_allclose(out.values[0, :, 0], ref, rtol=1e-12, atol=1e-12, equal_nan=True)
    assert accounted(out, "x") == t.size


_SPEED = 0xB4


@st.composite
def _candump(draw):
    n = draw(st.integers(1, 30))
    back = draw(st.integers(0, 3)) == 0  # time may go backwards in about 1 example of 4
    lines, frames = [], []
    t = 1000.0
    for _ in range(n):
        t = round(t + draw(st.sampled_from([0.0, 0.01, 0.01, 0.024, 0.2] + ([-0.01] if back else []))), 6)
        data = bytes(draw(st.lists(st.integers(0, 255), min_size=0, max_size=8)))
        fid = draw(st.sampled_from([_SPEED, _SPEED, _SPEED, 0x24]))
        lines.append(f"({t:.6f}) can0 {fid:03X}#{data.hex().upper()} R\n")
        frames.append((t, fid, data))
    return "".join(lines), frames


@needs_data  # reads the RAV4 DBC
@HYP
@given(_candump())
def test_hypothesis_candump_lines(tmp_path_factory, gen):
    text, frames = gen
    p = tmp_path_factory.mktemp("hyp") / "h.log"
    p.write_text(text)
    ts = np.array([f[0] for f in frames])
    sp = [f for f in frames if f[1] == _SPEED]
    event("backwards" if np.any(np.diff(ts) < 0) else ("no SPEED" if not sp else "data"))
    if np.any(np.diff(ts) < 0):
        check(lambda: read_log(p, DBC, ["SPEED.SPEED"], rate=50.0), error="goes backwards")
        return
    if not sp:
        check(lambda: read_log(p, DBC, ["SPEED.SPEED"], rate=50.0), error="no frame of message 'SPEED'")
        return
    out = check(lambda: read_log(p, DBC, ["SPEED.SPEED"], rate=50.0, span="log"))
    # SPEED: bytes 5..6 big-endian * 0.01 km/h (by hand); a payload shorter than 7 bytes is a bad sample
    t = np.array([f[0] for f in sp]) - ts[0]
    v = np.array([((d[5] << 8) | d[6]) * 0.01 if len(d) >= 7 else np.nan for _, _, d in sp])
    tm, vm = _merge(t, v)
    ref = _brute_grid(tm, vm, out.t, 3.0, "previous")
    assert np.array_equal(np.isfinite(ref), out.valid[0, :, 0])
    np.testing.assert_allclose(out.values[0, :, 0], ref, rtol=1e-12, atol=1e-12, equal_nan=True)
    assert accounted(out, "SPEED.SPEED") == len(sp)
    assert out.info["SPEED.SPEED"].n_undecodable == sum(len(d) < 7 for _, _, d in sp)


_good_cells = st.sampled_from(["", "1.5", "-2", "3e2", " 7 ", "0.25", "nan", "inf", "-inf"])
_bad_cells = st.sampled_from(["abc", "0x10", "1;5", "--1"])


@st.composite
def _csv_rows(draw):
    """Rows (time step, cell a, cell b, number of fields); each kind of damage in about 1 example of 4."""
    n = draw(st.integers(1, 25))
    back, bad_cell, bad_fields = (draw(st.integers(0, 3)) == 0 for _ in range(3))
    rows = []
    for _ in range(n):
        dt = draw(st.sampled_from([0.0, 0.01, 0.02] + ([-0.01] if back else [])))
        a, b = draw(_good_cells), draw(_good_cells)
        if bad_cell and draw(st.integers(0, 2)) == 0:
            a = draw(_bad_cells)
        nf = draw(st.sampled_from([2, 4])) if bad_fields and draw(st.integers(0, 5)) == 0 else 3
        rows.append((dt, a, b, nf))
    return rows


@HYP
@given(_csv_rows())
def test_hypothesis_csv_tables(tmp_path_factory, rows):
    lines = ["t,a,b"]
    t = 0.0
    expect_error = None
    times = []
    for i, (dt, a, b, nf) in enumerate(rows):
        t = round(t + dt, 6)
        times.append(t)
        fields = [repr(t), a, b][:nf] if nf <= 3 else [repr(t), a, b, "x"]
        lines.append(",".join(fields))
        if expect_error is None and len(fields) != 3:
            expect_error = rf"line {i + 2} has {len(fields)} fields"
    p = tmp_path_factory.mktemp("hyp") / "h.csv"
    p.write_text("\n".join(lines) + "\n")
    # the reader checks: field counts, then the time column, then the channels' cells
    if expect_error is None and np.any(np.diff(times) < 0):
        k = int(np.flatnonzero(np.diff(times) < 0)[0]) + 1
        expect_error = rf"goes backwards at row {k} \(line {k + 2}\)"
    if expect_error is None:
        for j, name in enumerate("ab"):
            for i, r in enumerate(rows):
                x = r[1 + j].strip()
                if x and x not in ("nan", "inf", "-inf") and not re.fullmatch(r"-?\d+(\.\d+)?(e\d+)?", x):
                    expect_error = expect_error or rf"line {i + 2}, column '{name}'"
    cells = {n: [(times[i], r[1 + j].strip()) for i, r in enumerate(rows) if r[1 + j].strip()]
             for j, n in enumerate("ab")}
    if expect_error is None and not all(cells.values()):
        expect_error = "has no samples"
    event("error: " + expect_error.split(" ")[-1] if expect_error else "data")
    if expect_error is not None:
        check(lambda: read_log(p, signals=["a", "b"], rate=20.0, span="log"), error=expect_error)
        return
    out = check(lambda: read_log(p, signals=["a", "b"], rate=20.0, span="log"))
    for c, n in enumerate("ab"):
        tm, vm = _merge(np.array([x for x, _ in cells[n]]), np.array([float(y) for _, y in cells[n]]))
        ref = _brute_grid(tm, vm, out.t, 3.0, "previous")
        assert np.array_equal(np.isfinite(ref), out.valid[0, :, c])
        np.testing.assert_allclose(out.values[0, :, c], ref, rtol=1e-12, atol=1e-12, equal_nan=True)
        assert accounted(out, n) == len(cells[n])


@HYP
@given(st.lists(st.tuples(st.sampled_from([0.0, 0.01, 0.05]), st.one_of(st.none(), _values)),
                min_size=1, max_size=30))
def test_hypothesis_parquet_nulls_and_nonfinite(tmp_path_factory, rows):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.round(np.cumsum([dt for dt, _ in rows]), 6)
    vals = [x for _, x in rows]
    p = tmp_path_factory.mktemp("hyp") / "h.parquet"
    pq.write_table(pa.table({"t": pa.array(t), "x": pa.array(vals, type=pa.float64())}), p)
    present = [x is not None for x in vals]
    event(f"nonfinite={sum(x is not None and not np.isfinite(x) for x in vals) > 0}")
    if not any(present):
        check(lambda: read_log(p, signals=["x"], rate=20.0), error="has no samples")
        return
    out = check(lambda: read_log(p, signals=["x"], rate=20.0, span="log"))
    tm, vm = _merge(t[present], np.array([x for x in vals if x is not None], float))
    ref = _brute_grid(tm, vm, out.t, 3.0, "previous")
    assert np.array_equal(np.isfinite(ref), out.valid[0, :, 0])
    np.testing.assert_allclose(out.values[0, :, 0], ref, rtol=1e-12, atol=1e-12, equal_nan=True)
    assert accounted(out, "x") == sum(present)
