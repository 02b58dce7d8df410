"""More log formats onto the same grid: Vector ASC, candump, Parquet, CSV tables, MDF4, and one dispatcher.

Every reader here returns a :class:`LoadedSignals` (a :class:`~fdikit.io.LogSignals`) built by the
same two steps as :func:`fdikit.io.read_can_log`:

* **frame logs** (Vector BLF and ASC, candump ``.log``, raw CAN frames in MDF4) are decoded per
  message with the DBC (:func:`frames_to_signals`; MDF4 bus logging is decoded by asammdf's
  ``extract_bus_logging``), with time 0 at the first frame of the log;
* **decoded-signal files** (Parquet, CSV tables, MDF4 with signal channels) keep the file's own
  time axis (a datetime column counts seconds from its first row);

then each signal is resampled onto one uniform grid at ``rate`` Hz without bridging gaps longer
than ``max_gap`` source periods (:func:`series_to_grid`, which calls
:func:`fdikit.io.resample_to_grid`).

Bad-input policy (never crash, never lie)
-----------------------------------------
* What cannot be trusted before processing -- a missing, truncated or corrupt file, an unknown
  format, a time axis that goes backwards, a missing channel, a DBC without a requested signal,
  an impossible unit conversion, a text line that is neither a frame nor a known event, a
  message seen on several CAN buses without ``channel=`` (ASC, candump, MDF4; the BLF frame
  reader does not report buses) -- raises :class:`~fdikit.errors.DataError` naming the file,
  line / row / frame and the values.
* Bad *samples* are kept as NaN source samples, so every grid sample whose interpolation touches
  them is flagged ``valid == False``: NaN or inf values, frames too short for a signal or that
  cannot be decoded, two frames of one message at the same time with different payloads.
  Their counts are in :class:`SignalQuality` (``info[name]``).
* Exact duplicates (same time, same payload or value) are merged, and counted (``n_duplicates``).
* A stuck signal (constant for at least ``stuck_after`` seconds) is reported in ``info``
  (``stuck``, ``longest_constant``), not refused: a constant signal can be real.

Time precision: ASC and candump store timestamps with 6 decimals, so each frame time and the grid
start move by up to 0.5 us, and a grid value read from them differs from the BLF path by about
``max |dv/dt| * 1 us`` (the tests allow ``2 us``).
"""

from __future__ import annotations

import csv as _csv
import difflib
import os
import re
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .can import (
    _SI,
    LogSignals,
    SignalInfo,
    _load_dbc,
    _load_resolved,
    _norm_unit,
    _read_blf_frames,
    _read_frame_table,
    _resample_apply,
    _resample_plan,
    _resolve,
    convert_units,
)
from .decode import FramePayloads, decode_message
from .timebase import TimeOrigin, origin_of_float, times_to_seconds

__all__ = [
    "FORMATS",
    "LoadedSignals",
    "SignalQuality",
    "SourceReport",
    "detect_format",
    "frames_to_signals",
    "read_asc",
    "read_blf",
    "read_can_log",
    "read_candump",
    "read_log",
    "read_mdf",
    "read_parquet",
    "read_table_csv",
    "series_to_grid",
]

#: Format names understood by :func:`read_log` and the file suffixes that select them.
FORMATS: dict[str, tuple[str, ...]] = {
    "blf": (".blf",),
    "asc": (".asc",),
    "candump": (".log", ".candump"),
    "parquet": (".parquet", ".pq"),
    "csv": (".csv",),
    "mdf": (".mf4", ".mdf", ".mf3", ".dat"),
}
_FRAME_FORMATS = ("blf", "asc", "candump")
#: Largest grid a loader builds (samples); a larger one is a time column in the wrong unit.
MAX_GRID = 50_000_000


# ---------------------------------------------------------------------------------- result types
@dataclass(frozen=True)
class SignalQuality(SignalInfo):
    """:class:`~fdikit.io.SignalInfo` plus what the loader found wrong with one signal.

    Attributes
    ----------
    n_nonfinite : int
        Source samples that are NaN or inf (in the file, or a frame that could not give the
        signal); every grid sample interpolated from one is flagged invalid.
    n_undecodable : int
        Frames of the signal's message too short to hold the signal, or that the DBC cannot
        decode (counted in ``n_nonfinite`` as well).
    n_duplicates : int
        Source samples merged because they repeat the previous one exactly (same time, same
        payload or value).
    n_conflicts : int
        Pairs of samples at the same time with different values: kept as one NaN sample.
    longest_constant : float
        Longest stretch (s) over which the source value did not change.
    stuck : bool
        ``longest_constant >= stuck_after`` (a report, not an error).
    """

    n_nonfinite: int = 0
    n_undecodable: int = 0
    n_duplicates: int = 0
    n_conflicts: int = 0
    longest_constant: float = 0.0
    stuck: bool = False


@dataclass(frozen=True)
class SourceReport:
    """What was read: format, file, record count and any lines skipped in lenient mode.

    Attributes
    ----------
    format : str
        One of :data:`FORMATS`.
    path : str
    n_records : int
        Frames (frame logs) or rows / samples (decoded files) read.
    skipped : tuple of (int, str)
        ``(line number, text)`` of lines skipped with ``strict=False`` (empty when strict).
    """

    format: str
    path: str
    n_records: int
    skipped: tuple[tuple[int, str], ...] = field(default=())


class LoadedSignals(LogSignals):
    """:class:`~fdikit.io.LogSignals` with a :class:`SourceReport` (``source``).

    ``info`` maps each channel to a :class:`SignalQuality`; ``reasons`` lists, for every run of
    invalid grid samples, ``(channel, start, stop, reason)`` (samples ``start <= k < stop``; see
    :meth:`invalid_reason`).
    """

    __slots__ = ("reasons", "source")

    def __init__(self, t, values, names, units=None, *, valid=None, info=None, source=None, t0=0.0,
                 time_origin=None, reasons=None):
        super().__init__(t, values, names, units, valid=valid, info=info, t0=t0, time_origin=time_origin)
        self.source = source
        self.reasons: list[tuple[str, int, int, str]] = list(reasons or [])

    def invalid_reason(self, k: int) -> str | None:
        """Why grid sample ``k`` is invalid (every channel's reason, joined), ``None`` when valid.

        Examples
        --------
        >>> import numpy as np
        >>> s = series_to_grid({"x": (np.r_[0.0, 0.1, 0.2, 1.0, 1.1], np.zeros(5))}, {}, rate=10.0)
        >>> s.invalid_reason(1) is None
        True
        >>> s.invalid_reason(5)
        'x: gap, no sample from 0.200000 s to 1.000000 s (0.8 s, longer than max_gap = 3 periods of 0.1 s)'

        """
        if not -self.n_samples <= k < self.n_samples:
            raise DataError(f"sample {k} out of range for {self.n_samples} samples")
        k = k % self.n_samples
        if self.valid[0, k].all():
            return None
        why = [r for n, a, b, r in self.reasons if a <= k < b]
        if not why:  # a selection or window of the loaded signals: the mask still says which
            why = [f"{self.names[c]}: no valid value" for c in np.flatnonzero(~self.valid[0, k])]
        return "; ".join(why)

    def _keep_source(self, s: LogSignals) -> LoadedSignals:
        return LoadedSignals(s.t, s.values, s.names, s.units, valid=s.valid, info=s.info, source=self.source,
                             t0=s.t0, time_origin=s.time_origin)

    def select(self, names) -> LoadedSignals:
        out = self._keep_source(super().select(names))
        keep = set(out.names)
        out.reasons = [r for r in self.reasons if r[0] in keep]
        return out

    def window(self, t0: float | None = None, t1: float | None = None) -> LoadedSignals:
        return self._keep_source(super().window(t0, t1))


# ---------------------------------------------------------------------------------- common core
def _longest_constant(t: np.ndarray, v: np.ndarray) -> float:
    """Longest time span (s) over which consecutive finite source values are equal."""
    if t.size < 2:
        return 0.0
    same = (v[1:] == v[:-1]) & np.isfinite(v[1:])
    if not same.any():
        return 0.0
    # runs of True in ``same``: run [i, j) spans t[i] .. t[j]
    d = np.diff(np.r_[0, same.astype(np.int8), 0])
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return float(np.max(t[ends] - t[starts]))


