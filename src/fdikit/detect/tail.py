"""Serial correlation and extreme-value tails of nominal statistics: the tools behind
:func:`~fdikit.detect.design_threshold` on one long record.

* :func:`autocorrelation` of one or many records, pooled over the records.
* :func:`block_length` chooses the block length of a moving-block bootstrap from the
  autocorrelation (Politis & White 2004, with the correction of Patton, Politis & White 2009):
  the flat-top lag-window estimates of the spectral density at zero and of its first moment give
  ``b = (2 G^2 / D)^(1/3) N^(1/3)`` with ``D = 4/3 g(0)^2`` (moving / circular blocks). The same
  window gives the integrated autocorrelation time ``tau = g(0) / R(0)`` and the effective sample
  size ``N / tau`` (the number of independent samples with the same variance of the mean).
* :func:`block_rate_ci` bootstraps the rate of an event indicator (an exceedance, an alarm onset)
  by resampling moving blocks of its running sums: every replicate is a sum of block counts, so a
  million-sample record costs a few milliseconds per hundred replicates.
* :func:`fit_gpd` fits a generalised Pareto distribution to the excesses over a high threshold
  (:data:`scipy.stats.genpareto`, maximum likelihood, location 0); :func:`gpd_level` and
  :func:`gpd_rate` turn it into the level exceeded with a given probability and back
  (peaks over threshold: ``P(X > x) = p_u (1 + xi (x - u) / sigma)^(-1/xi)`` for ``x > u``).
  Weighted fits (:func:`fit_gpd_weighted`) are what a block-bootstrap replicate needs: the
  excesses of a resampled block count as often as the block was drawn.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

from ..errors import DataError

__all__ = ["autocorrelation", "block_length", "block_rate_ci", "fit_gpd", "fit_gpd_weighted", "gpd_level",
           "gpd_rate"]


def _records(x) -> list[np.ndarray]:
    x = np.asarray(x, float)
    if x.ndim == 1:
        x = x[None]
    if x.ndim != 2:
        raise DataError(f"records must be (T,) or (records, T), got shape {x.shape}")
    return [r[np.isfinite(r)] for r in x]


def autocorrelation(x, max_lag: int) -> np.ndarray:
    """Sample autocorrelation ``rho(0..max_lag)`` of one record (T,) or many (records, T), pooled.

    Each record is centred on the common mean; the autocovariances (biased, divided by the number
    of samples) are summed over the records, then divided by the lag-0 value. Non-finite samples
    (e.g. the ``-inf`` that stands for "cannot alarm yet") are left out. Computed with FFTs.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> x = lfilter([1.0], [1.0, -0.8], np.random.default_rng(0).normal(size=200_000))
    >>> round(float(autocorrelation(x, 2)[1]), 2)
    0.8
    """
    recs = [r for r in _records(x) if r.size > 1]
    if not recs:
        raise DataError("autocorrelation needs at least 2 finite samples")
    mean = np.concatenate(recs).mean()
    max_lag = int(max_lag)
    acov = np.zeros(max_lag + 1)
    n = 0
    for r in recs:
        z = r - mean
        m = min(max_lag, z.size - 1)
        nfft = 1 << int(np.ceil(np.log2(2 * z.size)))
        f = np.fft.rfft(z, nfft)
        ac = np.fft.irfft(f * np.conj(f), nfft)[: m + 1]
        acov[: m + 1] += ac
        n += z.size
    if acov[0] <= 0:
        return np.r_[1.0, np.zeros(max_lag)]
    return acov / acov[0]


def block_length(x, *, max_lag: int | None = None) -> dict:
    """Moving-block bootstrap block length and integrated autocorrelation time of a record.

    Politis & White (2004) with the Patton-Politis-White (2009) correction: the bandwidth ``M =
    2 m`` with ``m`` the first lag after which ``K_N = max(5, sqrt(log10 N))`` autocorrelations in
    a row are insignificant (``|rho| < 2 sqrt(log10 N / N)``); with the flat-top window
    ``lambda``, ``g = sum lambda(k/M) R(k)`` and ``G = sum lambda(k/M) |k| R(k)`` over
    ``|k| <= M``, the block length ``b = (2 G^2 / D)^(1/3) N^(1/3)``, ``D = 4/3 g^2``.

    Parameters
    ----------
    x : array (T,) or (records, T)
        One record or independent records of the same process.
    max_lag : int, optional
        Largest lag examined (default ``min(T - 1, max(100, 10 sqrt(N)))``).

    Returns
    -------
    dict
        ``block`` (samples, >= 1, at most the record length), ``tau`` (integrated autocorrelation
        time, samples, >= 1), ``bandwidth`` ``M``, ``n`` (finite samples), ``n_eff`` (``n / tau``).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> x = lfilter([1.0], [1.0, -0.9], np.random.default_rng(1).normal(size=500_000))
    >>> b = block_length(x)
    >>> 15 < b["tau"] < 23          # (1 + 0.9) / (1 - 0.9) = 19
    True
    """
    recs = _records(x)
    n = int(sum(r.size for r in recs))
    T = max(r.size for r in recs)
    if n < 10:
        raise DataError(f"block length needs at least 10 finite samples, got {n}")
    if max_lag is None:
        max_lag = int(min(T - 1, max(100, 10 * math.sqrt(n))))
    max_lag = max(1, min(int(max_lag), T - 1))
    rho = autocorrelation(x, max_lag)
    K = max(5, math.ceil(math.sqrt(math.log10(n))))
    crit = 2.0 * math.sqrt(math.log10(n) / n)
    small = np.abs(rho[1:]) < crit  # small[k-1]: lag k insignificant
    m = max_lag
    run = 0
    for k in range(1, max_lag + 1):
        run = run + 1 if small[k - 1] else 0
        if run >= K:
            m = k - K  # the last significant lag before the run
            break
    m = max(m, 1)
    M = min(2 * m, max_lag)
    lags = np.arange(1, M + 1)
    t = lags / M
    lam = np.where(t <= 0.5, 1.0, 2.0 * (1.0 - t))
    g = 1.0 + 2.0 * np.sum(lam * rho[1 : M + 1])  # in units of R(0)
    G = 2.0 * np.sum(lam * lags * rho[1 : M + 1])
    tau = max(g, 1.0)
    D = 4.0 / 3.0 * tau**2
    b = (2.0 * G**2 / D) ** (1.0 / 3.0) * n ** (1.0 / 3.0) if G != 0 else 1.0
    b = int(min(max(1, round(b)), T))
    return {"block": b, "tau": float(tau), "bandwidth": int(M), "n": n, "n_eff": float(n / tau)}


def _block_starts(lengths: np.ndarray, b: int) -> np.ndarray:
    """Flat start indices of every length-``b`` block inside each record (records laid end to end)."""
    starts = []
    off = 0
    for L in lengths:
        if L >= b:
            starts.append(off + np.arange(L - b + 1))
        off += L
    return np.concatenate(starts) if starts else np.zeros(0, np.int64)


def block_rate_ci(events, block: int, *, level: float = 0.95, n_boot: int = 400, seed: int = 0,
                  lengths=None) -> tuple:
    """Moving-block bootstrap confidence interval of the rate (mean) of an event indicator.

    Blocks never span two records.

    Parameters
    ----------
    events : bool array (records, T)
        Event indicator (e.g. ``statistic > threshold``) of independent records.
    block : int
        Block length, samples (a record shorter than it is one block).
    level : float
        Confidence level of the percentile interval.
    n_boot : int
        Bootstrap replicates.
    seed : int
        Seed of the resampling.
    lengths : array (records,) of int, optional
        Samples of each record when they differ (record ``r`` is ``events[r, :lengths[r]]``; the
        rest is padding). Default: all ``T``.

    Returns
    -------
    (low, high) : floats
        Interval of the event probability per sample.

    Examples
    --------
    >>> import numpy as np
    >>> e = np.random.default_rng(0).random((1, 100_000)) < 0.01
    >>> lo, hi = block_rate_ci(e, 1)
    >>> bool(lo < 0.01 < hi)
    True
    """
    e = np.atleast_2d(np.asarray(events, bool))
    R, T = e.shape
    b = int(max(1, min(block, T)))
    L = np.full(R, T) if lengths is None else np.asarray(lengths, np.int64)
    S = np.concatenate([np.r_[0, np.cumsum(r[:n], dtype=np.int64)] for r, n in zip(e, L)])
    # cumulative sums per record with a leading 0: record r occupies S[off_r + r : off_r + r + L_r + 1]
    starts = _block_starts(L, b)
    rec = np.searchsorted(np.cumsum(L), starts, side="right")  # the record of each block start
    sums = S[starts + rec + b] - S[starts + rec]
    size = np.full(sums.size, b)
    short = np.flatnonzero(L < b)  # a record shorter than a block is one block of its own length
    if short.size:
        ends = np.cumsum(L + 1) - 1
        sums = np.concatenate([sums, S[ends[short]]])
        size = np.concatenate([size, L[short]])
    nb = max(1, round(int(L.sum()) / b))
    rng = np.random.default_rng(seed)
    est = np.empty(n_boot)
    chunk = max(1, 4_000_000 // nb)
    for i in range(0, n_boot, chunk):
        k = min(chunk, n_boot - i)
        pick = rng.integers(0, sums.size, size=(k, nb))
        est[i : i + k] = sums[pick].sum(axis=1) / (size[pick].sum(axis=1) if short.size else nb * b)
    a = (1 - level) / 2
    return float(np.quantile(est, a)), float(np.quantile(est, 1 - a))


def fit_gpd(excess) -> tuple[float, float]:
    """Maximum-likelihood generalised Pareto fit ``(xi, sigma)`` of excesses over a threshold.

    :data:`scipy.stats.genpareto` with the location fixed at 0 (``xi`` is its shape ``c``).

    Examples
    --------
    >>> import numpy as np
    >>> y = np.random.default_rng(0).exponential(2.0, 20_000)     # xi = 0, sigma = 2
    >>> xi, s = fit_gpd(y)
    >>> abs(xi) < 0.03, abs(s - 2) < 0.1
    (True, True)
    """
    y = np.asarray(excess, float)
    if y.size < 10:
        raise DataError(f"a GPD fit needs at least 10 excesses, got {y.size}")
    c, _, s = stats.genpareto.fit(y, floc=0.0)
    return float(c), float(s)


def fit_gpd_weighted(excess, weights, start: tuple[float, float]) -> tuple[float, float]:
    """Weighted maximum-likelihood GPD fit ``(xi, sigma)`` started from ``start`` (bootstrap
    replicates: ``weights`` are how often each excess was drawn)."""
    y = np.asarray(excess, float)
    w = np.asarray(weights, float)
    keep = w > 0
    y, w = y[keep], w[keep]
    ymax = y.max()
    sw = w.sum()

    def nll(th):
        xi, ls = th
        s = math.exp(ls)
        if xi < 0 and 1 + xi * ymax / s <= 0:
            return 1e300
        if abs(xi) < 1e-8:
            return sw * ls + np.dot(w, y) / s
        return sw * ls + (1 + 1 / xi) * np.dot(w, np.log1p(xi * y / s))

    res = optimize.minimize(nll, [start[0], math.log(start[1])], method="Nelder-Mead",
                            options={"xatol": 1e-5, "fatol": 1e-7, "maxiter": 400})
    return float(res.x[0]), float(math.exp(res.x[1]))


def gpd_level(u: float, p_u: float, xi: float, sigma: float, p: float) -> float:
    """Level exceeded with probability ``p < p_u`` under the tail ``P(X > u) = p_u`` and GPD excesses.

    Examples
    --------
    >>> round(gpd_level(0.0, 0.1, 0.0, 1.0, 0.001), 6)         # exponential tail: log(100)
    4.60517
    """
    r = p / p_u
    if abs(xi) < 1e-9:
        return float(u - sigma * math.log(r))
    return float(u + sigma / xi * (r ** (-xi) - 1.0))


def gpd_rate(u: float, p_u: float, xi: float, sigma: float, x: float) -> float:
    """Exceedance probability of a level ``x >= u`` under the fitted tail (inverse of :func:`gpd_level`).

    Examples
    --------
    >>> round(gpd_rate(0.0, 0.1, 0.0, 1.0, 4.60517), 6)
    0.001
    """
    z = (x - u) / sigma
    if abs(xi) < 1e-9:
        return float(p_u * math.exp(-z))
    a = 1 + xi * z
    if a <= 0:
        return 0.0
    return float(p_u * a ** (-1.0 / xi))
