"""Text CAN frame logs (Vector ASC, candump) read through python-can, with line accounting."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ...errors import DataError
from .checks import _check_file
from .grid import SourceReport


class _Lines:
    """A text file as an iterator of lines that remembers the current line number."""

    def __init__(self, path: Path, encoding: str = "utf-8"):
        self._f = open(path, encoding=encoding, errors="strict", newline=None)
        self.lineno = 0
        self.line = ""
        self.history: list[tuple[int, str]] = []

    def __iter__(self) -> Iterator[str]:
        return self

    def __next__(self) -> str:
        line = next(self._f)
        self.lineno += 1
        self.line = line
        self.history.append((self.lineno, line))
        return line

    def close(self) -> None:
        self._f.close()

    @property
    def closed(self) -> bool:
        return self._f.closed


#: ASC lines that python-can skips on purpose and that carry no CAN data frame.
_ASC_BENIGN = re.compile(
    r"^\s*$|^//|^date\s|^base\s|^(no\s+)?internal\s+events\s+logged|^begin\s+triggerblock|"
    r"^end\s+triggerblock|^\d+\.\d+\s+(start\s+of\s+measurement|log\s+trigger|sv:|"
    r"\d+\s+statistic:|can\s+\d+\s+status:|j1939tp)",
    re.IGNORECASE,
)


def _read_text_frames(path, fmt: str, *, strict: bool = True, encoding: str = "utf-8"):
    """Frames of an ASC or candump file via python-can, with line accounting."""
    import can

    what = {"asc": "ASC log", "candump": "candump log"}[fmt]
    p = _check_file(path, what)
    try:
        lines = _Lines(p, encoding)
    except LookupError:
        raise DataError(f"unknown text encoding {encoding!r}") from None
    reader_cls = can.ASCReader if fmt == "asc" else can.CanutilsLogReader
    ts: list[float] = []
    ids: list[int] = []
    data: list[bytes] = []
    where: list[int] = []
    chans: list[str] = []
    skipped: list[tuple[int, str]] = []
    seen_end = False

    def account(upto: int) -> None:
        """Lines read since the last frame (all but the one that made it, if ``upto``)."""
        nonlocal seen_end
        hist = lines.history[:-1] if upto else lines.history
        for no, text in hist:
            s = text.strip()
            if fmt == "asc" and re.match(r"^end\s+triggerblock", s, re.IGNORECASE):
                seen_end = True
            if not s or (fmt == "asc" and _ASC_BENIGN.match(s)):
                continue
            if strict:
                raise DataError(f"{what} {p.name!r} line {no} is neither a CAN frame nor a known "
                                f"{fmt.upper()} event: {s[:80]!r} (corrupt line; strict=False skips it)")
            skipped.append((no, s[:200]))
        lines.history.clear()

    try:
        reader = reader_cls(lines)
        for msg in reader:
            account(upto=1)
            if fmt == "asc" and re.match(r"^end\s+triggerblock", lines.line.strip(), re.IGNORECASE):
                seen_end = True
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            ts.append(float(msg.timestamp))
            ids.append(int(msg.arbitration_id))
            data.append(bytes(msg.data or b""))
            where.append(lines.lineno)
            # the bus as the file writes it (python-can numbers ASC channels from 0; the file from 1)
            ch = msg.channel
            chans.append(str(ch + 1) if fmt == "asc" and isinstance(ch, int) else str(ch))
        account(upto=0)
    except DataError:
        lines.close()
        raise
    except UnicodeDecodeError:
        lines.close()
        raw = p.read_bytes()
        try:
            raw.decode(encoding)
            pos, reason = -1, "?"
        except UnicodeDecodeError as exc:
            pos, reason = exc.start, exc.reason
        line_no = raw.count(b"\n", 0, pos) + 1
        raise DataError(f"{what} {p.name!r} is not {encoding} text: undecodable byte {raw[pos:pos + 1]!r} "
                        f"at offset {pos}, line {line_no} ({reason}; a Windows-written ASC may need "
                        "encoding='cp1252')") from None
    except (ValueError, IndexError, KeyError, TypeError, OverflowError, AttributeError) as exc:
        lines.close()
        raise DataError(f"{what} {p.name!r} line {lines.lineno} cannot be parsed "
                        f"({type(exc).__name__}: {exc}): {lines.line.strip()[:80]!r}") from None
    lines.close()
    if fmt == "asc" and strict and not seen_end:
        raise DataError(f"ASC log {p.name!r} is truncated: it does not end with 'End TriggerBlock' "
                        f"(last line {lines.lineno}: {lines.line.strip()[:80]!r}; strict=False reads it)")
    if not ts:
        raise DataError(f"{what} {p.name!r} holds no CAN data frames ({lines.lineno} lines)")
    src = SourceReport(fmt, str(p), len(ts), tuple(skipped))
    return np.asarray(ts, float), np.asarray(ids, np.int64), data, np.asarray(where), chans, src
