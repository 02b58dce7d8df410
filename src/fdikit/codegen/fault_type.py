"""The C emitter of :class:`~fdikit.isolate.FaultTypeClassifier`: the per-sample loop of its
compiled kernel (``_run_kernel``, with ``_classify``, ``_gain_test`` and ``_block_episodes``) in the
same order of floating-point operations, over fixed-size ring buffers of the window; registered in
:mod:`.registry` when :mod:`fdikit.codegen` is imported.

The classifier decides on the sensor's window in double precision in both variants (its types
are decisions on sums of thousands of samples; the float32 variant's inputs are widened)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .registry import class_path, register_emitter
from .stages import Field, StageEmitter, lit

__all__ = ["FTC_HELPERS", "FaultTypeEmitter"]

#: ``_block_episodes``, ``_gain_test`` and ``_classify`` of :mod:`fdikit.isolate.fault_type` over a
#: window of ``n`` samples held in ring buffers (``s0`` the oldest sample's slot, ``W`` the size).
#: ``max(a, b)`` is Python's (``b > a ? b : a``), as the compiled kernel has it.
FTC_HELPERS = """
#define FDK_FTC_AT(b, i) ((b)[(s0 + (i)) < W ? s0 + (i) : s0 + (i) - W])

static int64_t fdk_ftc_block_episodes(const double *rb, int64_t s0, int64_t W, int64_t n, int64_t block,
                                      double sig_blk, int64_t gap)
{
    int64_t nb = n / block, off = n - nb * block, b, i, n_ep = 0, below = 0;
    int seen = 0;
    for (b = 0; b < nb; ++b) {
        double m = 0.0, z;
        for (i = 0; i < block; ++i) m += FDK_FTC_AT(rb, off + b * block + i);
        z = fabs(m / (double)block) / sig_blk;
        if (z >= 5.0) {
            if (!seen || below >= gap) n_ep += 1;
            seen = 1; below = 0;
        } else if (z < 2.0) {
            below += 1;
        }
    }
    return n_ep;
}

