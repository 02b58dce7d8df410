"""fdikit.io.formats: the real RAV4 minute converted to ASC, candump, MDF4 (raw CAN and decoded),
Parquet and CSV tables in the test, each read back onto the same grid as the BLF path."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import LogSignals, read_can_log
from fdikit.io.formats import (
    LoadedSignals,
    SignalQuality,
    detect_format,
    frames_to_signals,
    read_asc,
    read_log,
    read_mdf,
    read_parquet,
    read_table_csv,
    series_to_grid,
)

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rav4-highway"
BLF = DATA / "drive.blf"
DBC = DATA / "toyota_rav4.dbc"
needs_data = pytest.mark.skipif(not BLF.exists(), reason=f"real RAV4 data not found at {DATA}")

SIGNALS = [
    "KINEMATICS.YAW_RATE", "KINEMATICS.ACCEL_X", "WHEEL_SPEEDS.WHEEL_SPEED_FL",
    "WHEEL_SPEEDS.WHEEL_SPEED_RR", "STEER_ANGLE_SENSOR.STEER_ANGLE", "BRAKE_MODULE.BRAKE_PRESSURE",
    "ENGINE_RPM.RPM", "GAS_PEDAL.GAS_PEDAL", "SPEED.SPEED",
]
RATE = 50.0


# ------------------------------------------------------------------ writers used by the tests
def frames_of(path):
    import can

    return [m for m in can.LogReader(str(path))]


def write_asc(msgs, path):
    import can

    with can.ASCWriter(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)


def write_candump(msgs, path):
    import can

    with can.CanutilsLogWriter(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)


def write_mf4_bus(msgs, path, t0=None):
    """Raw CAN frames as an MDF4 bus-logging group (CAN_DataFrame structure, bus event flag)."""
    from asammdf import MDF, Signal
    from asammdf.blocks import v4_constants as v4c
    from asammdf.blocks.source_utils import Source

    n = len(msgs)
    dt = np.dtype([("CAN_DataFrame.BusChannel", "u1"), ("CAN_DataFrame.ID", "<u4"),
                   ("CAN_DataFrame.IDE", "u1"), ("CAN_DataFrame.DLC", "u1"),
                   ("CAN_DataFrame.DataLength", "u1"), ("CAN_DataFrame.DataBytes", "u1", (8,))])
    rec = np.zeros(n, dt)
    rec["CAN_DataFrame.BusChannel"] = 1
    rec["CAN_DataFrame.ID"] = [m.arbitration_id for m in msgs]
    rec["CAN_DataFrame.DLC"] = [len(m.data) for m in msgs]
    rec["CAN_DataFrame.DataLength"] = [len(m.data) for m in msgs]
    rec["CAN_DataFrame.DataBytes"] = np.frombuffer(
        b"".join(bytes(m.data).ljust(8, b"\0") for m in msgs), "u1").reshape(n, 8)
    src = Source(name="CAN1", path="CAN1", comment="", source_type=v4c.SOURCE_BUS, bus_type=v4c.BUS_TYPE_CAN)
    t = np.array([m.timestamp for m in msgs]) - (msgs[0].timestamp if t0 is None else t0)
    mdf = MDF(version="4.10")
    mdf.append([Signal(rec, t, name="CAN_DataFrame", source=src)], acq_name="CAN1", acq_source=src)
    mdf.save(str(path), overwrite=True)
    mdf.close()


def decode_by_frame(msgs, signals, dbc=DBC):
    """Per requested signal: (time from the first frame of the log, value) of every frame, by cantools."""
    import cantools

    db = cantools.database.load_file(str(dbc), strict=False)
    t0 = msgs[0].timestamp
    wanted = {}
    for s in signals:
        m, sig = s.split(".")
        wanted.setdefault(db.get_message_by_name(m).frame_id, []).append((s, sig))
    out = {s: ([], []) for s in signals}
    for m in msgs:
        if m.arbitration_id not in wanted:
            continue
        msg = db.get_message_by_frame_id(m.arbitration_id)
        d = msg.decode(bytes(m.data), decode_choices=False)
        for s, sig in wanted[m.arbitration_id]:
            out[s][0].append(m.timestamp - t0)
            out[s][1].append(float(d[sig]))
    units = {s: db.get_message_by_name(s.split(".")[0]).get_signal_by_name(s.split(".")[1]).unit or ""
             for s in signals}
    return {s: (np.array(a), np.array(b)) for s, (a, b) in out.items()}, units


def sparse_table(series):
    """One row per distinct time, a column per signal, NA where that signal has no sample."""
    import pandas as pd

    frames = [pd.DataFrame({"t": t, s: v}).drop_duplicates("t", keep="last").set_index("t")
              for s, (t, v) in series.items()]
    df = pd.concat(frames, axis=1).sort_index()
    return df.astype("Float64").reset_index()


def write_mf4_decoded(series, units, path):
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    for s, (t, v) in series.items():  # one group per signal: each keeps its own time stamps
        mdf.append([Signal(v, t, name=s, unit=units[s])])
    mdf.save(str(path), overwrite=True)
    mdf.close()


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def conv(tmp_path_factory):
    """The RAV4 minute in every format, and the BLF reference on a 50 Hz grid."""
    if not BLF.exists():
        pytest.skip(f"real RAV4 data not found at {DATA}")
    d = tmp_path_factory.mktemp("formats")
    msgs = frames_of(BLF)
    write_asc(msgs, d / "drive.asc")
    write_candump(msgs, d / "drive.log")
    write_mf4_bus(msgs, d / "bus.mf4")
    series, units = decode_by_frame(msgs, SIGNALS)
    write_mf4_decoded(series, units, d / "decoded.mf4")
    df = sparse_table(series)
    df.to_parquet(d / "decoded.parquet", write_page_checksum=True)
    df.to_csv(d / "decoded.csv", index=False, float_format="%.17g", na_rep="")
    ref = read_can_log(BLF, DBC, SIGNALS, rate=RATE)
    return {"dir": d, "msgs": msgs, "series": series, "units": units, "ref": ref}


def _slope_bound(series):
    """Largest |dv/dt| between consecutive frames of each signal (for the timestamp-rounding tolerance)."""
    return np.array([np.max(np.abs(np.diff(v) / np.diff(t))) for t, v in series.values()])


# ------------------------------------------------------------------ same signals as the BLF path
@needs_data
def test_blf_through_read_log_is_read_can_log(conv):
    ref = conv["ref"]
    s = read_log(BLF, DBC, SIGNALS, rate=RATE)
    assert isinstance(s, LoadedSignals) and isinstance(s, LogSignals)
    assert s.names == ref.names and s.units == ref.units
    assert np.array_equal(s.t, ref.t)
    assert np.array_equal(s.values, ref.values) and np.array_equal(s.valid, ref.valid)
    for n in SIGNALS:
        assert isinstance(s.info[n], SignalQuality)
        assert s.info[n].n_samples == ref.info[n].n_samples
        assert s.info[n].n_nonfinite == s.info[n].n_undecodable == s.info[n].n_conflicts == 0
    assert s.source.format == "blf" and s.source.n_records == 53_800  # README: 53,800 frames
    part = s.select(["SPEED.SPEED"]).window(10.0, 20.0)
    assert isinstance(part, LoadedSignals) and part.source is s.source
    assert isinstance(part.info["SPEED.SPEED"], SignalQuality) and part.t[0] >= 10.0 and part.t[-1] <= 20.0


@needs_data
@pytest.mark.parametrize("name", ["drive.asc", "drive.log"])
def test_asc_and_candump_match_blf_to_timestamp_rounding(conv, name):
    """ASC and candump store times with 6 decimals: each frame moves by <= 0.5 us, the grid start
    by <= 0.5 us, so a grid value moves by at most max|dv/dt| * 1 us; we allow 2 us."""
    ref = conv["ref"]
    s = read_log(conv["dir"] / name, DBC, SIGNALS, rate=RATE)
    assert s.source.format == ("asc" if name.endswith("asc") else "candump")
    assert s.source.n_records == 53_800 and s.source.skipped == ()
    assert s.names == ref.names and s.units == ref.units and s.valid.all()
    assert s.t.size == ref.t.size and np.max(np.abs(s.t - ref.t)) <= 0.5e-6
    err = np.max(np.abs(s.values[0] - ref.values[0]), axis=0)
    bound = _slope_bound(conv["series"]) * 2e-6
    assert np.all(err <= bound + 1e-12), dict(zip(SIGNALS, err / bound, strict=True))
    for n in SIGNALS:
        assert s.info[n].n_samples == ref.info[n].n_samples
    # the frame times themselves are the BLF times rounded to the microsecond
    t_blf = np.array([m.timestamp for m in conv["msgs"]])
    t_txt = np.array([m.timestamp for m in frames_of(conv["dir"] / name)])
    assert np.max(np.abs((t_txt - t_txt[0]) - (t_blf - t_blf[0]))) <= 0.5e-6 + 1e-9


@needs_data
def test_mf4_bus_logging_decoded_by_asammdf_matches_cantools(conv):
    """asammdf's extract_bus_logging (canmatrix) and the BLF path (cantools) decode independently."""
    ref = conv["ref"]
    s = read_log(conv["dir"] / "bus.mf4", DBC, SIGNALS, rate=RATE)
    assert s.source.format == "mdf" and s.source.n_records == 53_800
    assert s.names == ref.names and s.units == ref.units
    assert np.array_equal(s.t, ref.t)
    np.testing.assert_allclose(s.values, ref.values, rtol=1e-12, atol=1e-12)
    assert s.valid.all()
    with pytest.raises(DataError, match="raw CAN frames.*pass dbc="):
        read_mdf(conv["dir"] / "bus.mf4", SIGNALS)
    # the decoded file that asammdf writes (display names "MESSAGE.SIGNAL") reads as decoded channels
    from asammdf import MDF

    with MDF(str(conv["dir"] / "bus.mf4")) as raw:
        ext = raw.extract_bus_logging({"CAN": [(str(DBC), 0)]})
        ext.save(str(conv["dir"] / "extracted.mf4"), overwrite=True)
        ext.close()
    e = read_mdf(conv["dir"] / "extracted.mf4", SIGNALS, rate=RATE)
    assert e.units == ref.units and np.array_equal(e.t, ref.t)
    np.testing.assert_allclose(e.values, ref.values, rtol=1e-12, atol=1e-12)