def _longest_constant_rows(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`_longest_constant` of every row of ``v`` (shape (k, N)) at once, the same floats.

    The rows are laid end to end, each padded with a break (False) at both ends, so a run of
    equal finite values never crosses rows; the run over ``same[i:j]`` spans ``t[j] - t[i]``.
    """
    k, n = v.shape
    out = np.zeros(k)
    if n < 2:
        return out
    run = np.zeros((k, n + 1), bool)
    np.logical_and(v[:, 1:] == v[:, :-1], np.isfinite(v[:, 1:]), out=run[:, 1:n])
    flat = run.ravel()
    starts = np.flatnonzero(flat[1:] & ~flat[:-1]) + 1  # padded index i + 1 of a run same[i:j]
    if starts.size == 0:
        return out
    ends = np.flatnonzero(~flat[1:] & flat[:-1]) + 1  # padded index j + 1
    row, i = np.divmod(starts - 1, n + 1)
    j = ends - 1 - row * (n + 1)
    np.maximum.at(out, row, t[j] - t[i])
    return out


def _touches_bad(t: np.ndarray, fin: np.ndarray, grid: np.ndarray, method: str) -> np.ndarray:
    """Grid samples whose interpolation gives a non-zero weight to a non-finite source sample."""
    n = t.size
    if fin.all():
        return np.zeros(grid.shape, bool)
    i = np.searchsorted(t, grid, side="right") - 1
    if method == "previous" or n == 1:
        return (i >= 0) & ~fin[np.clip(i, 0, n - 1)]
    i0 = np.clip(i, 0, n - 2)
    i1 = i0 + 1
    span = t[i1] - t[i0]
    w = np.where(span > 0, (grid - t[i0]) / np.where(span > 0, span, 1.0), 0.0)
    return (~fin[i0] & (w < 1)) | (~fin[i1] & (w > 0))


def _clean_series(name: str, t: np.ndarray, v: np.ndarray,
                  where: str) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Check a per-signal time axis and merge same-time samples.

    Returns ``(t, v, n_duplicates, n_conflicts)``; raises when time is not finite or goes back.
    """
    t = np.asarray(t, float)
    v = np.asarray(v, float)
    if not np.isfinite(t).all():
        bad = np.flatnonzero(~np.isfinite(t))
        raise DataError(f"{where}: signal {name!r} has a non-finite time stamp at sample {int(bad[0])}")
    d = np.diff(t)
    if not (d <= 0).any():  # strictly increasing (the usual case)
        return t, v, 0, 0
    back = np.flatnonzero(d < 0)
    if back.size:
        k = int(back[0]) + 1
        raise DataError(f"{where}: time of signal {name!r} goes backwards at sample {k} "
                        f"({float(t[k - 1])!r} s then {float(t[k])!r} s)")
    same = np.flatnonzero(d == 0)
    if not same.size:
        return t, v, 0, 0
    v = v.copy()
    keep = np.ones(t.size, bool)
    n_dup = n_conf = 0
    for k in same + 1:  # k repeats the time of k - 1: merge into k (the last one is kept)
        a, b = v[k - 1], v[k]
        if a == b or (np.isnan(a) and np.isnan(b)):
            n_dup += 1
        else:
            n_conf += 1
            v[k] = np.nan
        keep[k - 1] = False
    return t[keep], v[keep], n_dup, n_conf


def series_to_grid(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]],
    source_units: Mapping[str, str],
    rate: float | None = None,
    *,
    units: str | Mapping[str, str] | None = None,
    max_gap: float = 3.0,
    method: str = "linear",
    span: str = "common",
    log_span: tuple[float, float] | None = None,
    stuck_after: float = 2.0,
    counts: Mapping[str, Mapping[str, int]] | None = None,
    source: SourceReport | None = None,
    where: str = "log",
    t0: float = 0.0,
    time_origin: TimeOrigin | None = None,
) -> LoadedSignals:
    """Put irregularly sampled signals on one uniform grid (the second step of every loader).

    Parameters
    ----------
    series : mapping of str -> (t, v)
        Per channel, sample times (s, non-decreasing) and values, shape ``(N,)`` each. NaN or
        inf values are *bad samples*: kept, and every grid sample whose interpolation touches one
        is flagged invalid. Samples at one time are merged (equal) or turned into one NaN
        sample (different). The channel order is the output order.
    source_units : mapping of str -> str
        Unit of each channel as recorded.
    rate : float, optional
        Grid rate (Hz); default the highest median source rate (rounded to 1 mHz).
    units : "si" or mapping, optional
        Conversion, as in :func:`fdikit.io.read_can_log`.
    max_gap : float
        Longest bridged interval, in that channel's median source periods.
    method : {"linear", "previous"}
    span : {"common", "log"}
        Grid over the common span of the channels, or over ``log_span``.
    log_span : (float, float), optional
        ``(start, end)`` of the whole log (s); default the union of the channels' spans.
    stuck_after : float
        A channel constant for at least this long (s) is reported ``stuck`` in its info.
    counts : mapping, optional
        Extra per-channel counts from the reader (``n_undecodable``).
    source : SourceReport, optional
    where : str
        What to call the source in error messages.
    t0, time_origin
        Absolute origin of the (relative) sample times, stored on the result
        (:mod:`fdikit.io.timebase`).

    Returns
    -------
    LoadedSignals
        One run, ``T`` samples; ``valid`` is ``False`` exactly where a value is NaN. A grid
        sample inside a gap (its neighbouring source samples more than ``max_gap`` periods
        apart) is NaN and invalid, never held or bridged; :meth:`LoadedSignals.invalid_reasons`
        says why each invalid sample is invalid.

    Examples
    --------
    >>> import numpy as np
    >>> s = series_to_grid({"x": (np.arange(5.0), np.array([0.0, 1.0, np.nan, 3.0, 4.0]))},
    ...                    {"x": "m"}, rate=2.0)
    >>> s.valid[0, :, 0].astype(int).tolist()
    [1, 1, 1, 0, 0, 0, 1, 1, 1]
    """
    names = list(series)
    if not names:
        raise DataError("no signals requested")
    if span not in ("common", "log"):
        raise DataError(f"span must be 'common' or 'log', got {span!r}")
    if not (isinstance(max_gap, int | float) and np.isfinite(max_gap) and max_gap > 0):
        raise DataError(f"max_gap must be a positive number of source periods, got {max_gap!r}")
    if method not in ("linear", "previous"):
        raise DataError(f"unknown resampling method {method!r}; use 'linear' or 'previous'")
    if units is not None and not isinstance(units, str | Mapping):
        raise DataError(f"units must be 'si' or a mapping of signal -> unit, got {units!r}")
    if isinstance(units, str) and units.lower() != "si":
        raise DataError(f"units must be 'si' or a mapping of signal -> unit, got {units!r}")
    if isinstance(units, Mapping):
        for k in units:
            if k not in names:
                raise DataError(f"unit conversion given for {k!r}, which is not a requested signal")
    counts = counts or {}
    clean: dict[str, tuple[np.ndarray, np.ndarray, int, int]] = {}
    period: dict[str, float] = {}
    # the signals of one message share their time stamps (one array): what depends on the times
    # alone (checks, period, interpolation indices and weights, gap count) is computed once per
    # array; each entry keeps its array alive, so an id is never reused while the dict lives
    by_time: dict[int, dict[str, Any]] = {}
    checked: dict[int, tuple[Any, np.ndarray]] = {}
    for n in names:
        t_in, v = series[n]
        hit = checked.get(id(t_in))
        if hit is not None and hit[0] is t_in:  # times already checked: no same-time samples
            t, v, n_dup, n_conf = hit[1], np.asarray(v, float), 0, 0
        else:
            t, v, n_dup, n_conf = _clean_series(n, t_in, v, where)
            if n_dup == n_conf == 0 and t.size == np.size(t_in):
                checked[id(t_in)] = (t_in, t)
        if t.size == 0:
            raise DataError(f"{where}: signal {n!r} has no samples")
        clean[n] = (t, v, n_dup, n_conf)
        shared = by_time.get(id(t))
        if shared is None or shared["t"] is not t:
            per = float(np.median(np.diff(t))) if t.size > 1 else np.inf
            shared = by_time[id(t)] = {"t": t, "period": per}
        period[n] = shared["period"]
    if rate is None:
        fastest = min(period.values())
        if not np.isfinite(fastest) or fastest <= 0:
            raise DataError(f"{where}: cannot choose a grid rate (every signal has a single sample); "
                            "pass rate=")
        rate = float(np.round(1.0 / fastest, 3))
    try:
        rate = float(rate)
    except (TypeError, ValueError):
        raise DataError(f"grid rate must be a positive number of Hz, got {rate!r}") from None
    if not np.isfinite(rate) or rate <= 0:
        raise DataError(f"grid rate must be a positive number of Hz, got {rate}")
    if span == "common":
        a = max(clean[n][0][0] for n in names)
        b = min(clean[n][0][-1] for n in names)
        if b < a:
            raise DataError(f"{where}: the requested signals share no common time span "
                            f"({a:.6f} s .. {b:.6f} s)")
    elif log_span is not None:
        a, b = float(log_span[0]), float(log_span[1])
    else:
        a = min(clean[n][0][0] for n in names)
        b = max(clean[n][0][-1] for n in names)
    n_float = np.floor((b - a) * rate + 1e-9) + 1
    if not np.isfinite(n_float) or n_float > MAX_GRID:
        raise DataError(f"{where}: a grid of {n_float:.6g} samples ({b - a:.6g} s at {rate:g} Hz) is too "
                        f"large (limit {MAX_GRID}); check the time column's unit (time_unit='ms', 'us' or "
                        "'ns' for a clock that does not count seconds) and the rate")
    n_grid = int(n_float)
    grid = a + np.arange(n_grid) / rate

    values = np.empty((n_grid, len(names)))
    valid = np.empty((n_grid, len(names)), bool)
    out_units: list[str] = []
    conv: list[np.ndarray] = []
    for n in names:  # unit conversions first, in channel order (the first impossible one is the error)
        t, v, n_dup, n_conf = clean[n]
        src_unit = str(source_units.get(n, "") or "")
        target = src_unit
        if isinstance(units, str):
            target = _SI.get(_norm_unit(src_unit), src_unit)
        elif units is not None:
            target = units.get(n, src_unit)
        if target != src_unit:
            v = convert_units(v, src_unit, target, channel=n)
        out_units.append(target)
        conv.append(v)
    # the channels of one time axis (one message) are resampled together, as the rows of one
    # matrix: the same elementwise arithmetic as channel by channel, in fewer numpy calls
    groups: dict[int, list[int]] = {}
    for c, n in enumerate(names):
        groups.setdefault(id(clean[n][0]), []).append(c)
    fin_of: dict[int, np.ndarray] = {}
    longest_of: dict[int, float] = {}
    for cols in groups.values():
        t = clean[names[cols[0]]][0]
        shared = by_time[id(t)]
        if "plan" not in shared:
            shared["plan"] = _resample_plan(t, grid, max_gap, method, period[names[cols[0]]])
        plan = shared["plan"]
        vm = np.empty((len(cols), t.size))
        for j, c in enumerate(cols):
            vm[j] = conv[c]
        fin = np.isfinite(vm)
        all_fin = fin.all(axis=1)
        vals = _resample_apply(plan, vm if all_fin.all() else np.where(fin, vm, 0.0))
        ok = np.repeat(plan[-1][None, :], len(cols), axis=0)
        for j in range(len(cols)):
            if not all_fin[j]:  # an interpolation that uses a bad sample is bad
                ok[j] &= ~_touches_bad(t, fin[j], grid, method)
        with np.errstate(invalid="ignore", over="ignore"):
            ok &= np.isfinite(vals)
        # a grid time a rounding error (<= 1 ns) outside the samples (times made relative by a
        # subtraction) is the end sample itself, not a sample outside the data
        if "edge" not in shared:
            tol = 1e-9 * max(1.0, abs(float(grid[-1])))
            after, before = grid > t[-1], grid < t[0]
            near = (after & (grid - t[-1] <= tol)) | (before & (t[0] - grid <= tol))
            shared["edge"] = (after, near) if near.any() else None
        if shared["edge"] is not None:
            after, near = shared["edge"]
            for j in range(len(cols)):
                v = vm[j]
                edge = ~ok[j] & near
                if edge.any():
                    end = np.where(after, v[-1], v[0])
                    edge &= np.isfinite(end)
                    vals[j, edge] = end[edge]
                    ok[j, edge] = True
        if not ok.all():
            vals[~ok] = np.nan
        values[:, cols] = vals.T
        valid[:, cols] = ok.T
        longest = _longest_constant_rows(t, vm)
        for j, c in enumerate(cols):
            fin_of[c] = fin[j]
            longest_of[c] = float(longest[j])
    info: dict[str, SignalQuality] = {}
    reasons: list[tuple[str, int, int, str]] = []
    for c, n in enumerate(names):
        t, v, n_dup, n_conf = clean[n]
        src_unit = str(source_units.get(n, "") or "")
        ok = valid[:, c]
        n_ok = int(np.count_nonzero(ok))
        if n_ok < n_grid:
            reasons.extend(_invalid_spans(n, t, fin_of[c], grid, ok, method, max_gap, period[n]))
        longest = longest_of[c]
        span_s = float(t[-1] - t[0])
        info[n] = SignalQuality(
            n, src_unit, out_units[c], int(t.size),
            float((t.size - 1) / span_s) if t.size > 1 and span_s > 0 else float("nan"),
            period[n], float(t[0]), float(t[-1]),
            _n_gaps(by_time[id(t)], max_gap), n_grid - n_ok,
            n_nonfinite=int(t.size - np.count_nonzero(fin_of[c])),
            n_undecodable=int(counts.get(n, {}).get("n_undecodable", 0)),
            n_duplicates=n_dup, n_conflicts=n_conf, longest_constant=longest,
            stuck=bool(longest >= stuck_after))
    out = LoadedSignals(grid, values, names, out_units, valid=valid, info=info, source=source, t0=t0,
                        time_origin=time_origin)
    out.reasons = reasons
    return out


