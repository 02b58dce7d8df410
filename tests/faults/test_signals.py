"""Fault signals, the fault injector and scenario validation (fdikit.faults)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdikit.errors import DataError, ModelError
from fdikit.faults import (
    Bias,
    Drift,
    FaultInjector,
    Gain,
    Intermittent,
    Noise,
    Parametric,
    Ramp,
    Scenario,
    Sinusoid,
    Step,
    Stuck,
    parse_target,
)

T = np.round(np.arange(0, 41) * 0.1, 10)  # 0 .. 4 s


def window(t, start, end):
    return (t >= start) & (t < end)


# ---------------------------------------------------------------- each fault type, closed forms
def test_bias_only_inside_window():
    s = Bias("sensor:v", 0.5, start=1.0, end=3.0).signal(T, base=2.0)[0]
    expected = np.where(window(T, 1.0, 3.0), 2.5, 2.0)
    assert np.array_equal(s, expected)
    assert Step is Bias and Drift is Ramp


def test_ramp_grows_from_start_and_stops_at_end():
    s = Ramp("actuator:u", 2.0, start=1.0, end=3.0).signal(T, base=1.0)[0]
    expected = [1.0 + 2.0 * (t - 1.0) if 1.0 <= t < 3.0 else 1.0 for t in T]
    np.testing.assert_allclose(s, expected, rtol=0, atol=1e-12)
    assert s[T == 3.0][0] == 1.0  # end is exclusive


def test_sinusoid_closed_form():
    f = Sinusoid("sensor:v", 0.7, 1.3, phase=0.4, start=0.5, end=3.5)
    s = f.signal(T)[0]
    expected = [0.7 * math.sin(2 * math.pi * 1.3 * (t - 0.5) + 0.4) if 0.5 <= t < 3.5 else 0.0 for t in T]
    np.testing.assert_allclose(s, expected, rtol=0, atol=1e-12)


def test_intermittent_explicit_windows():
    f = Intermittent("sensor:v", 3.0, windows=[(0.5, 1.0), (2.0, 2.3), (3.5, 5.0)], start=0.0, end=3.8)
    s = f.signal(T)[0]
    on = window(T, 0.5, 1.0) | window(T, 2.0, 2.3) | window(T, 3.5, 3.8)
    assert np.array_equal(s, np.where(on, 3.0, 0.0))


def test_intermittent_period_and_duty():
    f = Intermittent("sensor:v", -1.0, period=0.8, duty=0.25, start=1.0, end=3.4)
    s = f.signal(T)[0]
    on = np.zeros(T.size, bool)
    for k in range(10):  # on for [1 + 0.8 k, 1 + 0.8 k + 0.2)
        on |= window(T, 1.0 + 0.8 * k - 1e-9, 1.0 + 0.8 * k + 0.2 - 1e-9)
    on &= window(T, 1.0, 3.4)
    assert on.sum() == 6  # 1.0, 1.1, 1.8, 1.9, 2.6, 2.7 (3.4 is outside)
    assert np.array_equal(s, np.where(on, -1.0, 0.0))


def test_gain_multiplies():
    s = Gain("sensor:w", 0.95, start=1.0, end=2.0).signal(T, base=[100.0, -4.0])
    expected = np.where(window(T, 1.0, 2.0), 0.95, 1.0) * np.array([[100.0], [-4.0]])
    np.testing.assert_allclose(s, expected, rtol=1e-15)


def test_stuck_at_value_and_hold_at_onset():
    # stuck at a value
    s = Stuck("sensor:v", 3.0, start=1.0, end=2.0).signal(T, base=7.0)[0]
    assert np.array_equal(s, np.where(window(T, 1.0, 2.0), 3.0, 7.0))
    # hold the (time-varying) healthy value at onset: v(t) = sin(t) + run index
    inj = FaultInjector([Stuck("sensor:a", start=1.2, end=3.0)], outputs=["a", "b"])
    inj.bind(np.arange(3))
    out = []
    for t in T:
        y = np.column_stack([np.sin(t) + np.arange(3), np.full(3, t)])
        out.append(inj.sensor(t, y))
    out = np.array(out)  # (T, runs, 2)
    held = np.sin(1.2) + np.arange(3)
    for k, t in enumerate(T):
        exp_a = held if 1.2 <= t < 3.0 else np.sin(t) + np.arange(3)
        np.testing.assert_allclose(out[k, :, 0], exp_a, rtol=0, atol=1e-15)
        assert np.all(out[k, :, 1] == t)  # the other channel untouched


@pytest.mark.parametrize("mode, expected", [("relative", 0.3 * 0.75), ("absolute", 0.3 - 0.25),
                                            ("set", -0.25)])
def test_parametric_modes(mode, expected):
    f = Parametric("param:R_w", -0.25, mode=mode, start=1.0, end=2.0)
    s = f.signal(T, base=0.3)[0]
    np.testing.assert_allclose(s, np.where(window(T, 1.0, 2.0), expected, 0.3), rtol=1e-15)


def test_permanent_fault_has_no_end():
    s = Bias("sensor:v", 1.0, start=2.0).signal(T)[0]
    assert np.array_equal(s, (T >= 2.0).astype(float))


# ---------------------------------------------------------------- per-run magnitudes
def test_per_run_magnitudes_follow_run_ids():
    mags = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    f = Bias("sensor:v", mags, start=0.0)
    assert f.signal([1.0], base=np.zeros(5))[:, 0].tolist() == mags.tolist()
    # run ids select entries of the per-run array
    assert f.signal([1.0], base=np.zeros(2), run_ids=[4, 1])[:, 0].tolist() == [4.0, 1.0]
    inj = FaultInjector([f], outputs=["v"])
    with pytest.raises(DataError, match="5 per-run values but the batch has 3 runs"):
        inj.bind(np.arange(3), total=3)
    with pytest.raises(DataError, match="run id 7"):
        inj.bind(np.array([7]), total=None)


def test_injector_does_not_modify_its_input_and_applies_in_order():
    inj = FaultInjector([Bias("actuator:u1", 1.0, start=0.0), Gain("actuator:u1", 3.0, start=0.0)],
                        inputs=["u0", "u1"])
    inj.bind(np.arange(2))
    u = np.ones((2, 2))
    out = inj.actuator(0.5, u)
    assert np.array_equal(u, np.ones((2, 2)))
    assert out[:, 1].tolist() == [6.0, 6.0] and out[:, 0].tolist() == [1.0, 1.0]  # (1 + 1) * 3


def test_fault_inputs_and_params():
    inj = FaultInjector([Ramp("slope", 2.0, start=1.0), Parametric("param:k", 1.0, start=0.5)],
                        params=["k", "c"], fault_inputs=["leak", "slope"])
    inj.bind(np.arange(2))
    np.testing.assert_allclose(inj.fault_inputs(1.5, 2), [[0.0, 1.0], [0.0, 1.0]])
    p = inj.params(1.0, {"k": 2.0, "c": 5.0})
    assert p["c"] == 5.0 and p["k"] == 4.0
    assert inj.params(0.2, {"k": 2.0, "c": 5.0})["k"] == 2.0


# ---------------------------------------------------------------- errors
def test_unknown_target_names_target_and_lists_valid_ones():
    with pytest.raises(ModelError) as e:
        FaultInjector([Bias("sensor:yaw", 1.0)], inputs=["brake"], outputs=["v", "w"], params=["K_f"],
                      model_name="car")
    msg = str(e.value)
    assert "'sensor:yaw'" in msg and "unknown sensor output 'yaw'" in msg
    for t in ("actuator:brake", "sensor:v", "sensor:w", "param:K_f"):
        assert t in msg
    with pytest.raises(ModelError, match="unknown actuator input 'gas'"):
        FaultInjector([Ramp("actuator:gas", 1.0)], inputs=["brake"])
    with pytest.raises(ModelError, match="unknown fault input 'slope'"):
        FaultInjector([Bias("slope", 1.0)], fault_inputs=["leak"])


def test_meaningless_combinations_raise():
    with pytest.raises(ModelError, match="Parametric fault needs a 'param:<name>'"):
        FaultInjector([Parametric("sensor:v", 0.1)], outputs=["v"])
    with pytest.raises(ModelError, match="additive fault input"):
        FaultInjector([Gain("leak", 0.5)], fault_inputs=["leak"])


def test_bad_fault_definitions_raise():
    with pytest.raises(DataError, match="end .* must be after start"):
        Bias("sensor:v", 1.0, start=2.0, end=1.0)
    with pytest.raises(DataError, match="NaN or inf"):
        Bias("sensor:v", [1.0, np.nan])
    with pytest.raises(DataError, match="shaped \\(runs,\\)"):
        Gain("sensor:v", np.ones((2, 2)))
    with pytest.raises(DataError, match="give windows="):
        Intermittent("sensor:v", 1.0)
    with pytest.raises(DataError, match="window 1 .* ends before it starts"):
        Intermittent("sensor:v", 1.0, windows=[(0, 1), (3, 2)])
    with pytest.raises(DataError, match="duty must be in"):
        Intermittent("sensor:v", 1.0, period=1.0, duty=1.5)
    with pytest.raises(DataError, match="mode must be"):
        Parametric("param:k", 0.1, mode="percent")
    with pytest.raises(DataError, match="names no sensor"):
        parse_target("sensor:")
    with pytest.raises(DataError, match="non-empty string"):
        Bias(3, 1.0)


def test_parse_target():
    assert parse_target("actuator:brake") == ("actuator", "brake")
    assert parse_target("param:K_f") == ("param", "K_f")
    assert parse_target("slope") == ("input", "slope")


# ---------------------------------------------------------------- scenario and noise validation
def test_scenario_grid_and_validation():
    sc = Scenario(duration=12.5, dt=1e-3, sample_time=5e-3)
    assert sc.grid() == (1e-3, 5, 12500, 2501)
    with pytest.raises(DataError, match="sample_time must be a multiple of the integration step"):
        Scenario(duration=1.0, dt=0.01, sample_time=0.025)
    with pytest.raises(DataError, match="duration must be a multiple of sample_time"):
        Scenario(duration=1.03, dt=0.01, sample_time=0.02)
    with pytest.raises(DataError, match="positive"):
        Scenario(duration=1.0, dt=-0.1)
    with pytest.raises(DataError, match="not both"):
        Scenario(duration=1.0, dt=0.1, inputs=[1.0], controller=lambda t, y: y)
    with pytest.raises(DataError, match="not a Fault"):
        Scenario(duration=1.0, dt=0.1, faults=["sensor:v"])
    with pytest.raises(DataError, match="Noise object"):
        Scenario(duration=1.0, dt=0.1, noise={"process": 1.0})
    with pytest.raises(DataError, match="dt is not set"):
        Scenario(duration=1.0).grid()


def test_noise_validation():
    with pytest.raises(DataError, match="not both"):
        Noise(process=[1.0], process_snr_db=20.0)
    with pytest.raises(DataError, match="variance -1.0 of channel 1 is negative"):
        Noise(measurement=[1.0, -1.0])
    with pytest.raises(DataError, match="not positive semidefinite"):
        Noise(process=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(DataError, match="not symmetric"):
        Noise(process=[[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(DataError, match="process_mode"):
        Noise(process=[1.0], process_mode="wiener")
    with pytest.raises(DataError, match="dB"):
        Noise(measurement_snr_db=np.nan)
