"""Issue 27 item 5: faults are injected on CAN signals, never on every signal of a message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.faults import Bias
from fdikit.systems.car.monitor_rav4.channels import RAW_CHANNELS, Rav4Preprocessing
from fdikit.systems.car.monitor_rav4.injection import (
    inject,
    injected_sensors,
    injection_summary,
    parse_inject,
)

PRE = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0)
RAV4 = Path(__file__).resolve().parents[3] / ".." / "shared" / "data" / "rav4-highway"


def _raw():
    t = np.arange(0.0, 5.0, 0.02)
    v = np.random.default_rng(0).normal(size=(1, t.size, len(RAW_CHANNELS)))
    return Signals(t, v, RAW_CHANNELS)


@pytest.mark.parametrize("spec", ["bias:STEER_ANGLE_SENSOR:3@2", "drift:KINEMATICS:0.1/s@2",
                                  "gain:WHEEL_SPEEDS:1.05@2", "intermittent:WHEEL_SPEEDS:1@2",
                                  "stuck:STEER_ANGLE_SENSOR:5@2"])
def test_a_message_wide_name_is_refused_with_its_signals(spec):
    with pytest.raises(DataError, match="CAN message of .* signals") as e:
        parse_inject(spec)
    msg = str(e.value)
    if "STEER_ANGLE_SENSOR" in spec:
        assert "STEER_ANGLE" in msg and "STEER_FRACTION" in msg
    # a Fault object built by hand is refused by inject as well
    with pytest.raises(DataError, match="CAN message"):
        inject(_raw(), [Bias("STEER_ANGLE_SENSOR", 3.0, start=2.0)], PRE)


def test_the_named_signal_alone_gets_the_fault_in_its_unit():
    s = _raw()
    col = {n: i for i, n in enumerate(RAW_CHANNELS)}
    for spec in ("bias:STEER_ANGLE:3@2", "bias:STEER_ANGLE_SENSOR.STEER_ANGLE:3@2"):
        d = (inject(s, parse_inject(spec), PRE).values - s.values)[0]
        on = s.t >= 2.0
        np.testing.assert_allclose(d[on, col["steer_angle"]], np.radians(3.0))  # 3 deg, not 6
        assert np.all(d[:, col["steer_fraction"]] == 0)
        assert np.all(np.delete(d, col["steer_angle"], axis=1) == 0)
        (row,) = injection_summary(parse_inject(spec), PRE)[0]["applied"]
        assert row == {"signal": "STEER_ANGLE_SENSOR.STEER_ANGLE", "unit": "deg", "magnitude": 3.0}


def test_a_frozen_message_still_freezes_each_signal_at_its_own_value():
    s = _raw()
    st = inject(s, parse_inject("stuck:STEER_ANGLE_SENSOR@2"), PRE).values[0]
    k = int(np.argmax(s.t >= 2.0))
    for c in ("steer_angle", "steer_fraction"):
        j = RAW_CHANNELS.index(c)
        assert np.ptp(st[k + 1:, j]) == 0 and np.ptp(s.values[0, k + 1:, j]) > 0


def test_internal_channel_magnitude_is_reported_in_the_signal_unit():
    (row,) = injection_summary(parse_inject("steer:0.01@2"), PRE)[0]["applied"]
    assert row["signal"] == "STEER_ANGLE_SENSOR.STEER_ANGLE" and row["unit"] == "deg"
    assert row["magnitude"] == pytest.approx(np.degrees(0.01 * 16.0))


def test_every_injected_sensor_is_judged():
    fs = parse_inject("bias:ACCEL_Y:1@20,drift:YAW_RATE:0.02/s@30,yaw_rate:0.01@40")
    assert injected_sensors(fs, PRE) == ["lateral_accelerometer", "yaw_rate"]


@pytest.mark.skipif(not RAV4.exists(), reason="the RAV4 log is not in ../shared/data/rav4-highway")
def test_a_two_fault_run_judges_both_faults_and_reports_the_applied_magnitudes():
    """With two faults on two sensors, announcing the second one is right, not false (issue 27
    item 5); the JSON gives what each signal received, in its unit."""
    from fdikit.systems.car.monitor_rav4 import run_rav4_log

    res = run_rav4_log(None, "bias:ACCEL_Y:1.0@35,gain:WHEEL_SPEED_RR:0.97@35")
    assert set(res["expected_sensors"]) == {"lateral_accelerometer", "wheel_rr"}
    named = {a["fault"] for a in res["announcements"] if a["t"] >= 35.0}
    assert any("wheel_rr" in h for h in named) or any("lateral" in h for h in named), res["announcements"]
    assert not [a for a in res["false_announcements"]
                if "wheel_rr" in a["fault"] or "lateral" in a["fault"]], res["false_announcements"]
    applied = {a["signal"]: a for f in res["injected"] for a in f["applied"]}
    assert any(k.endswith("ACCEL_Y") for k in applied), applied
