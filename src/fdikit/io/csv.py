"""CSV recordings: one time column and numeric channels, with the same gap convention as CAN logs."""

from __future__ import annotations

import csv as _csv
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..base import interrupt
from ..base.inputs import spooled
from ..errors import DataError
from .can import LogSignals, SignalInfo, convert_units
from .timebase import time_unit_hint, times_to_seconds

__all__ = ["read_csv"]

#: Cell texts read as "no value" (NaN, flagged invalid), as pandas reads them.
NA_TEXTS = frozenset({"", "na", "n/a", "nan", "-nan", "+nan", "null", "none", "#n/a", "<na>", "nat"})


def _cells_to_float(cells: list[str], where: str, column: str) -> np.ndarray:
    """Numeric cells (stripped text) as float64; a text cell is a DataError naming row and column."""
    arr = np.asarray(cells, dtype=str)
    na = np.fromiter((c.lower() in NA_TEXTS for c in cells), bool, len(cells))
    work = np.where(na, "nan", arr)
    try:
        out = work.astype(float)
    except ValueError:
        out = None
    # NumPy's text cast clears a KeyboardInterrupt raised in it and goes on: stop here instead
    interrupt.check()
    if out is not None:
        return out
    out = np.empty(len(cells))
    for k, x in enumerate(work.tolist()):
        try:
            out[k] = float(x)
        except ValueError:
            raise DataError(f"{where}: column {column!r} is not numeric: data row {k} (line {k + 2}) holds "
                            f"{x[:40]!r}") from None
    return out


#: The first bytes of binary files that are often given a .csv name, and what to do with them.
_MAGIC = ((b"\x1f\x8b", "gzip-compressed (decompress it first: gunzip)"),
          (b"PK\x03\x04", "a ZIP archive, e.g. an Excel .xlsx workbook (save it as CSV, or unzip it)"),
          (b"PAR1", "a Parquet file (name it .parquet)"),
          (b"MDF     ", "an MDF4 measurement file (name it .mf4)"))


