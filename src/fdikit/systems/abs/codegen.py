"""C emitters of the ABS residual generators (issue 29): the nonlinear observer
(:class:`~fdikit.systems.abs.residuals.ABSObserver`, eqs. (29)-(33)) and the parity residual r1
(:class:`~fdikit.systems.abs.residuals.ParityR1`, eq. (25)), registered with
:func:`fdikit.codegen.register_emitter` when :mod:`fdikit.codegen` first meets one of them.

The observer is the compiled kernel's arithmetic, operation for operation (bitwise equal). r1's
causal spline derivative is a 25-tap dot product that numpy hands to BLAS, whose summation order
is not specified: the C sums the taps in order, equal to within rounding (about 1e-13 of the
channel's scale), not bitwise."""

from __future__ import annotations

import numpy as np

from ...codegen.registry import register_emitter
from ...codegen.stages import Field, StageEmitter, lit
from .residuals import _CIN, _COUT, _EPS, _H, _HELD, _IW, _KF, _KORF, _MV, _NV, _PLP, _RW, _SUB, _WN, _ZETA

__all__ = ["ABSObserverEmitter", "ParityR1Emitter"]

#: The exact orifice step of the observer's x5 (residuals._orifice).
ORIFICE_HELPER = """
static double fdk_abs_orifice(double P, double P_up, double k, double h)
{
    double d = P_up - P, r = sqrt(fabs(d)) - 0.5 * k * h;
    if (r <= 0.0) return P_up;
    return P_up - copysign(r * r, d);
}
"""


def _table_helper(tab: np.ndarray) -> str:
    n = tab.size - 1
    vals = ",\n    ".join(", ".join(lit(v) for v in tab[i:i + 6]) for i in range(0, tab.size, 6))
    return f"""
static const double FDK_ABS_MU[{tab.size}] = {{
    {vals}
}};

/* the friction table of the observer's kernel (residuals._mu_nb) */
static double fdk_abs_mu_nb(double lam)
{{
    double a = fabs(lam), m, z;
    int i;
    if (a >= 1.0) m = FDK_ABS_MU[{n}];
    else {{
        z = a * {lit(float(n))}; i = (int)z;
        m = FDK_ABS_MU[i] + (z - (double)i) * (FDK_ABS_MU[i + 1] - FDK_ABS_MU[i]);
    }}
    return lam >= 0.0 ? m : -m;
}}
"""


class ABSObserverEmitter(StageEmitter):
    """:class:`~fdikit.systems.abs.residuals.ABSObserver`: the residuals at the sample, then
    ``substeps`` Euler steps with the exact orifice law for x5, in double in both variants."""

    kinds = ("ABSObserver",)

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.helpers = (ORIFICE_HELPER, _table_helper(np.asarray(obj._tab, float)))

    def fields(self):
        return [Field(f"{self.p}_x", "f64", 5), Field(f"{self.p}_started", "i64", 1)]

    def reset_code(self):
        return (f"    {{ int j; for (j = 0; j < 5; ++j) {self.f('x')}[j] = 0.0; }}\n"
                f"    {self.f('started')}[0] = 0;")

    def step_code(self, inp, out):
        o = self.obj
        q, L = [lit(v) for v in o.q], [[lit(v) for v in row] for row in o.L]
        x = self.f("x")
        held = o.q[_HELD] > 0.5
        pm, uin, uout, y1, y2 = inp
        lines = ["    {", "        double y1, y2, pm, uin, uout, e1, e2, r0, r1, lam, m, d0, d1, d2, d3, x5;",
                 "        int sub;",
                 f"        pm = (double){pm}; uin = (double){uin}; uout = (double){uout};",
                 f"        y1 = (double){y1}; y2 = (double){y2};",
                 "        if (!isfinite(y1) || !isfinite(y2) || !isfinite(pm) || !isfinite(uin) "
                 "|| !isfinite(uout)) return FDK_ERR_STAT;",
                 f"        if (!{self.f('started')}[0]) {{ {x}[0] = y1; {x}[1] = y2; "
                 f"{x}[2] = 0.0; {x}[3] = 0.0; "
                 f"{x}[4] = 0.0; {self.f('started')}[0] = 1; }}",
                 f"        r0 = y1 - {x}[0]; r1 = y2 - {x}[1]; e1 = r0; e2 = r1;",
                 f"        for (sub = 0; sub < {int(o.q[_SUB])}; ++sub) {{"]
        if not held:
            lines.append(f"            e1 = y1 - {x}[0]; e2 = y2 - {x}[1];")
        h, wn = q[_H], q[_WN]
        lines += [
            f"            lam = ({x}[1] > {q[_EPS]}) ? ({x}[1] - {x}[0]) / {x}[1] : 0.0;",
            "            m = fdk_abs_mu_nb(lam);",
            f"            d0 = ({q[_RW]} * {q[_NV]} * m - {x}[2]) / {q[_IW]} + {L[0][0]} * e1 "
            f"+ {L[0][1]} * e2;",
            f"            d1 = -4.0 * {q[_NV]} * m / ({q[_RW]} * {q[_MV]}) + {L[1][0]} * e1 "
            f"+ {L[1][1]} * e2;",
            f"            d2 = {x}[3] + {L[2][0]} * e1 + {L[2][1]} * e2;",
            f"            d3 = {wn} * {wn} * ({q[_KF]} * {x}[4] - 2.0 * {q[_ZETA]} * {x}[3] / {wn} - {x}[2]) "
            f"+ {L[3][0]} * e1 + {L[3][1]} * e2;",
            f"            x5 = fdk_abs_orifice({x}[4], pm, {q[_KORF]} * {q[_CIN]} * uin, {h});",
            f"            x5 = fdk_abs_orifice(x5, {q[_PLP]}, {q[_KORF]} * {q[_COUT]} * uout, {h});",
            f"            {x}[0] += {h} * d0; {x}[1] += {h} * d1; {x}[2] += {h} * d2; {x}[3] += {h} * d3;",
            f"            {x}[4] = x5 + {h} * ({L[4][0]} * e1 + {L[4][1]} * e2);",
            f"            if ({x}[0] < 0.0) {x}[0] = 0.0;",
            f"            if ({x}[1] < 0.0) {x}[1] = 0.0;",
            "        }"]
        if o.v_min > 0.0:
            lines.append(f"        if (!({lit(o.p['R_w'])} * y2 >= {lit(o.v_min)})) "
                         "{ r0 = 0.0; r1 = 0.0; }")
        lines += [f"        {out[0]} = FDK_R(r0);", f"        {out[1]} = FDK_R(r1);", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_x": arrays[f"{self.p}_x"].astype(float).reshape(1, 5),
                "_started": bool(arrays[f"{self.p}_started"][0])}

    def from_py(self, state):
        return {f"{self.p}_x": np.asarray(state["_x"], float).reshape(-1),
                f"{self.p}_started": np.array([bool(state["_started"])])}


