"""Decision.confirm_after (issue 27): a group's own, unspecific name waits for the specific names
that isolate a component -- confirmed by its own group's, dropped for another group's, announced
when the wait ends -- batch (Decision.events, Monitor.run) and streaming (Monitor.stream, step and
checkpoints) alike."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.monitor import Decision, Monitor

from .test_decision_groups import DT, Passthrough, _both

NAMES = ["P:x", "P:y", "x:bias", "y:bias", "y:gain"]
HYP = {"r:P:x": "x", "r:P:y": "y", "r:x:bias": "x:bias", "r:y:bias": "y:bias", "r:y:gain": "y:gain"}
GROUPS = {"x": ["x", "x:bias"], "y": ["y", "y:bias", "y:gain"]}


def _dec(confirm):
    return Decision([f"r:{n}" for n in NAMES], names=HYP, groups=GROUPS, clear_after=0.5,
                    confirm_after=confirm)


def _record():
    T = 900
    a = np.zeros((4, T, 5))
    a[0, 100:400, 0] = 1     # run 0: the guess "x", the peer check isolates y 0.2 s later
    a[0, 120:400, 3] = 1
    a[1, 100:400, 0] = 1     # run 1: the guess "x", confirmed by x:bias 0.3 s later
    a[1, 130:400, 2] = 1
    a[2, 100:400, 1] = 1     # run 2: the guess "y" alone: announced when the 0.5 s wait ends
    a[3, 100:140, 0] = 1     # run 3: a guess shorter than the wait: never announced
    a[3, 300:700, 4] = 1     # ... and y:gain alone later
    return a


def _onsets(ev):
    return [(e.run, e.k, e.hypothesis) for e in ev if e.kind == "onset"]


def test_the_unspecific_name_follows_the_isolating_evidence():
    a = _record()
    t = np.arange(a.shape[1]) * DT
    s = Signals(t, a, [f"r:{n}" for n in NAMES])
    assert _onsets(_dec(0.0).events(t, s)) == [(0, 100, "x"), (0, 120, "y:bias"), (1, 100, "x"),
                                               (2, 100, "y"), (3, 100, "x"), (3, 300, "y:gain")]
    ev = _dec(0.5).events(t, s)
    assert _onsets(ev) == [(0, 120, "y:bias"), (1, 130, "x:bias"), (2, 150, "y"), (3, 300, "y:gain")]
    # the confirmed guess keeps the episode open with its specific name until both are off
    assert [(e.run, e.kind, e.hypothesis) for e in ev if e.run == 1] == [(1, "onset", "x:bias"),
                                                                        (1, "cleared", "x:bias")]


def test_batch_equals_streaming_and_checkpoint():
    a = _record()
    rng = np.random.default_rng(3)
    noisy = np.concatenate([a, (rng.random((3, a.shape[1], 5)) < 0.02).astype(float)
                            * rng.integers(0, 2, (3, 1, 5))])   # random flickers, some channels only
    batch, stream, _ = _both(_dec(0.37), noisy, NAMES)
    assert batch == stream
    assert len(batch) > 8
    # a checkpoint in the middle of a wait continues it
    mon = Monitor([Passthrough(NAMES)], [], _dec(0.5), warmup=0.0)
    s = Signals(np.arange(a.shape[1]) * DT, a, NAMES)
    mon.reset(4)
    ev = []
    for k in range(125):
        ev += mon.step(float(s.t[k]), s.values[:, k], s.names)[2]
    mon2 = Monitor([Passthrough(NAMES)], [], _dec(0.5), warmup=0.0)
    mon2.restore(mon.state())
    for k in range(125, a.shape[1]):
        ev += mon2.step(float(s.t[k]), s.values[:, k], s.names)[2]
    assert _onsets(ev) == [(0, 120, "y:bias"), (1, 130, "x:bias"), (2, 150, "y"), (3, 300, "y:gain")]


def test_confirm_after_is_checked():
    with pytest.raises(DataError, match="confirm_after"):
        _dec(-1.0)
    with pytest.raises(DataError, match="confirm_after"):
        _dec("soon")


def test_an_unconfirmed_name_can_be_dropped():
    a = _record()
    t = np.arange(a.shape[1]) * DT
    s = Signals(t, a, [f"r:{n}" for n in NAMES])
    dec = Decision([f"r:{n}" for n in NAMES], names=HYP, groups=GROUPS, clear_after=0.5, confirm_after=0.5,
                   unconfirmed="drop")
    assert _onsets(dec.events(t, s)) == [(0, 120, "y:bias"), (1, 130, "x:bias"), (3, 300, "y:gain")]
    batch, stream, _ = _both(dec, a, NAMES)
    assert batch == stream
    with pytest.raises(DataError, match="unconfirmed"):
        Decision(["r:P:x"], confirm_after=1.0, unconfirmed="later")
