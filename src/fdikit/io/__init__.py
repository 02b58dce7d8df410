"""Loaders for recorded vehicle data, all onto the same :class:`~fdikit.Signals` grid.

* :func:`read_log` — any supported log, chosen by extension or content: Vector BLF and ASC,
  candump, MDF4 (decoded channels, or raw CAN frames decoded with a DBC), Parquet and CSV tables;
* :func:`read_can_log` — a CAN log decoded with a DBC onto one time grid;
* :func:`read_ulog`, :func:`read_rosbag`, :func:`read_topic_folder` — flight and robot logs (PX4
  ULog, ROS 1 / ROS 2 / MCAP bags, a folder of per-topic CSVs) whose topics come at several rates,
  gridded causally by :func:`topics_to_grid` (zero-order hold plus each topic's age; linear
  interpolation only on request, marked non-causal: :class:`MultiRateSignals`);
* :func:`read_csv` — a CSV recording;
* per-format readers :func:`read_blf`, :func:`read_asc`, :func:`read_candump`, :func:`read_mdf`,
  :func:`read_parquet`, :func:`read_table_csv`;
* :class:`FrameGridder` and :func:`parse_candump_line` — live CAN frames (e.g. ``candump -L``)
  onto the same grid as they arrive, with the batch loader's arithmetic;
* :mod:`fdikit.io.decode` — the vectorised CAN path under the frame readers: a BLF file as a
  frame table (:func:`read_blf_table`), DBC signals decoded per message id over all its frames
  (:func:`decode_message`, equal to cantools frame by frame), and the inverses for generated or
  fault-injected logs (:func:`set_signal`, :func:`write_blf_table`).

They return :class:`LogSignals` (or its subclass :class:`LoadedSignals`), a Signals whose values
may hold NaN where the source had a gap or a bad sample; ``valid`` marks the samples that hold
data and ``info`` reports per-signal quality (rates, gaps, duplicates, stuck stretches). Gaps
are never interpolated across (see :mod:`fdikit.io.can`); a loaded log says why each invalid
grid sample is invalid (:meth:`LoadedSignals.invalid_reason`).

Time columns (:mod:`fdikit.io.timebase`): ``time_unit="auto" | "s" | "ms" | "us" | "ns"``; an
absolute clock (UNIX epoch, ROS nanoseconds) is rebased exactly to start at 0 and its origin kept
in ``t0`` (s) and ``time_origin`` (:class:`TimeOrigin`, exact).
"""

from .can import LogSignals, SignalInfo, convert_units, resample_to_grid
from .csv import read_csv
from .decode import FramePayloads, decode_message, read_blf_table, set_signal, write_blf_table
from .formats import (
    FORMATS,
    LoadedSignals,
    MultiRateSignals,
    SignalQuality,
    SourceReport,
    detect_format,
    frames_to_signals,
    read_asc,
    read_blf,
    read_can_log,
    read_candump,
    read_log,
    read_mdf,
    read_parquet,
    read_rosbag,
    read_table_csv,
    read_topic_folder,
    read_ulog,
    series_to_grid,
    topics_to_grid,
)
from .stream import FrameGridder, parse_candump_line
from .timebase import TIME_UNITS, StreamTimes, TimeOrigin, times_to_seconds
from .write import write_csv, write_parquet

__all__ = [
    "FORMATS",
    "TIME_UNITS",
    "FrameGridder",
    "FramePayloads",
    "LoadedSignals",
    "LogSignals",
    "MultiRateSignals",
    "SignalInfo",
    "SignalQuality",
    "SourceReport",
    "StreamTimes",
    "TimeOrigin",
    "convert_units",
    "decode_message",
    "detect_format",
    "frames_to_signals",
    "parse_candump_line",
    "read_asc",
    "read_blf",
    "read_blf_table",
    "read_can_log",
    "read_candump",
    "read_csv",
    "read_log",
    "read_mdf",
    "read_parquet",
    "read_rosbag",
    "read_table_csv",
    "read_topic_folder",
    "read_ulog",
    "resample_to_grid",
    "series_to_grid",
    "set_signal",
    "times_to_seconds",
    "topics_to_grid",
    "write_blf_table",
    "write_csv",
    "write_parquet",
]
