"""The episode rule: :class:`Decision` turns alarm channels into one onset per fault episode and
a cleared event."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, dataclass, field

import numpy as np

from ..errors import DataError
from ..signals import Signals
from .events import _OK, Event

__all__ = ["Decision"]


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

    A cleared event says the fault is *not seen any more* (the records label it so), not that it
    is gone: the rule sees only the alarm, and a fault that persists while its residual decays
    (a constant sensor bias that an observer's state absorbs) ends its episode the same way.

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

