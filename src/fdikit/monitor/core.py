"""Shared runtime interfaces: residual generators, residual processors and the Monitor.

Every stage works in two forms that must give identical numbers:

* **batch**: ``run(signals) -> Signals`` over a whole record, vectorised over runs (and over
  time where the algorithm allows);
* **streaming**: ``reset(runs)`` then ``step(...)`` once per sample, for live data.

A :class:`ResidualGenerator` consumes named input channels ``u`` (known inputs) and ``y``
(measurements) and produces named residual channels (and, for reconstructors, fault
estimates). A :class:`ResidualProcessor` consumes named residual channels and produces test
statistics, probabilities or alarms. The :class:`Monitor` chains generators, processors and a
decision rule, and applies one policy to bad data in batch, gridded and follow mode:

* a sample that is NaN/inf, absurdly large (``max_abs``) or implausible (:class:`Plausibility`)
  is *invalid*: flagged with a reason, never fed to any component (the state is held);
* a time step longer than ``max_gap`` is a *gap* of ``n_missing`` samples: flagged, and the
  state is held exactly as if ``n_missing`` invalid samples had arrived;
* after a gap or a run of invalid samples the monitor *cannot judge* and re-enters *warm-up*:
  no announcement until the gap's transient is over, then every processor restarts from its
  initial state;
* announcements are *episodes* (:class:`Decision`): one onset per fault episode, one cleared
  event when it is over.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, dataclass, field
from itertools import pairwise
from typing import Any, ClassVar, NamedTuple

import numpy as np

from ..base.stage import ResidualGenerator, ResidualProcessor, _as_batch, _plain_step
from ..base.state import load_state, save_state
from ..errors import DataError
from ..signals import Signals, check_finite
from .plausibility import Plausibility, PlausibilityChecker

__all__ = [
    "STATUS_NAMES",
    "Decision",
    "Event",
    "Gap",
    "Monitor",
    "MonitorResult",
    "ResidualGenerator",
    "ResidualProcessor",
]

#: Per-sample status codes of :attr:`MonitorResult.status`: ``STATUS_NAMES[code]``.
#: ``"ok"``: judged; ``"cannot_judge"``: the sample was invalid and held; ``"warmup"``: processed
#: but not judged (after a gap or held samples, or at the start when ``warmup`` is given).
STATUS_NAMES: tuple[str, ...] = ("ok", "cannot_judge", "warmup")
_OK, _CANNOT, _WARM = 0, 1, 2

#: Relative tolerance on sample intervals: a step within ``1 %`` of ``dt`` (plus the float64
#: resolution of the time stamps, ``8 eps |t|``) is a regular step.
JITTER_TOL = 0.01

#: Longest default warm-up (s) when it comes from a filter's settling time (see Monitor).
MAX_DEFAULT_WARMUP = 10.0


@dataclass(frozen=True)
class Event:
    """An event of a fault episode.

    ``kind == "onset"``: at time ``t`` (sample ``k``, the row of the record) of run ``run``,
    ``hypothesis`` was announced, with the alarm channel's ``value`` and, where the decision has
    a size channel for it, the estimated fault ``size``. ``kind == "cleared"``: the episode
    ``episode`` (numbered from 0 per run, in order of onset) is over. The first five fields keep
    their positions.

    Examples
    --------
    >>> e = Event(0, 12, 0.12, "sensor:pos2", 1.0)
    >>> e.kind, e.size, e.episode
    ('onset', None, 0)
    """

    run: int
    k: int
    t: float
    hypothesis: str
    value: float
    kind: str = "onset"
    size: float | None = None
    episode: int = 0


class Gap(NamedTuple):
    """A time gap: ``n_missing`` samples are missing between ``t_start`` (the last sample before
    it) and ``t_end`` (row ``k``, the first sample after it). A gap concerns every run of the
    record; :attr:`MonitorResult.gaps` lists it once per run.

    Examples
    --------
    >>> g = Gap(0, 9.99, 10.5, 50, 1000)      # 0.51 s between two samples at dt = 0.01 s
    >>> g.n_missing, g.t_end - g.t_start > 0.5
    (50, True)
    """

    run: int
    t_start: float
    t_end: float
    n_missing: int
    k: int


def _event_key(e: Event) -> tuple:
    return (e.run, e.k, 0 if e.kind == "cleared" else 1, e.hypothesis)


@dataclass
class Decision:
    """Turns processor outputs into episodes: one onset per fault episode and a cleared event.

    Each channel in ``alarm_channels`` is an alarm, *on* at a sample where its value is
    ``>= level``. An *onset* is announced at the first judged sample (status ``"ok"``) where the
    alarm is on while no episode of that channel is open; the episode stays open -- re-crossings
    are not announced again -- until the value has stayed below ``clear_level`` for
    ``clear_after`` seconds of judged samples (``max(1, round(clear_after / dt))`` samples in a
    row); a *cleared* event is then given and the alarm re-armed. Samples that are not judged
    (held, warm-up) freeze the rule: nothing is announced or cleared and the count below
    ``clear_level`` neither grows nor restarts. ``clear_after = 0`` gives the rising-edge rule
    (a new onset at every crossing).

    Parameters
    ----------
    alarm_channels : sequence of str
    level : float
    names : dict, optional
        Channel -> the hypothesis it announces (default: the channel name).
    clear_level : float, optional
        ``<= level`` (default ``level``).
    clear_after : float
        Seconds below ``clear_level`` that end an episode (default 1.0).
    size_channels : mapping, optional
        Hypothesis or alarm channel -> a channel holding the estimated fault size; its value at
        the onset sample becomes the onset event's ``size``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> a = np.zeros(300); a[10:20] = 1; a[25:40] = 1          # a flickering alarm, dt = 0.01 s
    >>> s = Signals(np.arange(300) * 0.01, a[:, None], ["alarm"])
    >>> [(e.kind, e.k) for e in Decision(["alarm"], names={"alarm": "f"}).events(s.t, s)]
    [('onset', 10), ('cleared', 139)]
    """

    alarm_channels: Sequence[str]
    level: float = 0.5
    names: dict[str, str] = field(default_factory=dict)
    _: KW_ONLY
    clear_level: float | None = None
    clear_after: float = 1.0
    size_channels: Mapping[str, str] | None = None

    def __post_init__(self):
        if isinstance(self.alarm_channels, str):
            raise DataError(f"decision alarm_channels must be a list of channel names, got "
                            f"{self.alarm_channels!r}")
        self.alarm_channels = [str(c) for c in self.alarm_channels]
        try:
            self.level = float(self.level)
        except (TypeError, ValueError):
            raise DataError(f"decision level must be a number, got {self.level!r}") from None
        if not math.isfinite(self.level):
            raise DataError(f"decision level must be finite, got {self.level}")
        if self.clear_level is not None:
            cl = float(self.clear_level)
            if not (math.isfinite(cl) and cl <= self.level):
                raise DataError(f"decision clear_level ({cl:g}) must be finite and <= level ({self.level:g})")
            self.clear_level = cl
        ca = float(self.clear_after)
        if not (math.isfinite(ca) and ca >= 0):
            raise DataError(f"decision clear_after must be >= 0 seconds, got {self.clear_after!r}")
        self.clear_after = ca
        if self.size_channels is not None:
            self.size_channels = {str(k): str(v) for k, v in dict(self.size_channels).items()}
            known = set(self.alarm_channels) | {self.names.get(c, c) for c in self.alarm_channels}
            bad = [k for k in self.size_channels if k not in known]
            if bad:
                raise DataError(f"decision size_channels name {bad}, which are neither alarm channels nor "
                                f"hypotheses of this decision ({sorted(known)})")

    @property
    def low_level(self) -> float:
        """The level below which an episode counts towards clearing."""
        return self.level if self.clear_level is None else self.clear_level

    def hypothesis(self, channel: str) -> str:
        return self.names.get(channel, channel)

    def size_channel(self, channel: str) -> str | None:
        """The size channel of an alarm channel (by channel name, then by hypothesis), or None."""
        if not self.size_channels:
            return None
        return self.size_channels.get(channel, self.size_channels.get(self.hypothesis(channel)))

    @property
    def channels(self) -> list[str]:
        """Every channel :meth:`events` reads: the alarm channels, then the size channels."""
        sizes = [self.size_channel(c) for c in self.alarm_channels]
        return list(dict.fromkeys([*self.alarm_channels, *(c for c in sizes if c is not None)]))

    def clear_samples(self, dt: float) -> int:
        """``clear_after`` in samples of period ``dt``."""
        return max(1, round(self.clear_after / dt)) if dt > 0 else 1

    def events(self, t: np.ndarray, stats: Signals, *, status: np.ndarray | None = None,
               dt: float | None = None) -> list[Event]:
        """Onsets and cleared events over a record (the same list as the streaming Monitor).

        Parameters
        ----------
        t : array (T,)
        stats : Signals
            Holds the alarm channels (and the size channels).
        status : array (runs, T) of int, optional
            Per-sample status codes (:data:`STATUS_NAMES`); only ``"ok"`` samples are judged.
        dt : float, optional
            Sample period for ``clear_after`` (default: the median interval of ``t``).
        """
        t = np.asarray(t, float)
        idx = stats.index(self.alarm_channels)
        sz = [self.size_channel(c) for c in self.alarm_channels]
        sidx = [None if c is None else stats.index(c)[0] for c in sz]
        if dt is None:
            dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        n_clear = self.clear_samples(dt)
        runs = stats.values.shape[0]
        onsets, cleared = [], []  # (run, k, hypothesis, a, value, size) / (..., onset index)
        for run in range(runs):
            # the judged samples J (None: all of them, no copy through an index)
            J = None
            if status is not None:
                ok = np.asarray(status[run]) == _OK
                if not ok.all():
                    J = np.flatnonzero(ok)
                    if J.size == 0:
                        continue
            V = stats.values[run][:, idx]  # (P, A): the alarm columns only, then the judged rows
            if J is not None:
                V = V[J]
            with np.errstate(invalid="ignore"):
                on = V >= self.level
                low = V < self.low_level
            pos = np.arange(V.shape[0])
            for a, ch in enumerate(self.alarm_channels):
                on_pos = np.flatnonzero(on[:, a])
                if on_pos.size == 0:
                    continue
                # consecutive judged samples below the clear level, ending at each position
                last_not_low = np.maximum.accumulate(np.where(low[:, a], -1, pos))
                hits = np.flatnonzero(pos - last_not_low == n_clear)
                p = -1
                while True:
                    i = np.searchsorted(on_pos, p, "right")
                    if i == on_pos.size:
                        break
                    o = on_pos[i]
                    k = int(o if J is None else J[o])
                    size = None if sidx[a] is None else float(stats.values[run, k, sidx[a]])
                    onsets.append((run, k, self.hypothesis(ch), a, float(V[o, a]), size))
                    j = np.searchsorted(hits, o, "right")
                    if j == hits.size:
                        break
                    c = hits[j]
                    kc = int(c if J is None else J[c])
                    cleared.append((run, kc, self.hypothesis(ch), a, float(V[c, a]), len(onsets) - 1))
                    p = c
        order = sorted(range(len(onsets)), key=lambda i: onsets[i][:4])
        episode = {}
        count: dict[int, int] = {}
        out = []
        for i in order:
            run, k, h, a, v, size = onsets[i]
            episode[i] = count.get(run, 0)
            count[run] = episode[i] + 1
            out.append(((run, k, 1, h, a), Event(run, k, float(t[k]), h, v, "onset", size, episode[i])))
        for run, k, h, a, v, i in cleared:
            out.append(((run, k, 0, h, a), Event(run, k, float(t[k]), h, v, "cleared", None, episode[i])))
        out.sort(key=lambda x: x[0])
        return [e for _, e in out]


@dataclass
class MonitorResult:
    """What a Monitor run produced: residuals, statistics, events and the status of every sample."""

    residuals: Signals
    statistics: Signals
    #: onsets (announcements), one per fault episode
    events: list[Event]
    #: (runs, T) True where the sample was processed; False where it was held (bad input)
    valid: np.ndarray | None = None
    #: (run, sample, reason) of every held sample
    invalid: list[tuple[int, int, str]] = field(default_factory=list)
    #: (runs, T) status code of every sample: ``STATUS_NAMES[code]``
    status: np.ndarray | None = None
    #: every time gap (per run)
    gaps: list[Gap] = field(default_factory=list)
    #: cleared events (the end of each closed episode)
    cleared: list[Event] = field(default_factory=list)

    STATUS_NAMES: ClassVar[tuple[str, ...]] = STATUS_NAMES

    @property
    def episodes(self) -> list[tuple[Event, Event | None]]:
        """``(onset, cleared)`` per episode; ``cleared`` is None for an episode still open."""
        end = {(e.run, e.episode): e for e in self.cleared}
        return [(e, end.get((e.run, e.episode))) for e in self.events]

    def first_event(self, run: int = 0) -> Event | None:
        ev = [e for e in self.events if e.run == run]
        return ev[0] if ev else None


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


class Monitor:
    """A chain: residual generators -> residual processors -> decision, with one bad-data policy.

    Parameters
    ----------
    generators : sequence of ResidualGenerator
        Their outputs are concatenated (names must be unique).
    processors : sequence of ResidualProcessor
        Each reads named residual channels (and outputs of earlier processors).
    decision : Decision, optional
        Episode rule over the processors' outputs (or the generators', e.g. a generator that
        computes probabilities and announcements itself).
    validate : bool
        Check every incoming sample: NaN/inf, ``max_abs``, ``plausibility`` (and time for
        monotonicity). Gaps are detected either way.
    on_invalid : {"raise", "hold"}
        What an invalid sample does: ``"raise"`` a :class:`DataError` naming the channel and
        sample, or ``"hold"``: the sample is flagged invalid with a reason, every component keeps
        its state (nothing non-finite or implausible enters a filter or a probability), the
        previous residuals and statistics are repeated, and processing resumes with the next good
        sample. ``"hold"`` is for recorded or live data of one run (a bad sample of any run holds
        every run).
    plausibility : mapping channel -> Plausibility, optional
        Range, rate and spike rules per input channel (:mod:`fdikit.monitor.plausibility`).
    dt : float, optional
        Expected sample period (s). Default: the generators' (a ``dt`` attribute, or their
        design's ``dt``); else the record's median interval (batch), or the first interval
        (streaming).
    max_gap : float, optional
        A time step longer than this (s) is a gap (default ``1.5 * dt``); it must exceed ``dt``.
        A gap of step ``s`` stands for ``max(1, round(s / dt) - 1)`` missing samples.
    warmup : float, optional
        Warm-up length (s), counted in samples (``round(warmup / dt)``); given, it is fixed and
        also applies at the start of a record; ``0``: no warm-up. Default (``None``): after a
        gap or held samples only, at most the generators' settling time -- a ``settling_time``
        attribute, or for linear filters the 0.1 % settling time of the residual's free response
        ``C A^k`` (the residual transient of the stale state a gap leaves decays by a factor
        1000), at most :data:`MAX_DEFAULT_WARMUP` = 10 s, ``20 * dt`` for a generator that tells
        neither, the largest over the generators. With a decision it ends earlier once it has
        lasted ten times the number of missing samples and every alarm channel has stayed below
        its clear level for ``clear_after`` (a one-sample dropout, whose transient is small,
        costs about ``clear_after`` of judging; a long gap the full settling time).
    max_abs : float or None
        A value with ``|x| > max_abs`` is invalid whatever the plausibility rules (default
        1e12; ``None`` disables).

    Notes
    -----
    **Gaps.** With ``t_prev`` the time of the previous sample, a step ``t - t_prev > max_gap``
    is a gap: it is reported (:attr:`MonitorResult.gaps`, :attr:`last_gap`) and the state is
    held as if the missing samples had been invalid, so a log with a gap and the same log
    gridded with NaN samples in the gap give the same outputs and events (their row indices
    ``k`` differ by the missing rows). In batch, a record whose steps are not regular -- some
    step differs from ``dt`` by more than ``1 % dt + 8 eps |t|`` without being a gap -- is
    refused with a :class:`DataError` (resample it, e.g. with ``[log].rate``); the streaming
    path steps such a sample as one period.

    **Warm-up.** At the first good sample after a gap or after held samples every component
    with a ``resume(n_held)`` method is told, the status is ``"warmup"`` for the warm-up's
    samples (components run, their state evolves, nothing is announced and no episode is
    cleared), and before the first sample after it every processor is reset to its initial
    state (posteriors back to the prior, windows and counters empty), so no statistic carries
    the gap's transient. Generators keep their state: they were held, and re-converge during
    the warm-up.

    Batch (:meth:`run`) and streaming (:meth:`reset` / :meth:`step`) give identical outputs
    and events.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> from fdikit.detect import Hold
    >>> from fdikit.model import LinearFaultModel
    >>> from fdikit.residuals import ObserverResidual, design_observer_residual
    >>> m = LinearFaultModel([[0.9]], [[1.0]], [[1.0]], dt=0.1, inputs=["u"], outputs=["y"])
    >>> gen = ObserverResidual(design_observer_residual(m, method="poles", poles=[0.5]))
    >>> mon = Monitor([gen], [Hold(["r:y"], 0.5)], Decision(["r:y:alarm"]), on_invalid="hold")
    >>> t = np.arange(60) * 0.1
    >>> y = np.zeros(60); y[40:] = 2.0; y[10] = 1e300            # a spike, then a bias
    >>> res = mon.run(Signals(t, np.column_stack([np.zeros(60), y]), ["u", "y"]))
    >>> res.invalid[0][2]
    "channel 'y' at sample 10 (t = 1 s): 1e+300 exceeds the absurd-magnitude limit 1e+12 (max_abs)"
    >>> [(e.kind, e.k) for e in res.events], STATUS_NAMES[res.status[0, 11]]
    ([('onset', 40)], 'warmup')
    """

    def __init__(
        self,
        generators: Sequence[ResidualGenerator],
        processors: Sequence[ResidualProcessor] = (),
        decision: Decision | None = None,
        *,
        validate: bool = True,
        on_invalid: str = "raise",
        plausibility: Mapping[str, Plausibility] | None = None,
        dt: float | None = None,
        max_gap: float | None = None,
        warmup: float | None = None,
        max_abs: float | None = 1e12,
    ):
        # tuples: the channel plan and the per-sample entry points below are built from these
        # stages, so a stage swapped in place would run in batch but not in streaming; a changed
        # chain is a new Monitor
        self.generators = tuple(generators)
        self.processors = tuple(processors)
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
            sizes = [decision.size_channel(c) for c in decision.alarm_channels]
            missing = sorted({s for s in sizes if s is not None and s not in col})
            if missing:
                raise DataError(f"decision size channels {missing} are not produced by the monitor; it "
                                f"produces {self._pool_names}")
            self._size_idx = [None if s is None else col[s] for s in sizes]
        self._proc_idx = [np.array([col[n] for n in p.input_names], np.intp) for p in self.processors]
        starts = np.cumsum([len(self.residual_names)] + [len(p.output_names) for p in self.processors])
        self._proc_out = [slice(int(a), int(b)) for a, b in pairwise(starts)]
        self.input_names = sorted({n for g in self.generators for n in (*g.u_names, *g.y_names)})
        # ---- bad-data policy
        self.dt = _positive(dt, "dt")
        self.max_gap = _positive(max_gap, "max_gap")
        self.warmup = _positive(warmup, "warmup", allow_zero=True)
        if max_abs is not None:
            max_abs = _positive(max_abs, "max_abs")
        self.max_abs = max_abs
        plaus = dict(plausibility or {})
        bad = [k for k in plaus if k not in self.input_names]
        if bad:
            raise DataError(f"plausibility rules for {bad}, which are not input channels of the monitor; "
                            f"its inputs are {self.input_names}")
        for k, p in plaus.items():
            if not isinstance(p, Plausibility):
                raise DataError(f"plausibility rule for channel {k!r} must be a Plausibility, got "
                                f"{type(p).__name__} (use Plausibility.from_mapping for a table)")
        self.plausibility = plaus
        self._checker = PlausibilityChecker(self.input_names, plaus, max_abs) if plaus else None
        self._abs_checker = PlausibilityChecker(self.input_names, {}, max_abs)
        self._abs_limit = math.inf if max_abs is None else max_abs
        dts = {type(g).__name__: _generator_dt(g) for g in self.generators}
        known = [d for d in dts.values() if d is not None]
        if known and max(known) - min(known) > 1e-9 * max(known):
            raise DataError(f"the generators disagree on the sample time: {dts}; give Monitor(dt=...)")
        self._gen_dt = known[0] if known else None
        self._settle: dict[float, float] = {}
        self._plans: dict[tuple[str, ...], tuple] = {}
        # per-sample entry points: the sample reaching a stage is already a checked (runs, n) float
        # array, so a stage's own step arithmetic is called without re-checking shapes -- unless
        # the class overrides the public step (then that is what it means by a step)
        self._gen_steps = [(g._step_joined, True) if hasattr(g, "_step_joined") else
                           (g._step, False) if _plain_step(g, ResidualGenerator) else (g.step, False)
                           for g in self.generators]
        self._proc_steps = [p._step if _plain_step(p, ResidualProcessor) else p.step for p in self.processors]
        self._resumers = [c for c in (*self.generators, *self.processors) if hasattr(c, "resume")]
        self._runs: int | None = None
        self.last_invalid: str | None = None
        self.last_gap: Gap | None = None
        self.last_status: str | None = None

    # ------------------------------------------------------------------ time policy
    def expected_dt(self) -> float | None:
        """The configured sample period: ``dt`` if given, else the generators' (or None)."""
        return self.dt if self.dt is not None else self._gen_dt

    def default_warmup(self, dt: float) -> float:
        """The default warm-up (s) at sample period ``dt`` (see the class docstring)."""
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

    def _warm_samples(self, dt: float) -> int:
        w = self.default_warmup(dt) if self.warmup is None else self.warmup
        return round(w / dt)

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
        if n_w and self.processors:
            status[:, :n_w] = _WARM
            parts = [self._processors(Signals(t[a:b], r.values[:, a:b], r.names, check=False))
                     for a, b in ((0, n_w), (n_w, T)) if b > a]
            st_vals = np.concatenate([p.values for p in parts], axis=1)
        else:
            status[:, :n_w] = _WARM
            st_vals = self._processors(r).values
        st = Signals(t, st_vals, self.stat_names, check=False)
        events, cleared = [], []
        if self.decision is not None:
            pool = self._decision_pool(r, st)
            for e in self.decision.events(t, pool, status=status, dt=dt if dt else 1.0):
                (cleared if e.kind == "cleared" else events).append(e)
        return MonitorResult(r, st, events, np.ones((signals.runs, T), bool), [], status, [], cleared)

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
        A = len(self.decision.alarm_channels) if self.decision is not None else 0
        self._active = np.zeros((self._runs, A), bool)
        self._below = np.zeros((self._runs, A), np.int64)
        self._ep_id = np.zeros((self._runs, A), np.int64)
        self._n_ep = np.zeros(self._runs, np.int64)
        self._abs_checker.reset(self._runs, self._dt)
        if self._checker is not None:
            self._checker.reset(self._runs, self._dt)

    def _set_dt(self, dt: float | None) -> None:
        """Fix the sample period of this record (and what follows from it)."""
        self._dt = dt
        if dt is None:
            self._n_warm, self._n_clear, self._limit = 0, 1, math.inf
            self._warm_left, self._reset_due, self._warm_min, self._quiet = 0, False, 0, -1
            return
        self._limit = self._gap_limit(dt)
        self._n_warm = self._warm_samples(dt)
        self._n_clear = self.decision.clear_samples(dt) if self.decision is not None else 1
        # an explicit warm-up also covers the start of the record
        start = self._n_warm if self.warmup else 0
        self._warm_left, self._reset_due = start, start > 0
        self._warm_min, self._quiet = 0, -1  # -1: a fixed warm-up (no early end)
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
            if not m <= self._abs_limit:
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
        if not (on.any() or act.any()):
            return []
        low = v < d.low_level
        self._below = np.where(act & low, self._below + 1, 0)
        done = act & (self._below >= self._n_clear)
        new = on & ~act
        if not (done.any() or new.any()):
            return []
        out = []
        for run, a in np.argwhere(done):
            ch = d.alarm_channels[a]
            out.append(((int(run), 0, d.hypothesis(ch), int(a)),
                        Event(int(run), self._k, t, d.hypothesis(ch), float(v[run, a]), "cleared", None,
                              int(self._ep_id[run, a]))))
        act &= ~done
        self._below[done] = 0
        onsets = sorted((int(run), d.hypothesis(d.alarm_channels[a]), int(a)) for run, a in np.argwhere(new))
        for run, h, a in onsets:
            ep = int(self._n_ep[run])
            self._n_ep[run] += 1
            self._ep_id[run, a] = ep
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

    # ------------------------------------------------------------------ checkpoint / restore
    def state(self) -> dict[str, Any]:
        """The streaming state of the whole chain (plain data; see :meth:`restore`)."""
        if self._runs is None:  # nothing stepped yet: the initial state of one run
            self.reset(1)
        return {
            "k": self._k,
            "t_prev": self._t_prev,
            "held": self._held,
            "held_t": self._held_t,
            "missing": self._missing,
            "dt": self._dt,
            "warm_left": self._warm_left,
            "reset_due": self._reset_due,
            "warm_min": self._warm_min,
            "quiet": self._quiet,
            "episodes": {"active": self._active.copy(), "below": self._below.copy(),
                         "id": self._ep_id.copy(), "count": self._n_ep.copy()},
            "plausibility": None if self._checker is None else self._checker.state(),
            "runs": self._runs,
            "generators": [g.get_state() for g in self.generators],
            "processors": [p.get_state() for p in self.processors],
            "last": None if self._last is None else [a.copy() for a in self._last],
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
        if (state.get("plausibility") is None) != (self._checker is None):
            raise DataError("checkpoint and monitor differ in their plausibility rules")
        self.reset(int(state["runs"]))
        for g, s in zip(self.generators, state["generators"]):
            g.set_state(s)
        for p, s in zip(self.processors, state["processors"]):
            p.set_state(s)
        self._k, self._t_prev = int(state["k"]), state["t_prev"]
        if "dt" in state:
            self._set_dt(state["dt"])
            self._warm_left, self._reset_due = int(state["warm_left"]), bool(state["reset_due"])
            self._warm_min, self._quiet = int(state["warm_min"]), int(state["quiet"])
        self._held = int(state.get("held", 0))
        self._held_t = int(state.get("held_t", self._held))
        self._missing = int(state.get("missing", 0))
        A = self._active.shape[1]
        ep = state.get("episodes")
        if ep is not None:
            self._active = np.array(ep["active"], bool).reshape(self._runs, A)
            self._below = np.array(ep["below"], np.int64).reshape(self._runs, A)
            self._ep_id = np.array(ep["id"], np.int64).reshape(self._runs, A)
            self._n_ep = np.array(ep["count"], np.int64).reshape(self._runs)
        elif state.get("on") is not None:  # a checkpoint of the rising-edge rule: open = on
            self._active = np.array(state["on"], bool).reshape(self._runs, A)
        if self._checker is not None:
            self._checker.restore(state["plausibility"])
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
        valid = np.ones((signals.runs, signals.n_samples), bool)
        status = np.zeros((signals.runs, signals.n_samples), np.int8)
        invalid: list[tuple[int, int, str]] = []
        gaps: list[Gap] = []
        for k, t in enumerate(signals.t):
            r, s, ev = self.step(float(t), signals.values[:, k], signals.names)
            R[:, k], S[:, k] = r, s
            for e in ev:
                (cleared if e.kind == "cleared" else events).append(e)
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
                             status, gaps, cleared)
