"""The second step of every loader: irregular per-signal series onto one uniform grid.

:func:`series_to_grid` checks each series' time axis, merges same-time samples, resamples
without bridging gaps and returns a :class:`LoadedSignals` with per-signal quality
(:class:`SignalQuality`), what was read (:class:`SourceReport`) and why each invalid grid sample
is invalid.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import DataError
from ..can import (
    _SI,
    HOLD_TOL,
    LogSignals,
    SignalInfo,
    _norm_unit,
    _resample_apply,
    _resample_plan,
    convert_units,
)
from ..timebase import TimeOrigin
from .raw_checks import implausible_samples

#: Largest grid a loader builds (samples); a larger one is a time column in the wrong unit.
MAX_GRID = 50_000_000
#: Keyword options of :func:`series_to_grid` that every reader passes on.
_COMMON_OPTIONS = ("units", "max_gap", "method", "span", "stuck_after")


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
    n_implausible : int
        Source samples refused by the signal's plausibility rule before resampling
        (:mod:`fdikit.io.formats.raw_checks`); every grid sample interpolated from one is
        flagged invalid with the rule's reason (not counted in ``n_nonfinite``).
    """

    n_nonfinite: int = 0
    n_undecodable: int = 0
    n_duplicates: int = 0
    n_conflicts: int = 0
    longest_constant: float = 0.0
    stuck: bool = False
    n_implausible: int = 0


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
    :meth:`invalid_reason`). ``breaks`` lists ``(t_before, t_after, reason)`` for every stretch
    cut from the grid (its time jumps from ``t_before`` to ``t_after``: a clock jump, a pause of
    the whole log, a clock step back that starts a new segment); ``n_segments`` counts the
    segments of clock steps back.
    """

    __slots__ = ("breaks", "reasons", "source")

    def __init__(self, t, values, names, units=None, *, valid=None, info=None, source=None, t0=0.0,
                 time_origin=None, reasons=None):
        super().__init__(t, values, names, units, valid=valid, info=info, t0=t0, time_origin=time_origin)
        self.source = source
        self.reasons: list[tuple[str, int, int, str]] = list(reasons or [])
        self.breaks: list[tuple[float, float, str]] = []

    @property
    def n_segments(self) -> int:
        """Segments of the log between clock steps back (1 when its clock never steps back)."""
        return 1 + sum("clock steps back" in why for _a, _b, why in self.breaks)

    def invalid_reason(self, k: int) -> str | None:
        """Why grid sample ``k`` is invalid (every channel's reason, joined), ``None`` when valid.

        Examples
        --------
        >>> import numpy as np
        >>> s = series_to_grid({"x": (np.r_[0.0, 0.1, 0.2, 1.0, 1.1], np.zeros(5))}, {}, rate=10.0)
        >>> s.invalid_reason(1) is None
        True
        >>> s.invalid_reason(6)  # held up to max_gap = 3 periods (0.5 s), then a gap
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
        out = LoadedSignals(s.t, s.values, s.names, s.units, valid=s.valid, info=s.info, source=self.source,
                            t0=s.t0, time_origin=s.time_origin)
        out.breaks = list(self.breaks)
        return out

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
        if method == "previous":
            i = np.searchsorted(t, grid + HOLD_TOL, side="right") - 1
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
    method: str = "previous",
    span: str = "common",
    log_span: tuple[float, float] | None = None,
    stuck_after: float = 2.0,
    counts: Mapping[str, Mapping[str, int]] | None = None,
    source: SourceReport | None = None,
    where: str = "log",
    t0: float = 0.0,
    time_origin: TimeOrigin | None = None,
    plausibility: Mapping[str, Any] | None = None,
    resolution: Mapping[str, float] | None = None,
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
    method : {"previous", "linear"}
        Zero-order hold of each channel's last sample (causal, the default; a sample at most
        :data:`~fdikit.io.can.HOLD_TOL` after a grid time counts as at it) or linear
        interpolation between the neighbouring samples (uses the next sample: not causal).
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
    plausibility : mapping of str -> Plausibility or mapping, optional
        Range and spike rules per channel, in the channel's returned unit, applied to its source
        samples before resampling (:func:`fdikit.io.formats.raw_checks.implausible_samples`): a
        refused sample is a bad sample, and every grid sample it would touch is invalid with the
        rule's reason.
    resolution : mapping of str -> float, optional
        Quantisation step of each channel in its source unit (a DBC signal's scale), the floor of
        the spike test's scale.

    Returns
    -------
    LoadedSignals
        One run, ``T`` samples; ``valid`` is ``False`` exactly where a value is NaN. A grid
        sample inside a gap (its neighbouring source samples more than ``max_gap`` periods
        apart) is NaN and invalid, never held or bridged; :meth:`LoadedSignals.invalid_reason`
        says why each invalid sample is invalid.

    Examples
    --------
    >>> import numpy as np
    >>> s = series_to_grid({"x": (np.arange(5.0), np.array([0.0, 1.0, np.nan, 3.0, 4.0]))},
    ...                    {"x": "m"}, rate=2.0)
    >>> s.valid[0, :, 0].astype(int).tolist()  # the NaN at 2 s is held until the next sample
    [1, 1, 1, 1, 0, 0, 1, 1, 1]
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
    plausibility = dict(plausibility or {})
    for k in plausibility:
        if k not in names:
            raise DataError(f"plausibility rule given for {k!r}, which is not a requested signal")
    resolution = resolution or {}
    implausible: dict[str, tuple[np.ndarray, list[str]]] = {}
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
        res = abs(float(resolution.get(n, 0.0) or 0.0))
        if target != src_unit:
            v = convert_units(v, src_unit, target, channel=n)
            if res:
                r01 = convert_units(np.array([0.0, res]), src_unit, target, channel=n)
                res = abs(float(r01[1] - r01[0]))
        if n in plausibility:
            bad, why = implausible_samples(t, v, plausibility[n], res, where=n)
            if bad.any():
                v = np.where(bad, np.nan, v)
                implausible[n] = (bad, why)
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
        imp = implausible.get(n)
        if n_ok < n_grid:
            reasons.extend(_invalid_spans(n, t, fin_of[c], grid, ok, method, max_gap, period[n], imp))
        longest = longest_of[c]
        span_s = float(t[-1] - t[0])
        info[n] = SignalQuality(
            n, src_unit, out_units[c], int(t.size),
            float((t.size - 1) / span_s) if t.size > 1 and span_s > 0 else float("nan"),
            period[n], float(t[0]), float(t[-1]),
            _n_gaps(by_time[id(t)], max_gap), n_grid - n_ok,
            n_nonfinite=int(t.size - np.count_nonzero(fin_of[c])) - (0 if imp is None else int(imp[0].sum())),
            n_undecodable=int(counts.get(n, {}).get("n_undecodable", 0)),
            n_duplicates=n_dup, n_conflicts=n_conf, longest_constant=longest,
            stuck=bool(longest >= stuck_after),
            n_implausible=0 if imp is None else int(imp[0].sum()))
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


def _invalid_spans(name, t, fin, grid, ok, method, max_gap, period,
                   implausible=None) -> list[tuple[str, int, int, str]]:
    """Why each run of invalid grid samples of one channel is invalid: outside the channel's span,
    a gap longer than ``max_gap`` periods, an interpolation touching a source sample refused by
    the plausibility rule (``implausible``: its mask and reasons) or another bad source sample."""
    out = []
    bad = ~ok
    outside = bad & ((grid < t[0]) | (grid > t[-1]))
    touches = bad & ~outside & _touches_bad(t, fin, grid, method)
    if implausible is not None:
        imp, why = implausible
        by_imp = touches & _touches_bad(t, ~imp, grid, method)
        touches &= _touches_bad(t, fin | imp, grid, method)
        ti = t[imp]
        for a, b in _runs(by_imp):
            lo, hi = grid[max(a - 1, 0)], grid[min(b, grid.size - 1)]
            sel = [w for w, x in zip(why, ti) if lo <= x <= hi] or why[:1]
            out.append((name, a, b,
                        f"{name}: interpolated from an implausible source sample ({'; '.join(sel)})"))
    gap = bad & ~outside & ~touches & ~(_touches_bad(t, ~implausible[0], grid, method)
                                        if implausible is not None else False)
    for a, b in _runs(outside):
        out.append((name, a, b, f"{name}: no sample (outside its recorded span {t[0]:.6f} .. {t[-1]:.6f} s)"))
    for a, b in _runs(touches):
        out.append((name, a, b, f"{name}: interpolated from a NaN, inf or undecodable source sample"))
    i = np.searchsorted(t, grid + (HOLD_TOL if method == "previous" else 0.0), side="right") - 1
    for a, b in _runs(gap):
        i0 = int(np.clip(i[a], 0, t.size - 1))
        i1 = min(i0 + 1, t.size - 1)
        out.append((name, a, b, f"{name}: gap, no sample from {t[i0]:.6f} s to {t[i1]:.6f} s "
                                f"({t[i1] - t[i0]:.4g} s, longer than max_gap = {max_gap:g} periods of "
                                f"{period:.4g} s)"))
    out.sort(key=lambda r: (r[1], r[0]))
    return out
