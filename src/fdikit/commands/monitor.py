"""``fdikit design CONFIG`` and ``fdikit monitor LOG --config CONFIG``: config-driven monitors.

* ``fdikit design CONFIG [--json]`` runs the config's design recipe and writes the design
  artifacts (JSON + NPZ) into the config's artifact directory.
* ``fdikit monitor LOG --config CONFIG [--events FILE.jsonl] [--stats FILE.parquet] [--json]``
  reads a recorded log, maps its channels (scale, offset), runs the monitor built from the
  artifacts, writes the announcements (and every held bad sample) as JSON lines and the full
  residuals and statistics as Parquet, and prints a summary.
* ``fdikit monitor - --config CONFIG --follow`` reads CSV lines from standard input as they
  arrive (a header line with the time column and the source channels first), steps the
  monitor per line and prints each announcement as one JSON line at once; the results equal
  the batch run over the same data.
* With a CAN config (``[log].dbc`` set, ``[log].rate`` required) ``--follow`` reads
  ``candump -L`` lines instead (``candump -L can0 | fdikit monitor - --config C --follow``):
  frames are decoded and put on the grid as they arrive (:class:`fdikit.io.stream.FrameGridder`,
  the same arithmetic as the batch loader), so the announcements equal the batch run over the
  same candump log. ``--input csv|candump`` overrides the choice.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import DataError
from ._output import print_json

__all__ = ["register"]


def _design(args) -> int:
    from ..monitor.config import load_config, run_design

    t0 = time.perf_counter()
    cfg = load_config(args.config)
    paths = run_design(cfg)
    out = {"config": str(cfg.path), "artifacts": {k: str(v) for k, v in paths.items()},
           "wall_seconds": round(time.perf_counter() - t0, 3)}
    if args.json:
        print_json(out)
    else:
        for k, v in paths.items():
            print(f"{k}: {v}")
    return 0


def _event_record(e) -> dict:
    return {"t": e.t, "run": e.run, "sample": e.k, "hypothesis": e.hypothesis, "value": e.value,
            "announcement": True}


def _batch(args, cfg) -> int:
    from ..monitor.config import build_monitor, map_channels, read_log

    t0 = time.perf_counter()
    log = read_log(cfg, args.log)
    sig = map_channels(cfg, log)
    mon = build_monitor(cfg)
    res = mon.run(sig)
    records = [_event_record(e) for e in res.events]
    records += [{"t": float(sig.t[k]), "run": r, "sample": k, "invalid": why} for r, k, why in res.invalid]
    records.sort(key=lambda d: (d["sample"], "invalid" in d))
    if args.events:
        with open(args.events, "w") as fh:
            for rec in records:
                fh.write(json.dumps(rec) + "\n")
    if args.stats:
        import pandas as pd

        df = pd.DataFrame({"t": sig.t})
        for s in (res.residuals, res.statistics):
            for i, ch in enumerate(s.names):
                df[ch] = s.values[0, :, i]
        df["valid"] = res.valid[0] if res.valid is not None else True
        df.to_parquet(args.stats, index=False)
    summary = {
        "config": str(cfg.path), "log": str(args.log), "samples": sig.n_samples,
        "duration_s": float(sig.t[-1] - sig.t[0]) if sig.n_samples else 0.0,
        "channels": sig.names, "n_events": len(res.events),
        "events": [_event_record(e) for e in res.events[:100]],
        "first_event": _event_record(res.events[0]) if res.events else None,
        "invalid_samples": len(res.invalid),
        "max_statistics": {n: float(np.max(res.statistics.values[..., i]))
                           for i, n in enumerate(res.statistics.names)},
        "wall_seconds": round(time.perf_counter() - t0, 3),
    }
    if args.json:
        print_json(summary)
    else:
        print(f"{summary['samples']} samples, {summary['n_events']} announcements, "
              f"{summary['invalid_samples']} invalid samples held")
        for e in res.events:
            print(f"  t = {e.t:.3f} s  {e.hypothesis}  ({e.value:.4g})")
    return 0


def _follow_candump(args, cfg, mon, stream) -> int:
    """Stream candump lines through the gridder and the monitor, printing events as they happen."""
    from ..io.stream import FrameGridder, parse_candump_line
    from ..monitor.config import map_sample

    dbc, rate = cfg.log.get("dbc"), cfg.log.get("rate")
    if not dbc:
        raise DataError(f"{cfg.path}: following candump lines needs [log].dbc")
    if rate is None:
        raise DataError(f"{cfg.path}: following candump lines needs [log].rate (Hz): a stream cannot "
                        "measure the source rate ahead of time")
    sources = list(dict.fromkeys(c.source for c in cfg.channels))
    grid = FrameGridder(cfg.path.parent / dbc, sources, rate)
    n = 0

    def feed(samples):
        nonlocal n
        for t, vals, why in samples:
            _, _, events = mon.step(t, map_sample(cfg, vals))
            if mon.last_invalid is not None:
                print(json.dumps({"t": t, "sample": n, "invalid": mon.last_invalid}), flush=True)
            elif why:  # cannot happen: an invalid grid value is NaN and the monitor flags it
                raise AssertionError(why)
            for e in events:
                print(json.dumps(_event_record(e)), flush=True)
            n += 1

    for lineno, line in enumerate(stream, start=1):
        try:
            frame = parse_candump_line(line, lineno)
        except DataError as exc:
            print(json.dumps({"line": lineno, "invalid": str(exc)}), flush=True)
            continue
        if frame is None:
            continue
        t, bus, fid, data = frame
        try:
            samples = grid.push(t, fid, data, bus)
        except DataError as exc:  # e.g. time going back: the frame is refused, the stream goes on
            print(json.dumps({"line": lineno, "invalid": str(exc)}), flush=True)
            continue
        feed(samples)
    feed(grid.flush())
    return 0


def _follow(args, cfg) -> int:
    """Stream CSV (or candump) lines from stdin through the monitor, printing events as they happen."""
    from ..monitor.config import build_monitor, map_sample

    mon = build_monitor(cfg)
    mon.reset(1)
    kind = args.input or ("candump" if cfg.log.get("dbc") else "csv")
    if kind == "candump":
        stream = sys.stdin if args.log == "-" else open(args.log)  # closed below
        try:
            return _follow_candump(args, cfg, mon, stream)
        finally:
            if stream is not sys.stdin:
                stream.close()
    tcol = cfg.log.get("time", "t")
    stream = sys.stdin if args.log == "-" else open(args.log)  # closed below
    try:
        reader = csv.reader(stream)
        header = next(reader, None)
        if header is None:
            raise DataError("follow mode: no header line on the input")
        header = [h.strip() for h in header]
        if tcol not in header:
            raise DataError(f"follow mode: the header has no time column {tcol!r}: {header}")
        n = 0
        for lineno, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(row) != len(header):
                print(json.dumps({"line": lineno, "invalid": f"{len(row)} fields, expected {len(header)}"}),
                      flush=True)
                continue
            vals = {}
            for h, v in zip(header, row):
                try:
                    vals[h] = float(v)
                except ValueError:
                    vals[h] = float("nan")
            t = vals.pop(tcol)
            if not np.isfinite(t):
                bad_t = row[header.index(tcol)]
                print(json.dumps({"line": lineno, "invalid": f"time {bad_t!r} is not a number"}), flush=True)
                continue
            _, _, events = mon.step(t, map_sample(cfg, vals))
            if mon.last_invalid is not None:
                print(json.dumps({"t": t, "sample": n, "invalid": mon.last_invalid}), flush=True)
            for e in events:
                print(json.dumps(_event_record(e)), flush=True)
            n += 1
    finally:
        if stream is not sys.stdin:
            stream.close()
    return 0


def _monitor(args) -> int:
    from ..monitor.config import load_config

    cfg = load_config(args.config)
    if args.follow:
        if args.json:
            raise DataError("--follow prints one JSON line per announcement; it does not take --json")
        return _follow(args, cfg)
    if args.log == "-":
        raise DataError("reading a log from standard input needs --follow")
    if not Path(args.log).exists():
        raise DataError(f"{args.log}: no such log file")
    return _batch(args, cfg)


def register(sub) -> None:
    p = sub.add_parser("design", help="make the design artifacts of a monitor config",
                       description="Run the design recipe of a monitor configuration (a TOML file) and "
                                   "save every design it returns as a versioned artifact (a JSON file and "
                                   "an NPZ file) in the configuration's artifact directory, ready for "
                                   "'fdikit monitor'. Prints the path of each artifact; --json prints one "
                                   "JSON object with the paths and the wall time.")
    p.add_argument("config", help="monitor configuration file (TOML) with a [design] recipe")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the paths")
    p.set_defaults(func=_design)
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
                   help="JSON Lines file to write: one line per announcement and per held (invalid) sample")
    p.add_argument("--stats", help="Parquet file to write: the residuals and test statistics of every sample")
    p.add_argument("--follow", action="store_true",
                   help="follow mode: process CSV or candump lines as they arrive (from standard input with "
                   "LOG = -) and print one JSON line per announcement")
    p.add_argument("--input", choices=("csv", "candump"),
                   help="line format in follow mode (default: candump when the config names a DBC file "
                   "in [log].dbc, else csv)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON summary object (batch mode only; not with --follow)")
    p.set_defaults(func=_monitor)
