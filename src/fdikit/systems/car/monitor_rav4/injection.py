"""Fault injection into the RAV4 log: every fault type of :mod:`fdikit.faults` on the CAN names
in their DBC units (:func:`inject_channels`, :func:`inject`), the ``--inject`` syntax
(:func:`parse_inject`), and the monitor-channel biases the calibration injects (:func:`_inject_raw`).
"""

from __future__ import annotations

import re

import numpy as np

from ....errors import DataError
from ....signals import Signals
from .channels import _WHEEL, CHANNELS, RAW_CHANNELS, RAW_SOURCES, Rav4Preprocessing

__all__ = ["INJECT_TYPES", "check_inject_targets", "inject", "inject_channels", "injected_sensor",
           "injected_sensors", "injection_summary", "parse_inject"]


def _inject_raw(raw: np.ndarray, t: np.ndarray, faults, pre: Rav4Preprocessing) -> np.ndarray:
    """Add biases ``(channel, magnitude, start_s)`` given on the MONITOR channels to raw values
    (..., T, 9): the raw change that makes the preprocessed channel change by ``magnitude``."""
    v = raw.copy()
    col = {n: i for i, n in enumerate(RAW_CHANNELS)}
    for ch, mag, t0 in faults:
        on = t >= t0
        if ch in _WHEEL:
            v[..., on, col[ch]] += mag            # one wheel; its axle's difference moves by +-mag
        elif ch == "w_front_diff":
            v[..., on, col["wheel_fl"]] += mag
        elif ch == "w_rear_diff":
            v[..., on, col["wheel_rl"]] += mag
        elif ch == "steer":
            v[..., on, col["steer_angle"]] += mag * pre.i_s
        elif ch == "a_y":
            v[..., on, col["accel_y_raw"]] += mag * pre.ay_sign
        elif ch == "yaw_rate":
            v[..., on, col["yaw_rate_raw"]] += mag
        else:
            raise DataError(f"cannot inject on {ch!r}; channels: {CHANNELS + list(_WHEEL)}")
    return v


#: Sensors of the RAV4 log: raw channel -> the sensor it comes from.
_RAW_SENSOR = {"steer_angle": "steering", "steer_fraction": "steering", "speed": "speed",
               "yaw_rate_raw": "yaw_rate", "accel_y_raw": "lateral_accelerometer", "wheel_fl": "wheel_fl",
               "wheel_fr": "wheel_fr", "wheel_rl": "wheel_rl", "wheel_rr": "wheel_rr"}


def inject_channels(pre: Rav4Preprocessing) -> dict[str, list[tuple[str, float]]]:
    """What a fault target may name on the RAV4 log -> the raw channels (SI) and the scale from the
    target's units to theirs (see :func:`fdikit.faults.apply_faults`).

    * a CAN signal, alone or with its message (``YAW_RATE`` or ``KINEMATICS.YAW_RATE``), in its
      DBC unit (deg/s, deg, km/h, m/s^2 in the sensor's own sign);
    * a CAN message (``STEER_ANGLE_SENSOR``, ``KINEMATICS``, ``WHEEL_SPEEDS``): every signal of it,
      for a ``stuck`` fault without a value only (a frozen sensor freezes its whole message, each
      signal at its own value); any other fault on a message is refused by
      :func:`check_inject_targets` (it would add its magnitude to every signal of the message);
    * a raw channel (:data:`RAW_CHANNELS`, SI units);
    * an internal monitor channel: ``steer`` (road-wheel rad: the hand-wheel angle moves ``i_s``
      times as much), ``a_y`` (left positive: the opposite sign of the sensor when it is mounted
      so), ``yaw_rate`` (rad/s), ``w_front_diff`` / ``w_rear_diff`` (the left wheel of the axle).
      Gain and stuck act on the raw signal the channel is read from.
    """
    out: dict[str, list[tuple[str, float]]] = {}
    for n, (src, scale, _u) in RAW_SOURCES.items():
        msg, sig = src.split(".", 1)
        out[sig] = [(n, scale)]
        out[src] = [(n, scale)]
        out.setdefault(msg + "*", []).append((n, scale))
    for k in [k for k in out if k.endswith("*")]:
        grp = out.pop(k)
        out.setdefault(k[:-1], grp)
    out.update({"steer": [("steer_angle", pre.i_s)], "a_y": [("accel_y_raw", pre.ay_sign)],
                "yaw_rate": [("yaw_rate_raw", 1.0)], "w_front_diff": [("wheel_fl", 1.0)],
                "w_rear_diff": [("wheel_rl", 1.0)]})
    return out


