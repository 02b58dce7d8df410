"""``fdikit fleet LOGS... --config C --out DIR``: one monitor over a fleet's logs, exactly once per log.

LOGS are directories (searched recursively for log files: BLF, ASC, candump, MDF4, Parquet, CSV),
glob patterns (``"fleet/**/*.blf"``) or list files (``.txt`` / ``.lst`` / ``.list``: one path per
line, relative to the list file, ``#`` comments). Every log is read and decoded, run through the
monitor built from the config's artifacts, and its results written and committed on its own; a
task is a batch of a few logs (:func:`batch_size`: up to 16, fewer towards the end of the run),
which the worker processes in turn. The tasks run on local processes (default,
``--processes N``), on a local Dask cluster (``--workers N``) or on a running Dask cluster
(``--scheduler ADDRESS``); see :class:`fdikit.evaluate.Engine`. The workers of the local Dask
cluster run without Dask's statistical profiler, which took a fifth of a log's time; a running
cluster keeps its own setting (``distributed.worker.profile.enabled: false`` in its Dask config
gives it the same speed).

What it writes in ``DIR`` (Parquet datasets partitioned Hive-style by vehicle, one file per log)::

    summaries/vehicle=V/<log>.parquet   one row per log: log_id, path, route, status ("ok" or
                                        "error"), error (the reason), format, duration_s, samples,
                                        invalid_samples, episodes (announcements), cleared, gaps,
                                        cannot_judge/warmup samples, t0, first event,
                                        max statistics, extra fields, timings, worker
    events/vehicle=V/<log>.parquet      one row per onset (announcement) and per cleared event
                                        (log_id, route, t, sample, hypothesis, value, kind,
                                        episode, size)
    stats/vehicle=V/<log>.parquet       with --stats: every sample's residuals and statistics

``pandas.read_parquet(DIR / "summaries")`` reads a dataset with its ``vehicle`` column.

Vehicle and route come from the path (``--path-fields``, default ``{vehicle}/{route}``: the log's
directory and its file name without suffix, matched from the end of the path relative to where it
was found) or from a manifest (``--manifest FILE.csv`` with a ``path`` column and any of
``vehicle``, ``route`` and further columns, which land in ``fields``).

Exactly-once results:

* each file is written to a hidden temporary name (``.tmp-...``, which dataset readers skip) and
  renamed into place; the summary is renamed last, so a log with a summary is complete;
* a rerun skips every log whose summary and events are there and redoes the others (a log whose
  worker died before the rename, or whose output was removed); ``--retry-errors`` redoes error
  records too;
* a log that cannot be read or monitored (corrupt, truncated, wrong channels) becomes an error
  record naming the log and the reason, and the fleet goes on;
* a worker that dies mid-log: Dask reruns the task on another worker; the local pool is rebuilt
  and the unfinished tasks resubmitted; a rerun batch skips its logs committed before the worker
  died and redoes the rest.
"""

from __future__ import annotations

import argparse
import csv
import functools
import glob
import hashlib
import io
import json
import os
import socket
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from urllib.parse import quote

from ..errors import DataError, FdikitError
from ._output import print_json

__all__ = ["LogTask", "batch_size", "batches", "discover", "plan", "process_log", "process_logs", "register"]

_LIST_SUFFIXES = (".txt", ".lst", ".list")
#: Threads per worker process: one, so that N workers use N cores (numba, BLAS). And the C
#: allocator keeps the memory of one log for the next (trim above 128 MB, blocks below 32 MB from
#: the heap, one arena for the worker's threads) instead of returning it to the system and
#: faulting it in again page by page: Dask's default (trim at 64 kB) cost a RAV4 minute about 9000
#: page faults and a third of its time.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1", "MALLOC_TRIM_THRESHOLD_": str(128 << 20),
              "MALLOC_MMAP_THRESHOLD_": str(32 << 20), "MALLOC_ARENA_MAX": "1"}


def _log_suffixes() -> set[str]:
    from ..io.formats import FORMATS

    return {s for v in FORMATS.values() for s in v}


