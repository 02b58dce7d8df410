"""Shared checks of the codegen tests: a generated monitor equals its Python monitor (streaming
bitwise, batch within 1e-12 relative, events), a NaN sample is held in C as in Python without
changing a stage's state, and checkpoints move C -> Python -> C and continue bitwise."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fdikit import Signals
from fdikit.codegen import (
    CMonitor,
    c_to_py_state,
    compile_shared,
    emit_monitor,
    generate_monitor,
    py_to_c_state,
)

STATUS = ("ok", "cannot_judge", "warmup")


def build(mon, where: Path, name: str, f32: bool = False):
    """Generate and compile ``mon``: (double CMonitor, float32 CMonitor or None, emitters)."""
    generate_monitor(mon, where, name=name, precisions=("double", "float") if f32 else ("double",))
    c64 = CMonitor(compile_shared([where / f"{name}.c"], where / f"lib{name}.so"),
                   where / f"{name}.layout.json")
    c32 = None
    if f32:
        c32 = CMonitor(compile_shared([where / f"{name}_f32.c"], where / f"lib{name}_f32.so"),
                       where / f"{name}_f32.layout.json")
    return c64, c32, emit_monitor(mon, name=name).emitters


def py_stream(mon, t, x, names):
    """The Python streaming path: outputs (T, R + S), status codes, events as tuples."""
    mon.reset(1)
    outs, status, events = [], [], []
    for k in range(len(t)):
        r, s, ev = mon.step(float(t[k]), x[k][None], names)
        outs.append(np.concatenate([r[0], s[0]]))
        status.append(STATUS.index(mon.last_status))
        events += [(e.k, e.kind, e.hypothesis, e.episode, e.value, e.size) for e in ev]
    return np.array(outs), np.array(status), events


def c_events(res):
    return [(e["k"], e["kind"], e["hypothesis"], e["episode"], e["value"], e["size"]) for e in res["events"]]


def same(a, b) -> bool:
    """Equal plain-data states (dicts, tuples, arrays, numbers), bitwise (NaN equal to NaN)."""
    if isinstance(a, dict):
        return set(a) == set(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, tuple | list):
        return len(a) == len(b) and all(same(u, v) for u, v in zip(a, b))
    if a is None or b is None:
        return a is b
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=np.asarray(a).dtype.kind == "f")


def assert_equivalent(mon, c64, em, t, x, *, min_events=1, batch=True):
    """C equals Python on (t, x): streaming bitwise (outputs, statuses, events), batch within
    1e-12 relative; checkpoints C -> Python and Python -> C continue bitwise at two cuts; returns
    the Python streaming result."""
    names = list(mon.input_names)
    py_out, py_status, py_ev = py_stream(mon, t, x, names)
    res = c64.run(t, x)
    assert np.array_equal(res["status"], py_status), np.flatnonzero(res["status"] != py_status)[:5]
    bad = np.flatnonzero(~np.all(res["out"] == py_out, axis=1))
    assert bad.size == 0, (bad[:5], res["out"][bad[:1]], py_out[bad[:1]])
    assert c_events(res) == py_ev
    assert sum(e[1] == "onset" for e in py_ev) >= min_events
    if batch:
        rb = mon.run(Signals(t, x[None], names, check=False))
        pyb = np.concatenate([rb.residuals.values[0], rb.statistics.values[0]], axis=1)
        assert np.allclose(res["out"], pyb, rtol=1e-12, atol=1e-300)
        assert sorted(e[:4] for e in py_ev) == sorted((e.k, e.kind, e.hypothesis, e.episode)
                                                      for e in (*rb.events, *rb.cleared))
    for cut in (len(t) // 3, 2 * len(t) // 3):
        c64.run(t[:cut], x[:cut])
        mon.reset(1)
        mon.restore(c_to_py_state(c64.layout, c64.checkpoint(), mon, em))
        rest = [mon.step(float(t[k]), x[k][None], names) for k in range(cut, len(t))]
        assert np.array_equal(np.array([np.concatenate([r[0], s[0]]) for r, s, _ in rest]), py_out[cut:])
        py_stream(mon, t[:cut], x[:cut], names)
        fresh = CMonitor(c64.lib._name, c64.layout)
        fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
        r2 = fresh.run(t[cut:], x[cut:], reset=False)
        assert np.array_equal(r2["out"], py_out[cut:])
        assert np.array_equal(r2["status"], py_status[cut:])
        assert c_events(r2) == [e for e in py_ev if e[0] >= cut]
    return py_out, py_status, py_ev


def assert_nan_held(mon, c64, em, t, x, k, channel=1, exact=True):
    """After ``k`` samples, a NaN on ``channel`` is held in C as in Python; no stage state moves
    (``exact``: and the C state, read as Python's, is bitwise Python's)."""
    names = list(mon.input_names)
    c64.run(t[:k], x[:k])
    py_stream(mon, t[:k], x[:k], names)
    before = c64.checkpoint()
    bad = x[k].copy()
    bad[channel] = np.nan
    st, _out, ev = c64.step(t[k], bad)
    assert st == 1 and ev == []
    py_before = mon.state()
    mon.step(float(t[k]), bad[None], names)
    assert mon.last_status == "cannot_judge"
    a = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)
    p = mon.state()
    for g_c, g_p, g_b in zip(a["generators"] + a["processors"], p["generators"] + p["processors"],
                             py_before["generators"] + py_before["processors"]):
        assert same(g_p, g_b)
        assert same(g_c, g_p) or not exact
    assert same(a["plausibility"], p["plausibility"])
    after = c64.checkpoint()
    fields = c64.layout["fields"]
    offs = np.cumsum([0] + [f[2] for f in fields])
    changed = {fields[np.searchsorted(offs, i, side="right") - 1][0]
               for i in np.flatnonzero(~((before == after) | (np.isnan(before) & np.isnan(after))))}
    stage = {f[0] for f in fields if f[0].startswith(("g", "p")) and f[0][1:2].isdigit()}
    assert not (changed & stage), changed
