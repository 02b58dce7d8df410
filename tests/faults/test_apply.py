"""fdikit.faults.apply_faults: every fault type on a whole recorded log, on the log's names or on
aliases in other units; validation names the channel and the onset."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.faults import (
    Bias,
    Chirp,
    FaultInjector,
    Gain,
    Intermittent,
    Parametric,
    Ramp,
    Sinusoid,
    Stuck,
    apply_faults,
    resolve_channels,
)

T = np.arange(0.0, 10.0, 0.5)


def _log(runs=1):
    rng = np.random.default_rng(0)
    v = rng.normal(size=(runs, T.size, 3)) + np.array([0.0, 10.0, -3.0])
    return Signals(T, v, ["a", "b", "c"], ["deg/s", "km/h", "m/s^2"])


ALL = [
    Bias("b", 0.5, start=2.0),
    Ramp("b", 0.2, start=2.0, end=6.0),
    Gain("b", 1.05, start=2.0),
    Stuck("b", start=2.0),
    Stuck("b", 7.0, start=2.0),
    Intermittent("b", 1.0, start=2.0, period=2.0, duty=0.5),
    Sinusoid("b", 1.0, 0.25, start=2.0),
    Chirp("b", 1.0, f0=0.1, f1=0.5, sweep_time=4.0, start=2.0),
]


@pytest.mark.parametrize(
    "fault", ALL, ids=lambda f: type(f).__name__ + ("" if not isinstance(f, Stuck) else str(f.value))
)
def test_every_type_matches_the_simulation_injector(fault):
    """The whole-log result equals the per-sample FaultInjector that the simulator uses."""
    log = _log(runs=2)
    out = apply_faults(log, [fault])
    inj = FaultInjector([_as_sensor(fault)], outputs=["a", "b", "c"])
    inj.bind(np.arange(2))
    want = np.stack([inj.sensor(float(t), log.values[:, k].copy()) for k, t in enumerate(T)], axis=1)
    np.testing.assert_allclose(out.values, want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.values[:, T < 2.0], log.values[:, T < 2.0])  # before the onset
    np.testing.assert_array_equal(out.values[..., [0, 2]], log.values[..., [0, 2]])  # other channels
    assert out.names == log.names and out.units == log.units


def _as_sensor(f):
    import copy

    g = copy.deepcopy(f)
    g.target = "sensor:b"
    g.kind, g.channel = "sensor", "b"
    return g


def test_stuck_holds_the_onset_value_and_ramp_grows_from_zero():
    log = _log()
    out = apply_faults(log, [Stuck("a", start=3.0), Ramp("c", 0.5, start=4.0)])
    k3, k4 = int(np.argmax(T >= 3.0)), int(np.argmax(T >= 4.0))
    assert np.all(out["a"][0, k3:] == log["a"][0, k3])
    np.testing.assert_allclose(out["c"][0, k4:] - log["c"][0, k4:], 0.5 * (T[k4:] - 4.0), atol=1e-12)


def test_aliases_in_other_units_and_messages():
    log = _log()
    # the log holds rad/s; the fault is given in deg/s on the CAN name
    ch = {"YAW_RATE": ("a", np.pi / 180), "WHEELS": [("b", 1 / 3.6), ("c", 1 / 3.6)]}
    out = apply_faults(log, [Bias("YAW_RATE", 2.0, start=1.0)], channels=ch)
    np.testing.assert_allclose(out["a"][0, T >= 1.0] - log["a"][0, T >= 1.0], np.radians(2.0), atol=1e-15)
    st = apply_faults(log, [Stuck("WHEELS", 36.0, start=5.0)], channels=ch)  # 36 km/h = 10 m/s
    np.testing.assert_allclose(st.values[0, T >= 5.0][:, 1:], 10.0, atol=1e-12)
    # gain is unit-free, and the untouched samples are bit-identical (no unit round trip)
    g = apply_faults(log, [Gain("YAW_RATE", 1.1, start=5.0)], channels=ch)
    np.testing.assert_array_equal(g["a"][0, T < 5.0], log["a"][0, T < 5.0])
    np.testing.assert_allclose(g["a"][0, T >= 5.0], 1.1 * log["a"][0, T >= 5.0], rtol=1e-14)
    assert resolve_channels("sensor:WHEELS", log.names, ch) == [("b", 1 / 3.6), ("c", 1 / 3.6)]


def test_log_signals_keep_their_validity_mask():
    from fdikit.io import LogSignals

    v = _log().values.copy()
    valid = np.ones(v.shape, bool)
    v[0, 8, 1] = np.nan
    valid[0, 8, 1] = False
    log = LogSignals(T, v, ["a", "b", "c"], valid=valid)
    out = apply_faults(log, [Bias("b", 1.0, start=2.0)])
    assert isinstance(out, LogSignals)
    np.testing.assert_array_equal(out.valid, valid)
    assert np.isnan(out["b"][0, 8])
    ok = valid[0, :, 1] & (T >= 2.0)
    np.testing.assert_allclose(out["b"][0, ok] - v[0, ok, 1], 1.0)


def test_errors_name_the_channel_and_the_onset():
    log = _log()
    with pytest.raises(
        DataError, match=r"'nope' names no channel.*channels \['a', 'b', 'c'\] and the aliases \['X'\]"
    ):
        apply_faults(log, [Bias("nope", 1.0, start=1.0)], channels={"X": ("a", 1.0)})
    with pytest.raises(DataError, match=r"onset 12 s is outside the log, which spans 0 \.\. 9\.5 s"):
        apply_faults(log, [Ramp("a", 1.0, start=12.0)])
    with pytest.raises(DataError, match="onset -1 s"):
        apply_faults(log, [Bias("a", 1.0, start=-1.0)])
    with pytest.raises(DataError, match="Parametric"):
        apply_faults(log, [Parametric("param:R_w", 0.1)])
    with pytest.raises(DataError, match="alias 'X' maps to channel 'zz'"):
        apply_faults(log, [Bias("X", 1.0, start=1.0)], channels={"X": ("zz", 1.0)})
    with pytest.raises(DataError, match="scale"):
        apply_faults(log, [Bias("X", 1.0, start=1.0)], channels={"X": ("a", 0.0)})
    with pytest.raises(DataError, match="Fault objects"):
        apply_faults(log, [("a", 1.0, 2.0)])


def test_input_is_not_modified_and_per_run_magnitudes():
    log = _log(runs=3)
    before = log.values.copy()
    out = apply_faults(log, [Bias("a", [1.0, 2.0, 3.0], start=0.0)])
    np.testing.assert_array_equal(log.values, before)
    np.testing.assert_allclose(
        (out.values - before)[:, :, 0], np.array([1.0, 2.0, 3.0])[:, None] * np.ones(T.size)
    )
