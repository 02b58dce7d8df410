"""Apply faults to a whole recorded log: every fault type, on the log's own signal names and units.

:func:`apply_faults` replays a recording with synthetic faults: each :class:`~fdikit.faults.Fault`
(bias, ramp/drift, gain, stuck, intermittent, sinusoid, chirp, or a user-defined shape) acts on
one channel of the :class:`~fdikit.Signals` (or :class:`~fdikit.io.LogSignals`) over its
``start <= t < end`` window, exactly as :class:`~fdikit.faults.FaultInjector` applies it in a
simulation, sample by sample (a ``Stuck`` fault without a value holds the value the channel had
at its onset).

A fault's target is a channel of the log (``"yaw_rate"`` or ``"sensor:yaw_rate"``), or a name
declared in ``channels``: an alias for one or several channels of the log, each with the scale
from the fault's units to the log's (``value_in_log = scale * value_in_fault_units``). So a log
whose loader converted a CAN yaw rate to rad/s still takes a drift in deg/s on its CAN name::

    apply_faults(log, [Ramp("YAW_RATE", 0.01, start=20.0)],
                 channels={"YAW_RATE": ("yaw_rate", np.pi / 180)})

The magnitude, slope, stuck-at value and amplitude of the fault are then all in deg/s (the
channel is converted to the fault's units, the fault applied, and the result converted back).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals
from .signals import TIME_TOL, Fault, Parametric

__all__ = ["apply_faults", "resolve_channels"]


def resolve_channels(
    target: str, names: Sequence[str], channels: Mapping[str, Any] | None = None
) -> list[tuple[str, float]]:
    """The log channels (and scales) a fault target acts on.

    Parameters
    ----------
    target : str
        The fault's target: a channel name, ``"sensor:<channel>"``, or a key of ``channels``.
    names : sequence of str
        The log's channels.
    channels : mapping, optional
        Alias -> ``channel``, ``(channel, scale)`` or a list of those (several channels that fail
        together, e.g. every signal of one CAN message).

    Returns
    -------
    list of (channel, scale)

    Examples
    --------
    >>> resolve_channels("sensor:v", ["v", "w"])
    [('v', 1.0)]
    >>> resolve_channels("SPEED", ["v"], {"SPEED": ("v", 1 / 3.6)})
    [('v', 0.2777777777777778)]
    """
    aliases = dict(channels or {})
    name = target.split(":", 1)[1] if target.startswith("sensor:") else target
    for key in (target, name):
        if key in aliases:
            spec = aliases[key]
            items = (
                [spec]
                if isinstance(spec, str)
                or (isinstance(spec, tuple) and len(spec) == 2 and not isinstance(spec[0], tuple))
                else list(spec)
            )
            out = []
            for it in items:
                ch, sc = (it, 1.0) if isinstance(it, str) else (str(it[0]), float(it[1]))
                if ch not in names:
                    raise DataError(
                        f"alias {key!r} maps to channel {ch!r}, which the log does not have; "
                        f"it has {list(names)}"
                    )
                if not (np.isfinite(sc) and sc != 0):
                    raise DataError(
                        f"alias {key!r}: the scale of channel {ch!r} must be finite and non-zero, got {sc}"
                    )
                out.append((ch, sc))
            return out
    if name in names:
        return [(name, 1.0)]
    more = f" and the aliases {sorted(aliases)}" if aliases else ""
    raise DataError(
        f"fault target {target!r} names no channel of the log; it has the channels {list(names)}{more}"
    )


def apply_faults(
    signals: Signals, faults: Iterable[Fault], *, channels: Mapping[str, Any] | None = None
) -> Signals:
    """The log ``signals`` with ``faults`` applied to its channels.

    Faults are applied in the order given (two faults on one channel compose). Samples marked
    invalid in a :class:`~fdikit.io.LogSignals` stay invalid and untouched; the result is of the
    same type with the same validity mask, names and units.

    Parameters
    ----------
    signals : Signals or LogSignals
        The recorded log (one or many runs).
    faults : iterable of Fault
        Any fault of :mod:`fdikit.faults` but :class:`~fdikit.faults.Parametric` (a log has no
        model parameters). Per-run magnitudes are indexed by run.
    channels : mapping, optional
        Aliases of targets (see :func:`resolve_channels` and the module docstring): e.g. raw CAN
        names with the scale from their units to the log's.

    Returns
    -------
    Signals
        A new object; ``signals`` is not modified.

    Raises
    ------
    DataError
        A target that names no channel (listing the known ones), an onset outside the log (naming
        the fault and the log's span), a ``Parametric`` fault.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> from fdikit.faults import Gain, Ramp, Stuck
    >>> log = Signals(np.arange(5.0), np.c_[np.arange(5.0), 10 * np.ones(5)], ["x", "v_kmh"])
    >>> out = apply_faults(log, [Stuck("x", start=2.0), Ramp("x", 1.0, start=3.0), Gain("V", 1.1, start=1.0)],
    ...                    channels={"V": ("v_kmh", 1.0)})
    >>> out["x"].tolist(), out["v_kmh"].round(6).tolist()
    ([[0.0, 1.0, 2.0, 2.0, 3.0]], [[10.0, 11.0, 11.0, 11.0, 11.0]])
    """
    if not isinstance(signals, Signals):
        raise DataError(f"apply_faults needs Signals (a recorded log), got {type(signals).__name__}")
    faults = list(faults)
    t = np.asarray(signals.t, float)
    t0, t1 = float(t[0]), float(t[-1])
    vals = signals.values.copy()
    valid = getattr(signals, "valid", None)
    col = {n: i for i, n in enumerate(signals.names)}
    runs = signals.runs
    ids = np.arange(runs)
    for f in faults:
        if not isinstance(f, Fault):
            raise DataError(
                f"faults must be Fault objects (Bias, Ramp, Gain, Stuck, Intermittent, ...), got {f!r}"
            )
        if isinstance(f, Parametric):
            raise DataError(
                f"{f._label()}: a recorded log has no model parameters; a Parametric fault "
                "cannot be applied to it"
            )
        if not (t0 - TIME_TOL <= f.start <= t1 + TIME_TOL):
            raise DataError(
                f"{f._label()}: onset {f.start:g} s is outside the log, which spans {t0:g} .. {t1:g} s"
            )
        targets = resolve_channels(f.target, signals.names, channels)
        for ch, scale in targets:
            c = col[ch]
            bound = f.bind(ids, runs)
            ok = None if valid is None else valid[:, :, c]
            active = t >= f.start - TIME_TOL
            if f.end is not None:
                active &= t < f.end - TIME_TOL
            for k in np.flatnonzero(active):
                v = vals[:, k, c] / scale  # the channel in the fault's units
                fin = None if ok is None or ok[:, k].all() else ok[:, k]
                new = bound.apply(float(t[k]), v if fin is None else np.where(fin, v, 0.0))
                if new is v:  # inactive (an intermittent fault's off-window)
                    continue
                new = np.asarray(new, float) * scale
                vals[:, k, c] = new if fin is None else np.where(fin, new, vals[:, k, c])
    if valid is not None:
        return type(signals)(
            signals.t, vals, signals.names, signals.units, valid=valid, info=getattr(signals, "info", None)
        )
    return Signals(signals.t, vals, signals.names, signals.units, check=False)
