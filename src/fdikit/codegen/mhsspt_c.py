"""The MHSSPT as C: the helper functions every MHSSPT emitter shares (the exact uniform-mean
Gaussian log density, log-sum-exp, the log-domain Shiryayev recursion with and without the
normalised posteriors), :class:`MHSSPTCode`, the per-sample code and state they share (the log
posteriors and the sample count, the recursion call, the posterior and group-sum outputs), and the
emitter of the exact MHSSPT (:class:`MHSSPTEmitter`).

The tabulated MHSSPT (:mod:`fdikit.codegen.stages_mhsspt_tab`) and the systems' MHSSPT stages
(the RAV4 monitor's, the fused passenger-car monitor's) build on these; the text is emitted once
per generated file (blocks of equal text are written once)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from .stages import Field, StageEmitter, lit

__all__ = ["MHSSPT_DENSITY_HELPERS", "MHSSPT_HELPERS", "MHSSPT_UPDATE_HELPER", "UPDATE_P_HELPER",
           "MHSSPTCode", "MHSSPTEmitter"]

#: The exact uniform-mean Gaussian log density (``fdk_umg``) and ``fdk_logaddexp`` of
#: :mod:`fdikit.detect.mhsspt` (``kernels.py``), in double precision.
MHSSPT_DENSITY_HELPERS = """
static double fdk_log_ndtr(double x)
{
    double z, s;
    if (x > 0.0) return log1p(-0.5 * erfc(x / sqrt(2.0)));
    if (x > -37.0) return log(0.5 * erfc(-x / sqrt(2.0)));
    z = 1.0 / (x * x);
    s = 1.0 + z * (-1.0 + z * (3.0 + z * (-15.0 + z * (105.0 + z * (-945.0 + z * 10395.0)))));
    return -0.5 * x * x - log(-x) - 0.5 * log(2.0 * FDK_PI) + log(s);
}

static double fdk_umg(double x, double low, double high, double std, int point, double logw)
{
    double u, v, hi, lo, p, lhi, d;
    if (point) {
        double z = (x - low) / std;
        return -0.5 * z * z - log(std) - 0.5 * log(2.0 * FDK_PI);
    }
    u = (x - low) / std;
    v = (x - high) / std;
    if (v > 0.0) { hi = -v; lo = -u; } else { hi = u; lo = v; }
    if (hi > -30.0) {
        p = 0.5 * (erfc(-hi * FDK_INV_SQRT2) - erfc(-lo * FDK_INV_SQRT2));
        if (p > 0.0) return log(p) - logw;
    }
    lhi = fdk_log_ndtr(hi);
    d = fdk_log_ndtr(lo) - lhi;
    if (d > 0.0) d = 0.0;
    return lhi + log1p(-exp(d)) - logw;
}

static double fdk_logaddexp(double a, double b)
{
    double d;
    if (a < b) { d = a; a = b; b = d; }
    if (a == -HUGE_VAL) return -HUGE_VAL;
    d = b - a;
    if (d < -40.0) return a;
    return a + log(1.0 + exp(d));
}

"""

#: The recursion's body up to its normalisation (``fdikit.detect.mhsspt.recursion.mhsspt_update``):
#: the prior mixing in log space, the likelihoods added, ``m`` the largest ``phi``, ``s = 0``.
_RECURSION = """    int j;
    if (logq == -HUGE_VAL) {
        phi[0] = logF[0] + log1mp;
    } else {
        double lse_f = -HUGE_VAL;
        m = -HUGE_VAL;
        for (j = 1; j < H; ++j) if (logF[j] > m) m = logF[j];
        if (m > -HUGE_VAL) {
            double sf = 0.0;
            for (j = 1; j < H; ++j) { x = logF[j] - m; if (x > -40.0) sf += exp(x); }
            lse_f = m + log(sf);
        }
        phi[0] = fdk_logaddexp(logF[0] + log1mp, logq + lse_f);
    }
    lf0 = logF[0];
    for (j = 1; j < H; ++j) phi[j] = fdk_logaddexp(logF[j] + log1mq, lf0 + logp_pi[j]);
    m = -HUGE_VAL;
    for (j = 0; j < H; ++j) { phi[j] += ll[j]; if (phi[j] > m) m = phi[j]; }
    s = 0.0;
