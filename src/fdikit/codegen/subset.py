"""A monitor's leading part (:func:`subset_monitor`): its generators, its processors up to a given
one, and its decision on the alarm channels that part produces -- what the code generator emits
when a later stage cannot be generated yet (``generate(..., stop_after=...)``), and what the
harness compares it with."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..errors import DataError

__all__ = ["subset_monitor"]


def subset_monitor(mon: Any, n_processors: int, *, alarms: Sequence[str] | None = None,
                   names: Mapping[str, str] | None = None) -> Any:
    """A :class:`~fdikit.monitor.Monitor` of ``mon``'s generators and first ``n_processors``
    processors (the same stage objects), with the same runtime options.

    Parameters
    ----------
    mon : Monitor
    n_processors : int
        Processors kept (0 .. all).
    alarms : sequence of str, optional
        Alarm channels of the decision (default: those of ``mon``'s decision that the kept stages
        produce, in its order). Each must be a channel of the kept stages.
    names : mapping, optional
        Hypothesis names of extra ``alarms`` (the decision's own names are kept).

    Returns
    -------
    Monitor
        Its decision has ``mon``'s level, clear level, clear time, size channels and groups (those
        still produced or announced); None when no alarm channel is left.

    Raises
    ------
    DataError
        ``n_processors`` out of range, or an alarm channel the kept stages do not produce.

    Examples
    --------
    >>> from fdikit.detect import Hold
    >>> from fdikit.monitor import Decision, Monitor
    >>> from fdikit.residuals import FaultDetectionFilter, FilterDesign
    >>> import numpy as np
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                  np.zeros((1, 0)), np.eye(1), 0.1, [], ["y"], ["r"])
    >>> h1, h2 = Hold(["r"], 1.0), Hold(["r:alarm"], 0.5)
    >>> m = Monitor([FaultDetectionFilter(d)], [h1, h2], Decision(["r:alarm", "r:alarm:alarm"]))
    >>> subset_monitor(m, 1).decision.alarm_channels
    ['r:alarm']
    """
    from ..monitor import Decision, Monitor

    procs = list(mon.processors)
    if isinstance(n_processors, bool) or not 0 <= int(n_processors) <= len(procs):
        raise DataError(f"n_processors must be 0 .. {len(procs)}, got {n_processors!r}")
    kept = procs[:int(n_processors)]
    pool = [n for g in mon.generators for n in g.output_names] + [n for p in kept for n in p.output_names]
    dec = mon.decision
    if alarms is None:
        alarms = [] if dec is None else [c for c in dec.alarm_channels if c in pool]
    alarms = [str(a) for a in alarms]
    bad = [a for a in alarms if a not in pool]
    if bad:
        raise DataError(f"alarm channels {bad} are not produced by the kept stages "
                        f"({len(mon.generators)} generators, {len(kept)} processors)")
    decision = None
    if alarms:
        nm = {**(dict(dec.names) if dec is not None else {}), **dict(names or {})}
        nm = {c: nm[c] for c in alarms if c in nm}
        kw: dict[str, Any] = {}
        if dec is not None:
            kw = {"clear_level": dec.clear_level, "clear_after": dec.clear_after}
            sizes = {k: v for k, v in (dec.size_channels or {}).items()
                     if v in pool and (k in alarms or k in nm.values())}
            if sizes:
                kw["size_channels"] = sizes
            # the groups, on the names still announced (a group keeps one episode for its names)
            kept_names = {nm.get(c, c) for c in alarms}
            groups = {g: [h for h in m if h in kept_names] for g, m in (dec.groups or {}).items()}
            groups = {g: m for g, m in groups.items() if m}
            if groups:
                kw["groups"] = groups
        decision = Decision(alarms, dec.level if dec is not None else 0.5, nm, **kw)
    return Monitor(list(mon.generators), kept, decision, validate=mon.validate, on_invalid=mon.on_invalid,
                   plausibility=dict(mon.plausibility) or None, dt=mon.dt, max_gap=mon.max_gap,
                   warmup=mon.warmup, max_abs=mon.max_abs)
