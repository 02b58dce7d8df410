"""CAN logs: read a Vector BLF (or any python-can log) with a DBC and put chosen signals on one grid.

The loader

1. reads every frame with :class:`can.LogReader` (BLF, ASC, CSV, TRC, ... by suffix); for BLF it
   checks the file against its own header (file size, object count) so that a truncated file is
   an error, not a silently shorter log;
2. decodes, per message, only the frames whose arbitration id carries a requested signal, with
   :mod:`cantools` (``load_file(..., strict=False)``), so the physical values and units are the
   DBC's;
3. resamples every signal onto one uniform time grid at ``rate`` Hz by linear interpolation (or
   zero-order hold) **between neighbouring frames only**: a grid sample whose two neighbouring
   frames are more than ``max_gap`` source periods apart is *not* interpolated across; it is set
   to NaN and flagged invalid in :attr:`LogSignals.valid`.

Gap convention (used by every fdikit loader)
--------------------------------------------
The values of a :class:`LogSignals` may hold NaN. ``valid`` (bool, same shape as ``values``) is
``False`` exactly where a value is NaN because the source had no data close enough (a gap, or
before the first / after the last sample of that channel). Downstream stages must either drop
those samples or refuse them; nothing fills them in silently.
"""

from __future__ import annotations

import difflib
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals

__all__ = ["LogSignals", "SignalInfo", "convert_units", "resample_to_grid"]


# ---------------------------------------------------------------------------------- units
#: Multiplicative conversions ``(from, to) -> factor`` between the units that vehicle DBCs use.
_UNIT_FACTORS: dict[tuple[str, str], float] = {
    ("km/h", "m/s"): 1.0 / 3.6,
    ("mph", "m/s"): 0.44704,
    ("mph", "km/h"): 1.609344,
    ("deg", "rad"): np.pi / 180.0,
    ("deg/s", "rad/s"): np.pi / 180.0,
    ("rpm", "rad/s"): 2.0 * np.pi / 60.0,
    ("rpm", "Hz"): 1.0 / 60.0,
    ("g", "m/s^2"): 9.80665,
    ("%", "1"): 0.01,
    ("kPa", "Pa"): 1e3,
    ("bar", "Pa"): 1e5,
    ("bar", "kPa"): 1e2,
    ("ms", "s"): 1e-3,
}
_UNIT_ALIASES = {"kph": "km/h", "km/hr": "km/h", "m/s2": "m/s^2", "m/s/s": "m/s^2", "degree": "deg",
                 "degrees": "deg", "deg/sec": "deg/s", "rev/min": "rpm", "1/min": "rpm", "": "",
                 "percent": "%"}
#: The SI target of each unit, used by ``units="si"``.
_SI = {"km/h": "m/s", "mph": "m/s", "deg": "rad", "deg/s": "rad/s", "rpm": "rad/s", "g": "m/s^2",
       "kPa": "Pa", "bar": "Pa", "ms": "s", "%": "1"}


def _norm_unit(u: str | None) -> str:
    u = (u or "").strip()
    return _UNIT_ALIASES.get(u.lower(), _UNIT_ALIASES.get(u, u))


def convert_units(values: np.ndarray, from_unit: str, to_unit: str, *, channel: str = "") -> np.ndarray:
    """Convert ``values`` from one unit to another (multiplicative units only).

    Parameters
    ----------
    values : array_like
        Values in ``from_unit``.
    from_unit, to_unit : str
        Unit names such as ``"km/h"``, ``"m/s"``, ``"deg/s"``, ``"rad/s"``, ``"rpm"``, ``"%"``.
    channel : str
        Channel name used in the error message.

    Returns
    -------
    ndarray
        Values in ``to_unit`` (same shape).

    Examples
    --------
    >>> convert_units([36.0], "km/h", "m/s").tolist()
    [10.0]
    """
    a, b = _norm_unit(from_unit), _norm_unit(to_unit)
    v = np.asarray(values, dtype=float)
    if a == b:
        return v
    if (a, b) in _UNIT_FACTORS:
        return v * _UNIT_FACTORS[(a, b)]
    if (b, a) in _UNIT_FACTORS:
        return v / _UNIT_FACTORS[(b, a)]
    known = sorted({f"{x} -> {y}" for x, y in _UNIT_FACTORS})
    raise DataError(f"cannot convert channel {channel!r} from unit {from_unit!r} to {to_unit!r}; "
                    f"known conversions (either direction): {known}")


