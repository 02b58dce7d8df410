"""The whole car health monitor fused into one compiled per-sample update.

:class:`~fdikit.monitor.Monitor` composes the car monitor from separate stages (filters, parity
equations, features, MHSSPT, hold), each a Python call per sample: clear, but about 0.2-0.3 ms
per sample. :class:`FusedCarMonitor` runs the same computation for any number of calibrated
:class:`~fdikit.systems.car.monitor.CarMonitor` blocks in one numba kernel:

* the filters of all blocks fused into one block-diagonal filter
  (:func:`~fdikit.residuals.stack_designs`, with the delayed control feedthrough), evaluated as
  sums of columns over the rows each column touches (the block-diagonal zeros skipped);
* the two parity equations;
* the residual-norm features (first-order smoothing);
* the MHSSPT of each block in the log domain (ng-chen-speyer, Section IV-E; the recursion of the notes,
  :func:`~fdikit.detect.mhsspt.mhsspt_update`) with **tabulated** uniform-mean Gaussian log
  densities (:func:`~fdikit.detect.mhsspt.tabulate_umg`): per feature a uniform grid of spacing
  ``min std / 32`` over ``[min low - 12 max std, max high + 12 max std]``, linear interpolation
  (error <= (1/32)^2 / 8 ~ 1.2e-4 nats per component and hypothesis, measured at build time and
  reported as ``table_error``), the exact formula outside the grid;
* the warm-up and the hold-then-announce rule (each block's level and hold length).

Runs are processed in chunks of :data:`CHUNK`: the filter's multiply-adds run across the runs of
a chunk (vectorised), chunks run in parallel threads in a batch. Each run's own arithmetic is
the same in a chunk of one, so ``run`` (batch over runs and time, parallel) and
``reset``/``step`` (streaming) are bitwise equal (tested); against the stage-by-stage Monitor the
probabilities agree up to the table error (tested).

A fused monitor is also a :class:`~fdikit.monitor.ResidualGenerator` (for config-driven
monitors), a saveable design (``to_dict`` / ``from_dict``: every array it runs on, nothing
redesigned on loading) and :class:`~fdikit.base.state.Stateful` (checkpoint and restore).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit, prange

from ...base.stage import ResidualGenerator
from ...detect.mhsspt import mhsspt_update, tabulate_umg, umg_table_add
from ...errors import DataError
from ...residuals import FilterDesign, stack_designs
from ...signals import Signals
from .monitor import CarMonitor, OffsetFilter, ParityEquations, delayed_feedthrough

__all__ = ["FusedCarMonitor"]


#: Runs advanced together by one kernel call (the filter's multiply-adds run across them).
CHUNK = 16


#: Segments of the packed integer and float parameter vectors of the kernel (one array each: a
#: call's cost is dominated by unboxing its array arguments, so the kernel takes few).
INT_SEGS = ("C_l", "C_h", "C_o", "D_l", "D_h", "D_o", "A_l", "A_h", "A_o", "B_l", "B_h", "B_o", "par_idx",
            "f_idx", "f_starts", "nG", "toff", "blk_c0", "blk_c1", "blk_h0", "blk_h1", "hold_z", "iscal")
FLT_SEGS = ("C_x", "D_x", "A_x", "B_x", "v0", "pv0", "g0", "inv_h", "x0", "log1mp", "logq", "log1mq",
            "logp_pi", "level", "fscal")
_NI, _NF = len(INT_SEGS), len(FLT_SEGS)


@njit(cache=True)
def _iseg(IP, k):  # pragma: no cover - compiled
    """Integer segment ``k`` of the packed parameters (a view)."""
    return IP[IP[k]:IP[k + 1]]


@njit(cache=True)
def _fseg(FP, IP, k):  # pragma: no cover - compiled
    """Float segment ``k`` of the packed parameters (a view)."""
    return FP[IP[_NI + 1 + k]:IP[_NI + 2 + k]]


@njit(cache=True)
def _fused_chunk(i0, i1, V, xi_all, par_all, feat_all, logF_all, cnt_all, out_all, IP, FP, tab, dens, point,
                 grp, k0):  # pragma: no cover - compiled
    """All samples of runs ``i0..i1-1``. The filter runs across the runs of the chunk (the inner
    loop over runs is what the compiler vectorises); each run's own arithmetic -- every sum in
    the same order -- is that of a chunk of one, so batch and streaming are bitwise equal. The
    rest of the per-sample body is written out here (no inner calls but the MHSSPT update and
    the density outside its table): a call with many array arguments costs their reference
    counting, more than the arithmetic. ``IP``/``FP``: packed parameters (:func:`_pack`)."""
    C_l, C_h, C_o, D_l, D_h, D_o = _iseg(IP, 0), _iseg(IP, 1), _iseg(IP, 2), _iseg(IP, 3), _iseg(IP, 4), \
        _iseg(IP, 5)
    A_l, A_h, A_o, B_l, B_h, B_o = _iseg(IP, 6), _iseg(IP, 7), _iseg(IP, 8), _iseg(IP, 9), _iseg(IP, 10), \
        _iseg(IP, 11)
    par_idx, f_idx, f_starts, nG, toff = _iseg(IP, 12), _iseg(IP, 13), _iseg(IP, 14), _iseg(IP, 15), \
        _iseg(IP, 16)
    blk_c0, blk_c1, blk_h0, blk_h1 = _iseg(IP, 17), _iseg(IP, 18), _iseg(IP, 19), _iseg(IP, 20)
    hold_z = _iseg(IP, 21)
    q, warm = _iseg(IP, 22)[0], _iseg(IP, 22)[1]
    C_x, D_x, A_x, B_x = _fseg(FP, IP, 0), _fseg(FP, IP, 1), _fseg(FP, IP, 2), _fseg(FP, IP, 3)
    v0, pv0, g0, inv_h, x0 = _fseg(FP, IP, 4), _fseg(FP, IP, 5), _fseg(FP, IP, 6), _fseg(FP, IP, 7), \
        _fseg(FP, IP, 8)
    log1mp, logq, log1mq, logp_pi = _fseg(FP, IP, 9), _fseg(FP, IP, 10), _fseg(FP, IP, 11), _fseg(FP, IP, 12)
    level = _fseg(FP, IP, 13)
    par_a, f_alpha = _fseg(FP, IP, 14)[0], _fseg(FP, IP, 14)[1]
    low, high, std, logw = dens[0], dens[1], dens[2], dens[3]
    nf = xi_all.shape[1]
    nv = V.shape[2]
    H = logF_all.shape[1]
    nfeat = f_starts.shape[0] - 1
    G = grp.shape[0]
    W = i1 - i0
    XI = np.empty((nf, W))
    TMP = np.empty((nf, W))
    RR = np.empty((q, W))
    DV = np.empty((nv, W))
    r = np.empty(q + 2)
    ll = np.empty(H)
    phi = np.empty(H)
    P = np.empty(H)
    for w in range(W):
        for ii in range(nf):
            XI[ii, w] = xi_all[i0 + w, ii]
    for kk in range(V.shape[1]):
        # ---- fused filter: r = C xi + Dv (v - v0); xi <- A xi + Bv (v - v0), as sums of columns
        # over the rows each column touches (the block-diagonal zeros skipped), in a fixed order
        for j in range(nv):
            for w in range(W):
                DV[j, w] = V[i0 + w, kk, j] - v0[j]
        RR[:, :] = 0.0
        TMP[:, :] = 0.0
        if W == 1:  # one run (streaming): the same products and sums without the loop over runs
            for j in range(nf):
                x = XI[j, 0]
                o = C_o[j] - C_l[j]
                for ii in range(C_l[j], C_h[j]):
                    RR[ii, 0] += C_x[o + ii] * x
                o = A_o[j] - A_l[j]
                for ii in range(A_l[j], A_h[j]):
                    TMP[ii, 0] += A_x[o + ii] * x
            for j in range(nv):
                x = DV[j, 0]
                o = D_o[j] - D_l[j]
                for ii in range(D_l[j], D_h[j]):
                    RR[ii, 0] += D_x[o + ii] * x
                o = B_o[j] - B_l[j]
                for ii in range(B_l[j], B_h[j]):
                    TMP[ii, 0] += B_x[o + ii] * x
        else:
            for j in range(nf):
                o = C_o[j] - C_l[j]
                for ii in range(C_l[j], C_h[j]):
                    cij = C_x[o + ii]
                    for w in range(W):
                        RR[ii, w] += cij * XI[j, w]
                o = A_o[j] - A_l[j]
                for ii in range(A_l[j], A_h[j]):
                    aij = A_x[o + ii]
                    for w in range(W):
                        TMP[ii, w] += aij * XI[j, w]
            for j in range(nv):
                o = D_o[j] - D_l[j]
                for ii in range(D_l[j], D_h[j]):
                    dij = D_x[o + ii]
                    for w in range(W):
                        RR[ii, w] += dij * DV[j, w]
                o = B_o[j] - B_l[j]
                for ii in range(B_l[j], B_h[j]):
                    bij = B_x[o + ii]
                    for w in range(W):
                        TMP[ii, w] += bij * DV[j, w]
        XI[:, :] = TMP
        for w in range(W):
            i = i0 + w
            v = V[i, kk]
            out = out_all[i, kk]
            par_state = par_all[i]
            feat = feat_all[i]
            logF = logF_all[i]
            cnt = cnt_all[i]
            for ii in range(q):
                r[ii] = RR[ii, w]
            # ---- parity equations (throttle, brake, throttle_meas, brake_meas channel indices)
            if par_idx[0] >= 0:
                # the parity equations read absolute values: pv0 adds back an operating point that was
                # subtracted before the monitor (deviation inputs); zero for absolute inputs
                thr = v[par_idx[0]] + pv0[par_idx[0]]
                prev = par_state[1]
                if np.isnan(prev):
                    prev = thr
                r[q] = (v[par_idx[2]] + pv0[par_idx[2]]) - prev
                r[q + 1] = (v[par_idx[3]] + pv0[par_idx[3]]) - par_state[0]
                par_state[0] = par_a * par_state[0] + (1.0 - par_a) * (v[par_idx[1]] + pv0[par_idx[1]])
                par_state[1] = thr
            # ---- features: low-passed norms of the filters' residual vectors and of the parity residuals
            for j in range(nfeat):
                s = 0.0
                for c in range(f_starts[j], f_starts[j + 1]):
                    rc = r[f_idx[c]]
                    s += rc * rc
                feat[j] = feat[j] + f_alpha * (math.sqrt(s) - feat[j])
            # ---- MHSSPT per block (ng-chen-speyer, Section IV-E) on tabulated densities
            for b in range(blk_c0.shape[0]):
                h0, h1 = blk_h0[b], blk_h1[b]
                for j in range(h0, h1):
                    ll[j] = 0.0
                for c in range(blk_c0[b], blk_c1[b]):
                    x = feat[c] if k0 + kk >= warm else x0[c]
                    # linear interpolation in the table (as detect.mhsspt.umg_table_add, written out)
                    t = (x - g0[c]) * inv_h[c]
                    if t >= 0.0 and t < nG[c] - 1:
                        it = int(t)
                        fr = t - it
                        base = toff[c] + it
                        for j in range(h0, h1):
                            ll[j] += (1.0 - fr) * tab[base, j] + fr * tab[base + 1, j]
                    else:
                        umg_table_add(x, c, tab, g0, inv_h, nG, toff, low, high, std, point, logw, ll, h0, h1)
                mhsspt_update(logF, ll, phi, P, h0, h1, log1mp[b], logp_pi, logq[b], log1mq[b])
            # ---- outputs: group probabilities and hold-then-announce
            for g in range(G):
                pg = 0.0
                for e in range(grp.shape[1]):
                    if grp[g, e] >= 0:
                        pg += P[grp[g, e]]
                out[g] = pg
                if pg > level[g]:  # as fdikit.detect.Hold: strictly above the level
                    cnt[g] += 1
                else:
                    cnt[g] = 0
                out[G + g] = 1.0 if cnt[g] >= hold_z[g] else 0.0
    for w in range(W):
        for ii in range(nf):
            xi_all[i0 + w, ii] = XI[ii, w]


@njit(cache=True)
def _fused_run(V, xi, par, feat, logF, cnt, out, IP, FP, tab, dens, point, grp, k0):  # pragma: no cover
    """Chunks of runs one after the other (streaming: no thread start-up)."""
    R = V.shape[0]
    for c in range((R + CHUNK - 1) // CHUNK):
        _fused_chunk(c * CHUNK, min(R, (c + 1) * CHUNK), V, xi, par, feat, logF, cnt, out, IP, FP, tab, dens,
                     point, grp, k0)


@njit(cache=True, parallel=True)
def _fused_run_parallel(V, xi, par, feat, logF, cnt, out, IP, FP, tab, dens, point, grp,
                        k0):  # pragma: no cover - compiled
    """Chunks of runs in parallel threads (independent runs; the arithmetic of _fused_run)."""
    R = V.shape[0]
    for c in prange((R + CHUNK - 1) // CHUNK):
        _fused_chunk(c * CHUNK, min(R, (c + 1) * CHUNK), V, xi, par, feat, logF, cnt, out, IP, FP, tab, dens,
                     point, grp, k0)


def _pack(a: dict[str, np.ndarray], spans: dict[str, tuple], hold, level, scal_i,
          scal_f) -> tuple[np.ndarray, np.ndarray]:
    """Pack the kernel's parameters into one int64 vector (header: segment offsets) and one float
    vector, in the order of :data:`INT_SEGS` / :data:`FLT_SEGS`."""
    iv = {**{f"{m}_{k}": spans[m][i] for m in "CDAB" for i, k in enumerate("lho")},
          **{k: a[k] for k in ("par_idx", "f_idx", "f_starts", "nG", "toff", "blk_c0", "blk_c1", "blk_h0",
                               "blk_h1")},
          "hold_z": np.asarray(hold, np.int64), "iscal": np.asarray(scal_i, np.int64)}
    fv = {**{f"{m}_x": spans[m][3] for m in "CDAB"},
          **{k: a[k] for k in ("v0", "pv0", "g0", "inv_h", "x0", "log1mp", "logq", "log1mq", "logp_pi")},
          "level": np.asarray(level, float), "fscal": np.asarray(scal_f, float)}
    head = _NI + 1 + _NF + 1
    ioff = np.cumsum([head] + [len(iv[k]) for k in INT_SEGS])
    foff = np.cumsum([0] + [len(fv[k]) for k in FLT_SEGS])
    IP = np.concatenate([ioff, foff] + [np.asarray(iv[k], np.int64) for k in INT_SEGS]).astype(np.int64)
    FP = np.concatenate([np.asarray(fv[k], float) for k in FLT_SEGS])
    return IP, FP


def _colspans(M: np.ndarray) -> tuple[np.ndarray, ...]:
    """Column-span form of M: per column j the first and one-past-last nonzero row (``lo``, ``hi``),
    the offset of its values in ``vals``, ``vals`` (M[lo:hi, j] of every column, concatenated)
    and the number of rows (a one-element array)."""
    M = np.asarray(M, float)
    n = M.shape[1]
    lo, hi, off = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    vals, total = [], 0
    for j in range(n):
        nz = np.flatnonzero(M[:, j])
        if nz.size:
            lo[j], hi[j] = nz[0], nz[-1] + 1
            vals.append(M[lo[j]:hi[j], j])
        off[j] = total
        total += hi[j] - lo[j]
    return (lo, hi, off, np.ascontiguousarray(np.concatenate(vals) if vals else np.zeros(0)),
            np.array([M.shape[0]], np.int64))


#: Version of the payload of :meth:`FusedCarMonitor.to_dict` (checked by :meth:`FusedCarMonitor.from_dict`).
FUSED_FORMAT = 1

#: Arrays of a fused monitor: name -> (dtype, number of dimensions); all of them travel in an artifact.
_ARRAYS: dict[str, tuple[type, int]] = {
    "A": (float, 2), "Bv": (float, 2), "C": (float, 2), "Dv": (float, 2), "v0": (float, 1), "pv0": (float, 1),
    "par_idx": (np.int64, 1), "f_idx": (np.int64, 1), "f_starts": (np.int64, 1),
    "low": (float, 2), "high": (float, 2), "std": (float, 2), "point": (bool, 2), "logw": (float, 2),
    "blk_c0": (np.int64, 1), "blk_c1": (np.int64, 1), "blk_h0": (np.int64, 1), "blk_h1": (np.int64, 1),
    "log1mp": (float, 1), "logq": (float, 1), "log1mq": (float, 1), "logp_pi": (float, 1), "x0": (float, 1),
    "grp": (np.int64, 2), "tab": (float, 2), "g0": (float, 1), "inv_h": (float, 1), "nG": (np.int64, 1),
    "toff": (np.int64, 1),
}


class FusedCarMonitor(ResidualGenerator):
    """All blocks of the car monitor in one compiled per-sample update (see the module docstring).

    A :class:`~fdikit.monitor.ResidualGenerator`, so it runs inside a :class:`~fdikit.monitor.Monitor`
    (e.g. one built from a TOML config, :mod:`fdikit.monitor.config`); a saveable design
    (:meth:`to_dict` / :meth:`from_dict`, :func:`~fdikit.monitor.save_artifact`) and a
    :class:`~fdikit.base.state.Stateful` component (filter states, parity states, features,
    log posteriors, hold counters and the sample counter are its checkpoint).

    Parameters
    ----------
    monitors : sequence of CarMonitor
        Calibrated blocks (e.g. the longitudinal and the lateral monitor) of one design; each
        must use the same feature smoothing, warm-up, hold and announcement level, and
        fixed-speed filters (no speed schedule).
    resolution : float
        Table spacing as a fraction of the smallest std of each feature (default 1/32).
    deviations : bool
        ``False`` (default): the monitor reads the channels as measured and subtracts the
        filters' operating point itself (as :class:`~fdikit.systems.car.monitor.OffsetFilter`
        does). ``True``: it reads deviations from the operating point :attr:`operating_point`,
        subtracted before it (ng-chen-speyer, Section V: "the nominal values of the control commands
        and measurements have to be subtracted"; in a config, the channels' ``offset``); the
        parity equations add it back (they compare absolute command and measurement).

    Attributes
    ----------
    u_names, y_names : list of str
        Commands (``throttle`` deg, ``brake`` MPa, ``steer`` rad) and measurements read.
    input_names : list of str
        ``u_names + y_names``: the order of a full sample for :meth:`step` with one argument.
    output_names : list of str
        ``"P:<fault>"`` for every fault of every block, then ``"A:<fault>"`` (announced, 0/1).
    operating_point : dict
        Channel -> nominal value (channel units) the filters were linearised about.
    faults, hypotheses : list of str
        Monitored faults (probability groups) and every MHSSPT hypothesis of every block.
    hold, level : list
        Per fault: samples its probability must stay strictly above ``level`` before it is
        announced (its block's :class:`~fdikit.detect.Hold`).
    table_error : float
        Largest absolute log-density interpolation error measured at the grid midpoints (nats).
    parallel : bool
        Batch runs share the cores (default True; the results do not depend on it).

    Examples
    --------
    >>> fused = FusedCarMonitor([lon, lat])            # doctest: +SKIP
    >>> fused.reset(1); P = fused.step(sample)         # doctest: +SKIP
    >>> save_artifact("designs/car", fused)            # doctest: +SKIP
    """

    _state_attrs = ("_xi", "_par", "_feat", "_logF", "_cnt", "_k")

    def __init__(self, monitors: Sequence[CarMonitor], *, resolution: float = 1.0 / 32.0,
                 deviations: bool = False):
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
            members.append(FilterDesign(d.A[:nf, :nf], d.Bu[:nf], d.By[:nf], d.C[:, :nf], d.C[:, nf:],
                                        d.Dy, d.dt, d.u_names, d.y_names, d.residual_names))
        design = delayed_feedthrough(stack_designs(members))
        # the operating point: the blocks' trim (every command and measurement, the parity
        # equations' too), then exactly what each filter subtracts
        off: dict[str, float] = {}
        for cm in monitors:
            des = getattr(cm, "design", None)
            trim = {**getattr(des, "u0", {}), **getattr(des, "y0", {})}
            off.update({str(n): float(v) for n, v in trim.items()})
        off.update({n: float(u) for f in filters for n, u in zip(f.design.u_names, f.u0)})
        off.update({n: float(y) for f in filters for n, y in zip(f.design.y_names, f.y0)})
        u_names, y_names = list(design.u_names), list(design.y_names)
        if parity:
            u_names += [n for n in parity[0].u_names if n not in u_names]
            y_names += [n for n in parity[0].y_names if n not in y_names]
        chans = u_names + y_names
        self.u_names, self.y_names = u_names, y_names
        self.dt = float(design.dt)
        self.deviations = bool(deviations)
        self.operating_point = {n: off.get(n, 0.0) for n in chans}
        nv = len(chans)
        a: dict[str, Any] = {}
        a["A"] = np.ascontiguousarray(design.A)
        a["C"] = np.ascontiguousarray(design.C)
        a["Bv"] = np.zeros((design.order, nv))
        a["Dv"] = np.zeros((len(design.residual_names), nv))
        cols = [chans.index(n) for n in (*design.u_names, *design.y_names)]
        a["Bv"][:, cols] = np.hstack([design.Bu, design.By])
        a["Dv"][:, cols] = np.hstack([design.Du, design.Dy])
        op = np.array([self.operating_point[n] for n in chans])
        a["v0"] = np.zeros(nv) if self.deviations else op
        a["pv0"] = op if self.deviations else np.zeros(nv)
        if parity:
            pe = parity[0]
            a["par_idx"] = np.array([chans.index(n) for n in (*pe.u_names, *pe.y_names)], np.int64)
            self.par_a = float(pe.a)
            rnames = list(design.residual_names) + list(pe.output_names)
        else:
            a["par_idx"] = np.full(4, -1, np.int64)
            self.par_a = 0.0
            rnames = list(design.residual_names)
        self.filter_residual_names = rnames
        # features
        taus = {f.alpha for f in feats}
        if len(taus) != 1:
            raise DataError(f"blocks use different feature smoothing: {sorted(taus)}")
        self.alpha = float(feats[0].alpha)
        groups = {k: v for f in feats for k, v in f.groups.items()}
        fnames = list(groups)
        self.feature_names = fnames
        a["f_idx"] = np.array([rnames.index(c) for v in groups.values() for c in v], np.int64)
        a["f_starts"] = np.cumsum([0] + [len(v) for v in groups.values()]).astype(np.int64)
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
        p_names = []
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
            for g, mem in t.groups.items():
                grp_rows.append([h0[-1] + t.hypotheses.index(mm) for mm in mem])
                p_names.append(f"P:{g}")
        if len(warm) != 1:
            raise DataError(f"blocks use different warm-ups: {sorted(warm)}")
        self.warmup = int(warm.pop())
        width = max(len(r) for r in grp_rows)
        a["grp"] = np.array([r + [-1] * (width - len(r)) for r in grp_rows], np.int64)
        self.faults = [n[2:] for n in p_names]
        self.output_names = p_names + [f"A:{f}" for f in self.faults]
        # announcement of each fault: its block's level and hold length (fdikit.detect.Hold)
        self.hold, self.level = [], []
        for t, hd in zip(tests, holds):
            for g in t.groups:
                i = hd.input_names.index(f"P:{g}")
                self.hold.append(int(hd.Z))
                self.level.append(float(hd.threshold[i]))
        a.update(low=low, high=high, std=std, point=point,
                 logw=np.log(np.where(point, 1.0, np.maximum(high - low, 1e-300))),
                 blk_c0=np.array(c0, np.int64), blk_c1=np.array(c1, np.int64),
                 blk_h0=np.array(h0, np.int64), blk_h1=np.array(h1, np.int64),
                 log1mp=np.array(l1p, float), logq=np.array(lq, float), log1mq=np.array(l1q, float),
                 logp_pi=logp_pi, x0=x0)
        self.hypotheses = hyp_names
        a.update(self._build_tables(a, resolution))
        self._setup(a)

    # ------------------------------------------------------------------ construction helpers
    @staticmethod
    def _build_tables(a: dict[str, np.ndarray], resolution: float) -> dict[str, Any]:
        """Per feature a uniform grid and the log density of every hypothesis of its block on it
        (:func:`~fdikit.detect.mhsspt.tabulate_umg` per block, columns at the block's hypotheses)."""
        H, C = a["low"].shape
        g0, inv_h, nG, toff = np.zeros(C), np.zeros(C), np.zeros(C, np.int64), np.zeros(C, np.int64)
        tabs, err, total = [], 0.0, 0
        for b in range(a["blk_h0"].size):
            hs = slice(a["blk_h0"][b], a["blk_h1"][b])
            cs = slice(a["blk_c0"][b], a["blk_c1"][b])
            tb = tabulate_umg(a["low"][hs, cs], a["high"][hs, cs], a["std"][hs, cs], a["point"][hs, cs],
                              resolution)
            T = np.zeros((tb["tab"].shape[0], H))
            T[:, hs] = tb["tab"]
            tabs.append(T)
            g0[cs], inv_h[cs], nG[cs], toff[cs] = tb["g0"], tb["inv_h"], tb["nG"], tb["toff"] + total
            total += T.shape[0]
            err = max(err, tb["error"])
        return {"tab": np.ascontiguousarray(np.vstack(tabs)), "g0": g0, "inv_h": inv_h, "nG": nG,
                "toff": toff, "table_error": err}

    def _setup(self, a: dict[str, Any]) -> None:
        """Install the arrays (and derived sparse forms) and reset to one run."""
        self.table_error = float(a.pop("table_error"))
        self._a = {k: np.ascontiguousarray(a[k], dtype=_ARRAYS[k][0]) for k in _ARRAYS}
        self.input_names = list(self.u_names) + list(self.y_names)
        self.table_bytes = int(self._a["tab"].nbytes)
        self._H = self._a["low"].shape[0]
        spans = {m: _colspans(self._a[k]) for m, k in (("A", "A"), ("B", "Bv"), ("C", "C"), ("D", "Dv"))}
        self._IP, self._FP = _pack(self._a, spans, self.hold, self.level,
                                   (self._a["C"].shape[0], self.warmup), (self.par_a, self.alpha))
        self._dens = np.ascontiguousarray(np.stack([self._a[k] for k in ("low", "high", "std", "logw")]))
        self.parallel = True
        self.reset(1)

    # ------------------------------------------------------------------ artifact
    def to_dict(self) -> dict[str, Any]:
        """Everything the runtime needs, as plain data (arrays for NPZ, the rest JSON).

        Examples
        --------
        >>> d = fused.to_dict()                               # doctest: +SKIP
        >>> same = FusedCarMonitor.from_dict(d)               # doctest: +SKIP
        """
        return {"format": FUSED_FORMAT, "u_names": list(self.u_names), "y_names": list(self.y_names),
                "filter_residual_names": list(self.filter_residual_names),
                "feature_names": list(self.feature_names),
                "hypotheses": list(self.hypotheses), "faults": list(self.faults),
                "output_names": list(self.output_names), "operating_point": dict(self.operating_point),
                "deviations": self.deviations, "dt": self.dt, "par_a": self.par_a, "alpha": self.alpha,
                "warmup": self.warmup, "hold": list(self.hold), "level": list(self.level),
                "table_error": self.table_error,
                "arrays": {k: v.copy() for k, v in self._a.items()}}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FusedCarMonitor:
        """Rebuild from :meth:`to_dict` (nothing is redesigned or recalibrated); every array's
        shape is checked against the channel, feature and hypothesis counts, and a mismatch is
        refused with a :class:`~fdikit.errors.DataError` naming the array.

        Examples
        --------
        >>> same = FusedCarMonitor.from_dict(fused.to_dict())       # doctest: +SKIP
        >>> np.array_equal(same.run(log).values, fused.run(log).values)   # doctest: +SKIP
        True
        """
        if d.get("format") != FUSED_FORMAT:
            raise DataError(f"FusedCarMonitor payload format {d.get('format')!r}, this fdikit reads "
                            f"{FUSED_FORMAT}")
        self = cls.__new__(cls)
        for k in ("u_names", "y_names", "filter_residual_names", "feature_names", "hypotheses", "faults",
                  "output_names"):
            setattr(self, k, [str(s) for s in d[k]])
        self.operating_point = {str(k): float(v) for k, v in d["operating_point"].items()}
        self.deviations = bool(d["deviations"])
        self.dt, self.par_a, self.alpha = (float(d[k]) for k in ("dt", "par_a", "alpha"))
        self.warmup = int(d["warmup"])
        F = len(self.faults)
        self.hold = [int(h) for h in np.broadcast_to(np.asarray(d["hold"]), (F,))]
        self.level = [float(v) for v in np.broadcast_to(np.asarray(d["level"], float), (F,))]
        arrays = dict(d["arrays"])
        missing = sorted(set(_ARRAYS) - set(arrays))
        if missing:
            raise DataError(f"FusedCarMonitor payload lacks arrays {missing}")
        a = {k: np.asarray(arrays[k]) for k in _ARRAYS}
        for k, (_dt, nd) in _ARRAYS.items():
            if a[k].ndim != nd:
                raise DataError(f"FusedCarMonitor array {k!r} has {a[k].ndim} dimensions, expected {nd}")
        nv, nx = len(self.u_names) + len(self.y_names), a["A"].shape[0]
        nr = len(self.filter_residual_names) - (2 if a["par_idx"][0] >= 0 else 0)
        H, C = len(self.hypotheses), len(self.feature_names)
        want = {"A": (nx, nx), "Bv": (nx, nv), "C": (nr, nx), "Dv": (nr, nv), "v0": (nv,), "pv0": (nv,),
                "par_idx": (4,), "low": (H, C), "high": (H, C), "std": (H, C), "point": (H, C),
                "logw": (H, C), "logp_pi": (H,), "x0": (C,), "g0": (C,), "inv_h": (C,), "nG": (C,),
                "toff": (C,), "f_starts": (C + 1,), "grp": (len(self.faults), a["grp"].shape[1])}
        for k, shape in want.items():
            if a[k].shape != shape:
                raise DataError(f"FusedCarMonitor array {k!r} has shape {a[k].shape}, expected {shape} for "
                                f"{nv} channels, {nx} filter states, {H} hypotheses and {C} features")
        if a["tab"].shape != (int(a["nG"].sum()), H):
            raise DataError(f"FusedCarMonitor density table has shape {a['tab'].shape}, expected "
                            f"({int(a['nG'].sum())}, {H})")
        if len(self.output_names) != 2 * len(self.faults):
            raise DataError("FusedCarMonitor outputs must be P:<fault> and A:<fault> for every fault")
        bad = [k for k in _ARRAYS if a[k].dtype.kind == "f" and k not in ("logp_pi", "logq", "g0") and
               not np.all(np.isfinite(a[k]))]
        if bad:
            raise DataError(f"FusedCarMonitor arrays {bad} hold non-finite values")
        a["table_error"] = d["table_error"]
        self._setup(a)
        return self

    # ------------------------------------------------------------------ runtime
    def reset(self, runs: int = 1) -> None:
        a = self._a
        self._xi = np.zeros((runs, a["A"].shape[0]))
        self._par = np.column_stack([np.zeros(runs), np.full(runs, np.nan)])
        self._feat = np.zeros((runs, a["x0"].size))
        self._logF = np.full((runs, self._H), -np.inf)
        for h in a["blk_h0"]:
            self._logF[:, h] = 0.0
        self._cnt = np.zeros((runs, len(self.faults)), np.int64)
        self._k = 0

    def resume(self, n_held: int) -> None:
        """Data returns after ``n_held`` held (bad) samples: re-enter the warm-up.

        Called by :class:`fdikit.monitor.Monitor` (``on_invalid="hold"``) at the first good sample
        after a gap. Over the gap the plant moved on while the filter states stood still, so the
        residuals carry a start-up transient again; as at the start of a record, the MHSSPTs see
        the nominal features for ``warmup`` samples while the filters re-converge (the
        probabilities relax towards no fault instead of announcing the transient). Without it a
        0.11 s gap on the curve gave false yaw-rate, steering and front-wheel announcements.
        """
        if n_held > 0:
            self._k = 0

    def _advance(self, V: np.ndarray) -> np.ndarray:
        if V.shape[0] != self._xi.shape[0]:
            raise DataError(f"sample has {V.shape[0]} runs; the monitor was reset for {self._xi.shape[0]}")
        out = np.empty((V.shape[0], V.shape[1], len(self.output_names)))
        # independent runs in parallel threads when there is enough work to share; the same
        # per-run arithmetic either way (batch = streaming bitwise)
        kernel = _fused_run_parallel if self.parallel and V.shape[0] > 1 and V.size > 4096 else _fused_run
        kernel(V, self._xi, self._par, self._feat, self._logF, self._cnt, out, self._IP, self._FP,
               self._a["tab"], self._dens, self._a["point"], self._a["grp"], self._k)
        self._k += V.shape[1]
        return out

    def _step_joined(self, v: np.ndarray) -> np.ndarray:
        """One checked sample (runs, len(input_names)) -> (runs, outputs); the entry point of
        :class:`fdikit.monitor.Monitor` (no re-checks, no split and re-join of u and y)."""
        return self._advance(np.ascontiguousarray(v[:, None]))[:, 0]

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        v = np.concatenate((u, y), axis=1) if u.shape[1] else y
        return self._advance(np.ascontiguousarray(v[:, None]))[:, 0]

    def step(self, u_k: Any, y_k: Any = None) -> np.ndarray:
        """One sample -> (runs, outputs).

        ``step(v_k)``: the full sample ``v_k`` (runs, len(input_names)) (or (n,) for one run);
        ``step(u_k, y_k)``: commands and measurements apart, as every residual generator.
        """
        if y_k is not None:
            return super().step(u_k, y_k)
        v = np.asarray(u_k, float)
        if v.ndim == 1:
            v = v[None]
        if v.ndim != 2 or v.shape[1] != len(self.input_names):
            raise DataError(f"sample must have shape (runs, {len(self.input_names)}) for channels "
                            f"{self.input_names}, got {v.shape}")
        return self._advance(np.ascontiguousarray(v[:, None]))[:, 0]

    def run(self, signals: Signals) -> Signals:
        """Batch over a record (all runs): ``signals`` holds :attr:`input_names` -> (runs, T, outputs)."""
        V = np.ascontiguousarray(signals.values[:, :, signals.index(self.input_names)])
        if not np.all(np.isfinite(V)):
            run, k, c = np.argwhere(~np.isfinite(V))[0]
            raise DataError(f"channel {self.input_names[c]!r} is not finite at sample {k} (run {run})")
        self.reset(signals.runs)
        return Signals(signals.t, self._advance(V), self.output_names, check=False)
