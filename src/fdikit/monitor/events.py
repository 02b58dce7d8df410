"""What a monitor run reports: per-sample status codes, events of fault episodes, time gaps,
and the result of a whole record (:class:`MonitorResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np

from ..signals import Signals

__all__ = ["STATUS_NAMES", "Event", "Gap", "MonitorResult"]

#: ``"ok"``: judged; ``"cannot_judge"``: the sample was invalid and held; ``"warmup"``: processed
#: but not judged (after a gap or held samples, or at the start when ``warmup`` is given).
STATUS_NAMES: tuple[str, ...] = ("ok", "cannot_judge", "warmup")
_OK, _CANNOT, _WARM = 0, 1, 2



@dataclass(frozen=True)
class Event:
    """An event of a fault episode.

    ``kind == "onset"``: at time ``t`` (sample ``k``, the row of the record) of run ``run``,
    ``hypothesis`` was announced, with the alarm channel's ``value`` and, where the decision has
    a size channel for it, the estimated fault ``size``. ``kind == "cleared"``: the episode
    ``episode`` (numbered from 0 per run, in order of onset) is over. ``kind == "change"``: the
    open episode ``episode`` is now announced as ``hypothesis`` (a revised fault type of the same
    component, see :class:`~fdikit.monitor.Decision` ``groups``), which replaces ``previous``.
    The first five fields keep their positions.

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
    previous: str | None = None


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
    #: change events (an open episode announced under a revised name, e.g. its fault type)
    changes: list[Event] = field(default_factory=list)

    STATUS_NAMES: ClassVar[tuple[str, ...]] = STATUS_NAMES

    @property
    def episodes(self) -> list[tuple[Event, Event | None]]:
        """``(onset, cleared)`` per episode; ``cleared`` is None for an episode still open."""
        end = {(e.run, e.episode): e for e in self.cleared}
        return [(e, end.get((e.run, e.episode))) for e in self.events]

    def first_event(self, run: int = 0) -> Event | None:
        ev = [e for e in self.events if e.run == run]
        return ev[0] if ev else None

