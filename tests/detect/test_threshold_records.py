"""Thresholds from many short records and per-hour targets on little data (issue 28, items 3 and 5)."""

import re

import numpy as np
import pytest
from scipy.signal import lfilter

from fdikit.detect import design_threshold
from fdikit.errors import DataError
from fdikit.monitor.declarative import AlarmTarget, alarm_from_config


def _ar1(rng, shape, a=0.8):
    return lfilter([1.0], [1.0, -a], rng.normal(size=shape), axis=-1)


def test_per_hour_from_ten_minutes_states_interval_or_hours_needed():
    dt = 0.01
    x = _ar1(np.random.default_rng(0), 60_000)               # 10 minutes at 100 Hz
    # one false alarm an hour: beyond what 10 minutes show -> refused with the hours needed
    with pytest.raises(DataError) as err:
        design_threshold(x, 1.0, per="hour", dt=dt, Z=3)
    msg = str(err.value)
    m = re.search(r"needs >= ([0-9.e+]+) h of nominal data like these for the GPD tail \(>= ([0-9.e+]+) h "
                  r"for the empirical design\), given ([0-9.e+]+) h", msg)
    assert m, msg
    gpd_h, emp_h, given_h = map(float, m.groups())
    assert given_h == pytest.approx(1 / 6, rel=1e-2)
    assert emp_h == pytest.approx(10.0, rel=1e-2)            # min_events = 10 onsets at 1 / h
    assert given_h < gpd_h < emp_h
    # the stated hours are enough: that much data of the same process gives a GPD design
    more = _ar1(np.random.default_rng(1), int(np.ceil(1.05 * gpd_h * 3600 / dt)))
    d = design_threshold(more, 1.0, per="hour", dt=dt, Z=3)
    assert d.method == "gpd"
    # a target these 10 minutes can extrapolate to: the GPD tail with its interval, stated
    d = design_threshold(x, 30.0, per="hour", dt=dt, Z=3)
    assert d.method == "gpd" and 0 < d.ci[0] < d.ci[1] < np.inf
    assert "interval of the rate at the threshold" in d.note


def test_pooled_records_equal_runs_and_unequal_lengths():
    rng = np.random.default_rng(2)
    x = _ar1(rng, (6, 20_000))
    for per, pfa, kw in [("sample", 1e-3, {}), ("hour", 20.0, {"dt": 0.01}), ("run", 0.5, {"min_events": 0})]:
        a = design_threshold(x, pfa, per=per, Z=3, **kw)
        b = design_threshold(list(x), pfa, per=per, Z=3, **kw)
        assert a.threshold == b.threshold and np.array_equal(a.ci, b.ci) and a.n_eff == b.n_eff
    # records of different lengths, 1-D (one channel) and 2-D (channels)
    recs = [x[0], x[1, :5000], x[2, :12_000], x[3, :777]]
    d = design_threshold(recs, 1e-3, per="sample", Z=3)
    assert d.samples == 20_000 + 5000 + 12_000 + 777 and d.runs == 4 and np.ndim(d.threshold) == 0
    d2 = design_threshold([r[:, None] for r in recs], 1e-3, per="sample", Z=3)
    assert d2.threshold[0] == d.threshold
    # the samples and effective samples add up: the design shows lower rates than any one record
    h = design_threshold(recs, 20.0, per="hour", dt=0.01, Z=3)
    assert h.samples == d.samples and h.method in ("empirical", "gpd")


def test_pooled_records_never_bridge_boundaries():
    rng = np.random.default_rng(3)
    a = 0.1 * rng.normal(size=300)
    b = 0.1 * rng.normal(size=170)
    a[-1] = 10.0          # the first record ends high ...
    b[0] = 10.0           # ... and the next starts high: one sample each, never two in a row
    # concatenated, the hold of 2 would see two samples over 9 and alarm; pooled, it never does
    d = design_threshold([a, b], 0.0, per="sample", Z=2)
    assert d.threshold < 1.0
    cat = design_threshold(np.concatenate([a, b]), 0.0, per="sample", Z=2)
    assert cat.threshold > 9.0
    # per run: one critical value per record, the record's own held maximum
    c = design_threshold([a, b], 0.5, per="run", Z=2, method="empirical", min_events=0)
    own = [np.max(np.minimum(np.abs(r[1:]), np.abs(r[:-1]))) for r in (a, b)]
    assert np.array_equal(c.critical_values, own)
    with pytest.raises(DataError, match="different numbers of channels"):
        design_threshold([a, np.ones((5, 2))], 1e-2, per="sample")


def test_alarm_target_one_per_hour_means_one_expected_alarm_an_hour():
    a = alarm_from_config({"alarm": {"pfa": 1.0, "per": "hour", "hold": 3}})
    assert a == AlarmTarget(1.0, "hour", None, 3)
    dt = 0.1
    assert a.per_sample(dt) * 3600 / dt == pytest.approx(1.0, rel=1e-12)
    with pytest.raises(DataError, match="probability"):
        AlarmTarget(1.0, "sample")
    # designed on 20 h of simulated nominal data, the onset rate over 200 fresh hours lies in the
    # stated interval
    rng = np.random.default_rng(4)
    per_h = round(3600 / dt)
    d = design_threshold(_ar1(rng, (20, per_h), 0.9), a.pfa, per=a.per, Z=a.hold, dt=dt)
    onsets, hours = 0, 0
    for _ in range(10):
        x = np.abs(_ar1(rng, (20, per_h), 0.9))
        al = np.minimum.reduce([x[:, 2:], x[:, 1:-1], x[:, :-2]]) > d.threshold
        al = np.concatenate([np.zeros((20, 2), bool), al], axis=1)
        onsets += int(np.sum(al[:, 1:] & ~al[:, :-1]) + np.sum(al[:, 0]))
        hours += 20
    rate = onsets / hours
    assert d.ci[0] <= rate <= d.ci[1], (rate, d.ci, d.method)
    assert 0.5 < rate < 2.0


def test_declarative_fallback_is_announced():
    import tomllib
    from pathlib import Path

    from fdikit.monitor.declarative import design_monitor

    ex = Path(__file__).resolve().parents[2] / "examples" / "own-system"
    design = tomllib.loads((ex / "monitor.toml").read_text())["design"]
    with pytest.warns(UserWarning, match=r"target pfa = 0.1 expected false alarms per hour .* simulated "
                                         r"nominal data \(20 runs.*Gaussian chi bound"):
        out = design_monitor(design, ex)
    assert out["_report"]["threshold_design"]["method"] == "gaussian chi bound"


def test_gpd_method_per_unit_of_time():
    x = _ar1(np.random.default_rng(5), (2, 30_000))
    d = design_threshold(x, 100.0, per="minute", dt=0.01, method="gpd")    # failed on min_events = inf
    assert d.method == "gpd" and d.ci[0] < d.ci[1] and "per minute" in d.note
