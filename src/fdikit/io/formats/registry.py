"""The format registry and dispatcher: which formats exist, how a file's is detected, :func:`read_log`."""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ...base.inputs import is_stream, spooled, stream_kind
from ...errors import DataError
from ..can import LogSignals
from .asc import read_asc
from .blf import read_blf
from .candump import read_candump
from .checks import _check_file
from .csv_table import read_table_csv
from .grid import _COMMON_OPTIONS, LoadedSignals
from .mdf import read_mdf
from .parquet import read_parquet
from .rosbag import read_rosbag
from .topics import read_topic_folder
from .ulog import read_ulog

#: Format names understood by :func:`read_log` and the file suffixes that select them.
FORMATS: dict[str, tuple[str, ...]] = {
    "blf": (".blf",),
    "asc": (".asc",),
    "candump": (".log", ".candump"),
    "parquet": (".parquet", ".pq"),
    "csv": (".csv",),
    "mdf": (".mf4", ".mdf", ".mf3", ".dat"),
    "ulog": (".ulg", ".ulog"),
    "rosbag": (".bag", ".db3", ".mcap"),
    "topics": (),  # a folder of per-topic CSV files
}
_FRAME_FORMATS = ("blf", "asc", "candump")
#: Formats of topics at several rates, gridded by zero-order hold (causal) by default.
_TOPIC_FORMATS = ("ulog", "rosbag", "topics")
#: First bytes of each binary format.
_MAGIC = ((b"LOGG", "blf"), (b"PAR1", "parquet"), (b"MDF ", "mdf"), (b"ULog\x01\x12\x35", "ulog"),
          (b"#ROSBAG V2.0", "rosbag"), (b"\x89MCAP0\r\n", "rosbag"))


_CANDUMP_LINE = re.compile(r"^\(\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]+#")


def detect_format(path, *, among: Sequence[str] | None = None) -> str:
    """The format of a log file or folder, by suffix, else by its first bytes.

    A folder is a ROS 2 bag when it holds ``metadata.yaml``, else a folder of per-topic CSV files
    (``"topics"``) when it holds ``*.csv`` files. A file is recognised by its suffix, else by its
    magic bytes: BLF ``LOGG``, Parquet ``PAR1``, MDF ``MDF``, ULog ``ULog\\x01\\x12\\x35``, ROS 1
    bag ``#ROSBAG V2.0``, MCAP ``\\x89MCAP0\\r\\n``, else the first text line (ASC, candump).
    A stream (a FIFO, a pipe: :func:`fdikit.base.inputs.is_stream`) is recognised by its suffix
    only: sniffing would take its first bytes from the reader.

    Parameters
    ----------
    path : path-like
        The log file or folder.
    among : sequence of str, optional
        The formats the caller declared (e.g. the CAN frame logs ``("blf", "asc", "candump")`` of
        a config's ``[log] format = "can"``): the suffix counts only when it names one of them,
        else the content decides (a candump log named ``.csv``), and a file of none of them is
        refused.

    Returns
    -------
    str
        A key of :data:`FORMATS`.

    Raises
    ------
    DataError
        Missing file, or neither the suffix nor the content is a known format (or one of
        ``among``), or a stream whose suffix names no format.

    Examples
    --------
    >>> detect_format("drive.blf")  # doctest: +SKIP
    'blf'
    """
    d = Path(path)
    if d.is_dir():
        if (d / "metadata.yaml").is_file():
            return "rosbag"
        if any(d.glob("*.csv")):
            return "topics"
        raise DataError(f"log {str(d)!r} is a directory, not a file, and neither a ROS 2 bag (no "
                        "metadata.yaml) nor a folder of per-topic CSV files (no *.csv)")
    kind = stream_kind(path)
    p = Path(path) if kind else _check_file(path, "log")
    suffix = p.suffix.lower()
    if among is not None:
        unknown = [f for f in among if f not in FORMATS]
        if unknown:
            raise DataError(f"unknown log format(s) {unknown}; known formats: {sorted(FORMATS)}")
    for fmt, sufs in FORMATS.items():
        if suffix in sufs and (among is None or fmt in among):
            return fmt
    if kind:   # its first bytes would be taken from the reader that comes next
        raise DataError(f"log {p.name!r} is a {kind}: its format cannot be told from its first bytes "
                        "without consuming them; name the format (format=, or [log].format in a config), "
                        "or read it with fdikit.io.read_log, which reads such an input once")
    with open(p, "rb") as fh:
        head = fh.read(4096)
    found = None
    for magic, fmt in _MAGIC:
        if head.startswith(magic):
            found = fmt
            break
    if found is None:
        text = head.decode("utf-8", "replace").lstrip()
        first = text.splitlines()[0] if text else ""
        if re.match(r"(date|base|begin\s+triggerblock)\s", first, re.IGNORECASE):
            found = "asc"
        elif _CANDUMP_LINE.match(first):
            found = "candump"
    if among is not None:
        if found in among:
            return found
        raise DataError(f"log {p.name!r} was declared one of {list(among)}, but its first bytes "
                        f"{head[:24]!r} are none of them"
                        + (f" (it looks like a {found} log)" if found else ""))
    if found is not None:
        return found
    raise DataError(f"unknown log format for {p.name!r}: the suffix {suffix!r} is none of "
                    f"{sorted(s for v in FORMATS.values() for s in v)} and the first bytes "
                    f"{head[:16]!r} are not BLF, Parquet, MDF, ULog, ROS bag, MCAP, ASC or candump")


