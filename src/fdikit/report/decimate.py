"""Decimation of long records for display: min/max per bucket, so that no spike disappears."""

from __future__ import annotations

import numpy as np

from ..errors import DataError

__all__ = ["minmax_decimate", "true_intervals"]


def minmax_decimate(t, y, max_points: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """Decimate a sampled signal to at most ``max_points`` samples, keeping each bucket's extremes.

    The record is cut into ``max_points // 3`` buckets of equal sample count; each bucket keeps
    its smallest and its largest sample (and its first NaN, if any), in time order, at their own
    time stamps. So the
    displayed curve has the same envelope as the full one: a one-sample spike survives, and so
    does a gap (a NaN sample makes its bucket contribute a NaN, which a plot draws as a break).

    Parameters
    ----------
    t : array_like, shape (T,)
        Sample times, s.
    y : array_like, shape (T,)
        Values (NaN where there is no valid sample).
    max_points : int
        Upper bound on the number of returned samples (>= 4).

    Returns
    -------
    t_d, y_d : ndarray, shape (<= max_points,)
        The kept samples; the record itself when it is already short enough.

    Examples
    --------
    >>> import numpy as np
    >>> y = np.zeros(100_000); y[12_345] = 7.0
    >>> td, yd = minmax_decimate(np.arange(y.size) * 0.01, y, 1000)
    >>> td.size <= 1000, float(yd.max()), float(td[yd.argmax()])
    (True, 7.0, 123.45)
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if t.ndim != 1 or y.shape != t.shape:
        raise DataError(f"minmax_decimate: t and y must be 1-D of one length, got {t.shape} and {y.shape}")
    if max_points < 4:
        raise DataError(f"minmax_decimate: max_points must be >= 4, got {max_points}")
    n = t.size
    if n <= max_points:
        return t, y
    nb = max_points // 3
    lo = np.linspace(0, n, nb + 1).astype(np.int64)[:-1]
    bad = np.isnan(y)
    big = np.int64(n)
    idx = np.arange(n, dtype=np.int64)
    bucket = np.repeat(np.arange(nb), np.diff(np.append(lo, n)))
    # first index of each bucket's smallest and largest valid sample (reduceat over the buckets)
    yf_lo = np.where(bad, np.inf, y)
    yf_hi = np.where(bad, -np.inf, y)
    mins = np.minimum.reduceat(yf_lo, lo)
    maxs = np.maximum.reduceat(yf_hi, lo)
    kmin = np.minimum.reduceat(np.where(yf_lo == mins[bucket], idx, big), lo)
    kmax = np.minimum.reduceat(np.where(yf_hi == maxs[bucket], idx, big), lo)
    # a bucket holding a gap also keeps its first NaN sample, which a plot draws as a break
    knan = np.minimum.reduceat(np.where(bad, idx, big), lo)
    keep = np.unique(np.concatenate([kmin, kmax, knan]))
    keep = keep[keep < n]
    return t[keep], y[keep]


def true_intervals(t, mask, max_intervals: int = 500) -> list[tuple[float, float]]:
    """Time intervals ``[t_start, t_end]`` where ``mask`` is True (e.g. held samples to shade).

    Runs of True samples become intervals from the first to the last of their samples (plus
    half a sample period either side, so a single sample is visible). When there are more than
    ``max_intervals`` runs, neighbouring intervals closer than 1/``max_intervals`` of the
    record's span are merged (the shaded area can only grow: no held sample goes unshaded).
    """
    t = np.asarray(t, float)
    m = np.asarray(mask, bool)
    if t.shape != m.shape:
        raise DataError(f"true_intervals: t {t.shape} and mask {m.shape} differ")
    if not m.any():
        return []
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    half = 0.5 * (float(np.median(np.diff(t))) if t.size > 1 else 0.0)
    iv = np.column_stack([t[starts] - half, t[ends] + half])
    if len(iv) > max_intervals:
        span = float(t[-1] - t[0]) or 1.0
        gap = span / max_intervals
        merged = [list(iv[0])]
        for s, e in iv[1:]:
            if s - merged[-1][1] <= gap:
                merged[-1][1] = e
            else:
                merged.append([s, e])
        iv = np.array(merged)
    return [(float(a), float(b)) for a, b in iv]
