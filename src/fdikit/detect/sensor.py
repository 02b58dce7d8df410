"""Detectors for the sensor faults that real logs hold: stuck, drifting, scaled and intermittent.

Each is a :class:`~fdikit.base.stage.ResidualProcessor` whose output is its test statistic
*divided by its threshold*: the detector alarms where an output is ``>= 1`` (chain a
:class:`~fdikit.detect.Hold` with threshold 1 and ``absolute=False`` for a hold of ``Z`` samples).
A ``design_*`` function builds each one from nominal (fault-free) data: the nominal levels
(mean, variance) are estimated and the threshold is the level of the statistic on those data for
a target false-alarm rate (:func:`~fdikit.detect.design_threshold`; with ``pfa = 0``, the
default, just above the largest nominal value, times ``1 + margin``: what a short real record
can honestly support).

=======================  ==========================================================================
:class:`StuckDetector`   the measured signal has not moved (by more than ``tol``) since sample j,
                         while the model-expected signal moved by ``g = (max - min) / scale`` over
                         the same samples (without an expected signal: ``g`` = samples flat)
:class:`DriftDetector`   GLR of a ramp ``s (i - j + 1)`` starting from zero at an unknown sample
                         j in the window: ``g = max_j (sum tau_i r_i)^2 / (sigma^2 sum tau_i^2)``
:class:`GainDetector`    GLR of a gain: the residual proportional to the signal, ``r = theta s``
                         from sample j: ``g = max_j (sum r_i s_i)^2 / (sigma^2 sum s_i^2)``
:class:`IntermittentDetector`  bursts that come and go: episodes of ``|r - mu0| > level``
                         (ended once below ``release`` for ``gap`` samples) counted over the last
                         ``W`` samples; ``g = count / min_bursts``
=======================  ==========================================================================

Batch (:meth:`run`) and streaming (:meth:`reset` + :meth:`step`) run the same compiled kernel on
the same state, so they give identical numbers; the state is declared in ``_state_attrs``
(checkpoint and restore), and a non-finite sample is refused before any state changes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = [
    "DriftDetector",
    "GainDetector",
    "IntermittentDetector",
    "StuckDetector",
    "design_drift",
    "design_gain",
    "design_intermittent",
    "design_stuck",
]


# ---------------------------------------------------------------------------------- kernels
@njit(cache=True)
def _stuck_kernel(x, e, tol, inv_scale, has_e, nmin, out, anchor, pmin, pmax, n, started):  # pragma: no cover
    """x, e (R, T) measured and expected; state (R,) arrays; out (R, T)."""
    R, T = x.shape
    for r in range(R):
        for k in range(T):
            v = x[r, k]
            if started[r] == 0 or abs(v - anchor[r]) > tol:
                started[r] = 1
                anchor[r] = v
                pmin[r] = e[r, k]
                pmax[r] = e[r, k]
                n[r] = 0
            else:
                n[r] += 1
                if e[r, k] < pmin[r]:
                    pmin[r] = e[r, k]
                if e[r, k] > pmax[r]:
                    pmax[r] = e[r, k]
            if has_e:
                out[r, k] = (pmax[r] - pmin[r]) * inv_scale if n[r] >= nmin else 0.0
            else:
                out[r, k] = n[r] * inv_scale


#: Samples evaluated together by the window kernels: the candidate change points are swept once per
#: block, one vectorisable loop over the block's samples per candidate (their accumulators stay in
#: the L1/L2 cache). Long blocks spread the fixed cost of each candidate's loop (views, overlap
#: checks, remainder) over more samples: on the 1-minute, 50 Hz logs of the RAV4 monitor the
#: drift and gain kernels ran 20-30 % faster with 1024 than with 256.
_BLOCK = 1024
#: Blocks shorter than this (streaming, one sample at a time) take the plain per-sample loop.
_SCALAR_BELOW = 16
#: Relative band around the approximate step GLR of :func:`_ramp_kernel` within which the exact one
#: is computed (the approximation is within 3.01 * 2^-53 of it).
_STEP_BAND = 2.0**-40


@njit(cache=True)
def _ring_history(buf, p0, h, out):  # pragma: no cover
    """The last ``h`` samples of a ring buffer (next write at ``p0``), oldest first, into ``out[:h]``."""
    W = buf.size
    for i in range(h):
        q = p0 - h + i
        if q < 0:
            q += W
        out[i] = buf[q]


@njit(inline="always")
def _step_known(v, g):  # pragma: no cover
    """Whether ``v <= G``, with ``G = max_L a_L^2 / L`` the step GLR, is settled by its approximation
    ``g = max_L a_L^2 * (1 / L)`` (the sums and squares ``a_L^2`` the same, the quotient replaced by a
    product with the rounded reciprocal, one division less per candidate): then it is ``v <= g *
    (1 - _STEP_BAND)``.

    Each term is within a factor ``1 +- 3.01 u`` (u = 2^-53: the rounded reciprocal and product
    against the rounded quotient) of the exact one unless ``a_L^2`` is subnormal, so where ``g >=
    2^-900`` (a term that large is normal; a subnormal one is below both maxima) ``g`` is within that
    factor of ``G``, and a ``v`` outside the band ``g (1 +- 2^-40)`` compares with ``G`` as with
    ``g``. ``v = 0`` is always settled (0 or a NaN ``G``: ``v`` stays 0 either way). Not settled:
    ``v`` in the band (a tie), ``g`` tiny or NaN.
    """
    return v == 0.0 or (g >= 2.0**-900 and (v <= g * (1.0 - _STEP_BAND) or v > g * (1.0 + _STEP_BAND)))


@njit(cache=True, error_model="numpy")
def _ramp_kernel(x, mu0, W, Lmin, vs_step, out_p, out_m, buf, pos, cnt):  # pragma: no cover
    """One-sided ramp GLRs (unscaled): x (R, T, C) -> out_p, out_m (R, T, C); ring buffer state.
    With ``vs_step`` the statistic is 0 unless the best ramp explains the window better than the
    best step (``max_j ramp GLR > max_j step GLR``).

    For every sample k the sums over the last ``L = 1 .. n`` samples (n = the window filled so
    far, at most W) are accumulated backwards from the newest sample, ``s0 = sum r``, ``s1 = sum
    tau r`` (``s1 += s0``), and the GLRs ``s1^2 / sum tau^2`` (ramp) and ``s0^2 / L`` (step) are
    maximised over L. The maximum over the change point has no running form (every candidate
    start moves differently), so the work is O(W) per sample; it is done for a block of samples
    at once, the candidate L in the outer loop and the samples of the block in the inner one (no
    dependency between them: the compiler vectorises it), each sample's sums taken in the same
    order as one at a time, so the numbers are bitwise those of the per-sample loop. The
    candidates are taken two at a time (L, then L + 1, for every sample whose window holds both
    and when both are on the same side of ``Lmin``; otherwise alone): the accumulators are read
    and written once per pair. With ``vs_step`` the blocked loops keep the step GLR as
    ``a^2 * (1 / L)`` (no second division per candidate) and compute it exactly for the rare
    sample whose comparison that does not settle (:func:`_step_known`).
    """
    R, T, C = x.shape
    den = np.empty(W + 1)
    den[0] = 1.0
    rden = np.empty(W + 1)  # 1 / L: the blocked loops' step GLR is a * a * (1 / L), see below
    rden[0] = 1.0
    for L in range(1, W + 1):
        den[L] = L * (L + 1.0) * (2.0 * L + 1.0) / 6.0
        rden[L] = 1.0 / L
    B = min(_BLOCK, T)
    s0 = np.empty(B)
    s1 = np.empty(B)
    gp = np.empty(B)
    gm = np.empty(B)
    gs = np.empty(B)
    for r in range(R):
        for c in range(C):
            c0 = cnt[r, c]
            p0 = pos[r, c]
            h = min(c0, W - 1)  # the samples before this call that a window can still reach
            xl = np.empty(h + T)
            _ring_history(buf[r, c], p0, h, xl)
            m = mu0[c]
            for k in range(T):
                xl[h + k] = x[r, k, c] - m
            for k0 in range(0, T, _BLOCK):
                nb = min(_BLOCK, T - k0)
                if nb < _SCALAR_BELOW:
                    for j in range(nb):
                        k = k0 + j
                        n = min(c0 + k + 1, W)
                        a = 0.0
                        b = 0.0
                        vp = 0.0
                        vm = 0.0
                        vg = 0.0
                        for L in range(1, n + 1):
                            a += xl[h + k - L + 1]
                            b += a
                            if vs_step:
                                vs = a * a / L
                                if vs > vg:
                                    vg = vs
                            if L >= Lmin:
                                v = b * b / den[L]
                                if b > 0.0:
                                    if v > vp:
                                        vp = v
                                elif v > vm:
                                    vm = v
                        gp[j] = vp
                        gm[j] = vm
                        gs[j] = vg
                else:
                    s0[:nb] = 0.0
                    s1[:nb] = 0.0
                    gp[:nb] = 0.0
                    gm[:nb] = 0.0
                    gs[:nb] = 0.0
                    # the candidates two at a time (L, then L + 1: each sample's sums in the same
                    # order), the accumulators read and written once per pair
                    Lend = min(c0 + k0 + nb, W)
                    L = 1
                    while L <= Lend:
                        two = L < Lend and (L + 1 < Lmin or L >= Lmin)
                        js = max(0, L - c0 - 1 - k0)  # the block's samples whose window holds L samples
                        j2 = max(0, L - c0 - k0) if two else nb  # ... and L + 1 samples: they take both
                        for j in range(js, j2):  # L alone
                            a = s0[j] + xl[h + k0 - L + 1 + j]
                            s0[j] = a
                            b = s1[j] + a
                            s1[j] = b
                            if vs_step:
                                gs[j] = max(gs[j], a * a * rden[L])
                            if L >= Lmin:
                                v = b * b / den[L]
                                v1 = v if b > 0.0 else 0.0
                                gp[j] = max(gp[j], v1)
                                gm[j] = max(gm[j], v - v1)
                        if not two:
                            L += 1
                            continue
                        n = nb - j2
                        i0 = h + k0 - L + 1 + j2
                        x1, x2 = xl[i0:], xl[i0 - 1:]
                        a_, b_, g_ = s0[j2:], s1[j2:], gs[j2:]
                        r1, r2 = rden[L], rden[L + 1]
                        if L >= Lmin:
                            dn, dn2 = den[L], den[L + 1]
                            p_, m_ = gp[j2:], gm[j2:]
                            if vs_step:
                                for j in range(n):
                                    a = a_[j] + x1[j]
                                    b = b_[j] + a
                                    g = max(g_[j], a * a * r1)
                                    v = b * b / dn
                                    v1 = v if b > 0.0 else 0.0
                                    p = max(p_[j], v1)
                                    m = max(m_[j], v - v1)
                                    a = a + x2[j]
                                    b = b + a
                                    g_[j] = max(g, a * a * r2)
                                    v = b * b / dn2
                                    v1 = v if b > 0.0 else 0.0
                                    p_[j] = max(p, v1)
                                    m_[j] = max(m, v - v1)
                                    a_[j] = a
                                    b_[j] = b
                            else:  # no step alternative: its GLR is not needed
                                for j in range(n):
                                    a = a_[j] + x1[j]
                                    b = b_[j] + a
                                    v = b * b / dn
                                    v1 = v if b > 0.0 else 0.0
                                    p = max(p_[j], v1)
                                    m = max(m_[j], v - v1)
                                    a = a + x2[j]
                                    b = b + a
                                    v = b * b / dn2
                                    v1 = v if b > 0.0 else 0.0
                                    p_[j] = max(p, v1)
                                    m_[j] = max(m, v - v1)
                                    a_[j] = a
                                    b_[j] = b
                        elif vs_step:
                            for j in range(n):
                                a = a_[j] + x1[j]
                                b = b_[j] + a
                                g = max(g_[j], a * a * r1)
                                a = a + x2[j]
                                a_[j] = a
                                b_[j] = b + a
                                g_[j] = max(g, a * a * r2)
                        else:
                            for j in range(n):
                                a = a_[j] + x1[j]
                                b = b_[j] + a
                                a = a + x2[j]
                                a_[j] = a
                                b_[j] = b + a
                        L += 2
                for j in range(nb):
                    vp = gp[j]
                    vm = gm[j]
                    if vs_step:  # a step from some sample explains the window better: not a drift
                        # gs[j] approximates the step GLR (see _step_known); where that does not
                        # settle the comparison (a tie, a tiny or NaN gs[j]), the GLR is computed
                        g = gs[j]
                        lo = g * (1.0 - _STEP_BAND)
                        if not (_step_known(vp, g) and _step_known(vm, g)):
                            k = k0 + j
                            a = 0.0
                            g = 0.0
                            for L in range(1, min(c0 + k + 1, W) + 1):
                                a += xl[h + k - L + 1]
                                g = max(g, a * a / L)
                            lo = g
                        if vp <= lo:
                            vp = 0.0
                        if vm <= lo:
                            vm = 0.0
                    out_p[r, k0 + j, c] = vp
                    out_m[r, k0 + j, c] = vm
            # the ring buffer as writing the samples one by one leaves it
            for k in range(max(0, T - W), T):
                buf[r, c, (p0 + k) % W] = xl[h + k]
            pos[r, c] = (p0 + T) % W
            cnt[r, c] = min(c0 + T, W)


@njit(inline="always")
def _gain_update(a, b2, z, mg, be, ab, bb, g, gm):  # pragma: no cover
    """One candidate of :func:`_gain_kernel` for one sample: ``a = sum r s``, ``b2 = sum s^2``;
    the first maximum of ``a^2 / b2`` (and its sums) and the one-sided maxima, updated."""
    ok = b2 > 0.0
    v = a * a / b2
    up = ok & (v > be)  # the first maximum: the gain estimate's sums
    be = v if up else be
    ab = a if up else ab
    bb = b2 if up else bb
    # |theta| below the indifference zone: not a fault
    vg = v if (ok & ((mg <= 0.0) | (abs(a) >= z * b2))) else 0.0
    v1 = vg if a > 0.0 else 0.0
    return be, ab, bb, max(g, v1), max(gm, vg - v1)


@njit(cache=True, error_model="numpy")
def _gain_kernel(x, s, mu0, W, Lmin, mg, gsc, out_p, out_m, est, bx, bs, pos, cnt):  # pragma: no cover
    """One-sided gain GLRs (unscaled): residuals x (R, T, C) against the signal s (R, T) -> out_p,
    out_m, est (R, T, C); ring buffers bx (R, C, W), bs (R, W).

    As :func:`_ramp_kernel`: per sample the sums ``a = sum r s`` and ``bb = sum s^2`` over the
    last ``L`` samples are accumulated backwards from the newest one and ``a^2 / bb`` maximised
    over L (``theta = a / bb`` at the first maximum), for a block of samples at once with the
    samples in the inner, vectorised loop and the candidates two at a time (:func:`_gain_update`
    for each, in turn); bitwise the per-sample loop's numbers.
    """
    R, T, C = x.shape
    B = min(_BLOCK, T)
    A = np.empty((C, B))
    G = np.empty((C, B))
    GM = np.empty((C, B))
    BE = np.empty((C, B))
    AB = np.empty((C, B))
    BB = np.empty((C, B))
    bb = np.empty(B)
    Q1 = np.empty(B)
    zone = np.empty(C)
    for c in range(C):
        zone[c] = mg * gsc[c]
    for r in range(R):
        c0 = cnt[r]
        p0 = pos[r]
        h = min(c0, W - 1)
        sl = np.empty(h + T)
        xl = np.empty((C, h + T))
        _ring_history(bs[r], p0, h, sl)
        for c in range(C):
            _ring_history(bx[r, c], p0, h, xl[c])
        for k in range(T):
            sl[h + k] = s[r, k]
            for c in range(C):
                xl[c, h + k] = x[r, k, c] - mu0[c]
        for k0 in range(0, T, _BLOCK):
            nb = min(_BLOCK, T - k0)
            if nb < _SCALAR_BELOW:
                for j in range(nb):
                    k = k0 + j
                    n = min(c0 + k + 1, W)
                    for c in range(C):
                        a = 0.0
                        b2 = 0.0
                        g = 0.0
                        gm = 0.0
                        best = -1.0
                        th = 0.0
                        for L in range(1, n + 1):
                            i = h + k - L + 1
                            a += xl[c, i] * sl[i]
                            b2 += sl[i] * sl[i]
                            if L >= Lmin and b2 > 0.0:
                                v = a * a / b2
                                if v > best:
                                    best = v
                                    th = a / b2
                                if mg > 0.0 and abs(a) < zone[c] * b2:
                                    continue  # |theta| below the indifference zone: not a fault
                                if a > 0.0:
                                    if v > g:
                                        g = v
                                elif v > gm:
                                    gm = v
                        out_p[r, k, c] = g
                        out_m[r, k, c] = gm
                        est[r, k, c] = th
                continue
            bb[:nb] = 0.0
            A[:, :nb] = 0.0
            G[:, :nb] = 0.0
            GM[:, :nb] = 0.0
            BE[:, :nb] = -1.0
            AB[:, :nb] = 0.0
            BB[:, :nb] = 1.0
            # the candidates two at a time (L, then L + 1: each sample's sums in the same order), the
            # accumulators read and written once per pair
            Lend = min(c0 + k0 + nb, W)
            L = 1
            while L <= Lend:
                two = L < Lend and (L + 1 < Lmin or L >= Lmin)
                js = max(0, L - c0 - 1 - k0)  # the block's samples whose window holds L samples
                j2 = max(0, L - c0 - k0) if two else nb  # ... and L + 1 samples: they take both
                for j in range(js, j2):  # L alone
                    i = h + k0 - L + 1 + j
                    b2 = bb[j] + sl[i] * sl[i]
                    bb[j] = b2
                    for c in range(C):
                        a = A[c, j] + xl[c, i] * sl[i]
                        A[c, j] = a
                        if L >= Lmin:
                            BE[c, j], AB[c, j], BB[c, j], G[c, j], GM[c, j] = _gain_update(
                                a, b2, zone[c], mg, BE[c, j], AB[c, j], BB[c, j], G[c, j], GM[c, j]
                            )
                if not two:
                    L += 1
                    continue
                n = nb - j2
                i0 = h + k0 - L + 1 + j2
                s1, s2 = sl[i0:], sl[i0 - 1:]
                q_, q1_ = bb[j2:], Q1[j2:]
                for j in range(n):
                    q1 = q_[j] + s1[j] * s1[j]
                    q1_[j] = q1
                    q_[j] = q1 + s2[j] * s2[j]
                for c in range(C):
                    x1, x2 = xl[c, i0:], xl[c, i0 - 1:]
                    a_ = A[c, j2:]
                    if L < Lmin:
                        for j in range(n):
                            a_[j] = (a_[j] + x1[j] * s1[j]) + x2[j] * s2[j]
                        continue
                    g_, gm_, be_, ab_, bb_ = G[c, j2:], GM[c, j2:], BE[c, j2:], AB[c, j2:], BB[c, j2:]
                    z = zone[c]
                    for j in range(n):
                        a = a_[j] + x1[j] * s1[j]
                        be, ab, b_, g, gm = _gain_update(
                            a, q1_[j], z, mg, be_[j], ab_[j], bb_[j], g_[j], gm_[j]
                        )
                        a = a + x2[j] * s2[j]
                        be, ab, b_, g, gm = _gain_update(a, q_[j], z, mg, be, ab, b_, g, gm)
                        a_[j] = a
                        be_[j] = be
                        ab_[j] = ab
                        bb_[j] = b_
                        g_[j] = g
                        gm_[j] = gm
                L += 2
            for c in range(C):
                for j in range(nb):
                    out_p[r, k0 + j, c] = G[c, j]
                    out_m[r, k0 + j, c] = GM[c, j]
                    est[r, k0 + j, c] = AB[c, j] / BB[c, j] if BE[c, j] > -1.0 else 0.0
        for k in range(max(0, T - W), T):
            q = (p0 + k) % W
            bs[r, q] = sl[h + k]
            for c in range(C):
                bx[r, c, q] = xl[c, h + k]
        pos[r] = (p0 + T) % W
        cnt[r] = min(c0 + T, W)


#: The last evaluation of :func:`_gain_run` (its inputs and results), or None.
_GAIN_LAST: list = [None]
#: Only calls of at least this many samples, and at most this many values (runs x samples x
#: residuals), are remembered (streaming steps gain nothing; a huge batch would hold its memory).
_GAIN_MEMO_MIN, _GAIN_MEMO_MAX = 64, 1 << 20


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bitwise equality of two float64 arrays (``-0.0`` is not ``0.0`` here)."""
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _gain_run(x, s, mu0, W, Lmin, mg, gsc, bx, bs, pos, cnt) -> np.ndarray:
    """:func:`_gain_kernel` over residuals x (R, T, C) and the signal s (R, T), the state (bx, bs,
    pos, cnt) advanced in place: the stacked ``(out_p, out_m, est)`` as a read-only (3, R, T, C).

    Several detectors often test the same residuals against the same signal (a monitor's gain
    checks of the front and rear wheels share the wheel-speed residuals, and differ only in a
    residual's ``gain_scale``). A residual's outputs and state depend only on its own column, its
    ``mu0`` and ``gain_scale``, its ring buffer, and the shared signal, signal buffer, position,
    count, ``W``, ``Lmin`` and ``min_gain``: where all of these are bitwise those of the previous
    call's residual, its results are copied from that call instead of computed again (the kernel
    runs on the other residuals only), so the numbers are exactly the kernel's.
    """
    R, T, C = x.shape
    out = np.empty((3, R, T, C))
    if not (_GAIN_MEMO_MIN <= T and R * T * C <= _GAIN_MEMO_MAX):
        _gain_kernel(x, s, mu0, W, Lmin, mg, gsc, out[0], out[1], out[2], bx, bs, pos, cnt)
        out.flags.writeable = False
        return out
    shared = (W, Lmin, np.float64(mg).tobytes())
    last = _GAIN_LAST[0]
    found = {}  # channel -> the previous call's channel with the same inputs
    if last is not None and last["shared"] == shared and _same(last["s"], s) \
            and _same(last["bs0"], bs) and _same(last["pos0"], pos) and _same(last["cnt0"], cnt):
        for c in range(C):
            key = (mu0[c].tobytes(), gsc[c].tobytes())
            for ce, kc in enumerate(last["keys"]):
                if kc == key and _same(last["x"][:, :, ce], x[:, :, c]) \
                        and _same(last["bx0"][:, ce], bx[:, c]):
                    found[c] = ce
                    break
    memo = dict(shared=shared, s=s.copy(), bs0=bs.copy(), pos0=pos.copy(), cnt0=cnt.copy(),
                keys=[(mu0[c].tobytes(), gsc[c].tobytes()) for c in range(C)], x=x.copy(), bx0=bx.copy())
    todo = [c for c in range(C) if c not in found]
    if len(todo) == C:
        _gain_kernel(x, s, mu0, W, Lmin, mg, gsc, out[0], out[1], out[2], bx, bs, pos, cnt)
    else:
        for c, ce in found.items():
            out[:, :, :, c] = last["out"][:, :, :, ce]
            bx[:, c] = last["bx1"][:, ce]
        if todo:
            i = np.array(todo)
            o = np.empty((3, R, T, i.size))
            bxi = np.ascontiguousarray(bx[:, i])
            _gain_kernel(np.ascontiguousarray(x[:, :, i]), s, mu0[i], W, Lmin, mg, gsc[i], o[0], o[1], o[2],
                         bxi, bs, pos, cnt)
            out[:, :, :, i] = o
            bx[:, i] = bxi
        else:  # the shared state as the previous call left it
            bs[...] = last["bs1"]
            pos[...] = last["pos1"]
            cnt[...] = last["cnt1"]
    out.flags.writeable = False
    memo.update(out=out, bx1=bx.copy(), bs1=bs.copy(), pos1=pos.copy(), cnt1=cnt.copy())
    _GAIN_LAST[0] = memo
    return out


