"""The C emitter of the directional GLRT (:class:`~fdikit.detect.DirectionalGLRT`): a change of
unknown amplitude along a known signature, anchored or over a moving window, with or without
nuisance signatures (the Cholesky solve of the decoupled form), in the compiled kernels' order
of floating-point operations (``fdikit.detect.directional``)."""

from __future__ import annotations

import numpy as np

from .registry import register_emitter
from .stages import Field, StageEmitter, lit

__all__ = ["DirectionalGLRTEmitter"]

#: One signature (``_dglrt_batch``): running or windowed prefix sums of a and b.
DGLRT1_HELPER = """
static void fdk_dglrt1(double *Ar, double *Br, int64_t *pos, int64_t *counts, const double *r,
                       const double *s, const double *mu0, const double *w, int C, int W,
                       double min_info, double *g, double *eta_out)
{
    double a = 0.0, b = 0.0, sc, best, eta, dA, dB, v, baseA, baseB;
    int64_t p = pos[0], count = counts[0], L, i, top = 2 * (int64_t)W;
    int c;
    for (c = 0; c < C; ++c) { sc = s[c]; a += sc * (r[c] - mu0[c]) * w[c]; b += sc * sc * w[c]; }
    if (W == 0) {
        Ar[0] += a; Br[0] += b;
        if (Br[0] > min_info) { *g = 0.5 * Ar[0] * Ar[0] / Br[0]; *eta_out = Ar[0] / Br[0]; }
        else { *g = 0.0; *eta_out = 0.0; }
        return;
    }
    if (p == top) {
        baseA = Ar[top - W]; baseB = Br[top - W];
        for (i = 0; i < W + 1; ++i) { Ar[i] = Ar[top - W + i] - baseA; Br[i] = Br[top - W + i] - baseB; }
        p = W;
    }
    Ar[p + 1] = Ar[p] + a; Br[p + 1] = Br[p] + b; p += 1;
    if (count < W) count += 1;
    best = 0.0; eta = 0.0;
    for (L = 1; L < count + 1; ++L) {
        dA = Ar[p] - Ar[p - L]; dB = Br[p] - Br[p - L];
        if (dB > min_info) { v = 0.5 * dA * dA / dB; if (v > best) { best = v; eta = dA / dB; } }
    }
    *g = best; *eta_out = eta;
    pos[0] = p; counts[0] = count;
}
"""