@dataclass
class LogTask:
    """One log of a fleet: where it is, what it is called, where its results go."""

    path: str
    log_id: str
    part: str
    vehicle: str
    route: str
    fields: dict[str, str] = field(default_factory=dict)
    config: str = ""
    out: str = ""
    stats: bool = False


# ---------------------------------------------------------------------------------- finding logs
def discover(specs: list[str], *, exclude: Path | None = None) -> list[tuple[Path, PurePosixPath]]:
    """Log files named by directories, globs or list files: ``[(absolute path, relative path)]``.

    The relative path is from the directory searched (or the glob's fixed prefix, or the list
    file's directory); it is the log id. Duplicates (the same file found twice) are dropped.
    """
    suffixes = _log_suffixes()
    found: list[tuple[Path, PurePosixPath]] = []

    def rel(p: Path, root: Path) -> PurePosixPath:
        try:
            return PurePosixPath(p.relative_to(root).as_posix())
        except ValueError:
            return PurePosixPath(p.name)

    for spec in specs:
        p = Path(spec)
        if any(c in spec for c in "*?["):
            fixed = []
            for part in Path(spec).parts:
                if any(c in part for c in "*?["):
                    break
                fixed.append(part)
            root = Path(*fixed) if fixed else Path(".")
            hits = sorted(Path(x) for x in glob.glob(spec, recursive=True))
            files = [h for h in hits if h.is_file()]
            if not files:
                raise DataError(f"the pattern {spec!r} matches no log file")
            found += [(f.resolve(), rel(f.resolve(), root.resolve())) for f in files]
        elif p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in suffixes
                           and not f.name.startswith("."))
            if exclude is not None:
                ex = exclude.resolve()
                files = [f for f in files if ex not in f.resolve().parents]
            found += [(f.resolve(), rel(f.resolve(), p.resolve())) for f in files]
        elif p.is_file() and p.suffix.lower() in _LIST_SUFFIXES:
            base = p.resolve().parent
            for n, line in enumerate(p.read_text().splitlines(), start=1):
                line = line.split("#", 1)[0].strip()
                if not line:
                    continue
                f = (base / line).resolve()
                if not f.is_file():
                    raise DataError(f"list file {str(p)!r} line {n}: no such log file {line!r}")
                found.append((f, rel(f, base)))
        elif p.is_file():
            found.append((p.resolve(), PurePosixPath(p.name)))
        else:
            raise DataError(f"{spec!r} is not a log file, a directory, a list file or a pattern that matches")
    seen, out = set(), []
    for f, r in found:
        if f not in seen:
            seen.add(f)
            out.append((f, r))
    return out


def read_manifest(path: str | os.PathLike) -> dict[Path, dict[str, str]]:
    """A manifest CSV (column ``path``, relative to the manifest, plus metadata columns) by absolute path."""
    p = Path(path)
    try:
        with open(p, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        raise DataError(f"manifest {str(p)!r} does not exist") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"manifest {str(p)!r} is not a CSV file: {exc}") from None
    if not rows or "path" not in rows[0]:
        raise DataError(f"manifest {str(p)!r} needs a header with a 'path' column (and e.g. vehicle, route)")
    out = {}
    for n, row in enumerate(rows, start=2):
        if not (row.get("path") or "").strip():
            raise DataError(f"manifest {str(p)!r} line {n}: empty path")
        f = (p.resolve().parent / row["path"].strip()).resolve()
        out[f] = {k: (v or "").strip() for k, v in row.items() if k != "path" and k is not None}
    return out


def path_fields(rel: PurePosixPath, template: str) -> dict[str, str]:
    """Fields of a relative log path by a template such as ``"{vehicle}/{route}"``, matched from the end.

    Examples
    --------
    >>> path_fields(PurePosixPath("fleet/veh07/2024-05-01/r3.blf"), "{vehicle}/{date}/{route}")
    {'route': 'r3', 'date': '2024-05-01', 'vehicle': 'veh07'}
    >>> path_fields(PurePosixPath("r3.blf"), "{vehicle}/{route}")
    {'route': 'r3'}
    """
    parts = [*rel.parent.parts, rel.name[: -len(rel.suffix)] if rel.suffix else rel.name]
    tpl = [t for t in template.strip("/").split("/") if t]
    out: dict[str, str] = {}
    for t, v in zip(reversed(tpl), reversed(parts)):
        if t.startswith("{") and t.endswith("}"):
            out[t[1:-1]] = v
        elif t != v:
            return {}
    return out


