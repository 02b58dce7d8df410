"""fdikit.codegen's FaultTypeClassifier emitter (issue 29): random logs whose members have a
gain, a drift, bursts, a spike, a bias and a frozen raw signal, with a NaN sample and a gap (the
stage's ``resume``): the C gives bitwise the Python streaming outputs and events (the types are
revised within one episode per sensor: change events); a NaN sample leaves its state alone;
checkpoints cross between C and Python mid-episode."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit.codegen import (
    CMonitor,
    c_to_py_state,
    find_compiler,
    py_to_c_state,
    run_driver,
)
from fdikit.codegen.fault_type import FaultTypeEmitter
from fdikit.codegen.stages import stage_emitter
from fdikit.detect import Hold
from fdikit.isolate import FAULT_TYPES, FaultTypeClassifier
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import FaultDetectionFilter, FilterDesign

from .equivalence import sanitized_driver
from .test_codegen import DT, _build

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

M = ["a", "b", "c"]


def _monitor(revise_after=0):
    """The classifier's inputs passed through as residuals, its types held and announced, one
    group per sensor (``revise_after``: the announced type's hysteresis, issue 27)."""
    ftc = FaultTypeClassifier(M, {m: 0.1 for m in M}, 300, raw={"a": "raw:a", "c": "raw:c"},
                              gain_offset={"b": "off:b"},
                              stuck_after={"a": 40, "c": 30}, isolated_by={"b": ["ext:b"]}, confirm=0.5,
                              lookback=30, min_len=5, spike_max=8, burst_gap=20, clear_after=150, block=10,
                              gain_crit={"a": 20.0, "b": 25.0, "c": 30.0}, revise_after=revise_after,
                              revise_conf=0.3 if revise_after else 0.0, hold_while_isolated=revise_after > 0)
    ins = ftc.input_names
    n = len(ins)
    d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, 0)),
                     np.eye(n), DT, [], [f"in:{c}" for c in ins], ins)
    hold = Hold([f"{m}:{t}" for m in M for t in FAULT_TYPES], 0.5, Z=3, absolute=False)
    dec = Decision(hold.output_names, 0.5, {f"{m}:{t}:alarm": f"{m}:{t}" for m in M for t in FAULT_TYPES},
                   clear_after=0.5, groups={m: [f"{m}:{t}" for t in FAULT_TYPES] for m in M})
    return Monitor([FaultDetectionFilter(d)], [ftc, hold], dec, on_invalid="hold", dt=DT)


def _log(mon, seed, T=4000, gap=True):
    rng = np.random.default_rng(seed)
    k = np.arange(T)
    cols = {}
    for j, m in enumerate(M):
        x = 5 + 2 * np.sin(k / (50 + 20 * j)) + 0.1 * rng.normal(size=T)
        r = 0.1 * rng.normal(size=T)
        if m == "a":                                           # a gain, later a drift
            r += np.where((k > 400) & (k < 1400), 0.08 * x, 0.0)
            r += np.where((k > 2500) & (k < 3000), 0.002 * (k - 2500), 0.0)
        if m == "b":                                           # a drift, bursts, a spike
            r += np.where((k > 300) & (k < 1000), 0.003 * (k - 300), 0.0)
            for s in (1800, 1900, 2000):
                r[s:s + 15] += 1.5
            r[3000:3005] += 3.0
        if m == "c":                                           # a spike, a bias
            r[200:205] += 3.0
            r[1200:2200] += 0.6
        stat = np.abs(np.convolve(r, np.ones(10) / 10)[:T]) / 0.3
        cols |= {f"peer:{m}:isolated": (stat >= 1.0).astype(float), f"peer:{m}": stat, f"peer:{m}:e": r,
                 f"peer:{m}:ref": x}
        raw = np.round(x, 2)
        raw[1500:1700] = raw[1500]                             # frozen
        raw[3300:3340] = raw[3300]
        cols[f"raw:{m}"] = raw
    cols["ext:b"] = ((k > 2600) & (k < 2700)).astype(float)
    cols["off:b"] = -4.0 + 0.5 * np.sin(k / 300)              # b's zero offset (issue 27: a gain scales it)
    names = list(mon.input_names)             # (the monitor's order, which the C takes)
    X = np.column_stack([cols[c[3:]] for c in names])
    X[777, 2] = np.nan
    t = k * DT
    if gap:
        t[3500:] += 0.05
    return t, X, names


