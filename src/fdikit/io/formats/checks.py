"""The checks every log reader makes of its arguments before reading: the file, the signal list."""

from __future__ import annotations

import csv as _csv
from pathlib import Path

from ...errors import DataError


def _check_file(path, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{what} {str(p)!r} does not exist")
    if p.is_dir():
        raise DataError(f"{what} {str(p)!r} is a directory, not a file")
    if p.stat().st_size == 0:
        raise DataError(f"{what} {str(p)!r} is empty (0 bytes)")
    return p


def _check_signal_list(signals) -> list[str]:
    if signals is None:
        raise DataError("name the signals to read: signals=['MESSAGE.SIGNAL', ...]")
    if isinstance(signals, str):
        signals = [signals]
    signals = list(signals)
    if not signals:
        raise DataError("no signals requested")
    for s in signals:
        if not isinstance(s, str):
            raise DataError(f"signal names must be strings, got {s!r}")
    if len(set(signals)) != len(signals):
        raise DataError(f"signals requested twice: {sorted({s for s in signals if signals.count(s) > 1})}")
    return signals


def _csv_rows(p: Path, where: str) -> list[list[str]]:
    """Every row of a UTF-8 CSV file; a file that is not UTF-8, not CSV or empty is refused."""
    try:
        with open(p, encoding="utf-8", newline="") as fh:
            rows = list(_csv.reader(fh))
    except UnicodeDecodeError as exc:
        raise DataError(f"{where} is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except _csv.Error as exc:
        raise DataError(f"{where} cannot be parsed as CSV: {exc}") from None
    if not rows:
        raise DataError(f"{where} is empty")
    return rows
