"""The Vector ASC reader."""

from __future__ import annotations

from pathlib import Path

from .frames import frames_to_signals
from .grid import LoadedSignals
from .textlog import _read_text_frames


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
