"""The C emitter of the episode diagnosis by a D-matrix (:class:`~fdikit.isolate.DMatrixDecision`):
the latch of fired tests, the settle and clear counters, the maximum-likelihood decision over the
learned test reliabilities once the pattern is stable, and the held decision and size."""

from __future__ import annotations

import numpy as np

from .registry import register_emitter
from .stages import Field, StageEmitter, lit

__all__ = ["DMatrixDecisionEmitter"]


class DMatrixDecisionEmitter(StageEmitter):
    """:class:`~fdikit.isolate.DMatrixDecision`. The posterior is computed in double; its log
    likelihoods are sums of the learned log probabilities, which numpy forms by a matrix product
    (BLAS, summation order unspecified): the decided probability equals Python's to rounding."""

    kinds = ("DMatrixDecision",)

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.nt = len(obj.tests)
        self.G = len(obj.groups)

    def fields(self):
        return [Field(f"{self.p}_fired", "i64", self.nt), Field(f"{self.p}_since", "i64", 1),
                Field(f"{self.p}_quiet", "i64", 1), Field(f"{self.p}_locked", "i64", 1),
                Field(f"{self.p}_value", "f64", 1), Field(f"{self.p}_size", "f64", 1)]

    def reset_code(self):
        f = self.f
        return (f"    {{ int j; for (j = 0; j < {self.nt}; ++j) {f('fired')}[j] = 0; }}\n"
                f"    {f('since')}[0] = 0; {f('quiet')}[0] = 0; {f('locked')}[0] = -1;\n"
                f"    {f('value')}[0] = 0.0; "
                f"{f('size')}[0] = 0.0;")

    def step_code(self, inp, out):
        o, f, nt, G = self.obj, self.f, self.nt, self.G
        logp, log1mp = np.asarray(o._logp, float), np.asarray(o._log1mp, float)   # (n_t, n_rows)
        nr = logp.shape[1]
        lines = ["    {", f"        int on[{nt}], newf = 0, anyf = 0, anyon = 0, j, best;",
                 f"        double ll[{nr}], post[{G}], m, sw, a, b;"]
        lines += [f"        if (!FDK_FINITE({e})) return FDK_ERR_STAT;" for e in inp]
        for t in range(nt):
            lines += [f"        on[{t}] = {inp[t]} > FDK_R(0.5);",
                      f"        if (on[{t}] && !{f('fired')}[{t}]) newf = 1;",
                      f"        if (on[{t}]) {{ {f('fired')}[{t}] = 1; anyon = 1; }}",
                      f"        if ({f('fired')}[{t}]) anyf = 1;"]
        lines += [f"        {f('since')}[0] = newf ? 0 : (anyf ? {f('since')}[0] + 1 : 0);",
                  f"        {f('quiet')}[0] = anyon ? 0 : {f('quiet')}[0] + 1;",
                  f"        if ({f('locked')}[0] < 0 && anyf && {f('since')}[0] >= {int(o.settle)}) {{"]
        for r in range(nr):
            ta = " + ".join(f"(double){f('fired')}[{t}] * {lit(logp[t, r])}" for t in range(nt))
            tb = " + ".join(f"(1.0 - (double){f('fired')}[{t}]) * {lit(log1mp[t, r])}" for t in range(nt))
            lines += [f"            a = 0.0 + {ta};", f"            b = 0.0 + {tb};",
                      f"            ll[{r}] = a + b;"]
        lines += ["            m = ll[0];",
                  f"            for (j = 1; j < {nr}; ++j) if (ll[j] > m) m = ll[j];",
                  f"            sw = 0.0; for (j = 0; j < {nr}; ++j) "
                  "{ ll[j] = exp(ll[j] - m); sw += ll[j]; }",
                  f"            for (j = 0; j < {nr}; ++j) ll[j] = ll[j] / sw;"]
        for g in range(G):
            rows = [int(i) for i in np.flatnonzero(np.asarray(o._row_group) == g)]
            lines.append(f"            post[{g}] = " + " + ".join(f"ll[{i}]" for i in rows) + ";")
        lines += ["            best = 0;",
                  f"            for (j = 1; j < {G}; ++j) if (post[j] > post[best]) best = j;",
                  f"            {f('locked')}[0] = best; {f('value')}[0] = post[best];",
                  f"            {f('size')}[0] = 0.0;"]
        for g, src in enumerate(o._size_src):
            if src is not None:
                lines.append(f"            if (best == {g}) {f('size')}[0] = (double){inp[src]};")
        lines.append("        }")
        if o.clear is not None:
            lines += [f"        if (anyf && {f('quiet')}[0] >= {int(o.clear)}) {{",
                      f"            for (j = 0; j < {nt}; ++j) {f('fired')}[j] = 0;",
                      f"            {f('since')}[0] = 0; {f('locked')}[0] = -1; {f('value')}[0] = 0.0; "
                      f"{f('size')}[0] = 0.0;", "        }"]
        for g in range(G):
            lines.append(f"        {out[g]} = ({f('locked')}[0] == {g}) ? "
                         f"FDK_R({f('value')}[0]) : FDK_R(0.0);")
        for k, g in enumerate(o._size_cols):
            lines.append(f"        {out[G + k]} = ({f('locked')}[0] == {g}) ? "
                         f"FDK_R({f('size')}[0]) : FDK_R(0.0);")
        lines += ["        (void)post; (void)best;", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        a, p = arrays, self.p
        return {"_fired": a[f"{p}_fired"].astype(bool).reshape(1, -1),
                "_since": a[f"{p}_since"].astype(np.int64).reshape(1),
                "_quiet": a[f"{p}_quiet"].astype(np.int64).reshape(1),
                "_locked": a[f"{p}_locked"].astype(np.int64).reshape(1),
                "_value": a[f"{p}_value"].astype(float).reshape(1),
                "_size": a[f"{p}_size"].astype(float).reshape(1)}

    def from_py(self, state):
        p = self.p
        return {f"{p}_{k}": np.asarray(state[f"_{k}"]).astype(float).reshape(-1)
                for k in ("fired", "since", "quiet", "locked", "value", "size")}


register_emitter("fdikit.isolate.online:DMatrixDecision", DMatrixDecisionEmitter)
