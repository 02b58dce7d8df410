"""Time columns at full precision: units, absolute clocks and the rebase rule of every table reader.

A log's time column may count seconds from the start of the recording (``0.00, 0.01, ...``), or
hold an absolute clock: UNIX-epoch seconds (``1.7e9``), milliseconds, microseconds or the
nanoseconds of ROS bags (``1.7e18``). A float64 holds ``1.7e9`` s only to about 0.24 us and
``1.7e18`` ns not at all (to 256 ns), so such a column is never turned into float seconds
directly. Instead:

* the timestamps are read **exactly** -- integer text and integer columns as integers, decimal
  text as decimals (:class:`decimal.Decimal`), float columns by their shortest decimal
  representation (``repr``), which is the decimal the writer wrote;
* the unit is ``time_unit`` (``"s"``, ``"ms"``, ``"us"``, ``"ns"``), or with ``"auto"`` chosen
  from the magnitude of the first timestamp, which is unambiguous for an absolute clock only:
  ``>= 1e17`` is ns, ``>= 1e14`` us, ``>= 1e11`` ms, anything smaller seconds (UNIX time between
  1973 and 2286 lies in one band per unit; a *relative* clock in ms or us must be given its unit);
* **the rebase rule**: an *absolute* time axis -- its first timestamp is at least
  :data:`ABSOLUTE_AFTER` (10^6 s, 11.6 days, longer than any recording that starts at 0) --
  is made relative to its first sample: ``t = (N - N[0]) / 10^e`` computed from the exact
  integers ``N`` (one correctly rounded division per sample, so ``t`` equals the float of the
  exact relative time, e.g. ``0.01`` exactly where the text said ``...00.010``), and the origin
  is kept in :class:`TimeOrigin` (``signals.t0`` in seconds, ``signals.time_origin`` exact).
  A relative time axis (first timestamp below 10^6 s) is kept as the file has it (seconds:
  the float of each cell; other units: the exact value divided into seconds), with
  ``t0 == 0``. ``rebase=True`` / ``False`` overrides the rule.

Events reported at ``t`` on a rebased log happened at absolute time ``t0 + t`` (seconds of
the file's clock); :meth:`TimeOrigin.absolute` gives it exactly as a decimal string.
"""

from __future__ import annotations

import decimal
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import DataError

__all__ = ["ABSOLUTE_AFTER", "TIME_UNITS", "StreamTimes", "TimeOrigin", "times_to_seconds"]

#: Decimal exponent of each time unit (a timestamp in the unit times 10**-exponent is seconds).
TIME_UNITS: dict[str, int] = {"s": 0, "ms": 3, "us": 6, "ns": 9}
#: A time axis whose first timestamp is at least this many seconds is absolute and is rebased.
ABSOLUTE_AFTER = 1e6
_AUTO_BANDS = ((1e17, "ns"), (1e14, "us"), (1e11, "ms"))
_CTX = decimal.Context(prec=80)


@dataclass(frozen=True)
class TimeOrigin:
    """The exact absolute time of ``t = 0`` of a rebased log.

    Attributes
    ----------
    ticks : int
        The first timestamp as an exact integer count of ``10**-exponent`` seconds.
    exponent : int
        Decimal exponent of a tick (9: nanoseconds, 2: hundredths of a second, ...).
    unit : str
        The time unit the column was read in (``"s"``, ``"ms"``, ``"us"``, ``"ns"``).
    rebased : bool
        ``True`` when ``t`` was made relative to the first sample; ``False`` when ``t`` is the
        file's own (relative) time axis and the origin is 0.
    """

    ticks: int
    exponent: int
    unit: str
    rebased: bool

    @property
    def seconds(self) -> float:
        """The origin in seconds (the nearest float64; exact in :attr:`text`)."""
        return self.ticks / 10**self.exponent

    @property
    def text(self) -> str:
        """The origin in seconds as an exact decimal string."""
        return self.absolute(0)

    def absolute(self, t: float) -> str:
        """Absolute time (s) of relative time ``t`` as an exact decimal string (``t``'s float
        value added to the exact origin, rounded to the tick)."""
        q = decimal.Decimal(1).scaleb(-self.exponent)
        ctx = decimal.Context(prec=60)
        v = ctx.add(decimal.Decimal(self.ticks).scaleb(-self.exponent, ctx), decimal.Decimal(float(t)))
        return str(v.quantize(q, context=ctx)) if self.exponent >= 0 else str(v)