@njit(cache=True)
def _burst_kernel(x, mu0, side, level, release, gap, W, out, on, quiet, buf, pos, cnt):  # pragma: no cover
    """Burst counts: x (R, T, C) -> out (R, T, C) onsets within the last W samples (``side`` 0:
    |r - mu0|; +-1: the signed deviation)."""
    R, T, C = x.shape
    for r in range(R):
        for c in range(C):
            for k in range(T):
                d = x[r, k, c] - mu0[c]
                a = abs(d) if side[c] == 0 else side[c] * d
                onset = 0
                if on[r, c] == 0:
                    if a > level[c]:
                        on[r, c] = 1
                        quiet[r, c] = 0
                        onset = 1
                else:
                    if a < release[c]:
                        quiet[r, c] += 1
                        if quiet[r, c] >= gap:
                            on[r, c] = 0
                    else:
                        quiet[r, c] = 0
                p = pos[r, c]
                cnt[r, c] += onset - buf[r, c, p]
                buf[r, c, p] = onset
                pos[r, c] = (p + 1) % W
                out[r, k, c] = cnt[r, c]


@njit(inline="always")
def _min_nan(a, b):  # pragma: no cover
    """``np.minimum(a, b)``: a NaN operand is the result."""
    return a if (a <= b or a != a) else b


