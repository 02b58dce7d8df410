"""The C emitter of :class:`~fdikit.isolate.FaultTypeClassifier`: the per-sample loop of its
compiled kernel (``_run_kernel``, with ``_accumulate``, ``_classify``, ``_gain_test_blocks`` and
``_block_episodes``) in the same order of floating-point operations, over fixed-size rings of block
aggregates; registered in
:mod:`.registry` when :mod:`fdikit.codegen` is imported.

The classifier decides on the sensor's block sums in double precision in both variants (its types
are decisions on sums of thousands of samples; the float32 variant's inputs are widened)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .registry import class_path, register_emitter
from .stages import Field, StageEmitter, lit, refuse_nonfinite

__all__ = ["FTC_HELPERS", "FaultTypeEmitter"]

#: ``_accumulate``, ``_block_episodes``, ``_gain_test_blocks`` and ``_classify`` of
#: :mod:`fdikit.isolate.fault_type` over a member's ring of block aggregates (slot ``b % NR``).
#: ``max(a, b)`` is Python's (``b > a ? b : a``), as the compiled kernel has it.
FTC_HELPERS = """
/* _accumulate: sample i of a block into its aggregates bs[5] (sums of r, i r, x, x r, x^2) and be[5]
   (first and last index out, below release before the first and after the last, episodes after the first) */
static void fdk_ftc_accumulate(double *bs, int64_t *be, int64_t i, double r, double x, double st,
                               double release, int64_t burst_gap)
{
    if (i == 0) {
        bs[0] = 0.0; bs[1] = 0.0; bs[2] = 0.0; bs[3] = 0.0; bs[4] = 0.0;
        be[0] = -1; be[1] = -1; be[2] = 0; be[3] = 0; be[4] = 0;
    }
    bs[0] += r;
    bs[1] += (double)i * r;
    bs[2] += x;
    bs[3] += x * r;
    bs[4] += x * x;
    if (st >= 1.0) {
        if (be[0] < 0) be[0] = i;
        else if (be[3] >= burst_gap) be[4] += 1;
        be[1] = i;
        be[3] = 0;
    } else if (st < release) {
        if (be[0] < 0) be[2] += 1;
        else be[3] += 1;
    }
}

static int64_t fdk_ftc_block_episodes(const double *bs, int64_t b0, int64_t nb, int64_t NR, double ib,
                                      double sig_blk, int64_t gap)
{
    int64_t m, s = b0 % NR, n_ep = 0, below = 0;
    int seen = 0;
    for (m = 0; m < nb; ++m) {
        double z;
        if (m > 0) s = s < NR - 1 ? s + 1 : 0;
        z = fabs(bs[s * 5] * ib) / sig_blk;
        if (z >= 5.0) {
            if (!seen || below >= gap) n_ep += 1;
            seen = 1; below = 0;
        } else if (z < 2.0) {
            below += 1;
        }
    }
    if (n_ep == 2 && below < gap) n_ep = 1;   /* the second burst has not ended: a step after a blip */
    return n_ep;
}

