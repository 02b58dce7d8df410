"""Multiple-hypothesis Shiryayev sequential probability test (MHSSPT), in the log domain.

Ng, Chen & Speyer, Section IV-E, after Malladi & Speyer (IEEE TAC 44(8), 1999); the recursion
and densities are written out in shared/notes/residual-processing.md. Hypothesis 0 is "no
fault"; hypotheses 1..M are faults. At every sample a change from H0 occurs with probability
``p``, to H_j with probability ``pi_j``; an optional return probability ``q`` lets a fault
hypothesis fall back to H0 (intermittent faults). With the posterior ``F`` of the previous
sample::

    phi_0 = F_0 (1 - p) + q sum_{j>=1} F_j
    phi_j = F_j (1 - q) + F_0 p pi_j
    F_j  <- phi_j f_j(x_k) / sum_i phi_i f_i(x_k)

computed with log-sum-exp so that likelihoods of 1e-300 neither underflow nor give 0/0. Terms
more than :data:`NEGLIGIBLE_NATS` below the largest are left out of the sums (they are below its
rounding). The densities are evaluated exactly or, with ``tabulate``, by interpolation in tables
(:func:`tabulate_umg`); many independent streams (runs) are advanced in one compiled call, in
parallel threads when the call has enough work.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, prange
from scipy.special import log_ndtr

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = [
    "MHSSPT",
    "NEGLIGIBLE_NATS",
    "LineMeanGaussian",
    "MHSSPTCalibration",
    "UniformMeanGaussian",
    "WhitenedMHSSPT",
    "calibrate_densities",
    "calibrate_segments",
    "design_mhsspt",
    "detection_time",
    "final_diagnosis",
    "mhsspt_update",
    "tabulate_umg",
    "tabulate_umg_cubic",
    "umg_component_logpdf",
]

_LOG_SQRT_2PI = 0.5 * np.log(2 * np.pi)


def _log_diff_ndtr(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """log(Phi(u) - Phi(v)) for u > v, accurate in both tails."""
    # upper tail (v > 0): Phi(u) - Phi(v) = Phi(-v) - Phi(-u)
    upper = v > 0
    hi = np.where(upper, -v, u)
    lo = np.where(upper, -u, v)
    lhi, llo = log_ndtr(hi), log_ndtr(lo)
    return lhi + np.log1p(-np.exp(np.minimum(llo - lhi, 0.0)))


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


@njit(cache=True)
def umg_table_add(x, c, tab, g0, inv_h, nG, toff, low, high, std, point, logw, ll, h0,
                  h1):  # pragma: no cover - compiled
    """Add the log density of component ``c`` at ``x`` of hypotheses ``h0..h1-1`` to ``ll``: linear
    interpolation in the table of :func:`tabulate_umg` inside its grid, the exact formula outside."""
    t = (x - g0[c]) * inv_h[c]
    if t >= 0.0 and t < nG[c] - 1:
        i0 = int(t)
        fr = t - i0
        base = toff[c] + i0
        for j in range(h0, h1):
            ll[j] += (1.0 - fr) * tab[base, j] + fr * tab[base + 1, j]
    else:
        for j in range(h0, h1):
            ll[j] += umg_component_logpdf(x, low[j, c], high[j, c], std[j, c], point[j, c], logw[j, c])


@njit(cache=True, parallel=True)
def _loglik_table(x, tab, g0, inv_h, nG, toff, low, high, std, point, logw, out):  # pragma: no cover
    """Tabulated log densities: x (R, T, C) -> out (R, T, H); streams in parallel (a bulk call)."""
    R, T, C = x.shape
    H = low.shape[0]
    for r in prange(R):
        for k in range(T):
            o = out[r, k]
            for j in range(H):
                o[j] = 0.0
            for c in range(C):
                umg_table_add(x[r, k, c], c, tab, g0, inv_h, nG, toff, low, high, std, point, logw, o, 0, H)


@njit(cache=True)
def _emit(o, P, lf, gmat, probs):  # pragma: no cover - compiled
    """One sample's outputs of a fused table kernel: the normalised posteriors the update just
    formed, then the group sums (``probs``: no second exp per hypothesis), or the log posteriors."""
    H = lf.shape[0]
    if probs:
        for j in range(H):
            o[j] = P[j]
        for g in range(gmat.shape[0]):
            acc = 0.0
            for e in range(gmat.shape[1]):
                if gmat[g, e] >= 0:
                    acc += o[gmat[g, e]]
            o[H + g] = acc
    else:
        for j in range(H):
            o[j] = lf[j]


@njit(cache=True)
def _mhsspt_table_stream(r, x, tab, g0, inv_h, nG, toff, dens, point, logF, log1mp, logp_pi, logq, log1mq,
                         gmat, probs, out):  # pragma: no cover - compiled
    """Stream ``r``: tabulated log likelihoods and the recursion for all its samples. ``out``
    receives the log posteriors or, with ``probs``, the probabilities (the normalised
    posteriors :func:`mhsspt_update` forms, as the fused car monitor uses them) then the group
    sums -- :meth:`MHSSPT._outputs` of the log posteriors to rounding."""
    T, C = x.shape[1], x.shape[2]
    H = logF.shape[1]
    ll = np.empty(H)
    phi = np.empty(H)
    P = np.empty(H)
    lf = logF[r]
    low, high, std, logw = dens[0], dens[1], dens[2], dens[3]
    for k in range(T):
        for j in range(H):
            ll[j] = 0.0
        for c in range(C):
            xc = x[r, k, c]
            # linear interpolation in the table (umg_table_add, written out: no call per component)
            t = (xc - g0[c]) * inv_h[c]
            if t >= 0.0 and t < nG[c] - 1:
                it = int(t)
                fr = t - it
                base = toff[c] + it
                for j in range(H):
                    ll[j] += (1.0 - fr) * tab[base, j] + fr * tab[base + 1, j]
            else:
                umg_table_add(xc, c, tab, g0, inv_h, nG, toff, low, high, std, point, logw, ll, 0, H)
        mhsspt_update(lf, ll, phi, P, 0, H, log1mp, logp_pi, logq, log1mq)
        _emit(out[r, k], P, lf, gmat, probs)


@njit(cache=True)
def _mhsspt_table_run(x, tab, g0, inv_h, nG, toff, dens, point, logF, log1mp, logp_pi, logq, log1mq,
                      gmat, probs, out):  # pragma: no cover - compiled
    """Tabulated MHSSPT over x (R, T, C), streams one after the other."""
    for r in range(x.shape[0]):
        _mhsspt_table_stream(r, x, tab, g0, inv_h, nG, toff, dens, point, logF, log1mp, logp_pi, logq, log1mq,
                             gmat, probs, out)


@njit(cache=True, parallel=True)
def _mhsspt_table_run_parallel(x, tab, g0, inv_h, nG, toff, dens, point, logF, log1mp, logp_pi, logq, log1mq,
                               gmat, probs, out):  # pragma: no cover - compiled
    """Tabulated MHSSPT over x (R, T, C), streams in parallel threads (the arithmetic of the serial one)."""
    for r in prange(x.shape[0]):
        _mhsspt_table_stream(r, x, tab, g0, inv_h, nG, toff, dens, point, logF, log1mp, logp_pi, logq, log1mq,
                             gmat, probs, out)


def _component_logpdf(x: np.ndarray, low: float, high: float, std: float, point: bool) -> np.ndarray:
    """Exact log density of one component at the points ``x`` (the table's reference)."""
    x = np.asarray(x, float)
    if point:
        return -0.5 * ((x - low) / std) ** 2 - math.log(std) - _LOG_SQRT_2PI
    return UniformMeanGaussian([low], [high], [std]).logpdf(x[:, None])


def tabulate_umg(low: np.ndarray, high: np.ndarray, std: np.ndarray, point: np.ndarray,
                 resolution: float = 1.0 / 32.0, max_points: int = 400_000) -> dict[str, np.ndarray]:
    """Tables of uniform-mean Gaussian component log densities for linear interpolation.

    Per component ``c`` a uniform grid over ``[min_j low - 12 max_j std, max_j high + 12 max_j std]``
    with spacing ``resolution * min_j std`` (at most ``max_points`` points), holding the exact
    log density of every hypothesis ``j``. Linear interpolation of a function with second
    derivative ``<= 1 / std^2`` errs by at most ``h^2 / (8 std^2) = resolution^2 / 8`` nats
    (1.2e-4 at 1/32); the error measured at the grid midpoints is returned as ``error``
    (where the density exceeds exp(-700)).

    Parameters
    ----------
    low, high, std : array (H, C)
        Mean ranges and standard deviations (units of the features).
    point : bool array (H, C)
        Components whose mean range is a point (plain Gaussian).
    resolution : float
        Grid spacing as a fraction of the smallest std of the component.

    Returns
    -------
    dict
        ``tab`` (sum of grid sizes, H), ``g0``, ``inv_h`` (C,) grid start and inverse spacing,
        ``nG``, ``toff`` (C,) grid sizes and row offsets in ``tab``, ``error`` (nats).

    Examples
    --------
    >>> t = tabulate_umg(np.array([[0.0], [1.0]]), np.array([[0.0], [2.0]]), np.ones((2, 1)),
    ...                  np.array([[True], [False]]))
    >>> t["tab"].shape[1], bool(t["error"] < 2e-4)
    (2, True)
    """
    low, high, std = (np.asarray(a, float) for a in (low, high, std))
    point = np.asarray(point, bool)
    H, C = low.shape
    if not resolution > 0:
        raise DataError(f"table resolution must be positive, got {resolution}")
    g0, inv_h = np.zeros(C), np.zeros(C)
    nG, toff = np.zeros(C, np.int64), np.zeros(C, np.int64)
    tabs, err, total = [], 0.0, 0
    for c in range(C):
        s_min, s_max = std[:, c].min(), std[:, c].max()
        lo = low[:, c].min() - 12 * s_max
        hi = high[:, c].max() + 12 * s_max
        n = int(min(np.ceil((hi - lo) / (resolution * s_min)) + 1, max_points))
        step = (hi - lo) / (n - 1)
        grid = lo + step * np.arange(n)
        mid = grid[:-1] + 0.5 * step
        T = np.zeros((n, H))
        for j in range(H):
            args = (low[j, c], high[j, c], std[j, c], bool(point[j, c]))
            T[:, j] = _component_logpdf(grid, *args)
            e = np.abs(0.5 * (T[:-1, j] + T[1:, j]) - _component_logpdf(mid, *args))
            # the error that matters: where the density is not negligible
            err = max(err, float(e[T[:-1, j] > -700].max(initial=0.0)))
        g0[c], inv_h[c], nG[c], toff[c] = lo, 1.0 / step, n, total
        total += n
        tabs.append(T)
    return {"tab": np.ascontiguousarray(np.vstack(tabs)), "g0": g0, "inv_h": inv_h, "nG": nG, "toff": toff,
            "error": err}


@njit(cache=True)
def _umg_exact_points(xs, low, high, std, point, logw, out):  # pragma: no cover - compiled
    """The exact component log density (:func:`umg_component_logpdf`) at the points ``xs``."""
    for i in range(xs.size):
        out[i] = umg_component_logpdf(xs[i], low, high, std, point, logw)


def _umg_value_slope(xs: np.ndarray, low: float, high: float, std: float, point: bool,
                     logw: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact log density and its derivative in x at the points ``xs`` (one component).

    d/dx log(Phi(u) - Phi(v)) = (phi(u) - phi(v)) / (std (Phi(u) - Phi(v))), u = (x - low)/std,
    v = (x - high)/std, with each ratio formed in the log domain (no overflow in either tail)."""
    f = np.empty(xs.size)
    _umg_exact_points(xs, low, high, std, point, logw, f)
    if point:
        return f, -(xs - low) / (std * std)
    lp = f + logw
    u, v = (xs - low) / std, (xs - high) / std
    d = (np.exp(-0.5 * u * u - _LOG_SQRT_2PI - lp) - np.exp(-0.5 * v * v - _LOG_SQRT_2PI - lp)) / std
    return f, d


def tabulate_umg_cubic(low: np.ndarray, high: np.ndarray, std: np.ndarray, point: np.ndarray,
                       logw: np.ndarray, uoff: np.ndarray, resolution: float = 1.0 / 16.0,
                       max_points: int = 200_000) -> dict[str, np.ndarray]:
    """Cubic Hermite tables of uniform-mean Gaussian component log densities.

    The components are given flat, channel by channel (``uoff[c]..uoff[c+1]-1`` are channel
    ``c``'s, e.g. the distinct components of an :class:`MHSSPT`'s densities). Per channel a
    uniform grid over ``[min low - 12 max std, max high + 12 max std]`` with spacing
    ``resolution * min std`` holds, per interval and component, the four coefficients of the
    cubic in the position ``s`` in [0, 1) within the interval that matches the exact log density
    and its exact slope at both ends (Hermite interpolation). Its error is at most
    ``h^4 max|f''''| / 384``, a few 1e-8 nats at 1/16 for these densities (whose fourth derivative
    is of the order of ``1 / std^4``) against 1.2e-4 for the linear table of :func:`tabulate_umg`
    at 1/32. The error measured against the exact density at four points inside every interval
    (where the density exceeds exp(-700)) is returned as ``error``.

    Returns
    -------
    dict
        ``coef`` (rows, 4): row ``coff[c] + i * n_c + (e - uoff[c])`` holds component ``e``'s
        cubic on interval ``i`` of channel ``c`` (``n_c`` components); ``g0``, ``inv_h``, ``nG``
        (grid start, inverse spacing, grid points) and ``coff`` per channel; ``error`` (nats).

    Examples
    --------
    >>> low, high, std = np.array([0.0, 1.0]), np.array([0.0, 3.0]), np.array([1.0, 1.0])
    >>> point = np.array([True, False]); logw = np.log(np.where(point, 1.0, high - low))
    >>> t = tabulate_umg_cubic(low, high, std, point, logw, np.array([0, 2]))
    >>> t["coef"].shape[1], bool(t["error"] < 1e-7)
    (4, True)
    """
    low, high, std, logw = (np.asarray(a, float) for a in (low, high, std, logw))
    point = np.asarray(point, bool)
    uoff = np.asarray(uoff, np.int64)
    if not resolution > 0:
        raise DataError(f"table resolution must be positive, got {resolution}")
    C = uoff.size - 1
    g0, inv_h = np.zeros(C), np.zeros(C)
    nG, coff = np.zeros(C, np.int64), np.zeros(C, np.int64)
    blocks, err, total = [], 0.0, 0
    probe = (np.arange(4) + 0.5) / 4.0
    for c in range(C):
        e0, e1 = int(uoff[c]), int(uoff[c + 1])
        s_min, s_max = std[e0:e1].min(), std[e0:e1].max()
        lo = low[e0:e1].min() - 12 * s_max
        hi = high[e0:e1].max() + 12 * s_max
        n = int(min(np.ceil((hi - lo) / (resolution * s_min)) + 1, max_points))
        step = (hi - lo) / (n - 1)
        grid = lo + step * np.arange(n)
        co = np.empty((n - 1, e1 - e0, 4))
        xs = (grid[:-1, None] + step * probe[None, :]).ravel()
        sp = np.tile(probe, n - 1)
        for m, e in enumerate(range(e0, e1)):
            args = (low[e], high[e], std[e], bool(point[e]), logw[e])
            f, d = _umg_value_slope(grid, *args)
            f0, f1, d0, d1 = f[:-1], f[1:], step * d[:-1], step * d[1:]
            co[:, m, 0] = f0
            co[:, m, 1] = d0
            co[:, m, 2] = 3.0 * (f1 - f0) - 2.0 * d0 - d1
            co[:, m, 3] = 2.0 * (f0 - f1) + d0 + d1
            ref = np.empty(xs.size)
            _umg_exact_points(xs, *args, ref)
            q = np.repeat(co[:, m, :], probe.size, axis=0)
            approx = q[:, 0] + sp * (q[:, 1] + sp * (q[:, 2] + sp * q[:, 3]))
            live = ref > -700
            err = max(err, float(np.abs(approx - ref)[live].max(initial=0.0)))
        g0[c], inv_h[c], nG[c], coff[c] = lo, 1.0 / step, n, total
        total += (n - 1) * (e1 - e0)
        blocks.append(co.reshape(-1, 4))
    return {"coef": np.ascontiguousarray(np.vstack(blocks)), "g0": g0, "inv_h": inv_h, "nG": nG,
            "coff": coff, "error": err}


@njit(cache=True)
def _exact_values(xc, e0, e1, ulow, uhigh, ustd, upoint, ulogw, vals):  # pragma: no cover - compiled
    """The exact log densities of components ``e0..e1-1`` at ``xc`` into ``vals`` (outside a table)."""
    for e in range(e0, e1):
        vals[e] = umg_component_logpdf(xc, ulow[e], uhigh[e], ustd[e], upoint[e], ulogw[e])


@njit(cache=True)
def _mhsspt_cubic_stream(r, x, coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap,
                         logF, log1mp, logp_pi, logq, log1mq, gmat, mode, out):  # pragma: no cover
    """Stream ``r``: cubic-table log likelihoods (:func:`tabulate_umg_cubic` inside its grid, the
    exact formula outside) and, unless ``mode`` is 0, the recursion, for all its samples.
    ``out[r, k]`` receives the log likelihoods (``mode`` 0), the log posteriors (1) or the
    probabilities then the group sums (2, as :func:`_mhsspt_table_stream` with ``probs``). The
    look-up is written out here: a compiled call per channel would cost five times the cubics."""
    T, C = x.shape[1], x.shape[2]
    H = jmap.shape[0]
    vals = np.empty(ulow.shape[0])
    ll = np.empty(H)
    phi = np.empty(H)
    P = np.empty(H)
    lf = logF[r]
    for k in range(T):
        for c in range(C):
            xc = x[r, k, c]
            e0 = uoff[c]
            e1 = uoff[c + 1]
            t = (xc - g0[c]) * inv_h[c]
            if t >= 0.0 and t < nG[c] - 1:
                i = int(t)
                s = t - i
                b = 4 * (coff[c] + i * (e1 - e0) - e0)  # the interval's 4 n_c coefficients, contiguous
                for e in range(e0, e1):
                    q = b + 4 * e
                    vals[e] = coef[q] + s * (coef[q + 1] + s * (coef[q + 2] + s * coef[q + 3]))
            else:
                _exact_values(xc, e0, e1, ulow, uhigh, ustd, upoint, ulogw, vals)
        o = out[r, k]
        if mode == 0:
            for j in range(H):
                acc = 0.0
                for c in range(C):
                    acc += vals[jmap[j, c]]
                o[j] = acc
            continue
        for j in range(H):
            acc = 0.0
            for c in range(C):
                acc += vals[jmap[j, c]]
            ll[j] = acc
        mhsspt_update(lf, ll, phi, P, 0, H, log1mp, logp_pi, logq, log1mq)
        _emit(o, P, lf, gmat, mode == 2)


@njit(cache=True)
def _mhsspt_cubic_run(x, coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap, logF,
                      log1mp, logp_pi, logq, log1mq, gmat, mode, out):  # pragma: no cover - compiled
    """Cubic-table MHSSPT over x (R, T, C), streams one after the other (``mode``: see
    :func:`_mhsspt_cubic_stream`)."""
    for r in range(x.shape[0]):
        _mhsspt_cubic_stream(r, x, coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap,
                             logF, log1mp, logp_pi, logq, log1mq, gmat, mode, out)


@njit(cache=True, parallel=True)
def _mhsspt_cubic_run_parallel(x, coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap,
                               logF, log1mp, logp_pi, logq, log1mq, gmat, mode, out):  # pragma: no cover
    """As :func:`_mhsspt_cubic_run`, streams in parallel threads (the same arithmetic)."""
    for r in prange(x.shape[0]):
        _mhsspt_cubic_stream(r, x, coef, g0, inv_h, nG, coff, ulow, uhigh, ustd, upoint, ulogw, uoff, jmap,
                             logF, log1mp, logp_pi, logq, log1mq, gmat, mode, out)


class UniformMeanGaussian:
    """Density of a residual vector whose components are Gaussian with an unknown mean that is
    uniformly distributed on ``[low_c, high_c]`` (ng-chen-speyer, Section IV-E)::

        f(x) = prod_c [Phi((x_c - a_c)/s_c) - Phi((x_c - b_c)/s_c)] / (b_c - a_c)

    ``a_c == b_c`` falls back to the Gaussian density with mean ``a_c``.

    Parameters
    ----------
    low, high, std : array_like (C,)
        Mean range and standard deviation of each component (std > 0, high >= low).

    Examples
    --------
    >>> d = UniformMeanGaussian([0.0], [0.0], [1.0])
    >>> round(float(d.logpdf([0.0])), 6)      # log of the standard normal density at 0
    -0.918939
    """

    def __init__(self, low, high, std):
        self.low = np.atleast_1d(np.asarray(low, float))
        self.high = np.atleast_1d(np.asarray(high, float))
        self.std = np.atleast_1d(np.asarray(std, float))
        if not (self.low.shape == self.high.shape == self.std.shape) or self.low.ndim != 1:
            raise DataError(f"low, high and std must be 1-D of equal length, got shapes "
                            f"{self.low.shape}, {self.high.shape}, {self.std.shape}")
        if not (np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high))
                and np.all(np.isfinite(self.std))):
            raise DataError("density parameters must be finite")
        if np.any(self.std <= 0):
            raise DataError(f"std must be positive, got {self.std.tolist()}")
        if np.any(self.high < self.low):
            c = int(np.argmax(self.high < self.low))
            raise DataError(f"component {c}: high {self.high[c]} < low {self.low[c]}")
        self._point = (self.high - self.low) <= 1e-12 * np.maximum(1.0, np.abs(self.high))

    @property
    def size(self) -> int:
        return self.low.size

    def logpdf(self, x) -> np.ndarray:
        """Log density of ``x`` shaped (..., C), summed over the components -> (...)."""
        x = np.asarray(x, float)
        if x.shape[-1] != self.size:
            raise DataError(f"density has {self.size} components, sample has {x.shape[-1]}")
        s = self.std
        gauss = -0.5 * ((x - self.low) / s) ** 2 - np.log(s) - _LOG_SQRT_2PI
        width = np.where(self._point, 1.0, self.high - self.low)
        with np.errstate(divide="ignore", invalid="ignore"):  # point components are not used
            unif = _log_diff_ndtr((x - self.low) / s, (x - self.high) / s) - np.log(width)
        return np.where(self._point, gauss, unif).sum(axis=-1)

    def to_dict(self) -> dict:
        return {"low": self.low.tolist(), "high": self.high.tolist(), "std": self.std.tolist()}


#: Terms more than 40 nats below the largest are dropped from the log-sum-exp sums of the
#: recursion: exp(-40) = 4.2e-18, so 1 + exp(-40) rounds to 1 (a two-term log-sum-exp is then
#: bitwise the larger term) and even 26 such terms change a sum dominated by 1 by less than half
#: a unit in the last place. It saves the exp and log of every hypothesis far from the lead.
NEGLIGIBLE_NATS = 40.0


@njit(cache=True)
def _logaddexp(a, b):  # pragma: no cover - compiled
    """log(exp(a) + exp(b)); the smaller term dropped when it is below the larger's rounding."""
    if a < b:
        a, b = b, a
    if a == -np.inf:
        return -np.inf
    d = b - a
    if d < -NEGLIGIBLE_NATS:
        return a
    return a + math.log(1.0 + math.exp(d))


@njit(cache=True)
def mhsspt_update(logF, ll, phi, P, h0, h1, log1mp, logp_pi, logq, log1mq):  # pragma: no cover - compiled
    """One step of the log-domain Shiryayev recursion for hypotheses ``h0..h1-1`` (``h0`` is H0).

    ``logF`` (log posteriors) is updated in place from the log likelihoods ``ll``; ``P`` receives
    the posterior probabilities (0 for hypotheses more than :data:`NEGLIGIBLE_NATS` below the
    most probable); ``phi`` is scratch. Shared by :class:`MHSSPT` and the fused car monitor.

    Examples
    --------
    >>> logF, ll = np.array([0.0, -np.inf]), np.array([0.0, np.log(4.0)])
    >>> P = np.empty(2)
    >>> mhsspt_update(logF, ll, np.empty(2), P, 0, 2, np.log1p(-0.2), np.array([-np.inf, np.log(0.2)]),
    ...               -np.inf, 0.0)
    >>> P.round(6).tolist()          # (0.8 * 1, 0.2 * 4) / 1.6
    [0.5, 0.5]
    """
    # propagation (notes, residual-processing: phi_0, phi_j)
    if logq == -np.inf:  # q = 0: phi_0 = F_0 (1 - p) exactly
        phi[h0] = logF[h0] + log1mp
    else:
        m = -np.inf
        for j in range(h0 + 1, h1):
            if logF[j] > m:
                m = logF[j]
        lse_f = -np.inf
        if m > -np.inf:
            sf = 0.0
            for j in range(h0 + 1, h1):
                x = logF[j] - m
                if x > -NEGLIGIBLE_NATS:
                    sf += math.exp(x)
            lse_f = m + math.log(sf)
        phi[h0] = _logaddexp(logF[h0] + log1mp, logq + lse_f)
    lf0 = logF[h0]
    for j in range(h0 + 1, h1):
        phi[j] = _logaddexp(logF[j] + log1mq, lf0 + logp_pi[j])
    # Bayes update and normalisation
    m = -np.inf
    for j in range(h0, h1):
        phi[j] += ll[j]
        if phi[j] > m:
            m = phi[j]
    s = 0.0
    for j in range(h0, h1):
        x = phi[j] - m
        if x > -NEGLIGIBLE_NATS:
            e = math.exp(x)
            P[j] = e
            s += e
        else:
            P[j] = 0.0
    lz = m + math.log(s)
    for j in range(h0, h1):
        logF[j] = phi[j] - lz
        P[j] = P[j] / s


@njit(cache=True)
def _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """Stream ``r``: loglik[r] (T, H) -> out[r] log posteriors; logF[r] updated in place."""
    T, H = loglik.shape[1], loglik.shape[2]
    phi = np.empty(H)
    P = np.empty(H)
    lf = logF[r]
    for k in range(T):
        mhsspt_update(lf, loglik[r, k], phi, P, 0, H, log1mp, logp_pi, logq, log1mq)
        for j in range(H):
            out[r, k, j] = lf[j]


@njit(cache=True)
def _mhsspt_recursion(loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """loglik (R, T, H) -> out (R, T, H) log posteriors; logF (R, H) is updated in place; streams in turn."""
    for r in range(loglik.shape[0]):
        _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out)


@njit(cache=True, parallel=True)
def _mhsspt_recursion_parallel(loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """As :func:`_mhsspt_recursion`, streams in parallel threads (the same arithmetic per stream)."""
    for r in prange(loglik.shape[0]):
        _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out)


@njit(cache=True)
def _first_nonfinite_run(x, r):  # pragma: no cover - compiled
    """The first (sample, channel) of run r of x (R, T, C) that is not finite, as k * C + c; -1 if none."""
    T, C = x.shape[1], x.shape[2]
    for k in range(T):
        for c in range(C):
            if not np.isfinite(x[r, k, c]):
                return k * C + c
    return -1


@njit(cache=True, parallel=True)
def _first_nonfinite(x):  # pragma: no cover - compiled
    """Per run, :func:`_first_nonfinite_run`: one parallel pass without temporaries (a bulk call
    checks ~1e7 values)."""
    first = np.full(x.shape[0], -1, np.int64)
    for r in prange(x.shape[0]):
        first[r] = _first_nonfinite_run(x, r)
    return first


@njit(cache=True)
def _first_nonfinite_serial(x):  # pragma: no cover - compiled
    """As :func:`_first_nonfinite`, without the thread launch (one run: nothing to share)."""
    first = np.full(x.shape[0], -1, np.int64)
    for r in range(x.shape[0]):
        first[r] = _first_nonfinite_run(x, r)
    return first


@njit(cache=True)
def _probabilities_row(L, gmat, out, n):  # pragma: no cover - compiled
    """Row n: exp of the log posteriors (0 below exp's range, as exp itself gives), then group sums."""
    H = L.shape[1]
    for j in range(H):
        v = L[n, j]
        out[n, j] = math.exp(v) if v > -746.0 else 0.0
    for g in range(gmat.shape[0]):
        acc = 0.0
        for e in range(gmat.shape[1]):
            if gmat[g, e] >= 0:
                acc += out[n, gmat[g, e]]
        out[n, H + g] = acc


@njit(cache=True)
def _probabilities(L, gmat, out):  # pragma: no cover - compiled
    """Posterior probabilities and group sums: L (N, H) log posteriors -> out (N, H + G)."""
    for n in range(L.shape[0]):
        _probabilities_row(L, gmat, out, n)


@njit(cache=True, parallel=True)
def _probabilities_parallel(L, gmat, out):  # pragma: no cover - compiled
    """As :func:`_probabilities`, rows in parallel threads."""
    for n in prange(L.shape[0]):
        _probabilities_row(L, gmat, out, n)


def table_direct(advance):
    """Mark an :class:`MHSSPT` subclass's ``_advance`` as the base recursion on the features of
    ``_prepare``, so that a tabulated test may compute its outputs in one fused call
    (``MHSSPT._direct``) instead."""
    advance.table_direct = True
    return advance


#: Work (samples x components) above which a call shares the streams among threads; below it the
#: thread start-up costs more than it saves (a streaming step).
PARALLEL_MIN_WORK = 4096
#: Log posteriors above which :meth:`MHSSPT._outputs` shares its rows among threads: one exp per
#: value is ~10 ns, so below this (a one-run minute of 3000 samples is 3.3e4) waking the threads
#: costs more than the whole serial pass.
PARALLEL_MIN_OUTPUTS = 1 << 18


class MHSSPT(ResidualProcessor):
    """Multiple-hypothesis Shiryayev test over a vector of residual features.

    Parameters
    ----------
    inputs : sequence of str
        Feature channels (e.g. the norm of each filter's residual), C of them.
    densities : mapping hypothesis name -> density
        Ordered; the FIRST entry is the no-fault hypothesis H0. A density has ``logpdf(x)``
        for ``x`` (..., C) -> (...) (e.g. :class:`UniformMeanGaussian`).
    p : float
        Probability of a change from H0 at each sample (0 < p < 1).
    pi : sequence of float, optional
        Probability of each fault hypothesis given a change (default uniform).
    q : float
        Return probability from a fault hypothesis to H0 (0 = the exact MHSSPT).
    groups : mapping name -> list of hypothesis names, optional
        Extra outputs summing hypotheses, e.g. ``{"brake": ["brake_small", "brake_large"]}``.
    tabulate : float, optional
        With :class:`UniformMeanGaussian` densities: evaluate them by linear interpolation in
        tables of spacing ``tabulate`` times each feature's smallest std (:func:`tabulate_umg`;
        error <= tabulate^2 / 8 nats per component, measured as ``table_error``) instead of the
        exact formula -- more than ten times faster (benchmarks/bench_car_monitor.py); the table and
        the recursion then run in one compiled call. ``None`` (default): exact.
    interpolation : {"linear", "cubic"}
        With ``tabulate``: ``"linear"`` (default) as above, or ``"cubic"``: Hermite cubics that
        match the exact log density and its slope at every grid point, on the distinct components
        of each channel (:func:`tabulate_umg_cubic`; error about ``tabulate^4 / 200`` nats, a few
        1e-8 at 1/16, measured as ``table_error``), for a test that must agree with the exact
        one; about eight times faster than the exact formula on the RAV4 monitor.

    Outputs ``"P:<hypothesis>"`` for every hypothesis, then ``"P:<group>"`` for every group.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> test = MHSSPT(["r"], {"none": UniformMeanGaussian([0], [0], [1]),
    ...                       "bias": UniformMeanGaussian([2], [4], [1])}, p=1e-3)
    >>> x = np.r_[np.zeros(20), np.full(10, 3.0)]
    >>> P = test.run(Signals(np.arange(30.0), x, ["r"]))["P:bias"][0]
    >>> bool(P[19] < 0.01), bool(P[-1] > 0.99)
    (True, True)
    """

    def __init__(
        self,
        inputs: Sequence[str],
        densities: Mapping[str, object],
        p: float,
        pi: Sequence[float] | None = None,
        q: float = 0.0,
        groups: Mapping[str, Sequence[str]] | None = None,
        tabulate: float | None = None,
        interpolation: str = "linear",
    ):
        self.input_names = [str(s) for s in inputs]
        self.hypotheses = [str(h) for h in densities]
        self.densities = list(densities.values())
        H = len(self.hypotheses)
        if H < 2:
            raise DataError("MHSSPT needs H0 and at least one fault hypothesis")
        for h, d in zip(self.hypotheses, self.densities):
            size = getattr(d, "size", len(self.input_names))
            if size != len(self.input_names):
                raise DataError(f"density of hypothesis {h!r} has {size} components for "
                                f"{len(self.input_names)} inputs {self.input_names}")
        if not 0 < p < 1:
            raise DataError(f"change probability p must be in (0, 1), got {p}")
        if not 0 <= q < 1:
            raise DataError(f"return probability q must be in [0, 1), got {q}")
        pi = np.full(H - 1, 1.0 / (H - 1)) if pi is None else np.asarray(pi, float)
        if pi.shape != (H - 1,) or np.any(pi < 0) or abs(pi.sum() - 1) > 1e-9:
            raise DataError(f"pi must be {H - 1} non-negative probabilities summing to 1, got {pi}")
        self.p, self.q, self.pi = float(p), float(q), pi
        self.groups = {str(g): list(m) for g, m in (groups or {}).items()}
        for g, members in self.groups.items():
            for h in members:
                if h not in self.hypotheses:
                    raise DataError(f"group {g!r} names unknown hypothesis {h!r}; "
                                    f"hypotheses: {self.hypotheses}")
        self._gidx = [[self.hypotheses.index(h) for h in m] for m in self.groups.values()]
        width = max([len(g) for g in self._gidx], default=1)
        self._gmat = np.full((len(self._gidx), width), -1, np.int64)
        for i, g in enumerate(self._gidx):
            self._gmat[i, :len(g)] = g
        self.output_names = [f"P:{h}" for h in self.hypotheses] + [f"P:{g}" for g in self.groups]
        with np.errstate(divide="ignore"):
            self._logp_pi = np.r_[-np.inf, np.log(self.p) + np.log(pi)]
            self._logq = np.log(self.q) if self.q > 0 else -np.inf
        self._log1mp, self._log1mq = np.log1p(-self.p), np.log1p(-self.q)
        if all(isinstance(d, UniformMeanGaussian) for d in self.densities):
            st = [np.stack([getattr(d, a) for d in self.densities]) for a in ("low", "high", "std")]
            point = np.stack([d._point for d in self.densities])
            logw = np.log(np.where(point, 1.0, st[1] - st[0]))
            self._umg = (*st, point, logw)
            self._umg_shared = (self._umg, _shared_components(*self._umg))
        else:
            self._umg = None
            self._umg_shared = None
        self.tabulate = None if tabulate is None else float(tabulate)
        if interpolation not in ("linear", "cubic"):
            raise DataError(f"interpolation must be 'linear' or 'cubic', got {interpolation!r}")
        self.interpolation = str(interpolation)
        self._table = None
        self._cubic = None
        self.table_error = 0.0
        if self.tabulate is not None:
            if self._umg is None:
                raise DataError("tabulated densities need UniformMeanGaussian densities")
            if self.interpolation == "cubic":
                shared = self._umg_shared[1]  # (ulow, uhigh, ustd, upoint, ulogw, uoff, jmap)
                tb = tabulate_umg_cubic(*shared[:6], self.tabulate)
                self._cubic = (tb["coef"].ravel(), tb["g0"], tb["inv_h"], tb["nG"], tb["coff"], *shared)
                self._table = self._cubic
            else:
                tb = tabulate_umg(self._umg[0], self._umg[1], self._umg[2], self._umg[3], self.tabulate)
                self._table = (tb["tab"], tb["g0"], tb["inv_h"], tb["nG"], tb["toff"])
                self._dens = np.ascontiguousarray(np.stack([self._umg[i] for i in (0, 1, 2, 4)]))
            self.table_error = tb["error"]
        self.reset(1)

    def loglik(self, x: np.ndarray) -> np.ndarray:
        """Log densities of every hypothesis: x (..., C) -> (..., H).

        When every density is a :class:`UniformMeanGaussian` this runs a compiled kernel;
        other density objects are evaluated through their ``logpdf``.
        """
        x = np.asarray(x, float)
        if self._umg is None:
            return np.stack([d.logpdf(x) for d in self.densities], axis=-1)
        x3 = np.ascontiguousarray(x.reshape(-1, 1, x.shape[-1]) if x.ndim != 3 else x)
        out = np.empty((*x3.shape[:2], len(self.hypotheses)))
        if self._cubic is not None:  # the log likelihoods alone (mode 0: no recursion, logF untouched)
            _mhsspt_cubic_run(x3, *self._cubic, np.zeros((x3.shape[0], out.shape[2])), self._log1mp,
                              self._logp_pi, self._logq, self._log1mq, self._gmat, 0, out)
        elif self._table is not None:
            _loglik_table(x3, *self._table, *self._umg, out)
        else:
            par = x3.shape[0] > 1 and x3.size > PARALLEL_MIN_WORK
            src, shared = getattr(self, "_umg_shared", None) or (None, None)
            if src is not self._umg:  # restored without __init__, or densities replaced
                shared = _shared_components(*self._umg)
                self._umg_shared = (self._umg, shared)
            # the components shared between hypotheses once (bitwise _loglik_umg)
            (_loglik_umg_shared_parallel if par else _loglik_umg_shared)(x3, *shared, out)
        return out.reshape((*x.shape[:-1], len(self.hypotheses)))

    _state_attrs = ("_logF", "_k")

    def to_dict(self) -> dict:
        """Configuration as plain data; densities must be :class:`UniformMeanGaussian`."""
        if self._umg is None:
            raise DataError("only MHSSPTs with UniformMeanGaussian densities can be exported")
        return {"inputs": list(self.input_names),
                "densities": {h: d.to_dict() for h, d in zip(self.hypotheses, self.densities)},
                "p": self.p, "pi": self.pi.tolist(), "q": self.q, "groups": self.groups,
                "tabulate": self.tabulate, "interpolation": self.interpolation}

    @classmethod
    def from_dict(cls, d: dict) -> MHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"], tabulate=d.get("tabulate"),
                   interpolation=d.get("interpolation", "linear"))

    def reset(self, runs: int = 1) -> None:
        self._logF = np.full((runs, len(self.hypotheses)), -np.inf)
        self._logF[:, 0] = 0.0
        self._k = 0

    def _outputs(self, logF: np.ndarray) -> np.ndarray:
        """Probabilities of the hypotheses, then the group sums: logF (..., H) -> (..., H + G)."""
        H = logF.shape[-1]
        L = np.ascontiguousarray(logF.reshape(-1, H))
        out = np.empty((L.shape[0], H + len(self._gidx)))
        kern = _probabilities_parallel if L.size > PARALLEL_MIN_OUTPUTS else _probabilities
        kern(L, self._gmat, out)
        return out.reshape((*logF.shape[:-1], out.shape[1]))

    def _check_finite(self, x: np.ndarray) -> None:
        """Refuse a non-finite input, naming the first one (run, then sample, then channel)."""
        if x.size <= PARALLEL_MIN_WORK:
            first = None
        else:
            first = (_first_nonfinite if x.shape[0] > 1 else _first_nonfinite_serial)(x)
        if first is not None and (first < 0).all():
            return
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(f"MHSSPT input {self.input_names[c]!r} is not finite at sample "
                            f"{self._k + k} (run {run})")

    def _prepare(self, x: np.ndarray) -> np.ndarray:
        """The features the densities see (a subclass may replace some, e.g. a warm-up)."""
        return x

    @table_direct
    def _advance(self, x: np.ndarray) -> np.ndarray:
        self._check_finite(x)
        if x.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        if self._table is not None:  # one compiled call: table look-up and recursion, streams in parallel
            out = np.empty((*x.shape[:2], len(self.hypotheses)))
            self._table_call(x, False, out)
        else:
            ll = np.ascontiguousarray(self.loglik(x))
            out = np.empty_like(ll)
            rec = _mhsspt_recursion_parallel if x.shape[0] > 1 and x.size > PARALLEL_MIN_WORK else \
                _mhsspt_recursion
            rec(ll, self._logF, self._log1mp, self._logp_pi, self._logq, self._log1mq, out)
        self._k += x.shape[1]
        return out

    def _table_call(self, x: np.ndarray, probs: bool, out: np.ndarray) -> None:
        par = x.shape[0] > 1 and x.size > PARALLEL_MIN_WORK
        if self._cubic is not None:
            kern = _mhsspt_cubic_run_parallel if par else _mhsspt_cubic_run
            kern(np.ascontiguousarray(x, dtype=float), *self._cubic, self._logF, self._log1mp, self._logp_pi,
                 self._logq, self._log1mq, self._gmat, 2 if probs else 1, out)
            return
        kern = _mhsspt_table_run_parallel if par else _mhsspt_table_run
        kern(np.ascontiguousarray(x, dtype=float), *self._table, self._dens, self._umg[3], self._logF,
             self._log1mp, self._logp_pi, self._logq, self._log1mq, self._gmat, probs, out)

    def _direct(self, x: np.ndarray) -> np.ndarray | None:
        """Outputs straight from the tabulated kernel: the normalised posteriors the recursion
        forms (no log-posterior intermediate and no second exp), equal to
        ``_outputs(_advance(x))`` to rounding (probabilities below 4.3e-18 are 0 here); None where
        that path is needed (exact densities, or a subclass whose ``_advance`` is not marked
        :func:`table_direct`: it does more than ``_prepare`` and the tabulated recursion)."""
        if self._table is None or not getattr(type(self)._advance, "table_direct", False):
            return None
        x = self._prepare(x)
        self._check_finite(x)
        if x.shape[0] != self._logF.shape[0]:
            raise DataError(f"sample has {x.shape[0]} runs; the test was reset for {self._logF.shape[0]}")
        out = np.empty((*x.shape[:2], len(self.output_names)))
        self._table_call(x, True, out)
        self._k += x.shape[1]
        return out

    def _step(self, r: np.ndarray) -> np.ndarray:
        x = r[:, None, :]
        out = self._direct(x)
        return (self._outputs(self._advance(x)) if out is None else out)[:, 0]

    def run(self, signals: Signals) -> Signals:
        idx = signals.index(self.input_names)
        # the channels as they are (a view) when they are all of them in order: no 30 MB copy
        x = signals.values if list(idx) == list(range(signals.n_channels)) else signals.values[:, :, idx]
        self.reset(signals.runs)
        out = self._direct(x)
        return Signals(signals.t, self._outputs(self._advance(x)) if out is None else out, self.output_names,
                       check=False)

    def log_posterior(self) -> np.ndarray:
        """Current log posterior of every hypothesis, (runs, H)."""
        return self._logF.copy()


@dataclass
class MHSSPTCalibration:
    """Densities and hypothesis groups calibrated by :func:`calibrate_densities`.

    ``densities`` is ordered: the no-fault hypothesis first, then ``<fault>:small`` and
    ``<fault>:large`` for every fault; ``groups`` maps each fault to its pair, so that
    ``MHSSPT(inputs, cal.densities, p, groups=cal.groups)`` reports ``P:<fault>`` as the sum.
    ``ranges`` records, per hypothesis, the magnitudes it covers.
    """

    densities: dict[str, UniformMeanGaussian]
    groups: dict[str, list[str]]
    ranges: dict[str, tuple[float, float]]


def calibrate_densities(
    nominal: np.ndarray,
    faults: Mapping[str, Mapping[float, np.ndarray]],
    *,
    no_fault: str = "none",
    split: Mapping[str, float] | None = None,
    inflate: float = 1.0,
) -> MHSSPTCalibration:
    """Calibrate uniform-mean Gaussian densities from simulated residual features.

    Ng, Chen & Speyer, Section IV-E: every fault is simulated over a range of magnitudes;
    two hypotheses per fault (small and large magnitudes) get, per feature component, the range
    ``[a, b]`` spanned by the feature means at those magnitudes and the standard deviation of
    the features about their means (pooled over the magnitudes).

    Parameters
    ----------
    nominal : array (N, C)
        Feature samples without a fault (after transients): H0 gets their mean as a point
        mean and their standard deviation.
    faults : mapping fault -> mapping magnitude -> array (N_m, C)
        Feature samples of each fault at each simulated magnitude (after the fault has
        settled). At least two magnitudes per fault.
    no_fault : str
        Name of the no-fault hypothesis.
    split : mapping fault -> magnitude, optional
        Magnitudes ``<= split`` (in absolute value) form the small hypothesis, the others the
        large one (default: the median magnitude; a magnitude at the split is in both).
    inflate : float
        Factor (>= 1) applied to every standard deviation (a robustness margin for model error).

    Returns
    -------
    MHSSPTCalibration

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> nominal = rng.normal(0, 0.1, (500, 1))
    >>> feats = {m: rng.normal(m, 0.1, (200, 1)) for m in (1.0, 2.0, 3.0, 4.0)}
    >>> cal = calibrate_densities(nominal, {"bias": feats})
    >>> list(cal.densities), cal.groups
    (['none', 'bias:small', 'bias:large'], {'bias': ['bias:small', 'bias:large']})
    >>> np.round(cal.densities["bias:large"].low, 1).tolist()
    [3.0]
    """
    nominal = np.asarray(nominal, float)
    if nominal.ndim != 2 or nominal.shape[0] < 2:
        raise DataError(f"nominal features must be (N >= 2, C), got shape {nominal.shape}")
    C = nominal.shape[1]
    if not np.all(np.isfinite(nominal)):
        raise DataError("nominal features contain NaN or inf")
    if not inflate >= 1:
        raise DataError(f"inflate must be >= 1, got {inflate}")
    dens = {no_fault: UniformMeanGaussian(nominal.mean(0), nominal.mean(0),
                                          inflate * np.maximum(nominal.std(0, ddof=1), 1e-12))}
    groups: dict[str, list[str]] = {}
    ranges: dict[str, tuple[float, float]] = {no_fault: (0.0, 0.0)}
    for fault, by_mag in faults.items():
        mags = sorted(by_mag, key=abs)
        if len(mags) < 2:
            raise DataError(f"fault {fault!r}: need features at >= 2 magnitudes, got {len(mags)}")
        stats = {}
        for m in mags:
            x = np.asarray(by_mag[m], float)
            if x.ndim != 2 or x.shape[1] != C or x.shape[0] < 2:
                raise DataError(f"fault {fault!r} magnitude {m}: features must be (N >= 2, {C}), "
                                f"got {x.shape}")
            if not np.all(np.isfinite(x)):
                raise DataError(f"fault {fault!r} magnitude {m}: features contain NaN or inf")
            stats[m] = (x.mean(0), ((x - x.mean(0)) ** 2).sum(0), x.shape[0])
        cut = abs((split or {}).get(fault, float(np.median(np.abs(mags)))))
        small = [m for m in mags if abs(m) <= cut] or mags[:1]
        large = [m for m in mags if abs(m) >= cut] or mags[-1:]
        names = []
        for label, members in (("small", small), ("large", large)):
            means = np.array([stats[m][0] for m in members])
            ss = sum(stats[m][1] for m in members)
            dof = sum(stats[m][2] - 1 for m in members)
            std = inflate * np.maximum(np.sqrt(ss / dof), 1e-12)
            h = f"{fault}:{label}"
            dens[h] = UniformMeanGaussian(means.min(0), means.max(0), std)
            ranges[h] = (float(members[0]), float(members[-1]))
            names.append(h)
        groups[fault] = names
    return MHSSPTCalibration(dens, groups, ranges)


class WarmupMHSSPT(MHSSPT):
    """:class:`MHSSPT` that sees the no-fault mean features for the first ``warmup`` samples, while
    the residual generators' start-up transient (filter state zero, plant not at the design trim)
    dies out, and again after every gap (:meth:`resume`); afterwards the exact recursion. Batch and
    streaming alike.

    Examples
    --------
    >>> from fdikit.detect import UniformMeanGaussian
    >>> t = WarmupMHSSPT(["r"], {"none": UniformMeanGaussian([0], [0], [1]),
    ...                          "bias": UniformMeanGaussian([2], [4], [1])}, p=1e-3, warmup=5)
    >>> t.reset(1)
    >>> float(t.step([9.0])[0, 1]) < 0.01          # ignored during the warm-up
    True
    """

    _state_attrs = (*MHSSPT._state_attrs, "_warm_from")

    def __init__(self, *args, warmup: int = 0, **kw):
        super().__init__(*args, **kw)
        self.warmup = int(warmup)
        d0 = self.densities[0]
        self._x0 = np.asarray(getattr(d0, "low", np.zeros(len(self.input_names))), float)

    def reset(self, runs: int = 1) -> None:
        super().reset(runs)
        self._warm_from = 0

    def to_dict(self) -> dict:
        """Configuration as plain data (:meth:`MHSSPT.to_dict` and the warm-up length)."""
        return {**super().to_dict(), "warmup": self.warmup}

    @classmethod
    def from_dict(cls, d: dict) -> WarmupMHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"], tabulate=d.get("tabulate"),
                   interpolation=d.get("interpolation", "linear"), warmup=d.get("warmup", 0))

    def resume(self, n_held: int) -> None:
        """Data returns after ``n_held`` held samples (:class:`fdikit.monitor.Monitor`,
        ``on_invalid="hold"``): the filters' states went stale over the gap, so the warm-up
        starts again from the next sample."""
        if n_held > 0:
            self._warm_from = self._k

    def _prepare(self, x):
        n = self.warmup - (self._k - self._warm_from)
        if n > 0:
            x = x.copy()
            x[:, :n] = self._x0
        return x

    @table_direct
    def _advance(self, x):
        return super()._advance(self._prepare(x))


def extend_ranges(cal, rise: Mapping[str, Mapping[float, np.ndarray]], *,
                  split: Mapping[str, float] | None = None, path: Any = None):
    """Widen every fault hypothesis's uniform-mean range to cover its features' rise.

    ``rise[fault][magnitude]`` (W, C) are the means of the features over short windows after the
    onset of ``fault`` at ``magnitude``; each hypothesis of the pair (small: magnitudes up to the
    median, large: from the median, as :func:`~fdikit.detect.calibrate_densities`, or ``split``)
    gets ``low = min(low, min over its magnitudes' windows)`` and ``high`` likewise, per feature.
    The standard deviations are kept (they describe the noise about the settled mean, not the
    trend of the rise). Returns a new :class:`~fdikit.detect.mhsspt.MHSSPTCalibration`.

    With ``path`` (C,) (the no-fault mean), each window is first clipped per feature to the hull
    of ``path`` and the hypothesis's settled range ``[low, high]``: the range then covers the way
    the features travel from the no-fault mean to their settled values and nothing beyond it, not
    a one-sample overshoot at the onset (a wheel-speed-sum step passes straight to two residuals
    for a sample) nor the noise of a short window in a feature the fault does not move. The
    uniform-mean density is ``1 / width`` across its range, so every unit of width a hypothesis
    takes to cover a brief spike it pays for at every later sample, and a noise-widened range of a
    feature the fault leaves alone lets that hypothesis take another fault's settled features.

    Examples
    --------
    >>> from fdikit.detect.mhsspt import MHSSPTCalibration
    >>> from fdikit.detect import UniformMeanGaussian
    >>> c = MHSSPTCalibration({"none": UniformMeanGaussian([0.0], [0.0], [1.0]),
    ...                        "f:small": UniformMeanGaussian([2.0], [3.0], [1.0]),
    ...                        "f:large": UniformMeanGaussian([4.0], [5.0], [1.0])},
    ...                       {"f": ["f:small", "f:large"]}, {})
    >>> e = extend_ranges(c, {"f": {1.0: np.array([[0.5], [2.5]]), 2.0: np.array([[3.5]]),
    ...                             3.0: np.array([[6.0]])}})
    >>> [(e.densities[h].low.tolist(), e.densities[h].high.tolist()) for h in ("f:small", "f:large")]
    [([0.5], [3.5]), ([3.5], [6.0])]
    >>> e = extend_ranges(c, {"f": {1.0: np.array([[-0.5], [2.5]]), 2.0: np.array([[3.5]]),
    ...                             3.0: np.array([[6.0]])}}, path=np.array([0.0]))
    >>> [(e.densities[h].low.tolist(), e.densities[h].high.tolist()) for h in ("f:small", "f:large")]
    [([0.0], [3.0]), ([3.5], [5.0])]
    """
    dens = dict(cal.densities)
    for fault, by_mag in rise.items():
        if fault not in cal.groups:
            raise DataError(f"no hypotheses for fault {fault!r}; faults: {list(cal.groups)}")
        mags = sorted(by_mag, key=abs)
        cut = abs((split or {}).get(fault, float(np.median(np.abs(mags)))))
        small = [m for m in mags if abs(m) <= cut] or mags[:1]
        large = [m for m in mags if abs(m) >= cut] or mags[-1:]
        hyps = cal.groups[fault]
        for h, ms in zip(hyps, (small, large) if len(hyps) == 2 else (mags,)):
            x = np.concatenate([np.asarray(by_mag[m], float) for m in ms])
            if not np.all(np.isfinite(x)):
                raise DataError(f"fault {fault!r}: rise features contain NaN or inf")
            d = dens[h]
            if path is not None:
                x = np.clip(x, np.minimum(d.low, path), np.maximum(d.high, path))
            dens[h] = UniformMeanGaussian(np.minimum(d.low, x.min(0)), np.maximum(d.high, x.max(0)), d.std)
    return MHSSPTCalibration(dens, dict(cal.groups), dict(cal.ranges))


def floor_std(cal, frac: float, *, h0_floor: bool = False):
    """Floor every density's per-feature std at ``frac`` times its own upper mean ``high`` (a
    relative model error: a few per cent of a residual's level) and, with ``h0_floor``, at the
    no-fault (first) hypothesis's std (a fault adds to the noise, it does not remove it), as a new
    :class:`~fdikit.detect.mhsspt.MHSSPTCalibration`.

    Examples
    --------
    >>> from fdikit.detect.mhsspt import MHSSPTCalibration
    >>> from fdikit.detect import UniformMeanGaussian
    >>> c = MHSSPTCalibration({"none": UniformMeanGaussian([0.1], [0.1], [0.001]),
    ...                        "f": UniformMeanGaussian([1.0], [2.0], [0.01])}, {}, {})
    >>> [floor_std(c, 0.05).densities[h].std.round(6).tolist() for h in ("none", "f")]
    [[0.005], [0.1]]
    >>> floor_std(c, 0.0, h0_floor=True).densities["f"].std.tolist()
    [0.01]
    """
    h0 = next(iter(cal.densities.values())).std if h0_floor else 0.0
    # a fault does not remove the noise: no hypothesis narrower than the no-fault one (h0_floor)
    dens = {h: UniformMeanGaussian(d.low, d.high, np.maximum(np.maximum(d.std, frac * np.abs(d.high)), h0))
            for h, d in cal.densities.items()}
    return MHSSPTCalibration(dens, dict(cal.groups), dict(cal.ranges))


# ---------------------------------------------------------------------------------- pattern table


# ------------------------------------------------------------------- MHSSPT from real, labelled data


class LineMeanGaussian:
    """Multivariate Gaussian density with full covariance whose mean is unknown and uniformly
    distributed on the segment from ``a`` to ``b`` (the multivariate form of
    :class:`UniformMeanGaussian`: a fault of unknown size moves the mean along its direction).

    With ``Sigma = L L'``, ``z = L^-1 (x - a)``, ``v = L^-1 (b - a)``, ``w = |v|``, ``u = v / w``
    and ``t = u' z``, integrating the mean out gives::

        f(x) = N(z - t u; 0, I) / |L| * [Phi(t) - Phi(t - w)] / w

    (in one dimension exactly :class:`UniformMeanGaussian`); ``a == b`` is the Gaussian density.

    Parameters
    ----------
    a, b : array_like (C,)
        Ends of the mean segment.
    cov : array_like (C, C)
        Covariance (symmetric positive definite).

    Examples
    --------
    >>> d = LineMeanGaussian([0.0], [2.0], [[1.0]])
    >>> u = UniformMeanGaussian([0.0], [2.0], [1.0])
    >>> bool(abs(d.logpdf([0.7]) - u.logpdf([0.7])) < 1e-12)
    True
    """

    def __init__(self, a, b, cov):
        self.a = np.atleast_1d(np.asarray(a, float))
        self.b = np.atleast_1d(np.asarray(b, float))
        self.cov = np.atleast_2d(np.asarray(cov, float))
        C = self.a.size
        if self.a.ndim != 1 or self.b.shape != (C,) or self.cov.shape != (C, C):
            raise DataError(f"a, b must be (C,) and cov (C, C); got {self.a.shape}, {self.b.shape}, "
                            f"{self.cov.shape}")
        if not all(np.all(np.isfinite(v)) for v in (self.a, self.b, self.cov)):
            raise DataError("density parameters must be finite")
        try:
            self._L = np.linalg.cholesky(0.5 * (self.cov + self.cov.T))
        except np.linalg.LinAlgError:
            ev = np.linalg.eigvalsh(0.5 * (self.cov + self.cov.T))
            raise DataError(f"covariance is not positive definite (smallest eigenvalue {ev.min():.3g})") \
                from None
        self._Linv = np.linalg.inv(self._L)
        v = self._Linv @ (self.b - self.a)
        self._w = float(np.linalg.norm(v))
        self._u = v / self._w if self._w > 1e-12 else np.zeros(C)
        self._logdet = float(np.sum(np.log(np.diag(self._L))))

    @property
    def size(self) -> int:
        return self.a.size

    def logpdf(self, x) -> np.ndarray:
        """Log density of ``x`` shaped (..., C) -> (...)."""
        x = np.asarray(x, float)
        if x.shape[-1] != self.size:
            raise DataError(f"density has {self.size} components, sample has {x.shape[-1]}")
        C = self.size
        d = x - self.a
        # elementwise sums in a fixed order (no BLAS): one sample gives the bits of a whole record
        z = [sum(self._Linv[i, j] * d[..., j] for j in range(i + 1)) for i in range(C)]  # L^-1 lower
        zz = sum(zi * zi for zi in z)
        if self._w <= 1e-12:
            return -0.5 * zz - self._logdet - C * _LOG_SQRT_2PI
        t = sum(self._u[i] * z[i] for i in range(C))
        perp2 = np.maximum(zz - t * t, 0.0)
        return (-0.5 * perp2 - (C - 1) * _LOG_SQRT_2PI - self._logdet
                + _log_diff_ndtr(t, t - self._w) - np.log(self._w))

    def to_dict(self) -> dict:
        return {"a": self.a.tolist(), "b": self.b.tolist(), "cov": self.cov.tolist()}


def _segment_list(x, what: str, C: int | None) -> list[np.ndarray]:
    segs = [x] if isinstance(x, np.ndarray) and x.ndim == 2 else list(x)
    out = []
    for i, s in enumerate(segs):
        s = np.asarray(s, float)
        if s.ndim != 2 or s.shape[0] < 2 or (C is not None and s.shape[1] != C):
            raise DataError(f"{what} segment {i}: features must be (N >= 2, {C or 'C'}), got {s.shape}")
        if not np.all(np.isfinite(s)):
            k, c = np.argwhere(~np.isfinite(s))[0]
            raise DataError(f"{what} segment {i}: feature {c} is not finite at sample {k}")
        out.append(s)
    return out


def calibrate_segments(
    nominal,
    segments: Mapping[str, Any],
    *,
    no_fault: str = "none",
    scale: tuple[float, float] = (0.5, 2.0),
    ridge: float = 1e-9,
) -> MHSSPTCalibration:
    """Full-covariance densities from labelled segments of real data, one unknown magnitude each.

    The no-fault hypothesis is the Gaussian with the nominal mean and covariance. Every labelled
    fault segment (one fault at one magnitude, which need not be known, after the onset
    transient) gives one hypothesis: a :class:`LineMeanGaussian` whose mean runs along the
    segment's offset ``d = mean(segment) - mean(nominal)`` from ``scale[0] d`` to ``scale[1] d``
    (the same fault at other sizes moves the features along the same direction) with the
    covariance of the segment about its mean. A fault with several segments gets one hypothesis
    per segment (``<fault>:0``, ``<fault>:1``, ...) and a group summing them; one segment is
    named ``<fault>``. Feed whitened features (:class:`~fdikit.detect.whiten.VARWhitener`) when
    the residuals are serially correlated (:func:`design_mhsspt` does).

    Parameters
    ----------
    nominal : array (N, C) or sequence of arrays (N_i, C)
        Fault-free features.
    segments : mapping fault -> array (N, C) or sequence of arrays
        Labelled fault segments.
    no_fault : str
        Name of the no-fault hypothesis.
    scale : (float, float)
        Range of fault sizes covered, relative to each segment's own (``(1, 1)``: exactly the
        observed size, a plain Gaussian).
    ridge : float
        Added to each covariance's diagonal, relative to its mean diagonal (numerical safety).

    Returns
    -------
    MHSSPTCalibration
        ``ranges`` holds ``scale`` per fault hypothesis.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> nom = rng.normal(size=(2000, 2))
    >>> cal = calibrate_segments(nom, {"f": rng.normal(size=(500, 2)) + [3.0, 1.0]})
    >>> list(cal.densities), np.round(cal.densities["f"].b, 0).tolist()
    (['none', 'f'], [6.0, 2.0])
    """
    nom = np.concatenate(_segment_list(nominal, "nominal", None))
    C = nom.shape[1]
    if nom.shape[0] < 2 * C + 2:
        raise DataError(f"{nom.shape[0]} nominal samples are too few for a {C} x {C} covariance")
    lo, hi = (float(s) for s in scale)
    if not (0 <= lo <= hi) or not np.isfinite(hi):
        raise DataError(f"scale must be 0 <= low <= high, got {scale}")

    def cov_of(x):
        S = np.atleast_2d(np.cov(x, rowvar=False))
        return S + ridge * max(float(np.mean(np.diag(S))), 1e-300) * np.eye(C)

    mu0 = nom.mean(0)
    dens: dict[str, Any] = {no_fault: LineMeanGaussian(mu0, mu0, cov_of(nom))}
    groups: dict[str, list[str]] = {}
    ranges: dict[str, tuple[float, float]] = {no_fault: (0.0, 0.0)}
    for fault, segs in segments.items():
        segs = _segment_list(segs, f"fault {fault!r}", C)
        names = [str(fault)] if len(segs) == 1 else [f"{fault}:{i}" for i in range(len(segs))]
        for h, s in zip(names, segs):
            if s.shape[0] < 2 * C + 2:
                raise DataError(f"fault {fault!r}: segment of {s.shape[0]} samples is too short for a "
                                f"{C} x {C} covariance")
            d = s.mean(0) - mu0
            dens[h] = LineMeanGaussian(mu0 + lo * d, mu0 + hi * d, cov_of(s))
            ranges[h] = (lo, hi)
        groups[str(fault)] = names
    return MHSSPTCalibration(dens, groups, ranges)


class WhitenedMHSSPT(MHSSPT):
    """:class:`MHSSPT` on pre-whitened features: every sample first passes a
    :class:`~fdikit.detect.whiten.VARWhitener` (its innovations are serially uncorrelated under
    the nominal model, so multiplying their likelihoods is right), then the recursion runs with
    densities calibrated on whitened data (e.g. :class:`LineMeanGaussian`, full covariance).
    The first ``whitener.order`` samples after :meth:`reset` (the whitener's history is not full
    yet, so its output is not an innovation) are seen as the no-fault mean, as
    :class:`WarmupMHSSPT` does. Batch and streaming alike; the whitener's history is part of the
    state.

    Parameters
    ----------
    inputs : sequence of str
        Feature channels (raw, not whitened).
    densities : mapping
        As :class:`MHSSPT`, on the whitened features.
    p, pi, q, groups
        As :class:`MHSSPT`.
    whitener : VARWhitener
        Fitted on nominal data of ``inputs``.

    Examples
    --------
    >>> from fdikit.detect.whiten import VARWhitener
    >>> w = VARWhitener(["r"], [0.0], [[[0.5]]])
    >>> t = WhitenedMHSSPT(["r"], {"none": LineMeanGaussian([0], [0], [[1]]),
    ...                            "f": LineMeanGaussian([1], [3], [[1]])}, p=1e-3, whitener=w)
    >>> x = np.r_[np.zeros(50), np.full(50, 4.0)]
    >>> P = t.run(Signals(np.arange(100.0), x, ["r"]))["P:f"][0]
    >>> bool(P[49] < 0.01), bool(P[-1] > 0.99)
    (True, True)
    """

    _state_attrs = (*MHSSPT._state_attrs, "whitener")

    def __init__(self, inputs, densities, p, pi=None, q=0.0, groups=None, *, whitener):
        super().__init__(inputs, densities, p, pi, q, groups)
        if list(whitener.input_names) != list(self.input_names):
            raise DataError(f"whitener inputs {whitener.input_names} differ from the test's "
                            f"{self.input_names}")
        self.whitener = whitener
        self.whitener.reset(1)

    def reset(self, runs: int = 1) -> None:
        super().reset(runs)
        if hasattr(self, "whitener"):
            self.whitener.reset(runs)

    def _advance(self, x):
        e = self.whitener.whiten(x)
        n = self.whitener.order - self._k  # whitening transient: the history is not full yet
        if n > 0:
            e = e.copy()
            e[:, :n] = self._x0
        return super()._advance(e)

    @property
    def _x0(self) -> np.ndarray:
        d0 = self.densities[0]
        return np.asarray(getattr(d0, "a", getattr(d0, "low", np.zeros(len(self.input_names)))), float)

    def to_dict(self) -> dict:
        """Configuration as plain data (densities must be :class:`LineMeanGaussian`)."""
        if not all(isinstance(d, LineMeanGaussian) for d in self.densities):
            raise DataError("only WhitenedMHSSPTs with LineMeanGaussian densities can be exported")
        return {"inputs": list(self.input_names),
                "densities": {h: d.to_dict() for h, d in zip(self.hypotheses, self.densities)},
                "p": self.p, "pi": self.pi.tolist(), "q": self.q, "groups": self.groups,
                "whitener": self.whitener.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> WhitenedMHSSPT:
        from .whiten import VARWhitener

        dens = {h: LineMeanGaussian(v["a"], v["b"], v["cov"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"],
                   whitener=VARWhitener.from_dict(d["whitener"]))


def design_mhsspt(
    inputs: Sequence[str],
    nominal,
    segments: Mapping[str, Any],
    p: float,
    *,
    whiten: bool = True,
    order: int | None = None,
    max_order: int = 10,
    scale: tuple[float, float] = (0.5, 2.0),
    q: float = 0.0,
    no_fault: str = "none",
) -> WhitenedMHSSPT:
    """An MHSSPT from labelled real data: pre-whitening fitted on the nominal records, then
    full-covariance densities from one segment per fault and magnitude (:func:`calibrate_segments`).

    Parameters
    ----------
    inputs : sequence of str
        Feature channel names (C).
    nominal : array (T, C) or sequence of arrays (T_i, C)
        Fault-free records (each one contiguous record).
    segments : mapping fault -> array (N, C) or sequence of arrays
        Labelled contiguous fault segments (after the onset transient), magnitudes unknown.
    p : float
        Change probability per sample.
    whiten : bool
        Fit a :class:`~fdikit.detect.whiten.VARWhitener` (False: mean removal only; right for
        serially independent features).
    order, max_order : int
        VAR order (None: BIC up to ``max_order``).
    scale, no_fault
        As :func:`calibrate_segments`.
    q : float
        Return probability (:class:`MHSSPT`).

    Returns
    -------
    WhitenedMHSSPT
        Its ``calibration`` attribute is the :class:`MHSSPTCalibration` used.

    Examples
    --------
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> ar = lambda n: lfilter([1.0], [1.0, -0.9], rng.normal(size=(n, 2)), axis=0)
    >>> t = design_mhsspt(["a", "b"], ar(20_000), {"f": ar(3000) + [4.0, -4.0]}, p=1e-4)
    >>> t.whitener.order, t.hypotheses
    (1, ['none', 'f'])
    """
    from .whiten import VARWhitener

    C = len(inputs)
    nom = _segment_list(nominal, "nominal", C)
    if whiten:
        w = VARWhitener.fit(nom, inputs, order=order, max_order=max_order)
    else:
        w = VARWhitener(inputs, np.concatenate(nom).mean(0), np.zeros((0, C, C)))
    k0 = w.order  # the first samples of each record are whitening transients

    def white(seg):
        w.reset(1)
        e = w.whiten(seg[None])[0]
        return e[k0:]

    wn = [white(s) for s in nom]
    ws = {f: [white(s) for s in _segment_list(v, f"fault {f!r}", C)] for f, v in segments.items()}
    cal = calibrate_segments(wn, ws, no_fault=no_fault, scale=scale)
    groups = {g: m for g, m in cal.groups.items() if m != [g]}
    test = WhitenedMHSSPT(inputs, cal.densities, p, q=q, groups=groups, whitener=w)
    test.calibration = cal
    return test


def _fault_outputs(out: Signals, outputs: Sequence[str] | None) -> tuple[str, list[str]]:
    h0 = out.names[0]
    if outputs is not None:
        return h0, [str(o) for o in outputs]
    groups = [n for n in out.names if n.startswith("P:")]
    # the hypotheses that a group sums are not decisions of their own: prefer groups, else hypotheses
    members = {n for n in groups if ":" in n[2:] and "P:" + n[2:].rsplit(":", 1)[0] in groups}
    return h0, [n for n in groups[1:] if n not in members]


def detection_time(out: Signals, level: float = 0.9, *, outputs: Sequence[str] | None = None) -> dict:
    """First sample at which a fault's posterior reaches ``level``, per run.

    Parameters
    ----------
    out : Signals
        An MHSSPT's output (``P:<hypothesis>`` channels, H0 first).
    level : float
        Posterior probability that counts as a detection.
    outputs : sequence of str, optional
        Fault outputs to consider (default: every ``P:`` output except H0, a group's member
        hypotheses replaced by the group).

    Returns
    -------
    dict
        ``sample`` (runs,) int (-1: never), ``time`` (runs,) s (nan: never), ``fault`` (list of
        the output that crossed first, or None).

    Examples
    --------
    >>> P = np.array([[0.99, 0.01], [0.5, 0.5], [0.05, 0.95]])
    >>> d = detection_time(Signals(np.arange(3.0), P, ["P:none", "P:f"]))
    >>> d["sample"].tolist(), d["fault"]
    ([2], ['P:f'])
    """
    _, names = _fault_outputs(out, outputs)
    P = out.values[:, :, out.index(names)]
    hit = P >= level
    anyhit = hit.any(axis=2)
    first = np.where(anyhit.any(axis=1), anyhit.argmax(axis=1), -1)
    times = np.where(first >= 0, out.t[np.maximum(first, 0)], np.nan)
    faults = [names[int(np.argmax(P[r, k]))] if k >= 0 else None for r, k in enumerate(first)]
    return {"sample": first, "time": times, "fault": faults}


def final_diagnosis(out: Signals, *, outputs: Sequence[str] | None = None) -> dict:
    """The most probable hypothesis at the last sample of each run (H0 included).

    Returns
    -------
    dict
        ``diagnosis`` (list of output names per run), ``probability`` (runs,).

    Examples
    --------
    >>> P = np.array([[0.99, 0.01], [0.05, 0.95]])
    >>> final_diagnosis(Signals(np.arange(2.0), P, ["P:none", "P:f"]))["diagnosis"]
    ['P:f']
    """
    h0, names = _fault_outputs(out, outputs)
    cols = [h0, *names]
    last = out.values[:, -1, out.index(cols)]
    k = last.argmax(axis=1)
    return {"diagnosis": [cols[i] for i in k], "probability": last[np.arange(last.shape[0]), k]}
