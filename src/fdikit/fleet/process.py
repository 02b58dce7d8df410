"""Processing one log of a fleet: read and decode it, run the monitor of the config over it and
commit its summary row, its events (and with ``stats`` every sample's statistics) on their own
(:func:`process_log`); a fleet task is a batch of such logs (:func:`process_logs`).

The worker keeps the config and its monitor between logs (built once per config file version).
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from ..base.outputs import io_error
from ..errors import FdikitError
from .commit import _commit, _empty_events, _schemas
from .tasks import LogTask, _part_dir, is_done

__all__ = ["process_log", "process_logs"]

_CACHE: dict[tuple, tuple] = {}


def _monitor_for(config: str):
    """The config and its monitor, built once per worker process (per config file version)."""
    from ..monitor.config import build_monitor, load_config

    st = os.stat(config)
    key = (config, st.st_mtime_ns, st.st_size)
    if key not in _CACHE:
        cfg = load_config(config)
        _CACHE.clear()
        _CACHE[key] = (cfg, build_monitor(cfg))
    return _CACHE[key]


def process_log(task: LogTask) -> dict:
    """Run the monitor over one log and commit its results; returns the summary row (a dict).

    Any failure to read or monitor the log is caught and becomes an error record (status
    ``"error"``, the reason in ``error``), and so does a failure to write its results (a full
    disk: the reason names the file); when not even the summary can be written, the error row is
    returned uncommitted, so the next run redoes the log.

    Parameters
    ----------
    task : LogTask
        The log, its names and its output directory (from :func:`fdikit.fleet.plan`).

    Returns
    -------
    dict
        The summary row as committed (see the ``summaries`` dataset of :mod:`fdikit.fleet`),
        plus ``vehicle``.

    Examples
    --------
    >>> from fdikit.fleet import plan
    >>> row = process_log(plan(["logs/"], "monitor.toml", "out")[0])  # doctest: +SKIP
    >>> row["status"], row["episodes"]  # doctest: +SKIP
    ('ok', 1)
    """
    import numpy as np
    import pyarrow as pa

    t_start = time.perf_counter()
    summary_schema, events_schema = _schemas()
    row = {"log_id": task.log_id, "path": task.path, "route": task.route, "status": "ok", "error": None,
           "format": None, "duration_s": None, "samples": 0, "invalid_samples": 0, "episodes": 0,
           "cleared": 0, "gaps": 0, "cannot_judge_samples": 0, "warmup_samples": 0, "t0": None,
           "hypotheses": "[]", "first_event_t": None, "first_hypothesis": None, "max_statistics": "{}",
           "fields": json.dumps(task.fields, sort_keys=True), "config": task.config,
           "load_s": 0.0, "monitor_s": 0.0, "write_s": 0.0, "wall_s": 0.0,
           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    events: list[dict] = []
    stats_table = None
    try:
        from ..monitor.config import map_channels, read_log
        from ..monitor.logs import log_format

        cfg, mon = _monitor_for(task.config)
        fmt = log_format(cfg.log, task.path)   # the declared [log].format, as read_log reads it
        row["format"] = "csv" if fmt == "recording" else fmt
        t0 = time.perf_counter()
        log = read_log(cfg, task.path)
        t1 = time.perf_counter()
        sig = map_channels(cfg, log)
        res = mon.run(sig)
        t2 = time.perf_counter()
        row["load_s"], row["monitor_s"] = t1 - t0, t2 - t1
        row["samples"] = int(sig.n_samples)
        row["duration_s"] = float(sig.t[-1] - sig.t[0]) if sig.n_samples else 0.0
        row["invalid_samples"] = len(res.invalid)
        row["episodes"] = len(res.events)
        row["cleared"] = len(res.cleared)
        row["gaps"] = len(res.gaps)
        row["t0"] = float(getattr(sig, "t0", 0.0) or 0.0)
        if res.status is not None:
            row["cannot_judge_samples"] = int(np.count_nonzero(res.status[0] == 1))
            row["warmup_samples"] = int(np.count_nonzero(res.status[0] == 2))
        row["hypotheses"] = json.dumps(sorted({e.hypothesis for e in res.events}))
        if res.events:
            row["first_event_t"], row["first_hypothesis"] = float(res.events[0].t), res.events[0].hypothesis
        names = res.statistics.names
        peak = res.statistics.values.max(axis=(0, 1)) if len(names) else ()
        row["max_statistics"] = json.dumps({n: float(peak[i]) for i, n in enumerate(names)})
        # onsets (announcements) and cleared events, in time order
        events = [{"log_id": task.log_id, "route": task.route, "t": float(e.t), "sample": int(e.k),
                   "run": int(e.run), "hypothesis": e.hypothesis, "value": float(e.value),
                   "kind": e.kind, "episode": int(e.episode),
                   "size": None if e.size is None else float(e.size)}
                  for e in sorted([*res.events, *res.cleared], key=lambda e: (e.run, e.k, e.kind != "onset"))]
        if task.stats:
            cols = {"t": sig.t}
            for s in (res.residuals, res.statistics):
                for i, ch in enumerate(s.names):
                    cols[ch] = s.values[0, :, i]
            cols["valid"] = res.valid[0] if res.valid is not None else np.ones(sig.n_samples, bool)
            stats_table = pa.table(cols)
    except Exception as exc:  # a bad log is a record, never the end of the fleet
        msg = str(exc) if isinstance(exc, FdikitError) else f"{type(exc).__name__}: {exc}"
        if task.path not in msg and Path(task.path).name not in msg:
            msg = f"{task.path}: {msg}"
        row.update(status="error", error=msg, samples=0, invalid_samples=0, episodes=0)
        events, stats_table = [], None
    t3 = time.perf_counter()
    out = Path(task.out)
    target = out
    try:
        target = _part_dir(out, "events", task.vehicle) / f"{task.part}.parquet"
        _commit(pa.Table.from_pylist(events, schema=events_schema) if events else _empty_events(), target)
        if task.stats:
            if stats_table is None:
                stats_table = pa.table({"t": pa.array([], pa.float64())})
            target = _part_dir(out, "stats", task.vehicle) / f"{task.part}.parquet"
            _commit(stats_table, target, small=False)
    except OSError as exc:  # a full disk: this log's error record, and the fleet goes on
        row.update(status="error", error=str(io_error(target, exc)), samples=0, invalid_samples=0,
                   episodes=0)
    row["write_s"] = time.perf_counter() - t3
    row["wall_s"] = time.perf_counter() - t_start
    # the summary last: once it is in place, the log is committed
    target = _part_dir(out, "summaries", task.vehicle) / f"{task.part}.parquet"
    try:
        _commit(pa.Table.from_pylist([row], schema=summary_schema), target)
    except OSError as exc:  # not even the error record fits: reported, not committed (redone next run)
        why = str(io_error(target, exc))
        row.update(status="error", error=why if row["error"] is None else f"{row['error']}; {why}",
                   samples=0, invalid_samples=0, episodes=0)
    return dict(row, vehicle=task.vehicle)


def _committed_row(task: LogTask) -> dict:
    """The summary row of a log already committed (as :func:`process_log` returned it)."""
    import pyarrow.parquet as pq

    s = _part_dir(Path(task.out), "summaries", task.vehicle) / f"{task.part}.parquet"
    row = pq.ParquetFile(s).read().to_pylist()[0]
    return dict(row, vehicle=task.vehicle)


def process_logs(tasks: list[LogTask], retry_errors: bool = False) -> list[dict]:
    """:func:`process_log` over a batch of logs in turn (one fleet task); returns their summary rows.

    Every log is still committed on its own (its files renamed into place, the summary last), so
    a batch cut short by a dead worker leaves its finished logs committed. When the batch is run
    again (Dask reruns a lost task; the local pool resubmits it), a log committed since the fleet
    was planned is not redone: its committed summary row is returned instead.

    Parameters
    ----------
    tasks : list of LogTask
    retry_errors : bool
        Redo a log whose committed summary is an error record.

    Returns
    -------
    list of dict
        One summary row per task, in order (see :func:`process_log`).

    Examples
    --------
    >>> from fdikit.fleet import batches, plan
    >>> tasks = plan(["logs/"], "monitor.toml", "out")  # doctest: +SKIP
    >>> rows = [r for b in batches(tasks, 1) for r in process_logs(b)]  # doctest: +SKIP
    """
    rows = []
    for task in tasks:
        if is_done(task, retry_errors=retry_errors):
            try:
                rows.append(_committed_row(task))
                continue
            except Exception:  # unreadable: redo the log
                pass
        rows.append(process_log(task))
    return rows
