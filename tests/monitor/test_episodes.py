"""Events as episodes (issue 16, item 4): one onset per fault episode, a cleared event, no flicker;
batch (Decision.events / Monitor.run) and streaming (Monitor.step) give the same lists."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.monitor import STATUS_NAMES, Decision, Event, Monitor, ResidualGenerator

DT = 0.01


class Passthrough(ResidualGenerator):
    """Residual r:<c> = measurement c (so a test sets the alarm channels directly)."""

    _state_attrs = ()

    def __init__(self, channels, dt=None):
        self.u_names, self.y_names = [], list(channels)
        self.output_names = [f"r:{c}" for c in channels]
        if dt is not None:
            self.dt = dt

    def reset(self, runs=1):
        pass

    def _step(self, u, y):
        return y.copy()


def flicker(T=400):
    """An alarm that is on 0.10-0.20 s, off 50 ms, on 0.25-0.40 s, off 30 ms, on 0.43-0.60 s."""
    a = np.zeros(T)
    a[10:20] = 1
    a[25:40] = 1
    a[43:60] = 1
    return a


def test_flickering_alarm_is_one_episode():
    a = flicker()
    s = Signals(np.arange(a.size) * DT, a[:, None], ["alarm"])
    ev = Decision(["alarm"], names={"alarm": "sensor:y"}).events(s.t, s)
    # one onset at the first crossing; cleared 1.0 s (100 samples) after the last on sample
    assert [(e.kind, e.k, e.hypothesis, e.episode) for e in ev] == [
        ("onset", 10, "sensor:y", 0), ("cleared", 159, "sensor:y", 0)]
    # clear_after = 0 is the old rising-edge rule: every re-crossing announced again
    old = Decision(["alarm"], clear_after=0.0).events(s.t, s)
    assert [e.k for e in old if e.kind == "onset"] == [10, 25, 43]
    assert [e.k for e in old if e.kind == "cleared"] == [20, 40, 60]


def test_monitor_batch_equals_stream_with_episodes_sizes_and_runs():
    rng = np.random.default_rng(4)
    T, runs = 600, 2
    a = np.zeros((runs, T))
    a[0] = flicker(T)
    a[0, 300:320] = 1           # a second episode after the first cleared
    a[1, 50:400] = rng.random(350) > 0.3   # chattering: one episode
    size = rng.standard_normal((runs, T))
    s = Signals(np.arange(T) * DT, np.stack([a, 1 - a, size], -1), ["a", "b", "size"])
    dec = Decision(["r:a", "r:b"], names={"r:a": "fault:a"}, clear_after=0.5,
                   size_channels={"fault:a": "r:size"})
    mon = Monitor([Passthrough(["a", "b", "size"])], [], dec)
    batch, stream = mon.run(s), mon.stream(s)
    assert batch.events == stream.events and batch.cleared == stream.cleared
    assert batch.events, "the record has episodes"
    on0 = [e for e in batch.events if e.run == 0 and e.hypothesis == "fault:a"]
    assert [e.k for e in on0] == [10, 300]
    assert [e.size for e in on0] == [size[0, 10], size[0, 300]]
    # run 1: the chattering alarm opens one episode and closes it 0.5 s after it stopped
    on1 = [e for e in batch.events if e.run == 1 and e.hypothesis == "fault:a"]
    assert len(on1) == 1 and on1[0].k >= 50
    # the "b" channel (on whenever a is off) has no size channel; episodes are numbered per run in
    # onset order and every cleared event carries its onset's number
    assert all(e.size is None for e in batch.events if e.hypothesis == "r:b")
    for run in range(runs):
        eps = [e.episode for e in batch.events if e.run == run]
        assert eps == list(range(len(eps)))
    for onset, cleared in batch.episodes:
        assert cleared is None or ((cleared.run, cleared.episode, cleared.hypothesis) == (
            onset.run, onset.episode, onset.hypothesis) and cleared.k > onset.k)
    # Monitor.step returns onsets and cleared events together, in the batch order
    mon.reset(runs)
    got = []
    for k in range(T):
        got += mon.step(float(s.t[k]), s.values[:, k], s.names)[2]
    key = lambda e: (e.run, e.k, e.kind == "onset", e.hypothesis)  # noqa: E731
    assert sorted(got, key=key) == sorted(batch.events + batch.cleared, key=key)
    assert {e.kind for e in got} == {"onset", "cleared"}


def test_clear_level_hysteresis_and_frozen_while_not_judged():
    T = 400
    v = np.zeros(T)
    v[10:30] = 1.0
    v[30:200] = 0.45           # below level 0.5 but above clear_level 0.3: the episode stays open
    v[200:] = 0.0
    s = Signals(np.arange(T) * DT, v[:, None], ["x"])
    mon = Monitor([Passthrough(["x"], dt=DT)], [], Decision(["r:x"], clear_level=0.3, clear_after=1.0),
                  on_invalid="hold")
    res = mon.run(s)
    assert [(e.kind, e.k) for e in res.events + res.cleared] == [("onset", 10), ("cleared", 299)]
    # NaN samples in the quiet part: held, not judged; the count below clear_level is frozen, and
    # the warm-up after them is not judged either, so the clearing comes later by exactly that
    w = np.array(v)
    w[250:260] = np.nan
    res2 = mon.run(Signals(s.t, w[:, None], ["x"], check=False))
    n_warm = round(mon.default_warmup(DT) / DT)
    assert [STATUS_NAMES[c] for c in res2.status[0, [249, 250, 260, 260 + n_warm]]] == [
        "ok", "cannot_judge", "warmup", "ok"]
    assert [(e.kind, e.k) for e in res2.cleared] == [("cleared", 299 + 10 + n_warm)]
    assert res2.cleared == mon.stream(Signals(s.t, w[:, None], ["x"], check=False)).cleared


def test_event_keeps_its_positional_fields_and_decision_is_checked():
    e = Event(1, 5, 0.05, "h", 0.9)
    assert (e.run, e.k, e.t, e.hypothesis, e.value, e.kind, e.size, e.episode) == (1, 5, 0.05, "h", 0.9,
                                                                                 "onset", None, 0)
    with pytest.raises(DataError, match=r"clear_level \(0.8\) must be finite and <= level \(0.5\)"):
        Decision(["a"], clear_level=0.8)
    with pytest.raises(DataError, match="clear_after must be >= 0"):
        Decision(["a"], clear_after=-1)
    with pytest.raises(DataError, match="size_channels name \\['nope'\\]"):
        Decision(["a"], size_channels={"nope": "s"})
    with pytest.raises(DataError, match="size channels \\['r:zz'\\] are not produced"):
        Monitor([Passthrough(["a"])], [], Decision(["r:a"], size_channels={"r:a": "r:zz"}))


def test_step_before_reset_is_a_clear_error():
    mon = Monitor([Passthrough(["a"])], [], Decision(["r:a"]))
    with pytest.raises(DataError, match=r"call reset\(runs\) before step"):
        mon.step(0.0, {"a": 1.0})