def _message_signals() -> dict[str, list[str]]:
    """CAN message -> its signals read by the monitor (``STEER_ANGLE_SENSOR`` -> two signals)."""
    out: dict[str, list[str]] = {}
    for src, _scale, _u in RAW_SOURCES.values():
        msg, sig = src.split(".", 1)
        out.setdefault(msg, []).append(sig)
    return out


def check_inject_targets(faults) -> None:
    """Refuse a fault that names a whole CAN message of several signals.

    A bias, drift, gain or intermittent fault on ``STEER_ANGLE_SENSOR`` would be added to every
    signal of the message (+3 deg on STEER_ANGLE *and* on STEER_FRACTION: 6 deg on the steering
    angle); the error lists the signals to name instead. A ``stuck`` fault without a value may
    name a message: the frozen message holds each signal at its own value.

    Raises
    ------
    DataError
        Naming the fault, the message and its signals.

    Examples
    --------
    >>> check_inject_targets(parse_inject("stuck:STEER_ANGLE_SENSOR@15,bias:STEER_ANGLE:3@20"))
    >>> check_inject_targets(parse_inject("bias:WHEEL_SPEEDS:1@20"))   # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: bias on 'WHEEL_SPEEDS': a CAN message of 4 signals ...
    """
    from ....faults import Stuck

    msgs = _message_signals()
    for f in faults:
        if isinstance(f, tuple | list):
            continue
        name = f.target.split(":", 1)[1] if f.target.startswith("sensor:") else f.target
        sigs = msgs.get(name, [])
        if len(sigs) < 2 or (isinstance(f, Stuck) and f.value is None):
            continue
        kind = type(f).__name__.lower()
        raise DataError(f"{kind} on {name!r}: a CAN message of {len(sigs)} signals {sigs}; the fault "
                        f"would be added to each of them. Name one signal, e.g. {kind}:{sigs[0]}:... "
                        f"(only stuck without a value may freeze a whole message)")


def _scaled(x, k: float):
    """``x * k`` as plain data (a float, or a list for per-run values)."""
    return (np.asarray(x, float) * k).tolist()


def injection_summary(faults, pre: Rav4Preprocessing) -> list[dict]:
    """What each fault applies, per CAN signal, in that signal's DBC unit.

    ``[{"fault": "bias", "target": ..., "start_s": ..., "end_s": ..., "applied": [{"signal":
    "STEER_ANGLE_SENSOR.STEER_ANGLE", "unit": "deg", "magnitude": 3.0}, ...]}]``: ``magnitude``
    (bias, intermittent), ``slope`` (drift, per s), ``gain`` or ``value`` (stuck) as the signal
    receives it; an internal channel's magnitude is converted (``steer:0.01`` is 0.01 rad of
    road-wheel angle, ``0.01 * i_s`` rad = that many deg of hand-wheel angle).

    Examples
    --------
    >>> pre = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0)
    >>> injection_summary(parse_inject("bias:STEER_ANGLE_SENSOR.STEER_ANGLE:3@2"), pre)[0]["applied"]
    [{'signal': 'STEER_ANGLE_SENSOR.STEER_ANGLE', 'unit': 'deg', 'magnitude': 3.0}]
    """
    from ....faults import Bias, Gain, Intermittent, Ramp, Stuck

    chans = inject_channels(pre)
    dbc_unit = {"rad": "deg", "m/s": "km/h", "rad/s": "deg/s", "m/s^2": "m/s^2"}
    out = []
    for f in _as_faults(faults):
        name = f.target.split(":", 1)[1] if f.target.startswith("sensor:") else f.target
        applied = []
        for raw, scale in chans.get(name, [(name, 1.0)]):
            if raw not in RAW_SOURCES:
                continue
            src, to_si, si_unit = RAW_SOURCES[raw]
            row: dict = {"signal": src, "unit": dbc_unit.get(si_unit, si_unit)}
            if isinstance(f, Bias | Intermittent):
                row["magnitude"] = _scaled(f.magnitude, scale / to_si)
            elif isinstance(f, Ramp):
                row["slope"] = _scaled(f.slope, scale / to_si)
            elif isinstance(f, Gain):
                row["gain"] = _scaled(f.gain, 1.0)
            elif isinstance(f, Stuck):
                row["value"] = None if f.value is None else _scaled(f.value, scale / to_si)
            applied.append(row)
        out.append({"fault": type(f).__name__.lower(), "target": f.target, "start_s": float(f.start),
                    "end_s": None if f.end is None else float(f.end), "applied": applied})
    return out


