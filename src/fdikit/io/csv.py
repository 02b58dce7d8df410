"""CSV recordings: one time column and numeric channels, with the same gap convention as CAN logs."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import DataError
from .can import LogSignals, SignalInfo, convert_units, resample_to_grid

__all__ = ["read_csv"]


def read_csv(
    path: str | os.PathLike,
    time: str = "t",
    columns: Sequence[str] | None = None,
    *,
    units: Mapping[str, str] | None = None,
    convert: Mapping[str, str] | None = None,
    rate: float | None = None,
    max_gap: float = 3.0,
) -> LogSignals:
    """Read a CSV recording into :class:`~fdikit.io.LogSignals`.

    Parameters
    ----------
    path : path-like
        A comma-separated file with a header row.
    time : str
        Name of the time column (seconds); must be strictly increasing.
    columns : sequence of str, optional
        Channels to keep (default: every column but ``time``).
    units : mapping, optional
        Unit of each channel as recorded (default ``""``).
    convert : mapping, optional
        Target unit per channel (see :func:`fdikit.io.convert_units`); needs ``units``.
    rate : float, optional
        Resample onto a uniform grid at this rate (Hz) without bridging gaps longer than
        ``max_gap`` median periods. Default: keep the file's own time stamps.
    max_gap : float
        See :func:`fdikit.io.resample_to_grid`.

    Returns
    -------
    LogSignals
        One run; empty cells (NaN) are flagged ``valid == False``, never filled.

    Raises
    ------
    DataError
        Missing file, missing time column or channel, non-numeric cells, time not strictly
        increasing (naming the row).

    Examples
    --------
    >>> from fdikit.io import read_csv
    >>> s = read_csv("imu.csv", time="t_s", columns=["gyro_z_rad_s"],
    ...              units={"gyro_z_rad_s": "rad/s"})  # doctest: +SKIP
    """
    import pandas as pd

    p = Path(path)
    if not p.exists():
        raise DataError(f"CSV file {str(p)!r} does not exist")
    try:
        df = pd.read_csv(p)
    except Exception as exc:
        raise DataError(f"cannot parse {str(p)!r} as CSV: {type(exc).__name__}: {exc}") from None
    if time not in df.columns:
        raise DataError(f"CSV {p.name!r} has no time column {time!r}; columns: {list(df.columns)}")
    cols = [c for c in df.columns if c != time] if columns is None else list(columns)
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise DataError(f"CSV {p.name!r} has no column(s) {missing}; columns: {list(df.columns)}")
    for c in [time, *cols]:
        if not np.issubdtype(df[c].dtype, np.number):
            bad = pd.to_numeric(df[c], errors="coerce").isna() & df[c].notna()
            row = int(np.flatnonzero(bad.to_numpy())[0]) if bad.any() else 0
            raise DataError(f"CSV {p.name!r} column {c!r} is not numeric "
                            f"(data row {row}: {df[c].iloc[row]!r})")
    t = df[time].to_numpy(float)
    if np.isnan(t).any():
        row = int(np.flatnonzero(np.isnan(t))[0])
        raise DataError(f"CSV {p.name!r}: time column {time!r} is empty at data row {row}")
    d = np.diff(t)
    if (d <= 0).any():
        k = int(np.flatnonzero(d <= 0)[0]) + 1
        raise DataError(f"CSV {p.name!r}: time {time!r} is not strictly increasing at data row {k} "
                        f"({t[k - 1]!r} then {t[k]!r})")
    units = dict(units or {})
    for k in units:
        if k not in cols:
            raise DataError(f"unit given for {k!r}, which is not a selected column {cols}")
    v = df[cols].to_numpy(float)
    out_units = [units.get(c, "") for c in cols]
    for k, target in (convert or {}).items():
        if k not in cols:
            raise DataError(f"conversion given for {k!r}, which is not a selected column {cols}")
        j = cols.index(k)
        v[:, j] = convert_units(v[:, j], out_units[j], target, channel=k)
        out_units[j] = target
    per = float(np.median(d)) if d.size else np.inf
    info = {}
    if rate is not None:
        n = int(np.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
        grid = t[0] + np.arange(n) / float(rate)
        vals = np.empty((n, len(cols)))
        ok = np.empty((n, len(cols)), bool)
        for j in range(len(cols)):
            fin = np.isfinite(v[:, j])
            vals[:, j], ok[:, j] = resample_to_grid(t[fin], v[fin, j], grid, max_gap=max_gap, period=per)
        t_out, v_out, valid = grid, vals, ok
    else:
        t_out, v_out, valid = t, v, np.isfinite(v)
    for j, c in enumerate(cols):
        mean_rate = float((t.size - 1) / (t[-1] - t[0])) if t.size > 1 else float("nan")
        info[c] = SignalInfo(c, units.get(c, ""), out_units[j], int(np.isfinite(v[:, j]).sum()), mean_rate,
                             per, float(t[0]), float(t[-1]), int(np.sum(d > max_gap * per)),
                             int((~valid[:, j]).sum()))
    return LogSignals(t_out, v_out, cols, out_units, valid=valid, info=info)
