"""One monitor over a fleet's logs, exactly once per log: the library behind ``fdikit fleet``.

Logs are named by directories (searched recursively for log files: BLF, ASC, candump, MDF4,
Parquet, CSV), glob patterns (``"fleet/**/*.blf"``) or list files (``.txt`` / ``.lst`` /
``.list``: one path per line, relative to the list file, ``#`` comments). Every log is read and
decoded, run through the monitor built from the config's artifacts, and its results written and
committed on its own; a task is a batch of a few logs (:func:`batch_size`: up to 16, fewer
towards the end of the run), which the worker processes in turn. The tasks run in this process
(:class:`InProcess`), on local processes, on a local Dask cluster or on a running Dask cluster
(see :class:`fdikit.evaluate.Engine` and :func:`make_engine`). The workers of the local Dask
cluster run without Dask's statistical profiler, which took a fifth of a log's time; a running
cluster keeps its own setting (``distributed.worker.profile.enabled: false`` in its Dask config
gives it the same speed).

What it writes in the output directory (Parquet datasets partitioned Hive-style by vehicle, one
file per log)::

    summaries/vehicle=V/<log>.parquet   one row per log: log_id, path, route, status ("ok" or
                                        "error"), error (the reason), format, duration_s, samples,
                                        invalid_samples, episodes (announcements), cleared, gaps,
                                        cannot_judge/warmup samples, t0, first event,
                                        max statistics, extra fields, timings, worker
    events/vehicle=V/<log>.parquet      one row per onset (announcement) and per cleared event
                                        (log_id, route, t, sample, hypothesis, value, kind,
                                        episode, size)
    stats/vehicle=V/<log>.parquet       with stats=True: every sample's residuals and statistics

``pandas.read_parquet(out / "summaries")`` reads a dataset with its ``vehicle`` column.

Vehicle and route come from the path (``path_fields``, default ``{vehicle}/{route}``: the log's
directory and its file name without suffix, matched from the end of the path relative to where it
was found) or from a manifest (a CSV file with a ``path`` column and any of ``vehicle``,
``route`` and further columns, which land in ``fields``).

Exactly-once results:

* each file is written to a hidden temporary name (``.tmp-...``, which dataset readers skip) and
  renamed into place; the summary is renamed last, so a log with a summary is complete;
* a rerun skips every log whose summary and events are there and redoes the others (a log whose
  worker died before the rename, or whose output was removed); ``retry_errors`` redoes error
  records too;
* a log that cannot be read or monitored (corrupt, truncated, wrong channels) becomes an error
  record naming the log and the reason, and the fleet goes on;
* a worker that dies mid-log: Dask reruns the task on another worker; the local pool is rebuilt
  and the unfinished tasks resubmitted; a rerun batch skips its logs committed before the worker
  died and redoes the rest.

Modules: :mod:`~fdikit.fleet.tasks` (finding and naming logs), :mod:`~fdikit.fleet.commit`
(atomic Parquet commits), :mod:`~fdikit.fleet.process` (one log, one batch),
:mod:`~fdikit.fleet.batch` (batching), :mod:`~fdikit.fleet.runner` (engines, resume, the report).

Examples
--------
>>> import fdikit.fleet
>>> report = fdikit.fleet.run(["fleet/"], "monitor.toml", "out", processes=4)  # doctest: +SKIP
>>> report["processed"], report["errors"]  # doctest: +SKIP
(120, 1)
"""

from .batch import MAX_BATCH, batch_size, batches
from .commit import _clean_tmp, _commit, _empty_events, _schemas, _serialise  # noqa: F401
from .process import _committed_row, _monitor_for, process_log, process_logs  # noqa: F401
from .runner import WORKER_ENV, InProcess, check_options, make_engine, run, run_fleet, summarise
from .tasks import LogTask, _part_dir, _part_name, discover, is_done, path_fields, plan, read_manifest  # noqa: F401

__all__ = [
    "MAX_BATCH",
    "WORKER_ENV",
    "InProcess",
    "LogTask",
    "batch_size",
    "batches",
    "check_options",
    "discover",
    "is_done",
    "make_engine",
    "path_fields",
    "plan",
    "process_log",
    "process_logs",
    "read_manifest",
    "run",
    "run_fleet",
    "summarise",
]
