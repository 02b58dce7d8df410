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
* **gain** first when its GLR (below) beats the bias one by ``prefer`` (a gain's residual comes and
  goes with the signal, which would else look like bursts);
* **intermittent** -- at least two episodes of the normalised residual above 1 in the window,
  separated by ``burst_gap`` samples below ``release``; **spike** -- one episode no longer than
  ``spike_max`` samples, followed by ``burst_gap`` samples below ``release``;
* otherwise the one-parameter models with an unknown change point ``j`` compete by their GLR
  (``sigma`` the nominal residual's standard deviation): a step ``r_i = b`` (**bias**),
  ``S_b = max_j (sum r)^2 / (sigma^2 n)``; a ramp ``r_i = s (i - j + 1)`` (**drift**),
  ``S_d = max_j (sum tau r)^2 / (sigma^2 sum tau^2)``; a residual proportional to the signal
  ``r_i = theta x_i`` (**gain**), ``S_g = max_j (sum x r)^2 / (sigma^2 sum x^2)``. Drift or gain
  wins over bias only when its statistic exceeds the bias one by ``prefer`` (a step is the
  default explanation); the confidence is the softmax of ``S / 2`` over the three.

The fault stays active -- its episode does not clear -- while the normalised residual stays above
``release`` or the signal stays frozen; it ends after ``clear_after`` samples below. Outputs, per
member ``m``: ``m:<type>`` for each of :data:`FAULT_TYPES` (1 while active with that type),
``m:confidence`` and ``m:active``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError

__all__ = ["FAULT_TYPES", "FaultTypeClassifier"]

#: The fault types the classifier tells apart, in output order.
FAULT_TYPES = ("bias", "drift", "gain", "stuck", "intermittent", "spike")
_BIAS, _DRIFT, _GAIN, _STUCK, _INTER, _SPIKE = range(6)


def _glr_scores(r: np.ndarray, x: np.ndarray, sigma: float, min_len: int) -> np.ndarray:
    """``[S_b, S_d, S_g]`` of residual r (n,) and signal x (n,), each maximised over the change
    point j (segments of at least ``min_len`` samples ending at the newest sample)."""
    n = r.size
    rr, xr = r[::-1], x[::-1]
    L = np.arange(1, n + 1, dtype=float)              # samples since the candidate change point
    sr = np.cumsum(rr)                                # sum r over the last L samples
    # sum tau r with tau = L - (age) : tau of the newest sample is L, of the oldest 1
    sar = np.cumsum(np.arange(n) * rr)                # sum age r (age 0 = newest)
    str_ = L * sr - sar
    stt = L * (L + 1) * (2 * L + 1) / 6.0
    sxr = np.cumsum(xr * rr)
    sxx = np.cumsum(xr * xr)
    ok = L >= min_len
    if not ok.any():
        return np.zeros(3)
    s2 = sigma * sigma
    sb = np.max((sr * sr / L)[ok]) / s2
    sd = np.max((str_ * str_ / stt)[ok]) / s2
    g = np.where(sxx > 0, sxr * sxr / np.where(sxx > 0, sxx, 1.0), 0.0)
    sg = np.max(g[ok]) / s2
    return np.array([sb, sd, sg])


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
        GLR margin drift or gain must beat bias by.

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
                    "_last")

    def __init__(self, members: Sequence[str], sigma: Mapping[str, float], window: int, *,
                 channels: Mapping[str, str] | None = None, raw: Mapping[str, str] | None = None,
                 stuck_after: Mapping[str, int] | None = None, lookback: int = 50, min_len: int = 10,
                 spike_max: int = 10, burst_gap: int = 25, release: float = 0.5, clear_after: int = 250,
                 prefer: float = 6.0):
        self.members = [str(m) for m in members]
        if not self.members:
            raise DataError("FaultTypeClassifier needs at least one member")
        self.sigma = {m: float(sigma[m]) for m in self.members}
        if any(not (np.isfinite(s) and s > 0) for s in self.sigma.values()):
            raise DataError(f"sigma must be finite and > 0 per member, got {self.sigma}")
        for what, v, lo in (("window", window, 2), ("lookback", lookback, 0), ("min_len", min_len, 1),
                            ("spike_max", spike_max, 1), ("burst_gap", burst_gap, 1),
                            ("clear_after", clear_after, 1)):
            if isinstance(v, bool) or int(v) != v or v < lo:
                raise DataError(f"{what} must be an integer >= {lo} (samples), got {v!r}")
        self.window, self.lookback, self.min_len = int(window), int(lookback), int(min_len)
        self.spike_max, self.burst_gap, self.clear_after = int(spike_max), int(burst_gap), int(clear_after)
        self.release, self.prefer = float(release), float(prefer)
        ch = {"isolated": "peer:{m}:isolated", "stat": "peer:{m}", "r": "peer:{m}:e", "x": "peer:{m}:ref"}
        ch.update(dict(channels or {}))
        self.channels = ch
        self.raw = {str(k): str(v) for k, v in (raw or {}).items()}
        self.stuck_after = {str(k): int(v) for k, v in (stuck_after or {}).items()}
        bad = sorted((set(self.raw) | set(self.stuck_after)) - set(self.members))
        if bad or set(self.stuck_after) - set(self.raw):
            raise DataError(f"raw and stuck_after must name members, and every stuck_after member needs a "
                            f"raw channel; got raw {self.raw}, stuck_after {self.stuck_after}")
        names = []
        for m in self.members:
            names += [ch[k].format(m=m) for k in ("isolated", "stat", "r", "x")]
            if m in self.raw:
                names.append(self.raw[m])
        self.input_names = list(dict.fromkeys(names))
        ix = {n: i for i, n in enumerate(self.input_names)}
        self._ix = np.array([[ix[ch[k].format(m=m)] for k in ("isolated", "stat", "r", "x")]
                             for m in self.members], np.int64)
        self._iraw = np.array([ix[self.raw[m]] if m in self.raw else -1 for m in self.members], np.int64)
        self._stuck = np.array([self.stuck_after.get(m, 0) for m in self.members], np.int64)
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

    def resume(self, n_held: int) -> None:
        """After held samples: start again (the window would span the gap)."""
        self.reset(self._R)

    def _segment(self, run: int, j: int, n: int, k0: int) -> tuple[np.ndarray, np.ndarray]:
        """n samples of run's member j from sample k0 (still in the buffer), oldest first."""
        W = self.window
        k0 = max(k0, self._k - W)
        idx = (np.arange(k0, k0 + n) % W)
        return self._rb[run, j, idx], self._xb[run, j, idx]

    def _classify(self, run: int, j: int) -> tuple[int, float]:
        m = self.members[j]
        if self._stuck[j] > 0 and self._zero[run, j] >= self._stuck[j]:
            z = float(self._zero[run, j])
            return _STUCK, z / (z + self._stuck[j])
        n = int(min(self.window, self._k - self._onset[run, j]))
        r, x = self._segment(run, j, n, int(self._onset[run, j]))
        S = _glr_scores(r, x, self.sigma[m], self.min_len)
        e = np.exp(0.5 * (S - S.max()))
        if S[2] > S[0] + self.prefer and S[2] >= S[1]:
            return _GAIN, float(e[_GAIN] / e.sum())   # bursts in step with the signal: a gain
        st = self._stat_seg(run, j, n, int(self._onset[run, j]))
        on = np.flatnonzero(st >= 1.0)
        if on.size:
            # episodes of the residual out, separated by at least burst_gap samples below release
            cq = np.concatenate([[0], np.cumsum(st < self.release)])
            sep = (cq[on[1:]] - cq[on[:-1] + 1]) >= self.burst_gap
            n_ep = 1 + int(sep.sum())
            if n_ep >= 2:
                return _INTER, 1.0 - 0.5 ** (n_ep - 1)
            quiet_end = cq[-1] - cq[on[-1] + 1]
            if on[-1] - on[0] < self.spike_max and quiet_end >= self.burst_gap:
                return _SPIKE, min(1.0, quiet_end / (2.0 * self.burst_gap))
        best = _DRIFT if S[1] > S[0] + self.prefer else _BIAS
        return best, float(e[best] / e.sum())

    def _stat_seg(self, run: int, j: int, n: int, k0: int) -> np.ndarray:
        k0 = max(k0, self._k - self.window)
        idx = (np.arange(k0, k0 + n) % self.window)
        return self._sb[run, j, idx]

    def _step(self, v: np.ndarray) -> np.ndarray:
        if v.shape[0] != self._R:
            raise DataError(f"sample has {v.shape[0]} runs; the FaultTypeClassifier was reset for {self._R}")
        if not np.all(np.isfinite(v)):
            run, c = np.argwhere(~np.isfinite(v))[0]
            raise DataError(f"FaultTypeClassifier input {self.input_names[c]!r} is not finite at sample "
                            f"{self._k} (run {run})")
        iso, stat, r, x = (v[:, self._ix[:, i]] for i in range(4))
        p = self._k % self.window
        self._rb[:, :, p], self._xb[:, :, p], self._sb[:, :, p] = r, x, stat
        has = self._iraw >= 0
        if has.any():
            raw = v[:, np.where(has, self._iraw, 0)]
            same = (raw == self._last) & has
            self._zero = np.where(same, self._zero + 1, 0)
            self._last = raw
        self._k += 1
        stuck = (self._stuck > 0) & (self._zero >= self._stuck)
        start = ~self._active & ((iso >= 1.0) | stuck)
        self._onset = np.where(start, np.maximum(self._k - 1 - self.lookback, 0), self._onset)
        self._active |= start
        self._below = np.where(self._active & (stat < self.release) & ~stuck, self._below + 1, 0)
        self._active &= self._below < self.clear_after
        for run, j in np.argwhere(self._active):
            self._type[run, j], self._conf[run, j] = self._classify(run, j)
        out = np.zeros((self._R, len(self.output_names)))
        M, T = len(self.members), len(FAULT_TYPES)
        for j in range(M):
            out[:, j * T:(j + 1) * T] = (self._type[:, j, None] == np.arange(T)) & self._active[:, j, None]
        out[:, M * T:M * T + M] = np.where(self._active, self._conf, 0.0)
        out[:, M * T + M:] = self._active
        return out

    def __repr__(self) -> str:
        return (f"FaultTypeClassifier(members={self.members}, window={self.window}, "
                f"stuck_after={self.stuck_after})")

    def to_dict(self) -> dict[str, Any]:
        return {"members": self.members, "sigma": self.sigma, "window": self.window,
                "channels": self.channels, "raw": self.raw, "stuck_after": self.stuck_after,
                "lookback": self.lookback, "min_len": self.min_len, "spike_max": self.spike_max,
                "burst_gap": self.burst_gap, "release": self.release, "clear_after": self.clear_after,
                "prefer": self.prefer}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FaultTypeClassifier:
        d = dict(d)
        return cls(d.pop("members"), d.pop("sigma"), d.pop("window"), **d)
