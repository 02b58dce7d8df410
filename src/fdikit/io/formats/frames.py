"""The frame-level half of the CAN loaders: frames (times, ids, payloads) decoded with a DBC onto the grid.

The log's clock is judged here, on the frames of every message at once:

* a step **back** of at least :data:`CLOCK_STEP_BACK` seconds is a clock step (a logger that
  re-synchronises): the log is split into segments there, the frames from the step on are shifted
  to start :data:`CLOCK_BREAK` seconds after the last frame before it, and each segment is
  gridded and judged on its own (a smaller step back is a shuffled or corrupt log: refused);
* a stretch with no frame of any requested message that is a gap for every signal (a clock jump
  forward, a logger pause, or the break between two segments) is cut from the grid: the grid
  time jumps over it, so a monitor sees a gap (it holds, counts it and re-enters warm-up),
  never a run of NaN samples.

Both are listed in :attr:`LoadedSignals.breaks`, with the grid times around them and a reason.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...errors import DataError
from ..can import _load_resolved
from ..decode import FramePayloads, decode_message
from ..timebase import origin_of_float
from .checks import _check_signal_list
from .grid import LoadedSignals, SourceReport, series_to_grid

#: Smallest step back of the frame times (s) taken as a clock step (a new segment); a smaller
#: one is a shuffled log and refused.
CLOCK_STEP_BACK = 0.1
#: Time (s) put between the last frame before a clock step and the first one after it.
CLOCK_BREAK = 10.0


def frames_to_signals(
    ts: np.ndarray,
    ids: np.ndarray,
    data: Sequence[bytes],
    dbc: Any,
    signals: Sequence[str],
    rate: float | None = None,
    *,
    units: str | Mapping[str, str] | None = None,
    max_gap: float = 3.0,
    method: str = "previous",
    span: str = "common",
    stuck_after: float = 2.0,
    lines: np.ndarray | None = None,
    channels: Sequence[str] | None = None,
    channel: str | int | None = None,
    source: SourceReport | None = None,
    where: str = "CAN log",
    plausibility: Mapping[str, Any] | None = None,
) -> LoadedSignals:
    """Decode CAN frames with a DBC and put the chosen signals on one grid.

    The frame-level half of :func:`fdikit.io.read_can_log`, for frames from any source.

    Parameters
    ----------
    ts : ndarray, shape (N,)
        Frame times (s), non-decreasing except at clock steps back (see the module docstring);
        time 0 of the result is ``ts[0]``.
    ids : ndarray of int, shape (N,)
        Arbitration ids.
    data : sequence of bytes or FramePayloads, length N
        Payloads. A payload too short for a signal gives a bad (NaN) sample of that signal,
        never zero padding. Each message's signals are decoded over all its frames at once
        (:func:`fdikit.io.decode.decode_message`, equal to cantools' per-frame decoding).
    dbc : path-like or cantools Database
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names.
    rate, units, max_gap, method, span, stuck_after
        As in :func:`series_to_grid`.
    lines : ndarray of int, shape (N,), optional
        Line number of each frame in a text log (for error messages).
    channels : sequence of str, length N, optional
        The bus (channel) of each frame, as the log names it. When given, a message seen on
        more than one bus is refused unless ``channel`` picks one: frames of two buses are
        never mixed into one signal.
    channel : str or int, optional
        Keep only the frames of this bus (compared as text with ``channels``).
    source : SourceReport, optional
    where : str
        Name of the source in error messages.
    plausibility : mapping of str -> Plausibility or mapping, optional
        Range and spike rules per signal (in its returned unit), applied to each frame's value
        before resampling (:mod:`fdikit.io.formats.raw_checks`; the DBC scale is the signal's
        resolution): an implausible frame flags the grid samples it would touch.

    Returns
    -------
    LoadedSignals
        With :attr:`~LoadedSignals.breaks` listing clock steps and stretches cut from the grid.

    Raises
    ------
    DataError
        Time going backwards by less than :data:`CLOCK_STEP_BACK` (a shuffled log; naming frame
        and line), a DBC without a requested signal, a requested message with no frame.

    Examples
    --------
    >>> import numpy as np, cantools
    >>> db = cantools.database.load_string('''VERSION ""
    ... BO_ 180 SPEED: 8 XXX
    ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
    ... ''', database_format="dbc")
    >>> s = frames_to_signals(np.array([0.0, 0.1, 0.2]), np.array([180, 180, 180]),
    ...                       [bytes([0, 0, 0, 0, 0, 0x03, 0xE8, 0])] * 3, db, ["SPEED.SPEED"], rate=10)
    >>> s["SPEED.SPEED"].tolist(), s.units
    ([[10.0, 10.0, 10.0]], ['km/h'])
    """
    signals = _check_signal_list(signals)
    _, resolved = _load_resolved(dbc, signals)
    ts = np.asarray(ts, float)
    ids = np.asarray(ids, np.int64)
    if ts.size == 0:
        raise DataError(f"{where} holds no CAN frames")
    if ts.shape != ids.shape or len(data) != ts.size:
        raise DataError(f"{where}: {ts.size} time stamps, {ids.size} ids and {len(data)} payloads")
    payloads = FramePayloads.from_bytes(data)
    ts, steps = _clock_segments(ts, where, lines)
    t0, t_end = float(ts[0]), float(ts[-1])
    chan = None
    if channels is not None:
        chan = np.asarray([str(c) for c in channels])
        if chan.size != ts.size:
            raise DataError(f"{where}: {chan.size} channels for {ts.size} frames")
    if channel is not None:
        if chan is None:
            raise DataError(f"{where} does not record the bus of its frames; channel= cannot be used")
        keep = chan == str(channel)
        if not keep.any():
            raise DataError(f"{where} has no frame on channel {str(channel)!r}; its channels are "
                            f"{sorted(set(chan.tolist()))}")
        ts, ids, chan = ts[keep], ids[keep], chan[keep]
        payloads = payloads.take(keep)
        lines = None if lines is None else np.asarray(lines)[keep]

    def select(fid: int, msg) -> np.ndarray:
        idx = np.flatnonzero(ids == fid)
        if idx.size and chan is not None and channel is None and np.unique(chan[idx]).size > 1:
            raise DataError(f"{where}: message {msg.name!r} (id 0x{fid:x}) is on several buses "
                            f"{sorted(set(chan[idx].tolist()))}; pass channel= to choose one")
        return idx

    return _decode_to_grid(resolved, signals, select, ts.__getitem__, payloads.take, t0, t_end, rate,
                           units=units, max_gap=max_gap, method=method, span=span, stuck_after=stuck_after,
                           source=source, where=where, plausibility=plausibility, steps=steps)


def _clock_segments(ts: np.ndarray, where: str, lines: np.ndarray | None = None
                    ) -> tuple[np.ndarray, list[tuple[float, float, str]]]:
    """Frame times with every clock step back shifted out (module docstring), and the steps:
    ``(time of the last frame before, time of the first after (shifted), reason)``. Raises when
    a time is not finite or steps back by less than :data:`CLOCK_STEP_BACK` (shuffled frames)."""

    def _at(k: int) -> str:
        return f"frame {k}" + (f" (line {int(lines[k])})" if lines is not None else "")

    if not np.isfinite(ts).all() or not np.any(ts[1:] < ts[:-1]):
        _check_frame_times(ts, where, lines)
        return ts, []
    d = np.diff(ts)
    back = np.flatnonzero(d < 0)
    small = back[d[back] > -CLOCK_STEP_BACK]
    if small.size:  # a shuffled log: the usual error at the first step back
        _check_frame_times(ts, where, lines)
    ts = ts.copy()
    steps = []
    for k in back + 1:
        shift = float(ts[k - 1] - ts[k]) + CLOCK_BREAK
        before = float(ts[k - 1])
        raw = float(ts[k])
        ts[k:] += shift
        steps.append((before, float(ts[k]),
                      f"the log's clock steps back by {before - raw:.6g} s at {_at(int(k))} "
                      f"({before!r} s then {raw!r} s): a new segment, its frames shifted by "
                      f"+{shift:.6g} s"))
    if np.any(np.diff(ts) < 0):  # a later segment overlapping an earlier one: cannot be
        _check_frame_times(ts, where, lines)
    return ts, steps


def _cut_clock_gaps(out: LoadedSignals, t0: float, steps) -> LoadedSignals:
    """Drop the grid samples at which every channel is in a gap (no frame of any requested
    message: a clock jump, a pause, the break between segments) and list them in ``breaks``."""
    if out.n_samples == 0 or out.valid[0].any(axis=1).all():
        out.breaks = [(b - t0, a - t0, why) for b, a, why in steps] if steps else []
        return out
    names = list(out.names)
    in_gap = np.zeros((out.n_samples, len(names)), bool)
    col = {n: i for i, n in enumerate(names)}
    for n, a, b, why in out.reasons:
        if ": gap, no sample from " in why:
            in_gap[a:b, col[n]] = True
    dead = in_gap.all(axis=1)
    if dead.any():  # with it the edge samples at which some channel is still in that gap
        part = in_gap.any(axis=1)
        run_id = np.cumsum(np.r_[True, part[1:] != part[:-1]])
        dead = part & np.isin(run_id, np.unique(run_id[dead]))
    breaks = []
    grid = out.t
    d = np.diff(np.r_[0, dead.astype(np.int8), 0])
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        lo = float(grid[a - 1]) if a > 0 else float(grid[a])
        hi = float(grid[b]) if b < grid.size else float(grid[b - 1])
        # a step's stretch overlaps the cut run (with a causal hold the run starts up to max_gap
        # source periods after the step's last frame, so containment is not required)
        why = [s for bt, at, s in steps if lo <= at - t0 and bt - t0 <= hi]
        breaks.append((lo, hi, "; ".join(why) if why else
                       f"no frame of any requested message from {lo:.6f} s to {hi:.6f} s (a clock jump "
                       f"or a logger pause): a gap of {b - a} grid samples, cut from the grid"))
    for bt, at, s in steps:
        if not any(lo <= at - t0 and bt - t0 <= hi for lo, hi, _ in breaks):
            breaks.append((bt - t0, at - t0, s))
    if not dead.any():
        out.breaks = breaks
        return out
    keep = ~dead
    before = np.r_[0, np.cumsum(keep)]  # kept samples before index i
    reasons = []
    for n, a, b, why in out.reasons:
        a2, b2 = int(before[a]), int(before[b])
        if b2 > a2:
            reasons.append((n, a2, b2, why))
    valid = out.valid[:, keep]
    info = {n: dataclasses.replace(q, n_invalid=int(np.count_nonzero(~valid[0, :, col[n]])))
            if dataclasses.is_dataclass(q) else q for n, q in out.info.items()}
    cut = LoadedSignals(out.t[keep], out.values[:, keep], out.names, out.units, valid=valid, info=info,
                        source=out.source, t0=out.t0, time_origin=out.time_origin, reasons=reasons)
    cut.breaks = sorted(breaks)
    return cut


def _check_frame_times(ts: np.ndarray, where: str, lines: np.ndarray | None = None) -> None:
    """Frame times must be finite and never go back (the error names the frame and line)."""

    def _at(k: int) -> str:
        return f"frame {k}" + (f" (line {int(lines[k])})" if lines is not None else "")

    if not np.isfinite(ts).all():
        bad = np.flatnonzero(~np.isfinite(ts))
        raise DataError(f"{where}: {_at(int(bad[0]))} has a non-finite time stamp")
    if np.any(ts[1:] < ts[:-1]):  # finite times: the same test as np.diff(ts) < 0
        k = int(np.flatnonzero(np.diff(ts) < 0)[0]) + 1
        raise DataError(f"{where}: time goes backwards at {_at(k)}: {float(ts[k - 1])!r} s then "
                        f"{float(ts[k])!r} s "
                        "(shuffled or corrupt log)")


def _decode_to_grid(resolved, signals: list[str], select, times, payloads, t0: float, t_end: float,
                    rate, *, source, where, steps=(), **kw) -> LoadedSignals:
    """Decode the requested signals per message and put them on the grid (:func:`frames_to_signals`
    after its checks). ``select(frame_id, msg)`` gives the indices of a message's frames,
    ``times(idx)`` their absolute times and ``payloads(idx)`` their :class:`FramePayloads`."""
    by_msg: dict[int, list[tuple[str, Any, Any]]] = {}
    for full, msg, sig in resolved:
        by_msg.setdefault(msg.frame_id, []).append((full, msg, sig))
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    src_units: dict[str, str] = {}
    counts: dict[str, dict[str, int]] = {}
    resolution: dict[str, float] = {}
    for fid, wanted in by_msg.items():
        msg = wanted[0][1]
        idx = select(fid, msg)
        if idx.size == 0:
            raise DataError(f"{where} has no frame of message {msg.name!r} (id 0x{fid:x}) needed for "
                            f"{[w[0] for w in wanted]}")
        snames = [w[2].name for w in wanted]
        # all frames of this message at once (numpy bit extraction; multiplexed messages per frame)
        cols, n_bad = decode_message(msg, snames, payloads(idx))
        tm = times(idx) - t0
        for c, (full, _msg, sig) in enumerate(wanted):
            series[full] = (tm, cols[:, c])
            src_units[full] = sig.unit or ""
            resolution[full] = abs(float(sig.scale or 0.0))
            counts[full] = {"n_undecodable": int(n_bad[c])}
    series = {s: series[s] for s in signals}
    if kw.get("plausibility") is not None:
        kw["resolution"] = resolution
    out = series_to_grid(series, src_units, rate, log_span=(0.0, t_end - t0), counts=counts, source=source,
                         where=where, t0=t0, time_origin=origin_of_float(t0), **kw)
    return _cut_clock_gaps(out, t0, list(steps))


def _blf_to_signals(frames, dbc, signals, rate=None, *, units=None, max_gap: float = 3.0,
                    method: str = "previous", span: str = "common", stuck_after: float = 2.0,
                    source: SourceReport | None = None, where: str = "CAN log",
                    plausibility: Mapping[str, Any] | None = None) -> LoadedSignals:
    """:func:`frames_to_signals` on a :class:`fdikit.io.decode.BlfFrames` (a BLF read on demand):
    the same checks, errors and numbers, with times and payloads read only for the frames of
    the requested messages."""
    signals = _check_signal_list(signals)
    _, resolved = _load_resolved(dbc, signals)
    times, steps = frames.times, []
    if not frames.times_ordered():  # the ticks cannot tell: check the times themselves
        all_t, steps = _clock_segments(frames.times(), where)
        if steps:
            times = all_t.__getitem__
    first_last = times(np.array([0, frames.n_frames - 1]))
    t0, t_end = float(first_last[0]), float(first_last[1])

    def select(fid: int, msg) -> np.ndarray:
        return frames.select(fid)

    return _decode_to_grid(resolved, signals, select, times, frames.payloads, t0, t_end, rate,
                           units=units, max_gap=max_gap, method=method, span=span, stuck_after=stuck_after,
                           source=source, where=where, plausibility=plausibility, steps=steps)