"""

#: One step of the log-domain Shiryayev recursion, ``fdk_mhsspt_update`` (the log posteriors).
MHSSPT_UPDATE_HELPER = ("/* one step of the log-domain Shiryayev recursion "
                        "(fdikit.detect.mhsspt.recursion.mhsspt_update) */" """
static void fdk_mhsspt_update(double *logF, const double *ll, double *phi, int H, double log1mp,
                              const double *logp_pi, double logq, double log1mq)
{
    double m, s, x, lz, lf0;
""" + _RECURSION + """    for (j = 0; j < H; ++j) { x = phi[j] - m; if (x > -40.0) s += exp(x); }
    lz = m + log(s);
    for (j = 0; j < H; ++j) logF[j] = phi[j] - lz;
}
""")

#: The densities, log-sum-exp and the recursion step (the exact MHSSPT's helpers).
MHSSPT_HELPERS = MHSSPT_DENSITY_HELPERS + MHSSPT_UPDATE_HELPER

#: The recursion step that also forms the normalised posteriors ``P``, ``fdk_mhsspt_update_p``
#: (``mhsspt_update`` with its ``P`` output, as the fused table kernels use it).
UPDATE_P_HELPER = """
static void fdk_mhsspt_update_p(double *logF, const double *ll, double *phi, double *P, int H,
                                double log1mp, const double *logp_pi, double logq, double log1mq)
{
    double m, s, x, e, lz, lf0;
""" + _RECURSION + """    for (j = 0; j < H; ++j) {
        x = phi[j] - m;
        if (x > -40.0) { e = exp(x); P[j] = e; s += e; } else P[j] = 0.0;
    }
    lz = m + log(s);
    for (j = 0; j < H; ++j) { logF[j] = phi[j] - lz; P[j] = P[j] / s; }
}
"""


class MHSSPTCode(StageEmitter):
    """What the MHSSPT emitters share: the state (the ``H`` log posteriors ``logF``, in double,
    and the sample count ``k``), its reset (the no-fault hypothesis certain), its checkpoint
    mapping (``_logF``, ``_k``), and the per-sample code around the densities: the inputs as
    double refused when not finite, the log likelihoods summed per hypothesis, the recursion call,
    the posterior and group-sum outputs. ``H`` hypotheses, ``C`` features."""

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        self.H, self.C = len(obj.hypotheses), len(obj.input_names)

    def fields(self):
        return [Field(f"{self.p}_logF", "f64", self.H), Field(f"{self.p}_k", "i64", 1)]

    def reset_code(self):
        return "\n".join([f"    {self.f('logF')}[0] = 0.0;",
                          *(f"    {self.f('logF')}[{j}] = -HUGE_VAL;" for j in range(1, self.H)),
                          f"    {self.f('k')}[0] = 0;"])

    def to_py(self, arrays):
        return {"_logF": arrays[f"{self.p}_logF"].astype(float).reshape(1, -1),
                "_k": int(arrays[f"{self.p}_k"][0])}

    def from_py(self, state):
        return {f"{self.p}_logF": np.asarray(state["_logF"], float).reshape(-1),
                f"{self.p}_k": np.array([state["_k"]])}

    def logp_pi_decl(self) -> str:
        """The declaration of the hypotheses' log prior weights ``logp_pi`` inside the step."""
        vals = ", ".join(lit(v) for v in self.obj._logp_pi)
        return f"        static const double logp_pi[{self.H}] = {{{vals}}};"

    def refusal_lines(self) -> list[str]:
        """The refusal of a non-finite feature ``xs[c]``, before the state changes (as the Python
        stage raises)."""
        return [f"        if (!FDK_FINITE(xs[{c}])) return FDK_ERR_STAT;" for c in range(self.C)]

    def input_lines(self, inp: list[str]) -> list[str]:
        """The features as double ``xs``, then :meth:`refusal_lines`."""
        return [f"        xs[{c}] = (double){e};" for c, e in enumerate(inp)] + self.refusal_lines()

    @staticmethod
    def umg_line(dst: str, x: str, low, high, std, point, logw, op: str = "=") -> str:
        """``dst = fdk_umg(x, ...)`` (or another assignment ``op``): one exact uniform-mean
        Gaussian log density of the feature ``x``."""
        return f"{dst} {op} fdk_umg({x}, {lit(low)}, {lit(high)}, {lit(std)}, {int(point)}, {lit(logw)});"

    def ll_lines(self, jmap) -> list[str]:
        """``ll[j]``, each hypothesis' log likelihood: the sum from 0.0 of its features' log
        densities ``vals[jmap[j, c]]`` in feature order."""
        return [f"        ll[{j}] = 0.0" + "".join(f" + vals[{int(jmap[j, c])}]" for c in range(self.C)) + ";"
                for j in range(self.H)]

    def update_call(self, posteriors: bool, logp_pi: str = "logp_pi") -> str:
        """The recursion step on ``ll``: ``fdk_mhsspt_update_p`` (also the normalised posteriors
        into ``P``) or ``fdk_mhsspt_update``."""
        o = self.obj
        fn, p_arg = ("fdk_mhsspt_update_p", "P, ") if posteriors else ("fdk_mhsspt_update", "")
        return (f"        {fn}({self.f('logF')}, ll, phi, {p_arg}{self.H}, {lit(o._log1mp)}, {logp_pi}, "
                f"{lit(o._logq)}, {lit(o._log1mq)});")

    def group_lines(self, src: str, out: list[str]) -> list[str]:
        """The group outputs ``out[H + g]``: the sums from 0.0 of the group's posteriors ``src``."""
        gmat = self.obj._gmat
        terms = ["".join(f" + {src}[{int(e)}]" for e in row if e >= 0) for row in gmat]
        return [f"        {out[self.H + g]} = FDK_R(0.0{t});" for g, t in enumerate(terms)]

    def posterior_tail(self, out: list[str], logp_pi: str = "logp_pi") -> list[str]:
        """The step's end with the normalised posteriors: the recursion call, ``k`` counted, the
        posteriors ``P`` and their group sums as outputs, the block closed."""
        return [self.update_call(True, logp_pi), f"        {self.f('k')}[0] += 1;",
                *(f"        {out[j]} = FDK_R(P[{j}]);" for j in range(self.H)), *self.group_lines("P", out),
                "    }"]