@njit(inline="always")
def _max_nan(a, b):  # pragma: no cover
    """``np.maximum(a, b)``: a NaN operand is the result."""
    return a if (a >= b or a != a) else b


@njit(cache=True)
def _combine_kernel(gp, gm, sigma2, sigs, thr, sides, out):  # pragma: no cover
    """Combined one-sided statistics: gp, gm (R, T, C) unscaled -> out (R, T, 1 or 4).

    With ``q = g / sigma2`` per channel, the statistic of a signature in its direction is the
    least ``q+`` (``q-``) over its channels with a positive (negative) entry, and in the opposite
    direction the same with the signs swapped; ``up`` and ``down`` are those of ``sigs[0]``, set
    to 0 wherever a rival ``sigs[i]``, ``i >= 1``, has ``max(its up, its down) >= them`` (in turn).
    ``out[..., 0]`` is ``max(up / thr, down / thr)`` with ``sides`` (and then ``out[..., 2:4]``
    the two), else ``max(up, down) / thr``. Sample by sample, the numbers of the numpy
    expressions it replaces (:meth:`GainDetector._compute`, :meth:`DriftDetector._compute`):
    the same divisions, and minima and maxima that pass a NaN on as numpy's do.
    """
    R, T, C = gp.shape
    K = sigs.shape[0]
    qp = np.empty(C)
    qm = np.empty(C)
    for r in range(R):
        for k in range(T):
            for c in range(C):
                qp[c] = gp[r, k, c] / sigma2[c]
                qm[c] = gm[r, k, c] / sigma2[c]
            up = 0.0
            down = 0.0
            for i in range(K):
                u = 0.0
                d = 0.0
                seen = False
                for c in range(C):
                    sg = sigs[i, c]
                    if sg == 0.0:
                        continue
                    p = qp[c]
                    m = qm[c]
                    if not sg > 0.0:
                        p, m = m, p
                    if seen:
                        u = _min_nan(u, p)
                        d = _min_nan(d, m)
                    else:
                        u = p
                        d = m
                        seen = True
                if i == 0:
                    up = u
                    down = d
                else:  # another fault explains the residuals as well: not this one
                    best = _max_nan(u, d)
                    if best >= up:
                        up = 0.0
                    if best >= down:
                        down = 0.0
            if sides:
                up = up / thr
                down = down / thr
                out[r, k, 0] = _max_nan(up, down)
                out[r, k, 2] = up
                out[r, k, 3] = down
            else:
                out[r, k, 0] = _max_nan(up, down) / thr


