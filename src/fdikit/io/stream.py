"""Live CAN frames onto the monitor's grid: candump lines in, grid samples out, as they arrive.

:class:`FrameGridder` is the streaming form of :func:`fdikit.io.frames_to_signals` (the batch
loader of every frame log): frames are decoded with the DBC as they come, and each grid sample
is released as soon as every requested signal has a frame at or after its time, with the same
arithmetic as the batch loader, so on the same frames the two give the same values:

* time 0 is the first frame of the stream (of any message);
* the grid starts at the latest first-frame time of the requested signals (the batch loader's
  common span) and runs at ``rate`` Hz;
* values are the last frame at or before the grid time (``method="previous"``, the causal
  default; a frame at most :data:`~fdikit.io.can.HOLD_TOL` after it counts as at it), or linear
  interpolations between the neighbouring frames (``method="linear"``: ``v0 + w (v1 - v0)``, a
  frame exactly at a grid time gives its value);
* a grid sample is invalid (NaN, with the reason) when its neighbouring frames are more than
  ``max_gap`` source periods apart, or when it touches a frame that could not be decoded or
  carried a NaN/inf value.

A run of grid samples with a gap in some signal is held back until it ends: when at one of its
samples *every* signal is in a gap (no frame of any requested message: a clock jump forward, a
pause of the logger), the whole run is dropped and the grid time jumps over it -- the batch
loader's rule (:mod:`fdikit.io.formats.frames`), so the monitor sees a gap, not NaN samples.
(A clock step *back* is still refused frame by frame here: a stream cannot tell it from one
corrupt time stamp without looking ahead.)

The one difference a stream cannot avoid: the batch loader measures a signal's period as the
median interval over the *whole* log, the stream as the median interval of the frames seen so
far (the last 256); the two agree on any log without gaps, and a gap is flagged by both.

:func:`parse_candump_line` reads one line of ``candump -L`` (``(time) bus ID#DATA``), the format
of live SocketCAN logging.
"""

from __future__ import annotations

import itertools
import math
import re
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import DataError
from .can import HOLD_TOL, _load_dbc, _resolve

__all__ = ["FrameGridder", "parse_candump_line"]

_CANDUMP = re.compile(r"^\s*\((?P<t>[-+0-9.eE]+)\)\s+(?P<bus>\S+)\s+(?P<id>[0-9A-Fa-f]{1,8})"
                      r"#(?P<fd>#[0-9A-Fa-f])?(?P<data>[0-9A-Fa-f.]*|R\d*)(?:\s+[RT])?\s*$")


def parse_candump_line(line: str, lineno: int | None = None) -> tuple[float, str, int, bytes] | None:
    """One ``candump -L`` line as ``(time_s, bus, arbitration_id, payload)``; ``None`` for a blank line.

    Remote frames (``ID#R``) carry no data and give an empty payload; CAN FD frames
    (``ID##<flags><data>``) are accepted, and so is the direction flag (`` R`` received,
    `` T`` transmitted) that newer can-utils and python-can write after the payload.

    Raises
    ------
    DataError
        A line that is not a candump frame, naming the line number and its text.

    Examples
    --------
    >>> parse_candump_line("(1700000000.250000) can0 0B4#00000000000003E8")
    (1700000000.25, 'can0', 180, b'\\x00\\x00\\x00\\x00\\x00\\x00\\x03\\xe8')
    """
    if not line.strip():
        return None
    m = _CANDUMP.match(line)
    where = f"line {lineno}" if lineno is not None else "line"
    if m is None:
        raise DataError(f"candump {where} is not a frame '(time) bus ID#DATA': {line.strip()[:80]!r}")
    data = m["data"]
    if data.startswith("R"):
        payload = b""
    else:
        data = data.replace(".", "")
        if len(data) % 2:
            raise DataError(f"candump {where}: payload {m['data']!r} has an odd number of hex digits")
        payload = bytes.fromhex(data)
    t = float(m["t"])
    if not math.isfinite(t):
        raise DataError(f"candump {where}: time stamp {m['t']!r} is not finite")
    return t, m["bus"], int(m["id"], 16), payload


class _Series:
    """Frames of one signal still needed: from the last frame at or before the next grid time on."""

    __slots__ = ("first", "intervals", "t", "v")

    def __init__(self):
        self.t: list[float] = []
        self.v: list[float] = []
        self.intervals: deque[float] = deque(maxlen=256)
        self.first: float | None = None


