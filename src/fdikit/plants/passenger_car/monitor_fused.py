"""The whole car health monitor fused into one compiled per-sample update.

:class:`~fdikit.monitor.Monitor` composes the car monitor from separate stages (filters, parity
equations, features, MHSSPT, hold), each a Python call per sample: clear, but about 0.3 ms per
sample. :class:`FusedCarMonitor` runs the same computation for any number of calibrated
:class:`~fdikit.plants.passenger_car.monitor.CarMonitor` blocks in one numba kernel per sample:

* the filters of all blocks fused into one block-diagonal filter
  (:func:`~fdikit.residuals.stack_designs`, with the delayed control feedthrough);
* the two parity equations;
* the residual-norm features (first-order smoothing);
* the MHSSPT of each block in the log domain (paper 1, Section IV-E; the recursion of the notes)
  with **tabulated** uniform-mean Gaussian log densities: per feature a uniform grid of spacing
  ``min std / 32`` over ``[min low - 12 max std, max high + 12 max std]``, linear interpolation
  (error <= (1/32)^2 / 8 ~ 1.2e-4 nats per component and hypothesis, measured at build time and
  reported as ``table_error``), the exact formula outside the grid;
* the warm-up and the hold-then-announce rule.

``run`` (batch over runs and time) and ``reset``/``step`` (streaming) call the same compiled row
update, so they are bitwise equal; against the stage-by-stage Monitor the probabilities agree
up to the table error (tested).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from ...detect.mhsspt import UniformMeanGaussian, umg_component_logpdf
from ...errors import DataError
from ...residuals import stack_designs
from ...signals import Signals
from .monitor import CarMonitor, OffsetFilter, ParityEquations, delayed_feedthrough

__all__ = ["FusedCarMonitor"]

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def _exact_component(x: np.ndarray, low: float, high: float, std: float, point: bool) -> np.ndarray:
    """Exact log density of one component (vector x) — the table's reference."""
    d = UniformMeanGaussian([low], [high], [std])
    return d.logpdf(np.asarray(x, float)[:, None]) if not point else \
        -0.5 * ((x - low) / std) ** 2 - math.log(std) - _HALF_LOG_2PI


_exact_nb = umg_component_logpdf  # one compiled component density, shared with detect.MHSSPT


