"""Multi-rate topics onto one grid, causally: zero-order hold of each topic's last message and its age.

Flight and robot logs (PX4 ULog, ROS bags, folders of per-topic CSVs) publish each *topic* (a
message with several numeric fields) at its own rate: 250 Hz IMU, 19 Hz odometry, 2.5 Hz GPS.
:func:`topics_to_grid` puts them on one uniform grid with the rule a live monitor sees:

* **causal default** (``method="previous"``): a grid sample at time ``g`` holds, per topic, the
  last message at or before ``g`` (zero-order hold). No grid value depends on a message after its
  time: shifting every message after ``t`` later leaves the grid before ``t`` unchanged (given
  ``rate``; the default rate is chosen from the whole record, so pass ``rate=`` to follow a log).
  A held value is valid until it is older than ``max_age`` seconds (default ``None``: held until
  the next message; the age channel says how old it is).
* **age channels**: one channel ``"<topic>.__age__"`` (unit ``s``) per topic: seconds since that
  topic's last message at each grid sample (NaN and invalid before its first message). It is a
  quality channel: select the data channels by name and the ages come along only when asked for.
* **linear interpolation only on request** (``method="linear"``): it uses the *next* message, so
  the result is marked non-causal (:attr:`MultiRateSignals.causal` is ``False``) and a monitor in
  follow mode must refuse it. Gaps longer than ``max_gap`` median periods are not bridged, as in
  :func:`~fdikit.io.formats.series_to_grid` (whose period is taken over the whole record).

The CAN, CSV, Parquet and MDF4 readers share the causal default (through
:func:`~fdikit.io.formats.series_to_grid`); the readers of topic logs
(:func:`~fdikit.io.read_ulog`, :func:`~fdikit.io.read_rosbag`,
:func:`~fdikit.io.read_topic_folder`) use this module, which adds the age channels.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from ...errors import DataError
from ..can import HOLD_TOL
from .grid import LoadedSignals, SourceReport, _runs, series_to_grid

#: Suffix of the age channel of each topic: ``"<topic>.__age__"``.
AGE_SUFFIX = ".__age__"
#: ``max_gap`` handed to :func:`series_to_grid` for the zero-order hold: never invalid by
#: staleness there (the period it measures gaps in is a whole-record median, not causal);
#: staleness is ``max_age`` seconds, checked here.
_HOLD_FOREVER = 1e300


class MultiRateSignals(LoadedSignals):
    """:class:`LoadedSignals` of topics at several rates, with the causality of its grid.

    Attributes
    ----------
    causal : bool
        ``True`` when every grid value uses only messages at or before its time (zero-order
        hold); ``False`` after linear interpolation (a monitor in follow mode refuses it).
    method : str
        ``"previous"`` or ``"linear"``.
    topics : dict of str -> list of str
        The data channels of each topic (its age channel is ``topic + ".__age__"``).
    """

    __slots__ = ("causal", "method", "topics")

    def __init__(self, *args, causal: bool = True, method: str = "previous", topics=None, **kw):
        super().__init__(*args, **kw)
        self.causal = bool(causal)
        self.method = method
        self.topics: dict[str, list[str]] = {k: list(v) for k, v in (topics or {}).items()}

    def _keep_source(self, s) -> MultiRateSignals:
        keep = set(s.names)
        topics = {k: [c for c in v if c in keep] for k, v in self.topics.items()}
        return MultiRateSignals(s.t, s.values, s.names, s.units, valid=s.valid, info=s.info,
                                source=self.source, t0=s.t0, time_origin=s.time_origin,
                                causal=self.causal, method=self.method,
                                topics={k: v for k, v in topics.items() if v})

    def age(self, topic: str) -> np.ndarray:
        """Seconds since ``topic``'s last message at each grid sample, shape ``(T,)`` (NaN before
        its first message)."""
        name = topic + AGE_SUFFIX
        if name not in self.names:
            raise DataError(f"no age channel for topic {topic!r}; age channels: "
                            f"{[n for n in self.names if n.endswith(AGE_SUFFIX)]}")
        return self[name][0]


def _age(t: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Seconds since the last sample at or before each grid time (NaN before the first)."""
    i = np.searchsorted(t, grid + HOLD_TOL, side="right") - 1
    out = np.full(grid.shape, np.nan)
    ok = i >= 0
    out[ok] = np.maximum(grid[ok] - t[i[ok]], 0.0)  # a sample HOLD_TOL after g is at g
    # a grid time a rounding error (<= 1 ns) before the first sample is that sample
    tol = 1e-9 * max(1.0, abs(float(grid[-1]))) if grid.size else 0.0
    near = ~ok & (t[0] - grid <= tol)
    out[near] = 0.0
    return out