# ---------------------------------------------------------------------------------- result type
@dataclass(frozen=True)
class SignalInfo:
    """What the loader saw of one signal in the source log.

    Attributes
    ----------
    name : str
        ``"MESSAGE.SIGNAL"``.
    source_unit, unit : str
        Unit in the DBC and unit of the returned values.
    n_samples : int
        Number of decoded frames.
    rate : float
        Mean source rate (Hz) = (n_samples - 1) / (t_last - t_first).
    median_interval : float
        Median frame interval (s): the source period that ``max_gap`` is measured in.
    t_first, t_last : float
        Time of the first and last frame (s, log time).
    n_gaps : int
        Number of frame intervals longer than ``max_gap`` source periods.
    n_invalid : int
        Grid samples flagged invalid (NaN) for this channel.
    """

    name: str
    source_unit: str
    unit: str
    n_samples: int
    rate: float
    median_interval: float
    t_first: float
    t_last: float
    n_gaps: int
    n_invalid: int


class LogSignals(Signals):
    """:class:`~fdikit.Signals` read from a recording, with a per-sample validity mask.

    Attributes
    ----------
    valid : ndarray of bool, shape (runs, T, channels)
        ``False`` where the value is NaN because the source had no data close enough (a gap
        longer than the loader's ``max_gap``, or outside that channel's recorded span).
    info : dict of str -> SignalInfo
        Source statistics per channel (rate, count, gaps); empty for derived selections.
    t0 : float
        Absolute time (s) of ``t == 0`` (see :class:`~fdikit.Signals`): the first timestamp of
        a log on an absolute clock, else 0.
    time_origin : TimeOrigin or None
        The exact origin (integer ticks, unit) when the time axis was rebased
        (:mod:`fdikit.io.timebase`); ``None`` for readers that do not rebase.
    """

    __slots__ = ("info", "time_origin", "valid")

    def __init__(self, t, values, names, units=None, *, valid=None, info=None, t0=0.0, time_origin=None):
        super().__init__(t, values, names, units, check=False, t0=t0)
        self.time_origin = time_origin
        if valid is None:
            valid = np.isfinite(self.values)
        valid = np.asarray(valid, dtype=bool)
        if valid.ndim == 1:
            valid = valid[:, None]
        if valid.ndim == 2:
            valid = valid[None]
        if valid.shape != self.values.shape:
            raise DataError(f"validity mask has shape {valid.shape}, values {self.values.shape}")
        bad = np.argwhere(valid & ~np.isfinite(self.values))
        if bad.size:
            r, k, c = (int(i) for i in bad[0])
            raise DataError(f"channel {self.names[c]!r} is marked valid but is not finite at run {r}, "
                            f"sample {k}")
        self.valid = valid
        self.info = dict(info or {})

    @property
    def all_valid(self) -> np.ndarray:
        """Samples where every channel is valid, shape ``(runs, T)``."""
        return self.valid.all(axis=2)

    def select(self, names) -> LogSignals:
        names = list(names)
        idx = self.index(names)
        return LogSignals(self.t, self.values[:, :, idx], names, [self.units[i] for i in idx],
                          valid=self.valid[:, :, idx],
                          info={n: self.info[n] for n in names if n in self.info},
                          t0=self.t0, time_origin=self.time_origin)

    def window(self, t0: float | None = None, t1: float | None = None) -> LogSignals:
        m = np.ones(self.t.size, bool)
        if t0 is not None:
            m &= self.t >= t0
        if t1 is not None:
            m &= self.t <= t1
        return LogSignals(self.t[m], self.values[:, m], self.names, self.units, valid=self.valid[:, m],
                          info=self.info, t0=self.t0, time_origin=self.time_origin)

    def dropna(self) -> Signals:
        """A plain, fully finite :class:`~fdikit.Signals` of the samples where all channels are valid
        (one run only)."""
        if self.runs != 1:
            raise DataError("dropna needs a single run")
        m = self.all_valid[0]
        return Signals(self.t[m], self.values[:, m], self.names, self.units, t0=self.t0)

    def __repr__(self) -> str:
        inv = int((~self.valid).sum())
        return super().__repr__()[:-1] + f", invalid samples={inv})"