def _part_name(log_id: str, path: Path) -> str:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in log_id)[-80:]
    return f"{safe}-{hashlib.sha1(str(path).encode()).hexdigest()[:10]}"


def _part_dir(out: Path, kind: str, vehicle: str) -> Path:
    return out / kind / f"vehicle={quote(vehicle, safe='')}"


def plan(specs: list[str], config: str | os.PathLike, out: str | os.PathLike, *, manifest=None,
         template: str = "{vehicle}/{route}", stats: bool = False) -> list[LogTask]:
    """The tasks of a fleet run: every log found, named, with its vehicle, route and output parts."""
    out = Path(out).resolve()
    meta = read_manifest(manifest) if manifest else {}
    tasks = []
    for path, rel in discover(specs, exclude=out):
        f = dict(path_fields(rel, template))
        f.update({k: v for k, v in meta.get(path, {}).items() if v != ""})
        vehicle = f.pop("vehicle", "") or "unknown"
        route = f.pop("route", "") or (rel.name[: -len(rel.suffix)] if rel.suffix else rel.name)
        log_id = str(rel)
        tasks.append(LogTask(str(path), log_id, _part_name(log_id, path), vehicle, route, f,
                             str(Path(config).resolve()), str(out), stats))
    return tasks


def is_done(task: LogTask, *, retry_errors: bool = False) -> bool:
    """Has this log been committed (its summary and its events are in place)?"""
    out = Path(task.out)
    s = _part_dir(out, "summaries", task.vehicle) / f"{task.part}.parquet"
    e = _part_dir(out, "events", task.vehicle) / f"{task.part}.parquet"
    if not (s.exists() and e.exists()):
        return False
    if task.stats and not (_part_dir(out, "stats", task.vehicle) / f"{task.part}.parquet").exists():
        return False
    if retry_errors:
        import pyarrow.parquet as pq

        try:
            return pq.read_table(s, columns=["status"]).column("status")[0].as_py() == "ok"
        except Exception:  # an unreadable summary: redo the log
            return False
    return True


# ---------------------------------------------------------------------------------- one log (worker)
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


