"""The Monitor: a chain of residual generators, residual processors and a decision, one bad-data policy.

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

This module builds the chain (:class:`Monitor`); its parts live beside it: the result types in
:mod:`.events`, the episode rule in :mod:`.decision`, the time policy in :mod:`.timing`, the
batch path in :mod:`.batch`, the streaming path in :mod:`.streaming` and checkpoint / restore in
:mod:`.checkpoint`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from itertools import pairwise

import numpy as np

from ..base.stage import ResidualGenerator, ResidualProcessor, _plain_step
from ..errors import DataError

# (the "x as x" imports keep this module's former names importable from here)
from .batch import _BatchPath
from .batch import _own_inputs as _own_inputs
from .checkpoint import _Checkpointing
from .decision import Decision
from .events import _CANNOT as _CANNOT
from .events import _OK as _OK
from .events import _WARM as _WARM
from .events import STATUS_NAMES, Event, Gap, MonitorResult
from .events import _event_key as _event_key
from .plausibility import Plausibility, PlausibilityChecker
from .streaming import _StreamingPath
from .timing import JITTER_TOL as JITTER_TOL
from .timing import MAX_DEFAULT_WARMUP as MAX_DEFAULT_WARMUP
from .timing import _generator_dt, _positive, _TimePolicy
from .timing import _settling_time as _settling_time

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


class Monitor(_BatchPath, _StreamingPath, _Checkpointing, _TimePolicy):
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
        also applies at the start of a record; ``0``: no warm-up. Default (``None``): at the start
        of a record, when there is a decision, the settling time of the generators that tell it
        (:meth:`start_warmup`; none for generators without one), ended early once every alarm
        channel has stayed below its clear level for ``clear_after``, so the filters' start-up
        transient announces nothing; after a gap or held samples, at most the generators' settling
        time -- a ``settling_time``
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
    with a ``resume(n_held)`` method is told. Then, and at the start of a record (a given
    ``warmup``, or by default with a decision the start-up warm-up above), the status is
    ``"warmup"`` for the warm-up's samples (components run, their state evolves, nothing is
    announced and no episode is cleared), and before the first sample after it every processor
    is reset to its initial state (posteriors back to the prior, windows and counters empty), so
    no statistic carries the start-up's or the gap's transient. Generators keep their state:
    they were held (or start from their initial state), and converge during the warm-up.

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

