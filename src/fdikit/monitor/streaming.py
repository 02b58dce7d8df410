"""The Monitor's streaming runtime: ``reset(runs)`` then ``step(...)`` once per sample, with the
bad-data policy (invalid samples held, gaps, warm-up) and the episode rule applied per sample."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..base.stage import _as_batch
from ..errors import DataError
from ..signals import Signals
from .events import _CANNOT, _OK, _WARM, STATUS_NAMES, Event, Gap, MonitorResult, _event_key


class _StreamingPath:
    """The Monitor's streaming path (a part of :class:`~fdikit.monitor.core.Monitor`)."""

    # ------------------------------------------------------------------ streaming
    def reset(self, runs: int = 1) -> None:
        """Start a new record of ``runs`` runs (every component to its initial state)."""
        for g in self.generators:
            g.reset(runs)
        for p in self.processors:
            p.reset(runs)
        self._k = 0
        self._t_prev: float | None = None
        self._held = 0          # held samples since the last good one (any reason)
        self._held_t = 0        # ... of them, those whose time was valid (they took a period)
        self._missing = 0       # samples missing in gaps since the last good one
        self._runs = int(runs)
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.last_invalid = None
        self.last_gap = None
        self.last_status = None
        self._set_dt(self.expected_dt())
        d = self.decision
        U = len(d._unit_chans) if d is not None else 0
        self._active = np.zeros((self._runs, U), bool)
        self._below = np.zeros((self._runs, U), np.int64)
        self._ep_id = np.zeros((self._runs, U), np.int64)
        self._cur = np.zeros((self._runs, U), np.int64)      # the hypothesis an episode names now
        H = sum(len(h) for h in d._unit_hyps) if d is not None else 0
        self._prev_on = np.zeros((self._runs, H), bool)      # per hypothesis, at the last judged sample
        self._n_ep = np.zeros(self._runs, np.int64)
        # per tentative name of Decision.confirm_after: -1 idle, j >= 0 waited, -2 announced, -3 dropped
        self._confirm = np.full((self._runs, len(d._tent) if d is not None else 0), -1, np.int64)
        self._abs_checker.reset(self._runs, self._dt)
        if self._checker is not None:
            self._checker.reset(self._runs, self._dt)

    def _set_dt(self, dt: float | None) -> None:
        """Fix the sample period of this record (and what follows from it)."""
        self._dt = dt
        if dt is None:
            self._n_warm, self._n_clear, self._limit, self._n_confirm = 0, 1, math.inf, 0
            self._warm_left, self._reset_due, self._warm_min, self._quiet = 0, False, 0, -1
            return
        self._limit = self._gap_limit(dt)
        self._n_warm = self._warm_samples(dt)
        self._n_clear = self.decision.clear_samples(dt) if self.decision is not None else 1
        self._n_confirm = self.decision.confirm_samples(dt) if self.decision is not None else 0
        # an explicit warm-up also covers the start of the record; by default, with a decision, the
        # start-up transient of the filters is a warm-up too, ended early once every alarm channel
        # has been quiet for clear_after
        n_start = self._start_warm_samples(dt)
        start = self._n_warm if self.warmup else n_start
        self._warm_left, self._reset_due = start, start > 0
        self._warm_min, self._quiet = 0, (0 if n_start else -1)  # -1: a fixed warm-up (no early end)
        if self._checker is not None:
            self._checker.dt = dt

    def step(self, t: float, sample: dict[str, Any] | np.ndarray,
             names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray, list[Event]]:
        """Advance one sample.

        ``sample`` is a mapping channel -> value (scalar or (runs,)) or an array
        ``(runs, len(names))``. Returns residuals ``(runs, R)``, statistics ``(runs, S)`` and the
        events of this sample (onsets and cleared events; ``Event.kind`` tells them apart).
        Afterwards :attr:`last_status` is the sample's status (:data:`STATUS_NAMES`),
        :attr:`last_invalid` the reason it was held (or None) and :attr:`last_gap` the gap that
        ended at it (or None).
        """
        if self._runs is None:
            raise DataError("call reset(runs) before step")
        self.last_invalid = None
        self.last_gap = None
        if self._t_prev is not None and not t > self._t_prev:
            msg = f"time is not increasing at sample {self._k}: {t} after {self._t_prev}"
            if self.on_invalid == "raise" or not np.isfinite(t):
                raise DataError(msg)
            return self._hold(msg)
        if not np.isfinite(t):
            raise DataError(f"time is not finite at sample {self._k}: {t}")
        t = float(t)
        if isinstance(sample, dict):
            key = tuple(sample)
            vals = np.empty((self._runs, len(key)))
            for i, n in enumerate(key):
                vals[:, i] = sample[n]
        else:
            if names is None:
                raise DataError("give channel names with an array sample")
            key = tuple(names)
            vals = _as_batch(sample, len(key), "monitor", key)
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plan(key)
        sel, gen_idx = plan
        # ---- time: a gap? (judged before any state changes)
        n_gap = 0
        if self._t_prev is not None:
            if self._dt is None:  # no configured period: the first interval defines it
                self._set_dt(t - self._t_prev)
            if t - self._t_prev > self._limit:
                n_gap = max(1, round((t - self._t_prev) / self._dt) - 1)
        # ---- values
        reason = None
        x = None
        if self.validate:
            # (the largest magnitude of the whole sample proves every input finite and sane;
            # otherwise look closely: a channel the monitor does not read may be NaN)
            m = float(np.abs(vals).max()) if vals.size else 0.0
            if not m <= self._abs_limit or m == math.inf:   # inf too when max_abs is None
                x = vals[:, sel]
                bad = ~np.isfinite(x)
                if bad.any():
                    run, c = np.argwhere(bad)[0]
                    reason = (f"channel {self.input_names[c]!r} has a non-finite value at sample {self._k} "
                              f"(run {run})")
                elif self._checker is None:
                    reason = self._abs_checker.check(self._k, t, x)
            if reason is None and self._checker is not None:
                x = vals[:, sel] if x is None else x
                reason = self._checker.check(self._k, t, x)
            if reason is not None and self.on_invalid == "raise":
                raise DataError(reason)
        if self._checker is not None and x is None:
            x = vals[:, sel]
        # ---- state changes from here on
        if n_gap:
            self._missing += n_gap
            self.last_gap = Gap(0, float(self._t_prev), t, n_gap, self._k)
            if self._checker is not None:
                self._checker.gap()
        if reason is not None:
            if self._checker is not None:
                self._checker.observe(t, x, False)
            return self._hold(reason, t)
        if self._checker is not None:
            self._checker.observe(t, x, True)
        n_resume = self._missing + self._held_t
        if n_resume:  # good data again after a gap or held samples: components that care are told
            for c in self._resumers:
                c.resume(n_resume)
            self._warm_left, self._reset_due = self._n_warm, True
            if self.warmup is None and self.decision is not None:
                # the default warm-up may end early: after at least ten times the missing samples,
                # once every alarm channel has been quiet for clear_after
                self._warm_min, self._quiet = min(self._n_warm, 10 * n_resume), 0
        self._held = self._held_t = self._missing = 0
        if self._warm_left > 0:
            status = _WARM
            self._warm_left -= 1
            self._warm_min = max(self._warm_min - 1, 0)
        else:
            status = _OK
            if self._reset_due:  # the warm-up is over: no statistic carries its transient
                for p in self.processors:
                    p.reset(self._runs)
                self._reset_due = False
        pool = np.empty((vals.shape[0], len(self._pool_names)))
        j = 0
        for (fn, joined), (ui, yi, uyi) in zip(self._gen_steps, gen_idx):
            out = fn(vals[:, uyi]) if joined else fn(vals[:, ui], vals[:, yi])
            pool[:, j:j + out.shape[1]] = out
            j += out.shape[1]
        for p, fn_p, idx, sl in zip(self.processors, self._proc_steps, self._proc_idx, self._proc_out):
            r_in = pool[:, idx]
            # processors whose rule depends on time (e.g. TimeGated) take it with the sample
            pool[:, sl] = p.step_at(t, r_in) if getattr(p, "needs_time", False) else fn_p(r_in)
        nr = len(self.residual_names)
        r, st = pool[:, :nr], pool[:, nr:]
        events = self._decide(t, pool) if (self.decision is not None and status == _OK) else []
        if status == _WARM and self._quiet >= 0:
            quiet = bool(np.all(pool[:, self._dec_idx] < self.decision.low_level))
            self._quiet = self._quiet + 1 if quiet else 0
            if self._warm_min == 0 and self._quiet >= self._n_clear:
                self._warm_left = 0
        self._k += 1
        self._t_prev = t
        self._last = (r, st)
        self.last_status = STATUS_NAMES[status]
        return r, st, events

    def _decide(self, t: float, pool: np.ndarray) -> list[Event]:
        """The episode rule of :class:`Decision` at one judged sample."""
        d = self.decision
        v = pool[:, self._dec_idx]
        on = v >= d.level  # (NaN compares False: neither on nor below the clear level)
        act = self._active
        gated = None
        if d._tent and self._n_confirm > 0:
            gated = v < d.low_level
            d._gate_step(on, gated, self._confirm, self._n_confirm)
        if d._simple:
            on_u = on
            if not (on.any() or act.any()):
                return []
            low_u = v < d.low_level if gated is None else gated
        else:
            on_h = np.stack([on[:, chans].any(axis=1) for hc in d._hyp_chans for chans in hc], axis=1)
            rise = on_h & ~self._prev_on
            self._prev_on = on_h
            on_u = np.stack([on[:, chans].any(axis=1) for chans in d._unit_chans], axis=1)
            if not (on_u.any() or act.any()):
                return []
            low = v < d.low_level if gated is None else gated
            low_u = np.stack([low[:, chans].all(axis=1) for chans in d._unit_chans], axis=1)
        self._below = np.where(act & low_u, self._below + 1, 0)
        done = act & (self._below >= self._n_clear)
        new = on_u & ~act
        out = []
        if not d._simple:
            h0 = np.cumsum([0] + [len(h) for h in d._unit_hyps])
            for run, u in np.argwhere(act & ~done):
                for hi in range(len(d._unit_hyps[u])):
                    if rise[run, h0[u] + hi] and hi != self._cur[run, u] \
                            and d._unit_hyps[u][hi] != d._unit_names[u]:
                        a = next(c for c in d._hyp_chans[u][hi] if on[run, c])
                        si = self._size_idx[a]
                        h, prev = d._unit_hyps[u][hi], d._unit_hyps[u][self._cur[run, u]]
                        out.append(((int(run), 2, h, int(a)),
                                    Event(int(run), self._k, t, h, float(v[run, a]), "change",
                                          None if si is None else float(pool[run, si]),
                                          int(self._ep_id[run, u]), prev)))
                        self._cur[run, u] = hi
        if not (done.any() or new.any() or out):
            return []
        for run, u in np.argwhere(done):
            h = d._unit_hyps[u][self._cur[run, u]]
            a = d._hyp_chans[u][self._cur[run, u]][0]
            out.append(((int(run), 0, h, int(a)),
                        Event(int(run), self._k, t, h, float(v[run, a]), "cleared", None,
                              int(self._ep_id[run, u]))))
        act &= ~done
        self._below[done] = 0
        onsets = []
        for run, u in np.argwhere(new):
            a = next(c for c in d._unit_chans[u] if on[run, c])
            onsets.append((int(run), d.hypothesis(d.alarm_channels[a]), int(a), int(u)))
        onsets.sort()
        for run, h, a, u in onsets:
            ep = int(self._n_ep[run])
            self._n_ep[run] += 1
            self._ep_id[run, u] = ep
            self._cur[run, u] = d._unit_hyps[u].index(h)
            si = self._size_idx[a]
            size = None if si is None else float(pool[run, si])
            out.append(((run, 1, h, a), Event(run, self._k, t, h, float(v[run, a]), "onset", size, ep)))
        act |= new
        out.sort(key=lambda x: x[0])
        return [e for _, e in out]

    def _plan(self, key: tuple[str, ...]) -> tuple:
        """Column indices of one sample layout (cached per tuple of channel names)."""
        lookup = {n: i for i, n in enumerate(key)}
        if len(lookup) != len(key):
            raise DataError(f"sample {self._k} names a channel twice: {list(key)}")
        for n in self.input_names:
            if n not in lookup:
                raise DataError(f"sample {self._k} lacks channel {n!r}; it has {list(key)}")
        sel = np.array([lookup[n] for n in self.input_names], np.intp)
        gen_idx = [(np.array([lookup[n] for n in g.u_names], np.intp),
                    np.array([lookup[n] for n in g.y_names], np.intp),
                    np.array([lookup[n] for n in (*g.u_names, *g.y_names)], np.intp))
                   for g in self.generators]
        if len(self._plans) > 64:  # a stream whose layout keeps changing: do not grow without bound
            self._plans.clear()
        self._plans[key] = (sel, gen_idx)
        return sel, gen_idx

    def _hold(self, reason: str, t: float | None = None):
        """Skip a bad sample: components keep their state, outputs repeat the last good ones."""
        self.last_invalid = reason
        self.last_status = STATUS_NAMES[_CANNOT]
        self._held += 1
        if self._last is None:
            R = np.zeros((self._runs, len(self.residual_names)))
            S = np.zeros((self._runs, len(self.stat_names)))
        else:
            R, S = self._last
        self._k += 1
        if t is not None:
            self._t_prev = t
            self._held_t += 1
        return R.copy(), S.copy(), []

    def stream(self, signals: Signals) -> MonitorResult:
        """Run the streaming path over a record (for tests and follow mode).

        The record's rate is checked as in :meth:`run` (a record sampled at another period than
        the generators' is refused); its steps are taken as they come.
        """
        dt = self._record_dt(signals.t)
        self.reset(signals.runs)
        if self._dt is None and dt is not None:
            self._set_dt(dt)
        R = np.empty((signals.runs, signals.n_samples, len(self.residual_names)))
        S = np.empty((signals.runs, signals.n_samples, len(self.stat_names)))
        events: list[Event] = []
        cleared: list[Event] = []
        changes: list[Event] = []
        valid = np.ones((signals.runs, signals.n_samples), bool)
        status = np.zeros((signals.runs, signals.n_samples), np.int8)
        invalid: list[tuple[int, int, str]] = []
        gaps: list[Gap] = []
        for k, t in enumerate(signals.t):
            r, s, ev = self.step(float(t), signals.values[:, k], signals.names)
            R[:, k], S[:, k] = r, s
            for e in ev:
                (cleared if e.kind == "cleared" else changes if e.kind == "change" else events).append(e)
            status[:, k] = STATUS_NAMES.index(self.last_status)
            if self.last_invalid is not None:
                valid[:, k] = False
                invalid.append((0, k, self.last_invalid))
            if self.last_gap is not None:
                gaps.extend(self.last_gap._replace(run=run) for run in range(signals.runs))
        events.sort(key=_event_key)
        cleared.sort(key=_event_key)
        return MonitorResult(Signals(signals.t, R, self.residual_names, check=False),
                             Signals(signals.t, S, self.stat_names, check=False), events, valid, invalid,
                             status, gaps, cleared, changes)