def process_log(task: LogTask) -> dict:
    """Run the monitor over one log and commit its results; returns the summary row (a dict).

    Any failure to read or monitor the log is caught and becomes an error record (status
    ``"error"``, the reason in ``error``); only a failure to write the results raises.
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
        from ..io.formats import detect_format
        from ..monitor.config import map_channels, read_log

        cfg, mon = _monitor_for(task.config)
        row["format"] = detect_format(task.path)
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
    _commit(pa.Table.from_pylist(events, schema=events_schema) if events else _empty_events(),
            _part_dir(out, "events", task.vehicle) / f"{task.part}.parquet")
    if task.stats:
        if stats_table is None:
            stats_table = pa.table({"t": pa.array([], pa.float64())})
        _commit(stats_table, _part_dir(out, "stats", task.vehicle) / f"{task.part}.parquet", small=False)
    row["write_s"] = time.perf_counter() - t3
    row["wall_s"] = time.perf_counter() - t_start
    # the summary last: once it is in place, the log is committed
    _commit(pa.Table.from_pylist([row], schema=summary_schema),
            _part_dir(out, "summaries", task.vehicle) / f"{task.part}.parquet")
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


#: The most logs in one fleet task: a task's dispatch and its result's trip cost about a log's
#: commit on a LocalCluster, so 16 logs spread it to a few percent of a log each.
MAX_BATCH = 16


def batch_size(n_logs: int, n_workers: int) -> int:
    """Logs in the next fleet task when ``n_logs`` remain: a quarter of each worker's share, 1 to
    :data:`MAX_BATCH` (guided scheduling: large tasks while much remains, smaller ones towards the
    end, so that the workers finish together, the last tasks one log each); one worker has
    nobody to wait for and takes :data:`MAX_BATCH` throughout.

    Examples
    --------
    >>> batch_size(200, 2), batch_size(200, 1), batch_size(20, 2), batch_size(3, 2), batch_size(5, 1)
    (16, 16, 3, 1, 5)
    """
    if n_workers <= 1:
        return max(1, min(MAX_BATCH, n_logs))
    return max(1, min(MAX_BATCH, -(-n_logs // (4 * n_workers))))


def batches(todo: list, n_workers: int) -> list[list]:
    """The logs ``todo`` cut into fleet tasks of :func:`batch_size` logs each, in order.

    Examples
    --------
    >>> [len(b) for b in batches(list(range(40)), 2)]
    [5, 5, 4, 4, 3, 3, 2, 2, 2, 2, 1, 1, 1, 1, 1, 1, 1, 1]
    """
    out, i = [], 0
    while i < len(todo):
        k = batch_size(len(todo) - i, n_workers)
        out.append(todo[i:i + k])
        i += k
    return out


# ---------------------------------------------------------------------------------- the command
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


def run_fleet(tasks: list[LogTask], engine, *, retry_errors: bool = False, progress: bool = False) -> dict:
    """Run every task not yet committed on ``engine``; returns the run's report (a dict)."""
    from ..evaluate.progress import progress_bar

    todo = [t for t in tasks if not is_done(t, retry_errors=retry_errors)]
    skipped = len(tasks) - len(todo)
    rows: list[dict] = []
    t0 = time.perf_counter()
    prog, info = progress_bar(progress and bool(todo), len(todo), "fleet")
    with prog:
        task_id = prog.add_task(f"{info[0]} ({len(todo)} logs)", total=info[1]) if info else None
        if todo:
            fn = functools.partial(process_logs, retry_errors=retry_errors) if retry_errors else process_logs
            for _, batch in engine.map_unordered(fn, batches(todo, engine.n_workers)):
                rows.extend(batch)
                if task_id is not None:
                    prog.advance(task_id, len(batch))
    wall = time.perf_counter() - t0
    ok = [r for r in rows if r["status"] == "ok"]
    errors = [{"log_id": r["log_id"], "path": r["path"], "error": r["error"]} for r in rows
              if r["status"] != "ok"]
    hours = sum(r["duration_s"] or 0.0 for r in ok) / 3600.0
    load = sum(r["load_s"] for r in rows)
    busy = sum(r["wall_s"] for r in rows)
    return {"logs": len(tasks), "skipped": skipped, "processed": len(rows), "ok": len(ok),
            "errors": len(errors), "error_records": errors[:100],
            "episodes": sum(r["episodes"] for r in ok),
            "vehicle_hours": hours, "wall_seconds": wall,
            "task_seconds": busy, "load_decode_share": (load / busy) if busy else None}


