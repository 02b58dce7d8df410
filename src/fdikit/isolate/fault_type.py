"""Fault-type classification of an isolated sensor (issue 27, item 2): bias, drift, gain, stuck,
intermittent or spike, from its residual and its signal, with a confidence, revised as evidence
grows.

Once a sensor is isolated (an isolation stage's flag, e.g. :class:`~fdikit.detect.PeerCheck`'s
``peer:m:isolated``) its fault is *active*; the type is decided over the window since the onset
(from the block holding the sample ``lookback`` samples before the first flag; at most the last
``window // block`` blocks, so that evidence grows until then).

The window is held as recursive sufficient statistics, not as samples (issue 29: a step costs O(1)
per sensor, the state is O(window / block)): each sample adds to its block of ``block`` samples
(blocks aligned to the sample count) the sums of ``r``, ``i r`` (``i`` its index in the block),
``x``, ``x r`` and ``x^2``, and the counts of the normalised residual's episodes (first and last
sample out, samples below ``release`` before and after them, episodes starting in between); a
ring of ``window // block + 1`` blocks per sensor holds them. The type is decided at the onset and
again each time a block completes, from the blocks alone (change points at block boundaries);
each sample between announces the latest decision (or stuck, checked per sample):

* **stuck** -- the sensor's raw signal has not changed (zero increments) for longer than the
  longest frozen run of the nominal data (``stuck_after``); checked on every sensor that has it,
  isolated or not;
* **gain** first, decided by regression on the signal (the residual's explained variance): over
  the blocks after the step's change point (below; the block the change falls in is left out, its
  mean mixes the samples before and after) (block means: the residual's high-frequency noise
  averages out), the block means of the residual are regressed on
  those of the signal with an intercept, ``r = a + theta x``. The drop of the sum of squares
  against a constant, ``F_b = theta^2 S_xx / s^2`` (``s^2`` the block-mean noise variance, the
  larger of the nominal ``sigma_block^2`` and the fit's own), is the evidence of a gain (a
  residual that moves with the signal, offset or not: a gain scales the sensor's offset too); it
  is a gain when ``F_b >= gain_crit``, unless the ramp's GLR wins (below) and time explains the
  residual better than the signal does (a drift the signal happens to follow). At least 4 blocks
  are needed, and a signal that does not move gives no evidence: with too little excitation the
  fault stays a bias (the default explanation) with a confidence of at most 0.5 until the line
  through the residual's fault-free level (the mean of the ring's blocks before the onset, else
  zero), the gain without an offset, is also ruled out (``F_g >= gain_crit``), and is revised to a
  gain as the signal moves: a bias at most 0.5 sure says the data cannot tell it from a gain.
  It is also a gain when that line through the fault-free level, ``r = r_0 + theta x``, fits
  (``F_g < gain_crit``) and beats the step ``r = r_0 + b`` by ``prefer``: ``F_b - F_g`` is the drop
  of the sum of squares from the step to it, both one parameter -- the gain's mean fixes its slope
  and the signal's moves must follow, where a step has none -- unless a line in time fits the
  block means better than the line in x (a drift); its confidence is
  ``1 / (1 + exp(-(F_b - F_g - prefer) / 2))``, 0.5 at the level as the first rule's is at
  ``gain_crit`` (the gain's posterior against a step that is ``exp(prefer / 2)`` times likelier a
  priori). ``x`` is the signal the gain scales: with
  ``gain_offset`` the member's reference plus the zero offset that the signal conditioning removed
  (a gyro's, a hand-wheel angle's), since a gain of the raw sensor scales the offset too (issue 27:
  on a straight road the yaw rate moves by +-0.2 deg/s and a yaw-rate gain's residual is mostly
  the gain times the gyro's -0.38 deg/s offset, a step to a test without it).
* **intermittent** -- at least two episodes of the normalised residual above 1 in the window,
  separated by ``burst_gap`` samples below ``release``, or of the residual's block means above 5
  block-mean standard deviations, separated by blocks below 2, the second one ended or a third
  begun (short bursts that a low-passed statistic smears into one; a blip before a step is no
  burst); **spike** -- one episode no longer than
  ``spike_max`` samples, followed by ``burst_gap`` samples below ``release``;
* otherwise a step and a ramp with an unknown change point ``j`` compete by their GLR (``sigma``
  the nominal residual's standard deviation): a step ``r_i = b`` (**bias**),
  ``S_b = max_j (sum r)^2 / (sigma^2 n)``; a ramp ``r_i = s (i - j + 1)`` (**drift**),
  ``S_d = max_j (sum tau r)^2 / (sigma^2 sum tau^2)``. Drift wins over bias only when its
  statistic exceeds the bias one by ``prefer`` (a step is the default explanation); the confidence
  is the softmax of ``S / 2`` over the two (a gain is decided by the block test above; a
  sample-wise GLR of the gain in this softmax, which a zero offset makes as large as the step's,
  took the bias's and the drift's confidence away).

With ``revise_after`` the announced type has hysteresis (issue 27: no flapping between types
while one fault persists): the announced type is replaced only after it has lost ``revise_after``
samples in a row (three times as long for a return to a type the episode already left), and a
drift never falls back to a bias.

The fault stays active -- its episode does not clear -- while the normalised residual stays above
``release`` or the signal stays frozen; it ends after ``clear_after`` samples below. Outputs, per
member ``m``: ``m:<type>`` for each of :data:`FAULT_TYPES` (1 while active with that type),
``m:confidence`` and ``m:active``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["FAULT_TYPES", "FaultTypeClassifier"]

#: The fault types the classifier tells apart, in output order.
FAULT_TYPES = ("bias", "drift", "gain", "stuck", "intermittent", "spike")
_BIAS, _DRIFT, _GAIN, _STUCK, _INTER, _SPIKE = range(6)


#: the block aggregates of one member's ring, per block: sums of r, i r (i the sample's index in the
#: block), x, x r, x^2 (``_bs``); and of the normalised residual's episodes (``_be``): the index in the
#: block of the first and last sample out (>= 1; -1: none), the samples below ``release`` before the
#: first and after the last, and the episodes that start after the first in the block
#: (the sums of x r and x^2 fed a sample-wise gain GLR that is no longer decided on; they stay, so
#: that saved states keep their layout)
_SR, _SIR, _SX, _SXR, _SXX = range(5)
_FO, _LO, _BB, _BA, _NE = range(5)


@njit(cache=True)
def _accumulate(bs, be, i, r, x, st, release, burst_gap):
    """Add sample i of a block (residual r, signal x, normalised residual st) to its aggregates
    bs (5,), be (5,); i = 0 starts the block."""
    if i == 0:
        for c in range(5):
            bs[c] = 0.0
        be[_FO], be[_LO], be[_BB], be[_BA], be[_NE] = -1, -1, 0, 0, 0
    bs[_SR] += r
    bs[_SIR] += i * r
    bs[_SX] += x
    bs[_SXR] += x * r
    bs[_SXX] += x * x
    if st >= 1.0:
        if be[_FO] < 0:
            be[_FO] = i
        elif be[_BA] >= burst_gap:
            be[_NE] += 1
        be[_LO] = i
        be[_BA] = 0
    elif st < release:
        if be[_FO] < 0:
            be[_BB] += 1
        else:
            be[_BA] += 1


#: fewest blocks before the window for the residual's fault-free level (else zero)
_BASE_MIN = 4


@njit(cache=True)
def _classify(bs, be, b0, nb, NR, B, sigma, min_len, prefer, burst_gap, spike_max, sig_blk, gain_crit):
    """Type and confidence of one member's fault from the aggregates of its window's blocks ``b0``
    .. ``b0 + nb - 1`` (block numbers; ring slot ``b % NR``) of ``B`` samples (see the module
    docstring); change points at block boundaries."""
    # the GLRs [S_b, S_d], each maximised over the change point (segments of at least min_len
    # samples ending at the newest sample): sums over the last q blocks, newest first
    sr = sar = 0.0
    sb = sd = -np.inf
    Lb = 0                                            # the step's change point: the last Lb blocks
    s = (b0 + nb - 1) % NR                            # ring slots stepped, not taken modulo NR
    for q in range(nb):
        if q > 0:
            s = s - 1 if s > 0 else NR - 1
        sr += bs[s, _SR]
        sar += (q * B + B - 1) * bs[s, _SR] - bs[s, _SIR]     # age (0 = newest) times r
        L = (q + 1) * B
        if L < min_len:
            continue
        s_tr = L * sr - sar                           # sum tau r, tau = 1 (oldest) .. L (newest)
        stt = L * (L + 1) * (2 * L + 1) / 6.0
        if sr * sr / L > sb:
            sb, Lb = sr * sr / L, q + 1
        sd = max(sd, s_tr * s_tr / stt)
    S0 = S1 = 0.0
    if nb * B >= min_len:
        s2 = sigma * sigma
        S0, S1 = sb / s2, sd / s2
    smax = max(S0, S1)
    e0, e1 = np.exp(0.5 * (S0 - smax)), np.exp(0.5 * (S1 - smax))
    esum = e0 + e1
    # the gain test over the blocks after the change point's: that block holds the change at block
    # resolution, its mean mixes the samples before and after it
    nl = max(Lb - 1, 0)
    ib = 1.0 / B
    # the residual's fault-free level: the mean of the ring's blocks before the window (before the
    # onset), if at least _BASE_MIN; a gain without an offset is a line through it (issue 27: the
    # peers' fit leaves the residual an offset of its own on held-out data)
    p0 = max(0, b0 + nb - (NR - 1))
    r0 = 0.0
    if b0 - p0 >= _BASE_MIN:
        s = p0 % NR
        for m in range(b0 - p0):
            if m > 0:
                s = s + 1 if s < NR - 1 else 0
            r0 += bs[s, _SR]
        r0 = r0 * ib / (b0 - p0)
    fb, fg, by_time = _gain_test_blocks(bs, b0 + nb - nl, nl, NR, ib, sig_blk, r0)
    if by_time and S1 > S0 + prefer:
        fb = 0.0                                      # a drift, which the signal happens to follow
    if fb >= gain_crit:                               # the residual follows the signal: a gain
        return _GAIN, 1.0 / (1.0 + np.exp(-0.5 * (fb - gain_crit)))
    # a gain through the fault-free level against a step, both one parameter: the gain's mean fixes
    # its slope, the signal's moves must follow (a sensor's zero offset, ``gain_offset``, makes the
    # mean large against the moves; a step has no slope)
    dg = fb - fg
    if fg < gain_crit and dg >= prefer and not by_time:
        return _GAIN, 1.0 / (1.0 + np.exp(-0.5 * (dg - prefer)))
    # episodes of the residual out, separated by at least burst_gap samples below release
    first = last = -1
    n_ep = 0
    below = 0                                         # samples below release since the last one out
    s = b0 % NR
    for m in range(nb):
        if m > 0:
            s = s + 1 if s < NR - 1 else 0
        below += be[s, _BB]
        if be[s, _FO] >= 0:
            if first < 0:
                first = m * B + be[s, _FO]
                n_ep = 1
            elif below >= burst_gap:
                n_ep += 1
            n_ep += be[s, _NE]
            last = m * B + be[s, _LO]
            below = be[s, _BA]
    if n_ep < 2:
        # bursts shorter than the statistic's low-pass smear into one episode there: count them on
        # the residual's block means too
        n_ep = max(n_ep, _block_episodes(bs, b0, nb, NR, ib, sig_blk, max(1, burst_gap // B)))
    if n_ep >= 2:
        return _INTER, 1.0 - 0.5 ** (n_ep - 1)
    if first >= 0:
        if last - first < spike_max and below >= burst_gap:
            return _SPIKE, min(1.0, below / (2.0 * burst_gap))
    best = _DRIFT if S1 > S0 + prefer else _BIAS
    c = (e1 if best == _DRIFT else e0) / esum
    if best == _BIAS and fg < gain_crit:
        c = min(c, 0.5)                               # a gain is not ruled out yet (too little excitation)
    return best, c


#: block-mean levels (in block-mean noise standard deviations) of a burst and of the quiet between
_BURST_ON, _BURST_OFF = 5.0, 2.0


@njit(cache=True)
def _block_episodes(bs, b0, nb, NR, ib, sig_blk, gap):
    """Episodes of the residual over blocks ``b0 .. b0 + nb - 1`` (``ib`` one over the block
    length): runs of block means with ``|mean| >= 5 sig_blk``, separated by at least ``gap`` blocks
    below ``2 sig_blk``. Two episodes count as one while the second has not ended (``gap`` quiet
    blocks after it): a nominal blip before a step is not an intermittent fault; a third episode,
    or the second one's end, makes it one."""
    n_ep, seen, below = 0, False, 0
    s = b0 % NR
    for m in range(nb):
        if m > 0:
            s = s + 1 if s < NR - 1 else 0
        z = abs(bs[s, _SR] * ib) / sig_blk
        if z >= _BURST_ON:
            if not seen or below >= gap:
                n_ep += 1
            seen, below = True, 0
        elif z < _BURST_OFF:
            below += 1
    if n_ep == 2 and below < gap:
        n_ep = 1                                      # the second burst has not ended: a step after a blip
    return n_ep