def _n_gaps(shared: dict[str, Any], max_gap: float) -> int:
    """Source intervals longer than ``max_gap`` periods, once per time axis."""
    if "n_gaps" not in shared:
        shared["n_gaps"] = int(np.sum(np.diff(shared["t"]) > max_gap * shared["period"]))
    return shared["n_gaps"]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of every run of True."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _invalid_spans(name, t, fin, grid, ok, method, max_gap, period) -> list[tuple[str, int, int, str]]:
    """Why each run of invalid grid samples of one channel is invalid: outside the channel's span,
    a gap longer than ``max_gap`` periods, or an interpolation touching a bad source sample."""
    out = []
    bad = ~ok
    outside = bad & ((grid < t[0]) | (grid > t[-1]))
    touches = bad & ~outside & _touches_bad(t, fin, grid, method)
    gap = bad & ~outside & ~touches
    for a, b in _runs(outside):
        out.append((name, a, b, f"{name}: no sample (outside its recorded span {t[0]:.6f} .. {t[-1]:.6f} s)"))
    for a, b in _runs(touches):
        out.append((name, a, b, f"{name}: interpolated from a NaN, inf or undecodable source sample"))
    i = np.searchsorted(t, grid, side="right") - 1
    for a, b in _runs(gap):
        i0 = int(np.clip(i[a], 0, t.size - 1))
        i1 = min(i0 + 1, t.size - 1)
        out.append((name, a, b, f"{name}: gap, no sample from {t[i0]:.6f} s to {t[i1]:.6f} s "
                                f"({t[i1] - t[i0]:.4g} s, longer than max_gap = {max_gap:g} periods of "
                                f"{period:.4g} s)"))
    out.sort(key=lambda r: (r[1], r[0]))
    return out


def _check_signal_list(signals) -> list[str]:
    if signals is None:
        raise DataError("name the signals to read: signals=['MESSAGE.SIGNAL', ...]")
    if isinstance(signals, str):
        signals = [signals]
    signals = list(signals)
    if not signals:
        raise DataError("no signals requested")
    for s in signals:
        if not isinstance(s, str):
            raise DataError(f"signal names must be strings, got {s!r}")
    if len(set(signals)) != len(signals):
        raise DataError(f"signals requested twice: {sorted({s for s in signals if signals.count(s) > 1})}")
    return signals


def frames_to_signals(
    ts: np.ndarray,
    ids: np.ndarray,
    data: Sequence[bytes],
    dbc: Any,
    signals: Sequence[str],
    rate: float | None = None,
    *,
    units: str | Mapping[str, str] | None = None,
    max_gap: float = 3.0,
    method: str = "linear",
    span: str = "common",
    stuck_after: float = 2.0,
    lines: np.ndarray | None = None,
    channels: Sequence[str] | None = None,
    channel: str | int | None = None,
    source: SourceReport | None = None,
    where: str = "CAN log",
) -> LoadedSignals:
    """Decode CAN frames with a DBC and put the chosen signals on one grid.

    The frame-level half of :func:`fdikit.io.read_can_log`, for frames from any source.

    Parameters
    ----------
    ts : ndarray, shape (N,)
        Frame times (s), non-decreasing; time 0 of the result is ``ts[0]``.
    ids : ndarray of int, shape (N,)
        Arbitration ids.
    data : sequence of bytes or FramePayloads, length N
        Payloads. A payload too short for a signal gives a bad (NaN) sample of that signal,
        never zero padding. Each message's signals are decoded over all its frames at once
        (:func:`fdikit.io.decode.decode_message`, equal to cantools' per-frame decoding).
    dbc : path-like or cantools Database
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names.
    rate, units, max_gap, method, span, stuck_after
        As in :func:`series_to_grid`.
    lines : ndarray of int, shape (N,), optional
        Line number of each frame in a text log (for error messages).
    channels : sequence of str, length N, optional
        The bus (channel) of each frame, as the log names it. When given, a message seen on
        more than one bus is refused unless ``channel`` picks one: frames of two buses are
        never mixed into one signal.
    channel : str or int, optional
        Keep only the frames of this bus (compared as text with ``channels``).
    source : SourceReport, optional
    where : str
        Name of the source in error messages.

    Returns
    -------
    LoadedSignals

    Raises
    ------
    DataError
        Time going backwards (naming frame and line), a DBC without a requested signal, a
        requested message with no frame.

    Examples
    --------
    >>> import numpy as np, cantools
    >>> db = cantools.database.load_string('''VERSION ""
    ... BO_ 180 SPEED: 8 XXX
    ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
    ... ''', database_format="dbc")
    >>> s = frames_to_signals(np.array([0.0, 0.1, 0.2]), np.array([180, 180, 180]),
    ...                       [bytes([0, 0, 0, 0, 0, 0x03, 0xE8, 0])] * 3, db, ["SPEED.SPEED"], rate=10)
    >>> s["SPEED.SPEED"].tolist(), s.units
    ([[10.0, 10.0, 10.0]], ['km/h'])
    """
    signals = _check_signal_list(signals)
    _, resolved = _load_resolved(dbc, signals)
    ts = np.asarray(ts, float)
    ids = np.asarray(ids, np.int64)
    if ts.size == 0:
        raise DataError(f"{where} holds no CAN frames")
    if ts.shape != ids.shape or len(data) != ts.size:
        raise DataError(f"{where}: {ts.size} time stamps, {ids.size} ids and {len(data)} payloads")
    payloads = FramePayloads.from_bytes(data)
    _check_frame_times(ts, where, lines)
    t0, t_end = float(ts[0]), float(ts[-1])
    chan = None
    if channels is not None:
        chan = np.asarray([str(c) for c in channels])
        if chan.size != ts.size:
            raise DataError(f"{where}: {chan.size} channels for {ts.size} frames")
    if channel is not None:
        if chan is None:
            raise DataError(f"{where} does not record the bus of its frames; channel= cannot be used")
        keep = chan == str(channel)
        if not keep.any():
            raise DataError(f"{where} has no frame on channel {str(channel)!r}; its channels are "
                            f"{sorted(set(chan.tolist()))}")
        ts, ids, chan = ts[keep], ids[keep], chan[keep]
        payloads = payloads.take(keep)
        lines = None if lines is None else np.asarray(lines)[keep]

    def select(fid: int, msg) -> np.ndarray:
        idx = np.flatnonzero(ids == fid)
        if idx.size and chan is not None and channel is None and np.unique(chan[idx]).size > 1:
            raise DataError(f"{where}: message {msg.name!r} (id 0x{fid:x}) is on several buses "
                            f"{sorted(set(chan[idx].tolist()))}; pass channel= to choose one")
        return idx

    return _decode_to_grid(resolved, signals, select, ts.__getitem__, payloads.take, t0, t_end, rate,
                           units=units, max_gap=max_gap, method=method, span=span, stuck_after=stuck_after,
                           source=source, where=where)