def _fleet(args) -> int:
    from ..evaluate.distributed import Engine
    from ..monitor.config import load_config

    if not Path(args.config).exists():
        raise DataError(f"{args.config}: no such config file")
    load_config(args.config)  # a bad config is one clear error, not an error record per log
    for flag in ("workers", "processes"):
        v = getattr(args, flag)
        if v is not None and v < 1:
            raise DataError(f"--{flag} must be >= 1, got {v}")
    if sum(x is not None for x in (args.workers, args.scheduler, args.processes)) > 1:
        raise DataError("choose one of --processes, --workers and --scheduler")
    from ._output import check_output_paths

    check_output_paths(args, folders=("out",))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = plan(args.logs, args.config, out, manifest=args.manifest, template=args.path_fields,
                 stats=args.stats)
    if not tasks:
        raise DataError(f"no log files found in {args.logs}")
    cleaned = _clean_tmp(out)
    progress = (sys.stderr.isatty() and not args.json) if args.progress is None else args.progress
    if args.scheduler:
        engine = Engine(scheduler=args.scheduler, env=WORKER_ENV)
    elif args.workers:
        engine = Engine(args.workers, dask=True, env=WORKER_ENV)
    else:
        engine = Engine(args.processes or min(os.cpu_count() or 1, len(tasks)), env=WORKER_ENV,
                        preload=("fdikit.commands.fleet", "fdikit.monitor.config", "fdikit.io"))
    with engine:
        report = run_fleet(tasks, engine, retry_errors=args.retry_errors, progress=progress)
        report["engine"] = engine.describe()
    report.update(out=str(out.resolve()), config=str(Path(args.config).resolve()),
                  temporary_files_removed=cleaned,
                  datasets={k: str((out / k).resolve()) for k in ("summaries", "events")
                            + (("stats",) if args.stats else ())})
    if args.json:
        print_json(report)
    else:
        print(f"{report['logs']} logs: {report['processed']} processed ({report['ok']} ok, "
              f"{report['errors']} errors), {report['skipped']} already done; "
              f"{report['episodes']} episodes; {report['vehicle_hours']:.3f} vehicle-hours in "
              f"{report['wall_seconds']:.1f} s on {report['engine']['workers']} "
              f"{report['engine']['kind']} workers")
        for e in report["error_records"]:
            print(f"  error: {e['error']}")
        print(f"results in {report['out']}")
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "fleet", help="run a config-driven monitor over a fleet of logs (local processes or Dask)",
        description=(
            "Run the monitor of a configuration file (TOML; make its artifacts first with\n"
            "'fdikit design CONFIG') over every log of a fleet, once per log, and write the\n"
            "results as Parquet datasets partitioned by vehicle in --out:\n"
            "  summaries/vehicle=V/*.parquet  one row per log (log id, route, status, error,\n"
            "                                 duration, samples, invalid samples, episodes, ...)\n"
            "  events/vehicle=V/*.parquet     one row per onset and per cleared event\n"
            "  stats/vehicle=V/*.parquet      with --stats: residuals and statistics per sample\n"
            "\n"
            "LOGS are directories (searched recursively), glob patterns or list files (.txt,\n"
            "one path per line). Vehicle and route come from the path (--path-fields) or from\n"
            "a manifest CSV (--manifest, columns path, vehicle, route, ...).\n"
            "\n"
            "Each log's files are written under temporary names and renamed into place, the\n"
            "summary last: a rerun skips the logs already committed and redoes the rest (a\n"
            "log whose worker died, a log whose output was removed). A log that cannot be\n"
            "read or monitored becomes an error record with the reason; the fleet goes on.\n"
            "\n"
            "Runs on local processes (default; --processes N), a local Dask cluster\n"
            "(--workers N) or a running Dask cluster (--scheduler ADDRESS). A progress bar\n"
            "on standard error shows the work (not with --json or when standard error is\n"
            "not a terminal). --json prints the run's report as one JSON object."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logs", nargs="+", help="log files, directories, glob patterns or list files")
    p.add_argument("--config", required=True, help="monitor configuration file (TOML)")
    p.add_argument("--out", required=True, help="output directory of the Parquet datasets")
    p.add_argument("--manifest", help="CSV with a 'path' column (relative to the manifest) and the "
                   "vehicle, route and further metadata of each log")
    p.add_argument("--path-fields", default="{vehicle}/{route}",
                   help="how vehicle and route are read from a log's path, matched from its end "
                   "(default '{vehicle}/{route}': the directory and the file name)")
    p.add_argument("--stats", action="store_true", help="also write every sample's residuals and statistics")
    p.add_argument("--retry-errors", action="store_true", help="redo the logs that gave an error record")
    p.add_argument("--processes", type=int, default=None,
                   help="local worker processes (default: the number of cores)")
    p.add_argument("--workers", type=int, default=None,
                   help="run on a local Dask cluster of this many worker processes")
    p.add_argument("--scheduler", default=None,
                   help="run on a running Dask cluster, given by its scheduler address (tcp://HOST:PORT)")
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="show the progress bar on standard error (default: when it is a terminal and "
                   "without --json)")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="show no progress bar")
    p.add_argument("--json", action="store_true", help="print the run's report as one JSON object")
    p.set_defaults(func=_fleet)