def _same(a, b) -> bool:
    """Equal plain-data states, bitwise (NaN equal to NaN: the raw value before the first sample)."""
    if isinstance(a, dict):
        return set(a) == set(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, tuple | list):
        return len(a) == len(b) and all(_same(u, v) for u, v in zip(a, b))
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def _py(mon, t, x, names, k0=0):
    if k0 == 0:
        mon.reset(1)
    out, ev = [], []
    for k in range(k0, len(t)):
        r, s, e = mon.step(float(t[k]), x[k][None], names)
        out.append(np.concatenate([r[0], s[0]]))
        ev += [(e_.k, e_.kind, e_.hypothesis, e_.episode, e_.value, e_.previous) for e_ in e]
    return np.array(out), ev


def _c(res):
    return [(e["k"], e["kind"], e["hypothesis"], e["episode"], e["value"], e["previous"])
            for e in res["events"]]


@pytest.fixture(scope="module", params=[0, 20], ids=["no_hysteresis", "hysteresis"])
def built(tmp_path_factory, request):
    mon = _monitor(request.param)
    return (mon, *_build(mon, tmp_path_factory.mktemp("ftc"), "fdk_ftc"))


def test_emitter_is_registered():
    assert isinstance(stage_emitter(_monitor().processors[0], "p0"), FaultTypeEmitter)


@pytest.mark.parametrize("seed", [0, 1])
def test_classifier_c_equals_python(built, seed):
    mon, _gen, c64, c32, _em = built
    t, x, names = _log(mon, seed)
    py_out, py_ev = _py(mon, t, x, names)
    res = c64.run(t, x)
    assert np.array_equal(res["out"], py_out)        # bitwise: types, confidences, active flags
    assert _c(res) == py_ev
    allnames = mon.residual_names + mon.stat_names
    seen = {ty for m in M for ty in FAULT_TYPES if py_out[:, allnames.index(f"{m}:{ty}")].any()}
    assert len(seen) >= 5, seen
    assert {e[1] for e in py_ev} == {"onset", "change", "cleared"}
    r32 = c32.run(t, x)
    assert [e[:4] for e in _c(r32)] == [e[:4] for e in py_ev]   # float32 inputs, the same events


def test_nan_leaves_the_classifier_state(built):
    mon, _gen, c64, _c32, _em = built
    t, x, _names = _log(mon, 2, gap=False)
    c64.run(t[:1300], x[:1300])
    before = c64.checkpoint()
    bad = x[1300].copy()
    bad[5] = np.nan
    st, _o, ev = c64.step(t[1300], bad)
    assert st == 1 and ev == []
    fields = c64.layout["fields"]
    offs = np.cumsum([0] + [f[2] for f in fields])
    after = c64.checkpoint()
    diff = (before != after) & ~(np.isnan(before) & np.isnan(after))   # (a member without raw: NaN)
    moved = {fields[np.searchsorted(offs, i, side="right") - 1][0] for i in np.flatnonzero(diff)}
    assert moved <= {"k", "held", "held_t", "t_prev"}, moved


@pytest.mark.parametrize("cut", [1300, 2650])
def test_checkpoint_crosses_mid_episode(built, cut):
    mon, _gen, c64, _c32, em = built
    t, x, names = _log(mon, 3, gap=False)
    full_out, full_ev = _py(mon, t, x, names)
    c64.run(t[:cut], x[:cut])
    st = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)
    _py(mon, t[:cut], x[:cut], names)
    assert _same(st["processors"], mon.state()["processors"])
    assert mon.processors[0]._active.any()                    # a fault is being typed at the cut
    mon.reset(1)
    mon.restore(st)
    out, ev = _py(mon, t, x, names, k0=cut)
    assert np.array_equal(out, full_out[cut:]) and ev == [e for e in full_ev if e[0] >= cut]
    _py(mon, t[:cut], x[:cut], names)
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    res = fresh.run(t[cut:], x[cut:], reset=False)
    assert np.array_equal(res["out"], full_out[cut:])
    assert _c(res) == [e for e in full_ev if e[0] >= cut]


def test_classifier_and_groups_under_sanitizers(built, tmp_path):
    """The ring buffers' index arithmetic and the grouped episode rule as a program under
    -fsanitize=address,undefined: the same numbers and events as Python."""
    mon, gen, _c64, _c32, _em = built
    layout = gen["layout"]
    exe = sanitized_driver(gen, tmp_path)
    t, x, names = _log(mon, 4)
    py_out, py_ev = _py(mon, t, x, names)
    res = run_driver(exe, layout, t, x)
    assert np.array_equal(res["out"], py_out) and _c(res) == py_ev
    assert "runtime error" not in res["stderr"]
