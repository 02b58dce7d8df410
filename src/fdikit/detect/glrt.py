"""Moving-window generalised likelihood ratio test for a change in mean, time-gated tests and
threshold design for a target false-alarm probability.

GLRT (luo-et-al, eq. (24), with the moving window of Section V-A)::

    g_k = 1 / (2 sigma^2) * max_{k-W+1 <= j <= k} (1 / (k-j+1)) * (sum_{i=j..k} (r_i - mu_0))^2

(before the window is full, ``j`` runs from the first sample). Window sums are differences of
running (prefix) sums, O(1) per sample amortised; the running sums are re-anchored every ``W``
samples so that none spans more than ``2W`` samples, so nothing drifts over a long record (a
million-sample test checks it) and batch and streaming perform the same operations in the same
order (identical results). The maximum over the ``W`` candidate change times is the one O(W)
part, with independent terms that the compiler vectorises (about 0.3 ns per term here;
``benchmarks/bench_glrt.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals
from .threshold import ABSOLUTE_DEFAULT

__all__ = ["GLRT", "TIME_UNITS", "ThresholdDesign", "TimeGated", "design_threshold", "glrt_statistic"]


@njit(cache=True, fastmath={"nnan", "ninf"})
def _glrt_sample(Q, p, n, invL):  # pragma: no cover - compiled
    """g (unscaled) at the newest sample: ``max_L (Q[p] - Q[p-L])^2 / L`` for L = 1..n.

    The L terms are independent (no running accumulation), so the loop vectorises; ``max`` is
    exact in any order, so the result does not depend on how it is vectorised. (Inputs are
    checked finite before they reach here, which is what ``nnan``/``ninf`` assume.)
    """
    top = Q[p]
    best = 0.0
    for L in range(1, n + 1):
        d = top - Q[p - L]
        v = d * d * invL[L - 1]
        best = max(best, v)
    return best


@njit(cache=True)
def _glrt_batch(x, mu0, scale, W, out, Qs, pos, counts):  # pragma: no cover - compiled
    """x (runs, T, C) -> out (runs, T, C).

    ``Qs`` (runs, C, 2W + 1) holds prefix sums of the centred residuals relative to an anchor,
    ``pos`` the index of the newest one: window sums are differences ``Q[p] - Q[p - L]``, O(1)
    each. When ``p`` reaches the end of the array, the last ``W + 1`` prefix sums move to the
    front with the oldest of them subtracted (re-anchoring, O(W) once per W samples, O(1)
    amortised), so a stored prefix sum never spans more than 2W samples: a record of any length
    is as accurate as a short one.
    """
    R, T, C = x.shape
    invL = 1.0 / np.arange(1, W + 1)
    top = 2 * W
    for r in range(R):
        for c in range(C):
            Q = Qs[r, c]
            p = pos[r, c]
            count = counts[r, c]
            m = mu0[c]
            sc = scale[c]
            for k in range(T):
                if p == top:  # re-anchor: keep the last W + 1 prefix sums, the oldest becomes 0
                    base = Q[top - W]
                    for i in range(W + 1):
                        Q[i] = Q[top - W + i] - base
                    p = W
                Q[p + 1] = Q[p] + (x[r, k, c] - m)
                p += 1
                if count < W:
                    count += 1
                out[r, k, c] = _glrt_sample(Q, p, count, invL) * sc
            pos[r, c] = p
            counts[r, c] = count


def glrt_statistic(r: np.ndarray, mu0, sigma2, W: int) -> np.ndarray:
    """GLRT statistic of eq. (24) for residuals ``r`` shaped (T,), (runs, T) or (runs, T, C).

    Examples
    --------
    >>> import numpy as np
    >>> g = glrt_statistic(np.full(10, 1.5), mu0=1.0, sigma2=0.25, W=4)
    >>> float(g[-1])          # W d^2 / (2 sigma^2) = 4 * 0.25 / 0.5
    2.0
    """
    x = np.asarray(r, float)
    shape = x.shape
    if x.ndim == 1:
        x = x[None, :, None]
    elif x.ndim == 2:
        x = x[:, :, None]
    g = GLRT._compute(x, np.broadcast_to(np.asarray(mu0, float), (x.shape[2],)).copy(),
                      np.broadcast_to(np.asarray(sigma2, float), (x.shape[2],)).copy(), int(W))
    return g.reshape(shape)


class GLRT(ResidualProcessor):
    """Moving-window GLRT for a change in mean, one statistic per input channel (eq. (24)).

    Parameters
    ----------
    inputs : sequence of str
        Residual channels.
    mu0, sigma2 : float or sequence
        Nominal mean and variance of each residual (calibrate them from nominal Monte Carlo
        runs with :meth:`calibrate`).
    W : int
        Window length in samples (>= 1).

    Notes
    -----
    Outputs ``"<input>:glrt"`` per input. The statistic is never negative, so the ``absolute``
    default of :class:`~fdikit.detect.Hold` and :func:`design_threshold`
    (:data:`~fdikit.detect.threshold.ABSOLUTE_DEFAULT`) leaves it unchanged: design the thresholds
    of all channels at once with ``design_threshold(glrt.run(nominal), pfa, per=..., Z=Z)`` and
    apply them with ``Hold(glrt.output_names, design.threshold, Z)``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> s = Signals(np.arange(6.0), [0, 0, 0, 1, 1, 1], ["r"])
    >>> GLRT(["r"], mu0=0.0, sigma2=0.5, W=3).run(s)["r:glrt"].round(3).tolist()
    [[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]]
    """

    def __init__(self, inputs: Sequence[str], mu0=0.0, sigma2=1.0, W: int = 50):
        self.input_names = [str(s) for s in inputs]
        c = len(self.input_names)
        if c == 0:
            raise DataError("GLRT needs at least one input channel")
        if int(W) != W or W < 1:
            raise DataError(f"GLRT window W must be an integer >= 1, got {W}")
        self.W = int(W)
        self.mu0 = np.broadcast_to(np.asarray(mu0, float), (c,)).copy()
        self.sigma2 = np.broadcast_to(np.asarray(sigma2, float), (c,)).copy()
        if not (np.all(np.isfinite(self.mu0)) and np.all(np.isfinite(self.sigma2))):
            raise DataError("GLRT mu0 and sigma2 must be finite")
        if np.any(self.sigma2 <= 0):
            bad = self.input_names[int(np.argmax(self.sigma2 <= 0))]
            raise DataError(f"GLRT sigma2 must be positive; channel {bad!r} has {self.sigma2.min()}")
        self.output_names = [f"{s}:glrt" for s in self.input_names]
        self.reset(1)

    @classmethod
    def calibrate(cls, nominal: Signals, inputs: Sequence[str], W: int, *, skip: int = 0) -> GLRT:
        """A GLRT whose mu0 and sigma2 are the mean and variance of nominal residuals.

        ``nominal`` holds nominal (fault-free) runs; the first ``skip`` samples of each run
        (transients) are left out.
        """
        r = nominal.values[:, skip:, nominal.index(list(inputs))].reshape(-1, len(inputs))
        if r.shape[0] < 2:
            raise DataError(f"need at least 2 nominal samples to calibrate, got {r.shape[0]}")
        return cls(inputs, r.mean(axis=0), r.var(axis=0, ddof=1), W)

    @staticmethod
    def _compute(x, mu0, sigma2, W, state=None):
        R, T, C = x.shape
        out = np.empty((R, T, C))
        if state is None:
            Qs = np.zeros((R, C, 2 * W + 1))
            pos = np.zeros((R, C), np.int64)
            counts = np.zeros((R, C), np.int64)
        else:
            Qs, pos, counts = state
        _glrt_batch(np.ascontiguousarray(x), mu0, 1.0 / (2.0 * sigma2), W, out, Qs, pos, counts)
        return out

    _state_attrs = ("_state", "_k")

    def to_dict(self) -> dict:
        """Configuration as plain data (see :mod:`fdikit.base.artifacts`)."""
        return {"inputs": list(self.input_names), "mu0": self.mu0.tolist(), "sigma2": self.sigma2.tolist(),
                "W": self.W}

    @classmethod
    def from_dict(cls, d: dict) -> GLRT:
        return cls(d["inputs"], d["mu0"], d["sigma2"], d["W"])

    def reset(self, runs: int = 1) -> None:
        c = len(self.input_names)
        self._state = (np.zeros((runs, c, 2 * self.W + 1)), np.zeros((runs, c), np.int64),
                       np.zeros((runs, c), np.int64))
        self._k = 0

    def _step(self, r: np.ndarray) -> np.ndarray:
        if r.shape[0] != self._state[0].shape[0]:
            raise DataError(f"sample has {r.shape[0]} runs; the GLRT was reset for {self._state[0].shape[0]}")
        self._check(r[:, None, :], self._k)
        self._k += 1
        return self._compute(r[:, None, :], self.mu0, self.sigma2, self.W, self._state)[:, 0]

    def _check(self, x: np.ndarray, k0: int) -> None:
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(f"GLRT input {self.input_names[c]!r} is not finite at sample {k0 + k} "
                            f"(run {run})")

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        if signals.n_samples < self.W:
            raise DataError(f"record of {signals.n_samples} samples is shorter than the GLRT window "
                            f"W = {self.W}")
        self._check(x, 0)
        self.reset(signals.runs)
        out = self._compute(x, self.mu0, self.sigma2, self.W, self._state)
        return Signals(signals.t, out, self.output_names, check=False)


class TimeGated(ResidualProcessor):
    """Time-gated test of luo-et-al eq. (35): outcome 1 at time t when the statistic is above
    ``q`` at t > T and stayed at or below ``q`` for every sample with time <= T.

    Inputs are statistic channels (e.g. ``"r4:glrt"``); outputs ``"<input>:gated"`` (0 or 1).
    Time is measured from the first sample after :meth:`reset` (the start of the record).
    """

    def __init__(self, inputs: Sequence[str], q, T: float):
        self.input_names = [str(s) for s in inputs]
        self.q = np.broadcast_to(np.asarray(q, float), (len(self.input_names),)).copy()
        if not np.isfinite(T) or T < 0:
            raise DataError(f"gate time T must be finite and >= 0, got {T}")
        self.T = float(T)
        self.output_names = [f"{s}:gated" for s in self.input_names]
        self.reset(1)

    _state_attrs = ("_early", "_t0", "_k")
    needs_time = True  # the Monitor passes the sample time: step_at(t, r)

    def to_dict(self) -> dict:
        return {"inputs": list(self.input_names), "q": self.q.tolist(), "T": self.T}

    @classmethod
    def from_dict(cls, d: dict) -> TimeGated:
        return cls(d["inputs"], d["q"], d["T"])

    def reset(self, runs: int = 1) -> None:
        self._early = np.zeros((runs, len(self.input_names)), bool)
        self._t0: float | None = None
        self._k = 0

    def step_at(self, t: float, r) -> np.ndarray:
        """Streaming step with the sample time (the gate needs it)."""
        r = np.atleast_2d(np.asarray(r, float))
        if self._t0 is None:
            self._t0 = t
        above = r > self.q
        if t - self._t0 <= self.T:
            self._early |= above
            return np.zeros_like(r)
        return (above & ~self._early).astype(float)

    def _step(self, r: np.ndarray) -> np.ndarray:  # pragma: no cover - needs time
        raise DataError("TimeGated needs sample times: use run(signals) or step_at(t, r)")

    def run(self, signals: Signals) -> Signals:
        g = signals.values[:, :, signals.index(self.input_names)]
        above = g > self.q
        early_mask = (signals.t - signals.t[0]) <= self.T
        early = above[:, early_mask].any(axis=1)  # (runs, C)
        out = above & ~early[:, None, :] & ~early_mask[None, :, None]
        self._early, self._t0 = early, float(signals.t[0])
        return Signals(signals.t, out.astype(float), self.output_names, check=False)


class ThresholdDesign(dict):
    """Result of :func:`design_threshold`: a dict whose keys are also attributes.

    A missing attribute raises :class:`AttributeError` (so ``hasattr``, :func:`copy.deepcopy`,
    pickling and numpy's protocol look-ups behave as for any object).

    Examples
    --------
    >>> import copy
    >>> d = ThresholdDesign(threshold=1.5, method="empirical")
    >>> d.threshold, hasattr(d, "nope"), copy.deepcopy(d) == d
    (1.5, False, True)
    """

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(f"ThresholdDesign has no field {name!r}; fields: {sorted(self)}") from None

    def __dir__(self):
        return [*super().__dir__(), *self.keys()]


#: Time units a false-alarm target may be given per (seconds, with the sample time in seconds).
TIME_UNITS = {"second": 1.0, "minute": 60.0, "hour": 3600.0, "day": 86400.0}


def _order_statistic(crit: np.ndarray, pfa: float, margin: float) -> tuple[float, float]:
    """The per-run order-statistic threshold (the historic design) and its design-data rate."""
    runs = crit.size
    allowed = int(np.floor(pfa * runs + 1e-9))  # runs that may alarm
    srt = np.sort(crit)
    base = srt[runs - 1 - allowed] if allowed < runs else srt[0]
    thr = base * (1 + margin) if base > 0 else base + margin
    thr = float(np.nextafter(thr, np.inf)) if thr <= base else float(thr)
    return thr, float(np.mean(crit >= thr))


def _apply_margin(q: float, margin: float) -> float:
    if margin == 0:
        return float(q)
    return float(q * (1 + margin) if q > 0 else q + margin)


def _clopper_pearson(k: int, n: int, level: float) -> tuple[float, float]:
    from scipy.stats import beta

    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def _upper_level(v: np.ndarray, count: float) -> float:
    """Level exceeded by ``count`` (fractional) of the values ``v``: linear interpolation between the
    order statistics (sorted descending, the ``count``-th and the next)."""
    s = -np.sort(-v[np.isfinite(v)])
    if count <= 0:
        return float(s[0])
    i = int(np.floor(count))
    if i >= s.size:
        return float(s[-1])
    hi = s[i - 1] if i >= 1 else s[0]
    lo = s[i]
    f = count - i
    return float(hi + f * (lo - hi)) if i >= 1 else float(lo)


class _Refused(Exception):
    pass


def _tail_fit(x: np.ndarray, p: float, n: int, n_eff: float, block: int, *, tail_events: float,
              max_extrapolation: float, n_boot: int, level: float, seed: int, onset_ratio: float = 1.0,
              rate_unit: float = 1.0, what: str) -> dict:
    """GPD design of the level with marginal exceedance probability ``p / onset_ratio``.

    ``x`` (records, T) values (``-inf`` never exceeds), ``n`` the denominator (samples), ``n_eff``
    the effective sample size, ``block`` the bootstrap block length. Raises ``_Refused`` with the
    reason when the data cannot support the target.
    """
    from .tail import fit_gpd, fit_gpd_weighted, gpd_level, gpd_rate

    pm = p / onset_ratio  # marginal exceedance probability wanted
    if n_eff * 0.1 < tail_events:
        raise _Refused(f"{n_eff:.0f} effective samples are too few for a tail fit (a GPD above the "
                       f"90 % quantile needs >= {tail_events:.0f} effective excesses, i.e. >= "
                       f"{10 * tail_events:.0f} effective samples)")
    p_u = min(0.1, tail_events / n_eff)
    extrap = p_u * onset_ratio / p
    if extrap > max_extrapolation:
        raise _Refused(f"the data shows rates down to {p_u * onset_ratio * rate_unit:.3g} {what} "
                       f"({tail_events:.0f} of {n_eff:.0f} effective samples); the target "
                       f"{p * rate_unit:.3g} lies {extrap:.0f}x below it, beyond the GPD tail's limit "
                       f"max_extrapolation = {max_extrapolation:g}; need >= "
                       f"{tail_events * onset_ratio / (p * max_extrapolation) * n / n_eff:.3g} samples "
                       f"({tail_events * onset_ratio / (p * max_extrapolation):.3g} effective)")
    flat = x.ravel()
    u = _upper_level(flat, p_u * n)
    above = flat > u
    k_u = int(above.sum())
    if k_u < 10:
        raise _Refused(f"only {k_u} samples above the tail threshold u = {u:.6g}")
    pu_hat = k_u / n
    exc = flat[above] - u
    xi, sig = fit_gpd(exc)
    q = gpd_level(u, pu_hat, xi, sig, pm)
    # block bootstrap of the fit: non-overlapping blocks within the records
    R, T = x.shape
    b = int(max(1, min(block, T)))
    nbr = T // b  # blocks per record (the remainder joins the last block)
    bid_t = np.minimum(np.arange(T) // b, nbr - 1)
    bid = (np.arange(R)[:, None] * nbr + bid_t[None, :]).ravel()
    nb = R * nbr
    blen = np.bincount(bid, minlength=nb).astype(float)
    bcnt = np.bincount(bid[above], minlength=nb).astype(float)
    eb = bid[above]
    rng = np.random.default_rng(seed)
    rates = np.empty(n_boot)
    for i in range(n_boot):
        w = np.bincount(rng.integers(0, nb, nb), minlength=nb).astype(float)
        pu_b = float(w @ bcnt / (w @ blen))
        ww = w[eb]
        if ww.sum() < 10:
            rates[i] = 0.0
            continue
        xb, sb = fit_gpd_weighted(exc, ww, (xi, sig))
        rates[i] = gpd_rate(u, pu_b, xb, sb, q) * onset_ratio
    a = (1 - level) / 2
    return {"threshold": q, "ci": (float(np.quantile(rates, a)), float(np.quantile(rates, 1 - a))),
            "tail": {"u": u, "p_u": pu_hat, "xi": xi, "sigma": sig, "n_excess": k_u,
                     "extrapolation": float(pu_hat * onset_ratio / p), "onset_ratio": onset_ratio}}


def _onset_counts(m: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Alarm onsets (0 -> 1 transitions, a record's first sample counting as after a 0) at each level:
    ``#(m_k > q) - #(min(m_k, m_{k-1}) > q)``."""
    v1 = np.sort(m[np.isfinite(m)])
    prev = np.concatenate([np.full((m.shape[0], 1), -np.inf), m[:, :-1]], axis=1)
    v2 = np.minimum(m, prev)
    v2 = np.sort(v2[np.isfinite(v2)])
    g1 = v1.size - np.searchsorted(v1, levels, side="right")
    g2 = v2.size - np.searchsorted(v2, levels, side="right")
    return g1 - g2


def _onsets(alarm: np.ndarray) -> np.ndarray:
    """Onset indicator of a boolean alarm (records, T)."""
    prev = np.concatenate([np.zeros((alarm.shape[0], 1), bool), alarm[:, :-1]], axis=1)
    return alarm & ~prev


def _design_channel(m: np.ndarray, pfa: float, per, unit: float | None, dt: float | None, *, margin: float,
                    method: str, min_events: float, tail_events: float, max_extrapolation: float,
                    level: float, n_boot: int, seed: int, name: str) -> dict:
    """Design one channel. ``m`` (runs, T): the held statistic (-inf where no alarm is possible)."""
    from .tail import block_length, block_rate_ci

    R, T = m.shape
    n = R * T
    out: dict = {"channel": name, "samples": n, "runs": R}
    if per == "run":
        crit = m.max(axis=1)
        out["critical_values"] = crit
        out.update(block_length=1, tau=1.0, n_eff=float(R))
        events = pfa * R
        if pfa == 0 or method == "empirical" or (method == "auto" and events >= min_events):
            if method == "empirical" and 0 < events < min_events:
                raise _Refused(f"{R} runs for a per-run target of {pfa:g}: {events:.3g} expected false "
                               f"alarms, the empirical design needs >= {min_events:g} "
                               f"(>= {min_events / pfa:.0f} runs)")
            thr, ach = _order_statistic(crit, pfa, margin)
            k = int(np.sum(crit >= thr))
            out.update(threshold=thr, achieved=ach, method="max" if pfa == 0 or events < 1 else "empirical",
                       ci=_clopper_pearson(k, R, level))
            if pfa == 0 or events < 1:
                out["note"] = (f"threshold above the largest of {R} nominal critical values: no false-alarm "
                               f"probability below 1/{R} is shown by these data")
            else:
                out["note"] = f"order statistic of {R} runs ({events:.3g} expected false alarms)"
            return out
        try:
            fit = _tail_fit(crit[:, None], pfa, R, float(R), 1, tail_events=tail_events,
                            max_extrapolation=max_extrapolation, n_boot=n_boot, level=level, seed=seed,
                            what="per run")
        except _Refused as exc:
            raise _Refused(f"{R} runs for a per-run target of {pfa:g} ({events:.3g} expected false alarms; "
                           f"the empirical design needs >= {min_events:g}, i.e. >= "
                           f"{min_events / pfa:.0f} runs): {exc}") from None
        thr = _apply_margin(fit["threshold"], margin)
        out.update(threshold=thr, achieved=float(np.mean(crit > thr)), method="gpd", ci=fit["ci"],
                   tail=fit["tail"],
                   note=(f"{events:.3g} expected false alarms in {R} runs is below min_events = "
                         f"{min_events:g}:"
                         f" GPD tail of the per-run maxima above u = {fit['tail']['u']:.6g} "
                         f"(extrapolated {fit['tail']['extrapolation']:.3g}x)"))
        return out

    bl = block_length(m)
    tau, b = bl["tau"], bl["block"]
    n_eff = n / tau
    out.update(block_length=b, tau=tau, n_eff=n_eff)
    if per == "sample":
        p, rate_unit, what, ratio = pfa, 1.0, "per sample", 1.0
        events = p * n_eff
        if pfa == 0:
            q = float(np.nextafter(m.max(), np.inf))
            out.update(threshold=_apply_margin(q, margin), achieved=0.0, method="max",
                       ci=block_rate_ci(m > q, b, level=level, n_boot=n_boot, seed=seed),
                       note=f"threshold above the largest of {n} nominal samples")
            return out
        if p * n >= np.isfinite(m).sum():
            raise _Refused(f"target {p:g} per sample is above the fraction of samples that can alarm")
        if method == "empirical" or (method == "auto" and events >= min_events):
            if events < min_events:
                raise _Refused(f"{n} samples ({n_eff:.0f} effective, autocorrelation time {tau:.3g}) for a "
                               f"target of {p:g} per sample: {events:.3g} effective false alarms, the "
                               f"empirical design needs >= {min_events:g}")
            q = _apply_margin(_upper_level(m.ravel(), p * n), margin)
            ach = float(np.mean(m > q))
            out.update(threshold=q, achieved=ach, method="empirical",
                       ci=block_rate_ci(m > q, b, level=level, n_boot=n_boot, seed=seed),
                       note=(f"empirical quantile of {n} samples ({n_eff:.0f} effective, autocorrelation "
                             f"time {tau:.3g} samples, bootstrap blocks of {b})"))
            if events < 1:   # min_events = 0 below one expected alarm: the data show no rate this small
                out.update(method="max", note=(
                    f"{events:.3g} effective false alarms expected in {n} samples ({n_eff:.0f} effective): "
                    f"the threshold lies at the top of the data, and no rate below ~1/{n_eff:.0f} per "
                    "sample is shown by them"))
            return out
    else:  # per unit of operating time: alarm onsets per `unit` seconds
        p = pfa * dt / unit  # onsets per sample
        rate_unit, what = unit / dt, f"per {unit:g} s"
        if pfa == 0:
            q = float(np.nextafter(m.max(), np.inf))
            out.update(threshold=_apply_margin(q, margin), achieved=0.0, method="max", ci=(0.0, 0.0),
                       note=f"threshold above the largest of {n} nominal samples")
            return out
        events = p * n  # onsets are counted once per episode: no correlation correction
        fin = m[np.isfinite(m)]
        if method == "empirical" or (method == "auto" and events >= min_events):
            if events < min_events:
                raise _Refused(f"{n} samples ({n * dt / unit:.3g} units of {unit:g} s) for a target of "
                               f"{pfa:g} {what}: {events:.3g} expected false alarms, the empirical design "
                               f"needs >= {min_events:g}")
            levels = np.unique(fin)[::-1]  # descending
            cnt = _onset_counts(m, levels)
            env = np.maximum.accumulate(cnt)
            ok = np.nonzero(env <= p * n)[0]
            q = float(levels[ok[-1]]) if ok.size else float(np.nextafter(levels[0], np.inf))
            q = _apply_margin(q, margin)
            on = _onsets(m > q)
            lo, hi = block_rate_ci(on, b, level=level, n_boot=n_boot, seed=seed)
            out.update(threshold=q, achieved=float(on.sum() / n * rate_unit), method="empirical",
                       ci=(lo * rate_unit, hi * rate_unit),
                       note=(f"empirical: {int(on.sum())} alarm onsets in {n * dt / unit:.3g} units of "
                             f"{unit:g} s (bootstrap blocks of {b} samples)"))
            if events < 1:   # min_events = 0 below one expected alarm: the data show no rate this small
                out.update(method="max", note=(
                    f"{events:.3g} false alarms expected in {n * dt / unit:.3g} units of {unit:g} s: the "
                    f"threshold lies at the top of the data, and no rate below ~1 per {n * dt / unit:.3g} "
                    "units is shown by them"))
            return out
        # the tail: marginal GPD times the ratio of onsets to exceedances (the inverse mean length of
        # an exceedance episode), measured at the highest level with >= min_events onsets (episodes
        # shorten as the level rises, so the ratio nearest the target is the one to use)
        srt = np.sort(fin)[::-1]
        levels = srt[: min(srt.size, int(max(50 * min_events, 1000)) * max(1, int(np.ceil(tau))))]
        cnt = _onset_counts(m, levels)
        hit = np.nonzero(cnt >= max(min_events, 1.0))[0]
        u0 = float(levels[hit[0]]) if hit.size else float(levels[-1])
        k_exc = max(int(np.sum(m > u0)), 1)
        ratio = float(_onset_counts(m, np.array([u0]))[0]) / k_exc
        ratio = min(max(ratio, 1.0 / max(tau, 1.0)), 1.0)
    try:
        fit = _tail_fit(m, p, n, n_eff, b, tail_events=tail_events, max_extrapolation=max_extrapolation,
                        n_boot=n_boot, level=level, seed=seed, onset_ratio=ratio, rate_unit=rate_unit,
                        what=what)
    except _Refused as exc:
        raise _Refused(f"{n} samples ({n_eff:.0f} effective, autocorrelation time {tau:.3g} samples) for a "
                       f"target of {pfa:g} {what}: {exc}") from None
    thr = _apply_margin(fit["threshold"], margin)
    if per == "sample":
        ach = float(np.mean(m > thr))
    else:
        ach = float(_onsets(m > thr).sum() / n * rate_unit)
    ci = (fit["ci"][0] * rate_unit, fit["ci"][1] * rate_unit)
    out.update(threshold=thr, achieved=ach, method="gpd", ci=ci, tail=fit["tail"],
               note=(f"target below what {n_eff:.0f} effective samples show ({events:.3g} effective false "
                     f"alarms < min_events = {min_events:g}): GPD tail above u = {fit['tail']['u']:.6g} "
                     f"(p_u = {fit['tail']['p_u']:.3g}, xi = {fit['tail']['xi']:.3g}, extrapolated "
                     f"{fit['tail']['extrapolation']:.3g}x)"
                     + ("" if per == "sample" else f", onsets per exceedance {ratio:.3g}")))
    return out


def design_threshold(
    nominal,
    pfa: float,
    *,
    per: str | float = "run",
    Z: int = 1,
    margin: float = 0.0,
    absolute: bool = ABSOLUTE_DEFAULT,
    dt: float | None = None,
    channels: Sequence[str] | None = None,
    family_wise: bool = False,
    method: str = "auto",
    min_events: float = 10.0,
    tail_events: float = 50.0,
    max_extrapolation: float = 100.0,
    confidence: float = 0.95,
    n_boot: int = 200,
    seed: int = 0,
) -> ThresholdDesign:
    """Thresholds for a false-alarm target per sample, per run or per unit of operating time, from
    nominal (fault-free) data of one or many statistics.

    The alarm rule is :class:`~fdikit.detect.Hold`'s (luo-et-al eq. (34)): an alarm at sample k when
    the statistic (``|x|`` with ``absolute``) is above the threshold ``q`` at samples
    ``k-Z+1 .. k``, i.e. when ``m_k = min(x_{k-Z+1}, ..., x_k) > q``. The target ``pfa`` means,
    with ``per``:

    ``"run"``
        The probability that a nominal run raises at least one alarm. Runs are independent; the
        threshold is the order statistic of the per-run critical values ``c_i = max_k m_k`` that
        leaves a fraction of at most ``pfa`` of the runs at or above it (the historic design),
        when the runs hold at least ``min_events`` expected false alarms (``pfa * runs``);
        otherwise the GPD tail of the ``c_i`` (below).
    ``"sample"``
        The probability that the alarm is on at a nominal sample (the fraction of alarmed
        samples; the first ``Z - 1`` samples of a run cannot alarm and count as quiet).
    a duration in seconds, or ``"second"``, ``"minute"``, ``"hour"``, ``"day"``
        The expected number of false alarms (alarm onsets, 0 -> 1 transitions: an episode counts
        once) per that much operating time; needs the sample time ``dt`` (from a
        :class:`~fdikit.Signals`' ``t`` or given). A per-run target on one long record is this with
        the run's duration (an upper bound of the per-run probability).

    Serial correlation (the usual case of one long real record): the moving-block bootstrap's
    block length comes from the record's autocorrelation (Politis & White 2004,
    :func:`fdikit.detect.tail.block_length`), and the record has ``n_eff = n / tau`` effective
    samples, ``tau`` its integrated autocorrelation time. The data *show* a rate ``p`` per sample
    when ``p * n_eff >= min_events`` (per time: ``min_events`` expected onsets); the threshold is
    then the empirical level (interpolated order statistic). Below that, a generalised Pareto
    distribution is fitted to the excesses over the level exceeded by ``tail_events`` effective
    samples (at most the 90 % quantile; :func:`scipy.stats.genpareto`), and the threshold is its
    level for the target, as long as that lies at most ``max_extrapolation`` times below the
    tail threshold's rate; per unit of time the marginal tail is scaled by the ratio of onsets to
    exceedances at the tail threshold. Further still, or with too few effective samples for a fit,
    the target is refused (:class:`~fdikit.DataError`, naming the numbers). Every design states
    its method, the effective samples and a block-bootstrap confidence interval of the true rate
    at the threshold (for independent runs: Clopper-Pearson).

    Parameters
    ----------
    nominal : Signals, or array (T,), (runs, T) or (runs, T, channels)
        Nominal statistics or residuals. A 1-D array is ONE residual over time (one record, one
        channel); a 2-D array is runs of one channel; a 3-D array and a Signals give one threshold
        per channel (Signals: named by its channels, ``dt`` from its time).
    pfa : float
        Target (``>= 0``; ``< 1`` for a probability). ``0`` puts the threshold above the largest
        nominal value (no rate is claimed).
    per : str or float
        What ``pfa`` counts (above). Default ``"run"``.
    Z : int
        Hold length of the alarm rule (>= 1).
    margin : float
        Relative safety margin added to each threshold (``q (1 + margin)``; ``q + margin`` when
        ``q <= 0``). Default 0.
    absolute : bool
        Compare ``|x|`` (default :data:`~fdikit.detect.threshold.ABSOLUTE_DEFAULT`, True: the same
        default as :class:`~fdikit.detect.Hold`; a GLRT statistic is non-negative, so it does not
        matter there).
    dt : float, optional
        Sample time, s (for a target per unit of time with array input).
    channels : sequence of str, optional
        Names of the channels of array input (default ``ch0, ch1, ...``).
    family_wise : bool
        The target applies to the family: a false alarm is any channel alarming. Each channel is
        designed for ``pfa / channels`` (Bonferroni: the family's rate is at most the target
        whatever the correlation between the channels; conservative by up to the number of
        channels when they are strongly correlated). ``family_achieved`` reports the family's
        rate on the design data.
    method : {"auto", "empirical", "gpd"}
        ``"auto"`` as above; ``"empirical"`` refuses rather than extrapolate (with ``min_events =
        0`` it never refuses: the historic behaviour); ``"gpd"`` always fits the tail.
    min_events : float
        Effective false alarms at the target the data must hold for the empirical design.
    tail_events : float
        Effective excesses above the GPD's threshold.
    max_extrapolation : float
        Largest ratio between the tail threshold's rate and the target.
    confidence : float
        Level of the confidence intervals.
    n_boot : int
        Bootstrap replicates.
    seed : int
        Seed of the bootstrap.

    Returns
    -------
    ThresholdDesign
        ``threshold`` (float for 1-D/2-D input, array (channels,) otherwise), ``achieved`` (the
        rate on the design data, in the units of ``per``; ``achieved_pfa`` is the same),
        ``ci`` ((2,) or (channels, 2), the ``confidence`` interval of the true rate at the
        threshold), ``method`` (``"empirical"``, ``"gpd"`` or ``"max"``), ``note`` (what was done,
        with the numbers), ``samples``, ``runs``, ``n_eff``, ``tau``, ``block_length``, ``tail``
        (GPD ``u``, ``p_u``, ``xi``, ``sigma``, ``n_excess``, ``extrapolation``; None when not
        used), ``target`` (per channel), ``pfa``, ``per``, ``unit`` (s, per-time targets),
        ``Z``, ``absolute``, ``channels``, ``family_wise``, ``family_achieved``, and for per-run
        targets ``critical_values`` ((runs,) or (runs, channels)).

    Raises
    ------
    DataError
        Bad shapes, non-finite data, or a target these data cannot support (naming the channel,
        the samples or runs, the effective samples and what would be needed).

    Examples
    --------
    Per run, from 400 nominal runs of a chi-square statistic:

    >>> import numpy as np
    >>> g = np.random.default_rng(0).chisquare(1, size=(400, 500))
    >>> d = design_threshold(g, 0.05, Z=3)
    >>> d.method, d.achieved_pfa <= 0.05
    ('empirical', True)

    Per sample, on one long correlated record of two residuals (1-D would be one residual):

    >>> from scipy.signal import lfilter
    >>> r = lfilter([1.0], [1.0, -0.9], np.random.default_rng(1).normal(size=(1, 200_000, 2)), axis=1)
    >>> d = design_threshold(r, 1e-3, per="sample", absolute=False)    # one-sided: r > q
    >>> d.method, d.threshold.shape, bool(15 < d.tau[0] < 23)      # (1 + 0.9) / (1 - 0.9) = 19
    (['empirical', 'empirical'], (2,), True)
    >>> design_threshold(r, 1e-7, per="sample")     # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: channel 'ch0': 200000 samples (... effective, ...
    """
    from ..signals import Signals as _Signals

    unit = None
    if isinstance(nominal, _Signals):
        g = nominal.values
        names = list(nominal.names)
        if dt is None and nominal.n_samples > 1:
            dt = float((nominal.t[-1] - nominal.t[0]) / (nominal.n_samples - 1))
        single = False
    else:
        if np.ma.isMaskedArray(nominal) and np.ma.getmaskarray(nominal).any():
            where = np.argwhere(np.ma.getmaskarray(nominal))[0].tolist()
            raise DataError(f"nominal data hold {int(np.ma.count_masked(nominal))} masked entries (the "
                            f"first at index {where}); a threshold is designed on complete records: pass "
                            "the unmasked runs or segments")
        g = np.asarray(np.ma.getdata(nominal) if np.ma.isMaskedArray(nominal) else nominal, float)
        single = g.ndim in (1, 2)
        if g.ndim == 1:  # one residual over time: one record
            g = g[None, :, None]
        elif g.ndim == 2:
            g = g[:, :, None]
        if g.ndim != 3:
            raise DataError(f"nominal statistic must be (T,), (runs, T) or (runs, T, channels), got shape "
                            f"{np.shape(nominal)}")
        names = [str(c) for c in channels] if channels is not None else [f"ch{i}" for i in range(g.shape[2])]
        if len(names) != g.shape[2]:
            raise DataError(f"{len(names)} channel names for {g.shape[2]} channels")
    one_d = not isinstance(nominal, _Signals) and np.ndim(nominal) == 1
    if isinstance(per, str) and per in TIME_UNITS:
        unit = TIME_UNITS[per]
    elif not isinstance(per, str):
        unit = float(per)
        if not unit > 0:
            raise DataError(f"a per-time target needs a positive duration, got per = {per}")
    elif per not in ("run", "sample"):
        raise DataError(f"per must be 'run', 'sample', a duration in s or one of {list(TIME_UNITS)}, "
                        f"got {per!r}")
    kind = "time" if unit is not None else per
    if kind == "time" and (dt is None or not dt > 0):
        raise DataError(f"a target per {per} needs the sample time: give dt (s) or a Signals")
    if pfa < 0 or not np.isfinite(pfa) or (kind != "time" and pfa >= 1):
        raise DataError(f"target false-alarm {'rate' if kind == 'time' else 'probability'} must be in "
                        f"[0, {'inf' if kind == 'time' else '1'}), got {pfa}")
    if kind != "run" and g.shape[1] == 1 and g.shape[0] > 1 and not isinstance(nominal, _Signals):
        raise DataError(f"nominal array of shape {np.shape(nominal)} is {g.shape[0]} runs of ONE sample "
                        f"each, and a target per {per} is judged over time; for one record of one channel "
                        f"pass a 1-D array ({g.shape[0]},) or shape (1, {g.shape[0]}); for channels over "
                        "time, shape (1, T, channels)")
    if method not in ("auto", "empirical", "gpd"):
        raise DataError(f"method must be 'auto', 'empirical' or 'gpd', got {method!r}")
    if int(Z) != Z or Z < 1:
        raise DataError(f"Z must be an integer >= 1, got {Z}")
    if g.shape[1] < Z:
        raise DataError(f"records of {g.shape[1]} samples are shorter than the hold Z = {Z}")
    if not np.all(np.isfinite(g)):
        run, k, c = np.argwhere(~np.isfinite(g))[0]
        raise DataError(f"nominal statistic {names[c]!r} is not finite at run {run}, sample {k}")
    if one_d and kind == "run":
        raise DataError(f"a 1-D array is one residual over time (one record of {g.shape[1]} samples): a "
                        "per-run target needs many runs; give per='sample' or a duration (per='hour', "
                        "with dt), or runs as a (runs, T) array")
    if absolute:
        g = np.abs(g)
    flat = g.reshape(-1, g.shape[2])
    const = np.nonzero(np.all(flat == flat[:1], axis=0))[0]
    if const.size:
        c = int(const[0])
        raise DataError(f"nominal statistic {names[c]!r} is constant ({'|x| = ' if absolute else ''}"
                        f"{flat[0, c]:g}) over all {flat.shape[0]} samples: a threshold above it would "
                        "alarm on any change, and no false-alarm rate can be estimated; check the channel "
                        "(a disconnected or saturated signal?) or leave it out")
    from numpy.lib.stride_tricks import sliding_window_view

    R, T, C = g.shape
    held = sliding_window_view(g, int(Z), axis=1).min(axis=3) if Z > 1 else g
    m = np.concatenate([np.full((R, int(Z) - 1, C), -np.inf), held], axis=1) if Z > 1 else g
    target = pfa / C if family_wise else pfa
    designs = []
    for c in range(C):
        try:
            designs.append(_design_channel(
                np.ascontiguousarray(m[:, :, c]), target, kind, unit, dt, margin=margin,
                method="auto" if method == "gpd" else method,
                min_events=np.inf if method == "gpd" else min_events, tail_events=tail_events,
                max_extrapolation=max_extrapolation, level=confidence, n_boot=int(n_boot), seed=seed + c,
                name=names[c]))
        except _Refused as exc:
            raise DataError(f"channel {names[c]!r}: {exc}") from None
    thr = np.array([d["threshold"] for d in designs])
    # the family's rate on the design data: any channel alarming
    alarm = m > thr
    anyal = alarm.any(axis=2)
    if kind == "run":
        fam = float(np.mean(anyal.any(axis=1)))
    elif kind == "sample":
        fam = float(np.mean(anyal))
    else:
        fam = float(_onsets(anyal).sum() / (R * T) * unit / dt)

    def col(key, default=None):
        v = [d.get(key, default) for d in designs]
        return v[0] if single else v

    out = ThresholdDesign(
        threshold=float(thr[0]) if single else thr,
        achieved_pfa=col("achieved"), achieved=col("achieved"),
        ci=np.array(designs[0]["ci"]) if single else np.array([d["ci"] for d in designs]),
        method=col("method"), note=col("note"), tail=col("tail"),
        samples=R * T, runs=R, n_eff=col("n_eff"), tau=col("tau"), block_length=col("block_length"),
        target=target if single else [target] * C, pfa=float(pfa), per=per, unit=unit, dt=dt, Z=int(Z),
        absolute=bool(absolute), channels=names, family_wise=bool(family_wise), family_achieved=fam,
        confidence=float(confidence))
    if kind == "run":
        out["critical_values"] = designs[0]["critical_values"] if single else \
            np.stack([d["critical_values"] for d in designs], axis=1)
    return out