class FrameGridder:
    """Decode live CAN frames with a DBC and release grid samples as soon as they are complete.

    Parameters
    ----------
    dbc : path-like or cantools Database
    signals : sequence of str
        ``"MESSAGE.SIGNAL"`` names (the output order).
    rate : float
        Grid rate (Hz). Required: a stream cannot look ahead for the median source rate.
    max_gap : float
        Longest bridged interval, in source periods (as the batch loader).
    method : {"previous", "linear"}
        Causal hold of the last frame (default) or linear interpolation (as the batch loader).
    channel : str, optional
        Keep only frames of this bus; without it, a requested message seen on two buses is refused
        (frames of two buses are never mixed into one signal), as in the batch loader.
    max_jump : float
        Longest interval (s) between two frames that the gridder bridges with grid samples
        (default one hour). A later frame is refused with a DataError naming it, as a corrupt clock:
        one garbled time stamp would otherwise make the gridder emit the whole interval, 3.6e5
        samples per hour at 100 Hz. Frames after it are judged against the last accepted one.

    Examples
    --------
    >>> import cantools
    >>> db = cantools.database.load_string('''VERSION ""
    ... BO_ 180 SPEED: 8 XXX
    ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
    ... ''', database_format="dbc")
    >>> g = FrameGridder(db, ["SPEED.SPEED"], rate=10.0)
    >>> out = []
    >>> for k, kmh in enumerate([10.0, 12.0, 14.0]):
    ...     out += g.push(100.0 + 0.1 * k, 180, (int(kmh * 100) << 8).to_bytes(8, "big"))
    >>> out += g.flush()
    >>> [(round(t, 3), round(v["SPEED.SPEED"], 6), why) for t, v, why in out]
    [(0.0, 10.0, None), (0.1, 12.0, None), (0.2, 14.0, None)]
    """

    def __init__(self, dbc: Any, signals: Sequence[str], rate: float, *, max_gap: float = 3.0,
                 method: str = "previous", channel: str | None = None, max_jump: float = 3600.0):
        if isinstance(signals, str) or not signals:
            raise DataError("signals must be a non-empty list of 'MESSAGE.SIGNAL' names")
        self.signals = [str(s) for s in signals]
        try:
            rate = float(rate)
        except (TypeError, ValueError):
            raise DataError(f"rate must be a positive number of Hz, got {rate!r}") from None
        if not (math.isfinite(rate) and rate > 0):
            raise DataError(f"rate must be a positive number of Hz, got {rate}")
        if not (math.isfinite(max_gap) and max_gap > 0):
            raise DataError(f"max_gap must be a positive number of source periods, got {max_gap!r}")
        if method not in ("linear", "previous"):
            raise DataError(f"unknown resampling method {method!r}; use 'linear' or 'previous'")
        try:
            max_jump = float(max_jump)
        except (TypeError, ValueError):
            raise DataError(f"max_jump must be a positive number of seconds, got {max_jump!r}") from None
        if not (math.isfinite(max_jump) and max_jump > 0):
            raise DataError(f"max_jump must be a positive number of seconds, got {max_jump!r}")
        self.max_jump = max_jump
        self.rate, self.max_gap, self.method, self.channel = rate, float(max_gap), method, channel
        db = _load_dbc(dbc)
        self._by_id: dict[int, list[tuple[str, Any, str]]] = {}
        for full, msg, sig in _resolve(db, self.signals):
            self._by_id.setdefault(msg.frame_id, []).append((full, msg, sig.name))
        self._series = {s: _Series() for s in self.signals}
        self._bus: dict[int, str] = {}
        self._t0: float | None = None
        self._t_last: float | None = None
        self._start: float | None = None
        self._k = 0
        self._pending: list[tuple[float, dict[str, float], str | None, bool]] = []
        self.frames = 0
        self.undecodable = 0

    # --------------------------------------------------------------------- internals
    def _period(self, s: _Series) -> float:
        return float(np.median(np.fromiter(s.intervals, float))) if s.intervals else math.inf

    def _value(self, name: str, g: float, final: bool) -> tuple[float, str | None]:
        """Value of one signal at grid time g, with the batch loader's arithmetic."""
        s = self._series[name]
        t, v = s.t, s.v
        # i: the last frame at or before g (frames before it were trimmed)
        i = 0
        g_at = g + HOLD_TOL if self.method == "previous" else g
        while i + 1 < len(t) and t[i + 1] <= g_at:
            i += 1
        lim = self.max_gap * self._period(s)
        bad = f"{name}: undecodable or non-finite frame"
        if self.method == "previous":
            if g - t[i] > lim:
                return math.nan, f"{name}: no frame for {g - t[i]:.4g} s (gap)"
            return (v[i], None) if math.isfinite(v[i]) else (math.nan, f"{bad} at {t[i]:.6f} s")
        i0 = i
        if i + 1 >= len(t):  # only at the end of the stream: g sits on the last frame
            if len(t) < 2:
                return (v[i], None) if math.isfinite(v[i]) else (math.nan, f"{bad} at {t[i]:.6f} s")
            i0 = i - 1
        t0, t1, v0, v1 = t[i0], t[i0 + 1], v[i0], v[i0 + 1]
        span = t1 - t0
        exact = t[i] == g
        if span > lim and not exact:
            return math.nan, f"{name}: frames {span:.4g} s apart (gap longer than {self.max_gap:g} periods)"
        w = (g - t0) / span if span > 0 else 0.0
        if (not math.isfinite(v0) and w < 1) or (not math.isfinite(v1) and w > 0):
            return math.nan, f"{bad} next to {g:.6f} s"
        return v0 + w * ((v1 if math.isfinite(v1) else 0.0) - (v0 if math.isfinite(v0) else 0.0)), None

    def _emit(self, final: bool = False) -> list[tuple[float, dict[str, float], str | None]]:
        out: list[tuple[float, dict[str, float], str | None]] = []
        if self._start is None:
            return out
        while True:
            g = self._start + self._k / self.rate
            # ready: every signal has a frame after g (at the end: at or after g)
            g_at = g + HOLD_TOL if self.method == "previous" else g
            for s in self._series.values():
                if s.t[-1] < g or (s.t[-1] <= g_at and not final):
                    return out
            vals, why = {}, []
            n_gap = 0
            for n in self.signals:
                x, reason = self._value(n, g, final)
                vals[n] = x
                if reason:
                    why.append(reason)
                    n_gap += "gap" in reason
            if n_gap:  # held back until the run of gap samples ends
                self._pending.append((g, vals, "; ".join(why), n_gap == len(self.signals)))
            else:
                out.extend(self._release())
                out.append((g, vals, "; ".join(why) or None))
            self._k += 1
            g_next = self._start + self._k / self.rate
            for s in self._series.values():  # drop frames no later grid time can use (keep one
                j = 0                           # before the bracket: the end-of-stream formula)
                while j + 2 < len(s.t) and s.t[j + 2] <= g_next:
                    j += 1
                if j:
                    del s.t[:j], s.v[:j]

    def _release(self) -> list[tuple[float, dict[str, float], str | None]]:
        """The held-back run of gap samples: dropped when every signal is in a gap at one of them."""
        run, self._pending = self._pending, []
        if any(dead for *_x, dead in run):
            return []
        return [(g, vals, why) for g, vals, why, _dead in run]

    # --------------------------------------------------------------------- public
    @property
    def t0(self) -> float | None:
        """Absolute time (s) of the stream's first frame: grid time ``t`` is ``t0 + t``
        (``None`` before the first frame), as ``LoadedSignals.t0`` of the batch loader."""
        return self._t0

    def push(self, t: float, frame_id: int, data: bytes, bus: str | None = None
             ) -> list[tuple[float, dict[str, float], str | None]]:
        """Add one frame (absolute time in s); return the grid samples it completes.

        Each sample is ``(t_grid, {signal: value}, reason)`` with time relative to the first frame
        of the stream and ``reason`` ``None`` for a valid sample, else why it is invalid (its
        values are NaN where invalid).
        """
        t = float(t)
        if not math.isfinite(t):
            raise DataError(f"frame {self.frames}: non-finite time stamp")
        if self._t_last is not None and t < self._t_last:
            raise DataError(f"frame {self.frames}: time goes backwards ({self._t_last!r} s then {t!r} s)")
        if self._t_last is not None and t - self._t_last > self.max_jump:
            raise DataError(f"frame {self.frames}: time stamp {t!r} s is {t - self._t_last:.6g} s after the "
                            f"previous frame ({self._t_last!r} s), more than max_jump = {self.max_jump:g} s: "
                            "a corrupt clock; the frame is refused")
        if self.channel is not None and bus is not None and str(bus) != str(self.channel):
            self.frames += 1
            self._t_last = t
            if self._t0 is None:
                self._t0 = t
            return []
        if self._t0 is None:
            self._t0 = t
        self._t_last = t
        self.frames += 1
        wanted = self._by_id.get(int(frame_id))
        if not wanted:
            return []
        if bus is not None and self.channel is None:
            seen = self._bus.setdefault(int(frame_id), str(bus))
            if seen != str(bus):
                raise DataError(f"message {wanted[0][1].name!r} (id 0x{int(frame_id):x}) is on several buses "
                                f"[{seen!r}, {str(bus)!r}]; choose one with channel=")
        tr = t - self._t0
        try:
            dec = wanted[0][1].decode(bytes(data), decode_choices=False, scaling=True, allow_truncated=True)
        except Exception:  # cantools raises several types for payloads it cannot decode
            dec = {}
            self.undecodable += 1
        for full, _msg, sname in wanted:
            x = dec.get(sname)
            val = float(x) if x is not None else math.nan
            s = self._series[full]
            if s.t and s.t[-1] == tr:  # same time twice: equal merges, different is a bad sample
                if not (s.v[-1] == val or (math.isnan(s.v[-1]) and math.isnan(val))):
                    s.v[-1] = math.nan
                continue
            if s.t:
                s.intervals.append(tr - s.t[-1])
            else:
                s.first = tr
            s.t.append(tr)
            s.v.append(val)
        if self._start is None:
            if all(s.first is not None for s in self._series.values()):
                self._start = max(s.first for s in self._series.values())
            else:  # still waiting for a signal's first frame: keep only what the grid start can use
                for s in self._series.values():
                    if len(s.t) > 2:
                        del s.t[:-2], s.v[:-2]
        return self._emit()

    def flush(self) -> list[tuple[float, dict[str, float], str | None]]:
        """At the end of the stream: release the samples that sit exactly on the last frames."""
        out = self._emit(final=True)
        return out + self._release()

    # --------------------------------------------------------------------- checkpoint / restore
    def state(self) -> dict[str, Any]:
        """The streaming state as plain data (lists, numbers, ``None``), for a checkpoint.

        The frames each signal still needs, its recent intervals (the period estimate) and first
        frame time, the bus of every message seen, the stream's first and last frame times, the
        grid start and index, and the frame counters. :meth:`restore` on a gridder built with the
        same signals continues bit for bit.

        Examples
        --------
        >>> import cantools
        >>> db = cantools.database.load_string('''VERSION ""
        ... BO_ 180 SPEED: 8 XXX
        ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
        ... ''', database_format="dbc")
        >>> frame = lambda kmh: (int(kmh * 100) << 8).to_bytes(8, "big")
        >>> g = FrameGridder(db, ["SPEED.SPEED"], rate=10.0)
        >>> g.push(100.0, 180, frame(10.0))
        []
        >>> h = FrameGridder(db, ["SPEED.SPEED"], rate=10.0)
        >>> h.restore(g.state())
        >>> [(round(t, 3), round(v["SPEED.SPEED"], 6)) for t, v, _ in h.push(100.1, 180, frame(12.0))]
        [(0.0, 10.0)]
        """
        series = {name: {"t": list(s.t), "v": list(s.v), "intervals": list(s.intervals), "first": s.first}
                  for name, s in self._series.items()}
        return {"series": series, "bus": {str(k): v for k, v in self._bus.items()}, "t0": self._t0,
                "t_last": self._t_last, "start": self._start, "k": self._k, "frames": self.frames,
                "undecodable": self.undecodable,
                "pending": [[g, dict(vals), why, dead] for g, vals, why, dead in self._pending]}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a :meth:`state` of a gridder of the same signals.

        The state is checked in full before anything changes: a state of other signals, with a
        missing key, or with values of the wrong kind is refused and the gridder is left as it was.

        Raises
        ------
        DataError
            Naming the key and what is wrong with it.

        Examples
        --------
        >>> import cantools
        >>> db = cantools.database.load_string('''VERSION ""
        ... BO_ 180 SPEED: 8 XXX
        ...  SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
        ... ''', database_format="dbc")
        >>> FrameGridder(db, ["SPEED.SPEED"], rate=10.0).restore({"series": {}})
        Traceback (most recent call last):
        ...
        fdikit.errors.DataError: FrameGridder state: missing keys ['bus', 'frames', ...]
        """
        where = "FrameGridder state"
        if not isinstance(state, dict):
            raise DataError(f"{where}: a state must be a dict, got {type(state).__name__}")
        keys = {"series", "bus", "t0", "t_last", "start", "k", "frames", "undecodable"}
        if keys - set(state):
            raise DataError(f"{where}: missing keys {sorted(keys - set(state))}")
        if set(state) - keys - {"pending"}:  # pending: optional (checkpoints before issue 27)
            raise DataError(f"{where}: unknown keys {sorted(set(state) - keys - {'pending'})}")
        pending = state.get("pending", [])
        if not isinstance(pending, list | tuple) or not all(
                isinstance(p, list | tuple) and len(p) == 4 and isinstance(p[1], dict) for p in pending):
            raise DataError(f"{where}: pending must be a list of [t, values, reason, dead] samples")

        series = state["series"]
        if not isinstance(series, dict) or sorted(series) != sorted(self._series):
            got = sorted(series) if isinstance(series, dict) else type(series).__name__
            raise DataError(f"checkpoint grids signals {got}, the config {sorted(self._series)}")

        def number(x: Any, what: str, optional: bool = False, finite: bool = True) -> float | None:
            if x is None and optional:
                return None
            if isinstance(x, bool) or not isinstance(x, int | float | np.integer | np.floating):
                none = " or None" if optional else ""
                raise DataError(f"{where}: {what} must be a number{none}, got {x!r}")
            if finite and not math.isfinite(x):
                raise DataError(f"{where}: {what} must be finite, got {x!r}")
            return float(x)

        def count(name: str) -> int:
            x = state[name]
            if isinstance(x, bool) or not isinstance(x, int | np.integer) or x < 0:
                raise DataError(f"{where}: {name} must be a count (an integer >= 0), got {x!r}")
            return int(x)

        new = {}
        for name, d in series.items():
            what = f"series {name!r}"
            if not isinstance(d, dict) or set(d) != {"t", "v", "intervals", "first"}:
                raise DataError(f"{where}: {what} must be a dict with keys first, intervals, t, v")
            if not all(isinstance(d[k], list | tuple | np.ndarray) for k in ("t", "v", "intervals")):
                raise DataError(f"{where}: {what}: t, v and intervals must be lists")
            if len(d["t"]) != len(d["v"]):
                raise DataError(f"{where}: {what} has {len(d['t'])} frame times and {len(d['v'])} values")
            t = [number(x, f"{what} frame time") for x in d["t"]]
            if any(b < a for a, b in itertools.pairwise(t)):
                raise DataError(f"{where}: {what}: frame times go backwards")
            v = [number(x, f"{what} value", finite=False) for x in d["v"]]
            iv = [number(x, f"{what} interval") for x in d["intervals"]]
            new[name] = (t, v, iv, number(d["first"], f"{what} first", optional=True))
        bus = state["bus"]
        if not isinstance(bus, dict):
            raise DataError(f"{where}: bus must be a dict of message id to bus name")
        try:
            bus = {int(k): str(v) for k, v in bus.items()}
        except (TypeError, ValueError):
            raise DataError(f"{where}: bus keys must be message ids (integers)") from None
        t0 = number(state["t0"], "t0", optional=True)
        t_last = number(state["t_last"], "t_last", optional=True)
        start = number(state["start"], "start", optional=True)
        k, frames, undecodable = count("k"), count("frames"), count("undecodable")
        pending = [(number(p[0], "pending time"), {str(k): number(v, "pending value", finite=False)
                                                   for k, v in p[1].items()}, str(p[2]), bool(p[3]))
                   for p in pending]
        for name, (t, v, iv, first) in new.items():
            s = self._series[name]
            s.t, s.v, s.first = t, v, first
            s.intervals.clear()
            s.intervals.extend(iv)
        self._bus = bus
        self._t0, self._t_last, self._start = t0, t_last, start
        self._k, self.frames, self.undecodable = k, frames, undecodable
        self._pending = pending
