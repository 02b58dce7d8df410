"""Moving-window generalised likelihood ratio test for a change in mean and time-gated tests
(threshold design lives in :mod:`fdikit.detect.threshold_design`; its names are re-exported here).

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
from .threshold_design import TIME_UNITS, ThresholdDesign, design_threshold

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