def _check_unit(unit: str, where: str) -> str:
    if not isinstance(unit, str) or (unit not in TIME_UNITS and unit != "auto"):
        raise DataError(f"{where}: time_unit must be one of {[*TIME_UNITS, 'auto']}, got {unit!r}")
    return unit


def _at(rows: Sequence[int] | np.ndarray | None, k: int, line_offset: int | None) -> str:
    r = int(rows[k]) if rows is not None else k
    return f"data row {r}" + (f" (line {r + line_offset})" if line_offset is not None else "")


#: Most decimals kept of a timestamp (1e-24 of its unit; more is rounded, never needed by a clock).
MAX_DECIMALS = 24


def _decimal_ticks(texts: Sequence[str]) -> tuple[list[int], int]:
    """Exact integer ticks of decimal texts and their common exponent (number of decimals, at most
    :data:`MAX_DECIMALS`)."""
    decs = [decimal.Decimal(x) for x in texts]
    e = max(0, max(-d.as_tuple().exponent for d in decs))
    if e > MAX_DECIMALS:
        q = decimal.Decimal(1).scaleb(-MAX_DECIMALS)
        try:
            decs = [d.quantize(q, context=_CTX) if -d.as_tuple().exponent > MAX_DECIMALS else d for d in decs]
        except decimal.InvalidOperation:
            raise DataError(f"time stamps with more than {_CTX.prec} significant digits") from None
        e = MAX_DECIMALS
    ticks = []
    for d in decs:
        sign, digits, exp = d.as_tuple()
        n = int("".join(map(str, digits)) or "0") * 10 ** (exp + e)
        ticks.append(-n if sign else n)
    return ticks, e


