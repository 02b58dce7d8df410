"""The topic-folder reader: a folder of per-topic CSV files, each on its own time column and rate.

Each file ``<topic>.csv`` is one topic (its name is the file's stem); each row is one message; its
numeric columns are channels ``"<topic>.<column>"``. A header cell ``"speed [m/s]"`` names the
column ``speed`` with unit ``m/s``. A column with no number in it (a frame id, a text status) is
not a channel; a column with numbers and some other text is an error naming the line; an empty
cell in a numeric column is a message without that value: a bad sample, flagged on the grid.

Time: each file has its own time column (``time="auto"`` looks for ``t``, ``time``,
``timestamp``, ``timestamps``, ``t_s``, ``time_s``; or name it), read exactly in ``time_unit``
(:mod:`fdikit.io.timebase`). Relative clocks (every file's first time below 10^6 s) are kept as
written. Absolute clocks (UNIX time in s, ms, us or ns) are made relative to the earliest first
time over all files, so the topics stay aligned: ``t0`` and ``time_origin`` hold that origin.
Mixing the two is an error.
"""

from __future__ import annotations

import csv as _csv
import re
from fractions import Fraction
from pathlib import Path

import numpy as np

from ...errors import DataError
from ..timebase import ABSOLUTE_AFTER, TimeOrigin, times_to_seconds
from .checks import _csv_rows
from .grid import SourceReport
from .multirate import MultiRateSignals, pick_channels, topics_to_grid
from .table import _check_table_time, _pick_time

_UNIT_IN_HEADER = re.compile(r"^(.*?)\s*\[([^\]]*)\]$")


def _header(cells: list[str]) -> tuple[list[str], list[str]]:
    names, units = [], []
    for c in cells:
        c = c.strip()
        m = _UNIT_IN_HEADER.match(c)
        names.append(m.group(1) if m else c)
        units.append(m.group(2).strip() if m else "")
    return names, units


_NUMBER = r"^\s*[-+]?((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|nan|inf|infinity)\s*$"


def _read_fast(p: Path, where: str, time, time_unit: str):
    """:func:`_read_topic_csv` by pyarrow's CSV parser; ``None`` when the file needs the exact
    line-by-line path (any parse problem, a column of numbers and text), which names the line."""
    import pyarrow as pa
    import pyarrow.compute as pc
    from pyarrow import csv as pacsv

    with open(p, encoding="utf-8", newline="") as fh:
        first = next(_csv.reader([fh.readline()]), [])
    header, units = _header(first)
    if not header or len(set(header)) != len(header):
        return None
    time_col = _pick_time(header, None if time == "auto" else time, where)
    jt = header.index(time_col)
    names = [f"c{j}" for j in range(len(header))]

    def parse(types):
        return pacsv.read_csv(p, read_options=pacsv.ReadOptions(column_names=names, skip_rows=1),
                              convert_options=pacsv.ConvertOptions(column_types=types,
                                                                   strings_can_be_null=False))

    try:
        tab = parse({})
        tcol = tab.column(jt)
        ty = tcol.type
        if tab.num_rows and tcol.null_count == 0 and pa.types.is_floating(ty) and time_unit in ("auto", "s"):
            f = tcol.to_numpy().astype(float)
            if abs(f[0]) < ABSOLUTE_AFTER:  # relative seconds: the float of each cell, as
                _check_table_time(f, where, time_col, None, line_offset=2)  # times_to_seconds
                t, origin = f, TimeOrigin(0, 0, "s", False)
            else:
                tab = None
        elif tab.num_rows and tcol.null_count == 0 and pa.types.is_integer(ty):
            t, origin = times_to_seconds(tcol.to_numpy(), time_unit, where=where, column=time_col)
        else:
            tab = None
        if tab is None:  # absolute decimal clocks: read the text, exactly
            tab = parse({f"c{jt}": pa.string()})
            if tab.num_rows == 0:
                return None
            traw = [x.strip() for x in tab.column(jt).to_pylist()]
            present = np.array([x != "" for x in traw])
            _check_table_time(np.zeros(present.size), where, time_col, present, line_offset=2)
            t, origin = times_to_seconds(traw, time_unit, where=where, column=time_col, line_offset=2)
    except (pa.ArrowInvalid, pa.ArrowTypeError, UnicodeDecodeError):
        return None
    if tab.num_rows == 0:
        return None
    _check_table_time(t, where, time_col, None, line_offset=2)
    cols: dict[str, np.ndarray] = {}
    col_units: dict[str, str] = {}
    for j, name in enumerate(header):
        if j == jt:
            continue
        col = tab.column(j)
        ty = col.type
        if pa.types.is_null(ty):
            continue  # an empty column
        if pa.types.is_string(ty) or pa.types.is_large_string(ty):
            if pc.any(pc.match_substring_regex(col, _NUMBER, ignore_case=True)).as_py():
                return None  # numbers and text: the exact path names the line
            continue  # a text column: not a channel
        if not (pa.types.is_integer(ty) or pa.types.is_floating(ty) or pa.types.is_boolean(ty)):
            return None
        cols[name] = pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False).astype(float, copy=False)
        col_units[name] = units[j]
    return t, origin, cols, col_units, tab.num_rows