/* the gain test on the newest len samples of the window: (F_b, F_g, by_time); rm, xm scratch */
static void fdk_ftc_gain_test(const double *rb, const double *xb, int64_t s0, int64_t W, int64_t n,
                              int64_t len, int64_t block, double sig_blk, double *rm, double *xm,
                              double *fb, double *fg, int *by_time)
{
    int64_t nb = len / block, off, b, i;
    double mr, mx, mt, sxx = 0.0, sxy = 0.0, syy = 0.0, stt = 0.0, sty = 0.0, sx0 = 0.0, sxy0 = 0.0;
    double rss, rss_t, s2, q;
    *fb = 0.0; *fg = 0.0; *by_time = 0;
    if (nb < 4) return;
    off = (n - len) + (len - nb * block);
    for (b = 0; b < nb; ++b) {
        rm[b] = 0.0; xm[b] = 0.0;
        for (i = 0; i < block; ++i) {
            rm[b] += FDK_FTC_AT(rb, off + b * block + i);
            xm[b] += FDK_FTC_AT(xb, off + b * block + i);
        }
        rm[b] /= (double)block;
        xm[b] /= (double)block;
    }
    mr = 0.0; mx = 0.0;
    for (b = 0; b < nb; ++b) mr += rm[b];
    mr = mr / (double)nb;
    for (b = 0; b < nb; ++b) mx += xm[b];
    mx = mx / (double)nb;
    mt = 0.5 * (double)(nb - 1);
    for (b = 0; b < nb; ++b) {
        double dx = xm[b] - mx, dy = rm[b] - mr, dt = (double)b - mt;
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
        stt += dt * dt;
        sty += dt * dy;
        sx0 += xm[b] * xm[b];
        sxy0 += xm[b] * rm[b];
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
    q = syy + (double)nb * mr * mr - sxy0 * sxy0 / sx0 - rss;
    if (0.0 > q) q = 0.0;
    *fg = q / s2;
    *by_time = rss_t < rss;
}

static void fdk_ftc_classify(const double *rb, const double *xb, const double *sb, int64_t s0, int64_t W,
                             int64_t n, double sigma, int64_t min_len, double prefer, double release,
                             int64_t burst_gap, int64_t spike_max, int64_t block, double sig_blk,
                             double gain_crit, double *rm, double *xm, int64_t *typ, double *conf)
{
    double sr = 0.0, sar = 0.0, sxr = 0.0, sxx = 0.0, sbv = -HUGE_VAL, sd = -HUGE_VAL, sg = -HUGE_VAL;
    double S[3], e[3], smax, esum, fb, fg, c, q;
    int64_t L, i, Lb = 0, first = -1, last = -1, n_ep = 0, below = 0, best, g;
    int by_time;
    for (L = 1; L <= n; ++L) {
        double r, x, s_tr, stt;
        i = n - L;
        r = FDK_FTC_AT(rb, i);
        x = FDK_FTC_AT(xb, i);
        sr += r;
        sar += (double)(L - 1) * r;
        sxr += x * r;
        sxx += x * x;
        if (L < min_len) continue;
        s_tr = (double)L * sr - sar;
        stt = (double)(L * (L + 1) * (2 * L + 1)) / 6.0;
        if (sr * sr / (double)L > sbv) { sbv = sr * sr / (double)L; Lb = L; }
        q = s_tr * s_tr / stt;
        if (q > sd) sd = q;
        q = sxx > 0 ? sxr * sxr / sxx : 0.0;
        if (q > sg) sg = q;
    }
    S[0] = S[1] = S[2] = 0.0;
    if (n >= min_len) {
        double s2 = sigma * sigma;
        S[0] = sbv / s2; S[1] = sd / s2; S[2] = sg / s2;
    }
    smax = S[2] > S[1] ? S[2] : S[1];
    smax = smax > S[0] ? smax : S[0];
    for (i = 0; i < 3; ++i) e[i] = exp(0.5 * (S[i] - smax));
    esum = e[0] + e[1] + e[2];
    fdk_ftc_gain_test(rb, xb, s0, W, n, Lb, block, sig_blk, rm, xm, &fb, &fg, &by_time);
    if (by_time && S[1] > S[0] + prefer) fb = 0.0;
    if (fb >= gain_crit) { *typ = 2; *conf = 1.0 / (1.0 + exp(-0.5 * (fb - gain_crit))); return; }
    for (i = 0; i < n; ++i) {
        double st = FDK_FTC_AT(sb, i);
        if (st >= 1.0) {
            if (first < 0) { first = i; n_ep = 1; }
            else if (below >= burst_gap) n_ep += 1;
            last = i;
            below = 0;
        } else if (st < release) {
            below += 1;
        }
    }
    if (n_ep < 2) {
        g = fdk_ftc_block_episodes(rb, s0, W, n, block, sig_blk,
                                   burst_gap / block > 1 ? burst_gap / block : 1);
        if (g > n_ep) n_ep = g;
    }
    if (n_ep >= 2) { *typ = 4; *conf = 1.0 - ldexp(1.0, (int)-(n_ep - 1)); return; }
    if (first >= 0 && last - first < spike_max && below >= burst_gap) {
        q = (double)below / (2.0 * (double)burst_gap);
        *typ = 5; *conf = q < 1.0 ? q : 1.0;
        return;
    }
    best = S[1] > S[0] + prefer ? 1 : 0;
    c = e[best] / esum;
    if (best == 0 && fg < gain_crit) c = 0.5 < c ? 0.5 : c;
    *typ = best; *conf = c;
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
    """:class:`~fdikit.isolate.FaultTypeClassifier`: the window's residual, signal and normalised
    residual in ring buffers (``window`` samples per member), the stuck counters, the active fault's
    onset, type, confidence and clear count; started again on resume."""

    kinds = ("FaultTypeClassifier",)
    handles_resume = True
    helpers = FTC_HELPERS

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        self.M, self.W = len(obj.members), int(obj.window)
        self.nbmax = max(self.W // int(obj.block), 1)

    def fields(self):
        MW, M = self.M * self.W, self.M
        return ([Field(f"{self.p}_{n}", "f64", MW) for n in ("rb", "xb", "sb")]
                + [Field(f"{self.p}_k", "i64", 1)]
                + [Field(f"{self.p}_{n}", "i64", M) for n in ("active", "onset", "type", "below", "zero",
                                                                  "cand", "cnt", "left")]
                + [Field(f"{self.p}_{n}", "f64", M) for n in ("conf", "last")])

    def reset_code(self):
        f, MW, M = self.f, self.M * self.W, self.M
        return (f"    {{ int i; for (i = 0; i < {MW}; ++i) {{ {f('rb')}[i] = 0.0; {f('xb')}[i] = 0.0; "
                f"{f('sb')}[i] = 0.0; }}\n"
                f"      for (i = 0; i < {M}; ++i) {{ {f('active')}[i] = 0; {f('onset')}[i] = 0; "
                f"{f('type')}[i] = 0; {f('below')}[i] = 0;\n"
                f"          {f('cand')}[i] = 0; {f('cnt')}[i] = 0; {f('left')}[i] = 0;\n"
                f"          {f('zero')}[i] = 0; {f('conf')}[i] = 0.0; {f('last')}[i] = NAN; }}\n"
                f"      {f('k')}[0] = 0; }}")

    def resume_code(self):
        return "    " + self.reset_code().replace("\n", "\n    ")

    def step_code(self, inp, out):
        o, M, W, f = self.obj, self.M, self.W, self.f
        n_in, lb = len(inp), int(o.lookback)
        K = o._ixx.shape[1]
        ix = ", ".join(str(int(v)) for v in o._ix.reshape(-1))
        ixx = ", ".join(str(int(v)) for v in o._ixx.reshape(-1)) or "0"
        arr = lambda xs, fmt=str: ", ".join(fmt(x) for x in xs)  # noqa: E731
        lines = ["    {",
                 f"        static const int IX[{4 * M}] = {{{ix}}};",
                 f"        static const int IXX[{max(M * K, 1)}] = {{{ixx}}};",
                 f"        static const int IRAW[{M}] = {{{arr(o._iraw)}}};",
                 f"        static const int64_t STUCK[{M}] = {{{arr(o._stuck)}}};",
                 f"        static const double SIGMA[{M}] = {{{arr(o._sigma, lit)}}};",
                 f"        static const double SIGBLK[{M}] = {{{arr(o._sig_blk, lit)}}};",
                 f"        static const double GAINC[{M}] = {{{arr(o._gain_crit, lit)}}};",
                 f"        double v[{n_in}], rm[{self.nbmax}], xm[{self.nbmax}], stat;",
                 "        int64_t p, j, c, k;",
                 "        int is_stuck, iso;"]
        lines += [f"        v[{i}] = (double){e};" for i, e in enumerate(inp)]
        lines += [f"        for (j = 0; j < {n_in}; ++j) if (!isfinite(v[j])) return FDK_ERR_STAT;",
                  f"        k = {f('k')}[0];",
                  f"        p = k % {W};",
                  f"        for (j = 0; j < {M}; ++j) {{",
                  f"            {f('rb')}[j * {W} + p] = v[IX[4 * j + 2]];",
                  f"            {f('xb')}[j * {W} + p] = v[IX[4 * j + 3]];",
                  f"            {f('sb')}[j * {W} + p] = v[IX[4 * j + 1]];",
                  "            if (IRAW[j] >= 0) {",
                  "                double raw = v[IRAW[j]];",
                  f"                {f('zero')}[j] = raw == {f('last')}[j] ? {f('zero')}[j] + 1 : 0;",
                  f"                {f('last')}[j] = raw;", "            }", "        }",
                  "        k += 1;", f"        {f('k')}[0] = k;",
                  f"        for (j = 0; j < {M}; ++j) {{",
                  "            stat = v[IX[4 * j + 1]];",
                  f"            is_stuck = STUCK[j] > 0 && {f('zero')}[j] >= STUCK[j];",
                  "            iso = v[IX[4 * j]] >= 1.0;",
                  f"            for (c = 0; c < {K}; ++c)",
                  f"                if (IXX[j * {max(K, 1)} + c] >= 0 && v[IXX[j * {max(K, 1)} + c]] >= 1.0 "
                  f"&& v[IX[4 * j + 1]] >= {lit(o.confirm)}) iso = 1;",
                  f"            if (!{f('active')}[j] && (iso || is_stuck)) {{",
                  f"                {f('onset')}[j] = k - 1 - {lb} > 0 ? k - 1 - {lb} : 0;",
                  f"                {f('active')}[j] = 1;",
                  f"                {f('cand')}[j] = -1; {f('cnt')}[j] = -1; {f('left')}[j] = 0;",
                  "            }",
                  f"            if ({f('active')}[j] && stat < {lit(o.release)} && !is_stuck"
                  f"{' && !iso' if o.hold_while_isolated else ''})",
                  f"                {f('below')}[j] += 1;",
                  f"            else {f('below')}[j] = 0;",
                  f"            if ({f('below')}[j] >= {int(o.clear_after)}) {f('active')}[j] = 0;",
                  f"            if ({f('active')}[j]) {{",
                  "                int64_t nt; double nc;",
                  "                if (is_stuck) {",
                  f"                    double z = (double){f('zero')}[j];",
                  "                    nt = 3; nc = z / (z + (double)STUCK[j]);",
                  "                } else {",
                  f"                    int64_t n = k - {f('onset')}[j] < {W} ? k - {f('onset')}[j] : {W};",
                  f"                    int64_t k0 = {f('onset')}[j] > k - {W} ? {f('onset')}[j] : k - {W};",
                  f"                    fdk_ftc_classify({f('rb')} + j * {W}, {f('xb')} + j * {W}, "
                  f"{f('sb')} + j * {W}, k0 % {W}, {W}, n,",
                  f"                                     SIGMA[j], {int(o.min_len)}, {lit(o.prefer)}, "
                  f"{lit(o.release)}, {int(o.burst_gap)}, {int(o.spike_max)},",
                  f"                                     {int(o.block)}, SIGBLK[j], GAINC[j], rm, xm, "
                  "&nt, &nc);",
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
        M, W = self.M, self.W
        a = {n: arrays[f"{self.p}_{n}"] for n in ("rb", "xb", "sb", "k", "active", "onset", "type", "conf",
                                                  "below", "zero", "last", "cand", "cnt", "left")}
        return {"_rb": a["rb"].astype(float).reshape(1, M, W), "_xb": a["xb"].astype(float).reshape(1, M, W),
                "_sb": a["sb"].astype(float).reshape(1, M, W), "_k": int(a["k"][0]),
                "_active": a["active"].astype(bool).reshape(1, M),
                "_onset": a["onset"].astype(np.int64).reshape(1, M),
                "_type": a["type"].astype(np.int64).reshape(1, M),
                "_conf": a["conf"].astype(float).reshape(1, M),
                "_below": a["below"].astype(np.int64).reshape(1, M),
                "_zero": a["zero"].astype(np.int64).reshape(1, M),
                "_last": a["last"].astype(float).reshape(1, M),
                **{f"_{n}": a[n].astype(np.int64).reshape(1, M) for n in ("cand", "cnt", "left")}}

    def from_py(self, state):
        real = ("rb", "xb", "sb", "conf", "last")
        out = {f"{self.p}_{n}": np.ravel(state[f"_{n}"]).astype(float if n in real else np.int64)
               for n in ("rb", "xb", "sb", "active", "onset", "type", "conf", "below", "zero", "last",
                         "cand", "cnt", "left")}
        return out | {f"{self.p}_k": np.array([state["_k"]])}


def _register() -> None:
    from ..isolate import FaultTypeClassifier

    register_emitter(class_path(FaultTypeClassifier), FaultTypeEmitter)


_register()
