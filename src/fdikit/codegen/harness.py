"""The equivalence harness: compile generated C with the system compiler into a shared library,
load it with ctypes, run it on a log, and move checkpoints between C and the Python monitor."""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .plausibility import plausibility_from_py, plausibility_to_py

__all__ = ["CFLAGS", "CMonitor", "c_to_py_state", "compile_shared", "driver_source", "find_compiler",
           "py_to_c_state", "run_driver"]

#: Flags every generated file must pass (``-ffp-contract=off``: no fused multiply-add, so the C
#: performs the Python stages' floating-point operations exactly).
CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-ffp-contract=off")

STATUS = ("ok", "cannot_judge", "warmup")


def find_compiler() -> str | None:
    """The system C compiler (``$CC``, ``cc``, ``gcc`` or ``clang``), or None."""
    for c in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if c and shutil.which(c):
            return shutil.which(c)
    return None


def compile_shared(sources: list[str | Path], out: str | Path, *, sanitize: bool = False,
                   extra: tuple[str, ...] = (), shared: bool = True) -> Path:
    """Compile C sources into a shared library with :data:`CFLAGS` (and
    ``-fsanitize=address,undefined`` when ``sanitize``). Raises :class:`DataError` with the
    compiler's message on failure, or when no compiler is found."""
    cc = find_compiler()
    if cc is None:
        raise DataError("no C compiler found (install gcc, e.g. 'apt-get install gcc', or set CC)")
    flags = [*CFLAGS, *(("-fPIC", "-shared") if shared else ()), *extra]
    if sanitize:
        flags += ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
    cmd = [cc, *flags, *map(str, sources), "-o", str(out), "-lm"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise DataError(f"the C compiler failed ({' '.join(cmd)}):\n{res.stderr}")
    return Path(out)


class _Event(ctypes.Structure):
    _fields_ = [("k", ctypes.c_int64), ("t", ctypes.c_double), ("value", ctypes.c_double),
                ("size", ctypes.c_double), ("episode", ctypes.c_int64), ("channel", ctypes.c_int32),
                ("kind", ctypes.c_int32), ("previous", ctypes.c_int32)]


class CMonitor:
    """A compiled generated monitor, driven from Python (one run).

    Parameters
    ----------
    lib : path
        The shared library (:func:`compile_shared`).
    layout : path or dict
        The ``<name>.layout.json`` written with the code.
    """

    def __init__(self, lib: str | Path, layout: str | Path | dict):
        self.layout = layout if isinstance(layout, dict) else json.loads(Path(layout).read_text())
        nm = self.layout["name"]
        self.lib = ctypes.CDLL(str(Path(lib).resolve()))
        fn = {k: getattr(self.lib, f"{nm}_{k}") for k in
              ("init", "reset", "step", "checkpoint", "restore", "design_hash", "state_size")}
        fn["design_hash"].restype = ctypes.c_char_p
        fn["step"].restype = ctypes.c_int
        fn["step"].argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p,
                               ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
        for k in ("init", "reset"):
            fn[k].argtypes = [ctypes.c_void_p]
        fn["checkpoint"].argtypes = fn["restore"].argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        self._fn = fn
        self.state_bytes = int(fn["state_size"]())
        self._state = (ctypes.c_double * ((self.state_bytes + 7) // 8))()
        self.n_in = len(self.layout["inputs"])
        self.n_out = len(self.layout["residuals"]) + len(self.layout["statistics"])
        self._ev = (_Event * max(2 * len(self.layout["alarm_channels"]), 1))()
        self._nev = ctypes.c_int(0)
        self._out = np.zeros(max(self.n_out, 1))
        fn["init"](self._state)

    @property
    def design_hash(self) -> str:
        """The design hash compiled into the code."""
        return self._fn["design_hash"]().decode()

    def check_design(self, expected: str) -> None:
        """Refuse code generated from another design than ``expected`` (e.g.
        :func:`~fdikit.codegen.config_digest` of the config now)."""
        if self.design_hash != expected:
            raise DataError(f"the generated code was built from another design (design hash "
                            f"{self.design_hash[:12]}..., the artifacts' is {expected[:12]}...): the design "
                            "changed after generation; rerun 'fdikit codegen'")

    def reset(self) -> None:
        self._fn["reset"](self._state)

    def step(self, t: float, x: np.ndarray) -> tuple[int, np.ndarray, list[dict]]:
        """One sample (values in :attr:`layout` ``inputs`` order): status code (negative: an
        error code), outputs (residuals then statistics) and events."""
        x = np.ascontiguousarray(x, dtype=float)
        st = self._fn["step"](self._state, float(t), x.ctypes.data, self._out.ctypes.data,
                              ctypes.addressof(self._ev), ctypes.byref(self._nev))
        ev = [self._event(self._ev[i]) for i in range(self._nev.value)] if st >= 0 else []
        return st, self._out[:self.n_out].copy(), ev

    def _event(self, e) -> dict:
        return _event_dict(self.layout, e.k, e.t, e.value, e.size, e.episode, e.channel, e.kind, e.previous)

    def run(self, t: np.ndarray, x: np.ndarray, *, reset: bool = True) -> dict[str, Any]:
        """Step through a record: ``t`` (T,), ``x`` (T, n_in). Returns ``out`` (T, n_out),
        ``status`` (T,) and ``events`` (onsets and cleared, in order)."""
        if reset:
            self.reset()
        T = len(t)
        out = np.empty((T, self.n_out))
        status = np.empty(T, np.int64)
        events: list[dict] = []
        for k in range(T):
            st, o, ev = self.step(t[k], x[k])
            if st < 0:
                raise DataError(f"the generated monitor refused sample {k} (t = {t[k]}) with code {st}")
            out[k], status[k] = o, st
            events += ev
        return {"out": out, "status": status, "events": events}

    def checkpoint(self) -> np.ndarray:
        """The state as ``checkpoint_len`` doubles (the generated ``checkpoint``)."""
        buf = np.zeros(self.layout["checkpoint_len"])
        self._fn["checkpoint"](self._state, buf.ctypes.data)
        return buf

    def restore(self, buf: np.ndarray) -> None:
        b = np.ascontiguousarray(buf, dtype=float)
        if b.shape != (self.layout["checkpoint_len"],):
            raise DataError(f"a checkpoint of this monitor has {self.layout['checkpoint_len']} values, got "
                            f"{b.shape}")
        self._fn["restore"](self._state, b.ctypes.data)


def _event_dict(layout: dict, k, t, value, size, episode, channel, kind, previous) -> dict:
    """A generated event as a dict: ``kind`` "onset", "cleared" or "change" (with ``previous``, the
    name it replaces; None otherwise)."""
    hyp = layout["hypotheses"]
    kind = {0: "cleared", 1: "onset", 2: "change"}.get(int(kind))
    if kind is None:
        raise DataError(f"the generated monitor wrote an event of unknown kind at sample {int(k)}")
    return {"k": int(k), "t": float(t), "hypothesis": hyp[int(channel)], "value": float(value), "kind": kind,
            "size": None if np.isnan(size) else float(size), "episode": int(episode),
            "previous": hyp[int(previous)] if int(previous) >= 0 else None}


def signals_input(layout: dict, signals: Any) -> tuple[np.ndarray, np.ndarray]:
    """The time and input matrix (T, n_in) of one-run :class:`~fdikit.Signals` in the layout's order."""
    if signals.runs != 1:
        raise DataError(f"the generated monitor runs one record at a time; got {signals.runs} runs")
    return signals.t, signals.values[0][:, signals.index(layout["inputs"])]


def _split(layout: dict, buf: np.ndarray) -> dict[str, np.ndarray]:
    arrays, off = {}, 0
    for name, _kind, n in layout["fields"]:
        arrays[name] = np.asarray(buf[off:off + n])
        off += n
    return arrays


def c_to_py_state(layout: dict, buf: np.ndarray, mon: Any, emitters) -> dict[str, Any]:
    """A C checkpoint as the Python :meth:`Monitor.state` of the same monitor (exact: every value
    is a double or an integer below 2^53)."""
    a = _split(layout, buf)
    i = {k: int(a[k][0]) for k in ("k", "held", "held_t", "missing", "warm_left", "reset_due", "warm_min",
                                   "quiet", "has_t_prev", "has_last", "n_ep")}
    R, S = len(layout["residuals"]), len(layout["statistics"])
    A = len(layout["alarm_channels"])
    U, H = int(layout.get("n_units", A)), int(layout.get("n_names", A))
    gens, procs = emitters
    last = a["last"][:R + S]
    # the wait of Decision.confirm_after per tentative name (-1 idle where the C does not wait)
    T = len(getattr(mon.decision, "_tent", ())) if mon.decision is not None else 0
    confirm = (a["confirm"][:T].astype(np.int64) if "confirm" in a
               else np.full(T, -1, np.int64)).reshape(1, T)
    return {"k": i["k"], "t_prev": float(a["t_prev"][0]) if i["has_t_prev"] else None, "held": i["held"],
            "held_t": i["held_t"], "missing": i["missing"], "dt": layout["dt"], "warm_left": i["warm_left"],
            "reset_due": bool(i["reset_due"]), "warm_min": i["warm_min"], "quiet": i["quiet"],
            "episodes": {"active": a["active"][:U].astype(bool).reshape(1, U),
                         "below": a["below"][:U].astype(np.int64).reshape(1, U),
                         "id": a["ep_id"][:U].astype(np.int64).reshape(1, U),
                         "count": np.array([i["n_ep"]], np.int64),
                         "current": a["cur"][:U].astype(np.int64).reshape(1, U),
                         "prev_on": a["prev_on"][:H].astype(bool).reshape(1, H), "confirm": confirm},
            "plausibility": None if not layout.get("plausibility") else
            plausibility_to_py(layout["plausibility"], a), "runs": 1,
            "generators": [e.to_py(a) for e in gens], "processors": [e.to_py(a) for e in procs],
            "last": [last[None, :R].copy(), last[None, R:].copy()] if i["has_last"] else None,
            "channels": {"inputs": list(mon.input_names), "residuals": list(mon.residual_names),
                         "statistics": list(mon.stat_names)}}


def py_to_c_state(layout: dict, state: dict[str, Any], emitters) -> np.ndarray:
    """The Python :meth:`Monitor.state` (one run) as a C checkpoint."""
    if int(state["runs"]) != 1:
        raise DataError("the generated monitor holds one run; the checkpoint has "
                        f"{state['runs']}")
    ep = state["episodes"]
    last = state["last"]
    vals: dict[str, Any] = {
        "k": state["k"], "has_t_prev": state["t_prev"] is not None, "held": state["held"],
        "held_t": state["held_t"], "missing": state["missing"], "warm_left": state["warm_left"],
        "reset_due": state["reset_due"], "warm_min": state["warm_min"], "quiet": state["quiet"],
        "has_last": last is not None, "n_ep": np.asarray(ep["count"]).reshape(-1)[0],
        "t_prev": 0.0 if state["t_prev"] is None else state["t_prev"],
        "last": None if last is None else np.concatenate([np.ravel(last[0]), np.ravel(last[1])]),
        "active": np.ravel(ep["active"]), "below": np.ravel(ep["below"]), "ep_id": np.ravel(ep["id"]),
        # (a checkpoint from before issue 27 has no names' state: zeros, as Python restores it)
        "cur": np.ravel(ep["current"]) if "current" in ep else None,
        "prev_on": np.ravel(ep["prev_on"]) if "prev_on" in ep else None,
        # (a checkpoint from before Decision.confirm_after: nothing waits, -1 as Python restores it)
        "confirm": np.ravel(ep["confirm"]) if "confirm" in ep else
        np.full(next((n for f, _k, n in layout["fields"] if f == "confirm"), 0), -1)}
    if layout.get("plausibility"):
        if state.get("plausibility") is None:
            raise DataError("the checkpoint has no plausibility state; the generated monitor has rules")
        vals.update(plausibility_from_py(state["plausibility"]))
    gens, procs = emitters
    for e, s in zip(gens, state["generators"]):
        vals.update(e.from_py(s))
    for e, s in zip(procs, state["processors"]):
        vals.update(e.from_py(s))
    buf = []
    for name, _kind, n in layout["fields"]:
        v = np.zeros(n) if vals.get(name) is None else np.asarray(vals[name], float).reshape(-1)
        if v.size < n:
            v = np.concatenate([v, np.zeros(n - v.size)])
        buf.append(v[:n])
    return np.concatenate(buf)


def driver_source(layout: dict) -> str:
    """A C ``main`` for the generated monitor: binary doubles on stdin, ``t`` then the inputs per
    sample; per sample on stdout ``status``, the outputs, the number of events and each event's
    ``k, t, value, size, episode, channel, kind, previous``, all as doubles. Used to run the code as a
    program (e.g. under the sanitizers) and in the benchmark."""
    nm = layout["name"]
    n_in = len(layout["inputs"])
    n_out = len(layout["residuals"]) + len(layout["statistics"])
    return f"""/* driver of {nm}: binary samples in, binary results out (fdikit.codegen.harness) */
#include <stdio.h>
#include "{nm}.h"

int main(void)
{{
    {nm}_state s;
    {nm}_event ev[{nm.upper()}_MAX_EVENTS];
    double in[{n_in + 1}], out[{max(n_out, 1)}], rec[8];
    int n, i, st;
    {nm}_init(&s);
    while (fread(in, sizeof(double), {n_in + 1}, stdin) == {n_in + 1}) {{
        double h[2];
        st = {nm}_step(&s, in[0], in + 1, out, ev, &n);
        if (st < 0) n = 0;
        h[0] = (double)st;
        fwrite(h, sizeof(double), 1, stdout);
        fwrite(out, sizeof(double), {n_out}, stdout);
        h[1] = (double)n;
        fwrite(h + 1, sizeof(double), 1, stdout);
        for (i = 0; i < n; ++i) {{
            rec[0] = (double)ev[i].k; rec[1] = ev[i].t; rec[2] = ev[i].value; rec[3] = ev[i].size;
            rec[4] = (double)ev[i].episode; rec[5] = (double)ev[i].channel; rec[6] = (double)ev[i].kind;
            rec[7] = (double)ev[i].previous;
            fwrite(rec, sizeof(double), 8, stdout);
        }}
    }}
    return 0;
}}
"""


def run_driver(exe: str | Path, layout: dict, t: np.ndarray, x: np.ndarray) -> dict[str, Any]:
    """Run a program built from :func:`driver_source` on a record; the same result as
    :meth:`CMonitor.run`."""
    data = np.column_stack([t, x]).astype(float).tobytes()
    res = subprocess.run([str(exe)], input=data, capture_output=True)
    if res.returncode != 0:
        raise DataError(f"{exe} failed ({res.returncode}): {res.stderr.decode(errors='replace')[-2000:]}")
    v = np.frombuffer(res.stdout, float)
    n_out = len(layout["residuals"]) + len(layout["statistics"])
    out, status, events, p = [], [], [], 0
    while p < v.size:
        status.append(int(v[p]))
        out.append(v[p + 1:p + 1 + n_out])
        n = int(v[p + 1 + n_out])
        p += 2 + n_out
        for _ in range(n):
            events.append(_event_dict(layout, *v[p:p + 8]))
            p += 8
    return {"out": np.array(out).reshape(-1, n_out), "status": np.array(status), "events": events,
            "stderr": res.stderr.decode(errors="replace")}