@njit(cache=True)
def _gain_test_blocks(bs, b0, nb, NR, ib, sig_blk, r0):
    """``(F_b, F_g, by_time)`` over blocks ``b0 .. b0 + nb - 1`` (ring slot ``b % NR`` of the
    aggregates bs; ``ib`` one over the block length): the block means of r regressed on those of x
    with an intercept;
    F_b the drop of the residual sum of squares against a constant (the slope: a gain, or a time
    trend that x follows), F_g against a line through ``(0, r0)`` (a gain without an offset from the
    fault-free level ``r0``), each
    over the noise variance of a block mean (the larger of ``sig_blk^2`` and the fit's own);
    ``by_time`` where a line in time fits the block means better than the line in x.
    ``(0, 0, False)`` with fewer than 4 blocks or no excitation."""
    if nb < 4:
        return 0.0, 0.0, False
    mr = mx = 0.0
    s = b0 % NR
    for m in range(nb):
        if m > 0:
            s = s + 1 if s < NR - 1 else 0
        mr += bs[s, _SR] * ib
        mx += bs[s, _SX] * ib
    mr, mx, mt = mr / nb, mx / nb, 0.5 * (nb - 1)
    sxx = sxy = syy = stt = sty = sx0 = sxy0 = 0.0
    s = b0 % NR
    for m in range(nb):
        if m > 0:
            s = s + 1 if s < NR - 1 else 0
        rm, xm = bs[s, _SR] * ib, bs[s, _SX] * ib
        dx, dy, dt = xm - mx, rm - mr, m - mt
        sxx += dx * dx
        sxy += dx * dy
        syy += dy * dy
        stt += dt * dt
        sty += dt * dy
        sx0 += xm * xm
        sxy0 += xm * (rm - r0)
    if sxx <= 0.0 or sx0 <= 0.0:
        return 0.0, 0.0, False
    rss = max(syy - sxy * sxy / sxx, 0.0)             # a + theta x
    rss_t = max(syy - sty * sty / stt, 0.0)           # a + s t: a drift
    s2 = max(sig_blk * sig_blk, rss / (nb - 2))
    fb = (syy - rss) / s2
    fg = max(syy + nb * (mr - r0) * (mr - r0) - sxy0 * sxy0 / sx0 - rss, 0.0) / s2
    return fb, fg, rss_t < rss


