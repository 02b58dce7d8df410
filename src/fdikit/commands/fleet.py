"""``fdikit fleet LOGS... --config C --out DIR``: one monitor over a fleet's logs, exactly once per log.

The command parses its arguments, checks the output folder and prints the report of
:func:`fdikit.fleet.run`; the library (:mod:`fdikit.fleet`) documents what is written in ``DIR``
(Parquet datasets of summaries, events and with ``--stats`` statistics, partitioned by vehicle),
how vehicle and route are named and how a rerun resumes exactly once per log.
"""

from __future__ import annotations

import argparse
import sys

# the library's names, importable from here as before the library existed
from ..fleet import (  # noqa: F401
    WORKER_ENV,
    LogTask,
    batch_size,
    batches,
    discover,
    is_done,
    path_fields,
    plan,
    process_log,
    process_logs,
    read_manifest,
    run_fleet,
)
from ._output import print_json

__all__ = ["LogTask", "batch_size", "batches", "discover", "plan", "process_log", "process_logs", "register"]


def _fleet(args) -> int:
    from .. import fleet

    fleet.check_options(args.config, processes=args.processes, workers=args.workers, scheduler=args.scheduler)
    from ._output import check_output_paths

    check_output_paths(args, folders=("out",))
    progress = (sys.stderr.isatty() and not args.json) if args.progress is None else args.progress
    report = fleet.run(args.logs, args.config, args.out, manifest=args.manifest, path_fields=args.path_fields,
                       stats=args.stats, retry_errors=args.retry_errors, processes=args.processes,
                       workers=args.workers, scheduler=args.scheduler, progress=progress)
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