register_emitter("fdikit.systems.abs.residuals:ABSObserver", ABSObserverEmitter)


def _interp_helper(xp: np.ndarray, fp: np.ndarray) -> str:
    """``np.interp`` on a fixed table, as numpy's C computes it (the bracketing interval by
    search, ``slope * (x - xp[j]) + fp[j]``, the end values outside)."""
    n = xp.size
    arr = lambda v: ",\n    ".join(", ".join(lit(a) for a in v[i:i + 6]) for i in range(0, v.size, 6))  # noqa: E731
    return f"""
static const double FDK_ABS_R1_XP[{n}] = {{
    {arr(xp)}
}};
static const double FDK_ABS_R1_FP[{n}] = {{
    {arr(fp)}
}};

static double fdk_abs_interp(double x)
{{
    int lo = 0, hi = {n - 1}, mid;
    double slope, r;
    if (isnan(x)) return x;
    if (x < FDK_ABS_R1_XP[0]) return FDK_ABS_R1_FP[0];
    if (x > FDK_ABS_R1_XP[{n - 1}]) return FDK_ABS_R1_FP[{n - 1}];
    if (x == FDK_ABS_R1_XP[{n - 1}]) return FDK_ABS_R1_FP[{n - 1}];
    while (hi - lo > 1) {{ mid = (lo + hi) / 2; if (FDK_ABS_R1_XP[mid] <= x) lo = mid; else hi = mid; }}
    if (FDK_ABS_R1_XP[lo] == x) return FDK_ABS_R1_FP[lo];
    slope = (FDK_ABS_R1_FP[lo + 1] - FDK_ABS_R1_FP[lo]) / (FDK_ABS_R1_XP[lo + 1] - FDK_ABS_R1_XP[lo]);
    r = slope * (x - FDK_ABS_R1_XP[lo]) + FDK_ABS_R1_FP[lo];
    if (isnan(r)) {{
        r = slope * (x - FDK_ABS_R1_XP[lo + 1]) + FDK_ABS_R1_FP[lo + 1];
        if (isnan(r) && FDK_ABS_R1_FP[lo] == FDK_ABS_R1_FP[lo + 1]) r = FDK_ABS_R1_FP[lo];
    }}
    return r;
}}
"""


