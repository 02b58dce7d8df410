"""One gap policy for batch, gridded and streaming records (issue 16, item 3).

A time gap is held exactly like NaN samples in its place; the monitor says it cannot judge,
re-enters warm-up and announces nothing the gap caused; absolute (epoch) time stamps work at full
precision; batch == streaming throughout.
"""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.detect import Hold
from fdikit.faults import Bias
from fdikit.monitor import STATUS_NAMES, Decision, Monitor
from fdikit.residuals import ObserverResidual
from fdikit.systems import two_mass

from .two_mass_monitor import build, observer_design

DT = two_mass.DT
WARM, CANNOT = STATUS_NAMES.index("warmup"), STATUS_NAMES.index("cannot_judge")


@pytest.fixture(scope="module")
def design():
    return observer_design()


def cut(sig, t0, t1):
    """The record without the samples in [t0, t1) (a time gap) and with NaN there (gridded)."""
    m = (sig.t - sig.t[0] >= t0 - 1e-9) & (sig.t - sig.t[0] < t1 - 1e-9)
    v = sig.values.copy()
    v[:, m] = np.nan
    gapped = Signals(sig.t[~m], sig.values[:, ~m], sig.names, check=False)
    return gapped, Signals(sig.t, v, sig.names, check=False), m


def same_events(a, b):
    """Events equal in everything but the row index k (a gapped record has fewer rows)."""
    key = lambda e: (e.run, e.t, e.hypothesis, e.value, e.kind, e.size, e.episode)  # noqa: E731
    return [key(e) for e in a] == [key(e) for e in b]


def test_nominal_record_with_a_gap_and_a_nan_block_raises_no_false_alarm(design):
    # a nominal record with one 0.5 s gap (at 10 s) and one 1 s NaN block (at 20 s). Before this
    # policy the gap was bridged (streaming) or held without warm-up (gridded): this monitor gave
    # 12 false announcements on this very record either way, the examples/two-mass config monitor
    # 19; and the batch path refused the gapped record outright ("signals are sampled at
    # 0.0101695 s but the filter was designed for dt = 0.01 s").
    rec = two_mass.record((), 1, 100, duration=30.0)
    v = rec.values.copy()
    v[:, 2000:2100] = np.nan
    rec = Signals(rec.t, v, rec.names, check=False)
    gapped, gridded, m = cut(rec, 10.0, 10.5)
    mon = build(design)
    res_gap, res_grid = mon.run(gapped), mon.run(gridded)
    assert res_gap.events == [] and res_grid.events == []
    assert [(g.t_start, g.t_end, g.n_missing, g.k) for g in res_gap.gaps] == [
        (rec.t[999], rec.t[1050], 50, 1000)]
    assert res_grid.gaps == []
    # the status: the NaN samples cannot be judged; the samples after them warm up
    assert (res_grid.status[0, m] == CANNOT).all() and res_grid.status[0, 1050] == WARM
    assert res_gap.status[0, 1000] == WARM and not (res_gap.status == CANNOT).sum() - 100
    # identical outputs at the shared samples: the gap was held exactly like the NaN samples
    np.testing.assert_array_equal(res_gap.statistics.values, res_grid.statistics.values[:, ~m])
    np.testing.assert_array_equal(res_gap.residuals.values, res_grid.residuals.values[:, ~m])
    # the batch run took the streaming path: the same as streaming sample by sample
    st = mon.stream(gapped)
    np.testing.assert_array_equal(st.statistics.values, res_gap.statistics.values)
    assert st.gaps == res_gap.gaps and (st.status == res_gap.status).all()


def test_fault_after_a_gap_gives_identical_events_and_none_from_the_gap(design):
    rec = two_mass.record([Bias("sensor:pos2", 0.02, start=15.0)], 1, 3, duration=25.0)
    clean = build(design).run(rec)
    gapped, gridded, _ = cut(rec, 8.0, 8.5)
    mon = build(design)
    a, b = mon.run(gapped), mon.run(gridded)
    assert a.events and same_events(a.events, b.events) and same_events(a.cleared, b.cleared)
    # the fault is found as on the clean record, and nothing is announced in or right after the gap
    assert [(e.t, e.hypothesis) for e in a.events] == [(e.t, e.hypothesis) for e in clean.events]
    assert all(e.t >= 15.0 for e in a.events)
    warm = gapped.t[(a.status[0] == WARM) & (gapped.t > 8.0)]   # (the start-up warm-up is before it)
    assert warm.min() == pytest.approx(8.5) and warm.max() < 15.0
    # follow mode: one sample at a time through step gives the same events
    mon.reset(1)
    got = []
    for k in range(gapped.n_samples):
        got += mon.step(float(gapped.t[k]), gapped.values[:, k], gapped.names)[2]
    assert [e for e in got if e.kind == "onset"] == a.events


