"""Plausibility checks on a monitor's input channels: physical range, rate of change, spikes.

A sample that fails a check is *invalid*: the :class:`~fdikit.monitor.Monitor` flags it with a
reason and holds its state over it exactly as over a NaN -- nothing implausible ever reaches a
filter or a probability. :class:`Plausibility` is the per-channel rule (plain data, validated);
:class:`PlausibilityChecker` is its streaming runtime, shared by the Monitor's batch and
streaming paths so both flag the same samples.

The rules, for a channel with value ``x`` at time ``t`` of sample ``k``:

* **range**: ``x < min`` or ``x > max`` is invalid;
* **rate**: with ``x_v, t_v`` the channel's last *valid* sample (the last one the monitor
  accepted), ``|x - x_v| > max_rate * (t - t_v)`` is a rate violation. A change that fast is
  invalid unless the step from the immediately preceding sample (when it arrived, one period
  earlier, finite) is itself within the rate: a genuine step of the signal then costs one
  sample, and the signal is accepted at its new level from the next one (without that escape a
  real step would be refused forever);
* **spike**: the increments ``d`` of the last ``window`` pairs of consecutive valid samples give
  a median ``m`` and a robust scale ``s = 1.4826 * MAD(d)`` (the MAD is the median absolute
  deviation from ``m``; 1.4826 makes ``s`` the standard deviation for Gaussian increments). A
  sample is a spike when both its increment from the preceding sample departs from ``m`` by more
  than ``spike * s`` and its change from the last valid sample, ``n`` periods back, departs from
  ``n * m`` by more than ``spike * s * sqrt(n)``. The test needs ``window`` increments collected
  and a preceding sample that arrived (not the first sample after a gap or a NaN). When the MAD
  is 0 -- a quantised signal whose increments are mostly zero (41 of 50 equal samples) -- ``s``
  is 1.4826 times the median of the non-zero deviations from ``m`` (the scale of the increments
  that move: about the quantisation step), so the test does not collapse; only a window of
  identical increments (a constant or constant-slope signal) gives ``s == 0``, and then the test
  is skipped. A spike is an isolated sample: a level that persists for two samples is accepted
  as a step;
* and, for every input channel whatever the rules, a value with ``|x| > max_abs`` (the
  Monitor's absurd-magnitude limit, 1e12 by default) is invalid.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["Plausibility", "PlausibilityChecker"]

#: 1.4826 * MAD estimates the standard deviation of Gaussian data.
_MAD_SCALE = 1.4826


def _num(x: Any, what: str) -> float | None:
    if x is None:
        return None
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise DataError(f"plausibility {what} must be a number, got {x!r}")
    x = float(x)
    if not math.isfinite(x):
        raise DataError(f"plausibility {what} must be finite, got {x}")
    return x


def _robust_scale(win: np.ndarray, meds: np.ndarray) -> np.ndarray:
    """1.4826 MAD of the increments ``win`` (..., W) about ``meds`` (...); where it is 0, 1.4826
    times the median of the non-zero deviations (0 only when every deviation is 0)."""
    dev = np.abs(win - meds[..., None])
    scales = _MAD_SCALE * np.median(dev, axis=-1)
    flat = scales == 0
    if flat.any():
        d = dev[flat]
        nz = np.zeros(d.shape[0])
        has = (d > 0).any(axis=-1)
        if has.any():
            nz[has] = _MAD_SCALE * np.nanmedian(np.where(d[has] > 0, d[has], np.nan), axis=-1)
        scales[flat] = nz
    return scales


@dataclass(frozen=True)
class Plausibility:
    """Plausibility rule of one input channel (see the module docstring for the exact tests).

    Parameters
    ----------
    min, max : float, optional
        Physical range in the channel's unit; a value outside it is invalid (``min < max``).
    max_rate : float, optional
        Largest plausible rate of change, in channel units per second (> 0).
    spike : float, optional
        Robust outlier threshold ``k`` (> 0): a sample whose increment lies more than ``k``
        robust standard deviations (1.4826 MAD) of the recent increments from their median is a
        spike. 5 to 10 is typical.
    window : int
        Number of recent increments of valid consecutive samples behind the spike test (>= 5).

    Examples
    --------
    >>> p = Plausibility(min=-50.0, max=50.0, max_rate=200.0)
    >>> p.max, p.window
    (50.0, 50)
    >>> Plausibility(min=1.0, max=0.0)
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: plausibility min (1) must be below max (0)
    """

    min: float | None = None
    max: float | None = None
    max_rate: float | None = None
    spike: float | None = None
    window: int = 50

    def __post_init__(self):
        lo, hi = _num(self.min, "min"), _num(self.max, "max")
        rate, spike = _num(self.max_rate, "max_rate"), _num(self.spike, "spike")
        if lo is not None and hi is not None and not lo < hi:
            raise DataError(f"plausibility min ({lo:g}) must be below max ({hi:g})")
        if rate is not None and not rate > 0:
            raise DataError(f"plausibility max_rate must be positive (units per second), got {rate:g}")
        if spike is not None and not spike > 0:
            raise DataError(f"plausibility spike must be a positive multiple of the MAD, got {spike:g}")
        if isinstance(self.window, bool) or not isinstance(self.window, (int, np.integer)) or self.window < 5:
            raise DataError(f"plausibility window must be an integer number of samples >= 5, got "
                            f"{self.window!r}")
        for name, v in (("min", lo), ("max", hi), ("max_rate", rate), ("spike", spike),
                        ("window", int(self.window))):
            object.__setattr__(self, name, v)

    @classmethod
    def from_mapping(cls, d: Mapping[str, Any], where: str = "plausibility") -> Plausibility:
        """A rule from a config table; an unknown key is an error naming it and ``where``.

        Examples
        --------
        >>> Plausibility.from_mapping({"max": 5, "spike": 8}).spike
        8.0
        """
        if not isinstance(d, Mapping):
            raise DataError(f"{where}: expected a table of plausibility keys, got {d!r}")
        allowed = ("min", "max", "max_rate", "spike", "window")
        bad = [k for k in d if k not in allowed]
        if bad:
            raise DataError(f"{where}: unknown plausibility keys {bad}; allowed: {list(allowed)}")
        try:
            return cls(**dict(d))
        except DataError as exc:
            raise DataError(f"{where}: {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """The rule as plain data (``None`` for an unset test)."""
        return {"min": self.min, "max": self.max, "max_rate": self.max_rate, "spike": self.spike,
                "window": self.window}


class PlausibilityChecker:
    """Streaming runtime of the plausibility rules of a monitor's input channels.

    :meth:`check` judges a sample without touching the state; :meth:`observe` then records it
    (``accepted`` when the monitor processed it) and :meth:`gap` marks missing samples. The
    Monitor calls them in that order for every sample of both its batch and streaming paths.

    Parameters
    ----------
    names : sequence of str
        The input channels, in the column order of the samples given to :meth:`check`.
    rules : mapping channel -> Plausibility
    max_abs : float or None
        Absurd-magnitude limit applied to every channel (``None``: off).

    Examples
    --------
    >>> c = PlausibilityChecker(["y"], {"y": Plausibility(max=50.0)}, max_abs=1e12)
    >>> c.reset(1, dt=0.01)
    >>> print(c.check(12, 0.12, np.array([[1e300]])))
    channel 'y' at sample 12 (t = 0.12 s): 1e+300 exceeds the absurd-magnitude limit 1e+12 (max_abs)
    >>> print(c.check(12, 0.12, np.array([[60.0]])))
    channel 'y' at sample 12 (t = 0.12 s): 60 above max 50 (plausibility)
    """

    def __init__(self, names: Sequence[str], rules: Mapping[str, Plausibility] | None,
                 max_abs: float | None):
        self.names = list(names)
        rules = dict(rules or {})
        C = len(self.names)
        col = {n: i for i, n in enumerate(self.names)}
        self.max_abs = None if max_abs is None else float(max_abs)
        self.lo = np.full(C, -np.inf)
        self.hi = np.full(C, np.inf)
        self.rate = np.full(C, np.inf)
        for n, p in rules.items():
            i = col[n]
            if p.min is not None:
                self.lo[i] = p.min
            if p.max is not None:
                self.hi[i] = p.max
            if p.max_rate is not None:
                self.rate[i] = p.max_rate
        self.has_range = bool(np.isfinite(self.lo).any() or np.isfinite(self.hi).any())
        self.rate_idx = np.flatnonzero(np.isfinite(self.rate))
        sp = [(col[n], p.spike, p.window) for n, p in rules.items() if p.spike is not None]
        self.spike_idx = np.array([i for i, _, _ in sp], np.intp)
        self.spike_k = np.array([k for _, k, _ in sp], float)
        # one window length for the ring buffer; each channel reads its own last `window` entries
        self.spike_w = np.array([w for _, _, w in sp], np.intp)
        self.W = int(self.spike_w.max()) if sp else 0
        #: True when the rules need the sequential state (rate or spike tests)
        self.sequential = bool(self.rate_idx.size or self.spike_idx.size)
        self.dt: float | None = None
        self.reset(1)

    # ------------------------------------------------------------------ state
    def reset(self, runs: int = 1, dt: float | None = None) -> None:
        """Forget every sample; ``dt`` is the expected sample period (s) for the spike test."""
        C = len(self.names)
        self.runs = int(runs)
        if dt is not None:
            self.dt = float(dt)
        self._ref = np.full((self.runs, C), np.nan)       # last valid value
        self._t_ref = math.nan                             # ... and its time
        self._prev = np.full((self.runs, C), np.nan)      # raw value of the previous arrival
        self._t_prev = math.nan                            # ... and its time (NaN: unusable)
        self._prev_ok = False                              # the previous arrival was accepted
        self._win = np.zeros((self.runs, self.spike_idx.size, max(self.W, 1)))
        self._n_win = 0                                    # increments stored (scalar: all at once)

    def state(self) -> dict[str, Any]:
        """Streaming state as plain data."""
        return {"ref": self._ref.copy(), "t_ref": self._t_ref, "prev": self._prev.copy(),
                "t_prev": self._t_prev, "prev_ok": self._prev_ok, "win": self._win.copy(),
                "n_win": self._n_win, "dt": self.dt, "runs": self.runs}

    def restore(self, s: Mapping[str, Any]) -> None:
        """Continue from :meth:`state`."""
        self.runs = int(s["runs"])
        self._ref, self._prev = np.array(s["ref"], float), np.array(s["prev"], float)
        self._t_ref, self._t_prev = float(s["t_ref"]), float(s["t_prev"])
        self._prev_ok, self._n_win = bool(s["prev_ok"]), int(s["n_win"])
        self._win = np.array(s["win"], float)
        self.dt = None if s["dt"] is None else float(s["dt"])

    # ------------------------------------------------------------------ the tests
    def _where(self, run: int, c: int, k: int, t: float) -> str:
        who = f"channel {self.names[c]!r}" + (f" (run {run})" if self.runs > 1 else "")
        return f"{who} at sample {k} (t = {t:.15g} s)"

    def check(self, k: int, t: float, x: np.ndarray) -> str | None:
        """The reason sample ``k`` at time ``t`` (values ``x`` (runs, C), finite) is implausible,
        or ``None``. Does not change the state."""
        if self.max_abs is not None:
            bad = np.abs(x) > self.max_abs
            if bad.any():
                r, c = np.argwhere(bad)[0]
                return (f"{self._where(r, c, k, t)}: {x[r, c]:g} exceeds the absurd-magnitude limit "
                        f"{self.max_abs:g} (max_abs)")
        if self.has_range:
            for bad, word, lim in ((x < self.lo, "below min", self.lo), (x > self.hi, "above max", self.hi)):
                if bad.any():
                    r, c = np.argwhere(bad)[0]
                    return f"{self._where(r, c, k, t)}: {x[r, c]:g} {word} {lim[c]:g} (plausibility)"
        if not self.sequential:
            return None
        # the preceding arrival is usable when it came one sample earlier without a gap
        prev_usable = math.isfinite(self._t_prev)
        if self.rate_idx.size and math.isfinite(self._t_ref):
            i = self.rate_idx
            lim = self.rate[i]
            el = t - self._t_ref
            d = np.abs(x[:, i] - self._ref[:, i])
            fast = d > lim * el
            if prev_usable and fast.any():
                with np.errstate(invalid="ignore"):
                    fast &= ~(np.abs(x[:, i] - self._prev[:, i]) <= lim * (t - self._t_prev))
            if fast.any():
                r, j = np.argwhere(fast)[0]
                c = int(i[j])
                return (f"{self._where(r, c, k, t)}: changes at {d[r, j] / el:.4g} units/s, above "
                        f"max_rate {lim[j]:g} (plausibility)")
        if self.spike_idx.size and prev_usable and self._n_win >= self.W and math.isfinite(self._t_ref):
            i = self.spike_idx
            win = self._win
            if self.W != int(self.spike_w.min()):  # channels with shorter windows: their last w entries
                meds, scales = self._stats_ragged()
            else:
                meds = np.median(win, axis=-1)
                scales = _robust_scale(win, meds)
            lim = self.spike_k * scales
            n = max(1, round((t - self._t_ref) / self.dt)) if self.dt else 1
            with np.errstate(invalid="ignore"):
                out_prev = np.abs(x[:, i] - self._prev[:, i] - meds) > lim
                out_ref = np.abs(x[:, i] - self._ref[:, i] - n * meds) > lim * math.sqrt(n)
            spike = out_prev & out_ref & (scales > 0)
            if spike.any():
                r, j = np.argwhere(spike)[0]
                c = int(i[j])
                dev = abs(x[r, c] - self._prev[r, c] - meds[r, j]) / scales[r, j]
                return (f"{self._where(r, c, k, t)}: spike, the increment {x[r, c] - self._prev[r, c]:.4g} "
                        f"lies {dev:.3g} robust deviations (1.4826 MAD) from the median of the last "
                        f"{int(self.spike_w[j])} (limit spike = {self.spike_k[j]:g}, plausibility)")
        return None

    def _stats_ragged(self) -> tuple[np.ndarray, np.ndarray]:
        """Median and robust scale per spike channel over its own window length."""
        meds = np.empty(self._win.shape[:2])
        scales = np.empty_like(meds)
        # the ring buffer holds the newest increment at position (n_win - 1) % W
        order = (np.arange(self.W) + self._n_win) % self.W  # oldest .. newest
        ordered = self._win[:, :, order]
        for j, w in enumerate(self.spike_w):
            seg = ordered[:, j, self.W - int(w):]
            m = np.median(seg, axis=-1)
            meds[:, j] = m
            scales[:, j] = _robust_scale(seg, m)
        return meds, scales

    # ------------------------------------------------------------------ recording
    def gap(self) -> None:
        """Samples are missing before the next one: its predecessor is not usable."""
        self._t_prev = math.nan
        self._prev_ok = False

    def observe(self, t: float, x: np.ndarray, accepted: bool) -> None:
        """Record the sample at time ``t`` (values ``x`` (runs, C), NaN allowed): always as the
        predecessor of the next one; when ``accepted`` also as the last valid sample (and, after
        an accepted predecessor, its increment enters the spike window)."""
        if accepted:
            if self.spike_idx.size and self._prev_ok and math.isfinite(self._t_prev):
                i = self.spike_idx
                self._win[:, :, self._n_win % self.W] = x[:, i] - self._ref[:, i]
                self._n_win += 1
            self._ref = np.array(x, float)
            self._t_ref = float(t)
        finite = np.all(np.isfinite(x))
        self._prev = np.array(x, float)
        # a non-finite sample is no usable predecessor (as if it had not arrived)
        self._t_prev = float(t) if finite else math.nan
        self._prev_ok = bool(accepted)