def topics_to_grid(
    topics: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
    source_units: Mapping[str, str],
    rate: float | None = None,
    *,
    method: str = "previous",
    max_age: float | None = None,
    age: bool = True,
    max_gap: float = 3.0,
    source: SourceReport | None = None,
    where: str = "log",
    t0: float = 0.0,
    time_origin=None,
    **kw,
) -> MultiRateSignals:
    """Put topics published at different rates on one grid (causal zero-order hold by default).

    Parameters
    ----------
    topics : mapping of str -> (t, {channel: values})
        Per topic, its message times (s, non-decreasing, shape ``(N,)``) and its channels'
        values (shape ``(N,)`` each; NaN or inf is a bad sample, flagged). Channel names are
        the output names (``"topic.field"``); order is kept.
    source_units : mapping of str -> str
        Unit of each channel as recorded (``""`` when the format has none).
    rate : float, optional
        Grid rate (Hz); default the fastest median topic rate (over the whole record: pass it to
        follow a live log).
    method : {"previous", "linear"}
        Zero-order hold of the last message (causal, the default) or linear interpolation
        between messages (non-causal: the result has ``causal == False``).
    max_age : float, optional
        With ``"previous"``: a held value older than this (s) is invalid (``"stale"``). Default
        ``None``: held until the next message (the age channel reports how old).
    age : bool
        Add one ``"<topic>.__age__"`` channel (s since the topic's last message) per topic.
    max_gap : float
        With ``"linear"``: longest bridged interval, in median source periods.
    **kw
        ``units``, ``span``, ``stuck_after`` as in :func:`~fdikit.io.formats.series_to_grid`.

    Returns
    -------
    MultiRateSignals

    Examples
    --------
    >>> import numpy as np
    >>> s = topics_to_grid({"gps": (np.array([0.0, 0.4]), {"gps.x": np.array([1.0, 2.0])}),
    ...                     "imu": (np.arange(6) * 0.1, {"imu.a": np.arange(6.0)})}, {}, rate=10)
    >>> s["gps.x"][0].tolist(), s.age("gps").round(6).tolist(), s.causal
    ([1.0, 1.0, 1.0, 1.0, 2.0], [0.0, 0.1, 0.2, 0.3, 0.0], True)
    """
    if method not in ("previous", "linear"):
        raise DataError(f"unknown resampling method {method!r}; use 'previous' (causal, the "
                        "default) or 'linear' (non-causal)")
    if max_age is not None:
        if method != "previous":
            raise DataError("max_age applies to method='previous' (linear uses max_gap)")
        if not (isinstance(max_age, int | float) and np.isfinite(max_age) and max_age >= 0):
            raise DataError(f"max_age must be a non-negative number of seconds, got {max_age!r}")
    if not topics:
        raise DataError(f"{where}: no topics to read")
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    owner: dict[str, str] = {}
    times: dict[str, np.ndarray] = {}
    for topic, (t, chans) in topics.items():
        t = np.asarray(t, float)
        times[topic] = t
        for c, v in chans.items():
            if c in series:
                raise DataError(f"{where}: channel {c!r} appears in two topics")
            series[c] = (t, v)  # one time array per topic: resampled together
            owner[c] = topic
    if not series:
        raise DataError(f"{where}: the selected topics hold no numeric channel")
    gap = _HOLD_FOREVER if method == "previous" else max_gap
    g = series_to_grid(series, source_units, rate, method=method, max_gap=gap, source=source,
                       where=where, t0=t0, time_origin=time_origin, **kw)
    values, valid = g.values[0], g.valid[0]
    info, reasons = dict(g.info), list(g.reasons)
    grid = g.t
    ages = {topic: _age(t, grid) for topic, t in times.items()}
    if method == "previous":
        # the hold was never cut: state the real gap policy in the reports
        info = {n: dataclasses.replace(q, n_gaps=0) for n, q in info.items()}
        if max_age is not None:
            values, valid = values.copy(), valid.copy()
            for c, n in enumerate(g.names):
                a = ages[owner[n]]
                stale = valid[:, c] & (a > max_age)
                if stale.any():
                    values[stale, c] = np.nan
                    valid[stale, c] = False
                    info[n] = dataclasses.replace(info[n], n_invalid=info[n].n_invalid + int(stale.sum()))
                    for a0, b0 in _runs(stale):
                        reasons.append((n, a0, b0, f"{n}: stale, the last message of {owner[n]!r} is "
                                                   f"older than max_age = {max_age:g} s"))
            reasons.sort(key=lambda r: (r[1], r[0]))
    names, units = list(g.names), list(g.units)
    cols, vcols = [values], [valid]
    if age:
        for topic in ages:
            names.append(topic + AGE_SUFFIX)
            units.append("s")
        am = np.stack([ages[tp] for tp in topics], axis=1)
        cols.append(am)
        vcols.append(np.isfinite(am))
    topic_names = {tp: [c for c in g.names if owner[c] == tp] for tp in topics}
    return MultiRateSignals(grid, np.concatenate(cols, axis=1), names, units,
                            valid=np.concatenate(vcols, axis=1), info=info, source=source, t0=g.t0,
                            time_origin=g.time_origin, reasons=reasons, causal=method == "previous",
                            method=method, topics=topic_names)