def test_epoch_time_stamps_give_the_same_events(design):
    rec = two_mass.record([Bias("sensor:pos2", 0.02, start=5.0)], 1, 8, duration=12.0)
    t0 = 1.7e9
    epoch = Signals(rec.t + t0, rec.values, rec.names)  # float64 steps jitter by ~2.4e-7 s
    assert np.ptp(np.diff(epoch.t)) > 1e-8
    ref = build(design).run(rec)
    got = build(design).run(epoch)
    assert ref.events and [(e.k, e.hypothesis, e.value) for e in got.events] == \
        [(e.k, e.hypothesis, e.value) for e in ref.events]
    np.testing.assert_array_equal(got.statistics.values, ref.statistics.values)
    # with a gap too (the streaming path): the same sample indices as the relative record
    g_rel, _, _ = cut(rec, 2.0, 2.5)
    g_abs = Signals(g_rel.t + t0, g_rel.values, g_rel.names)
    a, b = build(design).run(g_rel), build(design).run(g_abs)
    assert [(e.k, e.hypothesis) for e in a.events] == [(e.k, e.hypothesis) for e in b.events]
    assert [(g.k, g.n_missing) for g in b.gaps] == [(200, 50)]


def test_irregular_or_wrong_rate_records_are_refused_clearly(design):
    rec = two_mass.record((), 1, 0, duration=3.0)
    rng = np.random.default_rng(1)
    jit = rec.t + rng.uniform(-0.2, 0.2, rec.t.size) * DT       # 20 % jitter, no gap
    with pytest.raises(DataError, match=r"irregular: sample \d+ follows after .*\(\[log\]\.rate = 100 Hz\)"):
        build(design).run(Signals(jit, rec.values, rec.names))
    slow = Signals(np.arange(rec.n_samples) * 0.02, rec.values, rec.names)
    with pytest.raises(DataError, match=r"sampled every 0.02 s \(median interval\) but the monitor expects "
                                        r"dt = 0.01 s"):
        build(design).run(slow)
    with pytest.raises(DataError, match="max_gap .* must exceed the sample period"):
        build(design, max_gap=0.005).run(rec)
    with pytest.raises(DataError, match="warmup must be >= 0"):
        build(design, warmup=-1.0)


def test_explicit_warmup_covers_the_start_in_batch_and_stream(design):
    rec = two_mass.record([Bias("sensor:pos1", 0.03, start=0.3), Bias("sensor:pos2", 0.03, start=2.0)], 2, 4,
                          duration=4.0)
    mon = build(design, warmup=1.0)
    a, b = mon.run(rec), mon.stream(rec)  # batch splits the processors at the warm-up's end
    np.testing.assert_array_equal(a.statistics.values, b.statistics.values)
    assert a.events == b.events and a.cleared == b.cleared
    assert (a.status[:, :100] == WARM).all() and (a.status[:, 100:] == 0).all()
    # the pos1 bias at 0.3 s alarms without the warm-up; with it nothing is announced before 1 s
    assert any(e.k < 100 for e in build(design, warmup=0.0).run(rec).events)
    assert a.events and all(e.k >= 100 for e in a.events)


class Resumable(Hold):
    """A Hold that records the resume calls it gets."""

    calls: list

    def resume(self, n_held):
        self.calls.append(n_held)


def test_resume_hook_and_checkpoint_inside_a_warmup(design, tmp_path):
    rec = two_mass.record((), 1, 2, duration=6.0)
    gapped, _, _ = cut(rec, 2.0, 2.3)

    def mk():
        gen = ObserverResidual(design)
        h = Resumable(gen.output_names, 0.01, Z=3)
        h.calls = []
        return Monitor([gen], [h], Decision(h.output_names), on_invalid="hold"), h

    mon, h = mk()
    full = mon.stream(gapped)
    assert h.calls == [30]
    # checkpoint right after the gap (mid warm-up), restore into a fresh monitor, continue
    mon, _ = mk()
    mon.reset(1)
    stop = 205
    for k in range(stop):
        mon.step(float(gapped.t[k]), gapped.values[:, k], gapped.names)
    assert mon.last_status == "warmup"
    mon.save_checkpoint(tmp_path / "ck.npz")
    other, _ = mk()
    other.load_checkpoint(tmp_path / "ck.npz")
    S, ev = [], []
    for k in range(stop, gapped.n_samples):
        _, s, e = other.step(float(gapped.t[k]), gapped.values[:, k], gapped.names)
        S.append(s[0])
        ev += e
    np.testing.assert_array_equal(np.array(S), full.statistics.values[0, stop:])
    assert [e for e in ev if e.kind == "onset"] == [e for e in full.events if e.k >= stop]
