"""Tabulated densities: linear (:func:`tabulate_umg`) and cubic Hermite
(:func:`tabulate_umg_cubic`) tables of the uniform-mean Gaussian log densities, and the
compiled kernels that look them up and run the recursion in one call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ...errors import DataError
from .densities import _LOG_SQRT_2PI, UniformMeanGaussian
from .kernels import umg_component_logpdf
from .recursion import _emit, mhsspt_update

__all__ = ["tabulate_umg", "tabulate_umg_cubic"]


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
