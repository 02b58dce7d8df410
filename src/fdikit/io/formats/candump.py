"""The candump ``-L`` log reader."""

from __future__ import annotations

from pathlib import Path

from .frames import frames_to_signals
from .grid import LoadedSignals
from .textlog import _read_text_frames


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
    ([0.0, 0.05, 0.1], [[10.0, 10.0, 20.0]], 2)
    """
    ts, ids, data, lines, chans, src = _read_text_frames(path, "candump", strict=True)
    return frames_to_signals(ts, ids, data, dbc, signals, rate, lines=lines, channels=chans, source=src,
                             where=f"candump log {Path(path).name!r}", **kw)
