"""The gain (scale-factor) detector: the GLR of residuals that grow in proportion to a signal
(:class:`GainDetector`, its blocked compiled kernel, the memo that reuses the results of a
previous call for residuals with bitwise the same inputs, and :func:`design_gain`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from ...errors import DataError
from ...signals import Signals
from .base import _BLOCK, _SCALAR_BELOW, _per_channel, _ring_history, _SensorDetector, _window
from .calibrate import _dt, _nominal, _threshold
from .combine import _combine_kernel

__all__ = ["GainDetector", "design_gain"]


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

    Notes
    -----
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