def _binary_kind(p: Path) -> str | None:
    """What a binary file named like a CSV really is, from its first bytes (None: unknown)."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return None
    return next((what for magic, what in _MAGIC if head.startswith(magic)), None)


def _read_rows(p: Path, where: str, encoding: str) -> tuple[list[str], list[list[str]]]:
    try:
        with open(p, encoding=encoding, newline="") as fh:
            rows = list(_csv.reader(fh))
    except UnicodeDecodeError as exc:
        kind = _binary_kind(p)
        if kind:
            raise DataError(f"{where} is not a CSV text file: it is {kind}") from None
        raise DataError(f"{where} is not {encoding} text (byte {exc.start}: {exc.reason})") from None
    except _csv.Error as exc:
        raise DataError(f"{where} cannot be parsed as CSV: {exc}") from None
    except LookupError:
        raise DataError(f"unknown text encoding {encoding!r}") from None
    except OSError as exc:
        raise DataError(f"{where} cannot be read: {exc}") from None
    while rows and not any(x.strip() for x in rows[0]):
        rows.pop(0)
    if not rows:
        raise DataError(f"{where} is empty: no header row")
    header = [h.strip() for h in rows[0]]
    return header, rows[1:]


def read_csv(
    path: str | os.PathLike,
    time: str = "t",
    columns: Sequence[str] | None = None,
    *,
    units: Mapping[str, str] | None = None,
    convert: Mapping[str, str] | None = None,
    rate: float | None = None,
    max_gap: float = 3.0,
    time_unit: str = "auto",
    rebase: bool | None = None,
    encoding: str = "utf-8-sig",
    method: str = "previous",
) -> LogSignals:
    """Read a CSV recording into :class:`~fdikit.io.LogSignals`.

    Parameters
    ----------
    path : path-like
        A comma-separated file with a header row (a UTF-8 byte-order mark is allowed); a FIFO or
        pipe is read whole first, interruptibly (:func:`fdikit.base.inputs.spooled`).
    time : str
        Name of the time column; must be strictly increasing.
    columns : sequence of str, optional
        Channels to keep (default: every column but ``time``).
    units : mapping, optional
        Unit of each channel as recorded (default ``""``).
    convert : mapping, optional
        Target unit per channel (see :func:`fdikit.io.convert_units`); needs ``units``.
    rate : float, optional
        Resample onto a uniform grid at this rate (Hz) without bridging gaps longer than
        ``max_gap`` median periods (:func:`fdikit.io.series_to_grid`: a grid sample inside a gap,
        or interpolated from an empty / NaN / inf cell, is NaN and invalid). Default: keep the
        file's own time stamps.
    max_gap : float
        See :func:`fdikit.io.resample_to_grid`.
    time_unit : {"auto", "s", "ms", "us", "ns"}
        Unit of the time column. ``"auto"`` reads seconds unless the first timestamp is an
        absolute clock in ms (>= 1e11), us (>= 1e14) or ns (>= 1e17); a relative clock that is
        not in seconds needs its unit (see :mod:`fdikit.io.timebase`).
    rebase : bool, optional
        Make ``t`` start at 0. Default: when the time axis is absolute (first timestamp at least
        10^6 s, e.g. UNIX epoch), computed exactly from the timestamps' text; the origin is in
        ``t0`` (s) and ``time_origin`` (exact). A relative axis is kept as written.
    encoding : str
        Text encoding (default UTF-8 with an optional byte-order mark).
    method : {"previous", "linear"}
        With ``rate``: the causal hold of each column's last sample (the default: no grid value
        depends on a later row), or linear interpolation with the next row (not causal).

    Returns
    -------
    LogSignals
        One run; empty or ``nan`` / ``inf`` cells are flagged ``valid == False``, never filled.

    Raises
    ------
    DataError
        Missing or empty file, a header without data rows, duplicated column names, missing time
        column or channel, a row with the wrong number of fields (naming its line), a text cell
        in a numeric column (naming row and column), time not strictly increasing (naming the row),
        a grid too large for memory (a time column in the wrong unit).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "epoch.csv"
    >>> _ = p.write_text("t,x\\n1700000000.00,1\\n1700000000.01,2\\n1700000000.02,3\\n")
    >>> s = read_csv(p)
    >>> s.t.tolist(), s.t0, s.time_origin.text
    ([0.0, 0.01, 0.02], 1700000000.0, '1700000000.00')
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"CSV file {str(p)!r} does not exist")
    if p.is_dir():
        raise DataError(f"CSV file {str(p)!r} is a directory, not a file")
    where = f"CSV {p.name!r}"
    with spooled(p) as src:   # a FIFO or pipe: read once, interruptibly, into a file of its name
        header, body = _read_rows(src, where, encoding)
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"{where}: duplicated column name(s) {dup} in the header {header}")
    if time not in header:
        hint = ""
        if len(header) == 1 and any(d in header[0] for d in ";\t|"):
            hint = " (the header has one column: is the file delimited by ';' or tabs, not commas?)"
        raise DataError(f"CSV {p.name!r} has no time column {time!r}; columns: {header}{hint}")
    lines = []
    rows = []
    for i, r in enumerate(body):
        if not any(x.strip() for x in r):
            continue  # a blank line
        if len(r) != len(header):
            raise DataError(f"{where} line {i + 2} has {len(r)} fields, the header has {len(header)} "
                            f"(truncated or corrupt line): {','.join(r)[:80]!r}")
        rows.append([x.strip() for x in r])
        lines.append(i + 2)
    if not rows:
        raise DataError(f"{where} has a header {header} but no data rows")
    cols = [c for c in header if c != time] if columns is None else list(columns)
    missing = [c for c in cols if c not in header]
    if missing:
        raise DataError(f"CSV {p.name!r} has no column(s) {missing}; columns: {header}")
    if not cols:
        raise DataError(f"{where} has no channel besides the time column {time!r}")
    units = dict(units or {})
    for k in units:
        if k not in cols:
            raise DataError(f"unit given for {k!r}, which is not a selected column {cols}")
    for k in convert or {}:
        if k not in cols:
            raise DataError(f"conversion given for {k!r}, which is not a selected column {cols}")
    it = header.index(time)
    tcells = [r[it] for r in rows]
    empty = [k for k, c in enumerate(tcells) if c.lower() in NA_TEXTS]
    if empty:
        k = empty[0]
        what = "empty" if not tcells[k] else f"not finite ({tcells[k]!r})"
        raise DataError(f"CSV {p.name!r}: time column {time!r} is {what} at data row {k} (line {lines[k]})")
    t, origin = times_to_seconds(tcells, time_unit, rebase=rebase, where=where, column=time, line_offset=2)
    d = np.diff(t)
    if (d <= 0).any():
        k = int(np.flatnonzero(d <= 0)[0]) + 1
        raise DataError(f"CSV {p.name!r}: time {time!r} is not strictly increasing at data row {k} "
                        f"(line {lines[k]}: {tcells[k - 1]} then {tcells[k]})")
    v = np.empty((t.size, len(cols)))
    for j, c in enumerate(cols):
        jj = header.index(c)
        v[:, j] = _cells_to_float([r[jj] for r in rows], where, c)
    out_units = [units.get(c, "") for c in cols]
    for k, target in (convert or {}).items():
        j = cols.index(k)
        v[:, j] = convert_units(v[:, j], out_units[j], target, channel=k)
        out_units[j] = target
    t0 = origin.seconds if origin.rebased else 0.0
    time_origin = origin if origin.rebased else None
    if rate is not None:
        from .formats import SourceReport, series_to_grid

        try:
            return series_to_grid({c: (t, v[:, j]) for j, c in enumerate(cols)}, dict(zip(cols, out_units)),
                                  rate, max_gap=max_gap, method=method,
                                  source=SourceReport("csv", str(p), int(t.size)),
                                  where=where, t0=t0, time_origin=time_origin)
        except DataError as exc:
            raise DataError(str(exc) + time_unit_hint(t, rate)) from None
    per = float(np.median(d)) if d.size else np.inf
    info = {}
    valid = np.isfinite(v)
    for j, c in enumerate(cols):
        mean_rate = float((t.size - 1) / (t[-1] - t[0])) if t.size > 1 else float("nan")
        info[c] = SignalInfo(c, units.get(c, ""), out_units[j], int(valid[:, j].sum()), mean_rate,
                             per, float(t[0]), float(t[-1]), int(np.sum(d > max_gap * per)),
                             int((~valid[:, j]).sum()))
    return LogSignals(t, v, cols, out_units, valid=valid, info=info, t0=t0, time_origin=time_origin)
