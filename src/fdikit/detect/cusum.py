"""A two-sided CUSUM on each peer-check residual (:class:`PeerCUSUM`): small persistent shifts of a
member of a redundant group accumulate until they isolate it (issue 27, item 2).

A :class:`~fdikit.detect.PeerCheck` compares each member's low-passed residual with a threshold set
by the largest nominal excursion (for a steering angle: the steering model's slow error), so a
shift below it is never isolated, however long it lasts. The CUSUM of the same residual,
``g+ = max(0, g+ + r - mu - nu)`` and ``g- = max(0, g- - r + mu - nu)`` (Page 1954), grows by
``|shift| - nu`` per sample and isolates a member when ``max(g+, g-)`` over its threshold is the
largest of its group and at least 1; the thresholds come from nominal data
(:func:`design_peer_cusum`). Its outputs merge with the peer check's so a fault-type stage reads
either: ``cusum:m:stat`` is the larger of the two normalised statistics and ``cusum:m:isolated``
is 1 where either isolates ``m``.

A member compared but not announced (a peer only) blocks the isolation while its CUSUM is the
group's largest. Its reference, the median of its peers, moves with a faulty announced member:
by up to ``|c_1| f / 2`` for a shift ``f`` of one of an even number of peers (the mean of the middle
two), ``|c_1| f`` of an odd number (``c_1`` its fitted gain on the median). With the *transfer*
of these bounds (:func:`design_peer_cusum` ``coef``: ``T[a][b]``, the normalised CUSUM of ``b``
per unit of ``a``'s that a large fault on ``a`` can cause, ``|c_1,b| k h_a / h_b``) the group's
largest announced member ``m`` with ``g_m >= 1`` is isolated also when a peer only is larger, if
every peer only ``p`` stays within what ``m``'s fault explains plus what ``p`` reaches without a
fault, its own threshold (``g_p <= T[m][p] g_m + 1``), and ``m`` is beyond what ``p``'s fault
explains (``g_m > T[p][m] g_p``) (issue 27: on the RAV4 the rear axle's yaw rate, the group's
tightest member, rose above a small steering fault's own CUSUM and hid it; its fault-free CUSUM
reaches 1.4 on the held-out half, which the bound without the ``+ 1`` did not allow).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["PeerCUSUM", "design_peer_cusum"]


class PeerCUSUM(ResidualProcessor):
    """A two-sided CUSUM on each member's peer-check residual, merged with the peer check.

    Parameters
    ----------
    groups : mapping str -> sequence of str
        Group -> its members that can be isolated (each reads ``peer:m:r``, ``peer:m`` and
        ``peer:m:isolated`` of a :class:`~fdikit.detect.PeerCheck`).
    mean, nu, thresholds : mapping str -> float
        Member -> nominal mean of its residual, the CUSUM's drift (>= 0) and its threshold (> 0),
        in the residual's unit.
    warmup : int
        Samples at the start (and after :meth:`resume`) during which the CUSUM takes nothing in.
    announce : sequence of str, optional
        Members of the groups that can be isolated (default all): only they read the peer check's
        ``peer:m`` and ``peer:m:isolated`` and have outputs; the others (read ``peer:m:r`` only) take
        part in the group's comparison, so a shift that moves them most isolates no announced member.
    passthrough : sequence of str
        Further members without a CUSUM: their outputs are the peer check's (``cusum:m`` is 0), so
        that a fault-type stage reads every member from this stage.
    transfer : mapping str -> mapping str -> float, optional
        ``transfer[a][b]`` (>= 0): the normalised CUSUM of member ``b`` per unit of ``a``'s that a
        fault on ``a`` can cause (see the module docstring), for every announced ``a`` and peer only
        ``b`` of a group and back (missing pairs: 0). Default none: a peer only that is the group's
        largest always blocks.

    Notes
    -----
    Outputs per member ``m``: ``cusum:m`` (``max(g+, g-)`` over the threshold), ``cusum:m:stat``
    (the larger of it and ``peer:m``) and ``cusum:m:isolated`` (1 where the peer check isolates
    ``m`` or ``m``'s CUSUM is its group's largest and >= 1, or, with ``transfer``, its group's
    largest announced one, >= 1, and every larger peer only explained by ``m``'s fault and its own
    threshold).

    Examples
    --------
    >>> c = PeerCUSUM({"g": ["a", "b"]}, {"a": 0.0, "b": 0.0}, {"a": 0.1, "b": 0.1}, {"a": 1.0, "b": 1.0})
    >>> c.reset(1)
    >>> for _ in range(5):                  # a reads 0.4 high, below the peer check's threshold
    ...     out = c.step([[0.4, 0.4, 0.0, 0.0, 0.0, 0.0]])[0]
    >>> dict(zip(c.output_names, out.round(2).tolist()))["cusum:a:isolated"]
    1.0
    """

    _state_attrs = ("_up", "_lo", "_k")

    def __init__(self, groups: Mapping[str, Sequence[str]], mean: Mapping[str, float],
                 nu: Mapping[str, float], thresholds: Mapping[str, float], *, warmup: int = 0,
                 passthrough: Sequence[str] = (), announce: Sequence[str] | None = None,
                 transfer: Mapping[str, Mapping[str, float]] | None = None):
        if isinstance(groups, str) or not isinstance(groups, Mapping):
            raise DataError(f"PeerCUSUM groups must map a group to its members, got {groups!r}")
        self.groups = {str(g): [str(m) for m in ms] for g, ms in groups.items()}
        self.passthrough = [str(m) for m in passthrough]
        cus = [m for ms in self.groups.values() for m in ms]
        if isinstance(passthrough, str) or set(cus) & set(self.passthrough):
            raise DataError(f"PeerCUSUM passthrough must be a list of members outside the groups, got "
                            f"{passthrough!r}")
        self.members = cus + self.passthrough
        self.announce = list(cus) if announce is None else [str(m) for m in announce]
        bad = [m for m in self.announce if m not in cus]
        if isinstance(announce, str) or bad:
            raise DataError(f"PeerCUSUM announce names {bad or announce!r}, which are not members of "
                            f"its groups")
        self._out = [m for m in self.members if m in self.announce or m in self.passthrough]
        for key, tab in (("mean", mean), ("nu", nu), ("thresholds", thresholds)):
            missing = [m for m in cus if m not in tab]
            if missing:
                raise DataError(f"PeerCUSUM {key} lacks members {missing}")
        self.mean = {m: float(mean[m]) for m in cus}
        self.nu = {m: float(nu[m]) for m in cus}
        self.thresholds = {m: float(thresholds[m]) for m in cus}
        if any(not (np.isfinite(v) and v >= 0) for v in self.nu.values()):
            raise DataError(f"PeerCUSUM nu must be finite and >= 0, got {self.nu}")
        if any(not (np.isfinite(v) and v > 0) for v in self.thresholds.values()):
            raise DataError(f"PeerCUSUM thresholds must be finite and > 0, got {self.thresholds}")
        self.warmup = int(warmup)
        self.input_names = ([f"peer:{m}:r" for m in self.members]
                            + [f"peer:{m}{s}" for s in ("", ":isolated") for m in self._out])
        self.output_names = [f"cusum:{m}{s}" for s in ("", ":stat", ":isolated") for m in self._out]
        self._oix = np.array([self.members.index(m) for m in self._out], np.int64)
        # passthrough members: an infinite threshold keeps their CUSUM statistic at 0
        self._mu = np.array([self.mean.get(m, 0.0) for m in self.members])
        self._nu = np.array([self.nu.get(m, 0.0) for m in self.members])
        self._h = np.array([self.thresholds.get(m, np.inf) for m in self.members])
        self._gidx = [np.array([self.members.index(m) for m in ms], np.int64) for ms in self.groups.values()]
        self.transfer, self._T = _transfer(transfer, cus, self.members)
        ann = set(self.announce)
        # per group: its announced members and its peers only (the transfer rule's candidates and vetoes)
        self._gann = [np.array([self.members.index(m) for m in ms if m in ann], np.int64)
                      for ms in self.groups.values()]
        self._gpeer = [[self.members.index(m) for m in ms if m not in ann] for ms in self.groups.values()]
        self.reset(1)

    def reset(self, runs: int = 1) -> None:
        self._R = int(runs)
        self._up = np.zeros((self._R, len(self.members)))
        self._lo = np.zeros((self._R, len(self.members)))
        self._k = 0

    def resume(self, n_held: int) -> None:
        """After held samples: start again with the warm-up."""
        self.reset(self._R)

    def _step(self, r: np.ndarray) -> np.ndarray:
        if r.shape[0] != self._R:
            raise DataError(f"sample has {r.shape[0]} runs; the PeerCUSUM was reset for {self._R}")
        if not np.all(np.isfinite(r)):
            run, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"PeerCUSUM input {self.input_names[c]!r} is not finite at sample {self._k} "
                            f"(run {run})")
        M, A = len(self.members), len(self._out)
        e, peer, iso_p = r[:, :M], r[:, M:M + A], r[:, M + A:]
        self._k += 1
        if self._k > self.warmup:
            self._up = np.maximum(0.0, self._up + (e - self._mu) - self._nu)
            self._lo = np.maximum(0.0, self._lo - (e - self._mu) - self._nu)
        g = np.maximum(self._up, self._lo) / self._h
        iso = np.zeros_like(g)
        rows = np.arange(self._R)
        for gi, ga, gp in zip(self._gidx, self._gann, self._gpeer, strict=True):
            best = gi[np.argmax(g[:, gi], axis=1)]
            iso[rows, best] = g[rows, best] >= 1.0
            if self._T is not None and ga.size and gp:
                # a peer only is the largest: explained by the largest announced member's fault plus its
                # own fault-free level (up to its threshold, g = 1)
                m = ga[np.argmax(g[:, ga], axis=1)]
                gm = g[rows, m]
                ok = (gm >= 1.0) & np.isin(best, gp)
                for p in gp:
                    ok &= (g[:, p] <= self._T[m, p] * gm + 1.0) & (gm > self._T[p, m] * g[:, p])
                iso[rows, m] = np.maximum(iso[rows, m], ok)
        g, iso = g[:, self._oix], iso[:, self._oix]
        return np.concatenate([g, np.maximum(g, peer), np.maximum(iso, iso_p)], axis=1)

    def __repr__(self) -> str:
        return (f"PeerCUSUM(groups={self.groups}, thresholds={self.thresholds}, warmup={self.warmup}, "
                f"passthrough={self.passthrough}, announce={self.announce}"
                + (f", transfer={self.transfer}" if self.transfer is not None else "") + ")")

    def to_dict(self) -> dict[str, Any]:
        d = {"groups": self.groups, "mean": self.mean, "nu": self.nu, "thresholds": self.thresholds,
             "warmup": self.warmup, "passthrough": self.passthrough, "announce": self.announce}
        if self.transfer is not None:
            d["transfer"] = self.transfer
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PeerCUSUM:
        return cls(d["groups"], d["mean"], d["nu"], d["thresholds"], warmup=d["warmup"],
                   passthrough=d.get("passthrough", ()), announce=d.get("announce"),
                   transfer=d.get("transfer"))


def _transfer(transfer, cus, members):
    """The checked transfer mapping and its (M, M) matrix (None, None without one)."""
    if transfer is None:
        return None, None
    if isinstance(transfer, str) or not isinstance(transfer, Mapping):
        raise DataError(f"PeerCUSUM transfer must map a member to {{member: factor}}, got {transfer!r}")
    bad = [(a, b) for a, row in transfer.items() for b in row if a not in cus or b not in cus or a == b]
    if bad:
        raise DataError(f"PeerCUSUM transfer names pairs {bad} that are not two members of its groups")
    out = {str(a): {str(b): float(v) for b, v in row.items()} for a, row in transfer.items()}
    if any(not (np.isfinite(v) and v >= 0) for row in out.values() for v in row.values()):
        raise DataError(f"PeerCUSUM transfer factors must be finite and >= 0, got {out}")
    T = np.zeros((len(members), len(members)))
    for a, row in out.items():
        for b, v in row.items():
            T[members.index(a), members.index(b)] = v
    return out, T


def design_peer_cusum(nominal: Signals, groups: Mapping[str, Sequence[str]], *, skip: int = 0,
                      nu: float = 1.0, margin: float = 0.5, warmup: int = 0,
                      passthrough: Sequence[str] = (), announce: Sequence[str] | None = None,
                      coef: Mapping[str, Sequence[float]] | None = None) -> PeerCUSUM:
    """A :class:`PeerCUSUM` on nominal (fault-free) :class:`~fdikit.detect.PeerCheck` outputs.

    Per member, from the samples from ``skip`` on: the mean and standard deviation ``s`` of
    ``peer:m:r``; the drift ``nu * s``; the threshold the largest CUSUM statistic reaches on the
    nominal record, times ``1 + margin`` (a short real record gives no tail to fit a per-hour
    target; the margin covers what the record did not show).

    Parameters
    ----------
    nominal : Signals
        PeerCheck outputs on fault-free data (``peer:m:r`` of every member).
    groups : mapping str -> sequence of str
        As :class:`PeerCUSUM`.
    skip : int
        Samples at the start left out.
    nu : float
        Drift in standard deviations of the nominal residual (> 0).
    margin : float
        Threshold margin over the nominal maximum (>= 0).
    warmup, passthrough, announce
        As :class:`PeerCUSUM`.
    coef : mapping str -> sequence of float, optional
        The peer check's coefficients (:class:`~fdikit.detect.PeerCheck` ``coef``: ``c_1``, the gain
        on the peers' median, second): with them the :class:`PeerCUSUM` ``transfer`` between each
        announced member ``a`` and each peer only ``b`` of a group, ``|c_1,b| k h_a / h_b`` (``k``
        1/2 for an even number of peers, 1 for an odd one; ``h`` the thresholds) and back.

    Returns
    -------
    PeerCUSUM
    """
    if not (np.isfinite(nu) and nu > 0 and np.isfinite(margin) and margin >= 0):
        raise DataError(f"design_peer_cusum: nu must be > 0 and margin >= 0, got nu={nu}, margin={margin}")
    members = [m for ms in groups.values() for m in ms]
    mean, drift, thr = {}, {}, {}
    for m in members:
        e = nominal[f"peer:{m}:r"][:, skip:]
        mean[m] = float(e.mean())
        s = float(e.std())
        if not s > 0:
            raise DataError(f"design_peer_cusum: the nominal residual peer:{m}:r is constant")
        drift[m] = nu * s
        up = np.zeros(e.shape[0])
        lo = np.zeros(e.shape[0])
        top = 0.0
        for k in range(e.shape[1]):
            up = np.maximum(0.0, up + e[:, k] - mean[m] - drift[m])
            lo = np.maximum(0.0, lo - e[:, k] + mean[m] - drift[m])
            top = max(top, float(up.max()), float(lo.max()))
        thr[m] = max(top, s) * (1.0 + margin)
    transfer = None
    if coef is not None:
        ann = set(members if announce is None else announce)
        transfer = {}
        for ms in groups.values():
            k = 0.5 if (len(ms) - 1) % 2 == 0 else 1.0     # the median of an even / odd number of peers
            for a in ms:
                for b in ms:
                    if a != b and (a in ann) != (b in ann):
                        if b not in coef or len(coef[b]) < 2:
                            raise DataError(f"design_peer_cusum: coef lacks the peer gain of {b!r}")
                        transfer.setdefault(a, {})[b] = abs(float(coef[b][1])) * k * thr[a] / thr[b]
    return PeerCUSUM(groups, mean, drift, thr, warmup=warmup, passthrough=passthrough, announce=announce,
                     transfer=transfer)
