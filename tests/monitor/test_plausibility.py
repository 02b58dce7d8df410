"""Plausibility checks (issue 16, item 2): range, rate and spike rules per channel and the generic
absurd-magnitude limit. A failing sample is flagged with its reason and never reaches a filter."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.faults import Bias
from fdikit.monitor import Monitor, Plausibility, PlausibilityChecker
from fdikit.residuals import ObserverResidual
from fdikit.systems import two_mass

from .two_mass_monitor import build, observer_design

CH = ["force", "pos1", "pos2"]


@pytest.fixture(scope="module")
def design():
    return observer_design()


@pytest.fixture(scope="module")
def record():
    return two_mass.record([Bias("sensor:pos2", 0.02, start=12.0)], 1, 21, duration=16.0)


def with_value(rec, k, c, x):
    v = rec.values.copy()
    v[0, k, CH.index(c)] = x
    return Signals(rec.t, v, rec.names, check=False)


def test_a_1e300_spike_is_flagged_and_changes_nothing_after_it(design, record):
    # before: the spike counted as a valid sample, the observer's residual reached 1e290, the
    # alarms stayed on for the rest of the log and invalid_samples read 0
    spiky = with_value(record, 300, "pos2", 1e300)
    res = build(design).run(spiky)
    assert [(k, why) for _, k, why in res.invalid] == [
        (300, "channel 'pos2' at sample 300 (t = 3 s): 1e+300 exceeds the absurd-magnitude limit 1e+12 "
              "(max_abs)")]
    assert np.abs(res.residuals.values).max() < 0.1
    # held exactly like a NaN there: identical outputs everywhere
    nan = build(design).run(with_value(record, 300, "pos2", np.nan))
    np.testing.assert_array_equal(res.statistics.values, nan.statistics.values)
    # and the events equal those of the log without the spike: the bias at 12 s, nothing else
    clean = build(design).run(record)
    assert res.events
    assert [(e.t, e.hypothesis) for e in res.events] == [(e.t, e.hypothesis) for e in clean.events]
    assert all(e.t >= 12.0 for e in res.events)
    assert res.events == build(design).stream(spiky).events
    # max_abs=None switches the generic limit off: the spike is data again (and poisons the filter)
    off = Monitor([ObserverResidual(design)], on_invalid="hold", max_abs=None).run(spiky)
    assert off.invalid == [] and np.abs(off.residuals.values).max() > 1e200
    # on_invalid="raise": a clear error
    mon = Monitor([ObserverResidual(design)])
    with pytest.raises(DataError, match=r"channel 'pos2' at sample 300 \(t = 3 s\): 1e\+300 exceeds"):
        mon.run(spiky)


def test_range_rate_and_spike_rules(design, record):
    rules = {"pos2": Plausibility(min=-2.0, max=2.0), "pos1": Plausibility(max_rate=3.0, spike=8.0)}
    bad = with_value(record, 200, "pos2", 3.0)                       # out of range
    v = bad.values.copy()
    v[0, 500, 1] += 0.1                                              # 10 m/s in one sample: rate
    v[0, 800, 1] += 0.025                                            # ~9 noise std: a spike
    v[0, 1000:, 1] += 0.06                                           # a genuine step: one sample lost
    bad = Signals(bad.t, v, bad.names, check=False)
    mon = build(design, plausibility=rules)
    res = mon.run(bad)
    got = {k: why for _, k, why in res.invalid}
    assert sorted(got) == [200, 500, 800, 1000]
    assert got[200] == "channel 'pos2' at sample 200 (t = 2 s): 3 above max 2 (plausibility)"
    assert got[500].startswith("channel 'pos1' at sample 500 (t = 5 s): changes at ") and \
        got[500].endswith("units/s, above max_rate 3 (plausibility)")
    assert "spike" in got[800] and "limit spike = 8" in got[800]
    # nominal data raise no flag, and batch == streaming
    assert build(design, plausibility=rules).run(record).invalid == []
    st = build(design, plausibility=rules).stream(bad)
    assert st.invalid == res.invalid and st.events == res.events
    np.testing.assert_array_equal(st.statistics.values, res.statistics.values)
    # the rules' state survives a checkpoint
    m = build(design, plausibility=rules)
    m.reset(1)
    for k in range(790):
        m.step(float(bad.t[k]), bad.values[:, k], bad.names)
    other = build(design, plausibility=rules)
    other.restore(m.state())
    flagged = []
    for k in range(790, 1010):
        other.step(float(bad.t[k]), bad.values[:, k], bad.names)
        if other.last_invalid:
            flagged.append(k)
    assert flagged == [800, 1000]


def test_rules_are_validated():
    with pytest.raises(DataError, match=r"min \(1\) must be below max \(0\)"):
        Plausibility(min=1, max=0)
    with pytest.raises(DataError, match="max_rate must be positive"):
        Plausibility(max_rate=-2)
    with pytest.raises(DataError, match="spike must be a positive"):
        Plausibility(spike=0)
    with pytest.raises(DataError, match="window must be an integer"):
        Plausibility(spike=5, window=2)
    with pytest.raises(DataError, match="must be a number"):
        Plausibility(max="high")
    with pytest.raises(DataError, match=r"channels.y: unknown plausibility keys \['maximum'\]"):
        Plausibility.from_mapping({"maximum": 3}, where="channels.y")
    assert Plausibility.from_mapping({"min": 0, "max": 2}).to_dict()["max"] == 2.0


def test_rules_must_name_input_channels(design):
    with pytest.raises(DataError, match=r"plausibility rules for \['speed'\], which are not input channels"):
        Monitor([ObserverResidual(design)], plausibility={"speed": Plausibility(max=1)})
    with pytest.raises(DataError, match="must be a Plausibility"):
        Monitor([ObserverResidual(design)], plausibility={"pos1": {"max": 1}})


def test_checker_spike_is_an_isolated_sample():
    rng = np.random.default_rng(0)
    x = np.cumsum(0.01 * rng.standard_normal(300))
    x[150] += 1.0             # a spike
    x[220:] += 1.0            # a step: costs one sample, then the new level is accepted
    c = PlausibilityChecker(["y"], {"y": Plausibility(spike=8.0, window=40)}, 1e12)
    c.reset(1, dt=0.1)
    flagged = []
    for k, v in enumerate(x):
        why = c.check(k, 0.1 * k, np.array([[v]]))
        c.observe(0.1 * k, np.array([[v]]), why is None)
        if why:
            flagged.append(k)
    assert flagged == [150, 220]
