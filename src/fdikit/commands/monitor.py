"""``fdikit design CONFIG`` and ``fdikit monitor LOG --config CONFIG``: config-driven monitors.

* ``fdikit design CONFIG [--json]`` writes the design artifacts of the config's recipe
  (:mod:`fdikit.commands.design`).
* ``fdikit monitor LOG --config CONFIG [--events F.jsonl] [--stats F.parquet] [--json]`` runs the
  monitor built from the artifacts over a recorded log, writes its records (episodes' onsets and
  cleared events, gaps, held samples; :mod:`fdikit.monitor.records`) and every sample's
  statistics with its status code, and prints a summary. Every output path is checked first.
* ``fdikit monitor - --config CONFIG --follow`` steps the monitor over CSV or (a config with
  ``[log].dbc``) ``candump -L`` lines as they arrive and prints each record at once as a JSON
  line, equal to the batch run's; ``--checkpoint``/``--resume`` continue after a crash
  (:class:`fdikit.monitor.live.LiveMonitor`).

The command parses its arguments and prints; the work is the library's.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ..base.inputs import is_stream, open_lines
from ..base.outputs import io_error
from ..errors import DataError
from ._output import print_json

__all__ = ["register"]


def _batch(args, cfg) -> int:
    from ..monitor.config import build_monitor, map_channels, read_log
    from ..monitor.records import batch_records, batch_summary, summary_lines, write_records, write_stats

    t0 = time.perf_counter()
    log = read_log(cfg, args.log)
    sig = map_channels(cfg, log)
    mon = build_monitor(cfg)
    res = mon.run(sig)
    records = batch_records(sig, res)
    if args.events:
        write_records(args.events, records)
    if args.stats:
        write_stats(args.stats, sig, res)
    summary = batch_summary(cfg, args.log, sig, res, t_start=t0)
    if args.report or args.plot:
        from ..report import monitor_report, monitor_thresholds

        if args.report:
            summary["report"] = str(monitor_report(args.report, signals=sig, result=res, monitor=mon,
                                                   config=cfg, log=args.log,
                                                   signal_valid=getattr(log, "valid", None)))
        if args.plot:
            from ..report.figures import monitor_figure

            try:
                summary["plot"] = monitor_figure(sig, res, args.plot, thresholds=monitor_thresholds(mon),
                                                 level=mon.decision.level if mon.decision else None)
            except OSError as exc:
                raise io_error(args.plot, exc) from None
    if args.json:
        print_json(summary)
    else:
        for line in summary_lines(summary, records):
            print(line)
    return 0


def _follow(args, cfg) -> int:
    """Stream CSV (or candump) lines through the live monitor, printing each record at once."""
    from ..monitor.live import LiveMonitor

    if args.resume and not args.checkpoint:
        raise DataError("--resume needs --checkpoint FILE (the checkpoint to continue from)")
    if args.checkpoint_every < 1:
        raise DataError(f"--checkpoint-every must be >= 1 sample, got {args.checkpoint_every}")
    live = LiveMonitor(cfg, input=args.input)
    stream = sys.stdin if args.log == "-" else open_lines(args.log)  # a FIFO without blocking; closed below
    try:
        live.follow(stream, on_record=lambda rec: print(json.dumps(rec), flush=True), events=args.events,
                    checkpoint=args.checkpoint, resume=args.resume, checkpoint_every=args.checkpoint_every)
    except KeyboardInterrupt:  # Ctrl-C is follow mode's normal end: its summary, then the stop
        print(live.summary_line(), file=sys.stderr, flush=True)
        raise
    finally:
        if stream is not sys.stdin:
            stream.close()
    print(live.summary_line(), file=sys.stderr, flush=True)
    return 0


def _monitor(args) -> int:
    from ..monitor.config import load_config

    cfg = load_config(args.config)
    from ._output import check_output_paths

    check_output_paths(args, "events", "stats", "plot", "report", "checkpoint", inputs=("log", "config"),
                       labels={"log": "LOG"})
    if args.follow:
        if args.json:
            raise DataError("--follow prints one JSON line per announcement; it does not take --json")
        if args.log != "-" and not (Path(args.log).is_file() or is_stream(args.log)):
            raise DataError(f"{args.log}: no such log file (follow mode reads a file, a FIFO, or - for "
                            "standard input)")
        return _follow(args, cfg)
    if args.log == "-":
        raise DataError("reading a log from standard input needs --follow")
    if not Path(args.log).exists():
        raise DataError(f"{args.log}: no such log file")
    return _batch(args, cfg)


def register(sub) -> None:
    from .design import register as register_design

    register_design(sub)
    p = sub.add_parser(
        "monitor", help="run a config-driven monitor over a log",
        description=(
            "Run the monitor described by a configuration file (TOML) over a recorded log\n"
            "and report its fault announcements. Run 'fdikit design CONFIG' first to make\n"
            "the design artifacts the monitor is built from.\n"
            "\n"
            "Batch mode (LOG is a file): reads the log (a CSV table of signals; a BLF, ASC\n"
            "or candump CAN log, decoded with the config's DBC file; MDF4 or Parquet),\n"
            "maps its channels (scale, offset), runs the monitor and prints the\n"
            "number of samples, the announcements and the number of invalid samples that\n"
            "were held. --json prints this summary as one JSON object; --events and\n"
            "--stats also write the details to files.\n"
            "\n"
            "Follow mode (--follow, LOG '-' for standard input): reads lines as they\n"
            "arrive, steps the monitor per line and prints each announcement, and each\n"
            "invalid line or sample, at once as one JSON line. The input is CSV (a header\n"
            "line with the time column and the source channels first) or, when the config\n"
            "names a DBC file, 'candump -L' lines, e.g.\n"
            "    candump -L can0 | fdikit monitor - --config CONFIG --follow\n"
            "The announcements equal those of a batch run over the same data."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", help="recorded log file (CSV, BLF, ASC, candump, MDF4 or Parquet), "
                   "or - with --follow to read standard input")
    p.add_argument("--config", required=True, help="monitor configuration file (TOML)")
    p.add_argument("--events",
                   help="JSON Lines file to write: one line per fault-episode onset (the announcement) and "
                   "per cleared episode (kind, hypothesis, value, size, episode), per time gap and per held "
                   "(invalid) sample; batch and follow mode write the same lines (in follow mode also on "
                   "standard output, exactly once across --resume)")
    p.add_argument("--stats",
                   help="Parquet file to write: the residuals and test statistics of every sample, "
                   "with its valid flag and status code (0 ok, 1 cannot judge: held, 2 warm-up)")
    p.add_argument("--follow", action="store_true",
                   help="follow mode: process CSV or candump lines as they arrive (from standard input with "
                   "LOG = -) and print one JSON line per announcement")
    p.add_argument("--input", choices=("csv", "candump"),
                   help="line format in follow mode (default: candump when the config names a DBC file "
                   "in [log].dbc, else csv)")
    p.add_argument("--checkpoint",
                   help="follow mode: checkpoint file (NPZ), written atomically every --checkpoint-every "
                   "samples and at the end: the monitor's state, how far the input was read and the event "
                   "log's length")
    p.add_argument("--checkpoint-every", type=int, default=500,
                   help="follow mode: samples between checkpoints (default 500, 10 s at 50 Hz)")
    p.add_argument("--resume", action="store_true",
                   help="follow mode: continue from --checkpoint if it exists (after a crash or kill -9): "
                   "the event log is cut back to the checkpoint and the input lines read before it are "
                   "skipped (replay the input from its start, or let a live stream go on)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON summary object (batch mode only; not with --follow)")
    p.add_argument("--report", metavar="FILE.html", help="write a self-contained HTML report of the run")
    p.add_argument("--plot", metavar="FILE", help="write a figure of the signals, residuals and statistics "
                   "(format from the extension, e.g. .png)")
    p.set_defaults(func=_monitor)