def injected_sensors(faults, pre: Rav4Preprocessing | None = None) -> list[str]:
    """The sensor of every fault (:func:`injected_sensor`), in order and without repeats: a run
    with several faults is judged against all of them (``false_announcements`` names only an
    announcement of none of them).

    Examples
    --------
    >>> injected_sensors(parse_inject("bias:ACCEL_Y:1@20,drift:YAW_RATE:0.02/s@30,yaw_rate:0.01@40"))
    ['lateral_accelerometer', 'yaw_rate']
    """
    out: list[str] = []
    for f in _as_faults(faults):
        s = injected_sensor(f.target, pre)
        if s not in out:
            out.append(s)
    return out


def injected_sensor(target: str, pre: Rav4Preprocessing | None = None) -> str:
    """The sensor a fault target of :func:`inject_channels` names (``"yaw_rate"``, ``"wheel_fl"``, ...)."""
    chans = inject_channels(pre or Rav4Preprocessing(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0))
    name = target.split(":", 1)[1] if target.startswith("sensor:") else target
    raw = [c for c, _s in chans[name]] if name in chans else [name]
    sensors = {_RAW_SENSOR.get(c, c) for c in raw}
    return sensors.pop() if len(sensors) == 1 else "+".join(sorted(sensors))


def _as_faults(faults) -> list:
    from ....faults import Bias, Fault

    out = []
    for f in faults:
        if isinstance(f, Fault):
            out.append(f)
        elif isinstance(f, tuple | list) and len(f) == 3:
            out.append(Bias(str(f[0]), float(f[1]), start=float(f[2])))
        else:
            raise DataError(f"a fault must be a fdikit.faults.Fault or (channel, magnitude, start_s), "
                            f"got {f!r}")
    return out


def inject(sig: Signals, faults, pre: Rav4Preprocessing) -> Signals:
    """Raw signals (:data:`RAW_CHANNELS`) with sensor faults applied.

    ``faults``: :class:`~fdikit.faults.Fault` objects of any type (bias, ramp/drift, gain, stuck,
    intermittent, ...) whose target is a name of :func:`inject_channels` (CAN signal or message
    in its own units, raw channel, internal channel) and whose times are seconds from the start
    of the log (what :func:`parse_inject` returns), or ``(channel, magnitude, start_s)`` biases
    (the historic form: ``channel`` a monitor channel of :data:`CHANNELS` or a wheel ``wheel_fl``
    ...). Broadcast over runs.

    Examples
    --------
    >>> pre = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0)
    >>> s = Signals(np.arange(3.0), np.zeros((1, 3, 9)), RAW_CHANNELS)
    >>> inject(s, [("a_y", 0.5, 1.0)], pre)["accel_y_raw"].tolist()
    [[0.0, -0.5, -0.5]]
    >>> inject(s, parse_inject("drift:YAW_RATE:0.5/s@1"), pre)["yaw_rate_raw"].round(6).tolist()   # deg/s
    [[0.0, 0.0, 0.008727]]
    """
    from ....faults import apply_faults

    if sig.names[:len(RAW_CHANNELS)] != RAW_CHANNELS:
        raise DataError(f"inject needs the raw channels {RAW_CHANNELS}, got {sig.names}")
    faults = _as_faults(faults)
    if not faults:
        return sig
    check_inject_targets(faults)
    t0 = float(sig.t[0])
    rel = Signals(sig.t - t0, sig.values, sig.names, sig.units, check=False)
    out = apply_faults(rel, faults, channels=inject_channels(pre))
    return Signals(sig.t, out.values, sig.names, sig.units, check=False)


