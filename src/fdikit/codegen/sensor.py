"""C emitters of the sensor checks: :class:`~fdikit.detect.StuckDetector`,
:class:`~fdikit.detect.PeerCheck` and :class:`~fdikit.detect.PeerCUSUM`, with their warm-up and
their ``resume`` rule (start again after a gap), in the Python stages' order of floating-point
operations; registered in :mod:`.registry` when :mod:`fdikit.codegen` is imported."""

from __future__ import annotations

from typing import Any

import numpy as np

from .registry import class_path, register_emitter
from .stages import Field, StageEmitter, refuse_nonfinite, rl

__all__ = ["MEDIAN_HELPER", "PeerCUSUMEmitter", "PeerCheckEmitter", "StuckEmitter", "median_code"]

#: numpy's median of ``n`` values (finite): the middle of the sorted values, or the mean of the two
#: middle ones, ``(a + b) / 2`` as ``np.mean`` forms it.
MEDIAN_HELPER = """
static fdk_real fdk_median(const fdk_real *x, int n)
{
    fdk_real v[16], t;
    int i, j;
    for (i = 0; i < n; ++i) {
        t = x[i];
        for (j = i; j > 0 && v[j - 1] > t; --j) v[j] = v[j - 1];
        v[j] = t;
    }
    if (n % 2) return v[n / 2];
    return (v[n / 2 - 1] + v[n / 2]) / FDK_R(2.0);
}
"""


def median_code(dst: str, exprs: list[str], tmp: str = "mtmp") -> list[str]:
    """C lines setting ``dst`` to the median of the expressions (at most 16), via
    :data:`MEDIAN_HELPER`; ``tmp`` names the scratch array (declared here, in a block)."""
    if not 1 <= len(exprs) <= 16:
        raise ValueError(f"a generated median takes 1 to 16 values, got {len(exprs)}")
    return ["        {", f"            fdk_real {tmp}[{len(exprs)}];",
            *(f"            {tmp}[{i}] = {e};" for i, e in enumerate(exprs)),
            f"            {dst} = fdk_median({tmp}, {len(exprs)});", "        }"]


