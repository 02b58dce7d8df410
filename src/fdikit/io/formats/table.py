"""What the decoded-signal table readers (Parquet, CSV) share: time and signal columns, checks, gridding."""

from __future__ import annotations

import difflib
from collections.abc import Sequence

import numpy as np

from ...errors import DataError
from .checks import _check_signal_list
from .grid import series_to_grid

_TIME_NAMES = ("t", "time", "timestamp", "timestamps", "t_s", "time_s")


def _pick_time(columns: Sequence[str], time: str | None, where: str) -> str:
    if time is not None:
        if time not in columns:
            raise DataError(f"{where} has no time column {time!r}; columns: {list(columns)}")
        return time
    for c in _TIME_NAMES:
        if c in columns:
            return c
    raise DataError(f"{where} has no time column (looked for {list(_TIME_NAMES)}; pass time=, "
                    "or set [log].time in a monitor config); "
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
