"""The PX4 ULog reader (with pyulog): every numeric field of the logged uORB topics onto one grid.

Channel names are ``"message.field"`` (``"vehicle_attitude.q[0]"``, nested fields flattened by
pyulog: ``"esc_status.esc[0].esc_rpm"``). A message logged in several *instances* (two IMUs,
``multi_id`` 0 and 1) names instance 0 ``"message.field"`` and instance ``i > 0``
``"message[i].field"`` (``"sensor_accel[1].x"``); ``"message[0].field"`` is accepted for
instance 0. Brackets cannot occur in uORB message names, so the name is unambiguous (an
``_i`` suffix can be part of a real name).

Time: the ``timestamp`` field of each message (microseconds since boot), made relative to the
log's start (the file header's timestamp) exactly in integers, so ``t = 0`` is when logging
started, ``t0`` is that time in seconds since boot and ``time_origin`` holds it exactly.

Units: ULog stores none (PX4 topics are SI by convention), so ``source_units`` (a mapping
channel -> unit) names them where a conversion (``units=``) needs them.
"""

from __future__ import annotations

import contextlib
import io
import re

import numpy as np

from ...errors import DataError
from ..timebase import TimeOrigin
from .checks import _check_file
from .grid import SourceReport
from .multirate import MultiRateSignals, pick_channels, topics_to_grid

#: The first 7 bytes of every ULog file.
ULOG_MAGIC = b"ULog\x01\x12\x35"
_NUMERIC = {"int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t", "uint32_t", "int64_t", "uint64_t",
            "float", "double", "bool"}
_INSTANCE = re.compile(r"^([^.\[]+)\[(\d+)\]$")


def _topic_name(name: str, multi_id: int) -> str:
    return name if multi_id == 0 else f"{name}[{multi_id}]"


def _message_of(signal: str) -> str:
    """The uORB message name a requested channel or topic belongs to."""
    head = signal.split(".", 1)[0]
    m = _INSTANCE.match(head)
    return m.group(1) if m else head


def _canonical(signal: str) -> str:
    """``message[0].field`` -> ``message.field`` (instance 0 has no index)."""
    head, _, rest = signal.partition(".")
    m = _INSTANCE.match(head)
    if m and m.group(2) == "0":
        return m.group(1) + ("." + rest if rest else "")
    return signal


def _load(p, where: str, names):
    from pyulog import ULog

    with open(p, "rb") as fh:
        head = fh.read(16)
    if not head.startswith(ULOG_MAGIC[: len(head)]) or len(head) < len(ULOG_MAGIC):
        if len(head) < 16 and ULOG_MAGIC.startswith(head[:7]):
            raise DataError(f"{where} is truncated: {len(head)} bytes, shorter than the 16-byte ULog header")
        raise DataError(f"{where} is not a ULog file: it starts with {head[:8]!r}, not {ULOG_MAGIC!r}")
    if len(head) < 16:
        raise DataError(f"{where} is truncated: {len(head)} bytes, shorter than the 16-byte ULog header")
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):  # pyulog prints its corruption warnings
            ulog = ULog(str(p), message_name_filter_list=names, disable_str_exceptions=True)
    except Exception as exc:  # pyulog raises many types for a corrupt file
        raise DataError(f"{where} cannot be parsed as ULog (truncated or corrupt?): "
                        f"{type(exc).__name__}: {str(exc)[:200]}") from None
    return ulog, out.getvalue().strip()