class ParityR1Emitter(StageEmitter):
    """:class:`~fdikit.systems.abs.residuals.ParityR1` (causal variant): the Butterworth sections
    (scipy's ``sosfilt`` recurrence, started in the unit-step steady state), the causal spline
    derivative (taps summed in order) and eq. (25) with the friction table (``np.interp``), in
    double in both variants."""

    kinds = ("ParityR1",)

    def __init__(self, obj, prefix):
        from ...errors import DataError
        from .plant import MU_SLIP, MU_TABLE

        if obj.variant != "causal":
            raise DataError("stage ParityR1 (zero-phase variant) cannot be generated: it needs the whole "
                            "record")
        super().__init__(obj, prefix)
        self.sos = np.asarray(obj._lp.sos, float)
        self.ns = self.sos.shape[0]
        self.zi = np.asarray(obj._lp._zi_unit, float)
        self.w = np.asarray(obj._der.w, float)
        self.W = int(obj._der.window)
        self.helpers = _interp_helper(np.asarray(MU_SLIP, float), np.asarray(MU_TABLE, float))

    def fields(self):
        return [Field(f"{self.p}_z", "f64", self.ns * 4), Field(f"{self.p}_has_z", "i64", 1),
                Field(f"{self.p}_buf", "f64", self.W), Field(f"{self.p}_has_buf", "i64", 1)]

    def reset_code(self):
        return f"    {self.f('has_z')}[0] = 0; {self.f('has_buf')}[0] = 0;"

    def step_code(self, inp, out):
        o, z, b = self.obj, self.f("z"), self.f("buf")
        S = self.sos
        lines = ["    {", "        double yv[2], xc, xn, d2, lam, mu, r;", "        int j;",
                 f"        yv[0] = (double){inp[0]}; yv[1] = (double){inp[1]};",
                 "        if (!isfinite(yv[0]) || !isfinite(yv[1])) return FDK_ERR_STAT;",
                 f"        if (!{self.f('has_z')}[0]) {{"]
        for s in range(self.ns):
            for c in range(2):
                for k in range(2):
                    lines.append(f"            {z}[{4 * s + 2 * c + k}] = {lit(self.zi[s, k])} * yv[{c}];")
        lines += [f"            {self.f('has_z')}[0] = 1;", "        }"]
        for c in range(2):   # scipy's _sosfilt: direct form II transposed, section by section
            lines.append(f"        xc = yv[{c}];")
            for s in range(self.ns):
                z0, z1 = f"{z}[{4 * s + 2 * c}]", f"{z}[{4 * s + 2 * c + 1}]"
                lines += [f"        xn = {lit(S[s, 0])} * xc + {z0};",
                          f"        {z0} = {lit(S[s, 1])} * xc - {lit(S[s, 4])} * xn + {z1};",
                          f"        {z1} = {lit(S[s, 2])} * xc - {lit(S[s, 5])} * xn;",
                          "        xc = xn;"]
            lines.append(f"        yv[{c}] = xc;")
        W = self.W
        lines += [f"        if (!{self.f('has_buf')}[0]) {{ for (j = 0; j < {W}; ++j) {b}[j] = yv[1]; "
                  f"{self.f('has_buf')}[0] = 1; }}",
                  f"        else {{ for (j = 0; j < {W - 1}; ++j) {b}[j] = {b}[j + 1]; "
                  f"{b}[{W - 1}] = yv[1]; }}",
                  "        d2 = 0.0;"]
        lines += [f"        d2 += {b}[{i}] * {lit(self.w[i])};" for i in range(W)]
        p = o.p
        lines += ["        lam = (yv[1] > 1e-06) ? (yv[1] - yv[0]) / yv[1] : 0.0;",
                  "        mu = fdk_abs_interp(fabs(lam));",
                  "        if (lam < 0.0) mu = -mu; else if (lam == 0.0) mu = 0.0 * mu;",
                  f"        r = d2 + 4.0 * {lit(p['N_v'])} * mu / ({lit(p['R_w'])} * {lit(p['M_v'])});",
                  f"        if (!({lit(p['R_w'])} * yv[1] >= {lit(o.v_min)})) r = 0.0;",
                  f"        {out[0]} = FDK_R(r);", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        a = arrays
        z = a[f"{self.p}_z"].astype(float).reshape(self.ns, 1, 2, 2) if a[f"{self.p}_has_z"][0] else None
        buf = a[f"{self.p}_buf"].astype(float).reshape(1, 1, self.W) if a[f"{self.p}_has_buf"][0] else None
        return {"_lp": {"__component__": {"_z": z, "_shape": (1, 2)}},
                "_der": {"__component__": {"_buf": buf, "_shape": (1, 1)}}}

    def from_py(self, state):
        z = state["_lp"]["__component__"]["_z"]
        buf = state["_der"]["__component__"]["_buf"]
        return {f"{self.p}_z": np.zeros(self.ns * 4) if z is None else np.asarray(z, float).reshape(-1),
                f"{self.p}_has_z": np.array([z is not None]),
                f"{self.p}_buf": np.zeros(self.W) if buf is None else np.asarray(buf, float).reshape(-1),
                f"{self.p}_has_buf": np.array([buf is not None])}


register_emitter("fdikit.systems.abs.residuals:ParityR1", ParityR1Emitter)