def _check_frame_times(ts: np.ndarray, where: str, lines: np.ndarray | None = None) -> None:
    """Frame times must be finite and never go back (the error names the frame and line)."""

    def _at(k: int) -> str:
        return f"frame {k}" + (f" (line {int(lines[k])})" if lines is not None else "")

    if not np.isfinite(ts).all():
        bad = np.flatnonzero(~np.isfinite(ts))
        raise DataError(f"{where}: {_at(int(bad[0]))} has a non-finite time stamp")
    if np.any(ts[1:] < ts[:-1]):  # finite times: the same test as np.diff(ts) < 0
        k = int(np.flatnonzero(np.diff(ts) < 0)[0]) + 1
        raise DataError(f"{where}: time goes backwards at {_at(k)}: {float(ts[k - 1])!r} s then "
                        f"{float(ts[k])!r} s "
                        "(shuffled or corrupt log)")


def _decode_to_grid(resolved, signals: list[str], select, times, payloads, t0: float, t_end: float,
                    rate, *, source, where, **kw) -> LoadedSignals:
    """Decode the requested signals per message and put them on the grid (:func:`frames_to_signals`
    after its checks). ``select(frame_id, msg)`` gives the indices of a message's frames,
    ``times(idx)`` their absolute times and ``payloads(idx)`` their :class:`FramePayloads`."""
    by_msg: dict[int, list[tuple[str, Any, Any]]] = {}
    for full, msg, sig in resolved:
        by_msg.setdefault(msg.frame_id, []).append((full, msg, sig))
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    src_units: dict[str, str] = {}
    counts: dict[str, dict[str, int]] = {}
    for fid, wanted in by_msg.items():
        msg = wanted[0][1]
        idx = select(fid, msg)
        if idx.size == 0:
            raise DataError(f"{where} has no frame of message {msg.name!r} (id 0x{fid:x}) needed for "
                            f"{[w[0] for w in wanted]}")
        snames = [w[2].name for w in wanted]
        # all frames of this message at once (numpy bit extraction; multiplexed messages per frame)
        cols, n_bad = decode_message(msg, snames, payloads(idx))
        tm = times(idx) - t0
        for c, (full, _msg, sig) in enumerate(wanted):
            series[full] = (tm, cols[:, c])
            src_units[full] = sig.unit or ""
            counts[full] = {"n_undecodable": int(n_bad[c])}
    series = {s: series[s] for s in signals}
    return series_to_grid(series, src_units, rate, log_span=(0.0, t_end - t0), counts=counts, source=source,
                          where=where, t0=t0, time_origin=origin_of_float(t0), **kw)


def _blf_to_signals(frames, dbc, signals, rate=None, *, units=None, max_gap: float = 3.0,
                    method: str = "linear", span: str = "common", stuck_after: float = 2.0,
                    source: SourceReport | None = None, where: str = "CAN log") -> LoadedSignals:
    """:func:`frames_to_signals` on a :class:`fdikit.io.decode.BlfFrames` (a BLF read on demand):
    the same checks, errors and numbers, with times and payloads read only for the frames of
    the requested messages."""
    signals = _check_signal_list(signals)
    _, resolved = _load_resolved(dbc, signals)
    if not frames.times_ordered():  # the ticks cannot tell: check the times themselves
        _check_frame_times(frames.times(), where)
    first_last = frames.times(np.array([0, frames.n_frames - 1]))
    t0, t_end = float(first_last[0]), float(first_last[1])

    def select(fid: int, msg) -> np.ndarray:
        return frames.select(fid)

    return _decode_to_grid(resolved, signals, select, frames.times, frames.payloads, t0, t_end, rate,
                           units=units, max_gap=max_gap, method=method, span=span, stuck_after=stuck_after,
                           source=source, where=where)


# ---------------------------------------------------------------------------------- frame readers
def _check_file(path, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{what} {str(p)!r} does not exist")
    if p.is_dir():
        raise DataError(f"{what} {str(p)!r} is a directory, not a file")
    if p.stat().st_size == 0:
        raise DataError(f"{what} {str(p)!r} is empty (0 bytes)")
    return p


class _Lines:
    """A text file as an iterator of lines that remembers the current line number."""

    def __init__(self, path: Path, encoding: str = "utf-8"):
        self._f = open(path, encoding=encoding, errors="strict", newline=None)
        self.lineno = 0
        self.line = ""
        self.history: list[tuple[int, str]] = []

    def __iter__(self) -> Iterator[str]:
        return self

    def __next__(self) -> str:
        line = next(self._f)
        self.lineno += 1
        self.line = line
        self.history.append((self.lineno, line))
        return line

    def close(self) -> None:
        self._f.close()

    @property
    def closed(self) -> bool:
        return self._f.closed


#: ASC lines that python-can skips on purpose and that carry no CAN data frame.
_ASC_BENIGN = re.compile(
    r"^\s*$|^//|^date\s|^base\s|^(no\s+)?internal\s+events\s+logged|^begin\s+triggerblock|"
    r"^end\s+triggerblock|^\d+\.\d+\s+(start\s+of\s+measurement|log\s+trigger|sv:|"
    r"\d+\s+statistic:|can\s+\d+\s+status:|j1939tp)",
    re.IGNORECASE,
)


def _read_text_frames(path, fmt: str, *, strict: bool = True, encoding: str = "utf-8"):
    """Frames of an ASC or candump file via python-can, with line accounting."""
    import can

    what = {"asc": "ASC log", "candump": "candump log"}[fmt]
    p = _check_file(path, what)
    try:
        lines = _Lines(p, encoding)
    except LookupError:
        raise DataError(f"unknown text encoding {encoding!r}") from None
    reader_cls = can.ASCReader if fmt == "asc" else can.CanutilsLogReader
    ts: list[float] = []
    ids: list[int] = []
    data: list[bytes] = []
    where: list[int] = []
    chans: list[str] = []
    skipped: list[tuple[int, str]] = []
    seen_end = False

    def account(upto: int) -> None:
        """Lines read since the last frame (all but the one that made it, if ``upto``)."""
        nonlocal seen_end
        hist = lines.history[:-1] if upto else lines.history
        for no, text in hist:
            s = text.strip()
            if fmt == "asc" and re.match(r"^end\s+triggerblock", s, re.IGNORECASE):
                seen_end = True
            if not s or (fmt == "asc" and _ASC_BENIGN.match(s)):
                continue
            if strict:
                raise DataError(f"{what} {p.name!r} line {no} is neither a CAN frame nor a known "
                                f"{fmt.upper()} event: {s[:80]!r} (corrupt line; strict=False skips it)")
            skipped.append((no, s[:200]))
        lines.history.clear()

    try:
        reader = reader_cls(lines)
        for msg in reader:
            account(upto=1)
            if fmt == "asc" and re.match(r"^end\s+triggerblock", lines.line.strip(), re.IGNORECASE):
                seen_end = True
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            ts.append(float(msg.timestamp))
            ids.append(int(msg.arbitration_id))
            data.append(bytes(msg.data or b""))
            where.append(lines.lineno)
            # the bus as the file writes it (python-can numbers ASC channels from 0; the file from 1)
            ch = msg.channel
            chans.append(str(ch + 1) if fmt == "asc" and isinstance(ch, int) else str(ch))
        account(upto=0)
    except DataError:
        lines.close()
        raise
    except UnicodeDecodeError:
        lines.close()
        raw = p.read_bytes()
        try:
            raw.decode(encoding)
            pos, reason = -1, "?"
        except UnicodeDecodeError as exc:
            pos, reason = exc.start, exc.reason
        line_no = raw.count(b"\n", 0, pos) + 1
        raise DataError(f"{what} {p.name!r} is not {encoding} text: undecodable byte {raw[pos:pos + 1]!r} "
                        f"at offset {pos}, line {line_no} ({reason}; a Windows-written ASC may need "
                        "encoding='cp1252')") from None
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, AttributeError) as exc:
        lines.close()
        raise DataError(f"{what} {p.name!r} line {lines.lineno} cannot be parsed "
                        f"({type(exc).__name__}: {exc}): {lines.line.strip()[:80]!r}") from None
    lines.close()
    if fmt == "asc" and strict and not seen_end:
        raise DataError(f"ASC log {p.name!r} is truncated: it does not end with 'End TriggerBlock' "
                        f"(last line {lines.lineno}: {lines.line.strip()[:80]!r}; strict=False reads it)")
    if not ts:
        raise DataError(f"{what} {p.name!r} holds no CAN data frames ({lines.lineno} lines)")
    src = SourceReport(fmt, str(p), len(ts), tuple(skipped))
    return np.asarray(ts, float), np.asarray(ids, np.int64), data, np.asarray(where), chans, src


