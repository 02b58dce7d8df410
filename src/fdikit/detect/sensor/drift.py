"""The drift detector: the GLR of a ramp from an unknown sample in a moving window
(:class:`DriftDetector`, its blocked compiled ramp kernel, and :func:`design_drift`).
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

__all__ = ["DriftDetector", "design_drift"]


#: Relative band around the approximate step GLR of :func:`_ramp_kernel` within which the exact one
#: is computed (the approximation is within 3.01 * 2^-53 of it).
_STEP_BAND = 2.0**-40


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

    Notes
    -----
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