class StuckEmitter(StageEmitter):
    """:class:`~fdikit.detect.StuckDetector`: a flat run of the measured channel and the range of
    the expected one over it; nothing taken in during the warm-up; started again on resume."""

    kinds = ("StuckDetector",)
    handles_resume = True

    def fields(self):
        return [Field(f"{self.p}_{n}", "real", 1) for n in ("anchor", "pmin", "pmax")] + [
            Field(f"{self.p}_{n}", "i64", 1) for n in ("n", "started", "k")]

    def reset_code(self):
        return "\n".join(f"    {self.f(n)}[0] = {v};" for n, v in (
            ("anchor", "FDK_R(0.0)"), ("pmin", "FDK_R(0.0)"), ("pmax", "FDK_R(0.0)"), ("n", "0"),
            ("started", "0"), ("k", "0")))

    def resume_code(self):
        return self.reset_code().replace("    ", "        ", 1).replace("\n    ", "\n        ")

    def step_code(self, inp, out):
        o = self.obj
        has_e = o.expected is not None
        inv = rl(1.0 / (o.scale * o.threshold))
        f = self.f
        lines = ["    {", f"        fdk_real v = {inp[0]}, e = {inp[1] if has_e else 'FDK_R(0.0)'};",
                 "        if (!FDK_FINITE(v) || !FDK_FINITE(e)) return FDK_ERR_STAT;",
                 f"        if ({f('k')}[0] < {int(o.warmup)}) {{ {f('k')}[0] += 1; {out[0]} = FDK_R(0.0); }}",
                 "        else {"]
        if not has_e:
            lines.append("            e = v;")
        lines += [
            f"            if ({f('started')}[0] == 0 || FDK_ABS(v - {f('anchor')}[0]) > {rl(o.tol)}) {{",
            f"                {f('started')}[0] = 1; {f('anchor')}[0] = v;",
            f"                {f('pmin')}[0] = e; {f('pmax')}[0] = e; {f('n')}[0] = 0;",
            "            } else {",
            f"                {f('n')}[0] += 1;",
            f"                if (e < {f('pmin')}[0]) {f('pmin')}[0] = e;",
            f"                if (e > {f('pmax')}[0]) {f('pmax')}[0] = e;",
            "            }"]
        if has_e:
            lines.append(f"            {out[0]} = ({f('n')}[0] >= {int(o.min_samples)}) ? "
                         f"({f('pmax')}[0] - {f('pmin')}[0]) * {inv} : FDK_R(0.0);")
        else:
            lines.append(f"            {out[0]} = (fdk_real){f('n')}[0] * {inv};")
        lines += [f"            {f('k')}[0] += 1;", "        }", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        a = {n: arrays[f"{self.p}_{n}"] for n in ("anchor", "pmin", "pmax", "n", "started", "k")}
        return {"_anchor": a["anchor"].astype(float), "_pmin": a["pmin"].astype(float),
                "_pmax": a["pmax"].astype(float), "_n": a["n"].astype(np.int64),
                "_started": a["started"].astype(np.int64), "_k": int(a["k"][0]), "_R": 1}

    def from_py(self, state):
        out = {f"{self.p}_{n}": np.ravel(state[f"_{n}"]) for n in ("anchor", "pmin", "pmax", "n", "started")}
        return out | {f"{self.p}_k": np.array([state["_k"]])}


class PeerCheckEmitter(StageEmitter):
    """:class:`~fdikit.detect.PeerCheck`: each member against the median of its peers, the
    references and the rate channels' estimates (first-order filters started at the first sample),
    a first-order low-pass started at the first residual, normalised statistics and the group's
    isolated member; started again on resume."""

    kinds = ("PeerCheck",)
    handles_resume = True
    helpers = MEDIAN_HELPER

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        self.M = len(obj.members)
        self.L = len(obj.rate_channels)

    def fields(self):
        out = [Field(f"{self.p}_z", "real", self.M), Field(f"{self.p}_k", "i64", 1)]
        if self.L:                                    # the rate channels' filters
            out.append(Field(f"{self.p}_zr", "real", self.L))
        return out

    def reset_code(self):
        zr = (f"\n    {{ int i; for (i = 0; i < {self.L}; ++i) {self.f('zr')}[i] = FDK_R(0.0); }}"
              if self.L else "")
        return (f"    {{ int i; for (i = 0; i < {self.M}; ++i) {self.f('z')}[i] = FDK_R(0.0); }}\n"
                f"    {self.f('k')}[0] = 0;" + zr)

    def resume_code(self):
        return "    " + self.reset_code().replace("\n", "\n    ")

    def step_code(self, inp, out):
        o, M, f = self.obj, self.M, self.f
        n_in = len(inp)
        L = self.L
        lines = ["    {", f"        fdk_real px[{n_in}], e[{M}], st[{M}], iso[{M}], med"
                 + (f", rt[{L}]" if L else "") + ";", "        int i;"]
        lines += [f"        px[{i}] = {v};" for i, v in enumerate(inp)]
        lines += [refuse_nonfinite("px", n_in)]
        z, k = f("z"), f("k")
        if L:                                         # the rate estimates (PeerCheck._step's order)
            zr = f("zr")
            for i, ci in enumerate(o._rate_in):
                lines += [f"        if ({k}[0] == 0) {zr}[{i}] = px[{int(ci)}];",
                          f"        else {zr}[{i}] = {zr}[{i}] + {rl(o._a_rate)} * "
                          f"(px[{int(ci)}] - {zr}[{i}]);",
                          f"        rt[{i}] = (px[{int(ci)}] - {zr}[{i}]) * {rl(o._g_rate)};"]
        for j in range(M):
            c = o._c[j]
            nr = len(o._refs[j])
            lines += median_code("med", [f"px[{int(p)}]" for p in o._peers[j]])
            lines.append(f"        e[{j}] = px[{int(o._self[j])}] - {rl(c[0])} - {rl(c[1])} * med;")
            for r, d in zip(o._refs[j], c[2:2 + nr]):
                lines.append(f"        e[{j}] = e[{j}] - {rl(d)} * px[{int(r)}];")
            for r, d in zip(o._rates[j], c[2 + nr:]):
                lines.append(f"        e[{j}] = e[{j}] - {rl(d)} * rt[{int(r)}];")
        lines += [f"        if ({k}[0] == 0) {{ for (i = 0; i < {M}; ++i) {z}[i] = e[i]; }}",
                  "        else {"]
        lines += [f"            {z}[{j}] = {z}[{j}] + {rl(a)} * (e[{j}] - {z}[{j}]);"
                  for j, a in enumerate(o._alpha)]
        lines += ["        }", f"        {k}[0] += 1;"]
        lines += [f"        st[{j}] = FDK_ABS({z}[{j}]) / {rl(h)}; iso[{j}] = FDK_R(0.0);"
                  for j, h in enumerate(o._h)]
        lines += [f"        if ({k}[0] > {int(o.warmup)}) {{"]
        for gi in o._gidx:
            lines += [f"            {{ int b = {gi[0]};"]
            lines += [f"              if (st[{m}] > st[b]) b = {m};" for m in gi[1:]]
            lines += ["              iso[b] = (st[b] >= FDK_R(1.0)) ? FDK_R(1.0) : FDK_R(0.0); }"]
        lines += [f"        }} else {{ for (i = 0; i < {M}; ++i) st[i] = FDK_R(0.0); }}"]
        for j in range(M):
            lines += [f"        {out[j]} = st[{j}];", f"        {out[M + j]} = {z}[{j}];",
                      f"        {out[2 * M + j]} = px[{int(o._xidx[j])}] - e[{j}];",
                      f"        {out[3 * M + j]} = e[{j}];"]
        lines += [f"        {out[4 * M + a]} = iso[{int(j)}];" for a, j in enumerate(o._ann)]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        zr = arrays[f"{self.p}_zr"].astype(float).reshape(1, -1) if self.L else np.zeros((1, 0))
        return {"_z": arrays[f"{self.p}_z"].astype(float).reshape(1, -1), "_k": int(arrays[f"{self.p}_k"][0]),
                "_zr": zr}

    def from_py(self, state):
        out = {f"{self.p}_z": np.ravel(state["_z"]), f"{self.p}_k": np.array([state["_k"]])}
        if self.L:
            out[f"{self.p}_zr"] = np.ravel(state["_zr"])
        return out


class PeerCUSUMEmitter(StageEmitter):
    """:class:`~fdikit.detect.PeerCUSUM`: a two-sided CUSUM per member (nothing taken in during the
    warm-up), normalised by its threshold, the group's largest isolated when >= 1, merged with the
    peer check's statistic and isolation; started again on resume."""

    kinds = ("PeerCUSUM",)
    handles_resume = True

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        self.M = len(obj.members)

    def fields(self):
        return [Field(f"{self.p}_up", "real", self.M), Field(f"{self.p}_lo", "real", self.M),
                Field(f"{self.p}_k", "i64", 1)]

    def reset_code(self):
        return (f"    {{ int i; for (i = 0; i < {self.M}; ++i) {{ {self.f('up')}[i] = FDK_R(0.0); "
                f"{self.f('lo')}[i] = FDK_R(0.0); }} }}\n"
                f"    {self.f('k')}[0] = 0;")

    def resume_code(self):
        return "    " + self.reset_code().replace("\n", "\n    ")

    def step_code(self, inp, out):
        o, M, f = self.obj, self.M, self.f
        A = len(o._out)
        up, lo, k = f("up"), f("lo"), f("k")
        lines = ["    {", f"        fdk_real px[{len(inp)}], g[{M}], iso[{M}], x;", "        int i;"]
        lines += [f"        px[{i}] = {v};" for i, v in enumerate(inp)]
        lines += [refuse_nonfinite("px", len(inp)),
                  f"        {k}[0] += 1;", f"        if ({k}[0] > {int(o.warmup)}) {{"]
        # np.maximum(0.0, x): 0.0 where 0.0 >= x, else x; (up + (e - mu)) - nu, (lo - (e - mu)) - nu
        for j in range(M):
            mu, nu = rl(o._mu[j]), rl(o._nu[j])
            lines += [f"            x = {up}[{j}] + (px[{j}] - {mu}) - {nu};",
                      f"            {up}[{j}] = (FDK_R(0.0) >= x) ? FDK_R(0.0) : x;",
                      f"            x = {lo}[{j}] - (px[{j}] - {mu}) - {nu};",
                      f"            {lo}[{j}] = (FDK_R(0.0) >= x) ? FDK_R(0.0) : x;"]
        lines.append("        }")
        lines += [f"        g[{j}] = (({up}[{j}] >= {lo}[{j}]) ? {up}[{j}] : {lo}[{j}]) / {rl(h)}; "
                  f"iso[{j}] = FDK_R(0.0);" for j, h in enumerate(o._h)]
        for gi, ga, gp in zip(o._gidx, o._gann, o._gpeer, strict=True):
            lines += [f"        {{ int b = {gi[0]};"]
            lines += [f"          if (g[{m}] > g[b]) b = {m};" for m in gi[1:]]
            lines += ["          iso[b] = (g[b] >= FDK_R(1.0)) ? FDK_R(1.0) : FDK_R(0.0);"]
            if o._T is not None and ga.size and gp:
                lines += _transfer_code(o._T, ga, gp)
            lines += ["        }"]
        for a, j in enumerate(o._oix):
            pe, ip = f"px[{M + a}]", f"px[{M + A + a}]"
            lines += [f"        {out[a]} = g[{j}];",
                      f"        {out[A + a]} = (g[{j}] >= {pe}) ? g[{j}] : {pe};",
                      f"        {out[2 * A + a]} = (iso[{j}] >= {ip}) ? iso[{j}] : {ip};"]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_up": arrays[f"{self.p}_up"].astype(float).reshape(1, -1),
                "_lo": arrays[f"{self.p}_lo"].astype(float).reshape(1, -1),
                "_k": int(arrays[f"{self.p}_k"][0])}

    def from_py(self, state):
        return {f"{self.p}_up": np.ravel(state["_up"]), f"{self.p}_lo": np.ravel(state["_lo"]),
                f"{self.p}_k": np.array([state["_k"]])}


