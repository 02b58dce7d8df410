"""The ROS bag reader (with rosbags): ROS 1 ``.bag``, ROS 2 bags (folder, ``.db3`` or ``.mcap``).

Every numeric field of a topic's messages is a channel ``"topic.field.sub"``
(``"/imu/data.linear_acceleration.x"``; ROS topic names hold no dots, so the topic is the part
before the first dot). Numbers and booleans are channels; a fixed-length numeric array (the same
length in every message, at most :data:`MAX_ARRAY` elements: covariances, quaternions) gives one
channel per element, ``"field[i]"``; strings, arrays of messages, longer or variable-length arrays
(images, point clouds, ``data[]`` of a ``Float64MultiArray``) are not channels.

Time: ``time="log"`` (default) is the recorder's receive time of each message: when it reached
the bag, the order a live monitor sees them in. ``time="header"`` uses ``header.stamp`` (the
measurement time, which the sender chose; a topic without a header is then an error). Either is
made relative, exactly in integer nanoseconds, to the bag's first message (its log time): ``t0``
is that time in UNIX seconds and ``time_origin`` holds it exactly.

Units: ROS messages carry none (REP 103: SI), so ``source_units`` names them where a conversion
(``units=``) needs them.
"""

from __future__ import annotations

import dataclasses
import operator
from pathlib import Path

import numpy as np

from ...errors import DataError
from ..timebase import TimeOrigin
from .checks import _check_file
from .grid import SourceReport
from .multirate import MultiRateSignals, pick_channels, topics_to_grid

#: Longest fixed-length numeric array flattened into channels (one per element).
MAX_ARRAY = 64
_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"


def _paths(msg, prefix: str = "") -> tuple[list[str], list[tuple[str, int]]]:
    """Attribute paths of the numeric scalars and of the numeric arrays (with their length) of a
    deserialised message (a dataclass of rosbags' typestore)."""
    scalars: list[str] = []
    arrays: list[tuple[str, int]] = []
    for f in dataclasses.fields(msg):
        if f.name.startswith("__"):
            continue
        v = getattr(msg, f.name)
        path = prefix + f.name
        if isinstance(v, bool | int | float | np.number | np.bool_):
            scalars.append(path)
        elif isinstance(v, np.ndarray):
            if v.ndim == 1 and v.dtype.kind in "biuf" and 0 < v.size <= MAX_ARRAY:
                arrays.append((path, int(v.size)))
        elif dataclasses.is_dataclass(v):
            s, a = _paths(v, path + ".")
            scalars += s
            arrays += a
    return scalars, arrays


class _Topic:
    """Collects the numeric fields of one topic's messages."""

    def __init__(self, topic: str, first) -> None:
        self.topic = topic
        self.scalars, self.arrays = _paths(first)
        self.get_s = operator.attrgetter(*self.scalars) if self.scalars else None
        self.get_a = [operator.attrgetter(p) for p, _ in self.arrays]
        self.rows: list = []
        self.arr: list[list[np.ndarray]] = [[] for _ in self.arrays]
        self.times: list[int] = []
        self.stamps: list[int] = []
        self.has_header = hasattr(first, "header") and hasattr(first.header, "stamp")

    def channels(self) -> list[str]:
        out = [f"{self.topic}.{p}" for p in self.scalars]
        for p, n in self.arrays:
            out += [f"{self.topic}.{p}[{i}]" for i in range(n)]
        return out

    def add(self, ts: int, msg) -> None:
        self.times.append(ts)
        if self.has_header:
            st = msg.header.stamp
            self.stamps.append(int(st.sec) * 1_000_000_000 + int(st.nanosec))
        if self.get_s is not None:
            self.rows.append(self.get_s(msg))
        for j, g in enumerate(self.get_a):
            self.arr[j].append(g(msg))

    def values(self, where: str) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        n = len(self.times)
        if self.scalars:
            m = np.array(self.rows, dtype=float).reshape(n, len(self.scalars))
            for j, p in enumerate(self.scalars):
                out[f"{self.topic}.{p}"] = m[:, j]
        for (p, size), col in zip(self.arrays, self.arr):
            if any(a.shape != (size,) for a in col):
                continue  # variable length: not a channel (see the module docstring)
            m = np.stack(col).astype(float)
            for i in range(size):
                out[f"{self.topic}.{p}[{i}]"] = m[:, i]
        return out


def _check_bag(path, where: str) -> Path:
    p = Path(path)
    if p.is_dir():
        if not p.exists():
            raise DataError(f"{where} does not exist")
        if not (p / "metadata.yaml").is_file():
            raise DataError(f"{where} is a folder but not a ROS 2 bag: it has no metadata.yaml")
        return p
    p = _check_file(path, "ROS bag")
    with open(p, "rb") as fh:
        head = fh.read(16)
    if head.startswith(_ROS1_MAGIC):
        kind = ".bag"
    elif head.startswith(_MCAP_MAGIC):
        kind = ".mcap"
    elif head.startswith(_SQLITE_MAGIC):
        kind = ".db3"
    else:
        raise DataError(f"{where} is not a ROS bag: it starts with {head[:12]!r}, not {_ROS1_MAGIC!r} "
                        f"(ROS 1), {_MCAP_MAGIC!r} (MCAP) or an SQLite header (ROS 2 .db3)")
    if p.suffix.lower() != kind:
        raise DataError(f"{where} holds a {kind} bag but is named {p.suffix!r}: rosbags chooses the "
                        f"reader by suffix, rename it to {p.stem + kind!r}")
    return p


