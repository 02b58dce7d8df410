"""More log formats onto the same grid: Vector ASC, candump, Parquet, CSV tables, MDF4, PX4 ULog, ROS
bags, folders of per-topic CSVs, and one dispatcher.

Every reader here returns a :class:`LoadedSignals` (a :class:`~fdikit.io.LogSignals`) built by the
same two steps as :func:`fdikit.io.read_can_log`:

* **frame logs** (Vector BLF and ASC, candump ``.log``, raw CAN frames in MDF4) are decoded per
  message with the DBC (:func:`frames_to_signals`; MDF4 bus logging is decoded by asammdf's
  ``extract_bus_logging``), with time 0 at the first frame of the log;
* **decoded-signal files** (Parquet, CSV tables, MDF4 with signal channels) keep the file's own
  time axis (a datetime column counts seconds from its first row);

then each signal is resampled onto one uniform grid at ``rate`` Hz without bridging gaps longer
than ``max_gap`` source periods (:func:`series_to_grid`, which calls
:func:`fdikit.io.resample_to_grid`).

**Topic logs** (PX4 ULog :func:`read_ulog`, ROS 1 / ROS 2 / MCAP bags :func:`read_rosbag`, a folder
of per-topic CSVs :func:`read_topic_folder`) hold topics at several rates. They are gridded by
:func:`topics_to_grid` (:mod:`.multirate`) with a **causal** default: zero-order hold of each
topic's last message, plus one ``"<topic>.__age__"`` channel (seconds since that message); linear
interpolation only on request (``method="linear"``), and then the result says it is not causal
(:attr:`MultiRateSignals.causal` is ``False``), so a monitor following a live log can refuse it.

**The gridding rule.** A grid value that uses a sample after its own time (linear
interpolation) cannot be computed live, and a detector on such a grid dates its decisions before
the data they rest on. Every reader (CAN, CSV, Parquet, MDF4 and the topic logs) therefore holds
each signal's last sample by default (``method="previous"``, causal: a sample at most
:data:`fdikit.io.can.HOLD_TOL` = 1 ns after a grid time counts as at it); linear interpolation is
there on request (``method="linear"``, ``[log] resample = "linear"`` in a monitor config, which
follow mode refuses). The simulated papers' numbers never pass through a reader.

Bad-input policy (never crash, never lie)
-----------------------------------------
* What cannot be trusted before processing -- a missing, truncated or corrupt file, an unknown
  format, a time axis that goes backwards, a missing channel, a DBC without a requested signal,
  an impossible unit conversion, a text line that is neither a frame nor a known event, a
  message seen on several CAN buses without ``channel=`` (ASC, candump, MDF4; the BLF frame
  reader does not report buses) -- raises :class:`~fdikit.errors.DataError` naming the file,
  line / row / frame and the values.
* Bad *samples* are kept as NaN source samples, so every grid sample whose interpolation touches
  them is flagged ``valid == False``: NaN or inf values, frames too short for a signal or that
  cannot be decoded, two frames of one message at the same time with different payloads.
  Their counts are in :class:`SignalQuality` (``info[name]``).
* Exact duplicates (same time, same payload or value) are merged, and counted (``n_duplicates``).
* A stuck signal (constant for at least ``stuck_after`` seconds) is reported in ``info``
  (``stuck``, ``longest_constant``), not refused: a constant signal can be real.

Time precision: ASC and candump store timestamps with 6 decimals, so each frame time and the grid
start move by up to 0.5 us, and a grid value read from them differs from the BLF path by about
``max |dv/dt| * 1 us`` (the tests allow ``2 us``).

Layout, one module per concept: :mod:`.registry` (the formats, :func:`detect_format`,
:func:`read_log`, :func:`read_can_log`); one module per reader (:mod:`.blf`, :mod:`.asc`,
:mod:`.candump`, :mod:`.parquet`, :mod:`.csv_table`, :mod:`.mdf`, :mod:`.ulog`, :mod:`.rosbag`,
:mod:`.topics`); the causal multi-rate grid of topic logs (:mod:`.multirate`); what readers share
(:mod:`.frames`: CAN frames decoded onto the grid, :mod:`.textlog`: text frame logs,
:mod:`.table`: decoded-signal tables, :mod:`.checks`: argument checks); and the grid step with
its result types (:mod:`.grid`).
"""

from .asc import read_asc
from .blf import read_blf
from .candump import read_candump
from .csv_table import read_table_csv
from .frames import frames_to_signals
from .grid import MAX_GRID as MAX_GRID
from .grid import LoadedSignals, SignalQuality, SourceReport, series_to_grid
from .grid import _longest_constant as _longest_constant  # used by the tests
from .grid import _longest_constant_rows as _longest_constant_rows
from .mdf import read_mdf
from .multirate import AGE_SUFFIX, MultiRateSignals, topics_to_grid
from .parquet import read_parquet
from .registry import FORMATS, detect_format, read_can_log, read_log
from .rosbag import read_rosbag
from .topics import read_topic_folder
from .ulog import read_ulog

__all__ = [
    "AGE_SUFFIX",
    "FORMATS",
    "LoadedSignals",
    "MultiRateSignals",
    "SignalQuality",
    "SourceReport",
    "detect_format",
    "frames_to_signals",
    "read_asc",
    "read_blf",
    "read_can_log",
    "read_candump",
    "read_log",
    "read_mdf",
    "read_parquet",
    "read_rosbag",
    "read_table_csv",
    "read_topic_folder",
    "read_ulog",
    "series_to_grid",
    "topics_to_grid",
]
