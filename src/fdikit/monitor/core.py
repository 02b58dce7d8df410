"""Shared runtime interfaces: residual generators, residual processors and the Monitor.

Every stage works in two forms that must give identical numbers:

* **batch**: ``run(signals) -> Signals`` over a whole record, vectorised over runs (and over
  time where the algorithm allows);
* **streaming**: ``reset(runs)`` then ``step(...)`` once per sample, for live data.

A :class:`ResidualGenerator` consumes named input channels ``u`` (known inputs) and ``y``
(measurements) and produces named residual channels (and, for reconstructors, fault
estimates). A :class:`ResidualProcessor` consumes named residual channels and produces test
statistics, probabilities or alarms. The :class:`Monitor` chains generators, processors and a
decision rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np

from ..base.stage import ResidualGenerator, ResidualProcessor, _as_batch, _plain_step
from ..base.state import load_state, save_state
from ..errors import DataError
from ..signals import Signals, check_finite

__all__ = [
    "Decision",
    "Event",
    "Monitor",
    "MonitorResult",
    "ResidualGenerator",
    "ResidualProcessor",
]


@dataclass(frozen=True)
class Event:
    """An announcement: at time ``t`` (sample ``k``) of run ``run``, ``hypothesis`` was declared."""

    run: int
    k: int
    t: float
    hypothesis: str
    value: float


@dataclass
class Decision:
    """Turns processor outputs into announcements.

    Each channel in ``alarm_channels`` is an alarm (announced at its first sample with value
    >= ``level``; re-armed when it falls below). ``names`` maps a channel to the hypothesis it
    announces (default: the channel name).
    """

    alarm_channels: Sequence[str]
    level: float = 0.5
    names: dict[str, str] = field(default_factory=dict)

    def events(self, t: np.ndarray, stats: Signals) -> list[Event]:
        idx = stats.index(self.alarm_channels)
        on = stats.values[:, :, idx] >= self.level  # (runs, T, A)
        rising = on.copy()
        rising[:, 1:] &= ~on[:, :-1]
        out = []
        for run, k, a in np.argwhere(rising):
            ch = self.alarm_channels[a]
            out.append(Event(int(run), int(k), float(t[k]), self.names.get(ch, ch),
                             float(stats.values[run, k, idx[a]])))
        out.sort(key=lambda e: (e.run, e.k, e.hypothesis))
        return out


@dataclass
class MonitorResult:
    """What a Monitor run produced: residuals, statistics and events."""

    residuals: Signals
    statistics: Signals
    events: list[Event]
    #: (runs, T) True where the sample was processed; False where it was held (bad input)
    valid: np.ndarray | None = None
    #: (run, sample, reason) of every held sample
    invalid: list[tuple[int, int, str]] = field(default_factory=list)

    def first_event(self, run: int = 0) -> Event | None:
        ev = [e for e in self.events if e.run == run]
        return ev[0] if ev else None


class Monitor:
    """A chain: residual generators -> residual processors -> decision.

    Parameters
    ----------
    generators : sequence of ResidualGenerator
        Their outputs are concatenated (names must be unique).
    processors : sequence of ResidualProcessor
        Each reads named residual channels (and outputs of earlier processors).
    decision : Decision, optional
        Announcement rule over the processors' outputs (or the generators', e.g. a generator that
        computes probabilities and announcements itself).
    validate : bool
        Check every incoming sample for NaN/inf (and time for monotonicity).
    on_invalid : {"raise", "hold"}
        What a bad sample does: ``"raise"`` a :class:`DataError` naming the channel and sample,
        or ``"hold"``: the sample is flagged invalid with a reason, every component keeps its
        state (nothing non-finite enters a filter or a probability), the previous residuals and
        statistics are repeated, and processing resumes with the next good sample. ``"hold"``
        is for recorded or live data of one run (a Monte Carlo batch has no bad samples).
        At the first good sample after held ones, every generator and processor that has a
        ``resume(n_held)`` method is called first: a component whose state went stale over the
        gap (a filter tracking a plant that moved on) can re-enter its warm-up there.

    Batch (:meth:`run`) and streaming (:meth:`reset` / :meth:`step`) give identical outputs.
    """

    def __init__(
        self,
        generators: Sequence[ResidualGenerator],
        processors: Sequence[ResidualProcessor] = (),
        decision: Decision | None = None,
        *,
        validate: bool = True,
        on_invalid: str = "raise",
    ):
        self.generators = list(generators)
        self.processors = list(processors)
        self.decision = decision
        self.validate = validate
        if on_invalid not in ("raise", "hold"):
            raise DataError(f"on_invalid must be 'raise' or 'hold', got {on_invalid!r}")
        self.on_invalid = on_invalid
        self.residual_names = [n for g in self.generators for n in g.output_names]
        if len(set(self.residual_names)) != len(self.residual_names):
            raise DataError(f"residual channel names collide: {self.residual_names}")
        self.stat_names = [n for p in self.processors for n in p.output_names]
        avail = set(self.residual_names)
        for p in self.processors:
            missing = [n for n in p.input_names if n not in avail]
            if missing:
                raise DataError(f"processor {type(p).__name__} needs channels {missing} that no "
                                f"generator or earlier processor produces; have {sorted(avail)}")
            avail |= set(p.output_names)
        # the pool: every channel a stage produces, residuals first, then each processor's outputs
        self._pool_names = [*self.residual_names, *self.stat_names]
        col = {n: i for i, n in enumerate(self._pool_names)}
        if len(col) != len(self._pool_names):
            raise DataError(f"statistic channel names collide with each other or with residuals: "
                            f"{self.stat_names}")
        if decision is not None:
            missing = [c for c in decision.alarm_channels if c not in col]
            if missing:
                raise DataError(f"decision needs channels {missing}; the monitor produces "
                                f"{self._pool_names}")
            self._dec_idx = np.array([col[c] for c in decision.alarm_channels], np.intp)
        self._proc_idx = [np.array([col[n] for n in p.input_names], np.intp) for p in self.processors]
        starts = np.cumsum([len(self.residual_names)] + [len(p.output_names) for p in self.processors])
        self._proc_out = [slice(int(a), int(b)) for a, b in pairwise(starts)]
        self.input_names = sorted({n for g in self.generators for n in (*g.u_names, *g.y_names)})
        self._plans: dict[tuple[str, ...], tuple] = {}
        # per-sample entry points: the sample reaching a stage is already a checked (runs, n) float
        # array, so a stage's own step arithmetic is called without re-checking shapes -- unless
        # the class overrides the public step (then that is what it means by a step)
        self._gen_steps = [(g._step_joined, True) if hasattr(g, "_step_joined") else
                           (g._step, False) if _plain_step(g, ResidualGenerator) else (g.step, False)
                           for g in self.generators]
        self._proc_steps = [p._step if _plain_step(p, ResidualProcessor) else p.step for p in self.processors]
        self._k = 0
        self._t_prev: float | None = None
        self._on: np.ndarray | None = None
        self._held = 0

    # ------------------------------------------------------------------ batch
    def run(self, signals: Signals) -> MonitorResult:
        """Run the whole chain over a record (all runs at once)."""
        if self.validate:
            sel = signals.select(self.input_names).values
            if self.on_invalid == "hold" and not np.all(np.isfinite(sel)):
                return self.stream(signals)  # the streaming path holds state over bad samples
            check_finite(sel, self.input_names)
        res = [g.run(signals) for g in self.generators]
        r = res[0]
        for s in res[1:]:
            r = r.concat_channels(s)
        pool = r
        stats = []
        for p in self.processors:
            s = p.run(pool)
            stats.append(s)
            pool = pool.concat_channels(s)
        st = pool.select(self.stat_names) if self.stat_names else Signals(
            signals.t, np.zeros((signals.runs, signals.n_samples, 0)), [], check=False)
        events = self.decision.events(signals.t, r.concat_channels(st)) if self.decision is not None else []
        return MonitorResult(r, st, events, np.ones((signals.runs, signals.n_samples), bool))

    # ------------------------------------------------------------------ streaming
    def reset(self, runs: int = 1) -> None:
        for g in self.generators:
            g.reset(runs)
        for p in self.processors:
            p.reset(runs)
        self._k = 0
        self._t_prev = None
        self._on = None
        self._held = 0
        self._runs = runs
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.last_invalid: str | None = None

    def step(self, t: float, sample: dict[str, Any] | np.ndarray,
             names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray, list[Event]]:
        """Advance one sample.

        ``sample`` is a mapping channel -> value (scalar or (runs,)) or an array
        ``(runs, len(names))``. Returns residuals ``(runs, R)``, statistics ``(runs, S)`` and the
        events announced at this sample.
        """
        self.last_invalid = None
        if self._t_prev is not None and not t > self._t_prev:
            msg = f"time is not increasing at sample {self._k}: {t} after {self._t_prev}"
            if self.on_invalid == "raise" or not np.isfinite(t):
                raise DataError(msg)
            return self._hold(msg)
        if not np.isfinite(t):
            raise DataError(f"time is not finite at sample {self._k}: {t}")
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
        # (a finite sum of the whole sample proves every input finite; otherwise look closely:
        # a channel the monitor does not read may be NaN, or the sum may have overflowed)
        if self.validate and not math.isfinite(float(vals.sum())):
            bad = ~np.isfinite(vals[:, sel])
            if bad.any():
                run, c = np.argwhere(bad)[0]
                msg = (f"channel {self.input_names[c]!r} has a non-finite value at sample {self._k} "
                       f"(run {run})")
                if self.on_invalid == "raise":
                    raise DataError(msg)
                return self._hold(msg, t)
        if self._held:  # good data again after held samples: components that care are told
            for c in (*self.generators, *self.processors):
                if hasattr(c, "resume"):
                    c.resume(self._held)
            self._held = 0
        pool = np.empty((vals.shape[0], len(self._pool_names)))
        j = 0
        for (fn, joined), (ui, yi, uyi) in zip(self._gen_steps, gen_idx):
            out = fn(vals[:, uyi]) if joined else fn(vals[:, ui], vals[:, yi])
            pool[:, j:j + out.shape[1]] = out
            j += out.shape[1]
        for p, fn_p, idx, sl in zip(self.processors, self._proc_steps, self._proc_idx, self._proc_out):
            r_in = pool[:, idx]
            # processors whose rule depends on time (e.g. TimeGated) take it with the sample
            pool[:, sl] = p.step_at(float(t), r_in) if getattr(p, "needs_time", False) else fn_p(r_in)
        nr = len(self.residual_names)
        r, st = pool[:, :nr], pool[:, nr:]
        events: list[Event] = []
        if self.decision is not None:
            on = pool[:, self._dec_idx] >= self.decision.level
            if self._on is None or on.tobytes() != self._on.tobytes():  # something switched
                new = on if self._on is None else on & ~self._on
                for run, a in np.argwhere(new):
                    ch = self.decision.alarm_channels[a]
                    events.append(Event(int(run), self._k, float(t), self.decision.names.get(ch, ch),
                                        float(pool[run, self._dec_idx[a]])))
                events.sort(key=lambda e: (e.run, e.k, e.hypothesis))
            self._on = on
        self._k += 1
        self._t_prev = t
        self._last = (r, st)
        return r, st, events

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
        self._held += 1
        if self._last is None:
            R = np.zeros((self._runs, len(self.residual_names)))
            S = np.zeros((self._runs, len(self.stat_names)))
        else:
            R, S = self._last
        self._k += 1
        if t is not None:
            self._t_prev = t
        return R.copy(), S.copy(), []

    # ------------------------------------------------------------------ checkpoint / restore
    def state(self) -> dict[str, Any]:
        """The streaming state of the whole chain (plain data; see :meth:`restore`)."""
        return {
            "k": self._k,
            "t_prev": self._t_prev,
            "held": getattr(self, "_held", 0),
            "on": None if self._on is None else self._on.copy(),
            "runs": getattr(self, "_runs", 1),
            "generators": [g.get_state() for g in self.generators],
            "processors": [p.get_state() for p in self.processors],
            "last": None if getattr(self, "_last", None) is None else [a.copy() for a in self._last],
            "channels": {"inputs": list(self.input_names), "residuals": list(self.residual_names),
                         "statistics": list(self.stat_names)},
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a state captured by :meth:`state` on an identically built Monitor."""
        ch = state.get("channels", {})
        mine = {"inputs": list(self.input_names), "residuals": list(self.residual_names),
                "statistics": list(self.stat_names)}
        if ch != mine:
            raise DataError(f"checkpoint is for a monitor with channels {ch}, this one has {mine}")
        if len(state["generators"]) != len(self.generators) or \
                len(state["processors"]) != len(self.processors):
            raise DataError("checkpoint has a different number of generators or processors")
        for g, s in zip(self.generators, state["generators"]):
            g.set_state(s)
        for p, s in zip(self.processors, state["processors"]):
            p.set_state(s)
        self._k, self._t_prev, self._runs = int(state["k"]), state["t_prev"], int(state["runs"])
        self._held = int(state.get("held", 0))
        self._on = None if state["on"] is None else np.array(state["on"], dtype=bool)
        last = state.get("last")
        self._last = None if last is None else (np.array(last[0]), np.array(last[1]))

    def save_checkpoint(self, path) -> None:
        """Write :meth:`state` to ``path`` atomically (temporary file + rename)."""
        save_state(path, self.state(), meta={"kind": "Monitor"})

    def load_checkpoint(self, path) -> None:
        """Restore from a file written by :meth:`save_checkpoint`."""
        state, meta = load_state(path)
        if meta.get("kind") != "Monitor":
            raise DataError(f"{path}: not a Monitor checkpoint (kind {meta.get('kind')!r})")
        self.restore(state)

    def stream(self, signals: Signals) -> MonitorResult:
        """Run the streaming path over a record (for tests and follow mode)."""
        self.reset(signals.runs)
        R = np.empty((signals.runs, signals.n_samples, len(self.residual_names)))
        S = np.empty((signals.runs, signals.n_samples, len(self.stat_names)))
        events: list[Event] = []
        valid = np.ones((signals.runs, signals.n_samples), bool)
        invalid: list[tuple[int, int, str]] = []
        for k, t in enumerate(signals.t):
            r, s, ev = self.step(float(t), signals.values[:, k], signals.names)
            R[:, k], S[:, k] = r, s
            events.extend(ev)
            if self.last_invalid is not None:
                valid[:, k] = False
                invalid.append((0, k, self.last_invalid))
        events.sort(key=lambda e: (e.run, e.k, e.hypothesis))
        return MonitorResult(Signals(signals.t, R, self.residual_names, check=False),
                             Signals(signals.t, S, self.stat_names, check=False), events, valid, invalid)