@njit(cache=True)
def _fused_row(v, xi, A, Bv, C, Dv, v0, par_idx, par_a, par_state, r,
               f_idx, f_starts, f_alpha, feat,
               g0, inv_h, nG, toff, tab, low, high, std, point, logw,
               blk_c0, blk_c1, blk_h0, blk_h1, log1mp, logp_pi, logq, log1mq, logF, ll, phi,
               k, warm, x0, grp, hold_z, level, cnt, out):  # pragma: no cover - compiled
    """One sample of one run. v (nv,) raw channels; writes the probabilities, group sums and
    alarms into out."""
    nf = xi.shape[0]
    nv = v.shape[0]
    A_p, A_j, A_x = A
    B_p, B_j, B_x = Bv
    C_p, C_j, C_x = C
    D_p, D_j, D_x = Dv
    q = C_p.shape[0] - 1
    # ---- fused filter (sparse rows, the zeros of the block-diagonal structure skipped):
    # r = C xi + Dv (v - v0); xi <- A xi + Bv (v - v0)
    dv = np.empty(nv)
    for j in range(nv):
        dv[j] = v[j] - v0[j]
    for i in range(q):
        acc = 0.0
        for e in range(C_p[i], C_p[i + 1]):
            acc += C_x[e] * xi[C_j[e]]
        for e in range(D_p[i], D_p[i + 1]):
            acc += D_x[e] * dv[D_j[e]]
        r[i] = acc
    tmp = np.empty(nf)
    for i in range(nf):
        acc = 0.0
        for e in range(A_p[i], A_p[i + 1]):
            acc += A_x[e] * xi[A_j[e]]
        for e in range(B_p[i], B_p[i + 1]):
            acc += B_x[e] * dv[B_j[e]]
        tmp[i] = acc
    for i in range(nf):
        xi[i] = tmp[i]
    # ---- parity equations (throttle, brake, throttle_meas, brake_meas channel indices)
    if par_idx[0] >= 0:
        prev = par_state[1]
        if np.isnan(prev):
            prev = v[par_idx[0]]
        r[q] = v[par_idx[2]] - prev
        r[q + 1] = v[par_idx[3]] - par_state[0]
        par_state[0] = par_a * par_state[0] + (1.0 - par_a) * v[par_idx[1]]
        par_state[1] = v[par_idx[0]]
    # ---- features
    nfeat = f_starts.shape[0] - 1
    for j in range(nfeat):
        s = 0.0
        for c in range(f_starts[j], f_starts[j + 1]):
            w = r[f_idx[c]]
            s += w * w
        feat[j] = feat[j] + f_alpha * (math.sqrt(s) - feat[j])
    # ---- MHSSPT per block
    H = logF.shape[0]
    for j in range(H):
        ll[j] = 0.0
    for b in range(blk_c0.shape[0]):
        h0, h1 = blk_h0[b], blk_h1[b]
        for c in range(blk_c0[b], blk_c1[b]):
            x = feat[c] if k >= warm else x0[c]
            t = (x - g0[c]) * inv_h[c]
            if t >= 0.0 and t < nG[c] - 1:
                i0 = int(t)
                fr = t - i0
                base = toff[c] + i0
                for j in range(h0, h1):
                    ll[j] += (1.0 - fr) * tab[base, j] + fr * tab[base + 1, j]
            else:
                for j in range(h0, h1):
                    ll[j] += _exact_nb(x, low[j, c], high[j, c], std[j, c], point[j, c], logw[j, c])
        # propagate (log domain) and Bayes update; hypothesis h0 is the block's H0
        m = -np.inf
        for j in range(h0 + 1, h1):
            if logF[j] > m:
                m = logF[j]
        if m > -np.inf:
            sf = 0.0
            for j in range(h0 + 1, h1):
                sf += math.exp(logF[j] - m)
            lse_f = m + math.log(sf)
        else:
            lse_f = -np.inf
        a = logF[h0] + log1mp[b]
        bb = logq[b] + lse_f
        mx = max(a, bb)
        phi[h0] = mx + math.log(math.exp(a - mx) + math.exp(bb - mx)) if mx > -np.inf else -np.inf
        for j in range(h0 + 1, h1):
            a = logF[j] + log1mq[b]
            bb = logF[h0] + logp_pi[j]
            mx = max(a, bb)
            phi[j] = mx + math.log(math.exp(a - mx) + math.exp(bb - mx)) if mx > -np.inf else -np.inf
        m = -np.inf
        for j in range(h0, h1):
            phi[j] += ll[j]
            if phi[j] > m:
                m = phi[j]
        s = 0.0
        for j in range(h0, h1):
            s += math.exp(phi[j] - m)
        lz = m + math.log(s)
        for j in range(h0, h1):
            logF[j] = phi[j] - lz
    # ---- outputs: group probabilities and hold-then-announce
    G = grp.shape[0]
    for g in range(G):
        pg = 0.0
        for e in range(grp.shape[1]):
            if grp[g, e] >= 0:
                pg += math.exp(logF[grp[g, e]])
        out[g] = pg
        if pg > level:  # as fdikit.detect.Hold: strictly above the level
            cnt[g] += 1
        else:
            cnt[g] = 0
        out[G + g] = 1.0 if cnt[g] >= hold_z else 0.0


@njit(cache=True)
def _fused_run(V, xi, A, Bv, C, Dv, v0, par_idx, par_a, par_state, f_idx, f_starts, f_alpha, feat,
               g0, inv_h, nG, toff, tab, low, high, std, point, logw,
               blk_c0, blk_c1, blk_h0, blk_h1, log1mp, logp_pi, logq, log1mq, logF,
               k0, warm, x0, grp, hold_z, level, cnt, out):  # pragma: no cover - compiled
    R, T = V.shape[0], V.shape[1]
    q = C[0].shape[0] - 1
    r = np.empty(q + 2)
    H = logF.shape[1]
    ll = np.empty(H)
    phi = np.empty(H)
    for i in range(R):
        for k in range(T):
            _fused_row(V[i, k], xi[i], A, Bv, C, Dv, v0, par_idx, par_a, par_state[i], r,
                       f_idx, f_starts, f_alpha, feat[i], g0, inv_h, nG, toff, tab, low, high, std, point,
                       logw, blk_c0, blk_c1, blk_h0, blk_h1, log1mp, logp_pi, logq, log1mq, logF[i], ll, phi,
                       k0 + k, warm, x0, grp, hold_z, level, cnt[i], out[i, k])


