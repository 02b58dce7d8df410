"""Time-aligned, named signal arrays: the data type every fdikit stage consumes and produces.

A :class:`Signals` holds a time vector ``t`` of shape ``(T,)`` and values of shape
``(runs, T, channels)``; a single run is stored with ``runs == 1``. Channel names (and
optional units) travel with the values so that stages pick their inputs by name.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .errors import DataError

__all__ = ["Signals", "check_finite", "check_time"]


def check_time(t: np.ndarray, *, name: str = "t") -> np.ndarray:
    """Validate a time vector: 1-D, finite, strictly increasing. Returns it as float64."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise DataError(f"time vector {name!r} must be 1-D, got shape {t.shape}")
    # fast path: strictly increasing (a comparison with NaN is false) with finite ends is finite
    # throughout; t[k] > t[k-1] is t[k] - t[k-1] > 0 for floats (no temporaries but one bool array)
    if t.size == 0 or (math.isfinite(t[0]) and math.isfinite(t[-1])
                       and (t.size == 1 or bool(np.greater(t[1:], t[:-1]).all()))):
        return t
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(f"time vector {name!r} has a non-finite value at sample {bad[0]}")
    if t.size > 1:
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise DataError(
                f"time vector {name!r} is not strictly increasing at sample {k} "
                f"(t[{k - 1}] = {t[k - 1]!r}, t[{k}] = {t[k]!r})"
            )
    return t


def check_finite(values: np.ndarray, names: Sequence[str], *, what: str = "signal",
                 first_sample: int = 0) -> None:
    """Raise :class:`DataError` naming the channel, run and sample of the first NaN or inf.

    ``values`` has shape ``(runs, T, channels)`` (or ``(T, channels)``); samples are numbered from
    ``first_sample`` (a streaming step passes the index of the sample it is given).
    """
    v = np.asarray(values)
    if v.dtype.kind not in "fc":
        return
    ok = np.isfinite(v)
    if ok.all():
        return
    idx = np.argwhere(~ok)[0]
    if v.ndim == 3:
        run, k, c = (int(i) for i in idx)
        where = f"run {run}, sample {k + first_sample}"
    else:
        k, c = (int(i) for i in idx)
        where = f"sample {k + first_sample}"
    raise DataError(f"{what} channel {names[c]!r} has a non-finite value ({v[tuple(idx)]}) at {where}")


#: Column names taken as the time column of a DataFrame (lower case, stripped).
_TIME_NAMES = {"t", "time", "timestamp", "times", "time_s", "t_s", "time [s]", "time(s)", "timestamp_ns",
               "time_ns", "timestamp_us", "time_us", "stamp", "seconds"}
#: Decimal exponent of each numeric time unit.
_TIME_EXP = {"s": 0, "ms": 3, "us": 6, "ns": 9}


def _pandas_time(raw, name, time_unit: str) -> tuple[np.ndarray, float]:
    """Seconds from the first sample, and the origin ``t0``, of a pandas time index or column."""
    import pandas as pd

    where = "the index" if name == "index" else f"time column {name!r}"
    dtype = raw.dtype
    if pd.api.types.is_datetime64_any_dtype(dtype):
        nat = np.asarray(pd.isna(raw))
        if nat.any():
            raise DataError(f"{where} has a missing time (NaT) at row {int(np.argmax(nat))}")
        ns = pd.DatetimeIndex(raw).as_unit("ns").asi8
        if ns.size == 0:
            return np.zeros(0), 0.0
        return (ns - ns[0]) / 1e9, float(ns[0]) / 1e9
    if pd.api.types.is_timedelta64_dtype(dtype):
        return pd.TimedeltaIndex(raw).as_unit("ns").asi8 / 1e9, 0.0
    if not pd.api.types.is_numeric_dtype(dtype) or pd.api.types.is_bool_dtype(dtype):
        raise DataError(f"{where} has dtype {dtype}, not numbers or datetimes; convert it (pd.to_datetime "
                        "for date strings) or name the time column with time=")
    v = np.asarray(raw)
    if v.size == 0:
        return np.zeros(0, float), 0.0
    first = abs(float(v[0]))
    unit = time_unit
    if unit == "auto":
        unit = "ns" if first >= 1e17 else "us" if first >= 1e14 else "ms" if first >= 1e11 else "s"
    scale = 10.0 ** _TIME_EXP[unit]
    if np.issubdtype(v.dtype, np.integer):
        if (unit != "s" or first >= 1e6):   # exact integer differences, then one division
            d = v.astype(np.int64) - np.int64(v[0]) if v.dtype != np.uint64 else \
                (v - v[0]).astype(np.int64)
            return d / scale, float(v[0]) / scale
        return v.astype(float), 0.0
    v = v.astype(float)
    if unit != "s" or first >= 1e6:   # an absolute or scaled clock: rebase to its first sample
        return (v - v[0]) / scale, float(v[0]) / scale
    return v, 0.0


