"""Plausibility of the source samples of one signal, before resampling.

A monitor's range and spike rules judge *grid* samples; by then one implausible CAN frame has been
interpolated onto the two grid samples around it, each in range, and a single-frame spike looks
like a two-sample step. :func:`implausible_samples` applies the rules to the signal's own samples
(each frame of its message) so :func:`~fdikit.io.formats.grid.series_to_grid` flags exactly the
grid samples an implausible frame would touch.

A rule is a :class:`fdikit.monitor.Plausibility` or a mapping with the same keys (``min``,
``max``, ``spike``, ``window``; ``max_rate`` is the monitor's and is not used here) plus an optional
``resolution`` (the signal's quantisation step, in its unit). The tests, for samples ``x_i``:

* **range**: ``x_i < min`` or ``x_i > max``;
* **spike**: with ``d_i = x_i - x_{i-1}`` and, over the ``window`` increments before ``d_i``, the
  median ``m`` and the robust scale ``s``, sample ``i`` is a spike when it jumps away and back:
  ``|d_i - m| > spike * s`` and ``|d_{i+1} - m| > spike * s`` with opposite signs, while its
  neighbours agree, ``|x_{i+1} - x_{i-1} - 2 m| <= spike * s * sqrt(2)``. The scale is
  ``s = max(1.4826 MAD, resolution)``; when the MAD is 0 (a quantised signal whose increments are
  mostly zero) it is the larger of the resolution and 1.4826 times the median absolute deviation
  of the non-zero deviations from ``m``: it never collapses to 0 while the signal moves. A
  constant window with no resolution known gives ``s = 0``: nothing to judge against, no test.

Non-finite samples are left out (the loader flags them already); the first ``window + 1`` and the
last sample are not judged for spikes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...errors import DataError

#: 1.4826 * MAD estimates the standard deviation of Gaussian data.
_MAD_SCALE = 1.4826
#: Samples judged per block (bounds the memory of the sliding windows).
_BLOCK = 20_000
_KEYS = ("min", "max", "max_rate", "spike", "window", "resolution")


def rule_fields(rule: Any, where: str) -> dict[str, float | None]:
    """``min``, ``max``, ``spike``, ``window``, ``resolution`` of a rule (a Plausibility-like
    object or a mapping), checked."""
    if isinstance(rule, Mapping):
        bad = [k for k in rule if k not in _KEYS]
        if bad:
            raise DataError(f"{where}: unknown plausibility keys {bad}; allowed: {list(_KEYS)}")
        get = rule.get
    else:
        def get(k, default=None):
            return getattr(rule, k, default)
    out: dict[str, float | None] = {}
    for k in ("min", "max", "spike", "resolution"):
        x = get(k, None)
        if x is not None:
            try:
                x = float(x)
            except (TypeError, ValueError):
                raise DataError(f"{where}: plausibility {k} must be a number, got {x!r}") from None
            if not np.isfinite(x):
                raise DataError(f"{where}: plausibility {k} must be finite, got {x}")
        out[k] = x
    w = get("window", 50)
    if isinstance(w, bool) or not isinstance(w, int | np.integer) or w < 5:
        raise DataError(f"{where}: plausibility window must be an integer >= 5, got {w!r}")
    out["window"] = int(w)
    if out["spike"] is not None and not out["spike"] > 0:
        raise DataError(f"{where}: plausibility spike must be positive, got {out['spike']:g}")
    if out["resolution"] is not None and out["resolution"] < 0:
        raise DataError(f"{where}: plausibility resolution must be >= 0, got {out['resolution']:g}")
    return out


def _spike_scale(win: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """Median and robust scale of each row of ``win`` (increments), floored (module docstring)."""
    m = np.median(win, axis=1)
    dev = np.abs(win - m[:, None])
    s = _MAD_SCALE * np.median(dev, axis=1)
    flat = s == 0
    if flat.any():
        d = np.where(dev[flat] > 0, dev[flat], np.nan)
        nz = np.zeros(d.shape[0])
        has = ~np.isnan(d).all(axis=1)
        if has.any():
            nz[has] = _MAD_SCALE * np.nanmedian(d[has], axis=1)
        s[flat] = nz
    return m, np.maximum(s, resolution)


def implausible_samples(t: np.ndarray, v: np.ndarray, rule: Any, resolution: float = 0.0,
                        where: str = "signal") -> tuple[np.ndarray, list[str]]:
    """Samples of one signal that its plausibility rule refuses (see the module docstring).

    Parameters
    ----------
    t, v : ndarray, shape (N,)
        Sample times (s) and values (in the unit of the rule).
    rule : Plausibility or mapping
    resolution : float
        Quantisation step of the signal (e.g. the DBC scale), the floor of the spike scale; a
        ``resolution`` in the rule takes precedence.
    where : str
        Name of the signal in the reasons.

    Returns
    -------
    bad : ndarray of bool, shape (N,)
    why : list of str
        One reason per refused sample, in time order.

    Examples
    --------
    >>> v = np.r_[np.zeros(30), 0.1, np.zeros(29), 2.0, np.zeros(9)]   # mostly zero increments
    >>> bad, why = implausible_samples(np.arange(70) * 0.01, v, {"spike": 8, "window": 20},
    ...                                resolution=0.1)
    >>> np.flatnonzero(bad).tolist(), why[0][:40]
    ([60], 'signal at 0.6 s: 2 is a single-sample sp')
    """
    r = rule_fields(rule, where)
    res = float(r["resolution"]) if r["resolution"] is not None else float(resolution)
    t = np.asarray(t, float)
    v = np.asarray(v, float)
    bad = np.zeros(v.size, bool)
    why: dict[int, str] = {}
    fin = np.isfinite(v)
    with np.errstate(invalid="ignore"):
        for k, word in (("min", "below"), ("max", "above")):
            lim = r[k]
            if lim is None:
                continue
            out = fin & ((v < lim) if k == "min" else (v > lim))
            for i in np.flatnonzero(out):
                why[int(i)] = f"{where} at {t[i]:.6g} s: {v[i]:g} {word} {k} {lim:g} (plausibility)"
            bad |= out
    if r["spike"] is not None:
        idx = np.flatnonzero(fin)
        x = v[idx]
        W, k = int(r["window"]), float(r["spike"])
        d = np.diff(x)
        # sample j of x (1 <= j <= n-2) uses d[j-1] (in), d[j] (out) and the W increments before d[j-1]
        first = W + 1
        for a in range(first, x.size - 1, _BLOCK):
            b = min(a + _BLOCK, x.size - 1)
            j = np.arange(a, b)
            win = np.lib.stride_tricks.sliding_window_view(d, W)[j - 1 - W]
            m, s = _spike_scale(win, res)
            lim = k * s
            d_in, d_out = d[j - 1] - m, d[j] - m
            spike = ((s > 0) & (np.abs(d_in) > lim) & (np.abs(d_out) > lim)
                     & (np.sign(d_in) != np.sign(d_out))
                     & (np.abs(x[j + 1] - x[j - 1] - 2 * m) <= lim * np.sqrt(2.0)))
            for jj in np.flatnonzero(spike):
                i = int(idx[j[jj]])
                if i not in why:
                    why[i] = (f"{where} at {t[i]:.6g} s: {v[i]:g} is a single-sample spike, the increment "
                              f"{d[j[jj] - 1]:.4g} lies {abs(d_in[jj]) / s[jj]:.3g} robust deviations "
                              f"from the median of the last {W} (limit spike = {k:g}, plausibility on "
                              "the source samples)")
                bad[i] = True
    return bad, [why[i] for i in sorted(why)]