# ---------------------------------------------------------------------------------- resampling
#: A source sample at most this much (s) after a grid time counts as at that time for the causal
#: hold (``method="previous"``): time stamps made relative by a subtraction, or written as decimal
#: text, carry rounding errors of ~1e-17 s to ~1e-12 s, and a hold that missed the sample exactly at
#: its grid time by such an error would lag one whole source period.
HOLD_TOL = 1e-9


def resample_to_grid(t_src: np.ndarray, v_src: np.ndarray, grid: np.ndarray, *, max_gap: float = 3.0,
                     method: str = "previous", period: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Resample one irregularly sampled signal onto ``grid`` without bridging gaps.

    Parameters
    ----------
    t_src : ndarray, shape (N,)
        Source sample times (s), strictly increasing.
    v_src : ndarray, shape (N,)
        Source values.
    grid : ndarray, shape (T,)
        Target times (s).
    max_gap : float
        Longest bridgeable interval in source periods: a grid time is valid only when its two
        neighbouring source samples are at most ``max_gap * period`` apart (``"linear"``), or
        when the previous source sample is at most that old (``"previous"``).
    method : {"previous", "linear"}
        Zero-order hold of the previous sample (causal, the default; a sample at most
        :data:`HOLD_TOL` after a grid time counts as at it), or linear interpolation between
        neighbours (uses the next sample: not causal).
    period : float, optional
        Nominal source period (s); default the median source interval.

    Returns
    -------
    values : ndarray, shape (T,)
        Resampled values, NaN where invalid.
    valid : ndarray of bool, shape (T,)

    Examples
    --------
    >>> import numpy as np
    >>> t, grid = np.array([0., 1., 2., 10., 11.]), np.array([0.5, 5., 10.5])
    >>> v, ok = resample_to_grid(t, np.arange(5.), grid, max_gap=2.0)
    >>> v.tolist(), ok.tolist()
    ([0.0, nan, 3.0], [True, False, True])
    >>> v, ok = resample_to_grid(t, np.arange(5.), grid, method="linear")
    >>> v.tolist(), ok.tolist()
    ([0.5, nan, 3.5], [True, False, True])
    """
    t_src = np.asarray(t_src, float)
    v_src = np.asarray(v_src, float)
    grid = np.asarray(grid, float)
    if t_src.size == 0:
        return np.full(grid.shape, np.nan), np.zeros(grid.shape, bool)
    if method not in ("linear", "previous"):
        raise DataError(f"unknown resampling method {method!r}; use 'linear' or 'previous'")
    plan = _resample_plan(t_src, grid, max_gap, method, period)
    return _resample_apply(plan, v_src), plan[-1].copy()


def _resample_plan(t_src: np.ndarray, grid: np.ndarray, max_gap: float, method: str,
                   period: float | None) -> tuple:
    """What :func:`resample_to_grid` computes from the times alone (non-empty ``t_src``): the
    source indices and weights of every grid sample and the validity mask, shared by the signals
    of one message (same time stamps)."""
    n = t_src.size
    if period is None:
        period = float(np.median(np.diff(t_src))) if n > 1 else np.inf
    lim = max_gap * period
    # index of the last source sample at or before each grid time
    i = np.searchsorted(t_src, grid, side="right") - 1
    inside = (i >= 0) & (grid <= t_src[-1])
    if method == "previous":
        i = np.searchsorted(t_src, grid + HOLD_TOL, side="right") - 1
        ii = np.clip(i, 0, n - 1)
        ok = (i >= 0) & (grid - t_src[ii] <= lim)
        return ("previous", ii[ok], ok)
    i0 = np.clip(i, 0, max(n - 2, 0))
    i1 = np.minimum(i0 + 1, n - 1)
    span = t_src[i1] - t_src[i0]
    exact = inside & (t_src[np.clip(i, 0, n - 1)] == grid)
    ok = inside & ((span <= lim) | exact)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(span > 0, (grid - t_src[i0]) / np.where(span > 0, span, 1.0), 0.0)
    return ("linear", i0[ok], i1[ok], w[ok], ok)


def _resample_apply(plan: tuple, v_src: np.ndarray) -> np.ndarray:
    """The resampled values of one signal (or of each row of ``v_src``, shape (k, N)) by a plan of
    :func:`_resample_plan` (NaN where invalid)."""
    ok = plan[-1]
    out = np.full(v_src.shape[:-1] + ok.shape, np.nan)
    if plan[0] == "previous":
        out[..., ok] = v_src[..., plan[1]]
        return out
    _, i0, i1, w, _ = plan
    a = v_src[..., i0]
    out[..., ok] = a + w * (v_src[..., i1] - a)
    return out


# ---------------------------------------------------------------------------------- reading
def _read_frames(path: Path) -> tuple[np.ndarray, np.ndarray, list[bytes]]:
    """All frames of a log: timestamps (s), arbitration ids, payloads. Checks BLF integrity."""
    import can

    if not path.exists():
        raise DataError(f"CAN log {str(path)!r} does not exist")
    if path.is_dir():
        raise DataError(f"CAN log {str(path)!r} is a directory, not a log file")
    size = path.stat().st_size
    try:
        reader = can.LogReader(str(path))
    except ValueError as exc:  # unknown suffix
        raise DataError(f"{str(path)!r} is not a CAN log that python-can can read ({exc})") from None
    except (struct.error, can.io.blf.BLFParseError) as exc:
        raise DataError(f"{str(path)!r} is not a valid BLF file: its header cannot be parsed "
                        f"({type(exc).__name__}: {exc or 'bad signature'}; file size {size} bytes)") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{str(path)!r} is not a text CAN log ({exc})") from None
    ts: list[float] = []
    ids: list[int] = []
    data: list[bytes] = []
    try:
        with reader:
            for msg in reader:
                if msg.is_error_frame or msg.is_remote_frame:
                    continue
                ts.append(msg.timestamp)
                ids.append(msg.arbitration_id)
                data.append(bytes(msg.data))
    except (struct.error, can.io.blf.BLFParseError, EOFError, OSError) as exc:
        raise DataError(f"CAN log {str(path)!r} is corrupt or truncated after {len(ts)} frames "
                        f"({type(exc).__name__}: {exc})") from None
    except (ValueError, UnicodeDecodeError, IndexError) as exc:
        raise DataError(f"{str(path)!r} is not a CAN log python-can can parse ({type(exc).__name__}: "
                        f"{exc})") from None
    if isinstance(reader, can.BLFReader):
        if reader.file_size and reader.file_size != size:
            raise DataError(f"BLF file {str(path)!r} is truncated or padded: its header says "
                            f"{reader.file_size} bytes, the file has {size} bytes "
                            f"({len(ts)} frames readable of {reader.object_count})")
        if reader.object_count and len(ts) < reader.object_count:
            raise DataError(f"BLF file {str(path)!r} is truncated: its header counts "
                            f"{reader.object_count} objects, only {len(ts)} frames could be read")
    if not ts:
        raise DataError(f"CAN log {str(path)!r} holds no CAN frames (empty or not a log)")
    return np.asarray(ts, float), np.asarray(ids, np.int64), data


def _read_frame_table(path: Path):
    """The frames of a BLF log as a table ``(ts, ids, FramePayloads)``: the vectorised reader
    (:func:`fdikit.io.decode.read_blf_table`) with :func:`_read_frames`' integrity checks; any file
    it does not read exactly the way python-can reads it goes to :func:`_read_frames`."""
    from .decode import FramePayloads, read_blf_table

    table = None
    if path.is_file() and path.suffix.lower() == ".blf":
        try:
            table = read_blf_table(path)
        except (ValueError, IndexError, struct.error, OSError):  # unusual layout: python-can decides
            table = None
    if table is None:
        ts, ids, data = _read_frames(path)
        return ts, ids, FramePayloads.from_bytes(data)
    ts, ids, payloads, header = table
    _blf_integrity(path, header, len(ts))
    return ts, ids, payloads


def _blf_integrity(path: Path, header: dict[str, int], n: int) -> None:
    """:func:`_read_frames`' BLF checks on a frame table of ``n`` frames (file size, object count)."""
    size = path.stat().st_size
    if header["file_size"] and header["file_size"] != size:
        raise DataError(f"BLF file {str(path)!r} is truncated or padded: its header says "
                        f"{header['file_size']} bytes, the file has {size} bytes "
                        f"({n} frames readable of {header['object_count']})")
    if header["object_count"] and n < header["object_count"]:
        raise DataError(f"BLF file {str(path)!r} is truncated: its header counts "
                        f"{header['object_count']} objects, only {n} frames could be read")
    if not n:
        raise DataError(f"CAN log {str(path)!r} holds no CAN frames (empty or not a log)")


def _read_blf_frames(path: Path):
    """The frames of a BLF log read on demand (:class:`fdikit.io.decode.BlfFrames`) after
    :func:`_read_frames`' integrity checks, or ``None`` when the file is not the usual layout
    (then :func:`_read_frame_table` reads it)."""
    from .decode import read_blf_frames

    if not (path.is_file() and path.suffix.lower() == ".blf"):
        return None
    try:
        frames = read_blf_frames(path)
    except (ValueError, IndexError, struct.error, OSError):  # unusual layout: the table reader decides
        return None
    if frames is not None:
        _blf_integrity(path, frames.header, frames.n_frames)
    return frames


#: Parsed DBC files by (device, inode, modification time, size): a fleet decodes thousands of logs
#: with one DBC.
_DBC_CACHE: dict[tuple[int, int, int, int], Any] = {}
#: Resolved signal lists of the cached DBCs, by (DBC cache key, signal names).
_RESOLVED: dict[tuple[tuple[int, int, int, int], tuple[str, ...]], list] = {}


def _dbc_key(dbc: Any) -> tuple[int, int, int, int] | None:
    """The cache key of a DBC path (None: not a path, or it cannot be stat'ed)."""
    if not isinstance(dbc, str | os.PathLike):
        return None
    try:
        st = os.stat(dbc)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_size)