def _csr(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row pointers, column indices and values of the nonzeros of M, row by row in column order."""
    M = np.asarray(M, float)
    rows, cols = np.nonzero(M)
    ptr = np.zeros(M.shape[0] + 1, np.int64)
    np.add.at(ptr, rows + 1, 1)
    return np.cumsum(ptr), cols.astype(np.int64), np.ascontiguousarray(M[rows, cols])


class FusedCarMonitor:
    """All blocks of the car monitor in one compiled per-sample update (see the module docstring).

    Parameters
    ----------
    monitors : sequence of CarMonitor
        Calibrated blocks (e.g. the longitudinal and the lateral monitor) of one design; each
        must use the same feature smoothing, warm-up, hold and announcement level.
    resolution : float
        Table spacing as a fraction of the smallest std of each feature (default 1/32).

    Attributes
    ----------
    input_names : list of str
        Channels read (commands and measurements).
    output_names : list of str
        ``"P:<fault>"`` for every fault of every block, then ``"A:<fault>"`` (announced, 0/1).
    table_error : float
        Largest absolute log-density interpolation error measured at the grid midpoints (nats).

    Examples
    --------
    >>> fused = FusedCarMonitor([lon, lat])            # doctest: +SKIP
    >>> fused.reset(1); P = fused.step(sample)         # doctest: +SKIP
    """

    def __init__(self, monitors: Sequence[CarMonitor], *, resolution: float = 1.0 / 32.0):
        monitors = list(monitors)
        if not monitors:
            raise DataError("FusedCarMonitor needs at least one CarMonitor")
        gens, feats, tests, holds = [], [], [], []
        for cm in monitors:
            g = list(cm.monitor.generators)
            feats.append(cm.monitor.processors[0])
            tests.append(cm.monitor.processors[1])
            holds.append(cm.monitor.processors[2])
            gens += g
        other = [type(g).__name__ for g in gens if not isinstance(g, (OffsetFilter, ParityEquations))]
        if other:
            raise DataError(f"FusedCarMonitor fuses fixed-speed filters and the parity equations only; got "
                            f"{other} (build the monitor without a speed schedule)")
        filters = [g for g in gens if isinstance(g, OffsetFilter)]
        parity = [g for g in gens if isinstance(g, ParityEquations)]
        if len(parity) > 1:
            raise DataError("at most one block may carry the parity equations")
        # undo the per-block delay wrapping: stack the members and delay once
        members = []
        for f in filters:
            d = f.design
            m = len(d.u_names)
            nf = d.order - m
            from ...residuals import FilterDesign

            members.append(FilterDesign(d.A[:nf, :nf], d.Bu[:nf], d.By[:nf], d.C[:, :nf], d.C[:, nf:],
                                        d.Dy, d.dt, d.u_names, d.y_names, d.residual_names))
        design = delayed_feedthrough(stack_designs(members))
        off = {**{n: float(u) for f in filters for n, u in zip(f.design.u_names, f.u0)},
               **{n: float(y) for f in filters for n, y in zip(f.design.y_names, f.y0)}}
        chans = list(design.u_names) + list(design.y_names)
        if parity:
            for n in (*parity[0].u_names, *parity[0].y_names):
                if n not in chans:
                    chans.append(n)
        self.input_names = chans
        nu = len(design.u_names)
        self._A = np.ascontiguousarray(design.A)
        nv = len(chans)
        self._Bv = np.zeros((design.order, nv))
        self._Dv = np.zeros((len(design.residual_names), nv))
        self._Bv[:, :nu + len(design.y_names)] = np.hstack([design.Bu, design.By])
        self._Dv[:, :nu + len(design.y_names)] = np.hstack([design.Du, design.Dy])
        self._C = np.ascontiguousarray(design.C)
        self._v0 = np.array([off.get(n, 0.0) for n in chans])
        if parity:
            pe = parity[0]
            self._par_idx = np.array([chans.index(n) for n in (*pe.u_names, *pe.y_names)], np.int64)
            self._par_a = pe.a
            rnames = list(design.residual_names) + list(pe.output_names)
        else:
            self._par_idx = np.full(4, -1, np.int64)
            self._par_a = 0.0
            rnames = list(design.residual_names)
        # features
        taus = {f.alpha for f in feats}
        if len(taus) != 1:
            raise DataError(f"blocks use different feature smoothing: {sorted(taus)}")
        self._alpha = feats[0].alpha
        groups = {k: v for f in feats for k, v in f.groups.items()}
        fnames = list(groups)
        self._f_idx = np.array([rnames.index(c) for v in groups.values() for c in v], np.int64)
        self._f_starts = np.cumsum([0] + [len(v) for v in groups.values()]).astype(np.int64)
        # hypotheses
        Htot = sum(len(t.hypotheses) for t in tests)
        Ctot = len(fnames)
        low, high = np.zeros((Htot, Ctot)), np.zeros((Htot, Ctot))
        std, point = np.ones((Htot, Ctot)), np.ones((Htot, Ctot), bool)
        c0, c1, h0, h1, l1p, lq, l1q = [], [], [], [], [], [], []
        logp_pi = np.full(Htot, -np.inf)
        x0 = np.zeros(Ctot)
        hyp_names: list[str] = []
        h = 0
        self.output_names = []
        grp_rows = []
        warm = set()
        for t in tests:
            cs = [fnames.index(n) for n in t.input_names]
            if cs != list(range(cs[0], cs[0] + len(cs))):
                raise DataError("a block's features must be contiguous")
            c0.append(cs[0])
            c1.append(cs[-1] + 1)
            h0.append(h)
            for d in t.densities:
                low[h, cs], high[h, cs], std[h, cs] = d.low, d.high, d.std
                point[h, cs] = d._point
                h += 1
            h1.append(h)
            hyp_names += t.hypotheses
            l1p.append(t._log1mp)
            lq.append(t._logq)
            l1q.append(t._log1mq)
            logp_pi[h0[-1]:h1[-1]] = t._logp_pi
            x0[cs] = t.densities[0].low
            warm.add(getattr(t, "warmup", 0))
            for g, members in t.groups.items():
                grp_rows.append([h0[-1] + t.hypotheses.index(mm) for mm in members])
                self.output_names.append(f"P:{g}")
        if len(warm) != 1:
            raise DataError(f"blocks use different warm-ups: {sorted(warm)}")
        self._warm = warm.pop()
        width = max(len(r) for r in grp_rows)
        self._grp = np.array([r + [-1] * (width - len(r)) for r in grp_rows], np.int64)
        self.faults = [n[2:] for n in self.output_names]
        self.output_names += [f"A:{f}" for f in self.faults]
        zs = {hd.Z for hd in holds}
        lv = {hd.threshold[0] for hd in holds}
        if len(zs) != 1 or len(lv) != 1:
            raise DataError("blocks use different hold lengths or announcement levels")
        self._hold, self._level = int(zs.pop()), float(lv.pop())
        self._low, self._high, self._std, self._point = low, high, std, point
        self._logw = np.log(np.where(point, 1.0, np.maximum(high - low, 1e-300)))
        self._blk = tuple(np.array(a, np.int64) for a in (c0, c1, h0, h1))
        self._l1p, self._lq, self._l1q = np.array(l1p), np.array(lq), np.array(l1q)
        self._logp_pi = logp_pi
        self._x0 = x0
        self._H = Htot
        self.hypotheses = hyp_names
        self._build_tables(resolution, h0, h1, c0, c1)
        self._sA, self._sBv, self._sC, self._sDv = (_csr(M) for M in (self._A, self._Bv, self._C, self._Dv))
        self.reset(1)

    def _build_tables(self, resolution, h0, h1, c0, c1):
        C = self._x0.size
        g0, inv_h, nG, toff = np.zeros(C), np.zeros(C), np.zeros(C, np.int64), np.zeros(C, np.int64)
        tabs, err, total = [], 0.0, 0
        for b in range(len(h0)):
            hs = slice(h0[b], h1[b])
            for c in range(c0[b], c1[b]):
                s_min, s_max = self._std[hs, c].min(), self._std[hs, c].max()
                lo = self._low[hs, c].min() - 12 * s_max
                hi = self._high[hs, c].max() + 12 * s_max
                step = resolution * s_min
                n = int(min(np.ceil((hi - lo) / step) + 1, 400_000))
                step = (hi - lo) / (n - 1)
                grid = lo + step * np.arange(n)
                mid = grid[:-1] + 0.5 * step
                T = np.zeros((n, self._H))
                for j in range(h0[b], h1[b]):
                    args = (self._low[j, c], self._high[j, c], self._std[j, c], bool(self._point[j, c]))
                    T[:, j] = _exact_component(grid, *args)
                    e = np.abs(0.5 * (T[:-1, j] + T[1:, j]) - _exact_component(mid, *args))
                    # error that matters: where the density is not negligible against the others
                    err = max(err, float(e[T[:-1, j] > -700].max(initial=0.0)))
                g0[c], inv_h[c], nG[c], toff[c] = lo, 1.0 / step, n, total
                total += n
                tabs.append(T)
        self._tab = np.ascontiguousarray(np.vstack(tabs))
        self._g0, self._inv_h, self._nG, self._toff = g0, inv_h, nG, toff
        self.table_error = err
        self.table_bytes = int(self._tab.nbytes)

    # ------------------------------------------------------------------ runtime
    def reset(self, runs: int = 1) -> None:
        self._xi = np.zeros((runs, self._A.shape[0]))
        self._par = np.column_stack([np.zeros(runs), np.full(runs, np.nan)])
        self._feat = np.zeros((runs, self._x0.size))
        self._logF = np.full((runs, self._H), -np.inf)
        for h in self._blk[2]:
            self._logF[:, h] = 0.0
        self._cnt = np.zeros((runs, len(self.faults)), np.int64)
        self._k = 0

    def _args(self):
        return (self._sA, self._sBv, self._sC, self._sDv, self._v0, self._par_idx, self._par_a, self._par,
                self._f_idx, self._f_starts, self._alpha, self._feat, self._g0, self._inv_h, self._nG,
                self._toff, self._tab, self._low, self._high, self._std, self._point, self._logw,
                *self._blk, self._l1p, self._logp_pi, self._lq, self._l1q, self._logF)

    def _advance(self, V: np.ndarray) -> np.ndarray:
        if V.shape[0] != self._xi.shape[0]:
            raise DataError(f"sample has {V.shape[0]} runs; the monitor was reset for {self._xi.shape[0]}")
        out = np.empty((V.shape[0], V.shape[1], len(self.output_names)))
        _fused_run(V, self._xi, *self._args(), self._k, self._warm, self._x0, self._grp, self._hold,
                   self._level, self._cnt, out)
        self._k += V.shape[1]
        return out

    def step(self, v_k: Any) -> np.ndarray:
        """One sample ``v_k`` (runs, len(input_names)) (or (n,) for one run) -> (runs, outputs)."""
        v = np.asarray(v_k, float)
        if v.ndim == 1:
            v = v[None]
        return self._advance(np.ascontiguousarray(v[:, None]))[:, 0]

    def run(self, signals: Signals) -> Signals:
        """Batch over a record (all runs)."""
        V = np.ascontiguousarray(signals.values[:, :, signals.index(self.input_names)])
        if not np.all(np.isfinite(V)):
            run, k, c = np.argwhere(~np.isfinite(V))[0]
            raise DataError(f"channel {self.input_names[c]!r} is not finite at sample {k} (run {run})")
        self.reset(signals.runs)
        return Signals(signals.t, self._advance(V), self.output_names, check=False)
