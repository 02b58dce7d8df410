"""fdikit.io: the CAN log loader on the real RAV4 minute, its gap handling and its errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.io import LogSignals, convert_units, read_can_log, read_csv, resample_to_grid

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rav4-highway"
BLF = DATA / "drive.blf"
DBC = DATA / "toyota_rav4.dbc"
needs_data = pytest.mark.skipif(not BLF.exists(), reason=f"real RAV4 data not found at {DATA}")

SIGNALS = [
    "KINEMATICS.YAW_RATE", "KINEMATICS.ACCEL_X", "KINEMATICS.ACCEL_Y",
    "WHEEL_SPEEDS.WHEEL_SPEED_FL", "WHEEL_SPEEDS.WHEEL_SPEED_FR",
    "WHEEL_SPEEDS.WHEEL_SPEED_RL", "WHEEL_SPEEDS.WHEEL_SPEED_RR",
    "STEER_ANGLE_SENSOR.STEER_ANGLE", "STEER_ANGLE_SENSOR.STEER_RATE",
    "BRAKE_MODULE.BRAKE_PRESSURE", "BRAKE_MODULE.BRAKE_PRESSED", "ENGINE_RPM.RPM",
    "GAS_PEDAL.GAS_PEDAL", "SPEED.SPEED",
]


@pytest.fixture(scope="module")
def log():
    if not BLF.exists():
        pytest.skip(f"real RAV4 data not found at {DATA}")
    return read_can_log(BLF, DBC, SIGNALS, rate=50.0)


def _raw_frames(path, fid):
    import can

    ts, data = [], []
    first = None
    for m in can.LogReader(str(path)):
        if first is None:
            first = m.timestamp
        if m.arbitration_id == fid:
            ts.append(m.timestamp - first)
            data.append(bytes(m.data))
    return np.array(ts), data


# ------------------------------------------------------------------ the real log, as the README states
@needs_data
def test_names_units_rates_lengths(log):
    assert isinstance(log, LogSignals)
    assert log.names == SIGNALS
    units = dict(zip(log.names, log.units, strict=True))
    assert units["KINEMATICS.YAW_RATE"] == "deg/s"
    assert units["KINEMATICS.ACCEL_X"] == units["KINEMATICS.ACCEL_Y"] == "m/s^2"
    assert all(units[f"WHEEL_SPEEDS.WHEEL_SPEED_{w}"] == "km/h" for w in ("FL", "FR", "RL", "RR"))
    assert units["STEER_ANGLE_SENSOR.STEER_ANGLE"] == "deg"
    assert units["STEER_ANGLE_SENSOR.STEER_RATE"] == "deg/s"
    assert units["ENGINE_RPM.RPM"] == "rpm"
    # README: chassis ~83 Hz, brake and speed ~41 Hz, engine speed ~42 Hz, gas pedal ~31 Hz
    expect = {"KINEMATICS.YAW_RATE": 83, "WHEEL_SPEEDS.WHEEL_SPEED_FL": 83,
              "STEER_ANGLE_SENSOR.STEER_ANGLE": 83, "BRAKE_MODULE.BRAKE_PRESSURE": 41, "SPEED.SPEED": 41,
              "ENGINE_RPM.RPM": 42, "GAS_PEDAL.GAS_PEDAL": 31}
    for name, hz in expect.items():
        assert log.info[name].rate == pytest.approx(hz, rel=0.03), name
        assert log.info[name].n_samples == pytest.approx(60 * hz, rel=0.03), name
    # one minute, starting at the first frame: the grid covers 0 .. 60 s at 50 Hz
    assert log.t[0] == pytest.approx(0.0, abs=0.05)
    assert log.t[-1] == pytest.approx(60.0, abs=0.1)
    assert np.allclose(np.diff(log.t), 0.02, atol=1e-12)
    assert log.n_samples == int(np.floor((log.t[-1] - log.t[0]) * 50 + 1e-9)) + 1
    assert log.valid.all()  # the README says nothing is missing in this minute
    assert np.isfinite(log.values).all()


@needs_data
def test_decoding_against_hand_bit_arithmetic(log):
    """SPEED.SPEED and KINEMATICS.YAW_RATE decoded by hand from the DBC layout, held (the causal
    default grid: each grid sample is the last frame at or before it)."""
    ts, data = _raw_frames(BLF, 0xB4)  # SPEED: start bit 47, 16 bit Motorola, scale 0.01 km/h
    raw = np.array([(d[5] << 8) | d[6] for d in data], float) * 0.01
    ref = raw[np.searchsorted(ts, log.t, side="right") - 1]
    assert np.max(np.abs(log["SPEED.SPEED"][0] - ref)) < 1e-9
    ts, data = _raw_frames(BLF, 0x24)  # YAW_RATE: start bit 1, 10 bit Motorola, 0.244 deg/s, -125
    raw = np.array([((d[0] & 0x03) << 8) | d[1] for d in data], float) * 0.244 - 125.0
    ref = raw[np.searchsorted(ts, log.t, side="right") - 1]
    # linear interpolation on request: numpy's interp
    lin = read_can_log(BLF, DBC, ["KINEMATICS.YAW_RATE"], rate=50.0, method="linear")
    assert np.max(np.abs(lin["KINEMATICS.YAW_RATE"][0] - np.interp(lin.t, ts, raw))) < 1e-9
    assert np.max(np.abs(log["KINEMATICS.YAW_RATE"][0] - ref)) < 1e-9


@needs_data
def test_facts_measured_in_the_readme():
    # the data README's figures compare signals of different messages at one instant: interpolated
    # (a held grid adds up to one message period of staleness: the maximum reads 5.3 km/h)
    s = read_can_log(BLF, DBC, SIGNALS, rate=None, method="linear")
    # mean yaw rate -0.42 deg/s; wheel-speed mean vs SPEED.SPEED 1.3 km/h on average, 2.8 at most
    assert np.mean(s["KINEMATICS.YAW_RATE"]) == pytest.approx(-0.42, abs=0.02)
    wheels = np.mean([s[f"WHEEL_SPEEDS.WHEEL_SPEED_{w}"][0] for w in ("FL", "FR", "RL", "RR")], axis=0)
    diff = np.abs(wheels - s["SPEED.SPEED"][0])
    assert np.mean(diff) == pytest.approx(1.3, abs=0.1)
    assert np.max(diff) == pytest.approx(2.8, abs=0.4)  # the maximum depends a little on the grid
    assert 29 / 1.1 < s["SPEED.SPEED"].min() and s["SPEED.SPEED"].max() < 73 * 1.1
    # brake applied in 0.2 % of the BRAKE_MODULE frames
    assert s.info["BRAKE_MODULE.BRAKE_PRESSED"].n_samples == s.info["BRAKE_MODULE.BRAKE_PRESSURE"].n_samples
    _ts, data = _raw_frames(BLF, 0x224)
    pressure = np.array([((d[5] & 0x0F) << 8) | d[6] for d in data])  # start bit 43, 12 bit Motorola
    assert 100 * np.mean(pressure > 0) == pytest.approx(0.2, abs=0.1)
    # default rate = fastest source (~89 Hz by median interval)
    fastest = max(1 / i.median_interval for i in s.info.values())
    assert 1 / np.mean(np.diff(s.t)) == pytest.approx(fastest, rel=1e-3)


@needs_data
def test_si_conversion(log):
    si = read_can_log(BLF, DBC, SIGNALS, rate=50.0, units="si")
    u = dict(zip(si.names, si.units, strict=True))
    assert u["WHEEL_SPEEDS.WHEEL_SPEED_FL"] == "m/s" and u["KINEMATICS.YAW_RATE"] == "rad/s"
    assert u["ENGINE_RPM.RPM"] == "rad/s" and u["STEER_ANGLE_SENSOR.STEER_ANGLE"] == "rad"
    assert np.allclose(si["SPEED.SPEED"], log["SPEED.SPEED"] / 3.6)
    assert np.allclose(si["ENGINE_RPM.RPM"], log["ENGINE_RPM.RPM"] * np.pi / 30)
    one = read_can_log(BLF, DBC, ["SPEED.SPEED"], rate=50.0, units={"SPEED.SPEED": "mph"})
    kmh = read_can_log(BLF, DBC, ["SPEED.SPEED"], rate=50.0)
    assert one.units == ["mph"] and np.array_equal(one.t, kmh.t)
    assert np.allclose(one.values * 1.609344, kmh.values, rtol=1e-12)
    with pytest.raises(DataError, match="cannot convert"):
        read_can_log(BLF, DBC, ["SPEED.SPEED"], units={"SPEED.SPEED": "rad"})


# ------------------------------------------------------------------ gaps
@needs_data
def test_gap_is_marked_not_interpolated(tmp_path):
    import can

    gap = (20.0, 21.0)
    out = tmp_path / "gap.blf"
    with can.BLFWriter(str(out)) as w:
        t_first = None
        for m in can.LogReader(str(BLF)):
            t_first = m.timestamp if t_first is None else t_first
            if m.arbitration_id == 0xAA and gap[0] <= m.timestamp - t_first <= gap[1]:
                continue
            w.on_message_received(m)
    s = read_can_log(out, DBC, ["WHEEL_SPEEDS.WHEEL_SPEED_FL", "SPEED.SPEED"], rate=100.0, method="linear")
    fl = s.valid[0, :, 0]
    inside = (s.t > gap[0] + 0.02) & (s.t < gap[1] - 0.02)
    assert not fl[inside].any() and np.isnan(s.values[0, inside, 0]).all()
    # away from the gap (more than 3 source periods) everything is valid; other channels unaffected
    far = (s.t < gap[0] - 0.04) | (s.t > gap[1] + 0.04)
    assert fl[far].all()
    assert s.valid[0, :, 1].all()
    assert s.info["WHEEL_SPEEDS.WHEEL_SPEED_FL"].n_gaps == 1
    assert s.info["WHEEL_SPEEDS.WHEEL_SPEED_FL"].n_invalid == int((~fl).sum())
    clean = s.dropna()
    assert clean.n_samples == int(fl.sum()) and np.isfinite(clean.values).all()


def test_resample_to_grid_by_hand():
    t = np.array([0.0, 0.1, 0.2, 0.3, 1.0, 1.1])
    v = np.array([0.0, 1.0, 2.0, 3.0, 10.0, 11.0])
    grid = np.array([-0.05, 0.05, 0.25, 0.5, 1.05, 1.1, 1.2])
    val, ok = resample_to_grid(t, v, grid, max_gap=3.0, method="linear")
    assert ok.tolist() == [False, True, True, False, True, True, False]
    assert np.allclose(val[ok], [0.5, 2.5, 10.5, 11.0])
    assert np.isnan(val[~ok]).all()
    val, ok = resample_to_grid(t, v, grid, max_gap=3.0, method="previous")
    assert ok.tolist() == [False, True, True, True, True, True, True]  # 0.5 - 0.3 = 0.2 <= 0.3
    assert val[3] == 3.0 and val[6] == 11.0
    val, ok = resample_to_grid(t, v, grid, max_gap=1.5, method="previous")
    assert ok.tolist()[3] is False
    assert convert_units([100.0], "km/h", "m/s")[0] == pytest.approx(27.7777777778)
    assert convert_units([1.0], "rad/s", "deg/s")[0] == pytest.approx(57.29577951)


# ------------------------------------------------------------------ clear errors
@needs_data
def test_truncated_blf(tmp_path):
    bad = tmp_path / "cut.blf"
    bad.write_bytes(BLF.read_bytes()[:300_000])
    with pytest.raises(DataError, match="truncated"):
        read_can_log(bad, DBC, ["SPEED.SPEED"])
    tiny = tmp_path / "tiny.blf"
    tiny.write_bytes(BLF.read_bytes()[:100])
    with pytest.raises(DataError, match="tiny.blf"):
        read_can_log(tiny, DBC, ["SPEED.SPEED"])


@needs_data
def test_dbc_missing_signal(tmp_path):
    text = DBC.read_text()
    lines = [ln for ln in text.splitlines() if not ln.strip().startswith("SG_ YAW_RATE ")]
    assert len(lines) < len(text.splitlines())
    dbc2 = tmp_path / "no_yaw.dbc"
    dbc2.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"no signal 'YAW_RATE'.*ACCEL_X"):
        read_can_log(BLF, dbc2, ["KINEMATICS.YAW_RATE"])
    # the other signals of that message still load
    s = read_can_log(BLF, dbc2, ["KINEMATICS.ACCEL_X"], rate=10)
    assert s.names == ["KINEMATICS.ACCEL_X"]


@needs_data
def test_unknown_signal_names():
    with pytest.raises(DataError, match=r"no signal 'YAWRATE'.*did you mean \['YAW_RATE'\]"):
        read_can_log(BLF, DBC, ["KINEMATICS.YAWRATE"])
    with pytest.raises(DataError, match=r"no message 'KINEMATIC'.*KINEMATICS"):
        read_can_log(BLF, DBC, ["KINEMATIC.YAW_RATE"])
    with pytest.raises(DataError, match="MESSAGE.SIGNAL"):
        read_can_log(BLF, DBC, ["YAW_RATE"])


@needs_data
def test_not_a_log(tmp_path):
    fake = tmp_path / "notes.blf"
    fake.write_text("this is not a binary logging file\n" * 20)
    with pytest.raises(DataError, match="not a valid BLF"):
        read_can_log(fake, DBC, ["SPEED.SPEED"])
    other = tmp_path / "data.xyz"
    other.write_text("1,2,3\n")
    with pytest.raises(DataError, match="unknown log format"):
        read_can_log(other, DBC, ["SPEED.SPEED"])
    with pytest.raises(DataError, match="does not exist"):
        read_can_log(tmp_path / "missing.blf", DBC, ["SPEED.SPEED"])
    with pytest.raises(DataError, match="DBC"):
        read_can_log(BLF, tmp_path / "missing.dbc", ["SPEED.SPEED"])


# ------------------------------------------------------------------ CSV
@needs_data
def test_read_csv_imu(tmp_path):
    s = read_csv(DATA / "imu.csv", time="t_s", units={"gyro_z_rad_s": "rad/s"},
                 convert={"gyro_z_rad_s": "deg/s"})
    assert s.names == ["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s",
                       "acc_x_m_s2", "acc_y_m_s2", "acc_z_m_s2"]
    assert s.info["gyro_z_rad_s"].rate == pytest.approx(104, rel=0.03)  # README: about 104 Hz
    assert s.units[2] == "deg/s"
    assert np.mean(s["acc_z_m_s2"]) == pytest.approx(-9.8, abs=0.3)  # z down: gravity reads -g
    # CAN yaw rate vs IMU gyro z: correlation -0.78 (README)
    can_s = read_can_log(BLF, DBC, ["KINEMATICS.YAW_RATE"], rate=50.0)
    gz = np.interp(can_s.t, s.t, s["gyro_z_rad_s"][0])
    r = np.corrcoef(gz, can_s["KINEMATICS.YAW_RATE"][0])[0, 1]
    assert r == pytest.approx(-0.78, abs=0.03)
    g = read_csv(DATA / "imu.csv", time="t_s", columns=["gyro_z_rad_s"], rate=50.0)
    assert np.allclose(np.diff(g.t), 0.02) and g.valid.all()


def test_read_csv_errors(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("t,x\n0,1\n0.1,2\n0.1,3\n")
    with pytest.raises(DataError, match="not strictly increasing at data row 2"):
        read_csv(p)
    p.write_text("t,x\n0,1\n0.1,\n0.2,3\n")
    s = read_csv(p)
    assert s.valid[0, :, 0].tolist() == [True, False, True]
    with pytest.raises(DataError, match="no time column 'time'"):
        read_csv(p, time="time")
    with pytest.raises(DataError, match=r"no column\(s\) \['y'\]"):
        read_csv(p, columns=["y"])