#: Nuisance signatures (``_solve_first`` and ``_dglrt_multi``); scratch given by the caller.
DGLRTM_HELPER = """
static double fdk_solve_first(const double *G, const double *A, int m, double *work, double *x,
                              double *v00)
{
    double big = 0.0, d, ljj, v, y, z;
    int i, j, k, M = m + 2;
    for (j = 0; j < m; ++j) big = (G[j * m + j] > big) ? G[j * m + j] : big;
    if (!(big > 0.0)) { *v00 = -1.0; return 0.0; }
    for (j = 0; j < m; ++j) {
        d = G[j * m + j];
        for (k = 0; k < j; ++k) d -= work[j * M + k] * work[j * M + k];
        if (!(d > 1e-10 * big)) { *v00 = -1.0; return 0.0; }
        ljj = sqrt(d);
        work[j * M + j] = ljj;
        for (i = j + 1; i < m; ++i) {
            v = G[i * m + j];
            for (k = 0; k < j; ++k) v -= work[i * M + k] * work[j * M + k];
            work[i * M + j] = v / ljj;
        }
    }
    for (i = 0; i < m; ++i) {
        y = A[i]; z = (i == 0) ? 1.0 : 0.0;
        for (k = 0; k < i; ++k) {
            y -= work[i * M + k] * work[k * M + m];
            z -= work[i * M + k] * work[k * M + m + 1];
        }
        work[i * M + m] = y / work[i * M + i];
        work[i * M + m + 1] = z / work[i * M + i];
    }
    for (i = m - 1; i > -1; --i) {
        v = work[i * M + m];
        for (k = i + 1; k < m; ++k) v -= work[k * M + i] * x[k];
        x[i] = v / work[i * M + i];
    }
    v = 0.0;
    for (i = 0; i < m; ++i) v += work[i * M + m + 1] * work[i * M + m + 1];
    *v00 = v;
    return x[0];
}

/* S[c * m + i]: signature i of residual channel c (the tested one at i = 0); scratch: a, dA, a0
   (m), g2, dG, g0 (m * m), work (m * (m + 2)), xs (m) */
static void fdk_dglrtm(double *Ar, double *Gr, int64_t *pos, int64_t *counts, const double *r,
                       const double *S, const double *mu0, const double *w, int C, int m, int W,
                       double min_info, double *g, double *eta_out, double *a, double *g2, double *dA,
                       double *dG, double *a0, double *g0, double *work, double *xs)
{
    double e, si, best, best_eta, eta, v00, v;
    int64_t p = pos[0], count = counts[0], L, q, top = 2 * (int64_t)W, mm = (int64_t)m * m;
    int c, i, j;
    for (i = 0; i < m; ++i) a[i] = 0.0;
    for (i = 0; i < m * m; ++i) g2[i] = 0.0;
    for (c = 0; c < C; ++c) {
        e = (r[c] - mu0[c]) * w[c];
        for (i = 0; i < m; ++i) {
            si = S[c * m + i];
            a[i] += si * e;
            for (j = 0; j < m; ++j) g2[i * m + j] += si * S[c * m + j] * w[c];
        }
    }
    if (W == 0) {
        for (i = 0; i < m; ++i) { Ar[i] += a[i]; for (j = 0; j < m; ++j) Gr[i * m + j] += g2[i * m + j]; }
        eta = fdk_solve_first(Gr, Ar, m, work, xs, &v00);
        if (v00 > 0.0 && 1.0 / v00 > min_info) { *g = 0.5 * eta * eta / v00; *eta_out = eta; }
        else { *g = 0.0; *eta_out = 0.0; }
        return;
    }
    if (p == top) {
        for (i = 0; i < m; ++i) {
            a0[i] = Ar[(top - W) * m + i];
            for (j = 0; j < m; ++j) g0[i * m + j] = Gr[(top - W) * mm + i * m + j];
        }
        for (q = 0; q < W + 1; ++q) for (i = 0; i < m; ++i) {
            Ar[q * m + i] = Ar[(top - W + q) * m + i] - a0[i];
            for (j = 0; j < m; ++j)
                Gr[q * mm + i * m + j] = Gr[(top - W + q) * mm + i * m + j] - g0[i * m + j];
        }
        p = W;
    }
    for (i = 0; i < m; ++i) {
        Ar[(p + 1) * m + i] = Ar[p * m + i] + a[i];
        for (j = 0; j < m; ++j) Gr[(p + 1) * mm + i * m + j] = Gr[p * mm + i * m + j] + g2[i * m + j];
    }
    p += 1;
    if (count < W) count += 1;
    best = 0.0; best_eta = 0.0;
    for (L = 1; L < count + 1; ++L) {
        for (i = 0; i < m; ++i) {
            dA[i] = Ar[p * m + i] - Ar[(p - L) * m + i];
            for (j = 0; j < m; ++j) dG[i * m + j] = Gr[p * mm + i * m + j] - Gr[(p - L) * mm + i * m + j];
        }
        eta = fdk_solve_first(dG, dA, m, work, xs, &v00);
        if (v00 > 0.0 && 1.0 / v00 > min_info) {
            v = 0.5 * eta * eta / v00;
            if (v > best) { best = v; best_eta = eta; }
        }
    }
    *g = best; *eta_out = best_eta;
    pos[0] = p; counts[0] = count;
}
"""


