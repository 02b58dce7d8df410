"""Atomic commits of a log's results: the Arrow schemas of the summary and event tables, and
Parquet files written under a hidden temporary name and renamed into place (:func:`_commit`).

Dataset readers skip the hidden ``.tmp-...`` names, so a reader never sees half a file, and a
worker killed mid-write leaves only a temporary file that the next run removes.
"""

from __future__ import annotations

import functools
import io
import os
import uuid
from pathlib import Path

__all__: list[str] = []


@functools.lru_cache(maxsize=1)
def _schemas():
    """The Arrow schemas of the summary and event tables (built once per process)."""
    import pyarrow as pa

    summary = pa.schema([
        ("log_id", pa.string()), ("path", pa.string()), ("route", pa.string()), ("status", pa.string()),
        ("error", pa.string()), ("format", pa.string()), ("duration_s", pa.float64()),
        ("samples", pa.int64()), ("invalid_samples", pa.int64()), ("episodes", pa.int64()),
        ("cleared", pa.int64()), ("gaps", pa.int64()), ("cannot_judge_samples", pa.int64()),
        ("warmup_samples", pa.int64()), ("t0", pa.float64()),
        ("hypotheses", pa.string()), ("first_event_t", pa.float64()), ("first_hypothesis", pa.string()),
        ("max_statistics", pa.string()), ("fields", pa.string()), ("config", pa.string()),
        ("load_s", pa.float64()), ("monitor_s", pa.float64()), ("write_s", pa.float64()),
        ("wall_s", pa.float64()), ("worker", pa.string()),
    ])
    events = pa.schema([("log_id", pa.string()), ("route", pa.string()), ("t", pa.float64()),
                        ("sample", pa.int64()), ("run", pa.int64()), ("hypothesis", pa.string()),
                        ("value", pa.float64()), ("kind", pa.string()), ("episode", pa.int64()),
                        ("size", pa.float64())])
    return summary, events


_MADE_DIRS: set[Path] = set()


@functools.lru_cache(maxsize=1)
def _empty_events() -> bytes:
    """The Parquet file of a log without events (the same bytes for every such log: most logs of
    a healthy fleet), serialised once per process."""
    import pyarrow as pa

    return _serialise(pa.Table.from_pylist([], schema=_schemas()[1]))


def _serialise(table) -> bytes:
    """A small table as a plain Parquet file in memory (see :func:`_commit`)."""
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    pq.write_table(table, buf, compression="none", write_statistics=False, use_dictionary=False)
    return buf.getvalue()


def _commit(table, final: Path, *, small: bool = True) -> None:
    """Write a Parquet file under a hidden temporary name beside ``final`` and rename it into place.

    A ``small`` table (a summary row, a log's events) is serialised in memory without compression,
    column statistics or dictionary pages -- a plain Parquet file that every reader reads, at a
    third of the cost of the default writer for a table of a few rows -- and written with one
    system call; a large one (``--stats``) goes through pyarrow's writer with its defaults.
    ``table`` may also be the bytes of a Parquet file, written as they are.
    """
    import pyarrow.parquet as pq

    if final.parent not in _MADE_DIRS:
        final.parent.mkdir(parents=True, exist_ok=True)
        _MADE_DIRS.add(final.parent)
    tmp = final.parent / f".tmp-{uuid.uuid4().hex}-{final.name}"
    try:
        if small:
            data = table if isinstance(table, bytes) else _serialise(table)
            try:
                fh = open(tmp, "xb")
            except FileNotFoundError:  # the directory was removed since: make it again
                final.parent.mkdir(parents=True, exist_ok=True)
                fh = open(tmp, "xb")
            with fh:
                fh.write(data)
        else:
            final.parent.mkdir(parents=True, exist_ok=True)
            pq.write_table(table, tmp)
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


def _clean_tmp(out: Path) -> int:
    """Remove temporary files that a killed worker left behind."""
    n = 0
    for kind in ("summaries", "events", "stats"):
        d = out / kind
        if d.is_dir():
            for f in d.rglob(".tmp-*"):
                f.unlink(missing_ok=True)
                n += 1
    return n