class Signals:
    """Named, time-aligned signals for one or many runs.

    Parameters
    ----------
    t : array_like, shape (T,)
        Sample times in seconds, strictly increasing.
    values : array_like, shape (T, C) or (runs, T, C)
        Sample values. A 2-D array is one run.
    names : sequence of str, length C
        Channel names (unique).
    units : sequence of str, optional
        Channel units (``""`` when unknown).
    check : bool
        Validate finiteness of the values (default True). Time is always validated.
    t0 : float
        Absolute time (s) of ``t == 0``: a log read from an absolute clock (UNIX epoch, ROS
        nanoseconds) is rebased to start at 0 and keeps its origin here, so that an event at
        ``t`` happened at ``t0 + t``. Default 0 (``t`` is already the log's own clock).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> s = Signals(np.arange(3) * 0.1, np.ones((3, 2)), ["a", "b"])
    >>> s.values.shape, s["b"].shape
    ((1, 3, 2), (1, 3))
    """

    __slots__ = ("names", "t", "t0", "units", "values")

    def __init__(
        self,
        t: Any,
        values: Any,
        names: Sequence[str],
        units: Sequence[str] | None = None,
        *,
        check: bool = True,
        t0: float = 0.0,
    ):
        t = check_time(t)
        if np.ma.isMaskedArray(values):   # a masked entry is a missing sample, never its hidden value
            mask = np.ma.getmaskarray(values)
            if check and mask.any():
                idx = np.argwhere(mask)[0].tolist()
                raise DataError(f"values are masked at index {idx} ({int(mask.sum())} masked entries); pass "
                                "check=False to keep them as missing samples (NaN, which a Monitor flags as "
                                "invalid), or fill them")
            values = np.ma.filled(np.ma.asarray(values, dtype=float), np.nan)
        v = np.asarray(values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if v.ndim == 2:
            v = v[None]
        if v.ndim != 3:
            raise DataError(f"values must have shape (T, C) or (runs, T, C), got {v.shape}")
        names = [str(n) for n in names]
        if v.shape[1] != t.size:
            raise DataError(
                f"values have {v.shape[1]} samples along time but t has {t.size} (shape {v.shape})"
            )
        if v.shape[2] != len(names):
            raise DataError(f"values have {v.shape[2]} channels but {len(names)} names: {names}")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise DataError(f"duplicated channel names: {dup}")
        if units is None:
            units = [""] * len(names)
        units = [str(u) for u in units]
        if len(units) != len(names):
            raise DataError(f"{len(units)} units for {len(names)} channels")
        if check:
            check_finite(v, names)
        self.t = t
        self.values = v
        self.names = names
        self.units = units
        try:
            self.t0 = float(t0)
        except (TypeError, ValueError):
            raise DataError(f"t0 must be a number of seconds, got {t0!r}") from None
        if not np.isfinite(self.t0):
            raise DataError(f"t0 must be finite, got {t0!r}")

    # ------------------------------------------------------------------ basic properties
    @property
    def runs(self) -> int:
        return self.values.shape[0]

    @property
    def n_samples(self) -> int:
        return self.values.shape[1]

    @property
    def n_channels(self) -> int:
        return self.values.shape[2]

    @property
    def dt(self) -> float:
        """Mean sample interval (s)."""
        return float((self.t[-1] - self.t[0]) / max(self.t.size - 1, 1))

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        ch = ", ".join(self.names[:8]) + (", ..." if self.n_channels > 8 else "")
        span = f"{self.t[0]:g}..{self.t[-1]:g} s" if self.t.size else "empty"
        return f"Signals(runs={self.runs}, samples={self.n_samples}, {span}, channels=[{ch}])"

    # ------------------------------------------------------------------ channel access
    def index(self, names: str | Iterable[str]) -> list[int]:
        """Column indices of the given channel names; a clear error for unknown ones."""
        if isinstance(names, str):
            names = [names]
        out = []
        lookup = {n: i for i, n in enumerate(self.names)}
        for n in names:
            if n not in lookup:
                raise DataError(f"unknown channel {n!r}; available channels: {self.names}")
            out.append(lookup[n])
        return out

    def __getitem__(self, name: str) -> np.ndarray:
        """Values of one channel, shape ``(runs, T)``."""
        return self.values[:, :, self.index(name)[0]]

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def select(self, names: Iterable[str]) -> Signals:
        """A new :class:`Signals` with only the named channels, in that order."""
        names = list(names)
        idx = self.index(names)
        return Signals(
            self.t,
            self.values[:, :, idx],
            names,
            [self.units[i] for i in idx],
            check=False,
            t0=self.t0,
        )

    def run(self, i: int) -> Signals:
        """Run ``i`` alone (still 3-D with ``runs == 1``)."""
        if not -self.runs <= i < self.runs:
            raise DataError(f"run {i} out of range for {self.runs} runs")
        return Signals(self.t, self.values[i : i + 1], self.names, self.units, check=False, t0=self.t0)

    def window(self, t0: float | None = None, t1: float | None = None) -> Signals:
        """Samples with ``t0 <= t <= t1``."""
        m = np.ones(self.t.size, bool)
        if t0 is not None:
            m &= self.t >= t0
        if t1 is not None:
            m &= self.t <= t1
        return Signals(self.t[m], self.values[:, m], self.names, self.units, check=False, t0=self.t0)

    def concat_channels(self, other: Signals) -> Signals:
        """Channels of ``self`` followed by those of ``other`` (same time grid and runs)."""
        if self.t.shape != other.t.shape or not np.array_equal(self.t, other.t):
            raise DataError("cannot join channels of signals on different time grids")
        if self.runs != other.runs:
            raise DataError(f"cannot join signals with {self.runs} and {other.runs} runs")
        return Signals(
            self.t,
            np.concatenate([self.values, other.values], axis=2),
            self.names + other.names,
            self.units + other.units,
            check=False,
            t0=self.t0,
        )

    @staticmethod
    def join_channels(parts: Sequence[Signals]) -> Signals:
        """The channels of every part in turn (same time grid and runs), joined in one copy:
        ``parts[0].concat_channels(parts[1]).concat_channels(parts[2])...`` without the copies of
        the growing intermediate results."""
        parts = list(parts)
        if not parts:
            raise DataError("nothing to join")
        first = parts[0]
        if len(parts) == 1:
            return first
        for other in parts[1:]:
            if first.t.shape != other.t.shape or not np.array_equal(first.t, other.t):
                raise DataError("cannot join channels of signals on different time grids")
            if first.runs != other.runs:
                raise DataError(f"cannot join signals with {first.runs} and {other.runs} runs")
        return Signals(
            first.t,
            np.concatenate([p.values for p in parts], axis=2),
            [n for p in parts for n in p.names],
            [u for p in parts for u in p.units],
            check=False,
            t0=first.t0,
        )

    # ------------------------------------------------------------------ pandas edges
    def to_pandas(self, run: int | None = None):
        """A :class:`pandas.DataFrame` indexed by time (one run), or with a (run, t) MultiIndex."""
        import pandas as pd

        if run is not None or self.runs == 1:
            r = 0 if run is None else run
            return pd.DataFrame(self.values[r], index=pd.Index(self.t, name="t"), columns=self.names)
        idx = pd.MultiIndex.from_product([range(self.runs), self.t], names=["run", "t"])
        return pd.DataFrame(self.values.reshape(-1, self.n_channels), index=idx, columns=self.names)

    @classmethod
    def from_pandas(cls, df, time: str | None = None, units: Sequence[str] | None = None, *,
                    time_unit: str = "auto") -> Signals:
        """Build from a :class:`pandas.DataFrame` with a time index or a time column.

        Parameters
        ----------
        df : pandas.DataFrame
            One run: rows are samples, columns channels. Or the (run, t) MultiIndex frame that
            :meth:`to_pandas` writes for many runs.
        time : str, optional
            The time column's name, or ``"index"`` to take the index as time even when it is a
            plain row count. Default: the index when it is a time index (datetime, timedelta or
            numbers that are not row numbers); else the one column named like a time
            (``t``, ``time``, ``timestamp``, ``time_s``, ...; any case); else refused.
        units : sequence of str, optional
            Channel units.
        time_unit : {"auto", "s", "ms", "us", "ns"}
            Unit of a numeric time. ``"auto"``: seconds, unless the first timestamp is an absolute
            clock, whose unit follows from its magnitude as in the log readers (>= 1e17 ns,
            >= 1e14 us, >= 1e11 ms).

        Datetime clocks (``datetime64``, timezone-aware or not) and absolute numeric clocks
        (first time >= 1e6 s) are rebased to start at 0, their origin kept in ``t0`` (s since the
        UNIX epoch for datetimes); integer clocks are converted from exact integer differences.

        Raises
        ------
        DataError
            No time found (a RangeIndex and no time-like column), a time column that is not
            numeric or datetime, or time not increasing (from the constructor).

        Examples
        --------
        >>> import pandas as pd
        >>> df = pd.DataFrame({"time": [0.0, 0.1, 0.2], "y": [1.0, 2.0, 3.0]})
        >>> s = Signals.from_pandas(df)
        >>> s.names, s.t.tolist()
        (['y'], [0.0, 0.1, 0.2])
        >>> ix = pd.to_datetime(["2026-01-01 00:00:00.0", "2026-01-01 00:00:00.5"])
        >>> s = Signals.from_pandas(pd.DataFrame({"y": [1.0, 2.0]}, index=ix))
        >>> s.t.tolist(), s.t0
        ([0.0, 0.5], 1767225600.0)
        """
        import pandas as pd

        if time_unit not in _TIME_EXP and time_unit != "auto":
            raise DataError(f"time_unit must be 'auto' or one of {list(_TIME_EXP)}, got {time_unit!r}")
        if isinstance(df.index, pd.MultiIndex):
            return cls._from_run_frame(df, units)
        if time is None:
            idx = df.index
            row_numbers = isinstance(idx, pd.RangeIndex) or (
                pd.api.types.is_integer_dtype(idx.dtype) and idx.name is None
                and np.array_equal(np.asarray(idx), np.arange(len(idx))))
            if not row_numbers:
                time = "index"
            else:
                like = [c for c in df.columns if str(c).strip().lower() in _TIME_NAMES]
                if len(like) != 1:
                    raise DataError(
                        f"the DataFrame's index is row numbers, not time, and "
                        f"{'no column' if not like else f'{len(like)} columns ({like})'} is named like a "
                        f"time; pass time='<column>' (columns: {list(df.columns)[:20]}), or "
                        "time='index' to take the row numbers as seconds")
                time = like[0]
        if time == "index":
            raw = df.index
        else:
            if time not in df.columns:
                raise DataError(f"time column {time!r} not in {list(df.columns)}")
            raw = df[time]
            df = df.drop(columns=[time])
        t, t0 = _pandas_time(raw, time, time_unit)
        bad = [str(c) for c in df.columns if not (pd.api.types.is_numeric_dtype(df[c].dtype)
                                                  or pd.api.types.is_bool_dtype(df[c].dtype))]
        if bad:
            raise DataError(f"columns {bad} are not numeric (dtype {df[bad[0]].dtype}); select the signal "
                            "columns, or convert them")
        vals = df.to_numpy(dtype=float, na_value=np.nan)
        return cls(t, vals, [str(c) for c in df.columns], units, t0=t0)

    @classmethod
    def _from_run_frame(cls, df, units) -> Signals:
        """The (run, t) MultiIndex frame of :meth:`to_pandas`, back to runs."""
        names = list(df.index.names)
        if len(names) != 2 or names[0] != "run":
            raise DataError(f"a MultiIndex frame must be indexed by (run, t) as to_pandas writes it, got "
                            f"{names}")
        runs = df.index.get_level_values(0).unique()
        first = df.xs(runs[0], level=0)
        t = first.index.to_numpy(float)
        parts = []
        for r in runs:
            part = df.xs(r, level=0)
            if not np.array_equal(part.index.to_numpy(float), t):
                raise DataError(f"run {r!r} has another time axis than run {runs[0]!r}")
            parts.append(part.to_numpy(dtype=float, na_value=np.nan))
        return cls(t, np.stack(parts), [str(c) for c in df.columns], units)

    def equals(self, other: Signals, *, atol: float = 0.0) -> bool:
        """Same names, time and values (within ``atol``)."""
        return (
            self.names == other.names
            and np.array_equal(self.t, other.t)
            and self.values.shape == other.values.shape
            and bool(np.allclose(self.values, other.values, rtol=0, atol=atol))
        )
