"""Bad input never crashes and never lies (issue: monitor runtime, item 6), at the monitor level.

Every case corrupts a real record of the two-mass example and runs the config-style monitor
(observer residual, GLRT, hold, MHSSPT; on_invalid='hold') over it. A case passes when the run
does not crash, no output is NaN or inf, every corrupted sample is flagged invalid with a reason
(none silently dropped, no good sample flagged), and after the corruption the outputs equal those
of the record with the bad samples removed (the monitor held its state and resumed cleanly).
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fdikit import DataError, Signals
from fdikit.faults import Bias
from fdikit.systems import two_mass

from .two_mass_monitor import build as build_monitor
from .two_mass_monitor import observer_design

T = 300
CHANNELS = ["force", "pos1", "pos2"]


@pytest.fixture(scope="module")
def record():
    return two_mass.record([Bias("sensor:pos2", 0.01, start=1.5)], 1, 11, duration=(T - 1) * two_mass.DT)


@pytest.fixture(scope="module")
def design():
    return observer_design()


def build(design):
    """The two-mass monitor without a decision."""
    return build_monitor(design, decision=False)


def check(design, rec, values, times, bad_expected):
    """Run the stream and check the four promises; returns the result."""
    mon = build(design)
    mon.reset(1)
    R, S, invalid = [], [], []
    for k, t in enumerate(times):
        r, s, _ = mon.step(float(t), values[:, k], CHANNELS)
        R.append(r[0])
        S.append(s[0])
        if mon.last_invalid is not None:
            invalid.append(k)
            assert mon.last_invalid  # a reason, not an empty string
    R, S = np.array(R), np.array(S)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(S)), "NaN or inf reached an output"
    assert invalid == sorted(bad_expected), "flagged samples differ from the corrupted ones"
    good = np.setdiff1d(np.arange(len(times)), bad_expected)
    ref = build(design).stream(Signals(np.asarray(times)[good], values[:, good], CHANNELS))
    np.testing.assert_array_equal(R[good], ref.residuals.values[0])
    np.testing.assert_array_equal(S[good], ref.statistics.values[0])
    return R, S


KINDS = ["nan", "inf", "-inf", "dropout", "dup_time", "back_time"]


def corrupt(rec, kind, channel, start, length):
    v = rec.values.copy()
    t = rec.t.copy()
    ks = list(range(start, min(start + length, T)))
    c = CHANNELS.index(channel)
    if kind == "nan":
        v[0, ks, c] = np.nan
    elif kind == "inf":
        v[0, ks, c] = np.inf
    elif kind == "-inf":
        v[0, ks, c] = -np.inf
    elif kind == "dropout":  # every channel missing at once
        v[0, ks, :] = np.nan
    elif kind == "dup_time":  # repeated time stamps (a logger that re-sends a sample)
        t[ks] = t[start - 1]
    elif kind == "back_time":  # time jumps backwards
        t[ks] = t[start - 1] - 0.5 * two_mass.DT
    return v, t, ks


CASES = [(kind, ch, start, length) for kind in KINDS for ch in CHANNELS
         for start, length in ((1, 1), (50, 3), (160, 25), (T - 2, 2))]


@pytest.mark.parametrize("kind, channel, start, length", CASES)
def test_table_driven_corruption(design, record, kind, channel, start, length):
    v, t, bad = corrupt(record, kind, channel, start, length)
    check(design, record, v, t, bad)


def test_stuck_signal_is_data_not_an_error(design, record):
    # a stuck sensor is a *fault* for the monitor to find, not bad input: processed, no flag
    v = record.values.copy()
    v[0, 100:, 2] = v[0, 100, 2]
    _, S = check(design, record, v, record.t, [])
    names = build(design).stat_names
    # the frozen pos2 departs from the moving mass: the GLRT on r:pos2 alarms after the onset
    alarm = S[:, names.index("r:pos2:glrt:alarm")]
    assert not alarm[:100].any() and alarm[100:].any()


def test_missing_channel_and_wrong_shape_are_errors_before_processing(design, record):
    mon = build(design)
    mon.reset(1)
    with pytest.raises(DataError, match="lacks channel 'pos2'"):
        mon.step(0.0, record.values[:, 0, :2], CHANNELS[:2])
    with pytest.raises(DataError, match="must have shape"):
        mon.step(0.0, np.zeros((1, 5)), CHANNELS)
    with pytest.raises(DataError, match="unknown channel 'pos2'"):
        build(design).run(record.select(["force", "pos1"]))
    with pytest.raises(DataError, match="time is not finite"):
        mon.step(float("nan"), record.values[:, 0], CHANNELS)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_corruption(design, record, data):
    v = record.values.copy()
    t = record.t.copy()
    bad: set[int] = set()
    for _ in range(data.draw(st.integers(1, 6))):
        k = data.draw(st.integers(1, T - 1))
        what = data.draw(st.sampled_from(["nan", "inf", "huge_ok", "dup_time"]))
        c = data.draw(st.integers(0, 2))
        if what == "nan":
            v[0, k, c] = np.nan
            bad.add(k)
        elif what == "inf":
            v[0, k, c] = -np.inf
            bad.add(k)
        elif what == "huge_ok":  # a wild but finite value is data, not a flag
            v[0, k, c] = 1e6
        elif what == "dup_time" and k - 1 not in bad:
            t[k] = t[k - 1]
            bad.add(k)
    # a duplicated stamp right after another flagged sample compares against the last *good* time
    last = -np.inf
    expected = []
    for k in range(T):
        finite = np.all(np.isfinite(v[0, k]))
        if not t[k] > last or not finite:
            expected.append(k)
            if t[k] > last and not finite:
                last = t[k]
        else:
            last = t[k]
    check(design, record, v, t, expected)