_FORMAT_OPTIONS = {"blf": ("plausibility",), "asc": ("strict", "encoding", "channel", "plausibility"),
                   "candump": ("channel", "plausibility"),
                   "parquet": ("time", "source_units", "time_unit", "rebase"),
                   "csv": ("time", "source_units", "time_unit", "rebase"), "mdf": ("channel",),
                   "ulog": ("strict", "source_units", "max_age", "age"),
                   "rosbag": ("time", "source_units", "max_age", "age"),
                   "topics": ("time", "source_units", "time_unit", "max_age", "age", "pattern")}


def read_log(path, dbc=None, signals=None, rate=None, *, format: str | None = None, **kw) -> LoadedSignals:
    """Read any supported log onto one grid: the one entry point of :mod:`fdikit.io`.

    Parameters
    ----------
    path : path-like
        A Vector BLF or ASC log, a candump log, a Parquet or CSV table of decoded signals, an
        MDF4 file (decoded channels or raw CAN bus logging), a PX4 ULog file, a ROS 1 bag, a
        ROS 2 bag (folder, ``.db3`` or ``.mcap``), or a folder of per-topic CSV files. A FIFO or
        pipe is read whole first, interruptibly, into a temporary file of its name
        (:func:`fdikit.base.inputs.spooled`); ``source.path`` still names it.
    dbc : path-like or cantools Database, optional
        Needed for frame logs (BLF, ASC, candump, raw CAN in MDF4).
    signals : sequence of str
        Channels: ``"MESSAGE.SIGNAL"`` for frame logs, column / channel names otherwise
        (default for tables: every column but time).
    rate : float, optional
        Grid rate (Hz); default the fastest median source rate.
    format : str, optional
        Force a format (a key of :data:`FORMATS`) instead of detecting it.
    **kw
        Passed to the reader: ``units``, ``max_gap``, ``method``, ``span``, ``stuck_after``;
        ``time``, ``source_units``, ``time_unit`` (``"auto"``, ``"s"``, ``"ms"``, ``"us"``,
        ``"ns"``) and ``rebase`` for tables (:mod:`fdikit.io.timebase`: an absolute time axis is
        rebased exactly to start at 0, its origin kept in ``t0`` and ``time_origin``; frame
        logs always start at their first frame, ``t0`` its time); ``strict`` and ``encoding`` for ASC;
        ``channel`` for ASC, candump and MDF4 bus logging; ``plausibility`` (range and spike
        rules per signal, applied to each frame before resampling) for the CAN frame logs (BLF,
        ASC, candump); ``max_age``, ``age``,
        ``source_units`` for the topic logs (ULog, ROS bags, topic folders), with ``strict`` for
        ULog, ``time`` for ROS bags and topic folders, ``time_unit`` and ``pattern`` for topic
        folders. An option that does not apply to the detected format is a
        :class:`~fdikit.errors.DataError`.

    Notes
    -----
    Every reader holds each signal's last sample by default (``method="previous"``, causal:
    no grid value depends on a later sample); ``method="linear"`` interpolates with the next
    sample (non-causal). The topic logs (ULog, ROS bags, topic folders) add each topic's age and
    mark a linear grid non-causal (:mod:`fdikit.io.formats.multirate`).

    Returns
    -------
    LoadedSignals

    Raises
    ------
    DataError
        Unknown format (naming the suffix and first bytes), no DBC for a frame log, and every
        error of the chosen reader.

    Examples
    --------
    >>> from fdikit.io.formats import read_log
    >>> s = read_log("drive.asc", "toyota_rav4.dbc", ["SPEED.SPEED"], rate=50)  # doctest: +SKIP
    >>> read_log("drive.vsb", "toyota_rav4.dbc", ["SPEED.SPEED"])
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: log 'drive.vsb' does not exist
    """
    if is_stream(path):   # a FIFO or pipe: read once, interruptibly, into a file of its name
        with spooled(path) as src:
            out = read_log(src, dbc, signals, rate, format=format, **kw)
        if getattr(out, "source", None) is not None:
            out.source = dataclasses.replace(out.source, path=str(path))
        return out
    if format is None:
        fmt = detect_format(path)
    else:
        if format not in FORMATS:
            raise DataError(f"unknown log format {format!r}; known formats: {sorted(FORMATS)}")
        fmt = format
    if fmt not in ("csv", "parquet", "topics"):
        # frame logs and MDF count seconds (python-can, asammdf) and start at their first frame
        unit = kw.pop("time_unit", "auto")
        if unit not in ("auto", "s"):
            raise DataError(f"{Path(path).name!r} is a {fmt} log, whose time stamps are seconds; "
                            f"time_unit={unit!r} applies to CSV and Parquet tables only")
        if kw.pop("rebase", None) is False:
            raise DataError(f"{Path(path).name!r} is a {fmt} log: its time always starts at its first "
                            "frame or sample (rebase=False applies to CSV and Parquet tables only)")
    allowed = set(_COMMON_OPTIONS) | set(_FORMAT_OPTIONS[fmt])
    unknown = sorted(set(kw) - allowed)
    if unknown:
        raise DataError(f"option(s) {unknown} do not apply to a {fmt} log {Path(path).name!r}; "
                        f"its options are {sorted(allowed)}")
    if fmt in _TOPIC_FORMATS:
        if dbc is not None:
            raise DataError(f"{Path(path).name!r} is a {fmt} log of topics: it takes no DBC (dbc=)")
        reader = {"ulog": read_ulog, "rosbag": read_rosbag, "topics": read_topic_folder}[fmt]
        return reader(path, signals, rate, **kw)
    if fmt in _FRAME_FORMATS:
        if dbc is None:
            raise DataError(f"{Path(path).name!r} is a {fmt} CAN frame log: pass dbc= to decode it")
        reader = {"blf": read_blf, "asc": read_asc, "candump": read_candump}[fmt]
        return reader(path, dbc, signals, rate, **kw)
    if fmt == "parquet":
        return read_parquet(path, signals, rate, **kw)
    if fmt == "csv":
        return read_table_csv(path, signals, rate, **kw)
    return read_mdf(path, signals, rate, dbc=dbc, **kw)


