"""Live monitoring: CSV lines or ``candump -L`` frames in as they arrive, records out at once
(:class:`LiveMonitor`), with the stream's clock (:class:`LiveClock`), a JSON Lines event log that
survives a resume (:class:`EventLog`), and checkpoint / resume through public state APIs.

* CSV input: a header line with the time column and the source channels first, then one sample
  per line; the time column is read by the batch readers' rule (:class:`LiveClock`).
* candump input (a config with ``[log].dbc`` and ``[log].rate``): frames are decoded and put on
  the grid as they arrive (:class:`fdikit.io.stream.FrameGridder`, the arithmetic of the batch
  loader).

Each sample is stepped through the monitor built from the config's artifacts, and its records
(:mod:`fdikit.monitor.records`: the gap that ended at it, its held reason, cleared events and
onsets) come out at once; a line that cannot be read gives a record ``{"line", "invalid"}`` and
the stream goes on. The records equal those of a batch run over the same data.

A checkpoint (:meth:`LiveMonitor.save_checkpoint`) holds the monitor's state, the gridder's state,
how far the input was read and the event log's length; :meth:`LiveMonitor.load_checkpoint` puts
them back, and the next :meth:`LiveMonitor.records` skips the input lines consumed before it, so
the records of a crashed run plus those of its resumed run equal an uninterrupted run.
"""

from __future__ import annotations

import csv
import fcntl
import itertools
import json
import os
import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..base.inputs import iter_lines
from ..errors import DataError
from .records import NOT_SEEN, step_records

__all__ = ["EventLog", "LiveClock", "LiveMonitor"]

_FOLLOW_KEYS = ("n", "lines", "t_last", "header", "time_first")


def _cells(text: str, lineno: int, strip: bool = True) -> list[str]:
    """The (stripped) cells of one CSV line; a line the csv module refuses is a DataError."""
    try:
        row = next(csv.reader([text]), [])
        return [c.strip() for c in row] if strip else row
    except csv.Error as exc:
        raise DataError(f"follow mode: line {lineno} cannot be read as CSV ({exc})") from None


def _digest(text: str) -> str:
    """A short digest of an input line (its text without surrounding space)."""
    import hashlib

    return hashlib.sha1(text.strip().encode()).hexdigest()[:16]


