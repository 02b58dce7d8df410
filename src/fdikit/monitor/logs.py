"""How a config's ``[log]`` table reads a recorded log: its format, time column, time unit, DBC and
rate, the same on every route (``fdikit monitor``, ``fdikit design`` from logs, the fleet).

``[log].format`` is ``"auto"`` (by the file's suffix, else its first bytes), ``"csv"`` (a plain
CSV recording on its own time stamps, :func:`fdikit.io.read_csv`), ``"can"`` (a CAN frame log:
BLF, ASC or candump, recognised by its content whatever its name, decoded with ``[log].dbc``), or
one format of :data:`fdikit.io.formats.FORMATS` by name (``"candump"``, ``"parquet"``, ``"mdf"``,
...), which is then read as that format whatever the file is called. ``[log].time`` names the
time column of every table format (CSV, Parquet, topic folders, ROS bags); ``[log].time_unit``
its unit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..base.paths import config_path
from ..errors import DataError

__all__ = ["FRAME_FORMATS", "LOG_FORMATS", "check_log_table", "log_format", "read_options"]

#: ``[log].format`` values: the config's own ("auto", "csv", "can") and every reader's name.
LOG_FORMATS = ("auto", "csv", "can", "blf", "asc", "candump", "parquet", "mdf", "ulog", "rosbag", "topics")
#: CAN frame log formats (decoded with a DBC).
FRAME_FORMATS = ("blf", "asc", "candump")
#: Formats whose reader takes ``time=`` (the name of a time column).
_TIME_COLUMN = ("csv", "parquet", "topics", "rosbag")


def check_log_table(log: Mapping[str, Any], where: str = "config") -> None:
    """Refuse a ``[log].format`` that no reader has (naming the value and the known ones)."""
    fmt = log.get("format", "auto")
    if fmt not in LOG_FORMATS:
        raise DataError(f"{where}: [log].format must be one of {list(LOG_FORMATS)} ('can': a CAN frame "
                        f"log, BLF, ASC or candump, by its content), got {fmt!r}")


def log_format(log: Mapping[str, Any], path: str | Path) -> str:
    """The reader a ``[log]`` table picks for ``path``: ``"recording"`` (a plain CSV recording,
    :func:`fdikit.io.read_csv`) or a key of :data:`fdikit.io.formats.FORMATS`.

    Parameters
    ----------
    log : mapping
        The config's ``[log]`` table.
    path : path-like
        The log file (or folder).

    Returns
    -------
    str

    Raises
    ------
    DataError
        A declared format the file is not (``"can"`` for a file that is no CAN frame log).

    Examples
    --------
    >>> log_format({}, "drive.csv"), log_format({"format": "parquet"}, "drive.bin")
    ('recording', 'parquet')
    """
    from ..io.formats import detect_format

    fmt = log.get("format", "auto")
    if fmt == "csv" or (fmt == "auto" and Path(path).suffix.lower() == ".csv"):
        return "recording"
    if fmt == "can":
        return detect_format(path, among=FRAME_FORMATS)
    if fmt == "auto":
        return detect_format(path)
    return str(fmt)


def read_options(log: Mapping[str, Any], path: str | Path, base_dir: str | Path, *,
                 signals: Sequence[str] | None = None, time: str | None = None,
                 tables_as_recordings: bool = True, where: str = "config") -> tuple[str, dict[str, Any]]:
    """The reader and its keyword arguments for one log, as the ``[log]`` table declares them.

    Parameters
    ----------
    log : mapping
        The config's ``[log]`` table (``format``, ``time``, ``time_unit``, ``dbc``, ``rate``,
        ``resample``).
    path : path-like
        The log.
    base_dir : path-like
        The config's folder (``[log].dbc`` is relative to it).
    signals : sequence of str, optional
        The channels to read (needed for CAN frame logs).
    time : str, optional
        A time column that overrides ``[log].time`` (e.g. ``[design.plant.identify].time``).
    tables_as_recordings : bool
        A ``.csv`` file (or ``format = "csv"``) is a plain recording for :func:`fdikit.io.read_csv`
        (``fdikit monitor``); False: the table reader of :func:`fdikit.io.read_log` (the design
        route, which reads every column).
    where : str
        The config, for messages.

    Returns
    -------
    (str, dict)
        ``"recording"`` with the :func:`fdikit.io.read_csv` keywords, or a format key with the
        :func:`fdikit.io.read_log` keywords (``format``, ``dbc``, ``signals``, ``rate`` and the
        table options).

    Examples
    --------
    >>> read_options({"format": "parquet", "time": "stamp"}, "drive.bin", ".", signals=["v"])
    ('parquet', {'format': 'parquet', 'signals': ['v'], 'rate': None, 'time': 'stamp'})
    """
    fmt = log_format(log, path)
    time = time if time is not None else log.get("time")
    if fmt == "recording":
        if not tables_as_recordings:
            fmt = "csv"
        else:
            kw: dict[str, Any] = {"time": time or "t", "columns": None if signals is None else list(signals),
                                  "rate": log.get("rate")}
            if "time_unit" in log:
                kw["time_unit"] = str(log["time_unit"])
            if "resample" in log:
                kw["method"] = str(log["resample"])
            return fmt, kw
    kw = {"format": fmt}
    if tables_as_recordings or fmt in (*FRAME_FORMATS, "mdf"):
        kw["signals"] = None if signals is None else list(signals)   # MDF and CAN need their names
    if tables_as_recordings or fmt in FRAME_FORMATS:
        kw["rate"] = log.get("rate")
    dbc = log.get("dbc")
    if fmt in FRAME_FORMATS and not dbc:
        raise DataError(f"{where}: the {fmt} CAN frame log {Path(path).name!r} needs [log].dbc (the DBC "
                        "that decodes it)")
    if dbc and (fmt in FRAME_FORMATS or fmt == "mdf"):
        kw["dbc"] = config_path(base_dir, dbc, where=f"{where}: [log].dbc")
    if time is not None and fmt in _TIME_COLUMN:
        kw["time"] = time
    if "time_unit" in log:
        kw["time_unit"] = str(log["time_unit"])   # io.read_log refuses a unit its format cannot honour
    if "resample" in log:
        kw["method"] = str(log["resample"])       # the causal hold unless linear is asked for
    return fmt, kw
