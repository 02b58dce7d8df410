"""Fault-type classification of an isolated sensor (issue 27, item 2): bias, drift, gain, stuck,
intermittent or spike, from its residual and its signal, with a confidence, revised as evidence
grows.

Once a sensor is isolated (an isolation stage's flag, e.g. :class:`~fdikit.detect.PeerCheck`'s
``peer:m:isolated``) its fault is *active*; the type is decided at every sample over the window
since the onset (from ``lookback`` samples before the first flag; the first ``window`` samples
of it, so that evidence grows until then):

* **stuck** -- the sensor's raw signal has not changed (zero increments) for longer than the
  longest frozen run of the nominal data (``stuck_after``); checked on every sensor that has it,
  isolated or not;
* **gain** first, decided by regression on the signal (the residual's explained variance): over
  the samples since the step's change point (below), averaged in blocks of ``block`` samples (the
  residual's high-frequency noise averages out), the block means of the residual are regressed on
  those of the signal with an intercept, ``r = a + theta x``. The drop of the sum of squares
  against a constant, ``F_b = theta^2 S_xx / s^2`` (``s^2`` the block-mean noise variance, the
  larger of the nominal ``sigma_block^2`` and the fit's own), is the evidence of a gain (a
  residual that moves with the signal, offset or not: a gain scales the sensor's offset too); it
  is a gain when ``F_b >= gain_crit``, unless the ramp's GLR wins (below) and time explains the
  residual better than the signal does (a drift the signal happens to follow). At least 4 blocks
  are needed, and a signal that does not move gives no evidence: with too little excitation the
  fault stays a bias (the default explanation) with a confidence of at most 0.5 until the line
  through the origin, the gain without an offset, is also ruled out (``F_g >= gain_crit``), and is
  revised to a gain as the signal moves. (The sample-wise GLR ``S_g`` below is not used to decide
  a gain: on a coloured residual a constant step beat by a few units of ``S_g`` out of thousands
  typed biases as gains once the signal moved.)
* **intermittent** -- at least two episodes of the normalised residual above 1 in the window,
  separated by ``burst_gap`` samples below ``release``, or of the residual's block means above 5
  block-mean standard deviations, separated by blocks below 2 (short bursts that a low-passed
  statistic smears into one); **spike** -- one episode no longer than
  ``spike_max`` samples, followed by ``burst_gap`` samples below ``release``;
* otherwise a step and a ramp with an unknown change point ``j`` compete by their GLR (``sigma``
  the nominal residual's standard deviation): a step ``r_i = b`` (**bias**),
  ``S_b = max_j (sum r)^2 / (sigma^2 n)``; a ramp ``r_i = s (i - j + 1)`` (**drift**),
  ``S_d = max_j (sum tau r)^2 / (sigma^2 sum tau^2)``; and ``S_g = max_j (sum x r)^2 / (sigma^2 sum
  x^2)``. Drift wins over bias only when its statistic exceeds the bias one by ``prefer`` (a step
  is the default explanation); the confidence is the softmax of ``S / 2`` over the three.

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


@njit(cache=True)
def _classify(r, x, st, sigma, min_len, prefer, release, burst_gap, spike_max, block, sig_blk, gain_crit):
    """Type and confidence of one member's fault from its window since the onset, oldest first:
    residual r (n,), signal x (n,), normalised residual st (n,) (see the module docstring)."""
    n = r.size
    # the GLRs [S_b, S_d, S_g], each maximised over the change point (segments of at least min_len
    # samples ending at the newest sample): sums over the last L samples, newest first
    sr = sar = sxr = sxx = 0.0
    sb = sd = sg = -np.inf
    Lb = 0                                            # the step's change point: the last Lb samples
    for L in range(1, n + 1):
        i = n - L
        sr += r[i]
        sar += (L - 1) * r[i]                         # age (0 = newest) times r
        sxr += x[i] * r[i]
        sxx += x[i] * x[i]
        if L < min_len:
            continue
        s_tr = L * sr - sar                           # sum tau r, tau = 1 (oldest) .. L (newest)
        stt = L * (L + 1) * (2 * L + 1) / 6.0
        if sr * sr / L > sb:
            sb, Lb = sr * sr / L, L
        sd = max(sd, s_tr * s_tr / stt)
        sg = max(sg, sxr * sxr / sxx if sxx > 0 else 0.0)
    S = np.zeros(3)
    if n >= min_len:
        s2 = sigma * sigma
        S[0], S[1], S[2] = sb / s2, sd / s2, sg / s2
    smax = max(S[0], max(S[1], S[2]))
    e = np.exp(0.5 * (S - smax))
    esum = e[0] + e[1] + e[2]
    fb, fg, by_time = _gain_test(r[n - Lb:], x[n - Lb:], block, sig_blk)
    if by_time and S[1] > S[0] + prefer:
        fb = 0.0                                      # a drift, which the signal happens to follow
    if fb >= gain_crit:                               # the residual follows the signal: a gain
        return _GAIN, 1.0 / (1.0 + np.exp(-0.5 * (fb - gain_crit)))
    # episodes of the residual out, separated by at least burst_gap samples below release
    first = last = -1
    n_ep = 0
    below = 0                                         # samples below release since the last one out
    for i in range(n):
        if st[i] >= 1.0:
            if first < 0:
                first = i
                n_ep = 1
            elif below >= burst_gap:
                n_ep += 1
            last = i
            below = 0
        elif st[i] < release:
            below += 1
    if n_ep < 2:
        # bursts shorter than the statistic's low-pass smear into one episode there: count them on
        # the residual's block means too
        n_ep = max(n_ep, _block_episodes(r, block, sig_blk, max(1, burst_gap // block)))
    if n_ep >= 2:
        return _INTER, 1.0 - 0.5 ** (n_ep - 1)
    if first >= 0:
        if last - first < spike_max and below >= burst_gap:
            return _SPIKE, min(1.0, below / (2.0 * burst_gap))
    best = _DRIFT if S[1] > S[0] + prefer else _BIAS
    c = e[best] / esum
    if best == _BIAS and fg < gain_crit:
        c = min(c, 0.5)                               # a gain is not ruled out yet (too little excitation)
    return best, c


#: block-mean levels (in block-mean noise standard deviations) of a burst and of the quiet between
_BURST_ON, _BURST_OFF = 5.0, 2.0


@njit(cache=True)
def _block_episodes(r, block, sig_blk, gap):
    """Episodes of the residual r (n,): runs of block means with ``|mean| >= 5 sig_blk``, separated
    by at least ``gap`` blocks below ``2 sig_blk`` (blocks aligned to the newest sample)."""
    nb = r.size // block
    off = r.size - nb * block
    n_ep, seen, below = 0, False, 0
    for b in range(nb):
        m = 0.0
        for i in range(block):
            m += r[off + b * block + i]
        z = abs(m / block) / sig_blk
        if z >= _BURST_ON:
            if not seen or below >= gap:
                n_ep += 1
            seen, below = True, 0
        elif z < _BURST_OFF:
            below += 1
    return n_ep


@njit(cache=True)
def _gain_test(r, x, block, sig_blk):
    """``(F_b, F_g, by_time)``: the block means of r (n,) regressed on those of x with an intercept; F_b the
    drop of the residual sum of squares against a constant (the slope: a gain, or a time trend that
    x follows), F_g against a line through the origin (a gain without an
    offset), each over the noise variance of a block mean (the larger of ``sig_blk^2`` and the fit's
    own); ``by_time`` where a line in time fits the block means better than the line in x.
    ``(0, 0, False)`` with fewer than 4 blocks or no excitation."""
    nb = r.size // block
    if nb < 4:
        return 0.0, 0.0, False
    rm, xm = np.zeros(nb), np.zeros(nb)
    off = r.size - nb * block                         # the newest nb * block samples
    for b in range(nb):
        for i in range(block):
            rm[b] += r[off + b * block + i]
            xm[b] += x[off + b * block + i]
        rm[b] /= block
        xm[b] /= block
    mr, mx, mt = rm.mean(), xm.mean(), 0.5 * (nb - 1)
    sxx = sxy = syy = stt = sty = sx0 = sxy0 = 0.0
    for b in range(nb):
        dx, dy, dt = xm[b] - mx, rm[b] - mr, b - mt
        sxx += dx * dx
        sxy += dx * dy
        syy += dy * dy
        stt += dt * dt
        sty += dt * dy
        sx0 += xm[b] * xm[b]
        sxy0 += xm[b] * rm[b]
    if sxx <= 0.0 or sx0 <= 0.0:
        return 0.0, 0.0, False
    rss = max(syy - sxy * sxy / sxx, 0.0)             # a + theta x
    rss_t = max(syy - sty * sty / stt, 0.0)           # a + s t: a drift
    s2 = max(sig_blk * sig_blk, rss / (nb - 2))
    fb = (syy - rss) / s2
    fg = max(syy + nb * mr * mr - sxy0 * sxy0 / sx0 - rss, 0.0) / s2
    return fb, fg, rss_t < rss


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
def _run_kernel(V, ix, ixx, confirm, iraw, stuck, sigma, window, lookback, min_len, spike_max, burst_gap,
                release, clear_after, prefer, block, sig_blk, gain_crit, revise_after, revise_conf, hold_iso,
                k, rb, xb, sb, active, onset, typ, conf, below, zero, last, cand, cnt, left, out):
    """The classifier over samples V (R, T, inputs) from sample count k, state updated in place;
    outputs into out (R, T, outputs). Returns the new sample count."""
    R, T = V.shape[0], V.shape[1]
    M, W, NT = ix.shape[0], window, 6
    r_seg, x_seg, s_seg = np.empty(W), np.empty(W), np.empty(W)
    for kk in range(T):
        p = k % W
        for run in range(R):
            for j in range(M):
                rb[run, j, p] = V[run, kk, ix[j, 2]]
                xb[run, j, p] = V[run, kk, ix[j, 3]]
                sb[run, j, p] = V[run, kk, ix[j, 1]]
                if iraw[j] >= 0:
                    raw = V[run, kk, iraw[j]]
                    zero[run, j] = zero[run, j] + 1 if raw == last[run, j] else 0
                    last[run, j] = raw
        k += 1
        for run in range(R):
            for j in range(M):
                stat = V[run, kk, ix[j, 1]]
                is_stuck = stuck[j] > 0 and zero[run, j] >= stuck[j]
                iso = V[run, kk, ix[j, 0]] >= 1.0
                for c in range(ixx.shape[1]):
                    if ixx[j, c] >= 0 and V[run, kk, ixx[j, c]] >= 1.0 and V[run, kk, ix[j, 1]] >= confirm:
                        iso = True
                if not active[run, j] and (iso or is_stuck):
                    onset[run, j] = max(k - 1 - lookback, 0)
                    active[run, j] = True
                    cand[run, j], cnt[run, j], left[run, j] = -1, -1, 0
                if active[run, j] and stat < release and not is_stuck and not (hold_iso and iso):
                    below[run, j] += 1
                else:
                    below[run, j] = 0
                if below[run, j] >= clear_after:
                    active[run, j] = False
                if active[run, j]:
                    if is_stuck:
                        z = float(zero[run, j])
                        nt, nc = _STUCK, z / (z + stuck[j])
                    else:
                        n = min(W, k - onset[run, j])
                        k0 = max(onset[run, j], k - W)
                        for i in range(n):
                            q = (k0 + i) % W
                            r_seg[i], x_seg[i], s_seg[i] = rb[run, j, q], xb[run, j, q], sb[run, j, q]
                        nt, nc = _classify(r_seg[:n], x_seg[:n], s_seg[:n], sigma[j], min_len, prefer,
                                           release, burst_gap, spike_max, block, sig_blk[j], gain_crit[j])
                    typ[run, j], conf[run, j], cand[run, j], cnt[run, j], left[run, j] = _revise(
                        typ[run, j], conf[run, j], cand[run, j], cnt[run, j], left[run, j], nt, nc,
                        revise_after, revise_conf)
                for i in range(NT):
                    out[run, kk, j * NT + i] = 1.0 if (active[run, j] and typ[run, j] == i) else 0.0
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
        Longest window (samples) the type is decided over.
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
        Samples averaged into one block mean for the gain test (longer than the residual's
        high-frequency noise; at least 4 blocks since the change point before a gain is decided).
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

    _state_attrs = ("_rb", "_xb", "_sb", "_k", "_active", "_onset", "_type", "_conf", "_below", "_zero",
                    "_last", "_cand", "_cnt", "_left")

    def __init__(self, members: Sequence[str], sigma: Mapping[str, float], window: int, *,
                 channels: Mapping[str, str] | None = None,
                 isolated_by: Mapping[str, Sequence[str]] | None = None, confirm: float = 0.0,
                 raw: Mapping[str, str] | None = None,
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
        self._stuck = np.array([self.stuck_after.get(m, 0) for m in self.members], np.int64)
        self._sigma = np.array([self.sigma[m] for m in self.members])
        self._sig_blk = np.array([self.sigma_block[m] for m in self.members])
        self._gain_crit = np.array([self.gain_crit[m] for m in self.members])
        self.output_names = [f"{m}:{t}" for m in self.members for t in FAULT_TYPES]
        self.output_names += [f"{m}:confidence" for m in self.members] + [f"{m}:active" for m in self.members]
        self.reset(1)

    def reset(self, runs: int = 1) -> None:
        R, M, W = int(runs), len(self.members), self.window
        self._R = R
        self._rb = np.zeros((R, M, W))
        self._xb = np.zeros((R, M, W))
        self._sb = np.zeros((R, M, W))
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

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state of :meth:`get_state`; one saved before the type's hysteresis (no
        ``_cand``, ``_cnt``, ``_left``) continues with the announced type as the episode's first."""
        if isinstance(state, dict) and "_type" in state and not {"_cand", "_cnt", "_left"} & set(state):
            shape = np.shape(state["_type"])
            state = {**state, "_cand": np.full(shape, -1, np.int64), "_cnt": np.zeros(shape, np.int64),
                     "_left": np.zeros(shape, np.int64)}
        super().set_state(state)

    def resume(self, n_held: int) -> None:
        """After held samples: start again (the window would span the gap)."""
        self.reset(self._R)

    def _advance(self, v: np.ndarray) -> np.ndarray:
        """Samples v (runs, T, inputs) through the kernel -> outputs (runs, T, outputs)."""
        out = np.empty((v.shape[0], v.shape[1], len(self.output_names)))
        self._k = _run_kernel(v, self._ix, self._ixx, self.confirm, self._iraw, self._stuck, self._sigma,
                              self.window, self.lookback, self.min_len, self.spike_max, self.burst_gap,
                              self.release, self.clear_after, self.prefer, self.block, self._sig_blk,
                              self._gain_crit, self.revise_after, self.revise_conf,
                              self.hold_while_isolated, self._k, self._rb,
                              self._xb, self._sb, self._active, self._onset, self._type, self._conf,
                              self._below, self._zero, self._last, self._cand, self._cnt, self._left, out)
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
                "confirm": self.confirm, "raw": self.raw,
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