class DirectionalGLRTEmitter(StageEmitter):
    """:class:`~fdikit.detect.DirectionalGLRT`: anchored (``W=None``) or windowed, with or without
    nuisance signatures; in double in both variants."""

    kinds = ("DirectionalGLRT",)

    def __init__(self, obj, prefix):
        super().__init__(obj, prefix)
        self.C = len(obj.residual_names)
        self.m = obj.n_directions
        self.W = 0 if obj.W is None else int(obj.W)
        self.n = 1 if obj.W is None else 2 * obj.W + 1
        self.helpers = DGLRT1_HELPER if self.m == 1 else DGLRTM_HELPER

    def fields(self):
        m = self.m
        return [Field(f"{self.p}_A", "f64", self.n * m), Field(f"{self.p}_B", "f64", self.n * m * m),
                Field(f"{self.p}_pos", "i64", 1), Field(f"{self.p}_counts", "i64", 1),
                Field(f"{self.p}_k", "i64", 1)]

    def reset_code(self):
        f = self.f
        return (f"    {{ int j; for (j = 0; j < {self.n * self.m}; ++j) {f('A')}[j] = 0.0;\n"
                f"      for (j = 0; j < {self.n * self.m * self.m}; ++j) {f('B')}[j] = 0.0; }}\n"
                f"    {f('pos')}[0] = 0; {f('counts')}[0] = 0; {f('k')}[0] = 0;")

    def step_code(self, inp, out):
        o, C, m, f = self.obj, self.C, self.m, self.f
        w = 1.0 / o.sigma2
        lines = ["    {", f"        double r[{C}], S[{C * m}], g, eta;",
                 f"        static const double mu0[{C}] = {{{', '.join(lit(v) for v in o.mu0)}}};",
                 f"        static const double w[{C}] = {{{', '.join(lit(v) for v in w)}}};"]
        lines += [f"        if (!FDK_FINITE({e})) return FDK_ERR_STAT;" for e in inp]
        lines += [f"        r[{c}] = (double){inp[c]};" for c in range(C)]
        for i in range(m):
            for c in range(C):
                lines.append(f"        S[{c * m + i}] = (double){inp[C + i * C + c]};")
        lines.append(f"        {f('k')}[0] += 1;")
        if m == 1:
            lines.append(f"        fdk_dglrt1({f('A')}, {f('B')}, {f('pos')}, {f('counts')}, r, S, mu0, w, "
                         f"{C}, "
                         f"{self.W}, {lit(o.min_information)}, &g, &eta);")
        else:
            lines += [f"        double a[{m}], dA[{m}], a0[{m}], g2[{m * m}], dG[{m * m}], g0[{m * m}], "
                      f"work[{m * (m + 2)}], xs[{m}];",
                      f"        fdk_dglrtm({f('A')}, {f('B')}, {f('pos')}, {f('counts')}, r, S, mu0, w, "
                      f"{C}, {m}, "
                      f"{self.W}, {lit(o.min_information)}, &g, &eta, a, g2, dA, dG, a0, g0, work, xs);"]
        lines += [f"        {out[0]} = FDK_R(g);", f"        {out[1]} = FDK_R(eta);", "    }"]
        return "\n".join(lines)

    def to_py(self, arrays):
        m, n, p = self.m, self.n, self.p
        A, B = arrays[f"{p}_A"].astype(float), arrays[f"{p}_B"].astype(float)
        A = A.reshape(1, n) if m == 1 else A.reshape(1, n, m)
        B = B.reshape(1, n) if m == 1 else B.reshape(1, n, m, m)
        return {"_A": A, "_B": B, "_pos": arrays[f"{p}_pos"].astype(np.int64).reshape(1),
                "_counts": arrays[f"{p}_counts"].astype(np.int64).reshape(1), "_k": int(arrays[f"{p}_k"][0])}

    def from_py(self, state):
        p = self.p
        return {f"{p}_A": np.ravel(state["_A"]), f"{p}_B": np.ravel(state["_B"]),
                f"{p}_pos": np.ravel(state["_pos"]),
                f"{p}_counts": np.ravel(state["_counts"]), f"{p}_k": np.array([state["_k"]])}


register_emitter("fdikit.detect.directional:DirectionalGLRT", DirectionalGLRTEmitter)