def read_asc(path, dbc, signals, rate=None, *, strict: bool = True, encoding: str = "utf-8",
             **kw) -> LoadedSignals:
    """Read a Vector ASC log (python-can ``ASCReader``) decoded with a DBC onto one grid.

    Parameters
    ----------
    path : path-like
    dbc : path-like or cantools Database
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names.
    rate : float, optional
        Grid rate (Hz).
    strict : bool
        Refuse a line that is neither a frame nor a known ASC event, and a file without its
        closing ``End TriggerBlock`` (truncated); with ``False`` such lines are skipped and
        listed in ``result.source.skipped``.
    encoding : str
        Text encoding of the file (Vector tools on Windows may write ``"cp1252"``).
    **kw
        ``channel`` (the bus as the file numbers it, ``1``, ``2``, ...; needed when a requested
        message is on several buses), ``units``, ``max_gap``, ``method``, ``span``,
        ``stuck_after`` (see :func:`series_to_grid`).

    Returns
    -------
    LoadedSignals
        Same grid as :func:`fdikit.io.read_can_log` on the same frames (timestamps to 1 us).

    Examples
    --------
    >>> s = read_asc("drive.asc", "toyota_rav4.dbc", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    """
    ts, ids, data, lines, chans, src = _read_text_frames(path, "asc", strict=strict, encoding=encoding)
    return frames_to_signals(ts, ids, data, dbc, signals, rate, lines=lines, channels=chans, source=src,
                             where=f"ASC log {Path(path).name!r}", **kw)


def read_candump(path, dbc, signals, rate=None, **kw) -> LoadedSignals:
    r"""Read a candump ``-L`` log (python-can ``CanutilsLogReader``) decoded with a DBC onto one grid.

    Parameters
    ----------
    path : path-like
        Lines like ``(1.000000) can0 0B4#0000000000000000``.
    dbc, signals, rate, **kw
        As in :func:`read_asc` (``channel`` is the interface name, e.g. ``"can0"``).

    Returns
    -------
    LoadedSignals

    Examples
    --------
    >>> import pathlib, tempfile, cantools
    >>> db = cantools.database.load_string('VERSION ""\nBO_ 180 SPEED: 8 XXX\n'
    ...     ' SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX\n', database_format="dbc")
    >>> log = pathlib.Path(tempfile.mkdtemp()) / "drive.log"
    >>> _ = log.write_text("(100.000000) can0 0B4#000000000003E800 R\n"    # 10.00 km/h
    ...                    "(100.100000) can0 0B4#000000000007D000 R\n")   # 20.00 km/h
    >>> s = read_candump(log, db, ["SPEED.SPEED"], rate=20)
    >>> s.t.tolist(), s["SPEED.SPEED"].round(6).tolist(), s.source.n_records
    ([0.0, 0.05, 0.1], [[10.0, 15.0, 20.0]], 2)
    """
    ts, ids, data, lines, chans, src = _read_text_frames(path, "candump", strict=True)
    return frames_to_signals(ts, ids, data, dbc, signals, rate, lines=lines, channels=chans, source=src,
                             where=f"candump log {Path(path).name!r}", **kw)


def read_blf(path, dbc, signals, rate=None, **kw) -> LoadedSignals:
    """Read a Vector BLF log with the bad-input policy of this module.

    The frames come from the BLF reader of :func:`fdikit.io.read_can_log` (header size and
    object count checked, so truncation is an error); any other failure of the decompressor
    (a corrupt zlib container) is a :class:`~fdikit.errors.DataError` too. A file of the usual
    layout is read on demand (:func:`fdikit.io.decode.read_blf_frames`: times and payloads of
    the requested messages only), with the same checks, errors and numbers as
    :func:`frames_to_signals` on the whole frame table.

    Examples
    --------
    >>> s = read_blf("drive.blf", "toyota_rav4.dbc", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    """
    p = _check_file(path, "BLF file")
    frames = None
    try:
        if set(kw) <= set(_COMMON_OPTIONS):  # the usual layout is read on demand
            frames = _read_blf_frames(p)
        if frames is None:
            ts, ids, data = _read_frame_table(p)
    except DataError:
        raise
    except Exception as exc:  # zlib.error and friends from a corrupt container
        raise DataError(f"BLF file {p.name!r} is corrupt ({type(exc).__name__}: {exc})") from None
    where = f"BLF file {p.name!r}"
    if frames is not None:
        src = SourceReport("blf", str(p), frames.n_frames)
        return _blf_to_signals(frames, dbc, signals, rate, source=src, where=where, **kw)
    src = SourceReport("blf", str(p), int(ts.size))
    return frames_to_signals(ts, ids, data, dbc, signals, rate, source=src, where=where, **kw)


# ---------------------------------------------------------------------------------- decoded tables
_TIME_NAMES = ("t", "time", "timestamp", "timestamps", "t_s", "time_s")


def _pick_time(columns: Sequence[str], time: str | None, where: str) -> str:
    if time is not None:
        if time not in columns:
            raise DataError(f"{where} has no time column {time!r}; columns: {list(columns)}")
        return time
    for c in _TIME_NAMES:
        if c in columns:
            return c
    raise DataError(f"{where} has no time column (looked for {list(_TIME_NAMES)}; pass time=); "
                    f"columns: {list(columns)}")


def _pick_columns(columns: Sequence[str], time_col: str, signals, where: str) -> list[str]:
    if signals is None:
        cols = [c for c in columns if c != time_col]
        if not cols:
            raise DataError(f"{where} has no channel besides the time column {time_col!r}")
        return cols
    signals = _check_signal_list(signals)
    for s in signals:
        if s not in columns:
            close = difflib.get_close_matches(s, list(columns), n=3)
            raise DataError(f"{where} has no channel {s!r}" + (f"; did you mean {close}?" if close else "")
                            + f"; channels: {[c for c in columns if c != time_col][:30]}")
    return signals


def _check_table_time(t: np.ndarray, where: str, time_col: str, present: np.ndarray | None = None,
                      line_offset: int | None = None):
    """Time of a table: present, finite, non-decreasing. Rows count from 0 (data rows);
    ``line_offset`` adds the text line number (CSV: row + 2)."""

    def at(k: int) -> str:
        return f"row {k}" + (f" (line {k + line_offset})" if line_offset is not None else "")

    if present is not None and not present.all():
        k = int(np.flatnonzero(~present)[0])
        raise DataError(f"{where}: time column {time_col!r} is empty at {at(k)}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(f"{where}: time column {time_col!r} is not finite at {at(int(bad[0]))} "
                        f"({float(t[bad[0]])})")
    d = np.diff(t)
    nb = np.flatnonzero(d < 0)
    if nb.size:  # repeated times are allowed (rows of different messages); per channel they merge
        k = int(nb[0]) + 1
        raise DataError(f"{where}: time column {time_col!r} goes backwards at {at(k)} "
                        f"({float(t[k - 1])!r} then {float(t[k])!r}); it must be non-decreasing")


def _table_to_grid(t, cols, present, values, units_src, rate, kw, src, where, origin=None):
    series = {}
    for j, c in enumerate(cols):
        m = present[:, j]
        series[c] = (t[m], values[:, j][m])
    rebased = origin is not None and origin.rebased
    return series_to_grid(series, units_src, rate, source=src, where=where,
                          t0=origin.seconds if rebased else 0.0, time_origin=origin if rebased else None,
                          **kw)


