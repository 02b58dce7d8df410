"""One fault name, one episode (issue 28's Decision bug) and a revised fault type as a change event
of the same episode (issue 27, item 3): batch (Decision.events, Monitor.run) and streaming
(Monitor.stream, Monitor.step) give the same events."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.monitor import Decision, Monitor, ResidualGenerator

DT = 0.01


class Passthrough(ResidualGenerator):
    """Residual r:<c> = measurement c."""

    _state_attrs = ()

    def __init__(self, channels):
        self.u_names, self.y_names = [], list(channels)
        self.output_names = [f"r:{c}" for c in channels]
        self.dt = DT

    def reset(self, runs=1):
        pass

    def _step(self, u, y):
        return y.copy()


def _both(dec, a, names):
    """(batch events, streaming events) of a Monitor passing the columns of a (runs, T, C) through."""
    s = Signals(np.arange(a.shape[1]) * DT, a, names)
    mon = Monitor([Passthrough(names)], [], dec, warmup=0.0)
    b, st = mon.run(s), mon.stream(s)
    key = lambda e: (e.run, e.k, e.kind, e.hypothesis)  # noqa: E731
    return (sorted(b.events + b.cleared + b.changes, key=key),
            sorted(st.events + st.cleared + st.changes, key=key), b)


def test_two_channels_of_one_fault_name_are_one_episode():
    # issue 28: both channels on gave two onsets and two cleared events of "f" at the same sample
    T = 400
    a = np.zeros((1, T, 2))
    a[0, 10:100, 0] = 1          # a: on first, off first
    a[0, 50:150, 1] = 1          # b: on later, off last
    dec = Decision(["r:a", "r:b"], names={"r:a": "f", "r:b": "f"}, clear_after=0.5)
    ev = dec.events(np.arange(T) * DT, Signals(np.arange(T) * DT, a, ["r:a", "r:b"]))
    assert [(e.kind, e.k, e.hypothesis, e.episode) for e in ev] == [("onset", 10, "f", 0),
                                                                    ("cleared", 199, "f", 0)]
    batch, stream, _ = _both(dec, a, ["a", "b"])
    assert batch == stream
    assert [(e.kind, e.k) for e in batch] == [("onset", 10), ("cleared", 199)]


def test_a_revised_type_is_a_change_of_the_same_episode():
    T = 600
    a = np.zeros((2, T, 3))
    a[0, 10:100, 0] = 1          # run 0: bias, then gain (bias goes off as gain goes on), then cleared
    a[0, 100:300, 1] = 1
    a[0, 450:500, 2] = 1         # a new episode, announced as stuck
    a[1, 20:200, 2] = 1          # run 1: stuck and bias at once (onset names the first in order)
    a[1, 20:200, 0] = 1
    a[1, 150:200, 1] = 1         # ... gain turns on: a change
    names = ["x:bias", "x:gain", "x:stuck"]
    dec = Decision([f"r:{n}" for n in names], names={f"r:{n}": n for n in names},
                   groups={"x": names}, clear_after=0.5)
    batch, stream, res = _both(dec, a, names)
    assert batch == stream
    got = [(e.run, e.kind, e.k, e.hypothesis, e.previous, e.episode) for e in batch]
    assert got == [(0, "onset", 10, "x:bias", None, 0), (0, "change", 100, "x:gain", "x:bias", 0),
                   (0, "cleared", 349, "x:gain", None, 0), (0, "onset", 450, "x:stuck", None, 1),
                   (0, "cleared", 549, "x:stuck", None, 1),
                   (1, "onset", 20, "x:bias", None, 0), (1, "change", 150, "x:gain", "x:bias", 0),
                   (1, "cleared", 249, "x:gain", None, 0)]
    assert [e.kind for e in res.events] == ["onset"] * 3 and len(res.changes) == 2
    # step by step: the same events, the change returned at its sample
    s = Signals(np.arange(T) * DT, a, names)
    mon = Monitor([Passthrough(names)], [], dec, warmup=0.0)
    mon.reset(2)
    steps = []
    for k in range(T):
        steps += mon.step(float(s.t[k]), s.values[:, k], s.names)[2]
    key = lambda e: (e.run, e.k, e.kind, e.hypothesis)  # noqa: E731
    assert sorted(steps, key=key) == batch


def test_checkpoint_keeps_the_current_name():
    names = ["x:bias", "x:gain"]
    T = 300
    a = np.zeros((1, T, 2))
    a[0, 10:100, 0] = 1
    a[0, 100:200, 1] = 1
    dec = Decision([f"r:{n}" for n in names], names={f"r:{n}": n for n in names}, groups={"x": names},
                   clear_after=0.5)
    s = Signals(np.arange(T) * DT, a, names)
    mon = Monitor([Passthrough(names)], [], dec, warmup=0.0)
    mon.reset(1)
    for k in range(150):
        mon.step(float(s.t[k]), s.values[:, k], s.names)
    state = mon.state()
    mon2 = Monitor([Passthrough(names)], [], dec, warmup=0.0)
    mon2.restore(state)
    ev = []
    for k in range(150, T):
        ev += mon2.step(float(s.t[k]), s.values[:, k], s.names)[2]
    assert [(e.kind, e.hypothesis, e.episode) for e in ev] == [("cleared", "x:gain", 0)]


def test_groups_are_checked():
    with pytest.raises(DataError, match="not a hypothesis"):
        Decision(["a"], groups={"x": ["a", "b"]})
    with pytest.raises(DataError, match="two decision groups"):
        Decision(["a", "b"], groups={"x": ["a"], "y": ["a", "b"]})


def test_records_and_report_show_the_change():
    from fdikit.monitor.records import batch_records, summary_lines
    from fdikit.report.events import add_events, episode_spans
    from fdikit.report.html import Report

    names = ["x:bias", "x:gain"]
    T = 400
    a = np.zeros((1, T, 2))
    a[0, 10:100, 0] = 1
    a[0, 100:200, 1] = 1
    dec = Decision([f"r:{n}" for n in names], names={f"r:{n}": n for n in names}, groups={"x": names},
                   clear_after=0.5)
    s = Signals(np.arange(T) * DT, a, names)
    res = Monitor([Passthrough(names)], [], dec, warmup=0.0).run(s)
    recs = batch_records(s, res)
    assert [(r["kind"], r["hypothesis"], r.get("previous")) for r in recs] == [
        ("onset", "x:bias", None), ("change", "x:gain", "x:bias"), ("cleared", "x:gain", None)]
    summary = {"samples": T, "n_events": 1, "n_cleared": 1, "invalid_samples": 0, "n_gaps": 0,
               "status": {"ok": T}}
    assert "revised from x:bias" in summary_lines(summary, recs)[2]
    spans = episode_spans(recs, 4.0)
    assert len(spans) == 1 and not spans[0]["open"] and spans[0]["revised"] == [(1.0, "x:gain")]
    rep = Report("t")
    add_events(rep, recs)
    assert rep.data["changes"][0]["previous"] == "x:bias"


def test_the_components_own_name_never_replaces_a_specific_one():
    # "x" (an unspecific detector of the component) opens the episode; "x:bias" revises it; "x"
    # turning on again is no change back
    T = 400
    a = np.zeros((1, T, 2))
    a[0, 10:60, 0] = 1
    a[0, 100:150, 0] = 1
    a[0, 30:200, 1] = 1
    dec = Decision(["r:x", "r:b"], names={"r:x": "x", "r:b": "x:bias"}, groups={"x": ["x", "x:bias"]},
                   clear_after=0.5)
    batch, stream, _ = _both(dec, a, ["x", "b"])
    assert batch == stream
    assert [(e.kind, e.k, e.hypothesis) for e in batch] == [("onset", 10, "x"), ("change", 30, "x:bias"),
                                                            ("cleared", 249, "x:bias")]