def _gain_test(r: np.ndarray, x: np.ndarray, block: int, sig_blk: float) -> tuple[float, float, bool]:
    """The gain test of :func:`_gain_test_blocks` on samples: residual r (n,) and signal x (n,) in
    blocks of ``block`` samples aligned to the newest (a design's calibration on nominal windows)."""
    r, x = np.asarray(r, float), np.asarray(x, float)
    nb = r.size // block
    off = r.size - nb * block
    bs = np.zeros((max(nb, 1), 5))
    if nb:
        bs[:, _SR] = r[off:].reshape(nb, block).sum(axis=1)
        bs[:, _SX] = x[off:].reshape(nb, block).sum(axis=1)
    fb, fg, by_time = _gain_test_blocks(bs, 0, nb, max(nb, 1), 1.0 / block, sig_blk, 0.0)
    return float(fb), float(fg), bool(by_time)


@njit(cache=True)
def _revise(shown, conf, cand, cnt, left, nt, nc, after, min_conf):
    """The announced type's revision with hysteresis: ``(type, confidence, candidate, count, left)``
    from the announced ``shown`` (confidence ``conf``), the latest other decision and the samples
    in a row the announced type has lost (the new decision replaces it after ``after`` of them),
    the bit mask of the types the episode left, and this sample's decision ``nt`` (``nc``).
    ``cnt < 0``: the episode's first decision; ``after <= 0``: no hysteresis (the decision as is).
    ``min_conf`` applies to the fitted types (bias, drift, gain), not to the counted ones
    (intermittent, spike: their confidences are not a softmax of fits)."""
    if after <= 0 or cnt < 0 or nt == shown:
        return nt, nc, -1, 0, left
    cnt += 1                                          # samples the announced type has lost in a row
    if shown == _DRIFT and nt == _BIAS:               # a drift is a bias that keeps growing
        return shown, conf, nt, cnt, left
    if nt == _STUCK:                                  # a frozen signal is a fact, not a fit
        return nt, nc, -1, 0, left | (1 << shown)
    need = _RETURN * after if (left >> nt) & 1 else after
    if cnt >= need and (nc >= min_conf or nt >= _INTER):   # bursts are counted, not fitted
        return nt, nc, -1, 0, left | (1 << shown)
    return shown, conf, nt, cnt, left