#: Fault types of :func:`parse_inject`.
INJECT_TYPES = ("bias", "drift", "gain", "stuck", "intermittent")
_TYPE_ALIASES = {"bias": "bias", "offset": "bias", "step": "bias", "drift": "drift", "ramp": "drift",
                 "gain": "gain", "scale": "gain", "stuck": "stuck", "frozen": "stuck",
                 "intermittent": "intermittent"}
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_SPEC = re.compile(rf"\s*(?:(?P<type>[A-Za-z]+):)??(?P<ch>[A-Za-z_][A-Za-z0-9_.]*)"
                   rf"(?::(?P<val>{_NUM})(?P<per>/s)?)?"
                   rf"@(?P<start>{_NUM})(?:-(?P<end>{_NUM}))?(?P<opts>(?:;[A-Za-z_]+=[^;,]+)*)\s*")

def parse_inject(spec: str) -> list:
    """Faults of an ``--inject`` specification as :class:`~fdikit.faults.Fault` objects; ``"none"`` -> ``[]``.

    Comma-separated ``[TYPE:]SIGNAL[:VALUE]@START[-END][;period=P;duty=D]``, times in s from the
    start of the log. ``TYPE``: ``bias`` (default; ``offset``, ``step``), ``drift`` (``ramp``;
    VALUE a slope per s, ``0.02/s``), ``gain`` (VALUE the factor), ``stuck`` (at its value at
    START, or at VALUE), ``intermittent`` (a bias VALUE on for ``duty * period`` s of every
    ``period`` s; default 2 s and 0.25). ``SIGNAL``: any name of :func:`inject_channels` (a CAN
    signal or message in its DBC unit, a raw channel, an internal channel).

    Examples
    --------
    >>> parse_inject("yaw_rate:0.03@40")
    [Bias(target='yaw_rate', start=40.0, end=None, magnitude=0.03)]
    >>> [type(f).__name__ for f in parse_inject("stuck:STEER_ANGLE_SENSOR@15,drift:YAW_RATE:0.02/s@10-30")]
    ['Stuck', 'Ramp']
    >>> parse_inject("intermittent:WHEEL_SPEED_RL:1.0@12;period=3")[0].period
    3.0
    """
    from ....faults import Bias, Gain, Intermittent, Ramp, Stuck

    spec = spec.strip()
    if spec.lower() in ("", "none"):
        return []
    out = []
    for part in spec.split(","):
        m = _SPEC.fullmatch(part)
        if not m:
            raise DataError(f"bad fault spec {part!r}; use [TYPE:]SIGNAL[:VALUE]@START[-END], e.g. "
                            f"yaw_rate:0.03@40, drift:YAW_RATE:0.02/s@10, stuck:STEER_ANGLE_SENSOR@15")
        typ = m.group("type")
        if typ is None:
            kind = "bias"
        elif typ.lower() in _TYPE_ALIASES:
            kind = _TYPE_ALIASES[typ.lower()]
        else:
            raise DataError(f"fault spec {part!r}: unknown fault type {typ!r}; known: {list(INJECT_TYPES)}")
        ch, val = m.group("ch"), m.group("val")
        start = float(m.group("start"))
        end = float(m.group("end")) if m.group("end") else None
        opts = {}
        for kv in filter(None, (m.group("opts") or "").split(";")):
            k, v = kv.split("=", 1)
            try:
                opts[k.strip()] = float(v)
            except ValueError:
                raise DataError(f"fault spec {part!r}: option {k!r} needs a number, got {v!r}") from None
        allowed = {"period", "duty"} if kind == "intermittent" else set()
        if set(opts) - allowed:
            raise DataError(f"fault spec {part!r}: options {sorted(set(opts) - allowed)} do not apply to "
                            f"{kind} (allowed: {sorted(allowed) or 'none'})")
        if m.group("per") and kind != "drift":
            raise DataError(f"fault spec {part!r}: '/s' (a slope) is only for drift")
        if val is None and kind != "stuck":
            raise DataError(f"fault spec {part!r}: {kind} needs a value (SIGNAL:VALUE@START)")
        v = None if val is None else float(val)
        kw = {"start": start, "end": end}
        if kind == "bias":
            out.append(Bias(ch, v, **kw))
        elif kind == "drift":
            out.append(Ramp(ch, v, **kw))
        elif kind == "gain":
            out.append(Gain(ch, v, **kw))
        elif kind == "stuck":
            out.append(Stuck(ch, v, **kw))
        else:
            out.append(Intermittent(ch, v, period=opts.get("period", 2.0), duty=opts.get("duty", 0.25), **kw))
    check_inject_targets(out)
    return out
