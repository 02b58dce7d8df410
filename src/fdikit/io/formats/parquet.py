"""The Parquet reader of decoded-signal tables."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...errors import DataError
from ..timebase import times_to_seconds
from .checks import _check_file
from .grid import LoadedSignals, SourceReport
from .table import _check_table_time, _pick_columns, _pick_time, _table_to_grid


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