#: how many times longer than ``revise_after`` a type the episode left must win to come back
_RETURN = 3


@njit(cache=True)
def _run_kernel(V, ix, ixx, confirm, iraw, ioff, stuck, sigma, NB, lookback, min_len, spike_max, burst_gap,
                release, clear_after, prefer, block, sig_blk, gain_crit, revise_after, revise_conf, hold_iso,
                k, bs, be, active, onset, typ, conf, below, zero, last, cand, cnt, left, dtyp, dconf, out):
    """The classifier over samples V (R, T, inputs) from sample count k, state updated in place;
    outputs into out (R, T, outputs). Returns the new sample count. Each sample adds to its block's
    aggregates (ring of ``NB + 1`` blocks per member: the window's ``NB`` and the one being filled);
    an active fault is decided again when a block completes (and at its onset), each sample's
    decision is the latest one (or stuck)."""
    R, T = V.shape[0], V.shape[1]
    M, NT, B, NR = ix.shape[0], 6, block, NB + 1
    for kk in range(T):
        i, slot = k % B, (k // B) % NR
        for run in range(R):
            for j in range(M):
                x = V[run, kk, ix[j, 3]]
                if ioff[j] >= 0:
                    x = x + V[run, kk, ioff[j]]
                _accumulate(bs[run, j, slot], be[run, j, slot], i, V[run, kk, ix[j, 2]], x,
                            V[run, kk, ix[j, 1]], release, burst_gap)
                if iraw[j] >= 0:
                    raw = V[run, kk, iraw[j]]
                    zero[run, j] = zero[run, j] + 1 if raw == last[run, j] else 0
                    last[run, j] = raw
        k += 1
        done = k // B                                 # blocks completed
        for run in range(R):
            for j in range(M):
                stat = V[run, kk, ix[j, 1]]
                is_stuck = stuck[j] > 0 and zero[run, j] >= stuck[j]
                iso = V[run, kk, ix[j, 0]] >= 1.0
                for c in range(ixx.shape[1]):
                    if ixx[j, c] >= 0 and V[run, kk, ixx[j, c]] >= 1.0 and V[run, kk, ix[j, 1]] >= confirm:
                        iso = True
                decide = active[run, j] and i == B - 1
                if not active[run, j] and (iso or is_stuck):
                    onset[run, j] = max(k - 1 - lookback, 0)
                    active[run, j] = True
                    cand[run, j], cnt[run, j], left[run, j] = -1, -1, 0
                    decide = True
                if active[run, j] and stat < release and not is_stuck and not (hold_iso and iso):
                    below[run, j] += 1
                else:
                    below[run, j] = 0
                if below[run, j] >= clear_after:
                    active[run, j] = False
                if active[run, j]:
                    if decide:
                        b0 = max(onset[run, j] // B, done - NB)
                        dtyp[run, j], dconf[run, j] = _classify(
                            bs[run, j], be[run, j], b0, done - b0, NR, B, sigma[j], min_len, prefer,
                            burst_gap, spike_max, sig_blk[j], gain_crit[j])
                    if is_stuck:
                        z = float(zero[run, j])
                        nt, nc = _STUCK, z / (z + stuck[j])
                    else:
                        nt, nc = dtyp[run, j], dconf[run, j]
                    typ[run, j], conf[run, j], cand[run, j], cnt[run, j], left[run, j] = _revise(
                        typ[run, j], conf[run, j], cand[run, j], cnt[run, j], left[run, j], nt, nc,
                        revise_after, revise_conf)
                for c in range(NT):
                    out[run, kk, j * NT + c] = 1.0 if (active[run, j] and typ[run, j] == c) else 0.0
                out[run, kk, M * NT + j] = conf[run, j] if active[run, j] else 0.0
                out[run, kk, M * NT + M + j] = 1.0 if active[run, j] else 0.0
    return k


class FaultTypeClassifier(ResidualProcessor):
    """Decide the type of an isolated sensor's fault (see the module docstring).

    Parameters
    ----------
    members : sequence of str
        The sensors classified.
    sigma : mapping str -> float
        Member -> standard deviation of its nominal residual (> 0).
    window : int
        Longest window (samples) the type is decided over: its last ``window // block`` complete
        blocks (at least one), held as block sums (the state is ``window // block + 1`` blocks per
        member, not ``window`` samples).
    channels : mapping, optional
        Templates of the input channels with ``{m}`` for the member: ``isolated`` (the isolation
        flag, default ``"peer:{m}:isolated"``), ``stat`` (the normalised residual, >= 1 is out,
        ``"peer:{m}"``), ``r`` (the residual, ``"peer:{m}:e"``), ``x`` (the signal a gain scales,
        ``"peer:{m}:ref"``: the fault-free value the peers give, so that a gain ``g`` makes
        ``r = (g - 1) x``).
    isolated_by : mapping str -> sequence of str, optional
        Member -> further isolation flags (channels, >= 1 isolates) that start its fault as the
        ``isolated`` channel does: e.g. another isolation stage's alarm for that sensor, so that
        what that stage isolates first is typed too; they count only while the member's own
        normalised residual is at least ``confirm``.
    confirm : float
        Level of the member's normalised residual that the ``isolated_by`` flags need (0: none).
    raw : mapping str -> str, optional
        Member -> channel of its raw signal for the stuck check (members without one have none).
    gain_offset : mapping str -> str, optional
        Member -> channel of the zero offset that the signal conditioning removed from it, in the
        member's units: a gain of the raw sensor scales the member plus this, so the gain test's
        signal is ``x`` plus it (members without one: ``x`` alone).
    stuck_after : mapping str -> int, optional
        Member -> zero increments in a row that make it stuck (default: no stuck check).
    lookback : int
        Samples before the first isolation flag included in the window (the detection delay).
    min_len : int
        Shortest segment a change point may leave.
    spike_max : int
        Longest episode (samples) that is a spike.
    burst_gap : int
        Samples below ``release`` that separate two episodes (and end a spike).
    release : float
        The active fault's normalised residual below which it counts towards clearing.
    clear_after : int
        Samples below ``release`` (and not frozen) that end the fault.
    prefer : float
        GLR margin a drift must beat a bias by.
    block : int
        Samples summed into one block (the gain test's block means: longer than the residual's
        high-frequency noise; at least 4 blocks since the change point before a gain is decided);
        the type is decided again each time a block completes.
    sigma_block : mapping str -> float, optional
        Member -> standard deviation of a block mean of its nominal residual (default
        ``sigma / sqrt(block)``, right for white noise).
    gain_crit : float or mapping str -> float
        Level of the gain test's F statistic (the slope of the residual on the signal, in units of
        the block-mean noise variance) above which the fault is a gain. Per member, or one for all.
    revise_after : int
        Hysteresis of the announced type (0: none, the type is each sample's decision): within one
        episode the type first decided is replaced only after it has lost ``revise_after`` samples
        in a row, by the decision then (bias, drift, gain: with a confidence of at least
        ``revise_conf``); a type the episode left comes back only after three times as long; a
        drift never falls back to a bias (a drift is a bias that keeps growing); a frozen signal
        (stuck) is announced at once.
    revise_conf : float
        Confidence (0..1) the new type needs to replace the announced one.
    hold_while_isolated : bool
        The fault does not count towards clearing while an isolation flag is on (an isolation
        stage that still names the sensor while its normalised residual is low, e.g. a CUSUM):
        the episode, and the type announced for it, persist with the fault.

    Examples
    --------
    >>> ftc = FaultTypeClassifier(["a"], {"a": 0.1}, 200, min_len=5)
    >>> ftc.reset(1)
    >>> rng = np.random.default_rng(0)
    >>> for k in range(300):                        # a ramp from sample 100, isolated from 150
    ...     r = 0.1 * rng.standard_normal() + 0.01 * max(0, k - 100)
    ...     out = ftc.step([[float(k >= 150), abs(r) / 0.3, r, 5.0 + np.sin(k / 10)]])
    >>> float(out[0, ftc.output_names.index("a:drift")])
    1.0
    """

    _state_attrs = ("_bs", "_be", "_k", "_active", "_onset", "_type", "_conf", "_below", "_zero",
                    "_last", "_cand", "_cnt", "_left", "_dtype", "_dconf")

    def __init__(self, members: Sequence[str], sigma: Mapping[str, float], window: int, *,
                 channels: Mapping[str, str] | None = None,
                 isolated_by: Mapping[str, Sequence[str]] | None = None, confirm: float = 0.0,
                 raw: Mapping[str, str] | None = None, gain_offset: Mapping[str, str] | None = None,
                 stuck_after: Mapping[str, int] | None = None, lookback: int = 50, min_len: int = 10,
                 spike_max: int = 10, burst_gap: int = 25, release: float = 0.5, clear_after: int = 250,
                 prefer: float = 6.0, block: int = 10, sigma_block: Mapping[str, float] | None = None,
                 gain_crit: float | Mapping[str, float] = 25.0, revise_after: int = 0,
                 revise_conf: float = 0.0, hold_while_isolated: bool = False):
        self.members = [str(m) for m in members]
        if not self.members:
            raise DataError("FaultTypeClassifier needs at least one member")
        self.sigma = {m: float(sigma[m]) for m in self.members}
        if any(not (np.isfinite(s) and s > 0) for s in self.sigma.values()):
            raise DataError(f"sigma must be finite and > 0 per member, got {self.sigma}")
        for what, v, lo in (("window", window, 2), ("lookback", lookback, 0), ("min_len", min_len, 1),
                            ("spike_max", spike_max, 1), ("burst_gap", burst_gap, 1),
                            ("clear_after", clear_after, 1), ("block", block, 1),
                            ("revise_after", revise_after, 0)):
            if isinstance(v, bool) or int(v) != v or v < lo:
                raise DataError(f"{what} must be an integer >= {lo} (samples), got {v!r}")
        self.window, self.lookback, self.min_len = int(window), int(lookback), int(min_len)
        self.spike_max, self.burst_gap, self.clear_after = int(spike_max), int(burst_gap), int(clear_after)
        self.release, self.prefer = float(release), float(prefer)
        self.block, self.revise_after = int(block), int(revise_after)
        self.n_blocks = max(1, self.window // self.block)
        self.revise_conf = float(revise_conf)
        self.hold_while_isolated = bool(hold_while_isolated)
        if not 0.0 <= self.revise_conf <= 1.0:
            raise DataError(f"revise_conf must be a confidence in [0, 1], got {revise_conf!r}")
        gc = gain_crit if isinstance(gain_crit, Mapping) else {m: gain_crit for m in self.members}
        self.gain_crit = {m: float(gc[m]) for m in self.members}
        if any(not (np.isfinite(v) and v > 0) for v in self.gain_crit.values()):
            raise DataError(f"gain_crit must be finite and > 0 per member, got {gain_crit!r}")
        sb = dict(sigma_block or {})
        self.sigma_block = {m: float(sb.get(m, self.sigma[m] / np.sqrt(self.block))) for m in self.members}
        if any(not (np.isfinite(v) and v > 0) for v in self.sigma_block.values()):
            raise DataError(f"sigma_block must be finite and > 0 per member, got {self.sigma_block}")
        ch = {"isolated": "peer:{m}:isolated", "stat": "peer:{m}", "r": "peer:{m}:e", "x": "peer:{m}:ref"}
        ch.update(dict(channels or {}))
        self.channels = ch
        self.raw = {str(k): str(v) for k, v in (raw or {}).items()}
        self.stuck_after = {str(k): int(v) for k, v in (stuck_after or {}).items()}
        bad = sorted((set(self.raw) | set(self.stuck_after)) - set(self.members))
        if bad or set(self.stuck_after) - set(self.raw):
            raise DataError(f"raw and stuck_after must name members, and every stuck_after member needs a "
                            f"raw channel; got raw {self.raw}, stuck_after {self.stuck_after}")
        if gain_offset is not None and not isinstance(gain_offset, Mapping):
            raise DataError(f"gain_offset must map members to channels, got {gain_offset!r}")
        self.gain_offset = {str(k): str(v) for k, v in (gain_offset or {}).items()}
        if set(self.gain_offset) - set(self.members):
            raise DataError(f"gain_offset must map members to channels, got {gain_offset!r}; members "
                            f"{self.members}")
        self.isolated_by = {str(k): [str(c) for c in v] for k, v in (isolated_by or {}).items()}
        if isinstance(isolated_by, str) or any(isinstance(v, str) for v in (isolated_by or {}).values()) \
                or set(self.isolated_by) - set(self.members):
            raise DataError(f"isolated_by must map members to lists of channels, got {isolated_by!r}")
        names = []
        for m in self.members:
            names += [ch[k].format(m=m) for k in ("isolated", "stat", "r", "x")]
            names += self.isolated_by.get(m, [])
            if m in self.raw:
                names.append(self.raw[m])
            if m in self.gain_offset:
                names.append(self.gain_offset[m])
        self.input_names = list(dict.fromkeys(names))
        ix = {n: i for i, n in enumerate(self.input_names)}
        self._ix = np.array([[ix[ch[k].format(m=m)] for k in ("isolated", "stat", "r", "x")]
                             for m in self.members], np.int64)
        self.confirm = float(confirm)
        K = max([len(v) for v in self.isolated_by.values()] + [0])
        self._ixx = np.array([[ix[c] for c in self.isolated_by.get(m, [])]
                              + [-1] * (K - len(self.isolated_by.get(m, []))) for m in self.members],
                             np.int64).reshape(len(self.members), K)
        self._iraw = np.array([ix[self.raw[m]] if m in self.raw else -1 for m in self.members], np.int64)
        off = self.gain_offset
        self._ioff = np.array([ix[off[m]] if m in off else -1 for m in self.members], np.int64)
        self._stuck = np.array([self.stuck_after.get(m, 0) for m in self.members], np.int64)
        self._sigma = np.array([self.sigma[m] for m in self.members])
        self._sig_blk = np.array([self.sigma_block[m] for m in self.members])
        self._gain_crit = np.array([self.gain_crit[m] for m in self.members])
        self.output_names = [f"{m}:{t}" for m in self.members for t in FAULT_TYPES]
        self.output_names += [f"{m}:confidence" for m in self.members] + [f"{m}:active" for m in self.members]
        self.reset(1)

    def reset(self, runs: int = 1) -> None:
        R, M, NR = int(runs), len(self.members), self.n_blocks + 1
        self._R = R
        self._bs = np.zeros((R, M, NR, 5))
        self._be = np.zeros((R, M, NR, 5), np.int64)
        self._k = 0
        self._active = np.zeros((R, M), bool)
        self._onset = np.zeros((R, M), np.int64)
        self._type = np.zeros((R, M), np.int64)
        self._conf = np.zeros((R, M))
        self._below = np.zeros((R, M), np.int64)
        self._zero = np.zeros((R, M), np.int64)
        self._last = np.full((R, M), np.nan)
        self._cand = np.zeros((R, M), np.int64)
        self._cnt = np.zeros((R, M), np.int64)
        self._left = np.zeros((R, M), np.int64)
        self._dtype = np.zeros((R, M), np.int64)
        self._dconf = np.zeros((R, M))

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state of :meth:`get_state`; one saved before the type's hysteresis (no
        ``_cand``, ``_cnt``, ``_left``) continues with the announced type as the episode's first;
        one saved with the raw sample windows (``_rb``, ``_xb``, ``_sb``, before the block
        aggregates) has its samples summed into blocks."""
        if isinstance(state, dict) and "_type" in state and not {"_cand", "_cnt", "_left"} & set(state):
            shape = np.shape(state["_type"])
            state = {**state, "_cand": np.full(shape, -1, np.int64), "_cnt": np.zeros(shape, np.int64),
                     "_left": np.zeros(shape, np.int64)}
        if isinstance(state, dict) and {"_rb", "_xb", "_sb"} <= set(state) and "_bs" not in state:
            state = self._from_windows(state)
        super().set_state(state)

    def _from_windows(self, state: dict[str, Any]) -> dict[str, Any]:
        """A state of the raw-window classifier as block aggregates: the window's samples (ring
        buffers ``(runs, members, window)`` indexed by the sample count modulo their length) summed
        into the blocks they fall in; the latest decision is the announced type."""
        state = dict(state)
        rb, xb, sb = (np.asarray(state.pop(n), float) for n in ("_rb", "_xb", "_sb"))
        if rb.ndim != 3 or rb.shape[1] != len(self.members) or xb.shape != rb.shape or sb.shape != rb.shape:
            raise DataError(f"FaultTypeClassifier state: _rb, _xb, _sb must be (runs, {len(self.members)}, "
                            f"window) alike, got {rb.shape}, {xb.shape}, {sb.shape}")
        R, M, W = rb.shape
        k, B, NR = int(state["_k"]), self.block, self.n_blocks + 1
        bs, be = np.zeros((R, M, NR, 5)), np.zeros((R, M, NR, 5), np.int64)
        k0 = max(0, k - W, (k // B - self.n_blocks) * B)
        be[..., _FO], be[..., _LO] = -1, -1
        for kk in range(k0, k):
            i, s, q = kk % B, (kk // B) % NR, kk % W
            for run in range(R):
                for j in range(M):
                    _accumulate(bs[run, j, s], be[run, j, s], i, rb[run, j, q], xb[run, j, q], sb[run, j, q],
                                self.release, self.burst_gap)
        return {**state, "_bs": bs, "_be": be, "_dtype": np.asarray(state["_type"], np.int64).copy(),
                "_dconf": np.asarray(state["_conf"], float).copy()}

    def resume(self, n_held: int) -> None:
        """After held samples: start again (the window would span the gap)."""
        self.reset(self._R)

    def _advance(self, v: np.ndarray) -> np.ndarray:
        """Samples v (runs, T, inputs) through the kernel -> outputs (runs, T, outputs)."""
        out = np.empty((v.shape[0], v.shape[1], len(self.output_names)))
        self._k = _run_kernel(v, self._ix, self._ixx, self.confirm, self._iraw, self._ioff, self._stuck,
                              self._sigma, self.n_blocks, self.lookback, self.min_len, self.spike_max,
                              self.burst_gap,
                              self.release, self.clear_after, self.prefer, self.block, self._sig_blk,
                              self._gain_crit, self.revise_after, self.revise_conf,
                              self.hold_while_isolated, self._k, self._bs, self._be, self._active,
                              self._onset, self._type, self._conf, self._below, self._zero, self._last,
                              self._cand, self._cnt, self._left, self._dtype, self._dconf, out)
        return out

    def _check(self, v: np.ndarray, k: int) -> None:
        if v.shape[0] != self._R:
            raise DataError(f"sample has {v.shape[0]} runs; the FaultTypeClassifier was reset for {self._R}")
        if not np.all(np.isfinite(v)):
            run, kk, c = np.argwhere(~np.isfinite(v))[0]
            raise DataError(f"FaultTypeClassifier input {self.input_names[c]!r} is not finite at sample "
                            f"{k + kk} (run {run})")

    def _step(self, v: np.ndarray) -> np.ndarray:
        v = np.ascontiguousarray(v, dtype=float)[:, None, :]
        self._check(v, self._k)
        return self._advance(v)[:, 0]

    def run(self, signals: Signals) -> Signals:
        """The outputs over a whole record (the same numbers as :meth:`step`, in one compiled loop)."""
        v = np.ascontiguousarray(signals.values[:, :, signals.index(self.input_names)], dtype=float)
        self.reset(signals.runs)
        self._check(v, 0)
        return Signals(signals.t, self._advance(v), self.output_names, check=False)

    def __repr__(self) -> str:
        return (f"FaultTypeClassifier(members={self.members}, window={self.window}, "
                f"stuck_after={self.stuck_after})")

    def to_dict(self) -> dict[str, Any]:
        return {"members": self.members, "sigma": self.sigma, "window": self.window,
                "channels": self.channels, "isolated_by": self.isolated_by,
                "confirm": self.confirm, "raw": self.raw, "gain_offset": self.gain_offset,
                "stuck_after": self.stuck_after,
                "lookback": self.lookback, "min_len": self.min_len, "spike_max": self.spike_max,
                "burst_gap": self.burst_gap, "release": self.release, "clear_after": self.clear_after,
                "prefer": self.prefer, "block": self.block, "sigma_block": self.sigma_block,
                "gain_crit": self.gain_crit, "revise_after": self.revise_after,
                "revise_conf": self.revise_conf, "hold_while_isolated": self.hold_while_isolated}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FaultTypeClassifier:
        d = dict(d)
        return cls(d.pop("members"), d.pop("sigma"), d.pop("window"), **d)