def pick_channels(available: Mapping[str, list[str]], signals, where: str) -> dict[str, list[str]]:
    """The requested channels grouped by topic (all of them when ``signals`` is ``None``).

    ``available`` maps each topic to its channel names. A name may also be a whole topic, which
    selects all its channels. Unknown names are a :class:`DataError` listing what is available.
    """
    if signals is None:
        out = {tp: list(ch) for tp, ch in available.items() if ch}
        if not out:
            raise DataError(f"{where} holds no numeric field")
        return out
    if isinstance(signals, str):
        signals = [signals]
    signals = list(signals)
    if not signals:
        raise DataError("no signals requested")
    where_is = {c: tp for tp, ch in available.items() for c in ch}
    out: dict[str, list[str]] = {}
    for s in signals:
        if not isinstance(s, str):
            raise DataError(f"signal names must be strings, got {s!r}")
        if s in where_is:
            lst = out.setdefault(where_is[s], [])
            if s in lst:
                raise DataError(f"signal requested twice: {s!r}")
            lst.append(s)
        elif s in available:
            if not available[s]:
                raise DataError(f"{where}: topic {s!r} has no numeric field")
            out.setdefault(s, []).extend(c for c in available[s] if c not in out.get(s, []))
        else:
            import difflib

            close = difflib.get_close_matches(s, list(where_is) + list(available), n=3)
            listing = list(available) if len(where_is) > 40 else list(where_is)
            raise DataError(f"{where} has no channel or topic {s!r}"
                            + (f"; did you mean {close}?" if close else "")
                            + f"; available {'topics' if len(where_is) > 40 else 'channels'}: "
                              f"{listing[:60]}")
    return out
