"""Online estimate of the measurement noise and the per-sample switch between the two branches of
a noise-aware SMO reconstructor (compiled; batch and streaming run the same kernel).

The noise level of each output is read from its fourth difference
``d4[k] = y[k] - 4 y[k-1] + 6 y[k-2] - 4 y[k-3] + y[k-4]``: for white noise of standard deviation
``s`` it is Gaussian with variance ``70 s^2``, while a smooth signal sampled every ``h`` s leaves
only ``h^4 y''''`` (1e-20 of the signal at ``h = 1e-5``). The estimate averages ``log |d4|``
(an exponentially weighted mean over ``window`` samples): an isolated jump (a fault step) moves a
log-mean by ``log(jump / noise) / window``, not by ``jump^2 / window`` as a variance would, so
a fault is not mistaken for noise. ``E log|Z| = -(gamma + ln 2) / 2`` for standard normal ``Z``
turns the log-mean into a standard deviation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from ...errors import DataError

__all__ = ["NOISE_BAND", "NOISE_WARMUP", "NOISE_WINDOW", "estimate_noise_std"]

#: Samples of the exponentially weighted log-mean of the noise estimate (its memory).
NOISE_WINDOW = 256

#: Fourth differences averaged before the estimate is trusted; until then the noise branch is used.
NOISE_WARMUP = 16

#: Half-width (a factor) of the blend around the switch level: the clean branch alone below
#: ``switch / NOISE_BAND``, the noise branch alone above ``switch * NOISE_BAND``, log-linear between.
NOISE_BAND = 2.0

#: ``E log|Z|`` for a standard normal ``Z``: ``-(Euler's gamma + ln 2) / 2``.
LOG_ABS_NORMAL_MEAN = -0.6351814227307391

#: Variance of the fourth difference of unit white noise: ``1 + 16 + 36 + 16 + 1``.
D4_VARIANCE = 70.0


def _track_py(y, ybuf, count, lmean, window):
    """Feed one sample ``y`` (p) to the estimator; ``ybuf`` (4, p) holds ``y[k-1] .. y[k-4]``,
    ``count[0]`` the samples seen, ``lmean`` (p) the log-mean of ``|d4|``. Returns the number of
    differences averaged so far."""
    p = y.shape[0]
    c = count[0]
    if c >= 4.0:
        nd = c - 3.0
        a = 1.0 / (nd if nd < window else window)
        for j in range(p):
            d = y[j] - 4.0 * ybuf[0, j] + 6.0 * ybuf[1, j] - 4.0 * ybuf[2, j] + ybuf[3, j]
            lmean[j] += a * (np.log(abs(d) + 1e-300) - lmean[j])
    for j in range(p):
        ybuf[3, j] = ybuf[2, j]
        ybuf[2, j] = ybuf[1, j]
        ybuf[1, j] = ybuf[0, j]
        ybuf[0, j] = y[j]
    count[0] = c + 1.0
    return c - 3.0 if c >= 4.0 else 0.0


_track = njit(cache=True)(_track_py)


def _std_of(lmean, j):
    return np.exp(lmean[j] - LOG_ABS_NORMAL_MEAN) / np.sqrt(D4_VARIANCE)


_std = njit(cache=True)(_std_of)


def _estimate_py(Y, window, ybuf, count, lmean, out):
    """Noise standard deviation estimate of every output after every sample (NaN before a first
    difference)."""
    runs, T, p = Y.shape
    for run in range(runs):
        for k in range(T):
            nd = _track(Y[run, k], ybuf[run], count[run], lmean[run], window)
            for j in range(p):
                out[run, k, j] = _std(lmean[run], j) if nd > 0.0 else np.nan


_estimate = njit(cache=True)(_estimate_py)


def _blend_py(Y, out_n, out_c, sig, switch, band, window, warmup, ybuf, count, lmean, out, ratio):
    """Per sample: the noise ratio ``max_j s_j / sig_j`` and the blend of the noise branch
    ``out_n`` and the clean branch ``out_c`` ((runs, T, q + 3): ``q`` estimates, 3 status codes).

    Weight of the noise branch ``w = 0`` at ratio ``<= switch / band``, ``1`` at ``>= switch *
    band`` (and while fewer than ``warmup`` differences are averaged), log-linear between; the
    status is that of the branch used (the worse of the two inside the band).
    """
    runs, T, p = Y.shape
    m = out_n.shape[2]
    q = m - 3
    lo = switch / band
    span = np.log(band * band)
    for run in range(runs):
        for k in range(T):
            nd = _track(Y[run, k], ybuf[run], count[run], lmean[run], window)
            r = np.inf
            if nd >= warmup:
                r = 0.0
                for j in range(p):
                    if sig[j] > 0.0:
                        v = _std(lmean[run], j) / sig[j]
                        if v > r:
                            r = v
            ratio[run, k] = r
            if r <= lo:
                for i in range(m):
                    out[run, k, i] = out_c[run, k, i]
            elif r >= switch * band:
                for i in range(m):
                    out[run, k, i] = out_n[run, k, i]
            else:
                w = np.log(r / lo) / span
                for i in range(q):
                    out[run, k, i] = (1.0 - w) * out_c[run, k, i] + w * out_n[run, k, i]
                for i in range(q, m):
                    out[run, k, i] = max(out_c[run, k, i], out_n[run, k, i])


_blend = njit(cache=True)(_blend_py)


def estimate_noise_std(Y: Any, window: int = NOISE_WINDOW) -> np.ndarray:
    """Running estimate of the white-noise standard deviation on each measured output.

    The estimate a noise-aware :class:`~fdikit.residuals.smo.SlidingModeReconstructor` uses to
    choose between its branches: the exponentially weighted mean of ``log |d4|`` over
    ``window`` samples (a growing mean over the first ones), ``d4`` the fourth difference of the
    samples, turned into a standard deviation (see the module docstring). Causal: the value at
    sample ``k`` uses samples up to ``k``.

    Parameters
    ----------
    Y : array_like (runs, T, p) or (T, p)
        Measurements, finite.
    window : int
        Memory of the mean (samples, >= 1).

    Returns
    -------
    ndarray, the shape of ``Y``
        Estimated standard deviation (output units); NaN for the first four samples.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals.smo import estimate_noise_std
    >>> t = np.arange(20000) * 1e-4
    >>> y = np.sin(t)[:, None] + 1e-3 * np.random.default_rng(0).standard_normal((t.size, 1))
    >>> bool(0.8e-3 < estimate_noise_std(y)[-1, 0] < 1.25e-3)
    True
    """
    Y = np.asarray(Y, dtype=float)
    squeeze = Y.ndim == 2
    if squeeze:
        Y = Y[None]
    if Y.ndim != 3:
        raise DataError(f"Y must have shape (runs, T, p) or (T, p), got {Y.shape}")
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise DataError(f"window must be an integer >= 1 (samples), got {window!r}")
    bad = np.argwhere(~np.isfinite(Y))
    if bad.size:
        r, k, j = bad[0]
        raise DataError(f"Y is not finite at run {r}, sample {k}, channel {j}: {Y[r, k, j]}")
    runs, _T, p = Y.shape
    out = np.empty_like(Y)
    _estimate(np.ascontiguousarray(Y), float(window), np.zeros((runs, 4, p)), np.zeros((runs, 1)),
              np.zeros((runs, p)), out)
    return out[0] if squeeze else out