def _read_topic_csv(p: Path, time, time_unit: str):
    """One topic file: (t, origin, {column: values}, {column: unit}, rows)."""
    where = f"topic file {p.name!r}"
    if p.stat().st_size == 0:
        raise DataError(f"{where} is empty (0 bytes)")
    try:
        fast = _read_fast(p, where, time, time_unit)
    except UnicodeDecodeError:
        fast = None
    if fast is not None:
        return fast
    rows = _csv_rows(p, where)
    header, units = _header(rows[0])
    if len(set(header)) != len(header):
        raise DataError(f"{where}: duplicated column names in the header {header}")
    body = rows[1:]
    while body and not any(x.strip() for x in body[-1]):
        body.pop()
    if not body:
        raise DataError(f"{where} has a header but no rows")
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise DataError(f"{where} line {i + 2} has {len(r)} fields, the header has {len(header)} "
                            f"(truncated or corrupt line): {','.join(r)[:80]!r}")
    time_col = _pick_time(header, None if time == "auto" else time, where)
    arr = np.array(body, dtype=str)
    if arr.ndim != 2:
        arr = arr.reshape(len(body), len(header))
    jt = header.index(time_col)
    traw = np.char.strip(arr[:, jt])
    present = traw != ""
    _check_table_time(np.zeros(present.size), where, time_col, present, line_offset=2)
    t, origin = times_to_seconds(list(traw), time_unit, where=where, column=time_col, line_offset=2)
    _check_table_time(t, where, time_col, None, line_offset=2)
    cols: dict[str, np.ndarray] = {}
    col_units: dict[str, str] = {}
    for j, name in enumerate(header):
        if j == jt:
            continue
        raw = np.char.strip(arr[:, j])
        has = raw != ""
        out = np.full(raw.size, np.nan)
        try:
            out[has] = raw[has].astype(float)
        except ValueError:
            num = np.zeros(raw.size, bool)
            for i in np.flatnonzero(has):
                try:
                    out[i] = float(raw[i])
                    num[i] = True
                except ValueError:
                    pass
            if not num.any():
                continue  # a text column: not a channel
            bad = int(np.flatnonzero(has & ~num)[0])
            raise DataError(f"{where} line {bad + 2}, column {name!r}: {str(raw[bad])[:40]!r} is not a "
                            "number (the column holds numbers elsewhere)") from None
        if not has.any():
            continue  # an empty column
        cols[name] = out
        col_units[name] = units[j]
    return t, origin, cols, col_units, len(body)