def read_can_log(
    path: str | os.PathLike,
    dbc: Any,
    signals: Sequence[str],
    rate: float | None = None,
    *,
    units: str | Mapping[str, str] | None = None,
    max_gap: float = 3.0,
    method: str = "previous",
    span: str = "common",
    plausibility: Mapping[str, Any] | None = None,
) -> LogSignals:
    """Read a CAN log, decode the chosen signals with a DBC and put them on one time grid.

    Parameters
    ----------
    path : path-like
        The log (``.blf``, ``.asc``, ``.csv``, ``.trc``, ... as :class:`can.LogReader` knows).
    dbc : path-like or cantools Database
        The DBC (loaded with ``strict=False``: overlapping signals are allowed).
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names, e.g. ``["KINEMATICS.YAW_RATE", "SPEED.SPEED"]``.
    rate : float, optional
        Grid rate in Hz; default the highest median source rate among the chosen signals.
    units : "si" or mapping, optional
        Unit conversion: ``"si"`` converts every signal with a known SI target (km/h -> m/s,
        deg -> rad, deg/s -> rad/s, rpm -> rad/s, % -> 1); a mapping gives a target unit per
        signal name. Default: the DBC's units.
    max_gap : float
        Longest frame interval, in that signal's median source periods, that is interpolated
        across; longer gaps become NaN with ``valid == False`` (see the module docstring).
    method : {"previous", "linear"}
        Zero-order hold of the last frame (causal, the default), or linear interpolation between
        the neighbouring frames (uses the next frame: not causal).
    span : {"common", "log"}
        Grid from the latest first frame to the earliest last frame of the chosen signals
        (default; no leading/trailing NaN), or over the whole log (channels are invalid outside
        their recorded span). Time 0 is the first frame of the log either way.
    plausibility : mapping of str -> Plausibility or mapping, optional
        Range and spike rules per signal (in its returned unit) applied to each frame before
        resampling (:mod:`fdikit.io.formats.raw_checks`): an implausible frame flags the grid
        samples it would touch.

    Returns
    -------
    LogSignals
        One run, ``T`` samples at ``rate`` Hz, one channel per requested signal (named as
        requested), units from the DBC (or converted), ``valid`` mask and per-signal
        :class:`SignalInfo` in ``info``.

    Raises
    ------
    DataError
        Missing / not-a-log / truncated / corrupt file; a DBC without the requested message or
        signal (with close matches); a requested message with no frames in the log; an
        impossible unit conversion.

    Examples
    --------
    >>> from fdikit.io import read_can_log
    >>> s = read_can_log("drive.blf", "toyota_rav4.dbc",
    ...                  ["KINEMATICS.YAW_RATE", "SPEED.SPEED"], rate=50, units="si")  # doctest: +SKIP
    >>> s.units  # doctest: +SKIP
    ['rad/s', 'm/s']
    """
    # one frame-to-grid path for every log format: fdikit.io.formats (stricter bad-input policy:
    # short payloads are flagged, never zero-padded; conflicting duplicates are flagged; a
    # corrupt container is a DataError)
    kw = {} if plausibility is None else {"plausibility": plausibility}
    return read_log(path, dbc, signals, rate, units=units, max_gap=max_gap, method=method, span=span, **kw)