def read_parquet(path, signals=None, rate=None, *, time: str | None = None,
                 source_units: Mapping[str, str] | None = None, time_unit: str = "auto",
                 rebase: bool | None = None, **kw) -> LoadedSignals:
    """Read a Parquet table of decoded signals onto one grid.

    The table has one time column (seconds as a number, or a timestamp type, counted from the
    first row) and one numeric column per channel. A *null* cell means "no sample of this channel
    at this time" (a sparse table merging messages of different rates); a NaN or inf *value*
    is a bad sample and is flagged. Units come from each field's metadata key ``unit`` (as
    written by ``pyarrow`` with ``field.with_metadata({"unit": ...})``) or ``source_units``.
    Page checksums are verified when the file has them.

    Parameters
    ----------
    path : path-like
    signals : sequence of str, optional
        Columns to read (default all but time).
    rate : float, optional
        Grid rate (Hz).
    time : str, optional
        Time column; default the first of ``t, time, timestamp, timestamps, t_s, time_s``.
    source_units : mapping, optional
        Unit per column, overriding the file's metadata.
    time_unit : {"auto", "s", "ms", "us", "ns"}
        Unit of a numeric time column (``"auto"``: seconds, unless the first timestamp is an
        absolute clock in ms, us or ns; see :mod:`fdikit.io.timebase`). A timestamp-typed column
        is always counted from its first row.
    rebase : bool, optional
        Make time start at 0; default when the time axis is absolute (first timestamp at least
        10^6 s). Integer time stamps are rebased exactly; the origin is kept in ``t0`` and
        ``time_origin``.
    **kw
        ``units``, ``max_gap``, ``method``, ``span``, ``stuck_after`` (see :func:`series_to_grid`).

    Returns
    -------
    LoadedSignals

    Examples
    --------
    >>> s = read_parquet("decoded.parquet", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    p = _check_file(path, "Parquet file")
    where = f"Parquet file {p.name!r}"
    try:
        table = pq.read_table(p, page_checksum_verification=True)
    except Exception as exc:  # ArrowInvalid, OSError, ... for a truncated or corrupt file
        raise DataError(f"{where} is not a readable Parquet file (truncated or corrupt?): "
                        f"{type(exc).__name__}: {exc}") from None
    names = list(table.column_names)
    time_col = _pick_time(names, time, where)
    cols = _pick_columns(names, time_col, signals, where)
    tcol = table.column(time_col)
    origin = None
    try:
        if pa.types.is_timestamp(tcol.type) or pa.types.is_date(tcol.type):
            t_present = ~np.asarray(tcol.is_null().to_numpy(zero_copy_only=False), bool)
            tn = tcol.cast(pa.timestamp("ns")).fill_null(0).cast(pa.int64()).to_numpy(zero_copy_only=False)
            t = np.full(tn.size, np.nan)
            if tn.size and t_present.any():
                t[t_present], origin = times_to_seconds(tn[t_present], "ns", rebase=True, where=where,
                                                        column=time_col, rows=np.flatnonzero(t_present))
        elif pa.types.is_integer(tcol.type) or pa.types.is_floating(tcol.type):
            t_present = ~np.asarray(tcol.is_null().to_numpy(zero_copy_only=False), bool)
            if pa.types.is_integer(tcol.type):
                raw = np.asarray(tcol.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False), np.int64)
            else:
                raw = np.asarray(tcol.cast(pa.float64()).to_numpy(zero_copy_only=False), float)
            t = np.full(raw.size, np.nan)
            if raw.size and t_present.all():
                t, origin = times_to_seconds(raw, time_unit, rebase=rebase, where=where, column=time_col)
            elif raw.size:
                t[t_present] = raw[t_present]  # _check_table_time names the empty row
        else:
            raise DataError(f"{where}: time column {time_col!r} has type {tcol.type}, "
                            "not a number or timestamp")
    except (pa.ArrowException, OverflowError) as exc:
        raise DataError(f"{where}: time column {time_col!r} cannot be read: {exc}") from None
    if t.size == 0:
        raise DataError(f"{where} has no rows")
    _check_table_time(t, where, time_col, t_present)
    values = np.empty((t.size, len(cols)))
    present = np.empty((t.size, len(cols)), bool)
    units_src = {}
    for j, c in enumerate(cols):
        col = table.column(c)
        if not (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)
                or pa.types.is_boolean(col.type)):
            raise DataError(f"{where}: column {c!r} has type {col.type}, not numeric")
        present[:, j] = ~np.asarray(col.is_null().to_numpy(zero_copy_only=False), bool)
        values[:, j] = np.asarray(col.cast(pa.float64()).to_numpy(zero_copy_only=False), float)
        meta = table.schema.field(c).metadata or {}
        units_src[c] = (meta.get(b"unit") or meta.get(b"units") or b"").decode("utf-8", "replace")
    for k, u in (source_units or {}).items():
        if k not in names:
            raise DataError(f"source unit given for {k!r}, which is not a column of the file")
        if k in cols:
            units_src[k] = u
    src = SourceReport("parquet", str(p), int(t.size))
    return _table_to_grid(t, cols, present, values, units_src, rate, kw, src, where, origin)


def read_table_csv(path, signals=None, rate=None, *, time: str | None = None,
                   source_units: Mapping[str, str] | None = None, time_unit: str = "auto",
                   rebase: bool | None = None, **kw) -> LoadedSignals:
    r"""Read a CSV table of decoded signals onto one grid, with the Parquet reader's conventions.

    An empty cell is "no sample here"; ``nan`` / ``inf`` text is a bad sample (flagged); any
    other non-numeric cell, or a row with the wrong number of fields (a truncated or corrupt
    line), is a :class:`~fdikit.errors.DataError` naming the line. For a plain recording on its
    own time stamps see :func:`fdikit.io.read_csv`.

    Parameters
    ----------
    path : path-like
    signals, rate, time, source_units, time_unit, rebase, **kw
        As in :func:`read_parquet`.

    Returns
    -------
    LoadedSignals

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "decoded.csv"
    >>> _ = p.write_text("t,speed,yaw\n0.0,36,\n0.05,,0.5\n0.1,nan,\n0.15,,0.7\n0.2,72,\n")
    >>> s = read_table_csv(p, rate=20, span="log", source_units={"speed": "km/h"},
    ...                    units={"speed": "m/s"})
    >>> s.valid[0].astype(int).T.tolist()   # speed: its nan spoils 0.05 .. 0.15; yaw: only 0.05 .. 0.15
    [[1, 0, 0, 0, 1], [0, 1, 1, 1, 0]]
    >>> s["yaw"][0, 1:4].round(6).tolist(), s.info["speed"].n_nonfinite
    ([0.5, 0.6, 0.7], 1)
    """
    p = _check_file(path, "CSV file")
    where = f"CSV file {p.name!r}"
    try:
        with open(p, encoding="utf-8", newline="") as fh:
            rows = list(_csv.reader(fh))
    except UnicodeDecodeError as exc:
        raise DataError(f"{where} is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except _csv.Error as exc:
        raise DataError(f"{where} cannot be parsed as CSV: {exc}") from None
    if not rows:
        raise DataError(f"{where} is empty")
    header = [h.strip() for h in rows[0]]
    if len(set(header)) != len(header):
        raise DataError(f"{where}: duplicated column names in the header {header}")
    body = rows[1:]
    while body and not any(x.strip() for x in body[-1]):
        body.pop()  # trailing blank lines
    if not body:
        raise DataError(f"{where} has a header but no rows")
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise DataError(f"{where} line {i + 2} has {len(r)} fields, the header has {len(header)} "
                            f"(truncated or corrupt line): {','.join(r)[:80]!r}")
    time_col = _pick_time(header, time, where)
    cols = _pick_columns(header, time_col, signals, where)
    arr = np.array(body, dtype=object)

    def parse(j: int, name: str) -> tuple[np.ndarray, np.ndarray]:
        raw = [x.strip() for x in arr[:, j]]
        pres = np.array([x != "" for x in raw])
        out = np.full(len(raw), np.nan)
        for i, x in enumerate(raw):
            if x:
                try:
                    out[i] = float(x)
                except ValueError:
                    raise DataError(f"{where} line {i + 2}, column {name!r}: {x[:40]!r} "
                                    "is not a number") from None
        return out, pres

    traw = [x.strip() for x in arr[:, header.index(time_col)]]
    tp = np.array([x != "" for x in traw])
    _check_table_time(np.zeros(tp.size), where, time_col, tp, line_offset=2)
    t, origin = times_to_seconds(traw, time_unit, rebase=rebase, where=where, column=time_col,
                                 line_offset=2)
    _check_table_time(t, where, time_col, tp, line_offset=2)
    values = np.empty((t.size, len(cols)))
    present = np.empty((t.size, len(cols)), bool)
    for j, c in enumerate(cols):
        values[:, j], present[:, j] = parse(header.index(c), c)
    units_src = {c: "" for c in cols}
    for k, u in (source_units or {}).items():
        if k not in header:
            raise DataError(f"source unit given for {k!r}, which is not a column of the file")
        if k in cols:
            units_src[k] = u
    src = SourceReport("csv", str(p), int(t.size))
    return _table_to_grid(t, cols, present, values, units_src, rate, kw, src, where, origin)


# ---------------------------------------------------------------------------------- MDF4
def _open_mdf(p: Path, where: str):
    import logging

    from asammdf import MDF

    class _Collect(logging.Handler):
        def __init__(self):
            super().__init__(logging.WARNING)
            self.records: list[str] = []

        def emit(self, record):
            self.records.append(record.getMessage())

    h = _Collect()
    log = logging.getLogger("asammdf")
    log.addHandler(h)
    try:
        mdf = MDF(str(p))
        # touch every group's record layout now, so that a corrupt block fails here
        for i, g in enumerate(mdf.groups):
            _ = g.channel_group.cycles_nr, [c.name for c in g.channels], i
    except Exception as exc:  # asammdf raises many types for a corrupt or truncated file
        raise DataError(f"{where} is not a readable MDF file (truncated or corrupt?): "
                        f"{type(exc).__name__}: {str(exc)[:200]}") from None
    finally:
        log.removeHandler(h)
    if h.records:
        mdf.close()
        raise DataError(f"{where} is damaged: asammdf reported {h.records[0][:200]!r}")
    return mdf


def _mdf_get(mdf, name: str, where: str, group=None, index=None):
    import logging

    try:
        prev = logging.getLogger("asammdf").level
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            sig = mdf.get(name, group, index, raw=False, ignore_invalidation_bits=True)
        finally:
            logging.getLogger("asammdf").setLevel(prev)
    except Exception as exc:
        raise DataError(f"{where}: channel {name!r} cannot be read (corrupt file?): "
                        f"{type(exc).__name__}: {str(exc)[:200]}") from None
    s = np.asarray(sig.samples)
    if s.dtype.names or s.ndim != 1 or s.dtype.kind not in "biuf":
        raise DataError(f"{where}: channel {name!r} is not a numeric signal "
                        f"(dtype {s.dtype}, shape {s.shape})")
    v = s.astype(float)
    t = np.asarray(sig.timestamps, float)
    if t.shape != v.shape:
        raise DataError(f"{where}: channel {name!r} has {t.size} time stamps for {v.size} samples")
    if sig.invalidation_bits is not None:
        inval = np.asarray(sig.invalidation_bits, bool)
        if inval.shape == v.shape:
            v = np.where(inval, np.nan, v)  # invalid in the file: a bad sample
    unit = sig.unit or ""
    return t, v, unit


def _mdf_raw_can_groups(mdf) -> list[int]:
    from asammdf.blocks import v4_constants as v4c

    out = []
    for i, g in enumerate(mdf.groups):
        flags = getattr(g.channel_group, "flags", 0)
        if flags & v4c.FLAG_CG_BUS_EVENT and any(c.name == "CAN_DataFrame" for c in g.channels):
            out.append(i)
    return out


def read_mdf(path, signals=None, rate=None, *, dbc=None, channel: int | None = None, **kw) -> LoadedSignals:
    """Read an MDF4 file: decoded signal channels, or raw CAN frames decoded with a DBC.

    * With ``dbc`` and bus-logging groups (``CAN_DataFrame`` channels) in the file, the frames
      are decoded by asammdf's ``extract_bus_logging`` and time 0 is the first frame.
    * Otherwise each requested name must be one channel of the file (its name or a display
      name such as ``"MESSAGE.SIGNAL"``), on the file's own time axis; invalidation bits become
      bad (flagged) samples.

    Parameters
    ----------
    path : path-like
    signals : sequence of str
        Channel names (``"MESSAGE.SIGNAL"`` for bus logging).
    rate : float, optional
        Grid rate (Hz).
    dbc : path-like or cantools Database, optional
        Needed for raw CAN frames.
    channel : int, optional
        Bus (``CAN_DataFrame.BusChannel``) to decode, when a message is on several buses.
    **kw
        ``units``, ``max_gap``, ``method``, ``span``, ``stuck_after`` (see :func:`series_to_grid`).

    Returns
    -------
    LoadedSignals

    Examples
    --------
    >>> s = read_mdf("bus.mf4", ["SPEED.SPEED"], rate=50, dbc="toyota_rav4.dbc")  # doctest: +SKIP
    """
    p = _check_file(path, "MDF file")
    where = f"MDF file {p.name!r}"
    signals = _check_signal_list(signals)
    mdf = _open_mdf(p, where)
    try:
        raw_groups = _mdf_raw_can_groups(mdf)
        if dbc is not None and raw_groups:
            return _read_mdf_bus(mdf, p, where, raw_groups, dbc, signals, rate, kw, channel)
        if channel is not None:
            hint = "pass dbc= to decode them" if raw_groups else "this file holds decoded channels"
            raise DataError(f"{where}: channel= selects a bus of raw CAN frames; {hint}")
        if raw_groups and not any(s in mdf.channels_db for s in signals):
            raise DataError(f"{where} holds raw CAN frames (bus logging); pass dbc= to decode {signals}")
        series, units_src = {}, {}
        n_rec = 0
        for s in signals:
            if s not in mdf.channels_db:
                close = difflib.get_close_matches(s, list(mdf.channels_db), n=3)
                raise DataError(f"{where} has no channel {s!r}"
                                + (f"; did you mean {close}?" if close else ""))
            occ = mdf.channels_db[s]
            if len(occ) > 1:
                raise DataError(f"{where}: channel name {s!r} is ambiguous, it occurs in groups "
                                f"{sorted({g for g, _ in occ})}")
            g, i = occ[0]
            t, v, unit = _mdf_get(mdf, s, where, g, i)
            series[s] = (t, v)
            units_src[s] = unit
            n_rec += t.size
        src = SourceReport("mdf", str(p), n_rec)
        return series_to_grid(series, units_src, rate, source=src, where=where, **kw)
    finally:
        mdf.close()


def _read_mdf_bus(mdf, p, where, raw_groups, dbc, signals, rate, kw, channel=None) -> LoadedSignals:
    import logging

    db = _load_dbc(dbc)
    resolved = _resolve(db, signals)  # clear errors (and close matches) before the extraction
    t_first, t_last, n_frames = np.inf, -np.inf, 0
    f_t, f_id, f_len, f_bus = [], [], [], []
    for g in raw_groups:
        try:
            tm = np.asarray(mdf.get_master(g), float)
            fid = np.asarray(_mdf_get(mdf, "CAN_DataFrame.ID", where, g)[1], np.int64) & 0x1FFFFFFF
            fbus = np.asarray(_mdf_get(mdf, "CAN_DataFrame.BusChannel", where, g)[1], np.int64)
            names = [c.name for c in mdf.groups[g].channels]
            if "CAN_DataFrame.DataLength" in names:
                flen = np.asarray(_mdf_get(mdf, "CAN_DataFrame.DataLength", where, g)[1], np.int64)
            else:
                flen = np.asarray(_mdf_get(mdf, "CAN_DataFrame.DLC", where, g)[1], np.int64)
                fd = np.array([12, 16, 20, 24, 32, 48, 64])
                flen = np.where(flen <= 8, flen, fd[np.clip(flen - 9, 0, 6)])
        except DataError:
            raise
        except Exception as exc:
            raise DataError(f"{where}: the frames of CAN group {g} cannot be read: "
                            f"{type(exc).__name__}: {exc}") from None
        if not (tm.size == fid.size == flen.size == fbus.size):
            raise DataError(f"{where}: CAN group {g} has {tm.size} time stamps, {fid.size} ids and "
                            f"{flen.size} lengths")
        f_t.append(tm)
        f_id.append(fid)
        f_len.append(flen)
        f_bus.append(fbus)
        if tm.size:
            if not np.isfinite(tm).all():
                raise DataError(f"{where}: CAN group {g} has a non-finite time stamp at frame "
                                f"{int(np.flatnonzero(~np.isfinite(tm))[0])}")
            back = np.flatnonzero(np.diff(tm) < 0)
            if back.size:
                k = int(back[0]) + 1
                raise DataError(f"{where}: time of CAN group {g} goes backwards at frame {k} "
                                f"({float(tm[k - 1])!r} s then {float(tm[k])!r} s)")
            t_first, t_last = min(t_first, tm[0]), max(t_last, tm[-1])
            n_frames += tm.size
    if n_frames == 0:
        raise DataError(f"{where} holds no CAN frames")
    with tempfile.TemporaryDirectory() as tmp:
        if isinstance(dbc, str | os.PathLike):
            dbc_path = str(dbc)
        else:
            dbc_path = os.path.join(tmp, "db.dbc")
            Path(dbc_path).write_text(db.as_dbc_string())
        prev = logging.getLogger("asammdf").level
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            out = mdf.extract_bus_logging({"CAN": [(dbc_path, int(channel or 0))]})
        except Exception as exc:
            raise DataError(f"{where}: the CAN frames cannot be decoded with {Path(dbc_path).name!r}: "
                            f"{type(exc).__name__}: {str(exc)[:200]}") from None
        finally:
            logging.getLogger("asammdf").setLevel(prev)
    try:
        series, units_src = {}, {}
        for s in signals:
            if s not in out.channels_db:
                raise DataError(f"{where} has no frame of message {s.split('.')[0]!r} needed for {s!r} "
                                "(or none that the DBC decodes)")
            if len(out.channels_db[s]) > 1:
                raise DataError(f"{where}: {s!r} is on more than one CAN bus; pass channel= to choose one")
            g, i = out.channels_db[s][0]
            t, v, unit = _mdf_get(out, s, where, g, i)
            series[s] = (t - t_first, v)
            units_src[s] = unit
    finally:
        out.close()
    # asammdf decodes the 8 stored data bytes whatever DataLength says, and skips frames silently
    # if it must: check it decoded every frame of the message, and make a frame too short for
    # the signal a bad sample (as frames_to_signals does)
    f_t, f_id, f_len = np.concatenate(f_t), np.concatenate(f_id), np.concatenate(f_len)
    if channel:
        on_bus = np.concatenate(f_bus) == int(channel)
        f_t, f_id, f_len = f_t[on_bus], f_id[on_bus], f_len[on_bus]
    counts = {}
    for full, msg, sig in resolved:
        m = f_id == msg.frame_id
        t, v = series[full]
        if m.sum() != t.size or not np.array_equal(f_t[m] - t_first, t):
            raise DataError(f"{where}: asammdf decoded {t.size} frames of message {msg.name!r} "
                            f"(id 0x{msg.frame_id:x}) but the file holds {int(m.sum())}")
        short = f_len[m] < _bytes_needed(msg, sig.name)
        if short.any():
            v = v.copy()
            v[short] = np.nan
            series[full] = (t, v)
        counts[full] = {"n_undecodable": int(short.sum())}
    src = SourceReport("mdf", str(p), int(n_frames))
    return series_to_grid(series, units_src, rate, source=src, where=where, counts=counts,
                          log_span=(0.0, float(t_last - t_first)), **kw)


def _bytes_needed(msg, signal: str) -> int:
    """Fewest payload bytes from which cantools decodes ``signal`` of ``msg``."""
    for n in range(0, max(msg.length, 1) + 1):
        try:
            if signal in msg.decode(bytes(n), decode_choices=False, allow_truncated=True):
                return n
        except Exception:  # a payload this short cannot be decoded at all
            continue
    return msg.length


# ---------------------------------------------------------------------------------- dispatcher
_CANDUMP_LINE = re.compile(r"^\(\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]+#")


def detect_format(path) -> str:
    """The format of a log file, by suffix, else by its first bytes.

    Returns
    -------
    str
        A key of :data:`FORMATS`.

    Raises
    ------
    DataError
        Missing file, or neither the suffix nor the content is a known format.

    Examples
    --------
    >>> detect_format("drive.blf")  # doctest: +SKIP
    'blf'
    """
    p = _check_file(path, "log")
    suffix = p.suffix.lower()
    for fmt, sufs in FORMATS.items():
        if suffix in sufs:
            return fmt
    with open(p, "rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"LOGG"):
        return "blf"
    if head.startswith(b"PAR1"):
        return "parquet"
    if head.startswith(b"MDF "):
        return "mdf"
    text = head.decode("utf-8", "replace").lstrip()
    first = text.splitlines()[0] if text else ""
    if re.match(r"(date|base|begin\s+triggerblock)\s", first, re.IGNORECASE):
        return "asc"
    if _CANDUMP_LINE.match(first):
        return "candump"
    raise DataError(f"unknown log format for {p.name!r}: the suffix {suffix!r} is none of "
                    f"{sorted(s for v in FORMATS.values() for s in v)} and the first bytes "
                    f"{head[:16]!r} are not BLF, Parquet, MDF, ASC or candump")


_COMMON_OPTIONS = ("units", "max_gap", "method", "span", "stuck_after")
_FORMAT_OPTIONS = {"blf": (), "asc": ("strict", "encoding", "channel"), "candump": ("channel",),
                   "parquet": ("time", "source_units", "time_unit", "rebase"),
                   "csv": ("time", "source_units", "time_unit", "rebase"), "mdf": ("channel",)}


def read_log(path, dbc=None, signals=None, rate=None, *, format: str | None = None, **kw) -> LoadedSignals:
    """Read any supported log onto one grid: the one entry point of :mod:`fdikit.io`.

    Parameters
    ----------
    path : path-like
        A Vector BLF or ASC log, a candump log, a Parquet or CSV table of decoded signals, or
        an MDF4 file (decoded channels or raw CAN bus logging).
    dbc : path-like or cantools Database, optional
        Needed for frame logs (BLF, ASC, candump, raw CAN in MDF4).
    signals : sequence of str
        Channels: ``"MESSAGE.SIGNAL"`` for frame logs, column / channel names otherwise
        (default for tables: every column but time).
    rate : float, optional
        Grid rate (Hz); default the fastest median source rate.
    format : str, optional
        Force a format (a key of :data:`FORMATS`) instead of detecting it.
    **kw
        Passed to the reader: ``units``, ``max_gap``, ``method``, ``span``, ``stuck_after``;
        ``time``, ``source_units``, ``time_unit`` (``"auto"``, ``"s"``, ``"ms"``, ``"us"``,
        ``"ns"``) and ``rebase`` for tables (:mod:`fdikit.io.timebase`: an absolute time axis is
        rebased exactly to start at 0, its origin kept in ``t0`` and ``time_origin``; frame
        logs always start at their first frame, ``t0`` its time); ``strict`` and ``encoding`` for ASC;
        ``channel`` for ASC, candump and MDF4 bus logging. An option that does not apply to
        the detected format is a :class:`~fdikit.errors.DataError`.

    Returns
    -------
    LoadedSignals

    Raises
    ------
    DataError
        Unknown format (naming the suffix and first bytes), no DBC for a frame log, and every
        error of the chosen reader.

    Examples
    --------
    >>> from fdikit.io.formats import read_log
    >>> s = read_log("drive.asc", "toyota_rav4.dbc", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    >>> read_log("drive.vsb", "toyota_rav4.dbc", ["SPEED.SPEED"])
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: log 'drive.vsb' does not exist
    """
    if format is None:
        fmt = detect_format(path)
    else:
        if format not in FORMATS:
            raise DataError(f"unknown log format {format!r}; known formats: {sorted(FORMATS)}")
        fmt = format
    if fmt not in ("csv", "parquet"):
        # frame logs and MDF count seconds (python-can, asammdf) and start at their first frame
        unit = kw.pop("time_unit", "auto")
        if unit not in ("auto", "s"):
            raise DataError(f"{Path(path).name!r} is a {fmt} log, whose time stamps are seconds; "
                            f"time_unit={unit!r} applies to CSV and Parquet tables only")
        if kw.pop("rebase", None) is False:
            raise DataError(f"{Path(path).name!r} is a {fmt} log: its time always starts at its first "
                            "frame or sample (rebase=False applies to CSV and Parquet tables only)")
    allowed = set(_COMMON_OPTIONS) | set(_FORMAT_OPTIONS[fmt])
    unknown = sorted(set(kw) - allowed)
    if unknown:
        raise DataError(f"option(s) {unknown} do not apply to a {fmt} log {Path(path).name!r}; "
                        f"its options are {sorted(allowed)}")
    if fmt in _FRAME_FORMATS:
        if dbc is None:
            raise DataError(f"{Path(path).name!r} is a {fmt} CAN frame log: pass dbc= to decode it")
        reader = {"blf": read_blf, "asc": read_asc, "candump": read_candump}[fmt]
        return reader(path, dbc, signals, rate, **kw)
    if fmt == "parquet":
        return read_parquet(path, signals, rate, **kw)
    if fmt == "csv":
        return read_table_csv(path, signals, rate, **kw)
    return read_mdf(path, signals, rate, dbc=dbc, **kw)


def read_can_log(
    path: str | os.PathLike,
    dbc: Any,
    signals: Sequence[str],
    rate: float | None = None,
    *,
    units: str | Mapping[str, str] | None = None,
    max_gap: float = 3.0,
    method: str = "linear",
    span: str = "common",
) -> LogSignals:
    """Read a CAN log, decode the chosen signals with a DBC and put them on one time grid.

    Parameters
    ----------
    path : path-like
        The log (``.blf``, ``.asc``, ``.csv``, ``.trc``, ... as :class:`can.LogReader` knows).
    dbc : path-like or cantools Database
        The DBC (loaded with ``strict=False``: overlapping signals are allowed).
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names, e.g. ``["KINEMATICS.YAW_RATE", "SPEED.SPEED"]``.
    rate : float, optional
        Grid rate in Hz; default the highest median source rate among the chosen signals.
    units : "si" or mapping, optional
        Unit conversion: ``"si"`` converts every signal with a known SI target (km/h -> m/s,
        deg -> rad, deg/s -> rad/s, rpm -> rad/s, % -> 1); a mapping gives a target unit per
        signal name. Default: the DBC's units.
    max_gap : float
        Longest frame interval, in that signal's median source periods, that is interpolated
        across; longer gaps become NaN with ``valid == False`` (see the module docstring).
    method : {"linear", "previous"}
        Interpolation between neighbouring frames, or zero-order hold.
    span : {"common", "log"}
        Grid from the latest first frame to the earliest last frame of the chosen signals
        (default; no leading/trailing NaN), or over the whole log (channels are invalid outside
        their recorded span). Time 0 is the first frame of the log either way.

    Returns
    -------
    LogSignals
        One run, ``T`` samples at ``rate`` Hz, one channel per requested signal (named as
        requested), units from the DBC (or converted), ``valid`` mask and per-signal
        :class:`SignalInfo` in ``info``.

    Raises
    ------
    DataError
        Missing / not-a-log / truncated / corrupt file; a DBC without the requested message or
        signal (with close matches); a requested message with no frames in the log; an
        impossible unit conversion.

    Examples
    --------
    >>> from fdikit.io import read_can_log
    >>> s = read_can_log("drive.blf", "toyota_rav4.dbc",
    ...                  ["KINEMATICS.YAW_RATE", "SPEED.SPEED"], rate=50, units="si")  # doctest: +SKIP
    >>> s.units  # doctest: +SKIP
    ['rad/s', 'm/s']
    """
    # one frame-to-grid path for every log format: fdikit.io.formats (stricter bad-input policy:
    # short payloads are flagged, never zero-padded; conflicting duplicates are flagged; a
    # corrupt container is a DataError)
    return read_log(path, dbc, signals, rate, units=units, max_gap=max_gap, method=method, span=span)
