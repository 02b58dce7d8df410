"""The Monitor's time policy: the sample period, regular steps and gaps, and the warm-up at the
start and after a gap (its default from the generators' settling time)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["JITTER_TOL", "MAX_DEFAULT_WARMUP"]

#: Relative tolerance on sample intervals: a step within ``1 %`` of ``dt`` (plus the float64
#: resolution of the time stamps, ``8 eps |t|``) is a regular step.
JITTER_TOL = 0.01

#: Longest default warm-up (s) when it comes from a filter's settling time (see Monitor).
MAX_DEFAULT_WARMUP = 10.0



def _positive(x: Any, what: str, *, allow_zero: bool = False) -> float | None:
    if x is None:
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise DataError(f"Monitor {what} must be a number of seconds, got {x!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        need = ">= 0" if allow_zero else "positive"
        raise DataError(f"Monitor {what} must be {need} and finite, got {x!r}")
    return v


def _generator_dt(g: Any) -> float | None:
    """A generator's sample period: its ``dt`` or its design's ``dt``, if it has one."""
    for obj in (g, getattr(g, "design", None)):
        d = getattr(obj, "dt", None)
        if isinstance(d, (int, float, np.floating, np.integer)) and not isinstance(d, bool):
            d = float(d)
            if math.isfinite(d) and d > 0:
                return d
    return None


def _settling_time(g: Any, dt: float, horizon: float) -> float | None:
    """A generator's settling time (s): its ``settling_time`` if it exposes one; for a linear
    filter (``design.A``, ``design.C``) the 0.1 % settling time of its free response, the last
    time ``||C A^k||_2`` exceeds 1e-3 times its peak (within ``horizon``); else None."""
    s = getattr(g, "settling_time", None)
    if isinstance(s, (int, float, np.floating)) and math.isfinite(s) and s >= 0:
        return float(s)
    d = getattr(g, "design", None)
    A, C = getattr(d, "A", None), getattr(d, "C", None)
    try:
        A = np.asarray(A, float)
        C = np.asarray(C, float)
    except (TypeError, ValueError):
        return None
    if A.ndim != 2 or C.ndim != 2 or A.shape[0] != A.shape[1] or C.shape[1] != A.shape[0] or A.size == 0:
        return None
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(C))):
        return None
    n = math.ceil(horizon / dt) + 1
    M = C.copy()
    norms = np.empty(n)
    for k in range(n):
        norms[k] = np.linalg.norm(M, 2)
        M = M @ A
    peak = norms.max()
    if peak == 0:
        return 0.0
    above = np.flatnonzero(norms > 1e-3 * peak)
    return float(min((above[-1] + 1) * dt, horizon))


class _TimePolicy:
    """The Monitor's time policy (a part of :class:`~fdikit.monitor.core.Monitor`)."""

    def expected_dt(self) -> float | None:
        """The configured sample period: ``dt`` if given, else the generators' (or None)."""
        return self.dt if self.dt is not None else self._gen_dt

    def default_warmup(self, dt: float) -> float:
        """The default warm-up (s) at sample period ``dt`` (see :class:`~fdikit.monitor.core.Monitor`)."""
        if dt not in self._settle:
            cap = max(MAX_DEFAULT_WARMUP, 20 * dt)
            vals = [_settling_time(g, dt, cap) for g in self.generators]
            vals = [20 * dt if v is None else v for v in vals] or [20 * dt]
            self._settle[dt] = float(min(max(vals), cap))
        return self._settle[dt]

    def _tol(self, dt: float, t_abs: float) -> float:
        return JITTER_TOL * dt + 8 * np.finfo(float).eps * abs(t_abs)

    def _record_dt(self, t: np.ndarray) -> float | None:
        """The sample period for a record: the configured one (checked against the record's median
        interval) or that median."""
        dt = self.expected_dt()
        if t.size < 2:
            return dt
        med = float(np.median(np.diff(t)))
        if dt is None:
            return med
        if abs(med - dt) > self._tol(dt, float(np.max(np.abs(t[[0, -1]])))):
            raise DataError(f"the record is sampled every {med:.6g} s (median interval) but the monitor "
                            f"expects dt = {dt:g} s; resample the log onto a {dt:g} s grid "
                            f"([log].rate = {1 / dt:g} Hz)")
        return dt

    def _gap_limit(self, dt: float) -> float:
        g = 1.5 * dt if self.max_gap is None else self.max_gap
        if not g > dt:
            raise DataError(f"Monitor max_gap ({g:g} s) must exceed the sample period dt = {dt:g} s")
        return g

    def _gaps_of(self, t: np.ndarray, dt: float, *, strict: bool) -> list[tuple[int, int]]:
        """``(k, n_missing)`` of every gap; with ``strict`` a step that is neither regular nor a
        gap raises."""
        if t.size < 2:
            return []
        s = np.diff(t)
        limit = self._gap_limit(dt)
        gap = s > limit
        if strict:
            tol = JITTER_TOL * dt + 8 * np.finfo(float).eps * np.maximum(np.abs(t[1:]), np.abs(t[:-1]))
            off = ~gap & (np.abs(s - dt) > tol)
            if off.any():
                k = int(np.flatnonzero(off)[0]) + 1
                raise DataError(f"the record's time steps are irregular: sample {k} follows after "
                                f"{s[k - 1]:.6g} s (t = {t[k]:.15g} s) where dt = {dt:g} s (tolerance "
                                f"{JITTER_TOL:.0%}, and steps over max_gap = {limit:g} s are gaps); "
                                f"resample the log onto a {dt:g} s grid ([log].rate = {1 / dt:g} Hz)")
        ks = np.flatnonzero(gap)
        return [(int(k) + 1, max(1, round(float(s[k]) / dt) - 1)) for k in ks]

    def start_warmup(self, dt: float) -> float:
        """The default warm-up (s) at the start of a record: the settling time of the generators
        that tell it (a ``settling_time``, or a linear filter's), at most :data:`MAX_DEFAULT_WARMUP`;
        0 when none does (a generator without state has no start-up transient)."""
        key = ("start", dt)
        if key not in self._settle:
            cap = max(MAX_DEFAULT_WARMUP, 20 * dt)
            vals = [v for v in (_settling_time(g, dt, cap) for g in self.generators) if v is not None]
            self._settle[key] = float(min(max(vals, default=0.0), cap))
        return self._settle[key]

    def _start_warm_samples(self, dt: float | None) -> int:
        """Samples of the default start-up warm-up: with ``warmup=None``, a decision (which could
        announce the filters' start-up transient) and a known sample period; else 0."""
        if self.warmup is not None or self.decision is None or dt is None:
            return 0
        return round(self.start_warmup(dt) / dt)

    def _warm_samples(self, dt: float) -> int:
        w = self.default_warmup(dt) if self.warmup is None else self.warmup
        return round(w / dt)
