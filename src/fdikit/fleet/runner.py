"""Running a fleet: where the tasks run (in this process, a process pool, or Dask through
:mod:`fdikit.evaluate.distributed`), resuming (the committed logs skipped, error records redone on
request), and the run's report (:func:`run` from log specs to report, :func:`run_fleet` on a
planned fleet and an engine).
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ..errors import DataError
from .batch import batches
from .commit import _clean_tmp
from .process import process_logs
from .tasks import LogTask, is_done, plan

__all__ = ["WORKER_ENV", "InProcess", "check_options", "make_engine", "run", "run_fleet", "summarise"]

#: Threads per worker process: one, so that N workers use N cores (numba, BLAS). And the C
#: allocator keeps the memory of one log for the next (trim above 128 MB, blocks below 32 MB from
#: the heap, one arena for the worker's threads) instead of returning it to the system and
#: faulting it in again page by page: Dask's default (trim at 64 kB) cost a RAV4 minute about 9000
#: page faults and a third of its time.
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1", "MALLOC_TRIM_THRESHOLD_": str(128 << 20),
              "MALLOC_MMAP_THRESHOLD_": str(32 << 20), "MALLOC_ARENA_MAX": "1"}


class InProcess:
    """An engine that runs the fleet's tasks one after the other in this process.

    It has the interface of :class:`fdikit.evaluate.Engine` that :func:`run_fleet` uses
    (``n_workers``, ``map_unordered``, ``describe``, a context manager): for a notebook, a debugger,
    or a scheduler of the user's own that gives each process its share of a fleet.

    Examples
    --------
    >>> with InProcess() as engine:
    ...     list(engine.map_unordered(len, [[1, 2], [3]])), engine.describe()
    ([(0, 2), (1, 1)], {'kind': 'in-process', 'workers': 1})
    """

    kind = "in-process"
    n_workers = 1

    def __enter__(self) -> InProcess:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def map_unordered(self, fn: Callable, items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """``(index, fn(item))`` for every item, in order."""
        for i, item in enumerate(items):
            yield i, fn(item)

    def describe(self) -> dict[str, Any]:
        """What the engine is (as :meth:`fdikit.evaluate.Engine.describe`)."""
        return {"kind": self.kind, "workers": self.n_workers}


def check_options(config: str | os.PathLike, *, processes: int | None = None, workers: int | None = None,
                  scheduler: str | None = None) -> None:
    """Refuse a fleet run that cannot start, before any log is touched.

    Parameters
    ----------
    config : path-like
        The monitor configuration: it must exist and load (a bad config is one clear error, not
        an error record per log).
    processes, workers : int, optional
        At least 1 when given.
    scheduler : str, optional
        At most one of ``processes``, ``workers`` and ``scheduler`` may be given.

    Raises
    ------
    DataError
        Naming the config or the option.

    Examples
    --------
    >>> check_options("no-such-config.toml")
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: no-such-config.toml: no such config file
    """
    from ..monitor.config import load_config

    if not Path(config).exists():
        raise DataError(f"{config}: no such config file")
    load_config(config)  # a bad config is one clear error, not an error record per log
    for flag, v in (("workers", workers), ("processes", processes)):
        if v is not None and v < 1:
            raise DataError(f"--{flag} must be >= 1, got {v}")
    if sum(x is not None for x in (workers, scheduler, processes)) > 1:
        raise DataError("choose one of --processes, --workers and --scheduler")


def make_engine(n_logs: int, *, processes: int | None = None, workers: int | None = None,
                scheduler: str | None = None, in_process: bool = False):
    """The engine of a fleet run (not started; use it as a context manager).

    Parameters
    ----------
    n_logs : int
        Logs in the fleet: the default pool has no more processes than logs.
    processes : int, optional
        Local worker processes (default: the number of cores, at most ``n_logs``).
    workers : int, optional
        A local Dask cluster of this many worker processes (without Dask's profiler).
    scheduler : str, optional
        A running Dask cluster, by its scheduler address (``tcp://HOST:PORT``).
    in_process : bool
        Run in this process (:class:`InProcess`).

    Returns
    -------
    Engine or InProcess
        Every worker gets :data:`WORKER_ENV` (one thread, the allocator's settings).

    Examples
    --------
    >>> make_engine(3, in_process=True).describe()
    {'kind': 'in-process', 'workers': 1}
    >>> make_engine(3, processes=2).describe()["workers"]
    2
    """
    from ..evaluate.distributed import Engine

    if in_process:
        return InProcess()
    if scheduler:
        return Engine(scheduler=scheduler, env=WORKER_ENV)
    if workers:
        return Engine(workers, dask=True, env=WORKER_ENV)
    return Engine(processes or min(os.cpu_count() or 1, n_logs), env=WORKER_ENV,
                  preload=("fdikit.fleet.process", "fdikit.monitor.config", "fdikit.io"))


def run_fleet(tasks: list[LogTask], engine, *, retry_errors: bool = False, progress: bool = False) -> dict:
    """Run every task not yet committed on ``engine``; returns the run's report (a dict).

    The logs already committed are skipped (a rerun resumes); the others are cut into batches
    (:func:`fdikit.fleet.batches`) and run with :func:`fdikit.fleet.process_logs` on the engine.

    Parameters
    ----------
    tasks : list of LogTask
        The fleet (from :func:`fdikit.fleet.plan`).
    engine : Engine or InProcess
        Where the batches run: an :class:`fdikit.evaluate.Engine` (local processes or Dask),
        started, or :class:`InProcess`.
    retry_errors : bool
        Redo the logs whose committed summary is an error record.
    progress : bool
        Show a progress bar on standard error.

    Returns
    -------
    dict
        The report of :func:`summarise`.

    Examples
    --------
    >>> from fdikit.fleet import plan
    >>> tasks = plan(["logs/"], "monitor.toml", "out")  # doctest: +SKIP
    >>> with InProcess() as engine:  # doctest: +SKIP
    ...     report = run_fleet(tasks, engine)
    """
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
    return summarise(rows, logs=len(tasks), skipped=skipped, wall_seconds=time.perf_counter() - t0)


def _terminate_workers(engine) -> None:
    """Stop a local process pool's workers at once (their logs stay uncommitted: a rerun redoes
    them); the engine's close then returns without waiting for their batches."""
    pool = getattr(engine, "_pool", None)
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            proc.terminate()
        except (OSError, AttributeError):
            pass


def summarise(rows: list[dict], *, logs: int, skipped: int, wall_seconds: float) -> dict:
    """The report of a fleet run from the summary rows of the logs it processed.

    Parameters
    ----------
    rows : list of dict
        Summary rows (from :func:`fdikit.fleet.process_log`).
    logs : int
        Logs in the fleet.
    skipped : int
        Logs already committed before the run.
    wall_seconds : float
        Wall time of the run.

    Returns
    -------
    dict
        ``logs``, ``skipped``, ``processed``, ``ok``, ``errors``, ``error_records`` (the first
        100: log id, path, reason), ``episodes`` (of the ok logs), ``vehicle_hours``,
        ``wall_seconds``, ``task_seconds`` (the logs' wall times summed) and
        ``load_decode_share`` (of the task seconds; ``None`` without any).

    Examples
    --------
    >>> row = {"log_id": "v/r.blf", "path": "/v/r.blf", "status": "ok", "error": None,
    ...        "duration_s": 1800.0, "episodes": 2, "load_s": 0.25, "wall_s": 1.0}
    >>> rep = summarise([row], logs=3, skipped=2, wall_seconds=1.5)
    >>> rep["processed"], rep["episodes"], rep["vehicle_hours"], rep["load_decode_share"]
    (1, 2, 0.5, 0.25)
    """
    wall = wall_seconds
    ok = [r for r in rows if r["status"] == "ok"]
    errors = [{"log_id": r["log_id"], "path": r["path"], "error": r["error"]} for r in rows
              if r["status"] != "ok"]
    hours = sum(r["duration_s"] or 0.0 for r in ok) / 3600.0
    load = sum(r["load_s"] for r in rows)
    busy = sum(r["wall_s"] for r in rows)
    return {"logs": logs, "skipped": skipped, "processed": len(rows), "ok": len(ok),
            "errors": len(errors), "error_records": errors[:100],
            "episodes": sum(r["episodes"] for r in ok),
            "vehicle_hours": hours, "wall_seconds": wall,
            "task_seconds": busy, "load_decode_share": (load / busy) if busy else None}


def run(logs: list[str], config: str | os.PathLike, out: str | os.PathLike, *, manifest=None,
        path_fields: str = "{vehicle}/{route}", stats: bool = False, retry_errors: bool = False,
        processes: int | None = None, workers: int | None = None, scheduler: str | None = None,
        in_process: bool = False, progress: bool = False) -> dict:
    """One monitor over a fleet's logs, exactly once per log: plan, resume, run, report.

    Finds the logs (:func:`fdikit.fleet.discover`), names them (:func:`fdikit.fleet.plan`),
    removes the temporary files a killed worker left in ``out``, runs every log not yet
    committed on the chosen engine (:func:`run_fleet`) and returns the report.

    Parameters
    ----------
    logs : list of str
        Log files, directories, glob patterns or list files.
    config : path-like
        The monitor configuration (TOML; its artifacts made with ``fdikit design``).
    out : path-like
        Output directory of the Parquet datasets (created).
    manifest : path-like, optional
        A manifest CSV with the vehicle, route and further fields of each log.
    path_fields : str
        How vehicle and route are read from a log's path (:func:`fdikit.fleet.path_fields`).
    stats : bool
        Also write every sample's residuals and statistics.
    retry_errors : bool
        Redo the logs that gave an error record.
    processes, workers, scheduler, in_process
        Where the tasks run (:func:`make_engine`); at most one of the first three.
    progress : bool
        Show a progress bar on standard error.

    Returns
    -------
    dict
        The report of :func:`summarise`, plus ``engine`` (kind, workers), ``out``, ``config``,
        ``temporary_files_removed`` and ``datasets`` (the paths of ``summaries``, ``events`` and
        with ``stats`` ``stats``).

    Raises
    ------
    DataError
        A bad config or option (:func:`check_options`), no log found.

    Examples
    --------
    >>> import fdikit.fleet
    >>> report = fdikit.fleet.run(["logs/"], "monitor.toml", "out", in_process=True)  # doctest: +SKIP
    >>> report["ok"], report["errors"], report["skipped"]  # doctest: +SKIP
    (12, 0, 0)
    """
    check_options(config, processes=processes, workers=workers, scheduler=scheduler)
    out = Path(out)
    tasks = plan(logs, config, out, manifest=manifest, template=path_fields, stats=stats)
    if not tasks:
        raise DataError(f"no log files found in {logs}")
    out.mkdir(parents=True, exist_ok=True)
    cleaned = _clean_tmp(out)
    engine = make_engine(len(tasks), processes=processes, workers=workers, scheduler=scheduler,
                         in_process=in_process)
    with engine:
        try:
            report = run_fleet(tasks, engine, retry_errors=retry_errors, progress=progress)
        except KeyboardInterrupt:  # Ctrl-C, SIGTERM: stop the workers now, not after their batches
            _terminate_workers(engine)
            raise
        report["engine"] = engine.describe()
    report.update(out=str(out.resolve()), config=str(Path(config).resolve()),
                  temporary_files_removed=cleaned,
                  datasets={k: str((out / k).resolve()) for k in ("summaries", "events")
                            + (("stats",) if stats else ())})
    return report