/* _gain_test_blocks over blocks b0 .. b0 + nb - 1: (F_b, F_g, by_time) */
static void fdk_ftc_gain_test(const double *bs, int64_t b0, int64_t nb, int64_t NR, double ib, double sig_blk,
                              double r0, double *fb, double *fg, int *by_time)
{
    int64_t m, s;
    double mr = 0.0, mx = 0.0, mt, sxx = 0.0, sxy = 0.0, syy = 0.0, stt = 0.0, sty = 0.0, sx0 = 0.0;
    double sxy0 = 0.0, rss, rss_t, s2, q;
    *fb = 0.0; *fg = 0.0; *by_time = 0;
    if (nb < 4) return;
    s = b0 % NR;
    for (m = 0; m < nb; ++m) {
        if (m > 0) s = s < NR - 1 ? s + 1 : 0;
        mr += bs[s * 5] * ib;
        mx += bs[s * 5 + 2] * ib;
    }
    mr = mr / (double)nb;
    mx = mx / (double)nb;
    mt = 0.5 * (double)(nb - 1);
    s = b0 % NR;
    for (m = 0; m < nb; ++m) {
        double rm, xm, dx, dy, dt;
        if (m > 0) s = s < NR - 1 ? s + 1 : 0;
        rm = bs[s * 5] * ib;
        xm = bs[s * 5 + 2] * ib;
        dx = xm - mx; dy = rm - mr; dt = (double)m - mt;
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
        stt += dt * dt;
        sty += dt * dy;
        sx0 += xm * xm;
        sxy0 += xm * (rm - r0);
    }
    if (sxx <= 0.0 || sx0 <= 0.0) return;
    rss = syy - sxy * sxy / sxx;
    if (0.0 > rss) rss = 0.0;
    rss_t = syy - sty * sty / stt;
    if (0.0 > rss_t) rss_t = 0.0;
    s2 = sig_blk * sig_blk;
    q = rss / (double)(nb - 2);
    if (q > s2) s2 = q;
    *fb = (syy - rss) / s2;
    q = syy + (double)nb * (mr - r0) * (mr - r0) - sxy0 * sxy0 / sx0 - rss;
    if (0.0 > q) q = 0.0;
    *fg = q / s2;
    *by_time = rss_t < rss;
}

/* _classify over the window's blocks b0 .. b0 + nb - 1 (ring slot b % NR of bs[NR * 5], be[NR * 5]) */
static void fdk_ftc_classify(const double *bs, const int64_t *be, int64_t b0, int64_t nb, int64_t NR,
                             int64_t B, double sigma, int64_t min_len, double prefer, int64_t burst_gap,
                             int64_t spike_max, double sig_blk, double gain_crit, int64_t *typ, double *conf)
{
    double sr = 0.0, sar = 0.0, sbv = -HUGE_VAL, sd = -HUGE_VAL;
    double S0 = 0.0, S1 = 0.0, e0, e1, smax, esum, fb, fg, dg, c, q;
    int64_t qq, m, s, L, Lb = 0, first = -1, last = -1, n_ep = 0, below = 0, g;
    int by_time;
    double ib, r0;
    s = (b0 + nb - 1) % NR;
    for (qq = 0; qq < nb; ++qq) {
        double s_tr, stt;
        if (qq > 0) s = s > 0 ? s - 1 : NR - 1;
        sr += bs[s * 5];
        sar += (double)(qq * B + B - 1) * bs[s * 5] - bs[s * 5 + 1];
        L = (qq + 1) * B;
        if (L < min_len) continue;
        s_tr = (double)L * sr - sar;
        stt = (double)(L * (L + 1) * (2 * L + 1)) / 6.0;
        if (sr * sr / (double)L > sbv) { sbv = sr * sr / (double)L; Lb = qq + 1; }
        q = s_tr * s_tr / stt;
        if (q > sd) sd = q;
    }
    if (nb * B >= min_len) {
        double s2 = sigma * sigma;
        S0 = sbv / s2; S1 = sd / s2;
    }
    smax = S1 > S0 ? S1 : S0;
    e0 = exp(0.5 * (S0 - smax));
    e1 = exp(0.5 * (S1 - smax));
    esum = e0 + e1;
    g = Lb - 1 > 0 ? Lb - 1 : 0;
    ib = 1.0 / (double)B;
    r0 = 0.0;
    L = b0 + nb - (NR - 1) > 0 ? b0 + nb - (NR - 1) : 0;   /* the ring's oldest block */
    if (b0 - L >= 4) {
        s = L % NR;
        for (m = 0; m < b0 - L; ++m) {
            if (m > 0) s = s < NR - 1 ? s + 1 : 0;
            r0 += bs[s * 5];
        }
        r0 = r0 * ib / (double)(b0 - L);
    }
    fdk_ftc_gain_test(bs, b0 + nb - g, g, NR, ib, sig_blk, r0, &fb, &fg, &by_time);
    if (by_time && S1 > S0 + prefer) fb = 0.0;
    if (fb >= gain_crit) { *typ = 2; *conf = 1.0 / (1.0 + exp(-0.5 * (fb - gain_crit))); return; }
    dg = fb - fg;   /* a gain through the fault-free level against a step, both one parameter */
    if (fg < gain_crit && dg >= prefer && !by_time) {
        *typ = 2; *conf = 1.0 / (1.0 + exp(-0.5 * (dg - prefer))); return;
    }
    s = b0 % NR;
    for (m = 0; m < nb; ++m) {
        const int64_t *e;
        if (m > 0) s = s < NR - 1 ? s + 1 : 0;
        e = be + s * 5;
        below += e[2];
        if (e[0] >= 0) {
            if (first < 0) { first = m * B + e[0]; n_ep = 1; }
            else if (below >= burst_gap) n_ep += 1;
            n_ep += e[4];
            last = m * B + e[1];
            below = e[3];
        }
    }
    if (n_ep < 2) {
        g = fdk_ftc_block_episodes(bs, b0, nb, NR, ib, sig_blk, burst_gap / B > 1 ? burst_gap / B : 1);
        if (g > n_ep) n_ep = g;
    }
    if (n_ep >= 2) { *typ = 4; *conf = 1.0 - ldexp(1.0, (int)-(n_ep - 1)); return; }
    if (first >= 0 && last - first < spike_max && below >= burst_gap) {
        q = (double)below / (2.0 * (double)burst_gap);
        *typ = 5; *conf = q < 1.0 ? q : 1.0;
        return;
    }
    if (S1 > S0 + prefer) { *typ = 1; *conf = e1 / esum; return; }
    c = e0 / esum;
    if (fg < gain_crit) c = 0.5 < c ? 0.5 : c;
    *typ = 0; *conf = c;
}

