"""Issue 16 items 1 and 5 on the real RAV4 minute: faults of every type injected on the raw CAN
signals in their own units, detected and isolated by the sensor-fault detectors and the MHSSPT,
with no false announcement. The full table is slow; a smoke subset runs always."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError, Signals

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
rav4 = pytest.mark.skipif(
    not (DATA / "drive.blf").exists(),
    reason=f"RAV4 data not found at {DATA} (../shared/data/rav4-highway from the repo root)",
)

#: The table of the issue note: (spec, injected sensor, largest delay to the right announcement, s).
#: Magnitudes: the smallest a driver or a workshop would care about (see the issue note).
TABLE = [
    ("stuck:STEER_ANGLE_SENSOR@15", "steering", 10.0),
    ("stuck:STEER_ANGLE_SENSOR@45", "steering", 10.0),
    ("drift:YAW_RATE:0.02/s@10", "yaw_rate", 15.0),  # 0.2 deg/s per 10 s
    ("drift:YAW_RATE:0.02/s@35", "yaw_rate", 15.0),
    # 1 %: a tyre change / indirect TPMS level; the wheel peer check (issue 27, 0.2 Hz low-pass)
    # announces it after 1.56 s / 2.32 s (0.19 m/s at 19 m/s is 1.3 thresholds), with the nominal
    # minute at 0.67 of the threshold; the sign-based gain test of issue 16 took 0.56 s but named
    # the wrong wheel for gains below 1
    ("gain:WHEEL_SPEED_FL:1.01@20", "wheel_fl", 3.0),
    pytest.param("gain:WHEEL_SPEED_FL:1.01@50", "wheel_fl", 3.0, marks=pytest.mark.xfail(
        strict=True, reason="known limit: on the causal (held) grid of issue 28 the wheel peer "
        "threshold calibrated on the first half rises and a 1 % gain in the last 10 s peaks at 0.947 of "
        "it, not announced (the linear grid announced it after 2.3 s); a CUSUM on the wheels announces "
        "it in 2.0 s but gives wheel_rl:bias twice on the fault-free minute (issue 27)")),
    ("bias:ACCEL_Y:1.0@25", "lateral_accelerometer", 2.0),
    ("bias:ACCEL_Y:1.0@40", "lateral_accelerometer", 5.0),
    ("intermittent:WHEEL_SPEED_RL:1.0@12", "wheel_rl", 1.0),  # 1 km/h bursts, 0.5 s of every 2 s
    ("intermittent:WHEEL_SPEED_RL:1.0@42", "wheel_rl", 1.0),
]
SMOKE = [TABLE[0], TABLE[4]]


def _check(spec, sensor, max_delay):
    from fdikit.systems.car.monitor_rav4 import hypothesis_sensors, run_rav4_log

    r = run_rav4_log(None, spec)
    assert r["expected_sensor"] == sensor
    assert r["isolated_ok"], r["announcements"]
    assert sensor in hypothesis_sensors(r["isolated"])
    assert r["announcement_delay_s"] is not None and r["announcement_delay_s"] <= max_delay, r
    assert r["false_announcements"] == [], r["false_announcements"]
    return r


@rav4
def test_nominal_minute_no_announcement_and_held_out_statistics():
    from fdikit.systems.car.monitor_rav4 import run_rav4_log

    r = run_rav4_log(None, "none")
    assert r["announcements"] == []
    held, cal = r["held_out"], r["calibration"]
    assert held["span_s"][0] == cal["span_s"][1] == pytest.approx(r["calibrated_on_s"][1], abs=0.01)
    assert held["announcements"] == 0 and held["false_announcements"] == []
    # the calibration half's 0.60 (a lateral event at 10.2 s) is not the held-out half's number
    assert cal["max_wrong_probability"] == pytest.approx(r["max_wrong_probability"])
    assert held["max_wrong_probability"] < 1e-3 < cal["max_wrong_probability"]
    assert max(held["peak_sensor_statistic"].values()) < 1.0


@rav4
@pytest.mark.parametrize("spec,sensor,max_delay", SMOKE)
def test_smoke_injection_detected_and_isolated(spec, sensor, max_delay):
    _check(spec, sensor, max_delay)


@rav4
@pytest.mark.slow
@pytest.mark.parametrize("spec,sensor,max_delay", TABLE)
def test_injection_table(spec, sensor, max_delay):
    _check(spec, sensor, max_delay)


@rav4
@pytest.mark.slow
def test_drift_detected_long_before_the_smallest_calibrated_bias():
    """0.02 deg/s per s reaches the smallest calibrated yaw bias (0.01 rad/s) after 29 s; the drift
    detector announces it well before (here within 15 s), typed a drift, and the type does not flip
    (issue 27: the classifier's hysteresis; before, bias -> drift -> bias -> drift change events)."""
    from fdikit.systems.car.monitor_rav4 import RAV4_FAULTS

    smallest = min(RAV4_FAULTS["yaw_rate"][1])
    reach = np.degrees(smallest) / 0.02
    r = _check("drift:YAW_RATE:0.02/s@10", "yaw_rate", 15.0)
    assert r["isolated"] == "yaw_rate:drift"
    assert r["announcement_delay_s"] < 0.6 * reach
    assert [c for c in r["changes"] if c["fault"].startswith("yaw_rate")] == [], r["changes"]


# ---------------------------------------------------------------------------------- parsing, units
def test_parse_inject_every_type():
    from fdikit.faults import Bias, Gain, Intermittent, Ramp, Stuck
    from fdikit.systems.car.monitor_rav4 import parse_inject

    fs = parse_inject(
        "stuck:STEER_ANGLE_SENSOR@15, drift:YAW_RATE:0.05/s@20-40,gain:WHEEL_SPEED_FL:1.05@40,"
        "bias:KINEMATICS.ACCEL_Y:-0.5@3,intermittent:WHEEL_SPEED_RL:2@12;period=3;duty=0.5,"
        "yaw_rate:0.03@40,stuck:steer:0.01@5"
    )
    assert [type(f) for f in fs] == [Stuck, Ramp, Gain, Bias, Intermittent, Bias, Stuck]
    assert fs[0].value is None and fs[0].target == "STEER_ANGLE_SENSOR" and fs[0].start == 15.0
    assert (fs[1].slope, fs[1].start, fs[1].end) == (0.05, 20.0, 40.0)
    assert fs[2].gain == 1.05 and fs[3].magnitude == -0.5 and fs[3].target == "KINEMATICS.ACCEL_Y"
    assert (fs[4].magnitude, fs[4].period, fs[4].duty) == (2.0, 3.0, 0.5)
    assert fs[6].value == 0.01
    assert parse_inject("none") == []


@pytest.mark.parametrize(
    "spec,match",
    [
        ("wobble:YAW_RATE:1@2", "unknown fault type 'wobble'"),
        ("bias:YAW_RATE@2", "bias needs a value"),
        ("gain:YAW_RATE:1.1/s@2", "only for drift"),
        ("bias:YAW_RATE:1@2;period=2", "do not apply to bias"),
        ("YAW_RATE=1@2", "bad fault spec"),
    ],
)
def test_parse_inject_errors(spec, match):
    from fdikit.systems.car.monitor_rav4 import parse_inject

    with pytest.raises(DataError, match=match):
        parse_inject(spec)


def test_inject_raw_names_in_their_own_units():
    from fdikit.systems.car.monitor_rav4 import RAW_CHANNELS, Rav4Preprocessing, inject, parse_inject

    pre = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0)
    t = 100.0 + np.arange(11) * 0.5  # the log's own clock; specs are from its start
    v = np.tile(np.arange(1.0, 10.0), (11, 1))[None]
    s = Signals(t, v, RAW_CHANNELS)
    col = {n: i for i, n in enumerate(RAW_CHANNELS)}
    d = lambda spec: inject(s, parse_inject(spec), pre).values[0] - v[0]  # noqa: E731
    on = t - t[0] >= 2.0
    np.testing.assert_allclose(d("bias:YAW_RATE:1.0@2")[on, col["yaw_rate_raw"]], np.radians(1.0))
    np.testing.assert_allclose(d("bias:ACCEL_Y:1.0@2")[on, col["accel_y_raw"]], 1.0)  # sensor's own sign
    np.testing.assert_allclose(d("a_y:1.0@2")[on, col["accel_y_raw"]], -1.0)  # internal: left +
    np.testing.assert_allclose(d("bias:WHEEL_SPEED_RL:3.6@2")[on, col["wheel_rl"]], 1.0)  # km/h -> m/s
    np.testing.assert_allclose(d("bias:STEER_ANGLE:1.0@2")[on, col["steer_angle"]], np.radians(1.0))
    np.testing.assert_allclose(d("steer:0.01@2")[on, col["steer_angle"]], 0.16)  # road wheel x i_s
    np.testing.assert_allclose(
        d("drift:YAW_RATE:0.5/s@2")[on, col["yaw_rate_raw"]],
        np.radians(0.5) * (t[on] - t[0] - 2.0),
        atol=1e-15,
    )
    g = d("gain:WHEEL_SPEED_FL:1.02@2")
    np.testing.assert_allclose(g[on, col["wheel_fl"]], 0.02 * v[0, on, col["wheel_fl"]])
    st = inject(s, parse_inject("stuck:STEER_ANGLE_SENSOR@2"), pre).values[0]
    k = int(np.argmax(on))
    for c in ("steer_angle", "steer_fraction"):  # the whole message freezes
        np.testing.assert_array_equal(st[k:, col[c]], v[0, k, col[c]])
    assert np.all(d("none") == 0)
    with pytest.raises(DataError, match="outside the log"):
        d("bias:YAW_RATE:1.0@20")
    with pytest.raises(DataError, match="'WHEEL_SPEED_XX' names no channel"):
        d("bias:WHEEL_SPEED_XX:1.0@2")


@rav4
def test_sensor_channels_batch_equals_streaming_and_round_trip():
    from fdikit.systems.car.monitor_rav4 import Rav4SensorChannels, rav4_monitor

    mon = rav4_monitor()
    chk = mon.artifacts["sensor_channels"]
    raw = mon.raw
    sub = Signals(raw.t[:400], raw.values[:, :400], raw.names, check=False)
    b = chk.run(sub).values
    g = Rav4SensorChannels.from_dict(chk.to_dict())
    g.reset(1)
    u, y = g._inputs(sub)
    s = np.stack([g.step(u[:, k], y[:, k]) for k in range(400)], axis=1)
    np.testing.assert_array_equal(b, s)