def read_ulog(path, signals=None, rate=None, *, strict: bool = True, source_units=None,
              **kw) -> MultiRateSignals:
    """Read a PX4 ULog file onto one grid: zero-order hold per topic, with each topic's age.

    Parameters
    ----------
    path : path-like
        A ``.ulg`` file.
    signals : sequence of str, optional
        Channels ``"message.field"`` / ``"message[i].field"``, or whole messages
        (``"vehicle_local_position"``: every numeric field). Default: every numeric field of
        every logged message (``timestamp`` itself is the time axis, not a channel).
    rate : float, optional
        Grid rate (Hz); default the fastest median message rate (pass it to follow a log).
    strict : bool
        A file in which pyulog found corrupt messages (and skipped them) is a
        :class:`~fdikit.errors.DataError`; ``strict=False`` reads what pyulog recovered and
        says so in ``source.skipped``.
    source_units : mapping of str -> str, optional
        Units of channels (ULog stores none).
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
        Missing, empty, truncated or corrupt file; not a ULog file; a message or field not in
        the log (with the available list); no numeric field.

    Examples
    --------
    >>> s = read_ulog("flight.ulg", ["vehicle_local_position.x", "sensor_accel[1].x"],
    ...               rate=50)  # doctest: +SKIP
    """
    p = _check_file(path, "ULog file")
    where = f"ULog file {p.name!r}"
    if signals is not None:
        signals = [signals] if isinstance(signals, str) else list(signals)
        signals = [_canonical(s) if isinstance(s, str) else s for s in signals]
        names = sorted({_message_of(s) for s in signals if isinstance(s, str)})
    else:
        names = None
    ulog, warning = _load(p, where, names)
    skipped: tuple[tuple[int, str], ...] = ()
    if ulog.file_corruption:
        if strict:
            raise DataError(f"{where} is truncated or corrupt: pyulog skipped damaged messages"
                            + (f" ({warning[:120]})" if warning else "")
                            + "; pass strict=False to read what it recovered")
        skipped = ((0, "pyulog found corrupt messages and skipped them"),)
    available: dict[str, list[str]] = {}
    data_of: dict[str, object] = {}
    for d in ulog.data_list:
        topic = _topic_name(d.name, d.multi_id)
        fields = [f.field_name for f in d.field_data
                  if f.type_str in _NUMERIC and f.field_name != "timestamp"
                  and not f.field_name.startswith("_padding")]
        available[topic] = [f"{topic}.{f}" for f in fields]
        data_of[topic] = d
    if not available:
        if names is not None:
            logged = sorted({_topic_name(d.name, d.multi_id) for d in _load(p, where, None)[0].data_list})
            raise DataError(f"{where} has no data of message(s) {names}; logged messages: {logged[:80]}")
        raise DataError(f"{where} holds no logged data (truncated in its definitions section?)")
    try:
        chosen = pick_channels(available, signals, where)
    except DataError:
        if signals is None:
            raise
        missing = [s for s in signals if isinstance(s, str) and _message_of(s) not in
                   {d.name for d in ulog.data_list}]
        if missing:  # list every message of the log, not only those read
            logged = sorted({_topic_name(d.name, d.multi_id) for d in _load(p, where, None)[0].data_list})
            raise DataError(f"{where} has no message for {missing}; logged messages: {logged[:80]}") from None
        raise
    start = int(ulog.start_timestamp)
    topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    n_rec = 0
    for topic, chans in chosen.items():
        d = data_of[topic]
        ts = np.asarray(d.data["timestamp"], np.uint64)
        if ts.size and int(ts.max()) >= 2**63:
            raise DataError(f"{where}: message {topic!r} has a timestamp beyond 2^63 us (corrupt?)")
        rel = ts.astype(np.int64) - np.int64(min(start, 2**63 - 1))
        t = rel / 1e6  # exact integers, one correctly rounded division
        prefix = len(topic) + 1
        topics[topic] = (t, {c: np.asarray(d.data[c[prefix:]], float) for c in chans})
        n_rec += ts.size
    units_src = {c: "" for ch in chosen.values() for c in ch}
    for k, u in (source_units or {}).items():
        if k not in units_src:
            raise DataError(f"source unit given for {k!r}, which is not a channel read")
        units_src[k] = u
    src = SourceReport("ulog", str(p), int(n_rec), skipped)
    origin = TimeOrigin(start, 6, "us", True)
    return topics_to_grid(topics, units_src, rate, source=src, where=where, t0=origin.seconds,
                          time_origin=origin, **kw)
