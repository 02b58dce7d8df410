"""Writers: :class:`~fdikit.Signals` to a CSV or Parquet table that the readers read back.

* :func:`write_csv` -- a header row (the time column, then the channel names) and one row per
  sample, floats written in full precision (``repr``), a NaN as the text ``nan`` (a bad sample to
  :func:`fdikit.io.read_log`, a NaN to :func:`fdikit.io.read_csv`); CSV has no place for units;
* :func:`write_parquet` -- one float64 column per channel, each channel's unit in its field
  metadata (key ``unit``, which :func:`fdikit.io.read_parquet` reads back).

One run is written (``run=0`` by default). The file is written to a temporary name and renamed
(:func:`fdikit.base.outputs.open_output`), so a reader never sees half a file; a full disk is a
DataError naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..base.outputs import open_output
from ..errors import DataError
from ..signals import Signals

__all__ = ["write_csv", "write_parquet"]


def _prepare(signals: Signals, path, time: str, run: int, suffixes: tuple[str, ...]) -> Path:
    if not isinstance(signals, Signals):
        raise DataError(f"expected Signals, got {type(signals).__name__}")
    if not -signals.runs <= run < signals.runs:
        raise DataError(f"run {run} out of range for {signals.runs} run(s)")
    if time in signals.names:
        raise DataError(f"the time column name {time!r} is also a channel name; choose another time=")
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise DataError(f"{p}: the file name must end in {' or '.join(suffixes)}")
    if not p.parent.is_dir():
        raise DataError(f"{p}: the folder {str(p.parent)!r} does not exist")
    return p


def write_csv(signals: Signals, path: str | os.PathLike, *, time: str = "t", run: int = 0) -> Path:
    """Write one run of ``signals`` as a CSV table (time column first).

    Parameters
    ----------
    signals : Signals
    path : path-like
        A ``.csv`` file (its folder must exist).
    time : str
        Name of the time column (s).
    run : int
        Which run to write.

    Returns
    -------
    Path

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from fdikit import Signals
    >>> from fdikit.io import read_csv
    >>> s = Signals(np.arange(3) * 0.1, [[1.0, 2.0], [np.nan, 0.5], [3.0, 1e-12]], ["a", "b"], check=False)
    >>> p = write_csv(s, os.path.join(tempfile.mkdtemp(), "log.csv"))
    >>> r = read_csv(p)
    >>> np.array_equal(r.values, s.values, equal_nan=True), r.valid[0, :, 0].tolist()
    (True, [True, False, True])
    """
    p = _prepare(signals, path, time, run, (".csv",))
    v = signals.values[run]
    header = ",".join([time, *signals.names])
    if any("," in n or '"' in n or "\n" in n for n in [time, *signals.names]):
        raise DataError(f"channel names for CSV must not hold commas, quotes or line breaks: {signals.names}")
    cols = np.column_stack([signals.t, v])
    # repr of a float64 is the shortest string that reads back to the same number
    lines = [header]
    lines += [",".join(map(repr, row)) for row in cols.tolist()]
    text = "\n".join(lines) + "\n"
    with open_output(p, "w") as fh:
        fh.write(text)
    return p


def write_parquet(signals: Signals, path: str | os.PathLike, *, time: str = "t", run: int = 0) -> Path:
    """Write one run of ``signals`` as a Parquet table, with each channel's unit in its metadata.

    Parameters
    ----------
    signals : Signals
    path : path-like
        A ``.parquet`` (or ``.pq``) file (its folder must exist).
    time : str
        Name of the time column (s, float64).
    run : int
        Which run to write.

    Returns
    -------
    Path

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from fdikit import Signals
    >>> from fdikit.io import read_parquet
    >>> s = Signals(np.arange(4) * 0.5, np.arange(8.0).reshape(4, 2), ["v", "w"], ["m/s", "rad/s"])
    >>> p = write_parquet(s, os.path.join(tempfile.mkdtemp(), "log.parquet"))
    >>> r = read_parquet(p)
    >>> np.array_equal(r.values, s.values), r.units
    (True, ['m/s', 'rad/s'])
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    p = _prepare(signals, path, time, run, (".parquet", ".pq"))
    v = signals.values[run]
    fields = [pa.field(time, pa.float64(), metadata={"unit": "s"})]
    arrays = [pa.array(signals.t, pa.float64())]
    for j, (n, u) in enumerate(zip(signals.names, signals.units)):
        fields.append(pa.field(n, pa.float64(), metadata={"unit": u} if u else None))
        arrays.append(pa.array(np.ascontiguousarray(v[:, j]), pa.float64()))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields))
    with open_output(p, "wb") as fh:
        pq.write_table(table, fh)
    return p