def times_to_seconds(
    values: Sequence[str] | np.ndarray,
    time_unit: str = "auto",
    *,
    rebase: bool | None = None,
    where: str = "log",
    column: str = "t",
    rows: Sequence[int] | np.ndarray | None = None,
    line_offset: int | None = None,
) -> tuple[np.ndarray, TimeOrigin]:
    """Time stamps (text cells, or an integer or float array) to float64 seconds, exactly.

    Parameters
    ----------
    values : sequence of str or ndarray, shape (N,)
        The time column: stripped, non-empty text cells, or numbers.
    time_unit : {"auto", "s", "ms", "us", "ns"}
        Unit of the timestamps; ``"auto"`` decides by the first timestamp's magnitude (see the
        module docstring: reliable for absolute clocks only).
    rebase : bool, optional
        Make ``t`` relative to the first sample; default: when the first timestamp is at least
        :data:`ABSOLUTE_AFTER` seconds.
    where, column : str
        File and column for error messages.
    rows : sequence of int, optional
        Data-row number of each value (default ``0 .. N-1``).
    line_offset : int, optional
        Added to a data row to name its text line (CSV with one header line: 2).

    Returns
    -------
    t : ndarray, shape (N,)
        Seconds (relative to the first sample when rebased).
    origin : TimeOrigin

    Raises
    ------
    DataError
        A cell that is not a finite number (naming its row), an unknown ``time_unit``.

    Examples
    --------
    >>> t, o = times_to_seconds(["1700000000000000000", "1700000000010000000"], "ns")
    >>> t.tolist(), o.seconds, o.text
    ([0.0, 0.01], 1700000000.0, '1700000000.000000000')
    >>> times_to_seconds(["0.5", "0.75"])[0].tolist()
    [0.5, 0.75]
    """
    _check_unit(time_unit, where)
    n = len(values)
    if n == 0:
        raise DataError(f"{where}: time column {column!r} has no values")
    arr = np.asarray(values)
    ints: np.ndarray | None = None
    texts: list[str] | None = None
    if arr.dtype.kind in "iu":
        ints = arr.astype(np.int64)
        f = ints.astype(float)
    elif arr.dtype.kind == "b":
        raise DataError(f"{where}: time column {column!r} is boolean, not a number")
    elif arr.dtype.kind == "f":
        f = arr.astype(float)
    else:
        texts = [str(x).strip() for x in values]
        try:
            f = np.asarray(texts, dtype=str).astype(float)
        except ValueError:
            f = np.empty(n)
            for k, x in enumerate(texts):
                try:
                    f[k] = float(x)
                except ValueError:
                    raise DataError(f"{where}: time column {column!r} at {_at(rows, k, line_offset)} "
                                    f"is not a number: {x[:40]!r}") from None
        try:
            ints = np.asarray(texts, dtype=str).astype(np.int64)
        except (ValueError, OverflowError):
            ints = None
    bad = np.flatnonzero(~np.isfinite(f))
    if bad.size:
        k = int(bad[0])
        raise DataError(f"{where}: time column {column!r} is not finite at {_at(rows, k, line_offset)} "
                        f"({values[k]!r})")
    unit = time_unit
    if unit == "auto":
        unit = next((u for lim, u in _AUTO_BANDS if abs(f[0]) >= lim), "s")
    k_unit = TIME_UNITS[unit]
    first_s = float(f[0]) / 10**k_unit
    if rebase is None:
        rebase = abs(first_s) >= ABSOLUTE_AFTER
    if not rebase and k_unit == 0:
        # a relative clock in seconds: the float of each cell, as the file has it
        return f, TimeOrigin(0, 0, unit, False)
    # exact integer ticks
    if ints is not None:
        ticks_np: np.ndarray | None = ints
        ticks: list[int] | None = None
        e = 0
    else:
        if texts is None:  # a float column: its shortest decimals are what the writer wrote
            texts = [repr(float(x)) for x in f]
        ticks, e = _decimal_ticks(texts)
        ticks_np = None
    exponent = e + k_unit
    t0_ticks = int(ticks_np[0]) if ticks_np is not None else ticks[0]
    if ticks_np is not None:
        rel = ticks_np - ticks_np[0] if rebase else ticks_np
        big = rel.size and int(np.max(np.abs(rel))) >= 2**53
        if not big and exponent <= 22:  # exact int in a double, one correctly rounded division
            t = rel.astype(float) / 10.0**exponent
        else:
            t = np.array([int(r) / 10**exponent for r in rel.tolist()])
    else:
        base = ticks[0] if rebase else 0
        rel_l = [x - base for x in ticks]
        if max(abs(x) for x in rel_l) < 2**53 and exponent <= 22:
            t = np.asarray(rel_l, float) / 10.0**exponent
        else:
            t = np.array([x / 10**exponent for x in rel_l])
    if not rebase:
        return t, TimeOrigin(0, exponent, unit, False)
    return t, TimeOrigin(t0_ticks, exponent, unit, True)


def time_unit_hint(t: np.ndarray, rate: float | None) -> str:
    """A hint for error messages when a time axis looks like it is in the wrong unit."""
    if t.size < 2:
        return ""
    d = float(np.median(np.diff(t)))
    if d >= 1e3:
        return (f" (the median time step is {d:.6g} s: is the time column in ms, us or ns? "
                "pass time_unit=)")
    return ""


def origin_of_float(t0: float) -> TimeOrigin:
    """The origin of a time axis already made relative in float64 (frame logs: python-can gives
    float seconds), from the shortest decimal of ``t0`` (the decimal a text log wrote)."""
    ticks, e = _decimal_ticks([repr(float(t0))])
    return TimeOrigin(ticks[0], e, "s", True)