def read_topic_folder(folder, signals=None, rate=None, *, time: str = "auto", time_unit: str = "auto",
                      pattern: str = "*.csv", source_units=None, **kw) -> MultiRateSignals:
    """Read a folder of per-topic CSV files onto one grid: zero-order hold per topic, with ages.

    Parameters
    ----------
    folder : path-like
        A folder of ``<topic>.csv`` files (one topic each, at its own rate).
    signals : sequence of str, optional
        Channels ``"topic.column"`` or whole topics (``"gps"``). Default: every numeric column
        of every file.
    rate : float, optional
        Grid rate (Hz); default the fastest median topic rate (pass it to follow a log).
    time : str
        Time column of every file, or ``"auto"`` (the first of ``t``, ``time``, ``timestamp``,
        ``timestamps``, ``t_s``, ``time_s``).
    time_unit : {"auto", "s", "ms", "us", "ns"}
        Unit of the time columns (:func:`~fdikit.io.times_to_seconds`).
    pattern : str
        Glob of the topic files in ``folder``.
    source_units : mapping of str -> str, optional
        Units of channels (overrides a unit in the header).
    **kw
        ``method`` (``"previous"``, causal, the default; ``"linear"`` marks the result
        non-causal), ``max_age``, ``age``, ``max_gap``, ``units``, ``span``, ``stuck_after``: see
        :func:`~fdikit.io.formats.multirate.topics_to_grid`.

    Returns
    -------
    MultiRateSignals
        Data channels, then one ``"<topic>.__age__"`` channel per topic read.

    Raises
    ------
    DataError
        Missing folder, no topic file, a file that is not CSV or is truncated (naming file and
        line), a missing time column, time going back, a topic or column not found (with the
        available list), absolute and relative clocks mixed.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "odom.csv").write_text("timestamp,v [m/s]\\n0.0,1\\n0.1,2\\n0.2,3\\n0.3,4\\n")
    >>> _ = (d / "gps.csv").write_text("timestamp,lat\\n0.05,10\\n0.25,11\\n")
    >>> s = read_topic_folder(d, rate=10)
    >>> s.names, s.units[0]
    (['gps.lat', 'odom.v', 'gps.__age__', 'odom.__age__'], '')
    >>> s["gps.lat"][0].tolist(), s.age("gps").round(6).tolist(), s.units[1]
    ([10.0, 10.0, 11.0], [0.0, 0.1, 0.0], 'm/s')
    """
    d = Path(folder)
    if not d.exists():
        raise DataError(f"topic folder {str(d)!r} does not exist")
    if not d.is_dir():
        raise DataError(f"topic folder {str(d)!r} is a file, not a folder of per-topic CSV files")
    files = sorted(f for f in d.glob(pattern) if f.is_file())
    where = f"topic folder {d.name!r}"
    if not files:
        raise DataError(f"{where} has no file matching {pattern!r}")
    wanted = None
    if signals is not None:
        sig = [signals] if isinstance(signals, str) else list(signals)
        wanted = {s.split(".", 1)[0] for s in sig if isinstance(s, str)}
        stems = [f.stem for f in files]
        missing = sorted(wanted - set(stems))
        if missing:
            raise DataError(f"{where} has no topic {missing}; topics: {stems}")
        files = [f for f in files if f.stem in wanted]
    read = {f.stem: _read_topic_csv(f, time, time_unit) for f in files}
    rebased = {tp: r[1].rebased for tp, r in read.items()}
    if len(set(rebased.values())) > 1:
        raise DataError(f"{where} mixes absolute clocks ({[k for k, v in rebased.items() if v]}) and "
                        f"relative ones ({[k for k, v in rebased.items() if not v]}); pass time_unit= "
                        "or fix the files")
    origin = None
    if any(rebased.values()):
        exps = {r[1].exponent for r in read.values()}
        e = max(exps)
        first = {tp: Fraction(r[1].ticks, 10 ** r[1].exponent) for tp, r in read.items()}
        o = min(first.values())
        origin = TimeOrigin(int(o * 10**e), e, next(iter(read.values()))[1].unit, True)
    available: dict[str, list[str]] = {}
    topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    units_src: dict[str, str] = {}
    n_rec = 0
    for tp, (t, org, cols, cu, n) in read.items():
        if origin is not None:
            off = float(Fraction(org.ticks, 10**org.exponent) - Fraction(origin.ticks, 10**origin.exponent))
            t = t + off if off else t
        available[tp] = [f"{tp}.{c}" for c in cols]
        topics[tp] = (t, {f"{tp}.{c}": v for c, v in cols.items()})
        units_src.update({f"{tp}.{c}": cu[c] for c in cols})
        n_rec += n
    chosen = pick_channels(available, signals, where)
    topics = {tp: (topics[tp][0], {c: topics[tp][1][c] for c in ch}) for tp, ch in chosen.items()}
    units_src = {c: units_src[c] for ch in chosen.values() for c in ch}
    for k, u in (source_units or {}).items():
        if k not in units_src:
            raise DataError(f"source unit given for {k!r}, which is not a channel read")
        units_src[k] = u
    src = SourceReport("topics", str(d), int(n_rec))
    return topics_to_grid(topics, units_src, rate, source=src, where=where,
                          t0=origin.seconds if origin else 0.0, time_origin=origin, **kw)
