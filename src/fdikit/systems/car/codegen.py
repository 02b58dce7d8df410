"""C emitter of the fused passenger-car health monitor (issue 29):
:class:`~fdikit.systems.car.monitor_fused.FusedCarMonitor` (ng-chen-speyer, Sections IV-V: the
fault detection filters, the parity equations, the residual-norm features, the per-block MHSSPTs
on tabulated densities with their warm-up, and hold-then-announce) as the streaming path of its
compiled kernel (a chunk of one run), operation for operation; the gap rule (:meth:`resume`:
the warm-up again) included. Registered with :func:`fdikit.codegen.register_emitter` when
:mod:`fdikit.codegen` first meets the stage."""

from __future__ import annotations

import numpy as np

from ...codegen.arrays import c_array
from ...codegen.mhsspt_c import MHSSPT_DENSITY_HELPERS, UPDATE_P_HELPER
from ...codegen.registry import register_emitter
from ...codegen.stages import Field, StageEmitter, lit
from .monitor_fused import _colspans

__all__ = ["FusedCarMonitorEmitter"]


class FusedCarMonitorEmitter(StageEmitter):
    """:class:`~fdikit.systems.car.monitor_fused.FusedCarMonitor`, in double in both variants. The
    filter matrices are walked by columns over their nonzero spans and the density table is
    constant data (code bytes); the state is the filter, parity, feature, posterior and hold
    state and the sample counter."""

    kinds = ("FusedCarMonitor",)
    handles_resume = True

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        a = obj._a
        self.nf, self.nv = a["A"].shape[0], a["Bv"].shape[1]
        self.q = a["C"].shape[0]
        self.C, self.H, self.G = a["x0"].size, obj._H, len(obj.faults)
        P = f"fdk_{prefix}"
        arrs = []
        for m, k in (("A", "A"), ("B", "Bv"), ("C", "C"), ("D", "Dv")):
            lo, hi, off, vals, _n = _colspans(a[k])
            arrs += [c_array(f"{P}_{m}_l", lo, "int64_t"), c_array(f"{P}_{m}_h", hi, "int64_t"),
                     c_array(f"{P}_{m}_o", off, "int64_t"), c_array(f"{P}_{m}_x", vals)]
        arrs += [c_array(f"{P}_v0", a["v0"]), c_array(f"{P}_tab", a["tab"]),
                 c_array(f"{P}_logp_pi", a["logp_pi"])]
        self.helpers = (MHSSPT_DENSITY_HELPERS, UPDATE_P_HELPER, "\n".join(arrs) + "\n")

    def fields(self):
        p = self.p
        return [Field(f"{p}_xi", "f64", max(self.nf, 1)), Field(f"{p}_par", "f64", 2),
                Field(f"{p}_feat", "f64", self.C), Field(f"{p}_logF", "f64", self.H),
                Field(f"{p}_cnt", "i64", self.G), Field(f"{p}_k", "i64", 1)]

    def reset_code(self):
        f, a = self.f, self.obj._a
        h0 = set(int(h) for h in a["blk_h0"])
        lines = [f"    {{ int j; for (j = 0; j < {max(self.nf, 1)}; ++j) {f('xi')}[j] = 0.0;",
                 f"      for (j = 0; j < {self.C}; ++j) {f('feat')}[j] = 0.0;",
                 f"      for (j = 0; j < {self.G}; ++j) {f('cnt')}[j] = 0;",
                 f"      for (j = 0; j < {self.H}; ++j) {f('logF')}[j] = -HUGE_VAL; }}",
                 *(f"    {f('logF')}[{h}] = 0.0;" for h in sorted(h0)),
                 f"    {f('par')}[0] = 0.0; {f('par')}[1] = NAN; {f('k')}[0] = 0;"]
        return "\n".join(lines)

    def resume_code(self) -> str:
        """Good data after a gap or held samples: the warm-up again (:meth:`FusedCarMonitor.resume`)."""
        return f"        {self.f('k')}[0] = 0;"

    def step_code(self, inp, out):
        o, a, f = self.obj, self.obj._a, self.f
        P = f"fdk_{self.p}"
        nf, nv, q, H, G = self.nf, self.nv, self.q, self.H, self.G
        lines = ["    {", f"        double v[{nv}], DV[{nv}], RR[{max(q, 1)}], TMP[{max(nf, 1)}],",
                 f"            r[{q + 2}];",
                 "        double xv, t, fr, ss;",
                 f"        double ll[{H}], phi[{H}], Pp[{H}], pg;", "        int64_t j, ii, oo, it;"]
        lines += [f"        v[{j}] = (double){e};" for j, e in enumerate(inp)]
        lines += [f"        for (j = 0; j < {nv}; ++j) DV[j] = v[j] - {P}_v0[j];",
                  f"        for (j = 0; j < {q}; ++j) RR[j] = 0.0;",
                  f"        for (j = 0; j < {nf}; ++j) TMP[j] = 0.0;",
                  f"        for (j = 0; j < {nf}; ++j) {{",
                  f"            xv = {f('xi')}[j];",
                  f"            oo = {P}_C_o[j] - {P}_C_l[j];",
                  f"            for (ii = {P}_C_l[j]; ii < {P}_C_h[j]; ++ii) "
                  f"RR[ii] += {P}_C_x[oo + ii] * xv;",
                  f"            oo = {P}_A_o[j] - {P}_A_l[j];",
                  f"            for (ii = {P}_A_l[j]; ii < {P}_A_h[j]; ++ii) "
                  f"TMP[ii] += {P}_A_x[oo + ii] * xv;",
                  "        }",
                  f"        for (j = 0; j < {nv}; ++j) {{",
                  "            xv = DV[j];",
                  f"            oo = {P}_D_o[j] - {P}_D_l[j];",
                  f"            for (ii = {P}_D_l[j]; ii < {P}_D_h[j]; ++ii) "
                  f"RR[ii] += {P}_D_x[oo + ii] * xv;",
                  f"            oo = {P}_B_o[j] - {P}_B_l[j];",
                  f"            for (ii = {P}_B_l[j]; ii < {P}_B_h[j]; ++ii) "
                  f"TMP[ii] += {P}_B_x[oo + ii] * xv;",
                  "        }",
                  f"        for (j = 0; j < {nf}; ++j) {f('xi')}[j] = TMP[j];",
                  f"        for (j = 0; j < {q}; ++j) r[j] = RR[j];"]
        pi, pv0 = [int(i) for i in a["par_idx"]], a["pv0"]
        if pi[0] >= 0:   # the parity equations (absolute values: pv0 adds the operating point back)
            ab = lambda i: f"(v[{i}] + {lit(pv0[i])})"  # noqa: E731
            lines += ["        {", f"            double thr = {ab(pi[0])}, prev = {f('par')}[1];",
                      "            if (isnan(prev)) prev = thr;",
                      f"            r[{q}] = {ab(pi[2])} - prev;",
                      f"            r[{q + 1}] = {ab(pi[3])} - {f('par')}[0];",
                      f"            {f('par')}[0] = {lit(o.par_a)} * {f('par')}[0] + "
                      f"(1.0 - {lit(o.par_a)}) * {ab(pi[1])};",
                      f"            {f('par')}[1] = thr;", "        }"]
        fs, fi = a["f_starts"], a["f_idx"]
        for j in range(self.C):
            lines.append("        ss = 0.0;")
            lines += [f"        ss += r[{int(fi[c])}] * r[{int(fi[c])}];"
                      for c in range(int(fs[j]), int(fs[j + 1]))]
            fj = f"{f('feat')}[{j}]"
            lines.append(f"        {fj} = {fj} + {lit(o.alpha)} * (sqrt(ss) - {fj});")
        low, high, std, point, logw = (a[k] for k in ("low", "high", "std", "point", "logw"))
        for b in range(a["blk_c0"].size):
            h0, h1 = int(a["blk_h0"][b]), int(a["blk_h1"][b])
            lines.append(f"        for (j = {h0}; j < {h1}; ++j) ll[j] = 0.0;")
            for c in range(int(a["blk_c0"][b]), int(a["blk_c1"][b])):
                lines += [f"        xv = ({f('k')}[0] >= {int(o.warmup)}) ? {f('feat')}[{c}] : "
                          f"{lit(a['x0'][c])};",
                          f"        t = (xv - {lit(a['g0'][c])}) * {lit(a['inv_h'][c])};",
                          f"        if (t >= 0.0 && t < {lit(float(a['nG'][c] - 1))}) {{",
                          "            it = (int64_t)t; fr = t - (double)it;",
                          f"            for (j = {h0}; j < {h1}; ++j) ll[j] += (1.0 - fr) * "
                          f"{P}_tab[({int(a['toff'][c])} + it) * {H} + j] "
                          f"+ fr * {P}_tab[({int(a['toff'][c])} + it + 1) * {H} + j];",
                          "        } else {"]
                lines += [f"            ll[{j}] += fdk_umg(xv, {lit(low[j, c])}, {lit(high[j, c])}, "
                          f"{lit(std[j, c])}, "
                          f"{int(point[j, c])}, {lit(logw[j, c])});" for j in range(h0, h1)]
                lines.append("        }")
            lines.append(f"        fdk_mhsspt_update_p({f('logF')} + {h0}, ll + {h0}, phi + {h0}, Pp + {h0}, "
                         f"{h1 - h0}, {lit(a['log1mp'][b])}, {P}_logp_pi + {h0}, {lit(a['logq'][b])}, "
                         f"{lit(a['log1mq'][b])});")
        for g in range(G):
            terms = "".join(f" + Pp[{int(e)}]" for e in a["grp"][g] if e >= 0)
            cg = f"{f('cnt')}[{g}]"
            lines += [f"        pg = 0.0{terms};", f"        {out[g]} = FDK_R(pg);",
                      f"        {cg} = (pg > {lit(o.level[g])}) ? {cg} + 1 : 0;",
                      f"        {out[G + g]} = ({cg} >= {int(o.hold[g])}) ? FDK_R(1.0) : FDK_R(0.0);"]
        lines += [f"        {f('k')}[0] += 1;", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        p = self.p
        return {"_xi": arrays[f"{p}_xi"][:self.nf].astype(float).reshape(1, self.nf),
                "_par": arrays[f"{p}_par"].astype(float).reshape(1, 2),
                "_feat": arrays[f"{p}_feat"].astype(float).reshape(1, -1),
                "_logF": arrays[f"{p}_logF"].astype(float).reshape(1, -1),
                "_cnt": arrays[f"{p}_cnt"].astype(np.int64).reshape(1, -1), "_k": int(arrays[f"{p}_k"][0])}

    def from_py(self, state):
        p = self.p
        xi = np.asarray(state["_xi"], float).reshape(-1)
        return {f"{p}_xi": xi if self.nf else np.zeros(1), f"{p}_par": np.ravel(state["_par"]),
                f"{p}_feat": np.ravel(state["_feat"]), f"{p}_logF": np.ravel(state["_logF"]),
                f"{p}_cnt": np.ravel(state["_cnt"]), f"{p}_k": np.array([state["_k"]])}


register_emitter("fdikit.systems.car.monitor_fused:FusedCarMonitor", FusedCarMonitorEmitter)
