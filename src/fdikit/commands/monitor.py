"""``fdikit design CONFIG`` and ``fdikit monitor LOG --config CONFIG``: config-driven monitors.

* ``fdikit design CONFIG [--json]`` runs the config's design recipe and writes the design
  artifacts (JSON + NPZ) into the config's artifact directory.
* ``fdikit monitor LOG --config CONFIG [--events FILE.jsonl] [--stats FILE.parquet] [--json]``
  reads a recorded log, maps its channels (scale, offset), runs the monitor built from the
  artifacts, writes the fault episodes (an onset record, the announcement, and a cleared record
  each, with kind, size and episode number), every time gap and every held bad sample as JSON
  lines and the full residuals and statistics (with each sample's status code: 0 ok,
  1 cannot_judge, 2 warmup, :data:`fdikit.monitor.core.STATUS_NAMES`) as Parquet,
  and prints a summary with the status counts and the gaps. Every output path is checked
  before anything is computed.
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
import os
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
    from ..report.progress import progress_steps, progress_wanted

    cfg = load_config(args.config)
    with progress_steps(progress_wanted(args.json), 1, "fdikit design") as steps:
        steps.step(f"recipe {cfg.design.get('recipe') or 'declarative [design]'}")
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
    """An onset or cleared event as one JSON record (``announcement`` is True for an onset)."""
    kind = getattr(e, "kind", "onset")
    size = getattr(e, "size", None)
    return {"t": e.t, "run": e.run, "sample": e.k, "kind": kind, "hypothesis": e.hypothesis,
            "value": e.value, "size": None if size is None or not np.isfinite(size) else float(size),
            "episode": int(getattr(e, "episode", 0)), "announcement": kind == "onset"}


def _gap_record(g) -> dict:
    """A time gap (the state held, nothing judged): at its first sample after it."""
    return {"t": g.t_end, "run": g.run, "sample": g.k, "gap": True, "t_start": g.t_start,
            "n_missing": int(g.n_missing)}


def _invalid_record(t: float, run: int, k: int, why: str) -> dict:
    return {"t": float(t), "run": run, "sample": k, "invalid": why}


def _order(d: dict) -> tuple:
    """Records of one sample: the gap that ended at it, its held reason, cleared, then onsets."""
    rank = 0 if d.get("gap") else 1 if "invalid" in d else 2 if d.get("kind") == "cleared" else 3
    return (d["sample"], rank, d.get("run", 0), d.get("hypothesis", ""))


def _status_counts(res) -> dict:
    """Samples per status (``ok``, ``cannot_judge``, ``warmup``), over every run."""
    status = getattr(res, "status", None)
    names = getattr(res, "STATUS_NAMES", ("ok", "cannot_judge", "warmup"))
    if status is None:
        return {"ok": int(res.valid.sum()) if res.valid is not None else 0,
                "cannot_judge": len(res.invalid)}
    return {n: int(np.sum(status == i)) for i, n in enumerate(names)}


def _batch_records(sig, res) -> list[dict]:
    """Every record of a batch run, in the order follow mode writes them."""
    records = [_event_record(e) for e in (*res.events, *getattr(res, "cleared", []))]
    records += [_invalid_record(sig.t[k], r, k, why) for r, k, why in res.invalid]
    records += [_gap_record(g) for g in getattr(res, "gaps", [])]
    records.sort(key=_order)
    return records


def _batch(args, cfg) -> int:
    from ..monitor.config import build_monitor, map_channels, read_log

    t0 = time.perf_counter()
    log = read_log(cfg, args.log)
    sig = map_channels(cfg, log)
    mon = build_monitor(cfg)
    res = mon.run(sig)
    records = _batch_records(sig, res)
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
        status = getattr(res, "status", None)
        if status is not None:
            df["status"] = status[0].astype(np.int8)   # STATUS_NAMES[code]: 0 ok, 1 cannot_judge, 2 warmup
        df.to_parquet(args.stats, index=False)
    summary = {
        "config": str(cfg.path), "log": str(args.log), "samples": sig.n_samples,
        "duration_s": float(sig.t[-1] - sig.t[0]) if sig.n_samples else 0.0,
        "channels": sig.names, "n_events": len(res.events),
        "events": [_event_record(e) for e in res.events[:100]],
        "first_event": _event_record(res.events[0]) if res.events else None,
        "invalid_samples": len(res.invalid),
        "status": _status_counts(res),
        "n_cleared": len(getattr(res, "cleared", [])),
        "cleared": [_event_record(e) for e in getattr(res, "cleared", [])[:100]],
        "n_gaps": len(getattr(res, "gaps", [])),
        "gaps": [_gap_record(g) for g in getattr(res, "gaps", [])[:100]],
        "max_statistics": {n: float(np.max(res.statistics.values[..., i]))
                           for i, n in enumerate(res.statistics.names)},
        "wall_seconds": round(time.perf_counter() - t0, 3),
    }
    if args.report or args.plot:
        from ..report import monitor_report, monitor_thresholds

        if args.report:
            summary["report"] = str(monitor_report(args.report, signals=sig, result=res, monitor=mon,
                                                   config=cfg, log=args.log,
                                                   signal_valid=getattr(log, "valid", None)))
        if args.plot:
            from ..report.figures import monitor_figure

            summary["plot"] = monitor_figure(sig, res, args.plot, thresholds=monitor_thresholds(mon),
                                             level=mon.decision.level if mon.decision else None)
    if args.json:
        print_json(summary)
    else:
        st = summary["status"]
        print(f"{summary['samples']} samples, {summary['n_events']} announcements "
              f"({summary['n_cleared']} cleared), {summary['invalid_samples']} invalid samples held, "
              f"{summary['n_gaps']} gaps; status: " + ", ".join(f"{v} {k.replace('_', ' ')}"
                                                              for k, v in st.items()))
        for rec in records:
            if rec.get("gap"):
                print(f"  t = {rec['t']:.3f} s  gap of {rec['n_missing']} samples since "
                      f"t = {rec['t_start']:.3f} s: cannot judge, warm-up after it")
            elif "kind" in rec:
                size = "" if rec["size"] is None else f", size {rec['size']:.4g}"
                what = "cleared" if rec["kind"] == "cleared" else f"({rec['value']:.4g}{size})"
                print(f"  t = {rec['t']:.3f} s  {rec['hypothesis']}  {what}  [episode {rec['episode']}]")
    return 0


class _Output:
    """Follow mode's records: one JSON line each on stdout and, with ``--events``, in the event log.

    With ``--checkpoint`` the follower saves, every ``--checkpoint-every`` samples, the monitor's
    state, the gridder's state, how far the input was read and the event log's length, in one
    atomic file. ``--resume`` loads it, cuts the event log back to that length (records written
    after the checkpoint are written again, so none is doubled) and skips the input up to that
    position: the events of a crashed run plus those of its resumed run equal an uninterrupted run.
    """

    def __init__(self, args, cfg, mon, kind: str):
        self.args, self.cfg, self.mon, self.kind = args, cfg, mon, kind
        self.every = args.checkpoint_every
        self.ckpt = Path(args.checkpoint) if args.checkpoint else None
        self.n = 0                 # grid samples (candump) or data rows (CSV) stepped
        self.lines = 0             # input lines read up to the last one consumed
        self.t_last: float | None = None   # latest time of a consumed input line
        self.resumed: dict | None = None
        self.header: list[str] | None = None
        self.time_first: str | None = None   # follow CSV: the first timestamp's text (the origin)
        self._since = 0
        self.fh = None
        if args.events:
            self.fh = open(args.events, "a+b")  # closed in close()

    def start(self, gridder=None) -> None:
        """Fresh start (the event log emptied) or, with --resume and a checkpoint, continue."""
        if self.args.resume and self.ckpt is not None and self.ckpt.exists():
            from ..base.state import load_state

            state, meta = load_state(self.ckpt)
            if meta.get("kind") != "follow" or meta.get("input") != self.kind:
                raise DataError(f"{self.ckpt}: not a follow-mode checkpoint of {self.kind} input "
                                f"(kind {meta.get('kind')!r}, input {meta.get('input')!r})")
            if meta.get("config") != str(self.cfg.path.resolve()):
                raise DataError(f"{self.ckpt}: checkpoint of config {meta.get('config')!r}, not "
                                f"{str(self.cfg.path.resolve())!r}")
            self.mon.restore(state["monitor"])
            f = state["follow"]
            self.n, self.lines, self.t_last = int(f["n"]), int(f["lines"]), f["t_last"]
            self.header = f.get("header")
            self.time_first = f.get("time_first")
            if gridder is not None:
                _gridder_restore(gridder, state["gridder"])
            if self.fh is not None:
                size = int(f["events_bytes"])
                if self.fh.seek(0, 2) < size:
                    raise DataError(f"{self.args.events}: the event log is shorter ({self.fh.tell()} bytes) "
                                    f"than at the checkpoint ({size} bytes); it is not this run's log")
                self.fh.truncate(size)
            self.resumed = {"lines": self.lines, "t_last": self.t_last}
        elif self.fh is not None:
            self.fh.truncate(0)
        self._gridder = gridder

    def skip(self, index: int, t: float | None) -> bool:
        """Was input line ``index`` (0-based) consumed before the checkpoint?

        Yes while the line is among the first ``lines`` and not later than the last consumed
        time: a replay of the input from its start skips exactly what was consumed, and a live
        stream that goes on (later times) is not skipped at all.
        """
        r = self.resumed
        if r is None:
            return False
        done = index < r["lines"] and (t is None or r["t_last"] is None or t <= r["t_last"])
        if not done:
            self.resumed = None  # past the checkpoint: nothing more is skipped
        return done

    def consumed(self, index: int, t: float | None) -> None:
        self.lines = index + 1
        if t is not None and (self.t_last is None or t > self.t_last):
            self.t_last = t

    def write(self, rec: dict) -> None:
        line = json.dumps(rec)
        print(line, flush=True)
        if self.fh is not None:
            self.fh.write(line.encode() + b"\n")
            self.fh.flush()

    def stepped(self) -> None:
        self.n += 1
        self._since += 1

    def maybe_checkpoint(self, force: bool = False) -> None:
        if self.ckpt is None or not (force or self._since >= self.every):
            return
        from ..base.state import save_state

        size = 0
        if self.fh is not None:
            self.fh.flush()
            os.fsync(self.fh.fileno())
            size = self.fh.seek(0, 2)
        follow = {"n": self.n, "lines": self.lines, "t_last": self.t_last, "events_bytes": size,
                  "header": self.header, "time_first": self.time_first}
        state = {"monitor": self.mon.state(), "follow": follow,
                 "gridder": None if self._gridder is None else _gridder_state(self._gridder)}
        save_state(self.ckpt, state, meta={"kind": "follow", "input": self.kind,
                                           "config": str(self.cfg.path.resolve())})
        self._since = 0

    def close(self) -> None:
        if self.fh is not None:
            self.fh.close()


def _gridder_state(g) -> dict:
    """The streaming state of a :class:`fdikit.io.stream.FrameGridder` as plain data."""
    series = {name: {"t": list(s.t), "v": list(s.v), "intervals": list(s.intervals), "first": s.first}
              for name, s in g._series.items()}
    return {"series": series, "bus": {str(k): v for k, v in g._bus.items()}, "t0": g._t0,
            "t_last": g._t_last, "start": g._start, "k": g._k, "frames": g.frames,
            "undecodable": g.undecodable}


def _gridder_restore(g, st: dict) -> None:
    if sorted(st["series"]) != sorted(g._series):
        raise DataError(f"checkpoint grids signals {sorted(st['series'])}, the config {sorted(g._series)}")
    for name, d in st["series"].items():
        s = g._series[name]
        s.t, s.v, s.first = [float(x) for x in d["t"]], [float(x) for x in d["v"]], d["first"]
        s.intervals.clear()
        s.intervals.extend(float(x) for x in d["intervals"])
    g._bus = {int(k): v for k, v in st["bus"].items()}
    g._t0, g._t_last, g._start = st["t0"], st["t_last"], st["start"]
    g._k, g.frames, g.undecodable = int(st["k"]), int(st["frames"]), int(st["undecodable"])


def _follow_candump(args, cfg, mon, stream, out: _Output) -> int:
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
    out.start(grid)

    def feed(samples):
        for t, vals, why in samples:
            k = out.n
            _, _, events = mon.step(t, map_sample(cfg, vals))
            if mon.last_invalid is None and why:  # cannot happen: an invalid grid value is NaN
                raise AssertionError(why)
            _write_step(out, mon, t, k, events)
            out.stepped()

    for index, line in enumerate(stream):
        lineno = index + 1
        try:
            frame = parse_candump_line(line, lineno)
        except DataError as exc:
            if not out.skip(index, None):
                out.write({"line": lineno, "invalid": str(exc)})
                out.consumed(index, None)
            continue
        t = None if frame is None else frame[0]
        if out.skip(index, t):
            continue
        out.consumed(index, t)
        if frame is None:
            continue
        t, bus, fid, data = frame
        try:
            samples = grid.push(t, fid, data, bus)
        except DataError as exc:  # e.g. time going back: the frame is refused, the stream goes on
            out.write({"line": lineno, "invalid": str(exc)})
            continue
        feed(samples)
        out.maybe_checkpoint()
    feed(grid.flush())
    out.maybe_checkpoint(force=True)
    return 0


def _write_step(out, mon, t: float, k: int, events) -> None:
    """Follow mode: the records of one stepped sample, as the batch run writes them."""
    recs = []
    gap = getattr(mon, "last_gap", None)
    if gap is not None:
        recs.append(_gap_record(gap._replace(k=k) if hasattr(gap, "_replace") else gap))
    if mon.last_invalid is not None:
        recs.append(_invalid_record(t, 0, k, mon.last_invalid))
    recs += [_event_record(e) for e in events]
    for rec in sorted(recs, key=_order):
        out.write(rec)


class _Clock:
    """Follow mode's time column, read by the batch readers' rule (:mod:`fdikit.io.timebase`): the
    unit of ``[log].time_unit``, an absolute clock rebased to its first timestamp, exactly."""

    def __init__(self, unit: str, first: str | None = None):
        self.unit, self.first = unit, first

    def seconds(self, cell: str, lineno: int) -> float:
        from ..io.timebase import times_to_seconds

        cell = cell.strip()
        if self.first is None:
            t, _ = times_to_seconds([cell], self.unit, where="follow mode", rows=[lineno], line_offset=0)
            self.first = cell
            return float(t[0])
        t, _ = times_to_seconds([self.first, cell], self.unit, where="follow mode", rows=[0, lineno],
                                line_offset=0)
        return float(t[1])


def _follow_csv(args, cfg, mon, stream, out: _Output) -> int:
    from ..monitor.config import map_sample

    tcol = cfg.log.get("time", "t")
    out.start()
    clock = _Clock(cfg.time_unit, out.time_first)
    lines = iter(stream)
    header = out.header
    first = next(lines, None)
    if header is None or (first is not None and [h.strip() for h in next(csv.reader([first]))] == header):
        if first is None:
            raise DataError("follow mode: no header line on the input")
        header = [h.strip() for h in next(csv.reader([first]))]
        lines_iter = lines
    else:  # resumed on a stream that goes on without repeating its header
        lines_iter = iter([first, *lines]) if first is not None else lines
    if tcol not in header:
        raise DataError(f"follow mode: the header has no time column {tcol!r}: {header}")
    out.header = header
    it = header.index(tcol)
    for index, text in enumerate(lines_iter):
        lineno = index + 2
        row = next(csv.reader([text]), [])
        if not row:
            continue
        t_row = None
        if len(row) == len(header):
            try:
                t_row = clock.seconds(row[it], lineno)
            except (ValueError, DataError):
                t_row = None
            if t_row is not None and not np.isfinite(t_row):
                t_row = None
        if out.skip(index, t_row):
            continue
        out.consumed(index, t_row)
        if len(row) != len(header):
            out.write({"line": lineno, "invalid": f"{len(row)} fields, expected {len(header)}"})
            continue
        vals = {}
        for h, v in zip(header, row):
            if h == tcol:
                continue
            try:
                vals[h] = float(v)
            except ValueError:
                vals[h] = float("nan")
        if t_row is None:
            out.write({"line": lineno, "invalid": f"time {row[it]!r} is not a number"})
            continue
        t = t_row
        out.time_first = clock.first
        k = out.n
        _, _, events = mon.step(t, map_sample(cfg, vals))
        _write_step(out, mon, t, k, events)
        out.stepped()
        out.maybe_checkpoint()
    out.maybe_checkpoint(force=True)
    return 0


def _follow(args, cfg) -> int:
    """Stream CSV (or candump) lines from stdin through the monitor, printing events as they happen."""
    from ..monitor.config import build_monitor

    if args.resume and not args.checkpoint:
        raise DataError("--resume needs --checkpoint FILE (the checkpoint to continue from)")
    if args.checkpoint_every < 1:
        raise DataError(f"--checkpoint-every must be >= 1 sample, got {args.checkpoint_every}")
    mon = build_monitor(cfg)
    mon.reset(1)
    kind = args.input or ("candump" if cfg.log.get("dbc") else "csv")
    stream = sys.stdin if args.log == "-" else open(args.log)  # closed below
    out = _Output(args, cfg, mon, kind)
    try:
        if kind == "candump":
            return _follow_candump(args, cfg, mon, stream, out)
        return _follow_csv(args, cfg, mon, stream, out)
    finally:
        out.close()
        if stream is not sys.stdin:
            stream.close()


def _monitor(args) -> int:
    from ..monitor.config import load_config

    cfg = load_config(args.config)
    from ._output import check_output_paths

    check_output_paths(args, "events", "stats", "plot", "report", "checkpoint")
    if args.follow:
        if args.json:
            raise DataError("--follow prints one JSON line per announcement; it does not take --json")
        if args.log != "-" and not Path(args.log).is_file():
            raise DataError(f"{args.log}: no such log file (follow mode reads a file, or - for standard "
                            "input)")
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
