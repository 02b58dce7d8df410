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
    driver_source,
    emit_monitor,
    generate_monitor,
    py_to_c_state,
)

STATUS = ("ok", "cannot_judge", "warmup")


def sanitized_driver(gen: dict, where: Path) -> Path:
    """The program of :func:`~fdikit.codegen.driver_source` over generated code ``gen`` (the result
    of ``generate_monitor``), built in ``where`` under -fsanitize=address,undefined; the test is
    skipped, with the compiler's words, where the sanitizer runtimes are missing."""
    import pytest

    from fdikit.errors import DataError

    layout = gen["layout"]
    cdir = Path(gen["files"][0]).parent
    (where / "main.c").write_text(driver_source(layout))
    try:
        return compile_shared([where / "main.c", cdir / f"{layout['name']}.c"], where / "asan",
                              sanitize=True, shared=False, extra=(f"-I{cdir}",))
    except DataError as exc:   # a compiler without the sanitizer runtimes
        pytest.skip(f"no sanitizer runtime: {str(exc)[-200:]}")


def generated(mon, where: Path, name: str, f32: bool = True):
    """Generate and compile ``mon``: (the generation's result, double CMonitor, float32 CMonitor
    or None, emitters)."""
    gen = generate_monitor(mon, where, name=name, precisions=("double", "float") if f32 else ("double",))
    c64 = CMonitor(compile_shared([where / f"{name}.c"], where / f"lib{name}.so"),
                   where / f"{name}.layout.json")
    c32 = None
    if f32:
        c32 = CMonitor(compile_shared([where / f"{name}_f32.c"], where / f"lib{name}_f32.so"),
                       where / f"{name}_f32.layout.json")
    return gen, c64, c32, emit_monitor(mon, name=name).emitters


def build(mon, where: Path, name: str, f32: bool = False):
    """Generate and compile ``mon``: (double CMonitor, float32 CMonitor or None, emitters)."""
    return generated(mon, where, name, f32)[1:]


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


def assert_stream_equal(c64, t, x, py):
    """The C run on (t, x) gives bitwise the Python streaming result ``py`` (outputs, statuses,
    events: :func:`py_stream`); returns the C result."""
    py_out, py_status, py_ev = py
    res = c64.run(t, x)
    assert np.array_equal(res["status"], py_status), np.flatnonzero(res["status"] != py_status)[:5]
    assert np.array_equal(res["out"], py_out)       # bitwise: the same operations in the same order
    assert c_events(res) == py_ev
    return res


def f32_error(c32, t, x, py_out) -> float:
    """The float32 variant's largest error on (t, x), relative to each channel's largest magnitude."""
    scale = np.maximum(np.abs(py_out).max(axis=0), 1e-12)
    return float(np.max(np.abs(c32.run(t, x)["out"] - py_out) / scale))


def changed_fields(layout, before, after) -> set[str]:
    """The state fields (``layout["fields"]``) whose checkpoint values differ (NaN equal to NaN)."""
    fields = layout["fields"]
    offs = np.cumsum([0] + [f[2] for f in fields])
    moved = np.flatnonzero(~((before == after) | (np.isnan(before) & np.isnan(after))))
    return {fields[np.searchsorted(offs, i, side="right") - 1][0] for i in moved}


def field(layout, buf, name: str):
    """One state field's values in a checkpoint ``buf``."""
    fields = layout["fields"]
    offs = np.cumsum([0] + [f[2] for f in fields])
    i = [f[0] for f in fields].index(name)
    return buf[offs[i]:offs[i + 1]]


def nan_sample(c64, t, x, k, channel):
    """C run on the first ``k`` samples, then sample ``k`` with NaN on ``channel``: held (status 1,
    no event). Returns the checkpoints before and after it."""
    c64.run(t[:k], x[:k])
    before = c64.checkpoint()
    bad = x[k].copy()
    bad[channel] = np.nan
    st, _out, ev = c64.step(t[k], bad)
    assert st == 1 and ev == []
    return before, c64.checkpoint()


def c_then_python(mon, c64, em, t, x, cut):
    """C on the first ``cut`` samples, Python restored from its checkpoint continues: (the C
    checkpoint, Python's outputs from ``cut`` on)."""
    names = list(mon.input_names)
    c64.run(t[:cut], x[:cut])
    ck = c64.checkpoint()
    mon.reset(1)
    mon.restore(c_to_py_state(c64.layout, ck, mon, em))
    rest = [mon.step(float(t[k]), x[k][None], names) for k in range(cut, len(t))]
    return ck, np.array([np.concatenate([r[0], s[0]]) for r, s, _ in rest])


def python_then_c(mon, c64, em, t, x, cut):
    """Python on the first ``cut`` samples, a fresh C monitor restored from its state continues:
    (the C run from ``cut`` on, the restored C state read back as Python's; ``mon`` is left at
    ``cut``)."""
    py_stream(mon, t[:cut], x[:cut], list(mon.input_names))
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    back = c_to_py_state(c64.layout, fresh.checkpoint(), mon, em)
    return fresh.run(t[cut:], x[cut:], reset=False), back


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
        assert np.array_equal(c_then_python(mon, c64, em, t, x, cut)[1], py_out[cut:])
        r2, _back = python_then_c(mon, c64, em, t, x, cut)
        assert np.array_equal(r2["out"], py_out[cut:])
        assert np.array_equal(r2["status"], py_status[cut:])
        assert c_events(r2) == [e for e in py_ev if e[0] >= cut]
    return py_out, py_status, py_ev


def assert_nan_held(mon, c64, em, t, x, k, channel=1, exact=True):
    """After ``k`` samples, a NaN on ``channel`` is held in C as in Python; no stage state moves
    (``exact``: and the C state, read as Python's, is bitwise Python's)."""
    names = list(mon.input_names)
    py_stream(mon, t[:k], x[:k], names)
    before, after = nan_sample(c64, t, x, k, channel)
    bad = x[k].copy()
    bad[channel] = np.nan
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
    changed = changed_fields(c64.layout, before, after)
    stage = {f[0] for f in c64.layout["fields"] if f[0].startswith(("g", "p")) and f[0][1:2].isdigit()}
    assert not (changed & stage), changed