def _load_dbc(dbc: Any):
    import cantools

    if not isinstance(dbc, str | os.PathLike):
        return dbc  # an already loaded cantools Database
    key = _dbc_key(dbc)
    if key is not None and key in _DBC_CACHE:
        return _DBC_CACHE[key]
    p = Path(dbc)
    if not p.exists():
        raise DataError(f"DBC file {str(p)!r} does not exist")
    try:
        db = cantools.database.load_file(str(p), strict=False)
    except Exception as exc:  # cantools raises several parse error types
        raise DataError(f"cannot parse DBC {str(p)!r}: {type(exc).__name__}: {exc}") from None
    if key is not None:
        if len(_DBC_CACHE) >= 8:
            old = next(iter(_DBC_CACHE))
            _DBC_CACHE.pop(old)
            for k in [k for k in _RESOLVED if k[0] == old]:
                del _RESOLVED[k]
        _DBC_CACHE[key] = db
    return db


def _load_resolved(dbc: Any, signals: Sequence[str]):
    """``(db, _resolve(db, signals))``, the resolution cached with a DBC loaded from a path."""
    key = _dbc_key(dbc)
    if key is not None and key in _DBC_CACHE:
        hit = _RESOLVED.get((key, tuple(signals)))
        if hit is not None:
            return _DBC_CACHE[key], hit
    db = _load_dbc(dbc)
    resolved = _resolve(db, signals)
    if key is not None and _DBC_CACHE.get(key) is db:
        if len(_RESOLVED) >= 64:
            _RESOLVED.pop(next(iter(_RESOLVED)))
        _RESOLVED[(key, tuple(signals))] = resolved
    return db, resolved


def _resolve(db, signals: Sequence[str]):
    """Map ``"MESSAGE.SIGNAL"`` names to (message, signal) objects, with clear errors."""
    msg_names = [m.name for m in db.messages]
    out = []
    for full in signals:
        if not isinstance(full, str) or full.count(".") != 1:
            raise DataError(f"signal name {full!r} must be 'MESSAGE.SIGNAL' (e.g. 'KINEMATICS.YAW_RATE')")
        mname, sname = full.split(".")
        try:
            msg = db.get_message_by_name(mname)
        except KeyError:
            close = difflib.get_close_matches(mname, msg_names, n=3)
            raise DataError(f"unknown signal {full!r}: the DBC has no message {mname!r}"
                            + (f"; did you mean {close}?" if close else "")) from None
        snames = [s.name for s in msg.signals]
        if sname not in snames:
            close = difflib.get_close_matches(sname, snames, n=3)
            raise DataError(f"the DBC's message {mname!r} (id 0x{msg.frame_id:x}) has no signal {sname!r}; "
                            f"its signals are {snames}" + (f"; did you mean {close}?" if close else ""))
        out.append((full, msg, msg.get_signal_by_name(sname)))
    return out