@needs_data
@pytest.mark.parametrize("name", ["decoded.mf4", "decoded.parquet", "decoded.csv"])
def test_decoded_files_match_blf(conv, name):
    ref = conv["ref"]
    units = conv["units"]
    kw = {} if name.endswith("mf4") else {"source_units": units}
    s = read_log(conv["dir"] / name, signals=SIGNALS, rate=RATE, **kw)
    assert s.names == ref.names and s.units == ref.units
    assert np.array_equal(s.t, ref.t)
    np.testing.assert_allclose(s.values, ref.values, rtol=1e-12, atol=1e-12)
    assert s.valid.all()
    for n in SIGNALS:
        assert s.info[n].n_samples == ref.info[n].n_samples
    # default rate: the fastest median source rate, as for the BLF path
    d = read_log(conv["dir"] / name, signals=["KINEMATICS.YAW_RATE", "SPEED.SPEED"], **kw)
    b = read_can_log(BLF, DBC, ["KINEMATICS.YAW_RATE", "SPEED.SPEED"])
    assert d.t.size == b.t.size and np.allclose(d.t, b.t, atol=1e-12)


@needs_data
def test_parquet_units_from_field_metadata_and_si(conv, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    series, units = conv["series"], conv["units"]
    sel = ["SPEED.SPEED", "KINEMATICS.YAW_RATE", "ENGINE_RPM.RPM"]
    df = sparse_table({s: series[s] for s in sel})
    table = pa.Table.from_pandas(df, preserve_index=False)
    fields = [f.with_metadata({"unit": units[f.name]}) if f.name in units else f for f in table.schema]
    table = table.cast(pa.schema(fields))
    pq.write_table(table, tmp_path / "u.parquet")
    s = read_parquet(tmp_path / "u.parquet", sel, rate=RATE, units="si")
    assert s.units == ["m/s", "rad/s", "rad/s"]
    ref = read_can_log(BLF, DBC, sel, rate=RATE)
    np.testing.assert_allclose(s["SPEED.SPEED"], ref["SPEED.SPEED"] / 3.6, rtol=1e-12)
    np.testing.assert_allclose(s["KINEMATICS.YAW_RATE"], np.deg2rad(ref["KINEMATICS.YAW_RATE"]), rtol=1e-12)
    np.testing.assert_allclose(s["ENGINE_RPM.RPM"], ref["ENGINE_RPM.RPM"] * 2 * np.pi / 60, rtol=1e-12)
    assert [s.info[n].source_unit for n in sel] == ["km/h", "deg/s", "rpm"]


@needs_data
def test_readme_facts_through_every_format(conv):
    """README: mean yaw rate -0.42 deg/s; mean |mean wheel speed - SPEED| 1.3 km/h (here FL, RR only)."""
    for name in ["drive.asc", "drive.log", "bus.mf4", "decoded.mf4", "decoded.parquet"]:
        kw = {"source_units": conv["units"]} if name.endswith("parquet") else {}
        s = read_log(conv["dir"] / name, DBC, SIGNALS, rate=RATE, **kw)
        assert np.mean(s["KINEMATICS.YAW_RATE"]) == pytest.approx(-0.42, abs=0.02), name
        assert 29 / 1.1 < s["SPEED.SPEED"].min() and s["SPEED.SPEED"].max() < 73 * 1.1


# ------------------------------------------------------------------ dispatcher
@needs_data
def test_format_detection_by_suffix_and_content(conv, tmp_path):
    d = conv["dir"]
    assert detect_format(BLF) == "blf" and detect_format(d / "drive.asc") == "asc"
    assert detect_format(d / "drive.log") == "candump" and detect_format(d / "bus.mf4") == "mdf"
    assert detect_format(d / "decoded.parquet") == "parquet" and detect_format(d / "decoded.csv") == "csv"
    for src, fmt in [(BLF, "blf"), (d / "drive.asc", "asc"), (d / "drive.log", "candump"),
                     (d / "bus.mf4", "mdf"), (d / "decoded.parquet", "parquet")]:
        anon = tmp_path / f"{fmt}.bin"
        shutil.copy(src, anon)
        assert detect_format(anon) == fmt
    s = read_log(tmp_path / "candump.bin", DBC, ["SPEED.SPEED"], rate=RATE)
    assert s.equals(read_log(d / "drive.log", DBC, ["SPEED.SPEED"], rate=RATE))
    junk = tmp_path / "notes.xyz"
    junk.write_text("hello, this is not a log\n")
    with pytest.raises(DataError, match=r"unknown log format for 'notes.xyz'.*'.xyz'"):
        read_log(junk, DBC, ["SPEED.SPEED"])
    with pytest.raises(DataError, match="unknown log format 'vsb'"):
        read_log(BLF, DBC, ["SPEED.SPEED"], format="vsb")
    with pytest.raises(DataError, match="pass dbc="):
        read_log(d / "drive.asc", None, ["SPEED.SPEED"])
    with pytest.raises(DataError, match="name the signals"):
        read_log(BLF, DBC, None)
    # forcing a format: an ASC file read as candump fails clearly, naming a line
    with pytest.raises(DataError, match="line 1"):
        read_log(d / "drive.asc", DBC, ["SPEED.SPEED"], format="candump")


# ------------------------------------------------------------------ gaps, stuck signals, quality counts
@needs_data
def test_gap_marked_in_every_frame_format(conv, tmp_path):
    gap = (20.0, 21.0)
    msgs = conv["msgs"]
    t0 = msgs[0].timestamp
    kept = [m for m in msgs if not (m.arbitration_id == 0xAA and gap[0] <= m.timestamp - t0 <= gap[1])]
    write_asc(kept, tmp_path / "g.asc")
    write_candump(kept, tmp_path / "g.log")
    write_mf4_bus(kept, tmp_path / "g.mf4")
    sig = ["WHEEL_SPEEDS.WHEEL_SPEED_FL", "SPEED.SPEED"]
    for name in ["g.asc", "g.log", "g.mf4"]:
        s = read_log(tmp_path / name, DBC, sig, rate=100.0, method="linear")
        fl = s.valid[0, :, 0]
        inside = (s.t > gap[0] + 0.02) & (s.t < gap[1] - 0.02)
        far = (s.t < gap[0] - 0.04) | (s.t > gap[1] + 0.04)
        assert not fl[inside].any() and np.isnan(s.values[0, inside, 0]).all(), name
        assert fl[far].all() and s.valid[0, :, 1].all(), name
        assert s.info[sig[0]].n_gaps == 1 and s.info[sig[0]].n_invalid == int((~fl).sum())


def _longest_run_brute(t, v):
    best, start = 0.0, 0
    for k in range(1, len(v) + 1):
        if k == len(v) or v[k] != v[start]:
            best = max(best, t[k - 1] - t[start])
            start = k
    return best


@needs_data
def test_stuck_signal_reported_not_refused(conv, tmp_path):
    import can

    msgs = conv["msgs"]
    t0 = msgs[0].timestamp
    frozen = None
    out = []
    for m in msgs:  # freeze KINEMATICS (0x24) from 30 s to 35 s: the sensor repeats one payload
        if m.arbitration_id == 0x24 and 30.0 <= m.timestamp - t0 <= 35.0:
            frozen = frozen or bytes(m.data)
            m = can.Message(timestamp=m.timestamp, arbitration_id=0x24, data=frozen, is_extended_id=False,
                            channel=m.channel)
        out.append(m)
    write_candump(out, tmp_path / "stuck.log")
    sig = ["KINEMATICS.YAW_RATE", "SPEED.SPEED"]
    s = read_log(tmp_path / "stuck.log", DBC, sig, rate=RATE)
    clean = read_log(conv["dir"] / "drive.log", DBC, sig, rate=RATE)
    t, v = conv["series"]["KINEMATICS.YAW_RATE"]
    assert clean.info[sig[0]].longest_constant == pytest.approx(_longest_run_brute(t, v), abs=1e-5)
    assert not clean.info[sig[0]].stuck  # the real yaw rate never holds 2 s
    info = s.info[sig[0]]
    t, v = decode_by_frame(out, ["KINEMATICS.YAW_RATE"])[0]["KINEMATICS.YAW_RATE"]
    assert info.longest_constant == pytest.approx(_longest_run_brute(t, v), abs=1e-5)
    assert info.stuck and info.longest_constant >= 4.95
    assert s.valid.all()  # reported, not flagged: a constant value is not a bad sample
    m = (s.t >= 30.05) & (s.t <= 34.95)
    assert np.ptp(s["KINEMATICS.YAW_RATE"][0, m]) == 0.0


def test_series_to_grid_by_hand():
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 1.0, 1.1])
    v = np.array([0.0, 1.0, np.inf, 3.0, 4.0, 10.0, 11.0])
    s = series_to_grid({"x": (t, v)}, {"x": "km/h"}, rate=20.0, units="si", span="common", method="linear")
    # grid 0, 0.05, ..., 1.1; the inf at 0.2 spoils (0.1, 0.3); 0.4 -> 1.0 is a gap (6 periods > 3)
    g = s.t
    expect_bad = ((g > 0.1 + 1e-9) & (g < 0.3 - 1e-9)) | ((g > 0.4 + 1e-9) & (g < 1.0 - 1e-9))
    assert s.valid[0, :, 0].tolist() == (~expect_bad).tolist()
    ok = ~expect_bad
    ref = np.interp(g[ok], t[[0, 1, 3, 4, 5, 6]], v[[0, 1, 3, 4, 5, 6]]) / 3.6
    np.testing.assert_allclose(s.values[0, ok, 0], ref, rtol=1e-12)
    assert s.units == ["m/s"] and s.info["x"].n_nonfinite == 1 and s.info["x"].n_gaps == 1
    # same-time samples: equal ones merge, different ones become one bad sample
    t2 = np.array([0.0, 0.1, 0.1, 0.2, 0.3, 0.3, 0.4])
    v2 = np.array([0.0, 1.0, 1.0, 2.0, 3.0, 9.0, 4.0])
    s2 = series_to_grid({"y": (t2, v2)}, {}, rate=10.0, method="linear")
    assert s2.info["y"].n_duplicates == 1 and s2.info["y"].n_conflicts == 1
    assert s2.valid[0].ravel().tolist() == [True, True, True, False, True]
    assert s2.info["y"].n_samples == 5