class StreamTimes:
    """Time stamps of a live stream (one text cell per sample) to seconds, with the batch rule.

    The first stamp fixes the unit (``"auto"`` as in :func:`times_to_seconds`) and whether the
    stream is rebased (an absolute first stamp, or ``rebase=True``); every later stamp is then
    converted exactly relative to it, so follow mode gives bit for bit the times
    :func:`fdikit.io.read_csv` gives the same lines (a correctly rounded exact difference).

    Parameters
    ----------
    time_unit : {"auto", "s", "ms", "us", "ns"}
    rebase : bool, optional

    Attributes
    ----------
    origin : TimeOrigin or None
        Set by the first stamp (``None`` before it).

    Examples
    --------
    >>> st = StreamTimes()
    >>> [st("1700000000.00"), st("1700000000.01"), st("1700000000.02")], st.t0
    ([0.0, 0.01, 0.02], 1700000000.0)
    """

    def __init__(self, time_unit: str = "auto", rebase: bool | None = None):
        self.time_unit = _check_unit(time_unit, "stream")
        self.rebase = rebase
        self.origin: TimeOrigin | None = None
        self._base: decimal.Decimal | None = None

    @property
    def t0(self) -> float:
        """Absolute time (s) of ``t = 0`` (0 for a relative clock or before the first stamp)."""
        return self.origin.seconds if self.origin is not None and self.origin.rebased else 0.0

    def state(self) -> dict:
        """Plain data for a checkpoint (see :meth:`restore`)."""
        o = self.origin
        return {"time_unit": self.time_unit, "rebase": self.rebase,
                "origin": None if o is None else [str(o.ticks), o.exponent, o.unit, o.rebased]}

    def restore(self, state: dict) -> None:
        """Continue from a :meth:`state`; a bad state is refused before anything changes.

        Raises
        ------
        DataError
            A state that is not a dict of ``time_unit``, ``rebase`` and ``origin`` (``None`` or
            ``[ticks, exponent, unit, rebased]``), naming what is wrong.

        Examples
        --------
        >>> st = StreamTimes()
        >>> st("1700000000.00")
        0.0
        >>> st2 = StreamTimes()
        >>> st2.restore(st.state())
        >>> st2("1700000000.25")
        0.25
        >>> st2.restore({"time_unit": "s"})
        Traceback (most recent call last):
        ...
        fdikit.errors.DataError: StreamTimes state: keys ['time_unit'], expected ['origin', ...]
        """
        where = "StreamTimes state"
        keys = ["origin", "rebase", "time_unit"]
        if not isinstance(state, dict) or sorted(state) != keys:
            got = sorted(state) if isinstance(state, dict) else type(state).__name__
            raise DataError(f"{where}: keys {got}, expected {keys}")
        unit = _check_unit(state["time_unit"], where)
        if state["rebase"] not in (None, True, False):
            raise DataError(f"{where}: rebase must be True, False or None, got {state['rebase']!r}")
        o = state["origin"]
        origin = None
        if o is not None:
            try:
                ticks, exponent, o_unit, rebased = o
                ok = (isinstance(exponent, int | np.integer) and o_unit in TIME_UNITS
                      and isinstance(rebased, bool | np.bool_))
                origin = TimeOrigin(int(ticks), int(exponent), str(o_unit), bool(rebased)) if ok else None
            except (TypeError, ValueError):
                origin = None
            if origin is None:
                raise DataError(f"{where}: origin must be None or [ticks, exponent, unit, rebased], "
                                f"got {o!r}")
        self.time_unit, self.rebase = unit, state["rebase"]
        self.origin = origin
        self._base = None if self.origin is None else self._base_of(self.origin)

    @staticmethod
    def _base_of(o: TimeOrigin) -> decimal.Decimal:
        """The origin in the stream's unit, exactly."""
        return decimal.Decimal(o.ticks).scaleb(-o.exponent + TIME_UNITS[o.unit], _CTX)

    def __call__(self, text: str, where: str = "stream") -> float:
        """Seconds of one stamp (text); a :class:`DataError` for a cell that is not a finite number."""
        x = str(text).strip()
        try:
            d = decimal.Decimal(x)
        except decimal.InvalidOperation:
            raise DataError(f"{where}: time stamp {x[:40]!r} is not a number") from None
        if not d.is_finite():
            raise DataError(f"{where}: time stamp {x[:40]!r} is not finite")
        if self.origin is None:
            _, o = times_to_seconds([x], self.time_unit, rebase=self.rebase, where=where)
            self.origin = o
            self._base = self._base_of(o) if o.rebased else None
            if not o.rebased:
                return float(d) if TIME_UNITS[o.unit] == 0 else float(d.scaleb(-TIME_UNITS[o.unit], _CTX))
            return 0.0
        k = TIME_UNITS[self.origin.unit]
        if self._base is None:
            return float(d) if k == 0 else float(d.scaleb(-k, _CTX))
        return float(_CTX.subtract(d, self._base).scaleb(-k, _CTX))
