"""Compiled exact uniform-mean Gaussian log densities: one component at a scalar
(:func:`umg_component_logpdf`) and the log likelihoods of every hypothesis over many streams,
with the components that hypotheses share evaluated once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["umg_component_logpdf"]


_INV_SQRT2 = 1.0 / math.sqrt(2.0)


@njit(cache=True)
def _log_ndtr_nb(x):  # pragma: no cover - compiled
    """log Phi(x): erfc down to x = -37 (Phi ~ 1e-300), the asymptotic series below."""
    if x > 0.0:
        return math.log1p(-0.5 * math.erfc(x / math.sqrt(2.0)))
    if x > -37.0:
        return math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
    z = 1.0 / (x * x)
    # Phi(x) = phi(x)/|x| (1 - 1/x^2 + 3/x^4 - 15/x^6 + ...): error < 11! ! / 37^14 ~ 1e-18 here
    s = 1.0 + z * (-1.0 + z * (3.0 + z * (-15.0 + z * (105.0 + z * (-945.0 + z * 10395.0)))))
    return -0.5 * x * x - math.log(-x) - 0.5 * math.log(2.0 * math.pi) + math.log(s)


@njit(cache=True)
def umg_component_logpdf(x, low, high, std, point, logw):  # pragma: no cover - compiled
    """Log density of one uniform-mean Gaussian component at a scalar ``x`` (compiled).

    ``point``: the mean range is a point (plain Gaussian); ``logw = log(high - low)``.
    """
    if point:
        z = (x - low) / std
        return -0.5 * z * z - math.log(std) - 0.5 * math.log(2.0 * math.pi)
    u = (x - low) / std
    v = (x - high) / std
    if v > 0.0:  # upper tail: Phi(u) - Phi(v) = Phi(-v) - Phi(-u)
        hi, lo = -v, -u
    else:
        hi, lo = u, v
    if hi > -30.0:  # Phi(hi) - Phi(lo) directly (lo <= min(hi, 0): no cancellation beyond the range's
        # own, as in the log form), two erfc and one log instead of five transcendentals
        p = 0.5 * (math.erfc(-hi * _INV_SQRT2) - math.erfc(-lo * _INV_SQRT2))
        if p > 0.0:
            return math.log(p) - logw
    lhi = _log_ndtr_nb(hi)
    d = _log_ndtr_nb(lo) - lhi
    if d > 0.0:
        d = 0.0
    return lhi + math.log1p(-math.exp(d)) - logw


@njit(cache=True)
def _loglik_umg_stream(r, x, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """Log densities of stream ``r``: x[r] (T, C) -> out[r] (T, H)."""
    T, C = x.shape[1], x.shape[2]
    H = low.shape[0]
    for k in range(T):
        for j in range(H):
            acc = 0.0
            for c in range(C):
                acc += umg_component_logpdf(x[r, k, c], low[j, c], high[j, c], std[j, c], point[j, c],
                                            logw[j, c])
            out[r, k, j] = acc


@njit(cache=True)
def _loglik_umg(x, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """Log densities of uniform-mean Gaussians: x (R, T, C) -> out (R, T, H), streams in turn."""
    for r in range(x.shape[0]):
        _loglik_umg_stream(r, x, low, high, std, point, logw, out)


@njit(cache=True, parallel=True)
def _loglik_umg_parallel(x, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """As :func:`_loglik_umg`, streams in parallel threads."""
    for r in prange(x.shape[0]):
        _loglik_umg_stream(r, x, low, high, std, point, logw, out)


@njit(cache=True)
def _loglik_umg_shared_stream(r, x, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, out):  # pragma: no cover
    """As :func:`_loglik_umg_stream`, each distinct component of a channel evaluated once: the
    components ``uoff[c]..uoff[c+1]-1`` of channel ``c`` are distinct ``(low, high, std)``, and
    hypothesis ``j`` reads component ``jmap[j, c]``; its sum runs over the channels in order from
    0.0, as in :func:`_loglik_umg_stream` (bitwise the same)."""
    T, C = x.shape[1], x.shape[2]
    H = jmap.shape[0]
    vals = np.empty(ulow.shape[0])
    for k in range(T):
        for c in range(C):
            xc = x[r, k, c]
            for e in range(uoff[c], uoff[c + 1]):
                vals[e] = umg_component_logpdf(xc, ulow[e], uhigh[e], ustd[e], upoint[e], ulogw[e])
        for j in range(H):
            acc = 0.0
            for c in range(C):
                acc += vals[jmap[j, c]]
            out[r, k, j] = acc


@njit(cache=True)
def _loglik_umg_shared(x, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, out):  # pragma: no cover
    """:func:`_loglik_umg` with the components shared between hypotheses evaluated once."""
    for r in range(x.shape[0]):
        _loglik_umg_shared_stream(r, x, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, out)


@njit(cache=True, parallel=True)
def _loglik_umg_shared_parallel(x, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, out):  # pragma: no cover
    """As :func:`_loglik_umg_shared`, streams in parallel threads."""
    for r in prange(x.shape[0]):
        _loglik_umg_shared_stream(r, x, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, out)


def _shared_components(low: np.ndarray, high: np.ndarray, std: np.ndarray, point: np.ndarray,
                       logw: np.ndarray) -> tuple[np.ndarray, ...]:
    """The distinct components of every channel (equal ``low``, ``high``, ``std`` and ``point``
    give bitwise equal log densities): ``(low, high, std, point, logw)`` of them, flat, channel by
    channel, the offset of each channel's and ``jmap`` (H, C), the one hypothesis j reads."""
    H, C = low.shape
    keys: list = []
    uoff = np.zeros(C + 1, np.int64)
    jmap = np.zeros((H, C), np.int64)
    for c in range(C):
        seen: dict = {}
        for j in range(H):
            key = (low[j, c].tobytes(), high[j, c].tobytes(), std[j, c].tobytes(), bool(point[j, c]),
                   logw[j, c].tobytes())
            if key not in seen:
                seen[key] = len(keys)
                keys.append((j, c))
            jmap[j, c] = seen[key]
        uoff[c + 1] = len(keys)
    jj = np.array([k[0] for k in keys], np.int64)
    cc = np.array([k[1] for k in keys], np.int64)
    flat = [np.ascontiguousarray(a[jj, cc], dtype=float) for a in (low, high, std)]
    return (*flat, np.ascontiguousarray(point[jj, cc], dtype=np.bool_),
            np.ascontiguousarray(logw[jj, cc], dtype=float), uoff, jmap)