def test_frames_to_signals_short_payload_is_a_bad_sample_not_zero():
    import cantools

    db = cantools.database.load_string(
        'VERSION ""\nBO_ 180 SPEED: 8 XXX\n SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX\n',
        database_format="dbc")
    full = bytes([0, 0, 0, 0, 0, 0x03, 0xE8, 0])  # 10.00 km/h
    short = full[:5]  # the signal lives in bytes 5..6: this frame cannot hold it
    s = frames_to_signals(np.arange(6) / 10.0, np.full(6, 180), [full, full, short, full, full, full], db,
                          ["SPEED.SPEED"], rate=20.0, method="linear")
    assert s.info["SPEED.SPEED"].n_undecodable == 1 and s.info["SPEED.SPEED"].n_nonfinite == 1
    bad = (s.t > 0.1 + 1e-9) & (s.t < 0.3 - 1e-9)
    assert (~s.valid[0, :, 0]).tolist() == bad.tolist()
    assert np.all(s.values[0, ~bad, 0] == 10.0)


@needs_data
def test_asc_lenient_mode_lists_skipped_lines(conv, tmp_path):
    lines = (conv["dir"] / "drive.asc").read_text().splitlines(keepends=True)
    lines[100] = lines[100].replace("Rx", "Qx")  # python-can's ASCReader alone would skip it silently
    bad = tmp_path / "bad.asc"
    bad.write_text("".join(lines))
    with pytest.raises(DataError, match="line 101 is neither a CAN frame"):
        read_asc(bad, DBC, ["SPEED.SPEED"])
    s = read_asc(bad, DBC, ["SPEED.SPEED"], rate=RATE, strict=False)
    assert [no for no, _ in s.source.skipped] == [101]
    assert s.source.n_records == 53_799


