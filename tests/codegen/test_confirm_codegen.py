"""fdikit.codegen's episode rule with ``Decision(confirm_after=..., unconfirmed=...)`` (issue 29
after issue 27): a group's own, unspecific name waits for a specific name of its group (confirmed:
the onset names the specific one) or of another group (dropped until its alarm falls), and is
announced or dropped at the end of the wait. The generated decision gives the Python events
exactly (batch = streaming = C), with a gap, a NaN sample and the single-channel (simple) rule; its
wait state crosses between C and Python checkpoints."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit import Signals
from fdikit.codegen import CMonitor, c_to_py_state, emit_monitor, find_compiler, py_to_c_state
from fdikit.codegen.emit import stage_digest
from fdikit.monitor import Decision, Monitor

from .test_codegen import DT, _build
from .test_episodes_codegen import CH, _c, _monitor, _py, _random

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

#: a, b specific names of x (c its own name); e the own name of z, f its specific name; d alone
NAMES = {"a": "x:bias", "b": "x:gain", "c": "x", "d": "y", "e": "z", "f": "z:drift"}
GROUPS = {"x": ["x", "x:bias", "x:gain"], "z": ["z", "z:drift"]}


def _confirm_monitor(unconfirmed="announce", confirm_after=0.1, simple=False):
    base = _monitor(groups=False)
    names = {f"r{c}:alarm": NAMES[c] for c in CH}
    groups = GROUPS
    if simple:     # one channel per unit: the per-channel rule
        names = {f"r{c}:alarm": {"a": "x:bias", "c": "x", "e": "w:drift"}.get(c, c) for c in CH}
        groups = {"x": ["x"], "xs": ["x:bias"], "w": ["w:drift"]}
    dec = Decision([f"r{c}:alarm" for c in CH], 0.5, names, clear_after=0.1,
                   size_channels={"x:bias" if simple else "x:gain": "rb"}, groups=groups,
                   confirm_after=confirm_after, unconfirmed=unconfirmed)
    return Monitor(base.generators, base.processors, dec, on_invalid="hold", dt=DT)


def _scripted(T=900):
    x = np.zeros((T, len(CH)))
    on = {"c": [(100, 200), (300, 400)], "a": [(105, 150), (503, 520)], "e": [(500, 600)],
          "d": [(700, 710)], "b": [(800, 805)]}
    for c, spans in on.items():
        for a, b in spans:
            x[a:b, CH.index(c)] = 1.0 + CH.index(c) / 10
    return np.arange(T) * DT, x


def _batch(mon, t, x):
    b = mon.run(Signals(t, x[None], CH, check=False))
    return sorted((e.k, e.kind, e.hypothesis, e.episode, e.previous)
                  for e in (*b.events, *b.cleared, *b.changes))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("confirm")
    out = {}
    for key in ("announce", "drop", "simple"):
        mon = _confirm_monitor("announce" if key == "simple" else key, simple=key == "simple")
        out[key] = (mon, *_build(mon, tmp / key, f"fdk_cf_{key}", f32=False))
    return out


def test_confirm_drop_and_announce_scripted(built):
    got = {}
    for key in ("announce", "drop"):
        mon, _gen, c64, _c32, _em = built[key]
        t, x = _scripted()
        _out, py_ev = _py(mon, t, x)
        assert _c(c64.run(t, x)) == py_ev
        assert _batch(mon, t, x) == sorted(e[:4] + e[6:] for e in py_ev)
        got[key] = [(k, kind, h) for k, kind, h, *_ in py_ev if kind != "cleared"]
    # x confirmed by x:bias at 105; z contradicted by x:bias at 503; x alone from 300 announced after
    # the 10-sample wait (or dropped); y and x:gain announced at once
    assert got["announce"] == [(105, "onset", "x:bias"), (310, "onset", "x"), (503, "onset", "x:bias"),
                               (700, "onset", "y"), (800, "onset", "x:gain")]
    assert got["drop"] == [(105, "onset", "x:bias"), (503, "onset", "x:bias"), (700, "onset", "y"),
                           (800, "onset", "x:gain")]


@pytest.mark.parametrize("key", ["announce", "drop", "simple"])
@pytest.mark.parametrize("seed", [0, 1])
def test_confirm_random_bursts_c_equals_python(built, key, seed):
    mon, _gen, c64, _c32, _em = built[key]
    t, x = _random(seed)
    py_out, py_ev = _py(mon, t, x)
    res = c64.run(t, x)
    assert np.array_equal(res["out"], py_out)
    assert _c(res) == py_ev and len(py_ev) > 10
    assert _batch(mon, t, x) == sorted(e[:4] + e[6:] for e in py_ev)


@pytest.mark.parametrize("key", ["announce", "drop"])
@pytest.mark.parametrize("cut", [104, 305, 509])
def test_confirm_state_crosses_checkpoints(built, key, cut):
    """Cut inside a wait (104, 305: x waits; 509: z dropped): the wait state carries over C -> Python
    and Python -> C, and the continuation's events are the same."""
    mon, _gen, c64, _c32, em = built[key]
    t, x = _scripted()
    full_out, full_ev = _py(mon, t, x)
    c64.run(t[:cut], x[:cut])
    st = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)
    _py(mon, t[:cut], x[:cut])
    py_state = mon.state()
    for k in ("active", "below", "id", "count", "current", "prev_on", "confirm"):
        assert np.array_equal(st["episodes"][k], py_state["episodes"][k]), k
    assert st["episodes"]["confirm"].tolist() == [{104: [4, -1], 305: [5, -1], 509: [-1, -3]}[cut]]
    mon.reset(1)
    mon.restore(st)
    out, ev = _py(mon, t, x, k0=cut)
    assert np.array_equal(out, full_out[cut:]) and ev == [e for e in full_ev if e[0] >= cut]
    _py(mon, t[:cut], x[:cut])
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    res = fresh.run(t[cut:], x[cut:], reset=False)
    assert _c(res) == [e for e in full_ev if e[0] >= cut]


def test_confirm_is_part_of_the_design():
    """The wait changes the generated code and the digest; without a wait nothing is added."""
    plain = _monitor(groups=True)
    assert "confirm" not in [f[0] for f in emit_monitor(plain).layout["fields"]]
    a, d = _confirm_monitor("announce"), _confirm_monitor("drop")
    assert len({stage_digest(plain), stage_digest(a), stage_digest(d)}) == 3
    assert emit_monitor(a).layout["n_tentative"] == 2
    assert emit_monitor(a).source != emit_monitor(d).source
