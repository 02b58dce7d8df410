"""The Monitor's batch path: a whole record through the chain at once, vectorised over runs
and time (a record with gaps or held samples goes to the streaming path instead)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals, check_finite
from .events import _WARM, MonitorResult


def _own_inputs(p: Any) -> list[str] | None:
    """The channels a processor's batch ``run`` reads, when that is known: ``input_names`` of a
    processor whose ``run`` is fdikit's own (they read ``signals.index(self.input_names)`` only);
    None for any other (it gets the whole pool)."""
    names = getattr(p, "input_names", None)
    run = getattr(type(p), "run", None)
    mod = getattr(run, "__module__", "") or ""
    if names is None or not isinstance(p, ResidualProcessor) or not mod.startswith("fdikit."):
        return None
    return list(names)


class _BatchPath:
    """The Monitor's batch path (a part of :class:`~fdikit.monitor.core.Monitor`)."""

    # ------------------------------------------------------------------ batch
    def run(self, signals: Signals) -> MonitorResult:
        """Run the whole chain over a record (all runs at once).

        A record with gaps or invalid samples (``on_invalid="hold"``) goes through the streaming
        path (:meth:`stream`), which holds the state over them; a clean regular record is
        processed vectorised. Both give the same numbers.
        """
        t = signals.t
        dt = self._record_dt(t)
        sel = signals.select(self.input_names).values  # unknown channels are named here
        gaps = self._gaps_of(t, dt, strict=True) if dt is not None else []
        if gaps:
            return self.stream(signals)
        if self.validate:
            if not np.all(np.isfinite(sel)):
                if self.on_invalid == "hold":
                    return self.stream(signals)
                check_finite(sel, self.input_names)
            reason = self._batch_invalid(sel, t, dt)
            if reason is not None:
                if self.on_invalid == "raise":
                    raise DataError(reason)
                return self.stream(signals)
        T = signals.n_samples
        gen_in = signals
        if dt is not None and T > 1 and np.max(np.abs(np.diff(t) - dt)) > 1e-9 * dt:
            # regular within the tolerance (e.g. epoch time stamps at float64 resolution): the
            # generators see the ideal grid, which is what they were designed for
            gen_in = Signals(np.arange(T) * dt, signals.values, signals.names, signals.units, check=False)
        res = [g.run(gen_in) for g in self.generators]
        r = Signals.join_channels(res)
        r = Signals(t, r.values, r.names, r.units, check=False)
        status = np.zeros((signals.runs, T), np.int8)
        n_w = min(self._warm_samples(dt), T) if (self.warmup and dt is not None) else 0
        n_max = min(self._start_warm_samples(dt), T)
        if n_max > 0:
            # the default start-up warm-up: the filters' settling time, ended early once every alarm
            # channel has stayed below its clear level for clear_after (as streaming does)
            first = self._processors(Signals(t[:n_max], r.values[:, :n_max], r.names, check=False))
            pool = self._decision_pool(Signals(t[:n_max], r.values[:, :n_max], r.names, check=False), first)
            v = pool.values[:, :, pool.index(self.decision.alarm_channels)]
            quiet = np.all(v < self.decision.low_level, axis=(0, 2))
            n_clear = self.decision.clear_samples(dt)
            run_len = np.zeros(n_max, np.int64)
            c = 0
            for k, q in enumerate(quiet):
                c = c + 1 if q else 0
                run_len[k] = c
            done = np.flatnonzero(run_len >= n_clear)
            n_w = int(done[0]) + 1 if done.size else n_max
        if n_w and self.processors:
            status[:, :n_w] = _WARM
            parts = [self._processors(Signals(t[a:b], r.values[:, a:b], r.names, check=False))
                     for a, b in ((0, n_w), (n_w, T)) if b > a]
            st_vals = np.concatenate([p.values for p in parts], axis=1)
        else:
            status[:, :n_w] = _WARM
            st_vals = self._processors(r).values
        st = Signals(t, st_vals, self.stat_names, check=False)
        events, cleared, changes = [], [], []
        if self.decision is not None:
            pool = self._decision_pool(r, st)
            for e in self.decision.events(t, pool, status=status, dt=dt if dt else 1.0):
                kind = e.kind
                (cleared if kind == "cleared" else changes if kind == "change" else events).append(e)
        return MonitorResult(r, st, events, np.ones((signals.runs, T), bool), [], status, [], cleared,
                             changes)

    def _decision_pool(self, r: Signals, st: Signals) -> Signals:
        """The channels the decision reads, from the residuals and statistics (gathered, not the
        whole pool joined); the joined pool where a name is missing, which names it."""
        names = getattr(self.decision, "channels", None)
        if names is None:  # a decision of another kind: the whole pool
            return r.concat_channels(st)
        where = {n: (0, i) for i, n in enumerate(r.names)}
        where.update({n: (1, i) for i, n in enumerate(st.names)})
        if len(where) == r.n_channels + st.n_channels and all(n in where for n in names):
            return self._gather([r, st], where, names, r)
        return r.concat_channels(st)

    def _processors(self, r: Signals) -> Signals:
        """The processors' outputs over a record of residuals (fresh processors).

        Every processor sees the pool of the residuals and the outputs of the processors before
        it. The pool is kept as its parts (no copy of the growing pool per processor): a
        processor of fdikit's own, which reads its ``input_names`` only, gets just those channels
        (gathered in one copy; the same values as from the joined pool); any other gets the
        joined pool."""
        parts = [r]
        where: dict[str, tuple[int, int]] = {}  # name -> (part, column)

        def add(s: Signals) -> None:
            if any(n in where for n in s.names):  # what joining the pool would refuse
                names = [n for p in parts for n in p.names]
                dup = sorted({n for n in names if names.count(n) > 1})
                raise DataError(f"duplicated channel names: {dup}")
            for i, n in enumerate(s.names):
                where[n] = (len(parts) - 1, i)

        add(r)
        for p in self.processors:
            names = _own_inputs(p)
            if names is not None and all(n in where for n in names):
                pool = self._gather(parts, where, names, r)
            else:
                pool = Signals.join_channels(parts)
            parts.append(p.run(pool))
            add(parts[-1])
        if not self.stat_names:
            return Signals(r.t, np.zeros((r.runs, r.n_samples, 0)), [], check=False)
        if all(n in where for n in self.stat_names):
            return self._gather(parts, where, self.stat_names, r)
        return Signals.join_channels(parts).select(self.stat_names)

    @staticmethod
    def _gather(parts: list[Signals], where: dict[str, tuple[int, int]], names: Sequence[str],
                r: Signals) -> Signals:
        """Channels ``names`` of the pool ``parts`` as one new (contiguous) Signals."""
        names = list(names)
        vals = np.empty((r.runs, r.n_samples, len(names)))
        units = []
        j = 0
        while j < len(names):  # runs of consecutive columns of one part in one copy each
            a, i = where[names[j]]
            e = j + 1
            while e < len(names) and where[names[e]] == (a, i + e - j):
                e += 1
            vals[:, :, j:e] = parts[a].values[:, :, i:i + e - j]
            units += parts[a].units[i:i + e - j]
            j = e
        return Signals(r.t, vals, names, units, check=False, t0=r.t0)

    def _batch_invalid(self, sel: np.ndarray, t: np.ndarray, dt: float | None) -> str | None:
        """The reason of the first invalid sample of a finite record (max_abs, range, rate, spike)."""
        chk = self._checker
        if chk is None:
            if self.max_abs is None:
                return None
            bad = np.abs(sel) > self.max_abs
            if not bad.any():
                return None
            k = int(np.flatnonzero(bad.any(axis=(0, 2)))[0])
            chk = self._abs_checker
            chk.reset(sel.shape[0], dt)
            return chk.check(k, float(t[k]), sel[:, k])
        chk.reset(sel.shape[0], dt)
        if not chk.sequential:
            bad = np.abs(sel) > self.max_abs if self.max_abs is not None else np.zeros(sel.shape, bool)
            bad |= (sel < chk.lo) | (sel > chk.hi)
            if not bad.any():
                return None
            k = int(np.flatnonzero(bad.any(axis=(0, 2)))[0])
            return chk.check(k, float(t[k]), sel[:, k])
        for k in range(sel.shape[1]):
            x = sel[:, k]
            why = chk.check(k, float(t[k]), x)
            if why is not None:
                return why
            chk.observe(float(t[k]), x, True)
        return None
