"""Fault signals: what a fault does to one channel (an actuator, a sensor or a parameter) over time.

Every fault has a ``target`` string,

* ``"actuator:<input>"`` -- acts on the true control input between the controller and the plant;
* ``"sensor:<output>"`` -- acts on the clean measurement (before measurement noise is added);
* ``"param:<name>"`` -- acts on a named parameter of a nonlinear model;
* a plain name (e.g. ``"slope"``) -- drives the additive fault input of that name declared on a
  :class:`~fdikit.model.LinearFaultModel` (its value is 0 when healthy),

a ``start`` time and an optional ``end`` time in seconds: the fault is active for
``start <= t < end``. Magnitudes may be scalars, or arrays of shape ``(runs,)`` holding one value
per Monte Carlo run (indexed by run id, see :func:`fdikit.sim.simulate`).

A fault maps the healthy value ``v`` of its channel (shape ``(runs,)``) to the faulty value:

=================  =====================================================================
``Bias`` (Step)    ``v + b``
``Ramp`` (Drift)   ``v + slope * (t - start)``
``Sinusoid``       ``v + a * sin(2 pi f (t - start) + phase)``
``Chirp``          ``v + a * sin(phase(t))``, frequency swept linearly from ``f0`` to ``f1``
``Intermittent``   ``v + b`` inside on-windows (explicit list, or ``period`` and ``duty``)
``Gain``           ``g * v``
``Stuck``          ``value`` (stuck-at), or the value ``v`` had at onset (``value=None``)
``Parametric``     ``v * (1 + change)`` (relative), ``v + change`` (absolute) or ``change`` (set)
=================  =====================================================================

A new additive shape needs one public method: subclass :class:`Fault` and implement
``shape(t, p)``, the value added to the channel at time ``t`` while the fault is active (``p``
maps each name in ``per_run_fields`` to its value for every run)::

    @dataclass
    class Square(Fault):
        amplitude: float = 1.0
        period: float = 1.0
        per_run_fields: ClassVar[tuple[str, ...]] = ("amplitude",)

        def shape(self, t, p):
            return p["amplitude"] * np.sign(np.sin(2 * np.pi * (t - self.start) / self.period))
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np

from ..errors import DataError

__all__ = [
    "TARGET_KINDS",
    "TIME_TOL",
    "Bias",
    "Drift",
    "Fault",
    "Gain",
    "Intermittent",
    "Parametric",
    "Ramp",
    "Sinusoid",
    "Step",
    "Stuck",
    "parse_target",
    "per_run",
]

#: Tolerance (s) of the time-window comparisons: ``t`` computed as ``k * dt`` may miss ``start``
#: by rounding (``12 * 0.1 - 1.0 < 0.2``); a time within ``TIME_TOL`` of an edge counts as past it.
TIME_TOL = 1e-9

#: Target prefixes; any other string is the name of a fault input declared on a linear model.
TARGET_KINDS = ("actuator", "sensor", "param")


def parse_target(target: Any) -> tuple[str, str]:
    """Split a fault target into ``(kind, name)``.

    ``kind`` is ``"actuator"``, ``"sensor"``, ``"param"`` or ``"input"`` (a plain name: an
    additive fault input declared on a linear model).

    Examples
    --------
    >>> parse_target("sensor:wheel_speed"), parse_target("slope")
    (('sensor', 'wheel_speed'), ('input', 'slope'))
    """
    if not isinstance(target, str) or not target.strip():
        raise DataError(f"fault target must be a non-empty string, got {target!r}")
    kind, sep, name = target.partition(":")
    if sep and kind in TARGET_KINDS:
        if not name:
            raise DataError(f"fault target {target!r} names no {kind} (use '{kind}:<name>')")
        return kind, name
    return "input", target


def per_run(value: Any, run_ids: np.ndarray, total: int | None, what: str) -> Any:
    """Resolve a scalar or a per-run array for the runs ``run_ids``.

    Parameters
    ----------
    value : float or array_like, shape (R,)
        One value for all runs, or one value per Monte Carlo run (index = run id).
    run_ids : ndarray of int, shape (runs,)
        The run ids simulated in this batch.
    total : int or None
        When the batch is ``range(R)`` (no explicit run ids) the array must have exactly
        ``total`` entries; ``None`` only requires an entry for every requested run id.
    what : str
        Name used in error messages.

    Returns
    -------
    float or ndarray, shape (runs,)
    """
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        if not np.isfinite(a):
            raise DataError(f"{what} is {float(a)}; it must be finite")
        return float(a)
    if a.ndim != 1:
        raise DataError(f"{what} must be a scalar or an array of shape (runs,), got shape {a.shape}")
    if total is not None and a.size != total:
        raise DataError(f"{what} has {a.size} per-run values but the batch has {total} runs")
    if run_ids.size and int(run_ids.max()) >= a.size:
        raise DataError(f"{what} has {a.size} per-run values but run id {int(run_ids.max())} "
                        f"was requested (per-run arrays are indexed by run id)")
    out = a[run_ids]
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise DataError(f"{what} is {out[bad[0]]} for run id {int(run_ids[bad[0]])}; it must be finite")
    return out


@dataclass
class Fault:
    """Base class of fault signals; see the module docstring for the targets and semantics.

    Parameters
    ----------
    target : str
        ``"actuator:<input>"``, ``"sensor:<output>"``, ``"param:<name>"`` or a fault-input name.
    start : float
        Onset time (s). The fault is active for ``start <= t < end``.
    end : float or None
        End time (s), ``None`` for a permanent fault.
    """

    target: str
    start: float = field(default=0.0, kw_only=True)
    end: float | None = field(default=None, kw_only=True)

    #: Fields that may hold one value per run.
    per_run_fields: ClassVar[tuple[str, ...]] = ()
    #: Whether the fault adds a signal to the healthy value (meaningful on a fault input).
    additive: ClassVar[bool] = True

    def __post_init__(self) -> None:
        self.kind, self.channel = parse_target(self.target)
        start = float(self.start)
        if not np.isfinite(start):
            raise DataError(f"{self._label()}: start must be finite, got {self.start!r}")
        self.start = start
        if self.end is not None:
            end = float(self.end)
            if not end > start:
                raise DataError(f"{self._label()}: end ({end} s) must be after start ({start} s)")
            self.end = end
        for name in self.per_run_fields:
            v = getattr(self, name)
            if v is None:
                continue
            a = np.asarray(v, dtype=float)
            if a.ndim > 1:
                raise DataError(f"{self._label()}: {name} must be a scalar or shaped (runs,), "
                                f"got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise DataError(f"{self._label()}: {name} contains NaN or inf")

    def _label(self) -> str:
        return f"{type(self).__name__} fault on {self.target!r}"

    # ------------------------------------------------------------------ time windows
    def in_window(self, t: float, eps: float = TIME_TOL) -> bool:
        """``start <= t < end``, with a tolerance ``eps`` (s) for times computed on a grid."""
        if t < self.start - eps:
            return False
        return self.end is None or t < self.end - eps

    def is_active(self, t: float, eps: float = TIME_TOL) -> bool:
        """Whether the fault changes its channel at time ``t`` (s)."""
        return self.in_window(t, eps)

    # ------------------------------------------------------------------ application
    def bind(self, run_ids: np.ndarray, total: int | None) -> BoundFault:
        """Resolve per-run magnitudes for the runs ``run_ids`` (see :func:`per_run`)."""
        vals = {name: per_run(getattr(self, name), run_ids, total, f"{self._label()}: {name}")
                for name in self.per_run_fields if getattr(self, name) is not None}
        return BoundFault(self, vals, run_ids.size)

    def shape(self, t: float, p: dict[str, Any]) -> Any:
        """The additive fault signal at time ``t`` (s) while the fault is active: the public hook.

        A subclass for a new additive shape implements only this method.

        Parameters
        ----------
        t : float
            Time (s), ``start <= t < end``.
        p : dict
            Each name in ``per_run_fields`` with its value: a float, or an array of shape
            ``(runs,)`` when the field holds one value per run.

        Returns
        -------
        float or ndarray (runs,)
            Added to the healthy value of the channel.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement shape(t, p) "
                                  "(the additive fault signal while active)")

    def _apply(self, t: float, v: np.ndarray, vals: dict[str, Any], mem: dict) -> np.ndarray:
        if type(self).shape is Fault.shape:
            raise NotImplementedError(f"{type(self).__name__} must implement shape(t, p) "
                                      "(the additive fault signal while active)")
        return v + np.asarray(self.shape(t, vals), dtype=float)

    def apply(self, t: float, v: Any, run_ids: Sequence[int] | None = None) -> np.ndarray:
        """The faulty value at one time for a healthy value ``v`` (convenience, memoryless).

        Stateful faults (``Stuck`` without a value) need :meth:`bind`; here they hold ``v``.

        Examples
        --------
        >>> Ramp("sensor:v", 0.5, start=1.0, end=3.0).apply(2.0, [10.0]).tolist()
        [10.5]
        """
        v = np.atleast_1d(np.asarray(v, dtype=float))
        ids = np.arange(v.size) if run_ids is None else np.asarray(run_ids, int)
        b = self.bind(ids, None)
        return b.apply(t, v)

    def signal(self, t: Any, base: Any = 0.0, run_ids: Sequence[int] | None = None) -> np.ndarray:
        """The faulty value on a time grid for a constant healthy value ``base``.

        Parameters
        ----------
        t : array_like, shape (T,)
            Times in seconds, increasing.
        base : float or array_like, shape (runs,)
            Healthy value of the channel.

        Returns
        -------
        ndarray, shape (runs, T)

        Examples
        --------
        >>> Bias("sensor:v", 2.0, start=1.0, end=2.0).signal([0.0, 1.0, 1.5, 2.0]).tolist()
        [[0.0, 2.0, 2.0, 0.0]]
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        base = np.atleast_1d(np.asarray(base, dtype=float))
        ids = np.arange(base.size) if run_ids is None else np.asarray(run_ids, int)
        if ids.size != base.size:
            base = np.broadcast_to(base, ids.shape)
        b = self.bind(ids, None)
        return np.stack([b.apply(tk, base.copy()) for tk in t], axis=1)


class BoundFault:
    """A fault with its per-run magnitudes resolved and its memory (stuck values)."""

    __slots__ = ("fault", "mem", "runs", "vals")

    def __init__(self, fault: Fault, vals: dict[str, Any], runs: int):
        self.fault, self.vals, self.runs, self.mem = fault, vals, runs, {}

    def apply(self, t: float, v: np.ndarray, eps: float = TIME_TOL) -> np.ndarray:
        """Faulty value of the channel at time ``t``; ``v`` shape (runs,). Returns a new array
        (or ``v`` itself while the fault is inactive)."""
        if not self.fault.is_active(t, eps):
            return v
        return self.fault._apply(t, v, self.vals, self.mem)


@dataclass
class Bias(Fault):
    """Additive constant (bias / step) ``v + magnitude`` while active.

    Examples
    --------
    >>> Bias("sensor:v", 0.3, start=2.0).apply(2.0, [1.0]).tolist()
    [1.3]
    """

    magnitude: Any = 1.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("magnitude",)

    def _apply(self, t, v, vals, mem):
        return v + vals["magnitude"]


Step = Bias


@dataclass
class Ramp(Fault):
    """Additive drift ``v + slope * (t - start)`` while active (slope in units/s).

    Examples
    --------
    >>> Ramp("actuator:brake", 2.0, start=1.0).apply(1.5, [0.0]).tolist()
    [1.0]
    """

    slope: Any = 1.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("slope",)

    def _apply(self, t, v, vals, mem):
        return v + vals["slope"] * (t - self.start)


Drift = Ramp


@dataclass
class Sinusoid(Fault):
    """Additive sinusoid ``v + amplitude * sin(2 pi frequency (t - start) + phase)`` while active.

    ``frequency`` in Hz, ``phase`` in rad.

    Examples
    --------
    >>> round(float(Sinusoid("sensor:v", 2.0, 0.25).apply(1.0, [0.0])[0]), 12)
    2.0
    """

    amplitude: Any = 1.0
    frequency: Any = 1.0
    phase: Any = 0.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("amplitude", "frequency", "phase")

    def _apply(self, t, v, vals, mem):
        return v + vals["amplitude"] * np.sin(2.0 * np.pi * vals["frequency"] * (t - self.start)
                                              + vals["phase"])


@dataclass
class Chirp(Fault):
    """Additive linear chirp ``v + a sin(2 pi (f0 tau + (f1 - f0) tau^2 / (2 sweep_time)) + phase)``.

    ``tau = t - start``; the frequency rises linearly from ``f0`` to ``f1`` (Hz) over
    ``sweep_time`` (s) and stays at ``f1`` afterwards (continuous phase). Written with the public
    :meth:`Fault.shape` hook only.

    Examples
    --------
    >>> c = Chirp("sensor:v", 2.0, f0=0.0, f1=1.0, sweep_time=1.0)
    >>> round(float(c.apply(0.5, [0.0])[0]), 12)  # sin(2 pi * 0.125) * 2
    1.414213562373
    """

    amplitude: Any = 1.0
    f0: Any = 0.1
    f1: Any = 1.0
    sweep_time: float = 1.0
    phase: Any = 0.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("amplitude", "f0", "f1", "phase")

    def __post_init__(self) -> None:
        super().__post_init__()
        st = float(self.sweep_time)
        if not (np.isfinite(st) and st > 0):
            raise DataError(f"{self._label()}: sweep_time must be finite and > 0, got {self.sweep_time!r}")
        self.sweep_time = st

    def shape(self, t, p):
        tau = t - self.start
        f0, f1 = p["f0"], p["f1"]
        k = (f1 - f0) / self.sweep_time
        ts = min(tau, self.sweep_time)
        cyc = f0 * ts + 0.5 * k * ts * ts + f1 * max(tau - self.sweep_time, 0.0)
        return p["amplitude"] * np.sin(2.0 * np.pi * cyc + p["phase"])


@dataclass
class Intermittent(Fault):
    """Additive bias that switches on and off: ``v + magnitude`` inside on-windows.

    Give either ``windows``, a list of absolute ``(t_on, t_off)`` intervals (each
    ``t_on <= t < t_off``), or ``period`` and ``duty`` (fraction on): on for
    ``start + k period <= t < start + (k + duty) period``. Either way only inside
    ``start <= t < end``.

    Examples
    --------
    >>> f = Intermittent("sensor:v", 1.0, period=1.0, duty=0.25)
    >>> f.signal([0.0, 0.2, 0.3, 1.1, 1.5]).tolist()
    [[1.0, 1.0, 0.0, 1.0, 0.0]]
    """

    magnitude: Any = 1.0
    windows: Sequence[tuple[float, float]] | None = None
    period: float | None = None
    duty: float | None = None
    per_run_fields: ClassVar[tuple[str, ...]] = ("magnitude",)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.windows is not None:
            if self.period is not None or self.duty is not None:
                raise DataError(f"{self._label()}: give either windows or period/duty, not both")
            w = np.asarray(self.windows, dtype=float)
            if w.ndim != 2 or w.shape[1] != 2:
                raise DataError(f"{self._label()}: windows must be a list of (t_on, t_off) pairs, "
                                f"got shape {w.shape}")
            if not np.all(np.isfinite(w)):
                raise DataError(f"{self._label()}: windows contain NaN or inf")
            bad = np.flatnonzero(w[:, 1] <= w[:, 0])
            if bad.size:
                i = int(bad[0])
                raise DataError(f"{self._label()}: window {i} ({w[i, 0]}, {w[i, 1]}) ends before it starts")
            self.windows = [tuple(map(float, r)) for r in w]
        else:
            if self.period is None or self.duty is None:
                raise DataError(f"{self._label()}: give windows=[(t_on, t_off), ...] or period and duty")
            self.period, self.duty = float(self.period), float(self.duty)
            if not self.period > 0:
                raise DataError(f"{self._label()}: period must be positive, got {self.period}")
            if not 0.0 <= self.duty <= 1.0:
                raise DataError(f"{self._label()}: duty must be in [0, 1], got {self.duty}")

    def is_active(self, t: float, eps: float = TIME_TOL) -> bool:
        if not self.in_window(t, eps):
            return False
        if self.windows is not None:
            return any(a - eps <= t < b - eps for a, b in self.windows)
        phase = (t - self.start + eps) % self.period
        return phase < self.duty * self.period

    def _apply(self, t, v, vals, mem):
        return v + vals["magnitude"]


@dataclass
class Gain(Fault):
    """Multiplicative fault ``gain * v`` while active (``gain = 0.95``: a 5 % lower reading).

    Examples
    --------
    >>> Gain("sensor:wheel_speed", 0.95).apply(0.0, [100.0]).tolist()
    [95.0]
    """

    gain: Any = 1.0
    per_run_fields: ClassVar[tuple[str, ...]] = ("gain",)
    additive: ClassVar[bool] = False

    def _apply(self, t, v, vals, mem):
        return v * vals["gain"]


@dataclass
class Stuck(Fault):
    """Stuck-at fault: the channel reads ``value`` while active; with ``value=None`` it holds the
    healthy value it had at the first active instant (the onset).

    Examples
    --------
    >>> Stuck("sensor:v", 3.0, start=1.0).signal([0.0, 1.0, 2.0], base=7.0).tolist()
    [[7.0, 3.0, 3.0]]
    """

    value: Any = None
    per_run_fields: ClassVar[tuple[str, ...]] = ("value",)
    additive: ClassVar[bool] = False

    def _apply(self, t, v, vals, mem):
        if "value" in vals:
            val = vals["value"]
            return np.zeros(np.broadcast_shapes(np.shape(v), np.shape(val))) + val
        if "held" not in mem:
            mem["held"] = np.array(v, dtype=float, copy=True)
        return mem["held"].copy()


@dataclass
class Parametric(Fault):
    """Change of a model parameter (target ``"param:<name>"``) while active.

    ``mode="relative"``: ``p * (1 + change)`` (``change=-0.25`` is a 25 % decrease);
    ``mode="absolute"``: ``p + change``; ``mode="set"``: ``change`` replaces ``p``.

    Examples
    --------
    >>> Parametric("param:R_w", -0.25, start=1.0).apply(1.0, [0.3]).round(6).tolist()
    [0.225]
    """

    change: Any = 0.0
    mode: str = "relative"
    per_run_fields: ClassVar[tuple[str, ...]] = ("change",)
    additive: ClassVar[bool] = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.mode not in ("relative", "absolute", "set"):
            raise DataError(f"{self._label()}: mode must be 'relative', 'absolute' or 'set', "
                            f"got {self.mode!r}")

    def _apply(self, t, v, vals, mem):
        c = vals["change"]
        if self.mode == "relative":
            return v * (1.0 + c)
        if self.mode == "absolute":
            return v + c
        return np.zeros(np.broadcast_shapes(np.shape(v), np.shape(c))) + c


def fault_fields(f: Fault) -> dict[str, Any]:
    """The constructor fields of a fault (for reprs and serialisation)."""
    return {fl.name: getattr(f, fl.name) for fl in fields(f)}