class LiveClock:
    """A live stream's time column, read by the batch readers' rule (:mod:`fdikit.io.timebase`):
    the unit of ``[log].time_unit``, an absolute clock rebased to its first timestamp, exactly.

    Parameters
    ----------
    unit : {"auto", "s", "ms", "us", "ns"}
    first : str, optional
        The text of the stream's first timestamp (the origin), when continuing a stream.

    Examples
    --------
    >>> clock = LiveClock("auto")
    >>> [clock.seconds(x, n) for n, x in enumerate(["1700000000.00", "1700000000.01"], start=2)]
    [0.0, 0.01]
    >>> later = LiveClock("auto")
    >>> later.restore(clock.state())
    >>> later.seconds("1700000000.02", 4)
    0.02
    """

    def __init__(self, unit: str, first: str | None = None):
        self.unit, self.first = unit, first

    def seconds(self, cell: str, lineno: int) -> float:
        """Seconds of one timestamp (text) on input line ``lineno``; a DataError if it is not a time."""
        from ..io.timebase import times_to_seconds

        cell = cell.strip()
        if self.first is None:
            t, _ = times_to_seconds([cell], self.unit, where="follow mode", rows=[lineno], line_offset=0)
            self.first = cell
            return float(t[0])
        t, _ = times_to_seconds([self.first, cell], self.unit, where="follow mode", rows=[0, lineno],
                                line_offset=0)
        return float(t[1])

    def state(self) -> dict[str, Any]:
        """The clock's state as plain data (its unit and first timestamp)."""
        return {"unit": self.unit, "first": self.first}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a :meth:`state`; a bad state is refused with a DataError, unchanged."""
        if not isinstance(state, dict) or sorted(state) != ["first", "unit"]:
            raise DataError(f"LiveClock state: expected keys ['first', 'unit'], got {state!r}")
        first = state["first"]
        if not isinstance(state["unit"], str) or not (first is None or isinstance(first, str)):
            raise DataError(f"LiveClock state: unit must be text and first text or None, got {state!r}")
        self.unit, self.first = state["unit"], state["first"]


class EventLog:
    """A JSON Lines file of a live run's records that survives a resume.

    Opened for appending; :meth:`start` empties it for a fresh run or cuts it back to its length at
    a checkpoint (:meth:`sync` gives that length), so the records written after the checkpoint
    are written again by the resumed run and none is doubled.

    Parameters
    ----------
    path : path-like

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> p = Path(tempfile.mkdtemp()) / "events.jsonl"
    >>> with EventLog(p) as log:
    ...     log.start()
    ...     log.write('{"t": 0.5}')
    ...     size = log.sync()
    ...     log.write('{"t": 0.7}')
    >>> with EventLog(p) as log:
    ...     log.start(size)
    >>> p.read_text()
    '{"t": 0.5}\\n'
    """

    def __init__(self, path: str | os.PathLike):
        from ..base.outputs import io_error, open_device

        self.path = path
        self.fh = open_device(path, "wb")  # a device or a FIFO someone reads: written as it is
        self.device = self.fh is not None
        if self.fh is None:
            try:
                self.fh = open(path, "a+b", buffering=0)  # closed in close(); unbuffered
            except OSError as exc:
                raise io_error(path, exc) from None
            try:  # one writer per log: a second follower would write every record twice
                fcntl.flock(self.fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                self.fh.close()
                raise DataError(f"{path}: another process (a second follower) writes this event log; "
                                "give each follower its own --events file") from None

    def __enter__(self) -> EventLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self, size: int | None = None) -> None:
        """Empty the log (``size`` None) or cut it back to ``size`` bytes (a checkpoint's length)."""
        if self.device:
            return
        if size is None:
            self.fh.truncate(0)
            return
        size = int(size)
        if self.fh.seek(0, 2) < size:
            raise DataError(f"{self.path}: the event log is shorter ({self.fh.tell()} bytes) "
                            f"than at the checkpoint ({size} bytes); it is not this run's log")
        self.fh.truncate(size)

    def write(self, line: str) -> None:
        """Append one line (a JSON record, without its newline) and flush it; a full disk is a
        DataError naming the file, and the log is cut back to its last whole line."""
        from ..base.outputs import io_error

        data = memoryview(line.encode() + b"\n")
        pos = None if self.device else self.fh.seek(0, 2)
        try:
            while data:  # unbuffered: a short write goes on where it stopped
                data = data[self.fh.write(data):]
            if self.device:
                self.fh.flush()
        except OSError as exc:
            if pos is not None:
                try:
                    self.fh.truncate(pos)
                except OSError:
                    pass
            raise io_error(self.path, exc) from None

    def sync(self) -> int:
        """Flush the log to disk; returns its length in bytes."""
        from ..base.outputs import io_error

        try:
            self.fh.flush()
            if self.device:
                return 0
            os.fsync(self.fh.fileno())
        except OSError as exc:
            raise io_error(self.path, exc) from None
        return self.fh.seek(0, 2)

    def close(self) -> None:
        try:
            self.fh.close()
        except OSError:
            pass


class LiveMonitor:
    """The monitor of a config over a live stream: lines in, records out as they happen.

    Parameters
    ----------
    config : MonitorConfig or path-like
        The monitor configuration (its artifacts made with ``fdikit design``).
    input : {"csv", "candump"}, optional
        The line format; default the config's ``[log].format`` (``"can"`` or ``"candump"``:
        candump, ``"csv"``: CSV), else candump when the config names a DBC file (``[log].dbc``),
        else CSV.
    monitor : Monitor, optional
        The monitor to step (default: built from the config's artifacts); it is reset to one run.

    Attributes
    ----------
    kind : str
        The input format.
    samples : int
        Samples stepped so far (grid samples of candump input, data rows of CSV input).
    lines : int
        Input lines read up to the last one consumed.

    Raises
    ------
    DataError
        candump input without ``[log].dbc`` or ``[log].rate``.

    Examples
    --------
    >>> live = LiveMonitor("monitor.toml")  # doctest: +SKIP
    >>> for rec in live.records(open("log.csv")):  # doctest: +SKIP
    ...     print(rec)
    >>> live.save_checkpoint("follow.npz")  # doctest: +SKIP

    Resuming: a new LiveMonitor of the same config continues from the checkpoint, skipping the
    lines the checkpoint consumed when the input is replayed from its start:

    >>> live = LiveMonitor("monitor.toml")  # doctest: +SKIP
    >>> live.load_checkpoint("follow.npz")  # doctest: +SKIP
    >>> rest = list(live.records(open("log.csv")))  # doctest: +SKIP
    """

    def __init__(self, config: Any, *, input: str | None = None, monitor: Any = None):
        from .config import MonitorConfig, build_monitor, load_config

        cfg = config if isinstance(config, MonitorConfig) else load_config(config)
        mon = build_monitor(cfg) if monitor is None else monitor
        mon.reset(1)
        self.cfg, self.monitor = cfg, mon
        fmt = cfg.log.get("format", "auto")   # a declared format decides; else a DBC means candump
        self.kind = input or ("candump" if fmt in ("can", "candump") else "csv" if fmt == "csv"
                              else "candump" if cfg.log.get("dbc") else "csv")
        if self.kind not in ("csv", "candump"):
            raise DataError(f"unknown live input {self.kind!r}; use 'csv' or 'candump'")
        self.gridder = None
        if self.kind == "candump":
            from ..io.stream import FrameGridder

            dbc, rate = cfg.log.get("dbc"), cfg.log.get("rate")
            if not dbc:
                raise DataError(f"{cfg.path}: following candump lines needs [log].dbc")
            if rate is None:
                raise DataError(f"{cfg.path}: following candump lines needs [log].rate (Hz): a stream "
                                "cannot measure the source rate ahead of time")
            if cfg.log.get("resample", "previous") != "previous":
                raise DataError(f"{cfg.path}: [log].resample = {cfg.log['resample']!r} interpolates with "
                                "the next frame (not causal): a live monitor would date its decisions "
                                "before the data they rest on; follow mode needs the causal hold "
                                "(remove [log].resample or set it to 'previous')")
            sources = list(dict.fromkeys(c.source for c in cfg.channels))
            self.gridder = FrameGridder(cfg.path.parent / dbc, sources, rate)
        self.samples = 0             # grid samples (candump) or data rows (CSV) stepped
        self.lines = 0               # input lines read up to the last one consumed
        self.t_last: float | None = None   # latest time of a consumed input line
        self.header: list[str] | None = None
        self.time_first: str | None = None   # CSV: the first timestamp's text (the origin)
        self.first: str | None = None        # digest of the first input line (a resume checks it)
        self._resumed: dict | None = None
        self.counts = {"announcements": 0, "cleared": 0, "invalid": 0, "gaps": 0}  # follow()'s records
        self._since = 0
        self._every: int = 500
        self._hook: Callable[[LiveMonitor], None] | None = None

    # ------------------------------------------------------------------ checkpoint / resume
    def state(self) -> dict[str, Any]:
        """The live run's state as plain data: the monitor's, how far the input was read, the
        gridder's (candump input; else ``None``).

        Examples
        --------
        >>> sorted(LiveMonitor("monitor.toml").state())  # doctest: +SKIP
        ['follow', 'gridder', 'monitor']
        """
        follow = {"n": self.samples, "lines": self.lines, "t_last": self.t_last, "header": self.header,
                  "time_first": self.time_first, "first": self.first}
        return {"monitor": self.monitor.state(), "follow": follow,
                "gridder": None if self.gridder is None else self.gridder.state()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a :meth:`state` of a live run of the same config and input.

        The next :meth:`records` skips the input lines consumed before the state was taken (a
        replay of the input from its start) and steps everything after them (a live stream that
        goes on).

        Raises
        ------
        DataError
            A state that is not one of this live run (other keys, another monitor's channels,
            another gridder's signals, a gridder state for CSV input or none for candump).

        Examples
        --------
        >>> live.restore(earlier.state())  # doctest: +SKIP
        """
        if not isinstance(state, dict) or sorted(state) != ["follow", "gridder", "monitor"]:
            got = sorted(state) if isinstance(state, dict) else type(state).__name__
            raise DataError(f"live state: keys {got}, expected ['follow', 'gridder', 'monitor']")
        f = state["follow"]
        if not isinstance(f, dict) or any(k not in f for k in _FOLLOW_KEYS):
            raise DataError(f"live state: follow must be a dict with keys {list(_FOLLOW_KEYS)}")
        if (state["gridder"] is None) != (self.gridder is None):
            raise DataError(f"live state: {'no' if state['gridder'] is None else 'a'} gridder state, "
                            f"for {self.kind} input")
        try:
            n, lines = int(f["n"]), int(f["lines"])
        except (TypeError, ValueError):
            raise DataError(f"live state: n and lines must be counts, got {f['n']!r}, {f['lines']!r}"
                            ) from None
        self.monitor.restore(state["monitor"])
        self.samples, self.lines, self.t_last = n, lines, f["t_last"]
        self.header = f.get("header")
        self.time_first = f.get("time_first")
        self.first = f.get("first")
        if self.gridder is not None:
            self.gridder.restore(state["gridder"])
        self._resumed = {"lines": self.lines, "t_last": self.t_last, "first": self.first}

    def save_checkpoint(self, path: str | os.PathLike, *, events_bytes: int = 0) -> None:
        """Write :meth:`state` to ``path`` atomically (:func:`fdikit.base.state.save_state`).

        Parameters
        ----------
        path : path-like
        events_bytes : int
            The event log's length at this point (:meth:`EventLog.sync`), for the resumed run.

        Examples
        --------
        >>> live.save_checkpoint("follow.npz", events_bytes=log.sync())  # doctest: +SKIP
        """
        from ..base.state import save_state

        st = self.state()
        f = st["follow"]
        st["follow"] = {"n": f["n"], "lines": f["lines"], "t_last": f["t_last"], "events_bytes": events_bytes,
                        "header": f["header"], "time_first": f["time_first"], "first": f["first"]}
        save_state(path, st, meta={"kind": "follow", "input": self.kind,
                                   "config": str(self.cfg.path.resolve())})

    def load_checkpoint(self, path: str | os.PathLike) -> dict[str, Any]:
        """Continue from a file written by :meth:`save_checkpoint`; returns its ``follow`` record
        (``events_bytes``: the event log's length to cut back to, :meth:`EventLog.start`).

        Raises
        ------
        DataError
            Not a follow-mode checkpoint of this input kind or of this config, or a bad state.

        Examples
        --------
        >>> log.start(live.load_checkpoint("follow.npz")["events_bytes"])  # doctest: +SKIP
        """
        from ..base.state import load_state

        try:
            state, meta = load_state(path)
        except (zipfile.BadZipFile, EOFError, ValueError, KeyError) as exc:  # e.g. half written by hand
            raise DataError(f"{path}: not a readable fdikit checkpoint (truncated or corrupt: {exc})"
                            ) from None
        if meta.get("kind") != "follow" or meta.get("input") != self.kind:
            raise DataError(f"{path}: not a follow-mode checkpoint of {self.kind} input "
                            f"(kind {meta.get('kind')!r}, input {meta.get('input')!r})")
        if meta.get("config") != str(self.cfg.path.resolve()):
            raise DataError(f"{path}: checkpoint of config {meta.get('config')!r}, not "
                            f"{str(self.cfg.path.resolve())!r}")
        self.restore(state)
        return dict(state["follow"])

    # ------------------------------------------------------------------ the stream
    def _skip(self, index: int, t: float | None, text: str = "") -> bool:
        """Was input line ``index`` (0-based) consumed before the restored state?

        Yes while the line is among the first ``lines`` and not later than the last consumed
        time: a replay of the input from its start skips exactly what was consumed, and a live
        stream that goes on (later times) is not skipped at all.
        """
        r = self._resumed
        if r is None:
            return False
        done = index < r["lines"] and (t is None or r["t_last"] is None or t <= r["t_last"])
        if done and index == 0 and r.get("first") and _digest(text) != r["first"]:
            raise DataError(f"--resume: the input's first line {text.strip()[:60]!r} is not the first line "
                            "of the checkpointed run: a different log (replay the same input, or start "
                            "without --resume)")
        if not done:
            self._resumed = None  # past the checkpoint: nothing more is skipped
        return done

    def _consumed(self, index: int, t: float | None, text: str = "") -> None:
        if index == 0 and self._resumed is None:
            self.first = _digest(text)
        self.lines = index + 1
        if t is not None and (self.t_last is None or t > self.t_last):
            self.t_last = t

    def _step(self, t: float, vals: dict[str, float]) -> list[dict]:
        from .config import map_sample

        k = self.samples
        _, _, events = self.monitor.step(t, map_sample(self.cfg, vals))
        return step_records(self.monitor, t, k, events)

    def records(self, lines: Iterable[str], *, checkpoint_every: int = 500,
                on_checkpoint: Callable[[LiveMonitor], None] | None = None) -> Iterator[dict]:
        """Step the monitor over input lines as they arrive; yield each record at once.

        Parameters
        ----------
        lines : iterable of str
            The input (a file, ``sys.stdin``, any iterator of lines): CSV with its header line
            first, or ``candump -L`` lines.
        checkpoint_every : int
            Samples between calls of ``on_checkpoint``.
        on_checkpoint : callable, optional
            Called with this LiveMonitor every ``checkpoint_every`` samples (after the records up
            to that point were yielded) and at the end of the input, e.g. to
            :meth:`save_checkpoint`.

        Yields
        ------
        dict
            Records (:mod:`fdikit.monitor.records`), and ``{"line", "invalid"}`` for an input line
            that cannot be read.

        Raises
        ------
        DataError
            CSV input without a header line or without the time column in it.

        Examples
        --------
        >>> live = LiveMonitor("monitor.toml")  # doctest: +SKIP
        >>> onsets = [r for r in live.records(open("log.csv")) if r.get("kind") == "onset"]  # doctest: +SKIP
        """
        if checkpoint_every < 1:
            raise DataError(f"--checkpoint-every must be >= 1 sample, got {checkpoint_every}")
        self._every, self._hook = checkpoint_every, on_checkpoint
        if self.kind == "candump":
            return self._candump(lines)
        return self._csv(lines)

    def run(self, lines: Iterable[str], on_record: Callable[[dict], None], **kw) -> int:
        """:meth:`records` with a callback: ``on_record(record)`` for each; returns their number.

        Examples
        --------
        >>> LiveMonitor("monitor.toml").run(sys.stdin, print)  # doctest: +SKIP
        """
        n = 0
        for rec in self.records(lines, **kw):
            on_record(rec)
            n += 1
        return n

    def follow(self, lines: Iterable[str], *, on_record: Callable[[dict], None] | None = None,
               events: str | os.PathLike | None = None, checkpoint: str | os.PathLike | None = None,
               resume: bool = False, checkpoint_every: int = 500) -> int:
        """Follow mode: :meth:`records` with an event log and checkpoints; returns the records' number.

        Parameters
        ----------
        lines : iterable of str
            The input lines; a file object on a pipe or FIFO (``sys.stdin``) is read as its lines
            arrive, and Ctrl-C or SIGTERM end the wait for the next one at once
            (:func:`fdikit.base.inputs.iter_lines`).
        on_record : callable, optional
            Called with each record as it happens (before it is logged).
        events : path-like, optional
            The JSON Lines event log (:class:`EventLog`): emptied for a fresh run, cut back to the
            checkpoint's length on resume.
        checkpoint : path-like, optional
            Checkpoint file written every ``checkpoint_every`` samples and at the end
            (:meth:`save_checkpoint`, with the event log's length).
        resume : bool
            Continue from ``checkpoint`` if it exists (:meth:`load_checkpoint`).
        checkpoint_every : int
            Samples between checkpoints.

        Returns
        -------
        int

        Examples
        --------
        >>> live = LiveMonitor("monitor.toml")  # doctest: +SKIP
        >>> live.follow(sys.stdin, on_record=print, events="ev.jsonl", checkpoint="ck.npz",
        ...             resume=True)  # doctest: +SKIP
        """
        if resume and not checkpoint:
            raise DataError("--resume needs --checkpoint FILE (the checkpoint to continue from)")
        ckpt = Path(checkpoint) if checkpoint else None
        log = EventLog(events) if events else None
        try:
            if resume and ckpt is not None and ckpt.exists():
                size = self.load_checkpoint(ckpt)["events_bytes"]
                if log is not None:
                    log.start(size)
            elif log is not None:
                log.start()

            def save(live: LiveMonitor) -> None:
                live.save_checkpoint(ckpt, events_bytes=0 if log is None else log.sync())

            n = 0
            for rec in self.records(iter_lines(lines), checkpoint_every=checkpoint_every,
                                    on_checkpoint=save if ckpt is not None else None):
                self._count(rec)
                if on_record is not None:
                    on_record(rec)
                if log is not None:
                    log.write(json.dumps(rec))
                n += 1
            return n
        finally:
            if log is not None:
                log.close()

    def _count(self, rec: dict) -> None:
        c = self.counts
        key = ("gaps" if rec.get("gap") else "invalid" if "invalid" in rec
               else "announcements" if rec.get("kind") == "onset" else "cleared")
        c[key] += 1

    def summary_line(self) -> str:
        """One line on what a follow run did so far (printed at its end, and when it is stopped).

        Examples
        --------
        >>> LiveMonitor("monitor.toml").summary_line()  # doctest: +SKIP
        'follow: 0 samples, 0 announcements (0 not seen any more), 0 invalid lines or samples, 0 gaps'
        """
        c = self.counts
        return (f"follow: {self.samples} samples, {c['announcements']} announcements ({c['cleared']} "
                f"{NOT_SEEN}), {c['invalid']} invalid lines or samples, {c['gaps']} gaps")

    def _stepped(self) -> None:
        self.samples += 1
        self._since += 1

    def _maybe_checkpoint(self, force: bool = False) -> None:
        if self._hook is None or not (force or self._since >= self._every):
            return
        self._hook(self)
        self._since = 0

    def _candump(self, stream: Iterable[str]) -> Iterator[dict]:
        """Candump lines through the gridder and the monitor."""
        from ..io.stream import parse_candump_line

        grid = self.gridder

        def feed(samples):
            for t, vals, why in samples:
                recs = self._step(t, vals)
                if self.monitor.last_invalid is None and why:  # cannot happen: an invalid grid value is NaN
                    raise AssertionError(why)
                yield from recs
                self._stepped()

        for index, line in enumerate(stream):
            lineno = index + 1
            try:
                frame = parse_candump_line(line, lineno)
            except DataError as exc:
                if not self._skip(index, None, line):
                    yield {"line": lineno, "invalid": str(exc)}
                    self._consumed(index, None, line)
                continue
            t = None if frame is None else frame[0]
            if self._skip(index, t, line):
                continue
            self._consumed(index, t, line)
            if frame is None:
                continue
            t, bus, fid, data = frame
            try:
                samples = grid.push(t, fid, data, bus)
            except DataError as exc:  # e.g. time going back: the frame is refused, the stream goes on
                yield {"line": lineno, "invalid": str(exc)}
                continue
            yield from feed(samples)
            self._maybe_checkpoint()
        yield from feed(grid.flush())
        self._maybe_checkpoint(force=True)

    def _csv(self, stream: Iterable[str]) -> Iterator[dict]:
        """CSV lines (a header line first) through the monitor."""
        tcol = self.cfg.log.get("time", "t")
        clock = LiveClock(self.cfg.time_unit, self.time_first)
        lines = iter(stream)
        header = self.header
        first = next(lines, None)
        if header is None or (first is not None and _cells(first, 1) == header):
            if first is None:
                raise DataError("follow mode: no header line on the input")
            header = _cells(first, 1)
            lines_iter = lines
        else:  # resumed on a stream that goes on without repeating its header
            lines_iter = itertools.chain([first], lines) if first is not None else lines
        if tcol not in header:
            raise DataError(f"follow mode: the header has no time column {tcol!r}: {header}")
        self.header = header
        it = header.index(tcol)
        for index, text in enumerate(lines_iter):
            lineno = index + 2
            try:
                row = _cells(text, lineno, strip=False)
            except DataError as exc:  # e.g. a field longer than the CSV module's limit
                if not self._skip(index, None, text):
                    self._consumed(index, None, text)
                    yield {"line": lineno, "invalid": str(exc)}
                continue
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
            if self._skip(index, t_row, text):
                continue
            self._consumed(index, t_row, text)
            if len(row) != len(header):
                yield {"line": lineno, "invalid": f"{len(row)} fields, expected {len(header)}"}
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
                yield {"line": lineno, "invalid": f"time {row[it]!r} is not a number"}
                continue
            self.time_first = clock.first
            yield from self._step(t_row, vals)
            self._stepped()
            self._maybe_checkpoint()
        self._maybe_checkpoint(force=True)