# ---------------------------------------------------------------------------------- helpers
def _per_channel(v: Any, c: int, what: str, names: Sequence[str], positive: bool = False) -> np.ndarray:
    a = np.asarray(v, float)
    if a.ndim > 1 or (a.ndim == 1 and a.size != c):
        raise DataError(
            f"{what} must be a scalar or one value per channel {list(names)}, got shape {a.shape}"
        )
    a = np.broadcast_to(a, (c,)).copy()
    if not np.all(np.isfinite(a)):
        raise DataError(f"{what} must be finite, got {a.tolist()}")
    if positive and np.any(a <= 0):
        bad = names[int(np.argmax(a <= 0))]
        raise DataError(f"{what} must be positive; channel {bad!r} has {a[int(np.argmax(a <= 0))]}")
    return a


def _window(W: Any, what: str) -> int:
    if isinstance(W, bool) or int(W) != W or W < 1:
        raise DataError(f"{what} must be an integer >= 1, got {W!r}")
    return int(W)


class _SensorDetector(ResidualProcessor):
    """Shared plumbing: checked samples, run length bookkeeping, repr."""

    _what = "detector"

    def _check(self, x: np.ndarray, k0: int) -> None:
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(
                f"{type(self).__name__} input {self.input_names[c]!r} is not finite at sample "
                f"{k0 + k} (run {run})"
            )

    def _runs(self, r: np.ndarray) -> None:
        if r.shape[0] != self._R:
            raise DataError(
                f"sample has {r.shape[0]} runs; the {type(self).__name__} was reset for {self._R}"
            )

    def _set_warmup(self, warmup: Any) -> None:
        if isinstance(warmup, bool) or int(warmup) != warmup or warmup < 0:
            raise DataError(f"{type(self).__name__} warmup must be an integer >= 0 (samples), got {warmup!r}")
        self.warmup = int(warmup)

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        self._check(x, 0)
        self.reset(signals.runs)
        T = signals.n_samples
        w = min(self.warmup, T)
        out = np.zeros((signals.runs, T, len(self.output_names)))
        if T > w:
            out[:, w:] = self._compute(np.ascontiguousarray(x[:, w:]))
        self._k = T
        return Signals(signals.t, out, self.output_names, check=False)

    def _step(self, r: np.ndarray) -> np.ndarray:
        self._runs(r)
        self._check(r[:, None, :], self._k)
        if self._k < self.warmup:  # warm-up: the sample is not taken in, nothing is tested
            self._k += 1
            return np.zeros((r.shape[0], len(self.output_names)))
        out = self._compute(np.ascontiguousarray(r[:, None, :]))
        self._k += 1
        return out[:, 0]

    def resume(self, n_held: int) -> None:
        """After ``n_held`` held (invalid) samples: start again, with the warm-up (the window would
        span the gap)."""
        self.reset(self._R)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._repr_items())
        return f"{type(self).__name__}({args})"

    def to_dict(self) -> dict:
        """Configuration as plain data (see :mod:`fdikit.base.artifacts`)."""
        return dict(self._repr_items())

    @classmethod
    def from_dict(cls, d: dict) -> Any:
        return cls(**d)


