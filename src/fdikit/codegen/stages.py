"""C emitters of the monitor's stages: one class per supported stage (its state fields, its reset
and its per-sample code, in the Python stage's exact order of floating-point operations), and
:func:`stage_emitter`, which refuses every other stage by name."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["Field", "StageEmitter", "lit", "stage_emitter"]


@dataclass(frozen=True)
class Field:
    """One array of the generated state struct: ``kind`` ``"real"`` (fdk_real: double or float),
    ``"f64"`` (always double) or ``"i64"`` (int64_t); ``n`` elements."""

    name: str
    kind: str
    n: int


def lit(x: float) -> str:
    """A C double literal that parses back to exactly ``x`` (shortest round trip)."""
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "(-HUGE_VAL)"
    s = repr(x)
    if "e" not in s and "." not in s:
        s += ".0"
    return f"({s})" if s.startswith("-") else s


def rl(x: float) -> str:
    """A literal of the working precision (``FDK_R(x)`` casts to fdk_real)."""
    return f"FDK_R({lit(x)})"


def refuse_nonfinite(var: str, n: int, idx: str = "i", test: str = "FDK_FINITE") -> str:
    """The C statement refusing a stage's inputs ``var[0..n)`` when one is not finite (``return
    FDK_ERR_STAT``, before any state change, as the Python stage raises).

    Parameters
    ----------
    var : str
        The C array of the inputs.
    n : int
        How many.
    idx : str
        The (declared) loop variable; it ends at ``n``.
    test : str
        The finiteness macro or function (``FDK_FINITE`` or ``isfinite``).

    Returns
    -------
    str
        One line (indented for a stage's block): every element is tested and the flags or-ed, then
        one branch, instead of a branch per element.
    """
    return (f"        {{ int bad = 0; for ({idx} = 0; {idx} < {n}; ++{idx}) bad |= !{test}({var}[{idx}]); "
            "if (bad) return FDK_ERR_STAT; }")


class StageEmitter:
    """Base of the stage emitters. ``prefix`` names the stage's fields in the state struct."""

    #: Python class names this emitter generates (exact type match: a subclass may change the step)
    kinds: tuple[str, ...] = ()
    #: C functions (static) the stage's code calls, emitted once per generated file
    helpers: str = ""

    def __init__(self, obj: Any, prefix: str):
        self.obj = obj
        self.p = prefix

    def fields(self) -> list[Field]:
        return []

    def reset_code(self) -> str:
        """Statements putting the stage in its initial state (``s`` the state)."""
        return ""

    def step_code(self, inp: list[str], out: list[str]) -> str:
        """Statements of one sample: ``inp`` C expressions of the inputs (fdk_real), ``out`` the
        lvalues of the outputs. May ``return FDK_ERR_STAT`` (a non-finite statistic, as the Python
        stage raises)."""
        raise NotImplementedError

    # checkpoint interop with the Python stage: its get_state() <-> the flat field arrays
    def to_py(self, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
        return {}

    def from_py(self, state: dict[str, Any]) -> dict[str, np.ndarray]:
        return {}

    def f(self, name: str) -> str:
        return f"s->{self.p}_{name}"

    def resume_code(self) -> str:
        """Statements of the stage's ``resume`` rule (data back after held samples or a gap;
        ``n_resume`` the samples missed), for emitters with ``handles_resume``."""
        return ""


# ---------------------------------------------------------------------------- generators
class FilterEmitter(StageEmitter):
    """:class:`~fdikit.residuals.FaultDetectionFilter` (and :class:`~fdikit.residuals.ObserverResidual`):
    ``r = C xi + Dv v; xi <- A xi + Bv v`` over the structural nonzeros of ``[[C, Dv], [A, Bv]]``,
    each row summed from 0.0 in column order (the compiled Python kernel's order)."""

    kinds = ("FaultDetectionFilter", "ObserverResidual")

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.nf = obj._A.shape[0]
        self.q = obj._C.shape[0]
        self.m = obj._Dv.shape[1]
        self.ptr, self.col, self.val = (np.asarray(a) for a in obj._rows)
        self.x0 = np.asarray(obj.x0, float)

    def fields(self):
        return [Field(f"{self.p}_xi", "real", max(self.nf, 1))]

    def reset_code(self):
        return "\n".join(f"    {self.f('xi')}[{a}] = {rl(v)};" for a, v in enumerate(self.x0)) or ""

    def step_code(self, inp, out):
        nf, q = self.nf, self.q
        # (the state is read in place, the inputs through z: every new state is computed before
        # the state is written, so no row sees a new value)
        decl = f"fdk_real z[{max(self.m, 1)}], " + (f"nx[{nf}], " if nf else "") + "acc;"
        lines = ["    {", f"        {decl}"]
        lines += [f"        z[{j}] = {e};" for j, e in enumerate(inp)]
        xi = self.f("xi")

        def z(col):
            return f"{xi}[{col}]" if col < nf else f"z[{col - nf}]"
        for row in range(q + nf):
            terms = [f"        acc += {rl(self.val[e])} * {z(self.col[e])};"
                     for e in range(self.ptr[row], self.ptr[row + 1])]
            dst = out[row] if row < q else f"nx[{row - q}]"
            lines += ["        acc = FDK_R(0.0);", *terms, f"        {dst} = acc;"]
        lines += [f"        {self.f('xi')}[{a}] = nx[{a}];" for a in range(nf)]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_xi": arrays[f"{self.p}_xi"][:self.nf].astype(float).reshape(1, self.nf)}

    def from_py(self, state):
        xi = np.asarray(state["_xi"], float).reshape(-1)
        return {f"{self.p}_xi": xi if self.nf else np.zeros(1)}


# ---------------------------------------------------------------------------- processors
class FeatureNormsEmitter(StageEmitter):
    """:class:`~fdikit.detect.FeatureNorms`: ``x += alpha (|r_group| - x)``."""

    kinds = ("FeatureNorms",)

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.idx, self.starts = list(obj._idx), list(obj._starts)
        self.nout = len(obj.output_names)

    def fields(self):
        return [Field(f"{self.p}_x", "real", self.nout)]

    def reset_code(self):
        return "\n".join(f"    {self.f('x')}[{j}] = FDK_R(0.0);" for j in range(self.nout))

    def step_code(self, inp, out):
        lines = ["    {", "        fdk_real acc, v;"]
        for j in range(self.nout):
            lines.append("        acc = FDK_R(0.0);")
            for c in range(self.starts[j], self.starts[j + 1]):
                lines += [f"        v = {inp[self.idx[c]]};", "        acc += v * v;"]
            x = self.f("x") + f"[{j}]"
            lines += [f"        {x} = {x} + {rl(self.obj.alpha)} * (FDK_SQRT(acc) - {x});",
                      f"        {out[j]} = {x};"]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_x": arrays[f"{self.p}_x"].astype(float).reshape(1, -1), "_first": True}

    def from_py(self, state):
        return {f"{self.p}_x": np.asarray(state["_x"], float).reshape(-1)}


class HoldEmitter(StageEmitter):
    """:class:`~fdikit.detect.Hold`: a count of consecutive exceedances; alarm at ``Z``."""

    kinds = ("Hold",)

    def fields(self):
        return [Field(f"{self.p}_count", "i64", len(self.obj.input_names))]

    def reset_code(self):
        return "\n".join(f"    {self.f('count')}[{j}] = 0;" for j in range(len(self.obj.input_names)))

    def step_code(self, inp, out):
        n = len(inp)
        lines = ["    {", f"        fdk_real v[{n}];"]
        lines += [f"        v[{j}] = {e};" for j, e in enumerate(inp)]
        # refused before the state changes, as the Python stage raises
        lines += [f"        if (!FDK_FINITE(v[{j}])) return FDK_ERR_STAT;" for j in range(n)]
        for j in range(n):
            x = f"FDK_ABS(v[{j}])" if self.obj.absolute else f"v[{j}]"
            c = self.f("count") + f"[{j}]"
            lines += [f"        {c} = ({x} > {rl(self.obj.threshold[j])}) ? {c} + 1 : 0;",
                      f"        {out[j]} = ({c} >= {int(self.obj.Z)}) ? FDK_R(1.0) : FDK_R(0.0);"]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_count": arrays[f"{self.p}_count"].astype(int).reshape(1, -1)}

    def from_py(self, state):
        return {f"{self.p}_count": np.asarray(state["_count"], np.int64).reshape(-1)}


class SignatureEmitter(StageEmitter):
    """:class:`~fdikit.isolate.SignatureDecision`: the nearest signatures (Hamming) to the alarm
    pattern, ``1 / m`` each (nothing when the nominal pattern is among them)."""

    kinds = ("SignatureDecision",)

    def step_code(self, inp, out):
        rows = np.asarray(self.obj._rows, int)
        nr, n = rows.shape
        lines = ["    {", f"        int b[{n}], d[{nr}], dmin, m;"]
        lines += [f"        if (!FDK_FINITE({e})) return FDK_ERR_STAT;" for e in inp]
        lines += [f"        b[{j}] = ({e} > FDK_R(0.5)) ? 1 : 0;" for j, e in enumerate(inp)]
        for i in range(nr):
            terms = " + ".join(f"(b[{j}] != {int(rows[i, j])})" for j in range(n)) or "0"
            lines.append(f"        d[{i}] = {terms};")
        lines.append("        dmin = d[0];")
        lines += [f"        if (d[{i}] < dmin) dmin = d[{i}];" for i in range(1, nr)]
        lines.append("        m = (d[0] == dmin) ? 0 : (" + " + ".join(
            f"(d[{i}] == dmin)" for i in range(1, nr)) + ");")
        for i in range(1, nr):
            lines.append(f"        {out[i - 1]} = (m > 0 && d[{i}] == dmin) ? FDK_R(1.0) / (fdk_real)m : "
                         "FDK_R(0.0);")
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {}


class GLRTEmitter(StageEmitter):
    """:class:`~fdikit.detect.GLRT` (luo-et-al eq. (24)): prefix sums re-anchored every ``W``
    samples, the maximum over the window's change times."""

    kinds = ("GLRT",)

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.C, self.W = len(obj.input_names), int(obj.W)
        self.scale = 1.0 / (2.0 * np.asarray(obj.sigma2, float))

    def fields(self):
        return [Field(f"{self.p}_Q", "real", self.C * (2 * self.W + 1)),
                Field(f"{self.p}_pos", "i64", self.C),
                Field(f"{self.p}_count", "i64", self.C), Field(f"{self.p}_k", "i64", 1)]

    def reset_code(self):
        return ("    "
                f"{{ int i; for (i = 0; i < {self.C * (2 * self.W + 1)}; ++i) "
                f"{self.f('Q')}[i] = FDK_R(0.0);\n"
                f"      for (i = 0; i < {self.C}; ++i) "
                f"{{ {self.f('pos')}[i] = 0; {self.f('count')}[i] = 0; }}\n"
                f"      {self.f('k')}[0] = 0; }}")

    def step_code(self, inp, out):
        W, top = self.W, 2 * self.W
        lines = ["    {", "        fdk_real *Q, base, d, v, best, tp;", "        int64_t p, i, L;"]
        lines += [f"        if (!FDK_FINITE({e})) return FDK_ERR_STAT;" for e in inp]
        lines.append(f"        {self.f('k')}[0] += 1;")
        for c, e in enumerate(inp):
            lines += [
                f"        Q = {self.f('Q')} + {c * (top + 1)}; p = {self.f('pos')}[{c}];",
                f"        if (p == {top}) {{ base = Q[{top - W}]; for (i = 0; i <= {W}; ++i) "
                f"Q[i] = Q[{top - W} + i] - base; p = {W}; }}",
                f"        Q[p + 1] = Q[p] + ({e} - {rl(self.obj.mu0[c])}); p += 1;",
                f"        if ({self.f('count')}[{c}] < {W}) {self.f('count')}[{c}] += 1;",
                "        tp = Q[p]; best = FDK_R(0.0);",
                f"        for (L = 1; L <= {self.f('count')}[{c}]; ++L) {{ d = tp - Q[p - L]; "
                "v = d * d * (FDK_R(1.0) / (fdk_real)L); if (v > best) best = v; }",
                f"        {self.f('pos')}[{c}] = p;",
                f"        {out[c]} = best * {rl(self.scale[c])};"]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        Q = arrays[f"{self.p}_Q"].astype(float).reshape(1, self.C, 2 * self.W + 1)
        return {"_state": (Q, arrays[f"{self.p}_pos"].astype(np.int64).reshape(1, -1),
                           arrays[f"{self.p}_count"].astype(np.int64).reshape(1, -1)),
                "_k": int(arrays[f"{self.p}_k"][0])}

    def from_py(self, state):
        Q, pos, cnt = state["_state"]
        return {f"{self.p}_Q": np.asarray(Q, float).reshape(-1), f"{self.p}_pos": np.asarray(pos).reshape(-1),
                f"{self.p}_count": np.asarray(cnt).reshape(-1), f"{self.p}_k": np.array([state["_k"]])}


class TimeGatedEmitter(StageEmitter):
    """:class:`~fdikit.detect.TimeGated` (luo-et-al eq. (35)): above ``q`` after ``T`` s, never
    above it before."""

    kinds = ("TimeGated",)
    needs_time = True

    def fields(self):
        n = len(self.obj.input_names)
        return [Field(f"{self.p}_t0", "f64", 1), Field(f"{self.p}_has_t0", "i64", 1),
                Field(f"{self.p}_early", "i64", n), Field(f"{self.p}_k", "i64", 1)]

    def reset_code(self):
        n = len(self.obj.input_names)
        return (f"    {self.f('t0')}[0] = 0.0; {self.f('has_t0')}[0] = 0; {self.f('k')}[0] = 0;\n"
                + "\n".join(f"    {self.f('early')}[{j}] = 0;" for j in range(n)))

    def step_code(self, inp, out):
        lines = ["    {", f"        if (!{self.f('has_t0')}[0]) "
                          f"{{ {self.f('t0')}[0] = t; {self.f('has_t0')}[0] = 1; }}",
                 f"        if (t - {self.f('t0')}[0] <= {lit(self.obj.T)}) {{"]
        for j, e in enumerate(inp):
            lines += [f"            if ({e} > {rl(self.obj.q[j])}) {self.f('early')}[{j}] = 1;",
                      f"            {out[j]} = FDK_R(0.0);"]
        lines.append("        } else {")
        for j, e in enumerate(inp):
            lines.append(f"            {out[j]} = ({e} > {rl(self.obj.q[j])} && !{self.f('early')}[{j}]) "
                         "? FDK_R(1.0) : FDK_R(0.0);")
        lines += ["        }", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        has = bool(arrays[f"{self.p}_has_t0"][0])
        return {"_early": arrays[f"{self.p}_early"].astype(bool).reshape(1, -1),
                "_t0": float(arrays[f"{self.p}_t0"][0]) if has else None, "_k": int(arrays[f"{self.p}_k"][0])}

    def from_py(self, state):
        t0 = state["_t0"]
        return {f"{self.p}_early": np.asarray(state["_early"]).reshape(-1).astype(np.int64),
                f"{self.p}_t0": np.array([0.0 if t0 is None else t0]),
                f"{self.p}_has_t0": np.array([t0 is not None]), f"{self.p}_k": np.array([state["_k"]])}


#: The emitters of the core stages above, by class name (the MHSSPT's, in :mod:`.mhsspt_c` and
#: :mod:`.stages_mhsspt_tab`, and the other core stages' are registered in :mod:`.registry`).
EMITTERS: dict[str, type[StageEmitter]] = {k: e for e in (FilterEmitter, FeatureNormsEmitter, HoldEmitter,
                                                          SignatureEmitter, GLRTEmitter, TimeGatedEmitter)
                                           for k in e.kinds}


def stage_emitter(obj: Any, prefix: str) -> StageEmitter:
    """The emitter of one stage, or a :class:`DataError` naming a stage that cannot be generated.

    Emitters registered in :mod:`fdikit.codegen.registry` (other core stages, system stages) are
    looked up first, by the stage's exact class path."""
    from .registry import registered_emitter, registered_names

    name = type(obj).__name__
    reg = registered_emitter(obj)
    if reg is not None:
        if hasattr(obj, "resume") and not getattr(reg, "handles_resume", False):
            raise DataError(f"stage {name} cannot be generated yet: its emitter does not generate its "
                            "resume() rule")
        return reg(obj, prefix)
    cls = EMITTERS.get(name)
    module = type(obj).__module__
    if cls is None or not module.startswith("fdikit.") or module.startswith("fdikit.systems"):
        known = sorted({*EMITTERS, *registered_names()})
        raise DataError(f"stage {name} cannot be generated yet (fdikit.codegen supports {', '.join(known)}; "
                        "generate the stages before it with stop_after=)")
    if any(hasattr(obj, a) for a in ("resume",)):
        raise DataError(f"stage {name} cannot be generated yet: it has a resume() rule")
    return cls(obj, prefix)
