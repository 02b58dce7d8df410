"""Threshold design with explicit semantics (issue 15, item 4): per sample, per run, per hour; one
long correlated record (block bootstrap, GPD tail); refusals that name the numbers; 1-D input; one
``absolute`` default; ThresholdDesign as an object. Achieved rates are measured on held-out records."""

import copy

import numpy as np
import pytest
from scipy.signal import lfilter

from fdikit import DataError, Signals
from fdikit.detect import Hold, design_threshold


def ar1(n, phi, seed, channels=1):
    e = np.random.default_rng(seed).normal(size=(n, channels))
    return lfilter([1.0], [1.0, -phi], e, axis=0) * np.sqrt(1 - phi**2)


@pytest.fixture(scope="module")
def records():
    """One long design record and a longer held-out record of the same correlated process (2 channels)."""
    return ar1(300_000, 0.9, 1, 2), ar1(2_000_000, 0.9, 2, 2)


@pytest.mark.parametrize("pfa", [1e-2, 1e-3, 1e-4])
def test_per_sample_target_met_on_held_out_record(records, pfa):
    design, held = records
    d = design_threshold(design[None], pfa, per="sample")  # (1 run, T, 2 channels)
    assert d.threshold.shape == (2,)
    achieved = (np.abs(held) > d.threshold).mean(axis=0)
    assert np.all(achieved / pfa > 0.5) and np.all(achieved / pfa < 2.0), (d.method, achieved)
    # the design says how: method, effective samples (|AR(1)| at 0.9: tau ~ 1 + 2 * 0.81 / 0.19 ~ 9.5)
    assert all(6 < t < 14 for t in d.tau) and all(2e4 < n < 6e4 for n in d.n_eff)
    assert d.ci.shape == (2, 2) and np.all(d.ci[:, 0] < d.ci[:, 1])
    expected = "empirical" if pfa * min(d.n_eff) >= 10 else "gpd"
    assert d.method == [expected] * 2
    if expected == "gpd":
        assert all("GPD tail" in n for n in d.note) and d.tail[0]["extrapolation"] > 1


def test_one_long_record_threshold_follows_the_target(records):
    """Bug: on one long record the requested probability was ignored (same threshold for 0, 0.01, 0.5)."""
    x = records[0][:, 0]
    thr = [design_threshold(x, p, per="sample").threshold for p in (0.0, 0.01, 0.5)]
    assert thr[0] > thr[1] > thr[2]
    # the per-sample design is the quantile of |x|
    assert abs(thr[1] / np.quantile(np.abs(x), 0.99) - 1) < 1e-3
    assert abs(thr[2] / np.quantile(np.abs(x), 0.5) - 1) < 1e-3
    # a per-run target on one run cannot be met: refused, with the numbers
    with pytest.raises(DataError, match=r"1 runs for a per-run target of 0\.5"):
        design_threshold(x[None], 0.5)
    with pytest.raises(DataError, match=r"1 runs for a per-run target of 0\.01"):
        design_threshold(x[None], 0.01)


def test_one_d_input_is_one_residual_over_time(records):
    """Bug: a 1-D array silently became one run."""
    x = records[0][:50_000, 0]
    with pytest.raises(DataError, match="1-D array is one residual over time"):
        design_threshold(x, 0.01)
    a = design_threshold(x, 0.01, per="sample")
    b = design_threshold(x[None, :, None], 0.01, per="sample")
    assert a.threshold == b.threshold[0] and a.samples == 50_000 and a.runs == 1


def test_too_few_runs_refused_with_the_numbers():
    """Bug: 1-3 runs were accepted for pfa 1e-3 without a word."""
    g = np.random.default_rng(0).chisquare(1, size=(3, 500))
    with pytest.raises(DataError, match=r"3 runs for a per-run target of 0\.001.*>= 10000 runs"):
        design_threshold(g, 1e-3)
    # too few samples of one record for a per-sample target: the effective samples are named
    x = ar1(20_000, 0.9, 3)[:, 0]
    with pytest.raises(DataError, match=r"20000 samples \(\d+ effective.*max_extrapolation"):
        design_threshold(x, 1e-7, per="sample")


def test_per_run_target_met_on_fresh_runs_and_tail_below_the_data():
    rng = np.random.default_rng(4)
    g, fresh = rng.normal(size=(2000, 100)), rng.normal(size=(20000, 100))
    d = design_threshold(g, 0.02)  # 40 expected alarms: the order statistic
    assert d.method == "empirical" and d.achieved_pfa <= 0.02
    assert 0.01 < (np.abs(fresh) > d.threshold).any(axis=1).mean() < 0.03
    d = design_threshold(g, 1e-3)  # 2 expected alarms: the GPD tail of the per-run maxima
    assert d.method == "gpd" and "GPD tail" in d.note
    rate = (np.abs(fresh) > d.threshold).any(axis=1).mean()
    assert 0.5e-3 < rate < 2e-3, rate


def test_absolute_default_is_one_and_a_design_holds_on_its_own_data():
    """Bug: design_threshold's absolute default differed from Hold's: a '1 %' design then gave ~2-3 %."""
    rng = np.random.default_rng(5)
    r = rng.normal(size=(3000, 200, 1))
    d = design_threshold(r[..., 0], 0.01, margin=0.0)
    s = Signals(np.arange(200.0), r, ["r"])
    alarms = Hold(["r"], d.threshold).run(s)["r:alarm"].any(axis=1)
    assert alarms.mean() <= 0.01 + 1e-12
    from fdikit.detect.threshold import ABSOLUTE_DEFAULT

    assert ABSOLUTE_DEFAULT is True


def test_threshold_design_is_a_well_behaved_object():
    """Bug: ThresholdDesign.__getattr__ raised KeyError (hasattr, deepcopy and numpy broke)."""
    d = design_threshold(np.random.default_rng(6).normal(size=(500, 50)), 0.05)
    assert not hasattr(d, "no_such_field") and hasattr(d, "threshold")
    c = copy.deepcopy(d)
    assert c.threshold == d.threshold and np.array_equal(c.critical_values, d.critical_values)
    arr = np.array([d, d])
    assert arr.shape == (2,) and arr[0] is d
    with pytest.raises(AttributeError, match="no field 'nope'"):
        d.nope  # noqa: B018


def test_per_hour_family_wise_on_signals(records):
    design, held = records
    dt = 0.01
    s = Signals(np.arange(design.shape[0]) * dt, design, ["a", "b"])
    d = design_threshold(s, 20.0, per="hour", family_wise=True)  # 20 false alarms per hour, any channel
    assert d.channels == ["a", "b"] and d.target == [10.0, 10.0] and abs(d.dt / dt - 1) < 1e-9
    alarm = (np.abs(held) > d.threshold).any(axis=1)
    onsets = np.sum(alarm[1:] & ~alarm[:-1]) + alarm[0]
    per_hour = onsets / (held.shape[0] * dt / 3600)
    assert 10.0 < per_hour < 30.0, per_hour
    assert d.family_achieved <= 2 * 20.0
    with pytest.raises(DataError, match="needs the sample time"):
        design_threshold(design[None], 1.0, per="hour")


def test_refusal_names_the_channel():
    x = np.stack([ar1(30_000, 0.5, 7)[:, 0], ar1(30_000, 0.99, 8)[:, 0]], axis=1)
    with pytest.raises(DataError, match="channel 'slow'"):
        design_threshold(Signals(np.arange(30_000) * 0.1, x, ["fast", "slow"]), 1e-4, per="sample")
