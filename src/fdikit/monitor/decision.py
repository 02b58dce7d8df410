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

    **One fault name, one episode.** The episode belongs to the announced name, not to the channel:
    channels that announce the same hypothesis (``names``), and the hypotheses that ``groups``
    declares alternatives of one component (e.g. ``{"yaw_rate": ["yaw_rate", "yaw_rate:bias",
    "yaw_rate:gain"]}``: one sensor, its fault type revised as evidence grows), share one episode:
    it opens when the first of their channels goes on and clears when all of them have stayed below
    ``clear_level`` for ``clear_after``. The onset names the hypothesis of the first channel on (in
    the order of ``alarm_channels``). While the episode is open, a *change* event
    (``kind="change"``, ``previous`` the name it replaces, the same ``episode``) is given when another
    hypothesis of the group turns on (its channels were all off at the judged sample before); a
    hypothesis named as its group (the component's own, unspecific name, e.g. ``"yaw_rate"``) may
    open an episode but never replaces a more specific name. The cleared event names the latest
    hypothesis.

    **Isolated by the specific hypotheses** (``confirm_after > 0``). A group's own name is the
    unspecific guess of a test that names the component but not how (e.g. an MHSSPT hypothesis
    ``"yaw_rate"``), while the group's specific hypotheses come from the tests that isolate it
    (``"yaw_rate:bias"`` from a check of the sensor against its peers). With ``confirm_after`` the
    unspecific name waits for that evidence, at most ``confirm_after`` seconds of judged samples
    (``round(confirm_after / dt)``) from its rise: a specific hypothesis of its own group on
    confirms it at once (the onset then names the specific hypothesis), a specific hypothesis of
    another group on drops it until its alarm falls (the other component is announced by its own
    name), and with neither it is announced when the wait ends (``unconfirmed="announce"``) or
    dropped until its alarm falls (``"drop"``: only the isolating tests name a component of a group).
    ``0`` (default): announced at once.

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
    groups : mapping str -> sequence of str, optional
        Component -> the hypotheses that are alternatives of it (one episode, revisions announced
        as changes); a hypothesis belongs to one group at most.
    confirm_after : float
        Seconds a group's own (unspecific) name waits for a specific hypothesis to confirm or
        contradict it (default 0: no wait; see *Isolated by the specific hypotheses*).
    unconfirmed : {"announce", "drop"}
        What a wait that ends with neither does to the unspecific name (default ``"announce"``).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> a = np.zeros(300); a[10:20] = 1; a[25:40] = 1          # a flickering alarm, dt = 0.01 s
    >>> s = Signals(np.arange(300) * 0.01, a[:, None], ["alarm"])
    >>> [(e.kind, e.k) for e in Decision(["alarm"], names={"alarm": "f"}).events(s.t, s)]
    [('onset', 10), ('cleared', 139)]
    >>> b = np.zeros(300); b[50:] = 1                          # the type revised at sample 50
    >>> s2 = Signals(s.t, np.column_stack([a, b]), ["x:bias", "x:gain"])
    >>> d = Decision(["x:bias", "x:gain"], groups={"x": ["x:bias", "x:gain"]})
    >>> [(e.kind, e.hypothesis, e.previous, e.k) for e in d.events(s2.t, s2)]
    [('onset', 'x:bias', None, 10), ('change', 'x:gain', 'x:bias', 50)]
    >>> g = np.zeros(300); g[10:] = 1                          # an unspecific "x" from sample 10,
    >>> y = np.zeros(300); y[30:] = 1                          # the peer check isolates "y" at 30
    >>> s3 = Signals(s.t, np.column_stack([g, y]), ["P:x", "y:bias"])
    >>> d = Decision(["P:x", "y:bias"], names={"P:x": "x"}, groups={"x": ["x"], "y": ["y:bias"]},
    ...              confirm_after=0.5)
    >>> [(e.kind, e.hypothesis, e.k) for e in d.events(s3.t, s3)]
    [('onset', 'y:bias', 30)]
    """

    alarm_channels: Sequence[str]
    level: float = 0.5
    names: dict[str, str] = field(default_factory=dict)
    _: KW_ONLY
    clear_level: float | None = None
    clear_after: float = 1.0
    size_channels: Mapping[str, str] | None = None
    groups: Mapping[str, Sequence[str]] | None = None
    confirm_after: float = 0.0
    unconfirmed: str = "announce"

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
        try:
            cf = float(self.confirm_after)
        except (TypeError, ValueError):
            raise DataError(f"decision confirm_after must be a number of seconds, "
                            f"got {self.confirm_after!r}") from None
        if not (math.isfinite(cf) and cf >= 0):
            raise DataError(f"decision confirm_after must be >= 0 seconds, got {self.confirm_after!r}")
        self.confirm_after = cf
        if self.unconfirmed not in ("announce", "drop"):
            raise DataError(f"decision unconfirmed must be 'announce' or 'drop', got {self.unconfirmed!r}")
        if self.size_channels is not None:
            self.size_channels = {str(k): str(v) for k, v in dict(self.size_channels).items()}
            known = set(self.alarm_channels) | {self.names.get(c, c) for c in self.alarm_channels}
            bad = [k for k in self.size_channels if k not in known]
            if bad:
                raise DataError(f"decision size_channels name {bad}, which are neither alarm channels nor "
                                f"hypotheses of this decision ({sorted(known)})")
        self._build_units()

    def _build_units(self) -> None:
        """The episode units: per unit (a group, or a hypothesis outside every group) its alarm
        channels, and per hypothesis of it the channels that announce it (alarm order)."""
        hyps = list(dict.fromkeys(self.hypothesis(c) for c in self.alarm_channels))
        unit_of = {h: h for h in hyps}
        if self.groups is not None:
            if isinstance(self.groups, str) or not isinstance(self.groups, Mapping):
                raise DataError(f"decision groups must map a component to a list of hypotheses, got "
                                f"{self.groups!r}")
            self.groups = {str(g): [str(h) for h in ([m] if isinstance(m, str) else m)]
                           for g, m in self.groups.items()}
            seen: dict[str, str] = {}
            for g, members in self.groups.items():
                for h in members:
                    if h not in unit_of:
                        raise DataError(f"decision group {g!r} names {h!r}, which is not a hypothesis of "
                                        f"this decision ({hyps})")
                    if h in seen:
                        raise DataError(f"hypothesis {h!r} is in two decision groups: {seen[h]!r} and {g!r}")
                    seen[h] = g
                    unit_of[h] = g
        units = list(dict.fromkeys(unit_of[h] for h in hyps))
        self._unit_names = units
        self._unit_chans = [[a for a, c in enumerate(self.alarm_channels) if unit_of[self.hypothesis(c)] == u]
                            for u in units]
        self._unit_hyps = [list(dict.fromkeys(self.hypothesis(self.alarm_channels[a]) for a in ch))
                           for ch in self._unit_chans]
        self._hyp_chans = [[[a for a in ch if self.hypothesis(self.alarm_channels[a]) == h] for h in hs]
                           for ch, hs in zip(self._unit_chans, self._unit_hyps)]
        self._simple = all(len(ch) == 1 for ch in self._unit_chans)
        self._build_confirm(unit_of)

    def _build_confirm(self, unit_of: dict[str, str]) -> None:
        """The tentative names of ``confirm_after``: per group's own name its channels, the channels
        of its group's specific hypotheses and those of every other group's (alarm indices)."""
        self._tent: list[tuple[list[int], list[int], list[int]]] = []
        if self.confirm_after <= 0 or not self.groups:
            return
        chan_h = [self.hypothesis(c) for c in self.alarm_channels]
        spec = {a: unit_of[h] for a, h in enumerate(chan_h) if h in unit_of and unit_of[h] != h
                and any(h in m for m in self.groups.values())}
        for g in self.groups:
            mine = [a for a, h in enumerate(chan_h) if h == g]
            if mine:
                self._tent.append((mine, [a for a, u in spec.items() if u == g],
                                   [a for a, u in spec.items() if u != g]))
        # the onset names a specific hypothesis before the group's own name when both are on
        self._unit_chans = [sorted(ch, key=lambda a: chan_h[a] == self._unit_names[u])
                            for u, ch in enumerate(self._unit_chans)]

    def confirm_samples(self, dt: float) -> int:
        """``confirm_after`` in samples of period ``dt`` (0: no wait)."""
        return round(self.confirm_after / dt) if dt > 0 and self.confirm_after > 0 else 0

    def _gate(self, on: np.ndarray, low: np.ndarray, n: int) -> None:
        """Apply the wait of ``confirm_after`` (``n`` samples) in place to a record's judged rows
        ``on`` / ``low`` (P, A): the same rule as :meth:`_gate_step` sample by sample."""
        if not self._tent or n <= 0:
            return
        P = on.shape[0]
        for mine, own, other in self._tent:
            raw = on[:, mine].any(axis=1)
            o_own = on[:, own].any(axis=1) if own else np.zeros(P, bool)
            o_oth = on[:, other].any(axis=1) if other else np.zeros(P, bool)
            gate = np.zeros(P, bool)
            edges = np.flatnonzero(np.diff(np.r_[0, raw.astype(np.int8), 0]))
            for s, e in zip(edges[::2], edges[1::2]):
                w = min(s + n, e - 1)
                hit = np.flatnonzero(o_own[s:w + 1] | o_oth[s:w + 1])
                if hit.size:
                    i = s + int(hit[0])
                    if o_own[i]:
                        gate[i:e] = True
                elif s + n < e and self.unconfirmed == "announce":
                    gate[s + n:e] = True
            on[:, mine] &= gate[:, None]
            low[:, mine] |= ~gate[:, None]

    def _gate_step(self, on: np.ndarray, low: np.ndarray, state: np.ndarray, n: int) -> None:
        """One judged sample of the ``confirm_after`` wait (``n`` samples), in place: ``on`` / ``low``
        (runs, A); ``state`` (runs, n_tentative) int64: -1 idle, j >= 0 waited j samples, -2
        announced, -3 dropped until the alarm falls."""
        for i, (mine, own, other) in enumerate(self._tent):
            raw = on[:, mine].any(axis=1)
            o_own = on[:, own].any(axis=1) if own else np.zeros(raw.shape, bool)
            o_oth = on[:, other].any(axis=1) if other else np.zeros(raw.shape, bool)
            prev = state[:, i]
            j = np.where(prev == -1, 0, prev)
            wait = raw & (j >= 0)
            end = -2 if self.unconfirmed == "announce" else -3
            st = np.where(wait & o_own, -2, np.where(wait & o_oth, -3, np.where(
                wait & (j >= n), end, np.where(wait, j + 1, prev))))
            state[:, i] = np.where(raw, st, -1)
            gate = state[:, i] == -2
            on[:, mine] &= gate[:, None]
            low[:, mine] |= ~gate[:, None]

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

    def _rises(self, on: np.ndarray, u: int) -> list[tuple[int, int, int]]:
        """``(position, hypothesis index, its first channel on)`` of every judged sample at which a
        hypothesis of unit u turns on (all its channels off at the judged sample before), in order."""
        out = []
        for hi, chans in enumerate(self._hyp_chans[u]):
            if self._unit_hyps[u][hi] == self._unit_names[u]:
                continue            # the component's own name never replaces a specific one
            on_h = on[:, chans].any(axis=1)
            for q in np.flatnonzero(on_h[1:] & ~on_h[:-1]) + 1:
                out.append((int(q), hi, next(c for c in chans if on[q, c])))
        out.sort()
        return out

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
        onsets, cleared, changes = [], [], []  # (run, k, hypothesis, a, value, size) / (..., onset index)
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
            self._gate(on, low, self.confirm_samples(dt))
            pos = np.arange(V.shape[0])
            for u, chans in enumerate(self._unit_chans):
                if len(chans) == 1:
                    on_u, low_u = on[:, chans[0]], low[:, chans[0]]
                else:
                    on_u, low_u = on[:, chans].any(axis=1), low[:, chans].all(axis=1)
                on_pos = np.flatnonzero(on_u)
                if on_pos.size == 0:
                    continue
                # consecutive judged samples below the clear level, ending at each position
                last_not_low = np.maximum.accumulate(np.where(low_u, -1, pos))
                hits = np.flatnonzero(pos - last_not_low == n_clear)
                rises = self._rises(on, u) if len(self._unit_hyps[u]) > 1 else None
                p = -1
                while True:
                    i = np.searchsorted(on_pos, p, "right")
                    if i == on_pos.size:
                        break
                    o = on_pos[i]
                    a = next(c for c in chans if on[o, c])
                    k = int(o if J is None else J[o])
                    h = self.hypothesis(self.alarm_channels[a])
                    size = None if sidx[a] is None else float(stats.values[run, k, sidx[a]])
                    onsets.append((run, k, h, a, float(V[o, a]), size))
                    j = np.searchsorted(hits, o, "right")
                    end = hits[j] if j < hits.size else V.shape[0]
                    if rises is not None:
                        for q, hi, ac in rises:
                            if o < q < end and self._unit_hyps[u][hi] != h:
                                kq = int(q if J is None else J[q])
                                sz = None if sidx[ac] is None else float(stats.values[run, kq, sidx[ac]])
                                changes.append((run, kq, self._unit_hyps[u][hi], ac, float(V[q, ac]), sz, h,
                                                len(onsets) - 1))
                                h = self._unit_hyps[u][hi]
                    if j == hits.size:
                        break
                    c = hits[j]
                    kc = int(c if J is None else J[c])
                    ac = self._hyp_chans[u][self._unit_hyps[u].index(h)][0]
                    cleared.append((run, kc, h, ac, float(V[c, ac]), len(onsets) - 1))
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
        for run, k, h, a, v, size, prev, i in changes:
            ev = Event(run, k, float(t[k]), h, v, "change", size, episode[i], prev)
            out.append(((run, k, 2, h, a), ev))
        out.sort(key=lambda x: x[0])
        return [e for _, e in out]