def read_rosbag(path, signals=None, rate=None, *, time: str = "log", source_units=None,
                **kw) -> MultiRateSignals:
    """Read a ROS 1 or ROS 2 bag onto one grid: zero-order hold per topic, with each topic's age.

    Parameters
    ----------
    path : path-like
        A ROS 1 ``.bag`` file, a ROS 2 bag folder (``metadata.yaml`` with ``.db3`` or
        ``.mcap`` storage), or a single ``.db3`` / ``.mcap`` file.
    signals : sequence of str, optional
        Channels ``"topic.field.sub"`` or whole topics (``"/imu/data"``: every numeric field).
        Default: every numeric field of every topic.
    rate : float, optional
        Grid rate (Hz); default the fastest median topic rate (pass it to follow a log).
    time : {"log", "header"}
        Message time: the bag's receive time (default) or ``header.stamp``.
    source_units : mapping of str -> str, optional
        Units of channels (ROS messages carry none).
    **kw
        ``method`` (``"previous"``, causal, the default; ``"linear"`` marks the result
        non-causal), ``max_age``, ``age``, ``max_gap``, ``units``, ``span``, ``stuck_after``: see
        :func:`~fdikit.io.formats.multirate.topics_to_grid`.

    Returns
    -------
    MultiRateSignals
        Data channels, then one ``"<topic>.__age__"`` channel per topic read.

    Raises
    ------
    DataError
        Missing, empty, truncated or corrupt bag; not a bag; a topic or field not in the bag
        (with the available list); a topic without a header with ``time="header"``; no numeric
        field.

    Examples
    --------
    >>> s = read_rosbag("run.bag", ["/imu/data.angular_velocity.z", "/gps/fix"], rate=50)  # doctest: +SKIP
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    where = f"ROS bag {Path(path).name!r}"
    if not Path(path).exists():
        raise DataError(f"ROS bag {str(path)!r} does not exist")
    if time not in ("log", "header"):
        raise DataError(f"time must be 'log' (the bag's receive time) or 'header' (header.stamp), "
                        f"got {time!r}")
    p = _check_bag(path, where)
    wanted: set[str] | None = None
    if signals is not None:
        sig = [signals] if isinstance(signals, str) else list(signals)
        wanted = {s.split(".", 1)[0] for s in sig if isinstance(s, str)}
    collected: dict[str, _Topic] = {}
    n_rec = 0
    try:
        reader = AnyReader([p], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, and others for a damaged file
        raise DataError(f"{where} cannot be opened (truncated or corrupt?): "
                        f"{type(exc).__name__}: {str(exc)[:200]}") from None
    try:
        all_topics = sorted({c.topic for c in reader.connections})
        if wanted is not None:
            missing = sorted(wanted - set(all_topics))
            if missing:
                raise DataError(f"{where} has no topic {missing}; topics: {all_topics[:80]}")
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        types = {}
        for c in conns:
            if types.setdefault(c.topic, c.msgtype) != c.msgtype:
                raise DataError(f"{where}: topic {c.topic!r} carries two message types "
                                f"({types[c.topic]}, {c.msgtype})")
        start = int(reader.start_time) if conns else 0
        try:
            for conn, ts, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                tp = collected.get(conn.topic)
                if tp is None:
                    tp = collected[conn.topic] = _Topic(conn.topic, msg)
                tp.add(int(ts), msg)
                n_rec += 1
        except DataError:
            raise
        except Exception as exc:
            raise DataError(f"{where}: message {n_rec} cannot be read (truncated or corrupt?): "
                            f"{type(exc).__name__}: {str(exc)[:200]}") from None
    finally:
        reader.close()
    if not collected:
        raise DataError(f"{where} holds no message" + (f" on topics {sorted(wanted)}" if wanted else ""))
    available = {tp: c.channels() for tp, c in collected.items()}
    vals = {tp: c.values(where) for tp, c in collected.items()}
    available = {tp: [ch for ch in available[tp] if ch in vals[tp]] for tp in available}
    chosen = pick_channels(available, signals, where)
    topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    for tp, chans in chosen.items():
        c = collected[tp]
        if time == "header":
            if not c.has_header:
                raise DataError(f"{where}: topic {tp!r} ({types[tp]}) has no header.stamp; "
                                "use time='log'")
            ticks = np.array(c.stamps, np.int64)
        else:
            ticks = np.array(c.times, np.int64)
        topics[tp] = ((ticks - np.int64(start)) / 1e9, {ch: vals[tp][ch] for ch in chans})
    units_src = {ch: "" for chans in chosen.values() for ch in chans}
    for k, u in (source_units or {}).items():
        if k not in units_src:
            raise DataError(f"source unit given for {k!r}, which is not a channel read")
        units_src[k] = u
    origin = TimeOrigin(start, 9, "ns", True)
    src = SourceReport("rosbag", str(p), int(n_rec))
    return topics_to_grid(topics, units_src, rate, source=src, where=where, t0=origin.seconds,
                          time_origin=origin, **kw)