@needs_data
def test_csv_table_matches_plain_read_csv_on_the_imu():
    from fdikit.io import read_csv

    a = read_table_csv(DATA / "imu.csv", ["gyro_z_rad_s", "acc_z_m_s2"], rate=50.0, time="t_s")
    b = read_csv(DATA / "imu.csv", time="t_s", columns=["gyro_z_rad_s", "acc_z_m_s2"], rate=50.0)
    assert np.array_equal(a.t, b.t)
    np.testing.assert_allclose(a.values, b.values, rtol=1e-12)
    assert np.array_equal(a.valid, b.valid)


def test_parquet_datetime_time_column(tmp_path):
    import pandas as pd

    start = pd.to_datetime("2026-01-01 12:00:00").tz_localize("UTC")
    t = start + pd.to_timedelta(np.arange(5) * 0.1, unit="s")
    pd.DataFrame({"time": t, "x": [0.0, 1.0, 2.0, 3.0, 4.0]}).to_parquet(tmp_path / "dt.parquet")
    s = read_log(tmp_path / "dt.parquet", signals=["x"], rate=20.0, method="linear")
    np.testing.assert_allclose(s.t, np.arange(9) * 0.05, atol=1e-12)  # seconds from the first row
    np.testing.assert_allclose(s["x"][0], np.arange(9) * 0.5, atol=1e-12)
