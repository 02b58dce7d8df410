"""Loaders for recorded vehicle data.

* :func:`read_can_log` — a CAN log (Vector BLF, ASC, ...) decoded with a DBC onto one time grid;
* :func:`read_csv` — a CSV recording.

Both return :class:`LogSignals`, a :class:`~fdikit.Signals` whose values may hold NaN where the
source had a gap; ``LogSignals.valid`` marks the samples that hold data (see
:mod:`fdikit.io.can` for the convention). Gaps are never interpolated across.
"""

from .can import LogSignals, SignalInfo, convert_units, read_can_log, resample_to_grid
from .csv import read_csv

__all__ = ["LogSignals", "SignalInfo", "convert_units", "read_can_log", "read_csv", "resample_to_grid"]