/* _revise: the announced type's hysteresis (type, conf, cand, cnt, left updated from nt, nc) */
static void fdk_ftc_revise(int64_t *typ, double *conf, int64_t *cand, int64_t *cnt, int64_t *left, int64_t nt,
                           double nc, int64_t after, double min_conf)
{
    int64_t need;
    if (after <= 0 || *cnt < 0 || nt == *typ) {
        *typ = nt; *conf = nc; *cand = -1; *cnt = 0; return;
    }
    *cnt += 1;
    if (*typ == 1 && nt == 0) { *cand = nt; return; }
    if (nt == 3) {
        *left |= ((int64_t)1) << *typ; *typ = nt; *conf = nc; *cand = -1; *cnt = 0; return;
    }
    need = ((*left >> nt) & 1) ? 3 * after : after;
    if (*cnt >= need && (nc >= min_conf || nt >= 4)) {
        *left |= ((int64_t)1) << *typ; *typ = nt; *conf = nc; *cand = -1; *cnt = 0; return;
    }
    *cand = nt;
}
"""


class FaultTypeEmitter(StageEmitter):
    """:class:`~fdikit.isolate.FaultTypeClassifier`: per member a ring of ``n_blocks + 1`` block
    aggregates (five sums and five episode counts each), the stuck counters, the active fault's
    onset, type, confidence, clear count and latest decision; started again on resume."""

    kinds = ("FaultTypeClassifier",)
    handles_resume = True
    helpers = FTC_HELPERS

    _I64 = ("active", "onset", "type", "below", "zero", "cand", "cnt", "left", "dtype")
    _F64 = ("conf", "last", "dconf")

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        self.M, self.NB = len(obj.members), int(obj.n_blocks)
        self.NR = self.NB + 1

    def fields(self):
        n, M = self.M * self.NR * 5, self.M
        return ([Field(f"{self.p}_bs", "f64", n), Field(f"{self.p}_be", "i64", n),
                 Field(f"{self.p}_k", "i64", 1)]
                + [Field(f"{self.p}_{v}", "i64", M) for v in self._I64]
                + [Field(f"{self.p}_{v}", "f64", M) for v in self._F64])

    def reset_code(self):
        f, n, M = self.f, self.M * self.NR * 5, self.M
        return (f"    {{ int i; for (i = 0; i < {n}; ++i) {{ {f('bs')}[i] = 0.0; {f('be')}[i] = 0; }}\n"
                f"      for (i = 0; i < {M}; ++i) {{ {f('active')}[i] = 0; {f('onset')}[i] = 0; "
                f"{f('type')}[i] = 0; {f('below')}[i] = 0;\n"
                f"          {f('cand')}[i] = 0; {f('cnt')}[i] = 0; {f('left')}[i] = 0; {f('dtype')}[i] = 0;\n"
                f"          {f('zero')}[i] = 0; {f('conf')}[i] = 0.0; {f('last')}[i] = NAN; "
                f"{f('dconf')}[i] = 0.0; }}\n"
                f"      {f('k')}[0] = 0; }}")

    def resume_code(self):
        return "    " + self.reset_code().replace("\n", "\n    ")

    def step_code(self, inp, out):
        o, M, f = self.obj, self.M, self.f
        NB, NR, B = self.NB, self.NR, int(o.block)
        n_in, lb = len(inp), int(o.lookback)
        K = o._ixx.shape[1]
        ix = ", ".join(str(int(v)) for v in o._ix.reshape(-1))
        ixx = ", ".join(str(int(v)) for v in o._ixx.reshape(-1)) or "0"
        arr = lambda xs, fmt=str: ", ".join(fmt(x) for x in xs)  # noqa: E731
        lines = ["    {",
                 f"        static const int IX[{4 * M}] = {{{ix}}};",
                 f"        static const int IXX[{max(M * K, 1)}] = {{{ixx}}};",
                 f"        static const int IRAW[{M}] = {{{arr(o._iraw)}}};",
                 f"        static const int IOFF[{M}] = {{{arr(o._ioff)}}};",
                 f"        static const int64_t STUCK[{M}] = {{{arr(o._stuck)}}};",
                 f"        static const double SIGMA[{M}] = {{{arr(o._sigma, lit)}}};",
                 f"        static const double SIGBLK[{M}] = {{{arr(o._sig_blk, lit)}}};",
                 f"        static const double GAINC[{M}] = {{{arr(o._gain_crit, lit)}}};",
                 f"        double v[{n_in}], stat;",
                 "        int64_t i, slot, done, j, c, k;",
                 "        int is_stuck, iso, decide;"]
        lines += [f"        v[{i}] = (double){e};" for i, e in enumerate(inp)]
        lines += [refuse_nonfinite("v", n_in, "j", "isfinite"),
                  f"        k = {f('k')}[0];",
                  f"        i = k % {B};",
                  f"        slot = (k / {B}) % {NR};",
                  f"        for (j = 0; j < {M}; ++j) {{",
                  "            double x = v[IX[4 * j + 3]];",
                  "            if (IOFF[j] >= 0) x = x + v[IOFF[j]];",
                  f"            fdk_ftc_accumulate({f('bs')} + (j * {NR} + slot) * 5, "
                  f"{f('be')} + (j * {NR} + slot) * 5, i, v[IX[4 * j + 2]],",
                  f"                               x, v[IX[4 * j + 1]], {lit(o.release)}, "
                  f"{int(o.burst_gap)});",
                  "            if (IRAW[j] >= 0) {",
                  "                double raw = v[IRAW[j]];",
                  f"                {f('zero')}[j] = raw == {f('last')}[j] ? {f('zero')}[j] + 1 : 0;",
                  f"                {f('last')}[j] = raw;", "            }", "        }",
                  "        k += 1;", f"        {f('k')}[0] = k;",
                  f"        done = k / {B};",
                  f"        for (j = 0; j < {M}; ++j) {{",
                  "            stat = v[IX[4 * j + 1]];",
                  f"            is_stuck = STUCK[j] > 0 && {f('zero')}[j] >= STUCK[j];",
                  "            iso = v[IX[4 * j]] >= 1.0;",
                  f"            for (c = 0; c < {K}; ++c)",
                  f"                if (IXX[j * {max(K, 1)} + c] >= 0 && v[IXX[j * {max(K, 1)} + c]] >= 1.0 "
                  f"&& v[IX[4 * j + 1]] >= {lit(o.confirm)}) iso = 1;",
                  f"            decide = {f('active')}[j] && i == {B - 1};",
                  f"            if (!{f('active')}[j] && (iso || is_stuck)) {{",
                  f"                {f('onset')}[j] = k - 1 - {lb} > 0 ? k - 1 - {lb} : 0;",
                  f"                {f('active')}[j] = 1;",
                  f"                {f('cand')}[j] = -1; {f('cnt')}[j] = -1; {f('left')}[j] = 0;",
                  "                decide = 1;",
                  "            }",
                  f"            if ({f('active')}[j] && stat < {lit(o.release)} && !is_stuck"
                  f"{' && !iso' if o.hold_while_isolated else ''})",
                  f"                {f('below')}[j] += 1;",
                  f"            else {f('below')}[j] = 0;",
                  f"            if ({f('below')}[j] >= {int(o.clear_after)}) {f('active')}[j] = 0;",
                  f"            if ({f('active')}[j]) {{",
                  "                int64_t nt; double nc;",
                  "                if (decide) {",
                  f"                    int64_t b0 = {f('onset')}[j] / {B} >= done - {NB} ? "
                  f"{f('onset')}[j] / {B} : done - {NB};",
                  f"                    fdk_ftc_classify({f('bs')} + j * {NR * 5}, {f('be')} + j * {NR * 5}, "
                  f"b0, done - b0, {NR}, {B},",
                  f"                                     SIGMA[j], {int(o.min_len)}, {lit(o.prefer)}, "
                  f"{int(o.burst_gap)}, {int(o.spike_max)}, SIGBLK[j],",
                  f"                                     GAINC[j], &{f('dtype')}[j], &{f('dconf')}[j]);",
                  "                }",
                  "                if (is_stuck) {",
                  f"                    double z = (double){f('zero')}[j];",
                  "                    nt = 3; nc = z / (z + (double)STUCK[j]);",
                  "                } else {",
                  f"                    nt = {f('dtype')}[j]; nc = {f('dconf')}[j];",
                  "                }",
                  f"                fdk_ftc_revise(&{f('type')}[j], &{f('conf')}[j], &{f('cand')}[j], "
                  f"&{f('cnt')}[j], &{f('left')}[j], nt, nc,",
                  f"                               {int(o.revise_after)}, {lit(o.revise_conf)});",
                  "            }", "        }"]
        nt = 6
        for j in range(M):
            a = f"{f('active')}[{j}]"
            lines += [f"        {out[j * nt + i]} = ({a} && {f('type')}[{j}] == {i}) ? FDK_R(1.0) : "
                      "FDK_R(0.0);"
                      for i in range(nt)]
            lines += [f"        {out[M * nt + j]} = {a} ? (fdk_real){f('conf')}[{j}] : FDK_R(0.0);",
                      f"        {out[M * nt + M + j]} = {a} ? FDK_R(1.0) : FDK_R(0.0);"]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        M, NR = self.M, self.NR
        a = {n: arrays[f"{self.p}_{n}"] for n in ("bs", "be", "k", *self._I64, *self._F64)}
        st = {"_bs": a["bs"].astype(float).reshape(1, M, NR, 5),
              "_be": a["be"].astype(np.int64).reshape(1, M, NR, 5), "_k": int(a["k"][0]),
              "_active": a["active"].astype(bool).reshape(1, M)}
        st |= {f"_{n}": a[n].astype(np.int64).reshape(1, M) for n in self._I64 if n != "active"}
        st |= {f"_{n}": a[n].astype(float).reshape(1, M) for n in self._F64}
        return st

    def from_py(self, state):
        real = ("bs", *self._F64)
        out = {f"{self.p}_{n}": np.ravel(state[f"_{n}"]).astype(float if n in real else np.int64)
               for n in ("bs", "be", *self._I64, *self._F64)}
        return out | {f"{self.p}_k": np.array([state["_k"]])}


def _register() -> None:
    from ..isolate import FaultTypeClassifier

    register_emitter(class_path(FaultTypeClassifier), FaultTypeEmitter)


_register()
