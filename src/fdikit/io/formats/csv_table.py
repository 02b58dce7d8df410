"""The CSV reader of decoded-signal tables (the Parquet reader's conventions)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...errors import DataError
from ..timebase import times_to_seconds
from .checks import _check_file, _csv_rows
from .grid import LoadedSignals, SourceReport
from .table import _check_table_time, _pick_columns, _pick_time, _table_to_grid


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
    >>> s.valid[0].astype(int).T.tolist()   # speed: its nan (held) spoils 0.1 .. 0.15; yaw from 0.05
    [[1, 1, 0, 0, 1], [0, 1, 1, 1, 1]]
    >>> s["yaw"][0, 1:5].round(6).tolist(), s.info["speed"].n_nonfinite
    ([0.5, 0.5, 0.7, 0.7], 1)
    """
    p = _check_file(path, "CSV file")
    where = f"CSV file {p.name!r}"
    rows = _csv_rows(p, where)
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