# ---------------------------------------------------------------------------------- stuck
class StuckDetector(_SensorDetector):
    """A measured signal that stopped moving while the model says it should move.

    A *flat run* starts whenever the measured signal moves by more than ``tol`` from the value at
    the run's start (the anchor). Over the current flat run the statistic is the range of the
    expected signal, ``g = (max e - min e) / scale``: how far the model (another sensor, a
    prediction of this one) moved while the sensor did not. A quantised signal legitimately
    repeats its value when nothing happens (a steering wheel held straight), and then the expected
    signal does not move either, so ``g`` stays small. Without an expected signal the statistic is
    the number of samples the signal has been flat (the "recent past" test: a signal that never
    stays frozen this long in nominal data).

    Parameters
    ----------
    measured : str
        The measured channel.
    expected : str, optional
        A channel in the same units that the model expects the measurement to follow (low-pass it
        if it is noisy: its range over the flat run is the evidence).
    tol : float
        Largest change of the measurement still counted as "not moved" (its quantisation step, or
        0 for exact repetition), in its units.
    scale : float
        Unit of ``g``: the expected signal's range (units of the signal), or samples without one.
    threshold : float
        Threshold of ``g`` (in units of ``scale``); the output is ``g / threshold``.
    min_samples : int
        With an expected signal: ``g`` counts only once the flat run has lasted this many
        samples (longer than the signal is ever frozen in nominal data; 0: always).
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Outputs ``"<measured>:stuck"`` (alarm at >= 1).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(8.0)
    >>> x = [0, 1, 2, 3, 3, 3, 3, 3]                       # frozen from sample 3
    >>> e = [0, 1, 2, 3, 4, 5, 6, 7]                       # ... the model says it kept rising
    >>> d = StuckDetector("x", "e", threshold=2.0)
    >>> d.run(Signals(t, np.c_[x, e], ["x", "e"]))["x:stuck"].tolist()
    [[0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.5, 2.0]]
    """

    _state_attrs = ("_anchor", "_pmin", "_pmax", "_n", "_started", "_k", "_R")

    def __init__(
        self,
        measured: str,
        expected: str | None = None,
        *,
        tol: float = 0.0,
        scale: float = 1.0,
        threshold: float = 1.0,
        min_samples: int = 0,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        if isinstance(min_samples, bool) or int(min_samples) != min_samples or min_samples < 0:
            raise DataError(f"StuckDetector min_samples must be an integer >= 0, got {min_samples!r}")
        self.min_samples = int(min_samples)
        self.measured = str(measured)
        self.expected = None if expected is None else str(expected)
        self.input_names = [self.measured] + ([self.expected] if self.expected is not None else [])
        if self.expected == self.measured:
            raise DataError(
                f"StuckDetector: the expected channel must differ from the measured one ({self.measured!r})"
            )
        for name, v in (("tol", tol), ("scale", scale), ("threshold", threshold)):
            if not np.isfinite(v) or v < 0 or (name != "tol" and v == 0):
                raise DataError(
                    f"StuckDetector {name} must be finite and {'>= 0' if name == 'tol' else '> 0'}, got {v}"
                )
        self.tol, self.scale, self.threshold = float(tol), float(scale), float(threshold)
        self.output_names = [f"{self.measured}:stuck"]
        self.reset(1)

    def _repr_items(self):
        return [
            ("measured", self.measured),
            ("expected", self.expected),
            ("tol", self.tol),
            ("scale", self.scale),
            ("threshold", self.threshold),
            ("min_samples", self.min_samples),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        self._R = int(runs)
        self._anchor = np.zeros(runs)
        self._pmin = np.zeros(runs)
        self._pmax = np.zeros(runs)
        self._n = np.zeros(runs, np.int64)
        self._started = np.zeros(runs, np.int64)
        self._k = 0

    def _compute(self, x: np.ndarray) -> np.ndarray:
        R, T, _ = x.shape
        m = np.ascontiguousarray(x[:, :, 0])
        e = np.ascontiguousarray(x[:, :, 1]) if self.expected is not None else m
        out = np.empty((R, T))
        _stuck_kernel(
            m,
            e,
            self.tol,
            1.0 / (self.scale * self.threshold),
            self.expected is not None,
            self.min_samples,
            out,
            self._anchor,
            self._pmin,
            self._pmax,
            self._n,
            self._started,
        )
        return out[:, :, None]


# ---------------------------------------------------------------------------------- drift
class DriftDetector(_SensorDetector):
    """GLR of a drift: a ramp that grows from zero at an unknown sample in a moving window.

    For each residual channel, with ``r_i`` the residual minus its nominal mean ``mu0`` and the
    ramp ``s tau_i``, ``tau_i = i - j + 1`` from a change at sample ``j``::

        g_k = max_{k-W+1 <= j <= k-Lmin+1} (sum_{i=j..k} tau_i r_i)^2 / (sigma^2 sum tau_i^2)

    (the maximum over the slope is in closed form, ``s = sum tau r / sum tau^2``). The sums are
    accumulated backwards from the newest sample, O(W) per sample, nothing carried over between
    samples but the window itself. A one-sided statistic is kept per sign of the slope.

    ``signature`` turns the per-channel tests into one test of a fault direction: a fault that
    ramps every channel with ``signature != 0`` with the sign of its entry (a drifting yaw-rate
    sensor ramps both the residual against the wheel speeds and the one against the
    accelerometer; a fault of one of those sensors ramps only one of them). The combined
    statistic is the weakest of the channels' one-sided statistics in the signature's direction
    (or in the opposite one, whichever is larger), so every channel of the signature must see
    the ramp.

    Parameters
    ----------
    inputs : sequence of str
        Residual channels.
    W : int
        Window (samples): the longest ramp considered.
    mu0, sigma2 : float or sequence
        Nominal mean and variance of each residual.
    threshold : float or sequence
        Threshold of ``g`` (per channel; one value for the combined test with ``signature``).
    min_length : int
        Shortest ramp considered (samples): a one-sample "ramp" is a spike.
    signature : sequence of {-1, 0, 1}, optional
        The fault direction; with it the detector has ONE output.
    name : str, optional
        Name of the combined output (default the first input).
    vs_step : bool
        The statistic is 0 unless the best ramp explains the window better than the best step
        (a change of the mean, the GLR of :class:`~fdikit.detect.GLRT`) over the same candidate
        changes: a drift is told from a bias (for a pure step the best ramp reaches 8/9 of the
        step's GLR, for a pure ramp the best step 8/9 of the ramp's), at some loss of power.
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Outputs ``"<input>:drift"`` per input, or ``"<name>:drift"`` with a signature (alarm at >= 1).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(40.0)
    >>> r = np.where(t >= 20, 0.1 * (t - 19), 0.0)         # a ramp from sample 20
    >>> d = DriftDetector(["r"], W=20, sigma2=0.01, threshold=50.0)
    >>> g = d.run(Signals(t, r, ["r"]))["r:drift"][0]
    >>> int(np.argmax(g >= 1))                             # s^2 L(L+1)(2L+1)/6 / sigma^2 >= 50
    24
    """

    _state_attrs = ("_buf", "_pos", "_cnt", "_k", "_R")

    def __init__(
        self,
        inputs: Sequence[str],
        W: int = 500,
        mu0=0.0,
        sigma2=1.0,
        threshold=1.0,
        *,
        min_length: int = 1,
        signature: Sequence[float] | None = None,
        name: str | None = None,
        vs_step: bool = False,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        self.input_names = [str(s) for s in ([inputs] if isinstance(inputs, str) else inputs)]
        self.vs_step = bool(vs_step)
        c = len(self.input_names)
        if c == 0:
            raise DataError("DriftDetector needs at least one input channel")
        self.W = _window(W, "DriftDetector window W")
        self.min_length = _window(min_length, "DriftDetector min_length")
        if self.min_length > self.W:
            raise DataError(f"DriftDetector min_length ({self.min_length}) must be <= W ({self.W})")
        self.mu0 = _per_channel(mu0, c, "DriftDetector mu0", self.input_names)
        self.sigma2 = _per_channel(sigma2, c, "DriftDetector sigma2", self.input_names, positive=True)
        if signature is not None:
            sg = np.sign(np.asarray(signature, float))
            if sg.shape != (c,) or not np.any(sg != 0):
                raise DataError(
                    f"DriftDetector signature must have one entry -1/0/+1 per input "
                    f"{self.input_names} and at least one non-zero, got {list(signature)}"
                )
            self.signature = sg
            self.threshold = _per_channel(
                threshold, 1, "DriftDetector threshold", ["combined"], positive=True
            )
            self.name = str(name) if name is not None else self.input_names[0]
            self.output_names = [f"{self.name}:drift"]
        else:
            self.signature = None
            self.threshold = _per_channel(
                threshold, c, "DriftDetector threshold", self.input_names, positive=True
            )
            self.name = name
            self.output_names = [f"{s}:drift" for s in self.input_names]
        self.reset(1)

    def _repr_items(self):
        return [
            ("inputs", list(self.input_names)),
            ("W", self.W),
            ("mu0", self.mu0.tolist()),
            ("sigma2", self.sigma2.tolist()),
            ("threshold", self.threshold.tolist()),
            ("min_length", self.min_length),
            ("signature", None if self.signature is None else self.signature.tolist()),
            ("name", self.name),
            ("vs_step", self.vs_step),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        c = len(self.input_names)
        self._R = int(runs)
        self._buf = np.zeros((runs, c, self.W))
        self._pos = np.zeros((runs, c), np.int64)
        self._cnt = np.zeros((runs, c), np.int64)
        self._k = 0

    def _advance(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance over ``x`` (runs, T, C): the unscaled one-sided statistics."""
        R, T, C = x.shape
        gp, gm = np.empty((R, T, C)), np.empty((R, T, C))
        _ramp_kernel(
            x, self.mu0, self.W, self.min_length, self.vs_step, gp, gm, self._buf, self._pos, self._cnt
        )
        return gp, gm

    def one_sided(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance over ``x`` (runs, T, C): the scaled one-sided statistics ``(g_plus, g_minus)``."""
        gp, gm = self._advance(x)
        return gp / self.sigma2, gm / self.sigma2

    def _compute(self, x: np.ndarray) -> np.ndarray:
        if self.signature is None:
            gp, gm = self.one_sided(x)
            return np.maximum(gp, gm) / self.threshold
        gp, gm = self._advance(x)
        # the weakest channel in the signature's direction and in the opposite one, the larger
        out = np.empty((x.shape[0], x.shape[1], 1))
        _combine_kernel(gp, gm, self.sigma2, self.signature[None, :], self.threshold[0], False, out)
        return out


# ---------------------------------------------------------------------------------- gain
class GainDetector(_SensorDetector):
    """GLR of a gain (scale-factor) fault: residuals that grow in proportion to a signal.

    A sensor reading ``(1 + theta) y`` instead of ``y`` adds ``theta y`` to a residual that
    compares it with the others. From an unknown sample ``j`` in the window, per residual::

        g_k = max_{k-W+1 <= j <= k-Lmin+1} (sum_{i=j..k} r_i s_i)^2 / (sigma^2 sum_{i=j..k} s_i^2)

    with ``r_i`` the residual minus ``mu0`` and ``s_i`` the signal; the gain estimate at the
    maximising ``j`` is ``theta = sum r s / sum s^2``. One-sided statistics are kept per sign of
    ``theta`` (which sensor of a left-minus-right difference is scaled).

    ``signature`` (as :class:`DriftDetector`'s) makes one test of a fault that moves several
    residuals: the combined statistic is the weakest of the residuals' one-sided statistics in
    the signature's direction (``gain+``) or the opposite one (``gain-``), so a fault of another
    sensor that moves only one of the residuals is not taken for this one.

    Parameters
    ----------
    residuals : str or sequence of str
        The residual channel(s).
    signal : str
        The signal the fault is proportional to.
    W : int
        Window (samples).
    mu0, sigma2 : float or sequence
        Nominal mean and variance of each residual.
    threshold : float or sequence
        Threshold of ``g`` (per residual; one value with ``signature``).
    min_length : int
        Fewest samples of a candidate change.
    signature : sequence of {-1, 0, 1}, optional
        The fault direction over the residuals; with it the detector has one set of outputs.
    name : str, optional
        Name of the combined outputs (default the first residual).
    min_gain : float
        Indifference zone: a candidate change counts only where the estimated gain of the residual
        is at least ``min_gain * gain_scale`` in magnitude (a scale error too small to matter --
        or a slow wander of coloured noise that the GLR, scaled by the white-noise variance,
        over-rates -- is not a fault). 0 (default): the plain GLR. :func:`design_gain` calibrates
        the threshold on the plain GLR, so the zone only removes alarms.
    gain_scale : float or sequence
        Per residual, how much of the gain reaches it (``r = gain_scale * theta * s``; e.g. 1 for
        a wheel-speed difference, ``k_f / k_r`` for the other axle's scaled difference).
    rivals : sequence of signatures
        Signatures of other faults over the same residuals (with a signature): where one of them
        explains the residuals at least as well (its combined statistic is as large), the output
        is 0 -- a fault of another sensor that also moves all of this signature's residuals is
        not taken for this one.
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Outputs per residual (or once, ``"<name>:..."``, with a signature): ``"<residual>:gain"``
    (``g / threshold``, alarm at >= 1), ``"<residual>:gain_est"`` (theta at the most likely change;
    of the first residual of the signature), and the one-sided ``"<residual>:gain+"`` and
    ``"<residual>:gain-"`` over the threshold.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(30.0)
    >>> s = 20.0 + np.sin(t)                                # a speed, m/s
    >>> r = np.where(t >= 10, 0.02 * s, 0.0)                # +2 % on one sensor from sample 10
    >>> out = GainDetector("r", "s", W=20, sigma2=0.01, threshold=100.0).run(
    ...     Signals(t, np.c_[r, s], ["r", "s"]))
    >>> int(np.argmax(out["r:gain"][0] >= 1)), round(float(out["r:gain_est"][0, -1]), 6)
    (16, 0.02)
    """

    _state_attrs = ("_bx", "_bs", "_pos", "_cnt", "_k", "_R")

    def __init__(
        self,
        residuals,
        signal: str,
        W: int = 250,
        mu0=0.0,
        sigma2=1.0,
        threshold=1.0,
        *,
        min_length: int = 1,
        signature: Sequence[float] | None = None,
        name: str | None = None,
        rivals: Sequence[Sequence[float]] = (),
        min_gain: float = 0.0,
        gain_scale=1.0,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        if not (np.isfinite(min_gain) and min_gain >= 0):
            raise DataError(f"GainDetector min_gain must be finite and >= 0, got {min_gain}")
        self.min_gain = float(min_gain)
        self.residuals = [str(x) for x in ([residuals] if isinstance(residuals, str) else residuals)]
        self.signal = str(signal)
        c = len(self.residuals)
        if c == 0:
            raise DataError("GainDetector needs at least one residual channel")
        if self.signal in self.residuals:
            raise DataError(f"GainDetector: the signal {self.signal!r} cannot also be a residual")
        self.input_names = [*self.residuals, self.signal]
        self.W = _window(W, "GainDetector window W")
        self.min_length = _window(min_length, "GainDetector min_length")
        if self.min_length > self.W:
            raise DataError(f"GainDetector min_length ({self.min_length}) must be <= W ({self.W})")
        self.mu0 = _per_channel(mu0, c, "GainDetector mu0", self.residuals)
        self.sigma2 = _per_channel(sigma2, c, "GainDetector sigma2", self.residuals, positive=True)
        self.gain_scale = _per_channel(
            gain_scale, c, "GainDetector gain_scale", self.residuals, positive=True
        )
        self._gscale = np.ascontiguousarray(self.gain_scale)
        if signature is not None:
            sg = np.sign(np.asarray(signature, float))
            if sg.shape != (c,) or not np.any(sg != 0):
                raise DataError(
                    f"GainDetector signature must have one entry -1/0/+1 per residual "
                    f"{self.residuals} and at least one non-zero, got {list(signature)}"
                )
            self.signature = sg
            self.threshold = _per_channel(threshold, 1, "GainDetector threshold", ["combined"], positive=True)
            self.name = str(name) if name is not None else self.residuals[0]
            heads = [self.name]
            self.rivals = [np.sign(np.asarray(rv, float)) for rv in rivals]
            for rv in self.rivals:
                if rv.shape != (c,) or not np.any(rv != 0):
                    raise DataError(
                        f"GainDetector rival signatures need one entry -1/0/+1 per residual "
                        f"{self.residuals}, got {rv.tolist()}"
                    )
        else:
            if len(rivals):
                raise DataError("GainDetector rivals need a signature")
            self.rivals = []
            self.signature = None
            self.threshold = _per_channel(
                threshold, c, "GainDetector threshold", self.residuals, positive=True
            )
            self.name = name
            heads = self.residuals
        self.output_names = [f"{h}:{k}" for h in heads for k in ("gain", "gain_est", "gain+", "gain-")]
        self.reset(1)

    def _repr_items(self):
        return [
            ("residuals", list(self.residuals)),
            ("signal", self.signal),
            ("W", self.W),
            ("mu0", self.mu0.tolist()),
            ("sigma2", self.sigma2.tolist()),
            ("threshold", self.threshold.tolist()),
            ("min_length", self.min_length),
            ("signature", None if self.signature is None else self.signature.tolist()),
            ("name", self.name),
            ("rivals", [rv.tolist() for rv in self.rivals]),
            ("min_gain", self.min_gain),
            ("gain_scale", self.gain_scale.tolist()),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        self._R = int(runs)
        self._bx = np.zeros((runs, len(self.residuals), self.W))
        self._bs = np.zeros((runs, self.W))
        self._pos = np.zeros(runs, np.int64)
        self._cnt = np.zeros(runs, np.int64)
        self._k = 0

    def _compute(self, x: np.ndarray) -> np.ndarray:
        R, T, _ = x.shape
        c = len(self.residuals)
        gp, gm, th = _gain_run(
            np.ascontiguousarray(x[:, :, :c]),
            np.ascontiguousarray(x[:, :, c]),
            self.mu0,
            self.W,
            self.min_length,
            self.min_gain,
            self._gscale,
            self._bx,
            self._bs,
            self._pos,
            self._cnt,
        )
        if self.signature is None:
            gp, gm = gp / self.sigma2, gm / self.sigma2
            thr = self.threshold
            cols = [np.maximum(gp, gm) / thr, th, gp / thr, gm / thr]
            return np.stack(cols, axis=3).reshape(R, T, 4 * c)
        # the weakest residual in the signature's direction (and the opposite one), unless a rival
        # fault explains the residuals as well
        out = np.empty((R, T, 4))
        sigs = np.array([self.signature, *self.rivals], float).reshape(-1, c)
        _combine_kernel(gp, gm, self.sigma2, sigs, self.threshold[0], True, out)
        first = int(np.flatnonzero(self.signature != 0)[0])
        np.multiply(th[..., first], self.signature[first], out=out[:, :, 1])
        return out


# ---------------------------------------------------------------------------------- intermittent
class IntermittentDetector(_SensorDetector):
    """Bursts of a fault that come and go: episodes of a large residual counted over a window.

    An episode starts when ``|r - mu0| > level`` and ends once ``|r - mu0| < release`` has held
    for ``gap`` samples (hysteresis and debounce: noise near the level does not make a new
    episode of every crossing). The statistic is the number of episode onsets in the last ``W``
    samples over ``min_bursts``: a permanent fault is one episode, an intermittent one several.

    Parameters
    ----------
    inputs : sequence of str
        Residual channels (band-limit them first: a burst is then a clear hump).
    level : float or sequence
        Onset level of ``|r - mu0|`` per channel.
    W : int
        Window over which onsets are counted (samples).
    min_bursts : int
        Onsets within ``W`` that make the fault intermittent (output ``>= 1``).
    mu0 : float or sequence
        Nominal mean per channel.
    release : float or sequence, optional
        Level below which an episode may end (default ``level / 2``).
    gap : int
        Samples below ``release`` that end an episode.
    signed : bool
        Count episodes above ``+level`` and below ``-level`` separately (which sensor of a
        difference is intermittent): two outputs per input.
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Outputs ``"<input>:intermittent"`` per input (alarm at >= 1); with ``signed``,
    ``"<input>:intermittent+"`` and ``"<input>:intermittent-"``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(60.0)
    >>> r = np.where((t % 20 >= 5) & (t % 20 < 10), 1.0, 0.0)     # on 5 samples of every 20
    >>> d = IntermittentDetector(["r"], level=0.5, W=50, min_bursts=3, gap=2)
    >>> out = d.run(Signals(t, r, ["r"]))["r:intermittent"][0]
    >>> out[[5, 25, 45]].round(3).tolist()
    [0.333, 0.667, 1.0]
    """

    _state_attrs = ("_on", "_quiet", "_buf", "_pos", "_cnt", "_k", "_R")

    def __init__(
        self,
        inputs: Sequence[str],
        level=1.0,
        W: int = 500,
        min_bursts: int = 3,
        *,
        mu0=0.0,
        release=None,
        gap: int = 5,
        signed: bool = False,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        self.input_names = [str(s) for s in ([inputs] if isinstance(inputs, str) else inputs)]
        c = len(self.input_names)
        if c == 0:
            raise DataError("IntermittentDetector needs at least one input channel")
        self.W = _window(W, "IntermittentDetector window W")
        self.min_bursts = _window(min_bursts, "IntermittentDetector min_bursts")
        self.gap = _window(gap, "IntermittentDetector gap")
        self.mu0 = _per_channel(mu0, c, "IntermittentDetector mu0", self.input_names)
        self.level = _per_channel(level, c, "IntermittentDetector level", self.input_names, positive=True)
        self.release = (
            0.5 * self.level
            if release is None
            else _per_channel(release, c, "IntermittentDetector release", self.input_names, positive=True)
        )
        if np.any(self.release > self.level):
            raise DataError(
                f"IntermittentDetector release {self.release.tolist()} must not exceed level "
                f"{self.level.tolist()}"
            )
        self.signed = bool(signed)
        if self.signed:
            self.output_names = [f"{s}:intermittent{g}" for s in self.input_names for g in "+-"]
            self._side = np.tile([1, -1], c).astype(np.int64)
        else:
            self.output_names = [f"{s}:intermittent" for s in self.input_names]
            self._side = np.zeros(c, np.int64)
        self.reset(1)

    def _repr_items(self):
        return [
            ("inputs", list(self.input_names)),
            ("level", self.level.tolist()),
            ("W", self.W),
            ("min_bursts", self.min_bursts),
            ("mu0", self.mu0.tolist()),
            ("release", self.release.tolist()),
            ("gap", self.gap),
            ("signed", self.signed),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        c = len(self.output_names)
        self._R = int(runs)
        self._on = np.zeros((runs, c), np.int64)
        self._quiet = np.zeros((runs, c), np.int64)
        self._buf = np.zeros((runs, c, self.W), np.int64)
        self._pos = np.zeros((runs, c), np.int64)
        self._cnt = np.zeros((runs, c), np.int64)
        self._k = 0

    def _compute(self, x: np.ndarray) -> np.ndarray:
        m = 2 if self.signed else 1
        if m > 1:
            x = np.ascontiguousarray(np.repeat(x, m, axis=2))
        R, T, C = x.shape
        rep = lambda a: np.repeat(a, m)  # noqa: E731
        out = np.empty((R, T, C))
        _burst_kernel(
            x,
            rep(self.mu0),
            self._side,
            rep(self.level),
            rep(self.release),
            self.gap,
            self.W,
            out,
            self._on,
            self._quiet,
            self._buf,
            self._pos,
            self._cnt,
        )
        return out / self.min_bursts


# ---------------------------------------------------------------------------------- design
def _nominal(nominal: Signals, names: Sequence[str], skip: int) -> Signals:
    if not isinstance(nominal, Signals):
        raise DataError(f"nominal data must be Signals, got {type(nominal).__name__}")
    missing = [n for n in names if n not in nominal.names]
    if missing:
        raise DataError(f"nominal data lack channels {missing}; they have {list(nominal.names)}")
    if int(skip) != skip or skip < 0 or skip >= nominal.n_samples - 1:
        raise DataError(f"skip must be an integer in [0, {nominal.n_samples - 1}), got {skip}")
    return nominal


def _threshold(
    stat: np.ndarray,
    pfa: float,
    per,
    margin: float,
    dt: float | None,
    Z: int,
    what: str,
    floor_chi2: bool = False,
) -> np.ndarray:
    """Threshold(s) of statistics (runs, T, C) for the target (see :func:`design_threshold`).

    When the nominal data are too short for the target (``design_threshold`` refuses: too few
    effective samples for a tail fit; the usual case of a short real record), a target per unit
    of time falls back to extreme-value scaling: the maximum of ``n`` effective samples of a
    statistic with an exponential tail (a GLR is chi-square-like) grows as ``ln n``, so the
    threshold is the nominal maximum times ``ln(n_target) / ln(n_eff)``, with ``n_eff = n / tau``
    the effective samples of the data and ``n_target`` those of the operating time in which one
    false alarm is allowed (``tau`` the integrated autocorrelation time,
    :func:`fdikit.detect.tail.block_length`). Rough, conservative for lighter tails. With
    ``floor_chi2`` (GLR statistics) the threshold is never below the chi-square(1) level of the
    target per sample.
    """
    from .glrt import TIME_UNITS, design_threshold
    from .tail import block_length

    if not (np.isfinite(margin) and margin >= 0):
        raise DataError(f"{what}: margin must be finite and >= 0, got {margin}")
    try:
        d = design_threshold(stat, pfa, per=per, Z=Z, margin=margin, absolute=False, dt=dt)
        thr = np.atleast_1d(np.asarray(d.threshold, float))
    except DataError:
        timed = not (isinstance(per, str) and per in ("run", "sample"))
        if not (pfa > 0 and timed and dt):
            raise
        unit = TIME_UNITS[per] if isinstance(per, str) else float(per)
        thr = np.empty(stat.shape[2])
        for c in range(stat.shape[2]):
            x = stat[:, :, c]
            tau = block_length(x)["tau"]
            n_eff = max(x.size / tau, np.e)
            n_target = max(unit / pfa / dt / tau, n_eff)
            thr[c] = float(x.max()) * np.log(n_target) / np.log(n_eff) * (1.0 + margin)
    floor = 1e-12
    if floor_chi2 and pfa > 0 and dt and not (isinstance(per, str) and per in ("run", "sample")):
        # never below the level of a chi-square(1) GLR of white noise for the target per sample: a
        # statistic that is 0 on most nominal data (an indifference zone, a gate) is still tested
        from scipy.stats import chi2

        unit = TIME_UNITS[per] if isinstance(per, str) else float(per)
        floor = float(chi2.isf(min(pfa * dt / unit, 0.5), 1))
    return np.maximum(thr, floor)


def _dt(s: Signals) -> float | None:
    return float((s.t[-1] - s.t[0]) / (s.n_samples - 1)) if s.n_samples > 1 else None


def design_stuck(
    nominal: Signals,
    measured: str,
    expected: str | None = None,
    *,
    tol: float = 0.0,
    min_samples: int | None = None,
    quantile: float = 0.5,
    pfa: float = 0.0,
    per: str | float = "hour",
    margin: float = 0.5,
    Z: int = 1,
    skip: int = 0,
) -> StuckDetector:
    """A :class:`StuckDetector` calibrated on nominal data.

    The scale of the statistic is the standard deviation of the expected signal's increments
    (its noise: the range over a flat run is then in noise units). The threshold is the level of
    the statistic on the nominal data for the target (``pfa`` per ``per``, as
    :func:`~fdikit.detect.design_threshold`; ``pfa = 0``: just above the largest nominal value),
    times ``1 + margin``. With ``min_samples`` (a flat run must last longer than any the nominal
    data hold) the threshold is instead the ``quantile`` of the expected signal's range over
    windows of ``min_samples`` samples (how much it moves in that time in ordinary driving) times
    ``1 + margin``, and at least the largest gated nominal value times ``1 + margin``.

    Parameters
    ----------
    nominal : Signals
        Fault-free record(s) holding ``measured`` (and ``expected``).
    measured, expected : str
        See :class:`StuckDetector`.
    tol : float
        See :class:`StuckDetector`.
    min_samples : int, optional
        See :class:`StuckDetector`; ``"auto"``: one more than the longest nominal flat run.
    quantile : float
        Quantile of the expected signal's windowed range used with ``min_samples``.
    pfa, per, margin, Z :
        False-alarm target (see :func:`~fdikit.detect.design_threshold`; a target per unit of time
        that the data are too short for falls back to extreme-value scaling of the nominal
        maximum, ``ln(n_target) / ln(n_eff)`` effective samples), relative margin on the
        threshold and the hold the alarm will use.
    skip : int
        Samples left out at the start of every run (transients); the detector's ``warmup``.

    Returns
    -------
    StuckDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(2000) * 0.02
    >>> truth = np.sin(0.5 * t)
    >>> nom = Signals(t, np.c_[np.round(truth, 2), truth + 0.01 * rng.standard_normal(t.size)], ["x", "e"])
    >>> d = design_stuck(nom, "x", "e", tol=0.0)
    >>> bool(d.run(nom)["x:stuck"].max() < 1)
    True
    """
    names = [measured] + ([expected] if expected is not None else [])
    s = _nominal(nominal, names, skip)
    if expected is not None:
        e = s[expected][:, skip:]
        scale = float(np.std(np.diff(e, axis=1)))
        if not scale > 0:
            raise DataError(f"expected channel {expected!r} does not vary on the nominal data: no scale")
    else:
        scale = 1.0
    if min_samples == "auto":
        flat = StuckDetector(measured, None, tol=tol, warmup=skip).run(s).values[:, skip:, 0]
        min_samples = int(flat.max()) + 1
    nmin = int(min_samples or 0)
    d = StuckDetector(measured, expected, tol=tol, scale=scale, threshold=1.0, min_samples=nmin, warmup=skip)
    g = d.run(s).values[:, skip:]
    if nmin > 0 and expected is not None:
        if not 0 < quantile < 1:
            raise DataError(f"design_stuck: quantile must be in (0, 1), got {quantile}")
        from numpy.lib.stride_tricks import sliding_window_view

        if e.shape[1] <= nmin:
            raise DataError(
                f"design_stuck: nominal records of {e.shape[1]} samples are shorter than min_samples = {nmin}"
            )
        w = sliding_window_view(e, nmin + 1, axis=1)
        moving = float(np.quantile(np.ptp(w, axis=2), quantile)) / scale
        thr = max(moving, float(g.max())) * (1.0 + margin)
    else:
        thr = float(_threshold(g, pfa, per, margin, _dt(s), Z, "design_stuck")[0])
    return StuckDetector(
        measured, expected, tol=tol, scale=scale, threshold=max(thr, 1e-12), min_samples=nmin, warmup=skip
    )


def design_drift(
    nominal: Signals,
    inputs: Sequence[str],
    W: int,
    *,
    signature: Sequence[float] | None = None,
    name: str | None = None,
    min_length: int = 1,
    vs_step: bool = False,
    pfa: float = 0.0,
    per: str | float = "hour",
    margin: float = 0.5,
    Z: int = 1,
    skip: int = 0,
) -> DriftDetector:
    """A :class:`DriftDetector` calibrated on nominal data: ``mu0`` and ``sigma2`` are the mean and
    variance of each residual, the threshold the statistic's level for the target (as
    :func:`design_stuck`).

    Parameters
    ----------
    nominal : Signals
    inputs : sequence of str
    W : int
    signature, name, min_length, vs_step :
        See :class:`DriftDetector`.
    pfa, per, margin, Z, skip :
        See :func:`design_stuck`.

    Returns
    -------
    DriftDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(5000) * 0.02
    >>> r = np.random.default_rng(1).standard_normal(t.size)
    >>> d = design_drift(Signals(t, r, ["r"]), ["r"], W=250)
    >>> faulty = Signals(t, r + np.where(t > 50, 0.2 * (t - 50), 0.0), ["r"])   # 0.2 sigma / s
    >>> k = int(np.argmax(d.run(faulty)["r:drift"][0] >= 1))
    >>> bool(2 < t[k] - 50 < 4)        # threshold 36: s^2 L^3 / 3 ~ 36 after L ~ 175 samples
    True
    """
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    s = _nominal(nominal, inputs, skip)
    r = s.values[:, skip:][:, :, s.index(inputs)].reshape(-1, len(inputs))
    mu0, var = r.mean(axis=0), np.maximum(r.var(axis=0, ddof=1), 1e-300)
    kw = dict(min_length=min_length, signature=signature, name=name, warmup=skip)
    # the threshold is the ramp GLR's (the step gate only removes alarms: calibrated without it, the
    # nominal statistic would be 0 wherever a step fits better, and the threshold degenerate)
    d = DriftDetector(inputs, W, mu0, var, 1.0, vs_step=False, **kw)
    kw["vs_step"] = vs_step
    g = d.run(s).values[:, skip:]
    thr = _threshold(g, pfa, per, margin, _dt(s), Z, "design_drift", floor_chi2=True)
    return DriftDetector(inputs, W, mu0, var, thr if signature is None else thr[0], **kw)


def design_gain(
    nominal: Signals,
    residuals,
    signal: str,
    W: int,
    *,
    min_length: int = 1,
    signature: Sequence[float] | None = None,
    name: str | None = None,
    rivals=(),
    min_gain: float = 0.0,
    gain_scale=1.0,
    pfa: float = 0.0,
    per: str | float = "hour",
    margin: float = 0.5,
    Z: int = 1,
    skip: int = 0,
) -> GainDetector:
    """A :class:`GainDetector` calibrated on nominal data (``mu0``, ``sigma2`` of each residual; the
    threshold as :func:`design_stuck`).

    Parameters
    ----------
    nominal : Signals
    residuals : str or sequence of str
    signal : str
    W, min_length, signature, name, rivals, min_gain, gain_scale :
        See :class:`GainDetector`.
    pfa, per, margin, Z, skip :
        See :func:`design_stuck`.

    Returns
    -------
    GainDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(2)
    >>> t = np.arange(3000) * 0.02
    >>> v = 20 + 2 * np.sin(0.1 * t)
    >>> nom = Signals(t, np.c_[0.05 * rng.standard_normal(t.size), v], ["r", "v"])
    >>> d = design_gain(nom, "r", "v", W=100)
    >>> bool(d.run(nom)["r:gain"].max() < 1)
    True
    """
    res = [residuals] if isinstance(residuals, str) else list(residuals)
    s = _nominal(nominal, [*res, signal], skip)
    r = s.values[:, skip:][:, :, s.index(res)].reshape(-1, len(res))
    mu0, var = r.mean(axis=0), np.maximum(r.var(axis=0, ddof=1), 1e-300)
    kw = dict(
        min_length=min_length,
        signature=signature,
        name=name,
        rivals=rivals,
        gain_scale=gain_scale,
        warmup=skip,
    )
    d = GainDetector(res, signal, W, mu0, var, 1.0, min_gain=0.0, **kw)  # the plain GLR's threshold
    kw["min_gain"] = min_gain
    out = d.run(s)
    stat = [n for n in d.output_names if n.endswith(":gain")]
    g = out.values[:, skip:][:, :, out.index(stat)]
    thr = _threshold(g, pfa, per, margin, _dt(s), Z, "design_gain", floor_chi2=True)
    return GainDetector(res, signal, W, mu0, var, thr if signature is None else thr[0], **kw)


def design_intermittent(
    nominal: Signals,
    inputs: Sequence[str],
    W: int,
    *,
    min_bursts: int = 3,
    gap: int = 5,
    margin: float = 0.5,
    release: float = 0.5,
    signed: bool = False,
    skip: int = 0,
) -> IntermittentDetector:
    """An :class:`IntermittentDetector` calibrated on nominal data: ``mu0`` is each residual's mean
    and the onset level is the largest nominal ``|r - mu0|`` times ``1 + margin`` (no nominal
    sample starts an episode), the release level ``release`` times that.

    Parameters
    ----------
    nominal : Signals
    inputs : sequence of str
    W, min_bursts, gap, signed :
        See :class:`IntermittentDetector`.
    margin : float
        Relative margin of the level over the largest nominal deviation.
    release : float
        Release level as a fraction of the onset level (0 < release <= 1).
    skip : int
        Samples left out at the start of every run; the detector's ``warmup``.

    Returns
    -------
    IntermittentDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(3)
    >>> t = np.arange(3000) * 0.02
    >>> nom = Signals(t, 0.1 * rng.standard_normal(t.size), ["r"])
    >>> d = design_intermittent(nom, ["r"], W=500)
    >>> bool(d.run(nom)["r:intermittent"].max() == 0)
    True
    """
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    s = _nominal(nominal, inputs, skip)
    if not (np.isfinite(margin) and margin >= 0):
        raise DataError(f"design_intermittent: margin must be finite and >= 0, got {margin}")
    if not 0 < release <= 1:
        raise DataError(f"design_intermittent: release must be in (0, 1], got {release}")
    r = s.values[:, skip:][:, :, s.index(inputs)].reshape(-1, len(inputs))
    mu0 = r.mean(axis=0)
    level = np.maximum(np.abs(r - mu0).max(axis=0), 1e-300) * (1.0 + margin)
    return IntermittentDetector(
        inputs, level, W, min_bursts, mu0=mu0, release=release * level, gap=gap, signed=signed, warmup=skip
    )
