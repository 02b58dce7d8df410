"""C emitters of the RAV4 lateral monitor's own stages (issue 29): the preprocessing and the
scheduled filter bank (:class:`Rav4LateralFilter`), the sensor-check channels
(:class:`Rav4SensorChannels`), the peer signals (:class:`Rav4PeerSignals`) and the tabulated
MHSSPT with its warm-up (:class:`Rav4MHSSPT`), each in its Python stage's order of floating-point
operations.

Registered with :func:`fdikit.codegen.registry.register_emitter` when imported; the code generator
imports this module by its plugin convention the first time it meets one of these stages (it
never imports a system itself). The monitor's other stages (:class:`~fdikit.detect.FeatureNorms`,
:class:`~fdikit.detect.Hold`, :class:`~fdikit.detect.StuckDetector`,
:class:`~fdikit.detect.PeerCheck`) are core stages with core emitters.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from ....codegen.mhsspt_c import MHSSPT_HELPERS, MHSSPTCode
from ....codegen.registry import class_path, register_emitter
from ....codegen.scheduled import ScheduledFilterEmitter
from ....codegen.sensor import MEDIAN_HELPER, median_code
from ....codegen.stages import Field, StageEmitter, lit, refuse_nonfinite, rl
from ....errors import DataError
from ..rav4 import RAV4
from .filters import Rav4LateralFilter
from .mhsspt import Rav4MHSSPT
from .peers import Rav4PeerSignals
from .sensor_checks import Rav4SensorChannels

__all__ = ["Rav4FilterEmitter", "Rav4MHSSPTEmitter", "Rav4PeerSignalsEmitter", "Rav4SensorChannelsEmitter",
           "preprocessing_code"]


def preprocessing_code(pre: Any, u: list[str], y: list[str]) -> list[str]:
    """C declarations of the preprocessed channels ``pre_steer, pre_U, pre_ay, pre_yaw, pre_fd,
    pre_rd`` (:meth:`Rav4Preprocessing.apply`) from the raw ``u`` (3) and ``y`` (6) expressions."""
    return [f"        fdk_real pre_U = {u[2]};",
            f"        fdk_real pre_steer = ({u[0]} + {u[1]} - {rl(pre.delta_0)}) / {rl(pre.i_s)};",
            f"        fdk_real pre_ay = {rl(pre.ay_sign)} * ({y[1]} - {rl(pre.b_ay)});",
            f"        fdk_real pre_yaw = {y[0]} - {rl(pre.b_r)};",
            f"        fdk_real pre_fd = {y[2]} - {y[3]} - {rl(pre.c_f)} * pre_U;",
            f"        fdk_real pre_rd = {y[4]} - {y[5]} - {rl(pre.c_r)} * pre_U;",
            "        (void)pre_steer; (void)pre_ay; (void)pre_yaw; (void)pre_fd; (void)pre_rd;"]


class Rav4FilterEmitter(ScheduledFilterEmitter):
    """:class:`Rav4LateralFilter`: the fitted preprocessing of the raw channels, then the
    speed-scheduled filter bank on ``u = [steer]``, ``y = [a_y, yaw_rate, w_front_diff,
    w_rear_diff]``, blended in the speed."""

    kinds = ("Rav4LateralFilter",)

    def inputs(self, inp):
        decl = preprocessing_code(self.obj.pre, inp[:3], inp[3:])
        return decl, ["pre_steer"], ["pre_ay", "pre_yaw", "pre_fd", "pre_rd"], "pre_U"


class Rav4SensorChannelsEmitter(StageEmitter):
    """:class:`Rav4SensorChannels`: the analytic-redundancy channels and their second-order
    sections (the steering prediction started in steady state at its first value)."""

    kinds = ("Rav4SensorChannels",)

    def fields(self):
        return [Field(f"{self.p}_z", "real", 12), Field(f"{self.p}_started", "i64", 1)]

    def reset_code(self):
        return (f"    {{ int i; for (i = 0; i < 12; ++i) {self.f('z')}[i] = FDK_R(0.0); }}\n"
                f"    {self.f('started')}[0] = 0;")

    def step_code(self, inp, out):
        o = self.obj
        c = o.coef
        z, b, a = self.f("z"), o._b, o._a
        lines = ["    {", *preprocessing_code(o.pre, inp[:3], inp[3:]),
                 "        fdk_real U = pre_U > FDK_R(1.0) ? pre_U : FDK_R(1.0), raw[6], v, yv;",
                 "        int i;",
                 "        if (pre_U != pre_U) U = pre_U;",
                 f"        raw[0] = {rl(c['steer'][0])} * pre_yaw / U + {rl(c['steer'][1])} * pre_yaw * U;",
                 f"        raw[1] = pre_yaw - {rl(c['ay'][0])} * pre_ay / U - {rl(c['ay'][1])};",
                 f"        raw[2] = pre_yaw - {rl(c['rear'][0])} * pre_rd - {rl(c['rear'][1])};",
                 f"        raw[3] = pre_fd - {rl(c['k_f'])} * pre_yaw;",
                 f"        raw[4] = pre_rd - {rl(c['k_r'])} * pre_yaw;",
                 f"        raw[5] = pre_fd - {rl(c['k_f'] / c['k_r'])} * pre_rd;",
                 refuse_nonfinite("raw", 6),
                 f"        if ({self.f('started')}[0] == 0) {{"]
        for ch in range(6):
            x0 = f"raw[{ch}]" if o._first[ch] else "FDK_R(0.0)"
            lines += [f"            {z}[{2 * ch + 1}] = ({rl(b[ch, 2])} - {rl(a[ch, 2])}) * {x0};",
                      f"            {z}[{2 * ch}] = ({rl(b[ch, 1])} - {rl(a[ch, 1])}) * {x0}"
                      f" + {z}[{2 * ch + 1}];"]
        lines += [f"            {self.f('started')}[0] = 1;", "        }"]
        for ch in range(6):
            lines += [f"        v = raw[{ch}];", f"        yv = {rl(b[ch, 0])} * v + {z}[{2 * ch}];",
                      f"        {z}[{2 * ch}] = {rl(b[ch, 1])} * v - {rl(a[ch, 1])} * yv"
                      f" + {z}[{2 * ch + 1}];",
                      f"        {z}[{2 * ch + 1}] = {rl(b[ch, 2])} * v - {rl(a[ch, 2])} * yv;",
                      f"        {out[1 + ch]} = yv" + ("" if ch else f" + {rl(c['steer'][2])}") + ";"]
        lines += [f"        {out[0]} = pre_steer;", f"        {out[7]} = U;", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"_z": arrays[f"{self.p}_z"].astype(float).reshape(1, 6, 2),
                "_started": arrays[f"{self.p}_started"].astype(np.int64)}

    def from_py(self, state):
        return {f"{self.p}_z": np.ravel(state["_z"]), f"{self.p}_started": np.ravel(state["_started"])}


class Rav4PeerSignalsEmitter(StageEmitter):
    """:class:`Rav4PeerSignals` (stateless): the redundant groups' members, the wheels' reference
    (the median wheel speed squared) and the raw sensor values."""

    kinds = ("Rav4PeerSignals",)
    helpers = MEDIAN_HELPER

    def step_code(self, inp, out):
        o = self.obj
        u, y = inp[:3], inp[3:]
        raw = {"raw:wheel_fl": y[2], "raw:wheel_fr": y[3], "raw:wheel_rl": y[4], "raw:wheel_rr": y[5],
               "raw:yaw_rate": y[0], "raw:accel_y": y[1], "raw:steer_angle": u[0]}
        lines = ["    {", *preprocessing_code(o.pre, u, y),
                 "        fdk_real U = pre_U > FDK_R(1.0) ? pre_U : FDK_R(1.0), v[20], m;", "        int i;",
                 "        if (pre_U != pre_U) U = pre_U;"]
        cols = [y[2], y[3], y[4], y[5], "pre_yaw", "pre_ay / U",
                f"(pre_steer - {rl(o.steer[2])}) * U / {rl(RAV4['L'])}", f"pre_fd / {rl(o.k_f)}",
                f"pre_rd / {rl(o.k_r)}"]
        lines += [f"        v[{i}] = {e};" for i, e in enumerate(cols)]
        lines += median_code("m", y[2:6])
        lines.append("        v[9] = m * m;")
        lines += [f"        v[{10 + i}] = {raw[n]};" for i, n in enumerate(sorted(raw))]
        p = o.pre
        lines += [f"        v[17] = {rl(p.b_r)} + FDK_R(0.0) * U;",
                  f"        v[18] = {rl(p.ay_sign * p.b_ay)} / U;",
                  f"        v[19] = ({rl(o.steer[2])} - ({u[1]} - {rl(p.delta_0)}) / {rl(p.i_s)}) * U "
                  f"/ {rl(RAV4['L'])};"]
        n = len(o.output_names)
        if n != 20:
            raise DataError(f"stage {type(o).__name__} with {n} outputs cannot be generated (20 expected)")
        lines += [refuse_nonfinite("v", n)]
        lines += [f"        {out[i]} = v[{i}];" for i in range(n)]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {}


#: One step of the log-domain Shiryayev recursion (the core helper) and the normalised posteriors
#: ``P`` that :func:`fdikit.detect.mhsspt.mhsspt_update` forms (the fused table kernels' outputs),
#: recomputed from the same ``phi`` with the same operations.
UPDATE_P_HELPER = """
static void fdk_mhsspt_update_p(double *logF, const double *ll, double *phi, double *P, int H,
                                double log1mp, const double *logp_pi, double logq, double log1mq)
{
    double m = -HUGE_VAL, s = 0.0, x;
    int j;
    fdk_mhsspt_update(logF, ll, phi, H, log1mp, logp_pi, logq, log1mq);
    /* phi: the updated unnormalised log posteriors; P as the update's normalisation forms it */
    for (j = 0; j < H; ++j) if (phi[j] > m) m = phi[j];
    for (j = 0; j < H; ++j) {
        x = phi[j] - m;
        if (x > -40.0) { P[j] = exp(x); s += P[j]; } else P[j] = 0.0;
    }
    for (j = 0; j < H; ++j) P[j] = P[j] / s;
}
"""


def _floats(a) -> list[str]:
    """Exact C99 double literals of an array: hexadecimal floats (``float.hex``; the compiler
    parses them faster than decimal ones) of finite values, :func:`lit` otherwise."""
    a = np.ravel(np.asarray(a, float))
    return list(map(float.hex, a.tolist())) if np.isfinite(a).all() else [lit(v) for v in a]


def _array(ctype: str, name: str, vals) -> str:
    vals = list(vals)
    body = ",\n".join(", ".join(vals[i:i + 8]) for i in range(0, len(vals), 8)) or "0"
    return f"static const {ctype} {name}[{max(len(vals), 1)}] = {{\n{body}}};\n"


_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _tables(obj: Any, p: str) -> str:
    """The constant tables of a :class:`Rav4MHSSPT` as C (cached per stage object and prefix: the
    double and float32 variants share them)."""
    key = (p, id(obj._cubic[0]))
    hit = _TABLES.get(obj)
    if hit is not None and hit[0] == key:
        return hit[1]
    coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, _uoff, _jmap = obj._cubic
    f = _floats
    i = lambda a: [str(int(v)) for v in np.ravel(a)]  # noqa: E731
    text = "".join([
        f"/* {p}: the cubic tables of Rav4MHSSPT ({coef.size} coefficients) */\n",
        _array("double", f"{p}_coef", f(coef)), _array("double", f"{p}_g0", f(g0)),
        _array("double", f"{p}_inv_h", f(inv_h)), _array("int64_t", f"{p}_nG", i(nG)),
        _array("int64_t", f"{p}_coff", i(coff)), _array("double", f"{p}_ulow", f(ulow)),
        _array("double", f"{p}_uhigh", f(uhigh)), _array("double", f"{p}_ustd", f(ustd)),
        _array("int", f"{p}_upoint", i(upoint)), _array("double", f"{p}_ulogw", f(ulogw)),
        _array("double", f"{p}_logp_pi", f(obj._logp_pi)), _array("double", f"{p}_x0", f(obj._x0))])
    _TABLES[obj] = (key, text)
    return text


class Rav4MHSSPTEmitter(MHSSPTCode):
    """:class:`Rav4MHSSPT` with cubic Hermite tables (the design's ``tabulate``,
    ``interpolation="cubic"``): the tables as constant data, the exact densities outside them,
    the recursion and the posteriors it forms, in double in both variants; the warm-up (the middle
    of the no-fault range as the features) at the start and again after a gap (``resume``)."""

    kinds = ("Rav4MHSSPT",)
    handles_resume = True

    def __init__(self, obj: Any, prefix: str):
        if obj._cubic is None:
            raise DataError("stage Rav4MHSSPT cannot be generated yet without cubic tables (tabulate with "
                            "interpolation='cubic'); its exact and linear-table forms are not emitted")
        super().__init__(obj, prefix)
        coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap = obj._cubic
        self.tab = dict(coef=coef, g0=g0, inv_h=inv_h, nG=nG, coff=coff, ulow=ulow, uhigh=uhigh, ustd=ustd,
                        upoint=upoint, ulogw=ulogw, uoff=uoff, jmap=jmap)
        self.helpers = (MHSSPT_HELPERS, UPDATE_P_HELPER, _tables(obj, prefix))

    def fields(self):
        return [*super().fields(), Field(f"{self.p}_warm_from", "i64", 1)]

    def reset_code(self):
        return super().reset_code() + f" {self.f('warm_from')}[0] = 0;"

    def resume_code(self):
        return f"        {self.f('warm_from')}[0] = {self.f('k')}[0];"

    def step_code(self, inp, out):
        o, H, C, p, tb = self.obj, self.H, self.C, self.p, self.tab
        uoff, jmap = tb["uoff"], tb["jmap"]
        nu = int(uoff[-1])
        lines = ["    {", f"        double xs[{C}], vals[{nu}], ll[{H}], phi[{H}], P[{H}], t, sv;",
                 "        int64_t ii, b, q;",
                 f"        int warm = {int(o.warmup)} - ({self.f('k')}[0] - {self.f('warm_from')}[0]) > 0;"]
        lines += [f"        xs[{c}] = warm ? {p}_x0[{c}] : (double){e};" for c, e in enumerate(inp)]
        lines += self.refusal_lines()
        for c in range(C):
            e0, e1 = int(uoff[c]), int(uoff[c + 1])
            lines += [f"        t = (xs[{c}] - {p}_g0[{c}]) * {p}_inv_h[{c}];",
                      f"        if (t >= 0.0 && t < (double)({p}_nG[{c}] - 1)) {{",
                      "            ii = (int64_t)t; sv = t - (double)ii;",
                      f"            b = 4 * ({p}_coff[{c}] + ii * {e1 - e0} - {e0});",
                      f"            for (q = {e0}; q < {e1}; ++q) {{",
                      f"                const double *cf = {p}_coef + b + 4 * q;",
                      "                vals[q] = cf[0] + sv * (cf[1] + sv * (cf[2] + sv * cf[3])); }",
                      "        } else {",
                      f"            for (q = {e0}; q < {e1}; ++q) vals[q] = fdk_umg(xs[{c}], {p}_ulow[q], "
                      f"{p}_uhigh[q], {p}_ustd[q], {p}_upoint[q], {p}_ulogw[q]);",
                      "        }"]
        lines += self.ll_lines(jmap)
        return "\n".join(lines + self.posterior_tail(out, f"{p}_logp_pi"))

    def to_py(self, arrays):
        return {**super().to_py(arrays), "_warm_from": int(arrays[f"{self.p}_warm_from"][0])}

    def from_py(self, state):
        return {**super().from_py(state), f"{self.p}_warm_from": np.array([state["_warm_from"]])}


for _cls, _em in ((Rav4LateralFilter, Rav4FilterEmitter), (Rav4SensorChannels, Rav4SensorChannelsEmitter),
                  (Rav4PeerSignals, Rav4PeerSignalsEmitter), (Rav4MHSSPT, Rav4MHSSPTEmitter)):
    register_emitter(class_path(_cls), _em)