class MHSSPTEmitter(MHSSPTCode):
    """:class:`~fdikit.detect.MHSSPT` with exact :class:`~fdikit.detect.UniformMeanGaussian`
    densities (not tabulated): log densities, the log-domain recursion, the posteriors and group
    sums. Computed in double in both variants (the recursion's logs and exps need it)."""

    kinds = ("MHSSPT",)
    helpers = (MHSSPT_DENSITY_HELPERS, MHSSPT_UPDATE_HELPER)

    def __init__(self, obj, prefix):
        if obj.tabulate is not None or obj._umg is None:
            raise DataError("stage MHSSPT (tabulated densities) cannot be generated yet; the exact "
                            "densities (tabulate=None) can")
        super().__init__(obj, prefix)
        from ..detect.mhsspt.kernels import _shared_components

        self.sh = _shared_components(*obj._umg)

    def step_code(self, inp, out):
        ulow, uhigh, ustd, upoint, ulogw, uoff, jmap = self.sh
        H = self.H
        lines = ["    {", f"        double xs[{self.C}], vals[{len(ulow)}], ll[{H}], phi[{H}];",
                 self.logp_pi_decl(), *self.input_lines(inp)]
        for c in range(self.C):
            lines += [self.umg_line(f"        vals[{e}]", f"xs[{c}]", ulow[e], uhigh[e], ustd[e], upoint[e],
                                    ulogw[e]) for e in range(uoff[c], uoff[c + 1])]
        lines += self.ll_lines(jmap)
        lines += [self.update_call(False), f"        {self.f('k')}[0] += 1;"]
        for j in range(H):
            v = f"{self.f('logF')}[{j}]"
            lines.append(f"        phi[{j}] = ({v} > -746.0) ? exp({v}) : 0.0;")
            lines.append(f"        {out[j]} = FDK_R(phi[{j}]);")
        lines += [*self.group_lines("phi", out), "    }"]
        return "\n".join(lines)