def _transfer_code(T, ga, gp) -> list[str]:
    """C of PeerCUSUM's transfer rule in one group (``b`` its largest member, ``g``, ``iso``): the
    largest announced member isolated when a peer only is the largest and explained by its fault."""
    lines = [f"          {{ int a = {ga[0]}, ok;"]
    lines += [f"            if (g[{m}] > g[a]) a = {m};" for m in ga[1:]]
    lines += ["            ok = (g[a] >= FDK_R(1.0)) && (" + " || ".join(f"b == {p}" for p in gp) + ");"]
    for m in ga:
        conds = " && ".join(f"(g[{p}] <= {rl(T[m, p])} * g[{m}] + FDK_R(1.0)) && "
                            f"(g[{m}] > {rl(T[p, m])} * g[{p}])"
                            for p in gp)
        lines += [f"            if (a == {m}) ok = ok && {conds};"]
    lines += ["            if (ok) iso[a] = FDK_R(1.0); }"]
    return lines


def _register() -> None:
    from ..detect import PeerCheck, PeerCUSUM, StuckDetector

    register_emitter(class_path(StuckDetector), StuckEmitter)
    register_emitter(class_path(PeerCheck), PeerCheckEmitter)
    register_emitter(class_path(PeerCUSUM), PeerCUSUMEmitter)


_register()
