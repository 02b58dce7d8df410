"""Peer checks of redundant sensors: each member of a redundant group against a reference built
from its peers (issue 27, item 1).

A system declares *redundant groups*: signals that measure, after the system's own conversion, the
same quantity (the four wheel speeds; the yaw rate and the yaw rates that the accelerometer, the
steering model and the wheels say). Each member ``m`` of a group is compared with the mean of
the other members and the group's reference signals, with an affine map fitted on nominal data::

    e_m = x_m - (c_0 + c_1 median_{j != m} x_j + sum_k d_k ref_k + sum_l g_l rate_l)

``rate_l`` is the rate of change of a *rate channel* (``rates``), estimated causally as a first-order
high-pass over the sample time: ``z_k = z_(k-1) + a (x_k - z_(k-1))`` (``a = 1 - exp(-2 pi
rate_hz dt)``, ``z_0 = x_0``), ``rate_k = (x_k - z_k) a / ((1 - a) dt)``, exact on a ramp. It follows
effects proportional to an acceleration: a wheel's longitudinal slip under braking and traction
moves its speed by about ``a U``, the rate of ``U^2 / 2``, which an affine map of the speed does not
follow (on the RAV4's real minute, a front wheel's residual against its peers otherwise keeps a
slope of 0.014-0.022 per m/s of speed through the held-out half's braking: the size of a 1-2 %
gain).

The residual is low-passed (first order, ``band_hz``) and divided by its threshold, designed from
the nominal residual (:func:`~fdikit.detect.design_threshold`); the member whose normalised
residual is the largest of its group, and at least 1, is *isolated*. A fault of size ``f`` on one
member moves its own residual by ``f``; the peers' references are medians (of at least 3 peers),
which one faulty member does not move once it is outside their spread: the faulty member is the
largest; no side is ever inferred from a sign.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["PeerCheck", "design_peer_check"]


class PeerCheck(ResidualProcessor):
    """Each member of each redundant group checked against its peers.

    Parameters
    ----------
    groups : mapping str -> sequence of str
        Group name -> its member channels (at least 2 each; a channel belongs to one group).
    coef : mapping str -> sequence of float
        Member -> ``[c_0, c_1, d_1, ..., d_K, g_1, ..., g_L]`` (offset, gain on the peers' median,
        one per reference, one per rate channel).
    thresholds : mapping str -> float
        Member -> threshold of its low-passed residual (its unit), > 0.
    dt : float
        Sample time (s).
    references : mapping str -> sequence of str, optional
        Group -> reference channels (default none).
    rates : mapping str -> sequence of str, optional
        Group -> channels whose rate of change (see the module docstring) is an affine term too,
        after the references (default none).
    rate_hz : float
        Cut-off of the rate estimate's first-order filter (Hz, > 0).
    band_hz : float or mapping str -> float
        Cut-off of the first-order residual low-pass (Hz), per group or one for all.
    announce : sequence of str, optional
        Members that can be isolated (default all; the others only serve as peers).
    warmup : int
        Samples at the start (and after :meth:`resume`) during which nothing is isolated.
    prefix : str
        Prefix of the output names (default ``"peer"``): two checks of the same members, e.g. one
        for detection and one, with more terms, for a fault-type stage, need different ones.

    Notes
    -----
    Outputs, per member ``m``: ``peer:m`` (the absolute low-passed residual over the
    threshold), ``peer:m:r`` (the low-passed residual, signed, in the member's unit),
    ``peer:m:ref`` (the reference the peers give, ``x_m - e_m``: what a gain of the member
    scales), ``peer:m:e`` (the unfiltered residual) and, for announced members,
    ``peer:m:isolated`` (1 where ``m`` is its group's largest ``peer:m`` and that is >= 1,
    else 0).

    Examples
    --------
    >>> pc = PeerCheck({"w": ["a", "b", "c"]}, {m: [0.0, 1.0] for m in "abc"}, {m: 0.1 for m in "abc"},
    ...                0.01, band_hz=1000.0)
    >>> pc.reset(1)
    >>> out = pc.step([[1.0, 1.0, 1.6]])[0]        # c reads 0.6 high: e_c = 0.6, e_a = e_b = -0.3
    >>> [round(float(out[pc.output_names.index(f"peer:{m}:isolated")]), 1) for m in "abc"]
    [0.0, 0.0, 1.0]
    """

    _state_attrs = ("_z", "_k", "_zr")

    def __init__(self, groups: Mapping[str, Sequence[str]], coef: Mapping[str, Sequence[float]],
                 thresholds: Mapping[str, float], dt: float, *,
                 references: Mapping[str, Sequence[str]] | None = None,
                 band_hz: float | Mapping[str, float] = 1.0, announce: Sequence[str] | None = None,
                 warmup: int = 0, rates: Mapping[str, Sequence[str]] | None = None, rate_hz: float = 0.5,
                 prefix: str = "peer"):
        self.groups = {str(g): [str(m) for m in ms] for g, ms in groups.items()}
        self.references = {g: [str(r) for r in (references or {}).get(g, [])] for g in self.groups}
        self.rates = {g: [str(r) for r in (rates or {}).get(g, [])] for g in self.groups}
        for what, given in (("references", references), ("rates", rates)):
            bad = [g for g in (given or {}) if g not in self.groups]
            if bad:
                raise DataError(f"{what} name unknown groups {bad}; groups: {sorted(self.groups)}")
            if any(isinstance(v, str) for v in (given or {}).values()):
                raise DataError(f"{what} must map groups to lists of channels, got {given!r}")
        self.rate_hz = float(rate_hz)
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise DataError(f"rate_hz must be > 0 (Hz), got {rate_hz!r}")
        members = [m for ms in self.groups.values() for m in ms]
        if len(set(members)) != len(members) or any(len(ms) < 2 for ms in self.groups.values()):
            raise DataError(f"each group needs >= 2 members and a channel may be in one group only: "
                            f"{self.groups}")
        self.members = members
        self.dt = float(dt)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise DataError(f"dt must be > 0, got {dt!r}")
        bh = band_hz if isinstance(band_hz, Mapping) else {g: band_hz for g in self.groups}
        self.band_hz = {g: float(bh[g]) for g in self.groups}
        self.coef = {}
        for g, ms in self.groups.items():
            for m in ms:
                c = np.asarray(coef[m], float)
                n_c = 2 + len(self.references[g]) + len(self.rates[g])
                if c.shape != (n_c,) or not np.all(np.isfinite(c)):
                    raise DataError(f"member {m!r}: coef must be {n_c} finite numbers (c_0, c_1, one per "
                                    f"reference, one per rate channel), got {coef[m]!r}")
                self.coef[m] = [float(v) for v in c]
        self.thresholds = {m: float(thresholds[m]) for m in members}
        if any(not (np.isfinite(h) and h > 0) for h in self.thresholds.values()):
            raise DataError(f"thresholds must be finite and > 0, got {self.thresholds}")
        self.announce = list(members if announce is None else [str(a) for a in announce])
        if set(self.announce) - set(members):
            raise DataError(f"announce names {sorted(set(self.announce) - set(members))}, not members")
        if isinstance(warmup, bool) or int(warmup) != warmup or warmup < 0:
            raise DataError(f"warmup must be an integer >= 0 (samples), got {warmup!r}")
        self.warmup = int(warmup)
        self.prefix = str(prefix)
        if not self.prefix or ":" in self.prefix:
            raise DataError(f"prefix must be a non-empty name without ':', got {prefix!r}")
        refs = [r for g in self.groups for r in self.references[g] + self.rates[g] if r not in members]
        self.input_names = members + list(dict.fromkeys(refs))
        #: the rate channels (each filtered once), in input order
        self.rate_channels = [n for n in self.input_names
                              if any(n in self.rates[g] for g in self.groups)]
        P = self.prefix
        self.output_names = ([f"{P}:{m}" for m in members] + [f"{P}:{m}:r" for m in members]
                             + [f"{P}:{m}:ref" for m in members] + [f"{P}:{m}:e" for m in members]
                             + [f"{P}:{m}:isolated" for m in self.announce])
        self._build()
        self.reset(1)

    def _build(self) -> None:
        """e = x[m] - c_1 median(x[peers]) - x[refs] d - c_0, per member."""
        ix = {n: i for i, n in enumerate(self.input_names)}
        self._self = np.array([ix[m] for m in self.members], np.int64)
        self._peers = [np.array([ix[p] for p in ms if p != m], np.int64)
                       for ms in self.groups.values() for m in ms]
        self._refs = [np.array([ix[r] for r in self.references[g]], np.int64)
                      for g, ms in self.groups.items() for _m in ms]
        self._rate_in = np.array([ix[r] for r in self.rate_channels], np.int64)
        self._rates = [np.array([self.rate_channels.index(r) for r in self.rates[g]], np.int64)
                       for g, ms in self.groups.items() for _m in ms]
        self._a_rate = 1.0 - np.exp(-2.0 * np.pi * self.rate_hz * self.dt)
        self._g_rate = self._a_rate / ((1.0 - self._a_rate) * self.dt)
        self._c = [np.asarray(self.coef[m], float) for m in self.members]
        self._alpha = np.array([1.0 - np.exp(-2.0 * np.pi * self.band_hz[g] * self.dt)
                                for g, ms in self.groups.items() for _m in ms])
        self._h = np.array([self.thresholds[m] for m in self.members])
        self._gidx = [[self.members.index(m) for m in ms] for ms in self.groups.values()]
        self._ann = np.array([self.members.index(m) for m in self.announce], np.int64)
        self._xidx = self._self

    def residuals(self, x: np.ndarray, rate: np.ndarray | None = None) -> np.ndarray:
        """The unfiltered residuals e (..., M) of inputs x (..., n_in) and the rates (..., L) of the
        rate channels (:meth:`rate_estimates`; required when the check has rate channels)."""
        if self.rate_channels and rate is None:
            raise DataError(f"PeerCheck.residuals needs the rates of {self.rate_channels}")
        out = np.empty((*x.shape[:-1], len(self.members)))
        for j in range(len(self.members)):
            c = self._c[j]
            e = x[..., self._self[j]] - c[0] - c[1] * np.median(x[..., self._peers[j]], axis=-1)
            nr = len(self._refs[j])
            for r, d in zip(self._refs[j], c[2:2 + nr], strict=True):
                e = e - d * x[..., r]
            for r, d in zip(self._rates[j], c[2 + nr:], strict=True):
                e = e - d * rate[..., r]
            out[..., j] = e
        return out

    def rate_estimates(self, x: np.ndarray) -> np.ndarray:
        """The rates (R, T, L) of the rate channels over a record of inputs x (R, T, n_in), from the
        filter's start (the same numbers as step by step)."""
        return self._rate_filter(x)[0]

    def _rate_filter(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rates (R, T, L), the filter's last state (R, L)) over inputs x (R, T, n_in)."""
        xr = x[..., self._rate_in]
        z = np.empty_like(xr)
        zk = np.zeros((xr.shape[0], xr.shape[2]))
        if xr.shape[1]:
            zk = xr[:, 0].copy()
            z[:, 0] = zk
            for k in range(1, xr.shape[1]):
                zk = zk + self._a_rate * (xr[:, k] - zk)
                z[:, k] = zk
        return (xr - z) * self._g_rate, zk

    def reset(self, runs: int = 1) -> None:
        self._R = int(runs)
        self._z = np.zeros((self._R, len(self.members)))
        self._zr = np.zeros((self._R, len(self.rate_channels)))
        self._k = 0

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state of :meth:`get_state`; one saved before the rate channels (no ``_zr``) is
        accepted by a check without them."""
        if isinstance(state, dict) and "_zr" not in state and not self.rate_channels and "_z" in state:
            state = {**state, "_zr": np.zeros((np.shape(state["_z"])[0], 0))}
        super().set_state(state)

    def resume(self, n_held: int) -> None:
        """After held samples: start again with the warm-up."""
        self.reset(self._R)

    def _step(self, r: np.ndarray) -> np.ndarray:
        if r.shape[0] != self._R:
            raise DataError(f"sample has {r.shape[0]} runs; the PeerCheck was reset for {self._R}")
        if not np.all(np.isfinite(r)):
            run, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"PeerCheck input {self.input_names[c]!r} is not finite at sample {self._k} "
                            f"(run {run})")
        xr = r[:, self._rate_in]
        if self._k == 0:
            self._zr = xr.copy()      # the rate filter starts at the first sample (rate 0)
        else:
            self._zr = self._zr + self._a_rate * (xr - self._zr)
        e = self.residuals(r, (xr - self._zr) * self._g_rate)
        if self._k == 0:
            self._z = e.copy()        # the low-pass starts at the first residual
        else:
            self._z = self._z + self._alpha * (e - self._z)
        self._k += 1
        stat = np.abs(self._z) / self._h
        iso = np.zeros_like(stat)
        if self._k > self.warmup:
            for gi in self._gidx:
                best = np.argmax(stat[:, gi], axis=1)
                top = stat[np.arange(self._R), np.asarray(gi)[best]]
                iso[np.arange(self._R), np.asarray(gi)[best]] = top >= 1.0
        else:
            stat = np.zeros_like(stat)
        return np.concatenate([stat, self._z, r[:, self._xidx] - e, e, iso[:, self._ann]], axis=1)

    def run(self, signals: Signals) -> Signals:
        """The outputs over a whole record: the residuals vectorised, the low-pass a loop over the
        samples (the same numbers as :meth:`step`)."""
        r = signals.values[:, :, signals.index(self.input_names)]
        if not np.all(np.isfinite(r)) or r.shape[1] == 0:
            return super().run(signals)       # the step loop names the sample it refuses
        self.reset(signals.runs)
        R, T = r.shape[:2]
        rate, zr = self._rate_filter(r)
        e = self.residuals(r, rate)
        z = np.empty_like(e)
        zk = e[:, 0].copy()
        z[:, 0] = zk
        for k in range(1, T):
            zk = zk + self._alpha * (e[:, k] - zk)
            z[:, k] = zk
        self._z, self._k = zk.copy(), T
        self._zr = zr.copy()
        stat = np.abs(z) / self._h
        iso = np.zeros_like(stat)
        rr, kk = np.meshgrid(np.arange(R), np.arange(T), indexing="ij")
        for gi in self._gidx:
            g = np.asarray(gi)
            best = g[np.argmax(stat[:, :, g], axis=2)]
            iso[rr, kk, best] = stat[rr, kk, best] >= 1.0
        stat[:, :self.warmup] = 0.0
        iso[:, :self.warmup] = 0.0
        out = np.concatenate([stat, z, r[:, :, self._xidx] - e, e, iso[:, :, self._ann]], axis=2)
        return Signals(signals.t, out, self.output_names, check=False)

    def __repr__(self) -> str:
        rates = f", rates={self.rates}, rate_hz={self.rate_hz:g}" if self.rate_channels else ""
        prefix = f", prefix={self.prefix!r}" if self.prefix != "peer" else ""
        return (f"PeerCheck(groups={self.groups}, references={self.references}{rates}, "
                f"band_hz={self.band_hz}, announce={self.announce}{prefix})")

    def to_dict(self) -> dict[str, Any]:
        return {"groups": self.groups, "coef": self.coef, "thresholds": self.thresholds, "dt": self.dt,
                "references": self.references, "band_hz": self.band_hz, "announce": self.announce,
                "warmup": self.warmup, "rates": self.rates, "rate_hz": self.rate_hz, "prefix": self.prefix}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PeerCheck:
        return cls(d["groups"], d["coef"], d["thresholds"], d["dt"], references=d["references"],
                   band_hz=d["band_hz"], announce=d["announce"], warmup=d["warmup"],
                   rates=d.get("rates"), rate_hz=d.get("rate_hz", 0.5), prefix=d.get("prefix", "peer"))


def design_peer_check(nominal: Signals, groups: Mapping[str, Sequence[str]], *,
                      references: Mapping[str, Sequence[str]] | None = None,
                      band_hz: float | Mapping[str, float] = 1.0, announce: Sequence[str] | None = None,
                      skip: int = 0, warmup: int = 0, pfa: float = 1.0, per: str | float = "hour",
                      margin: float = 0.0, rates: Mapping[str, Sequence[str]] | None = None,
                      rate_hz: float = 0.5, prefix: str = "peer", fit_hz: float | None = None) -> PeerCheck:
    """A :class:`PeerCheck` fitted and thresholded on nominal (fault-free) data.

    Each member's coefficients are the least-squares fit of the member on the median of its peers,
    the references, the rates of the rate channels and a constant (samples from ``skip`` on; the
    rates estimated causally from the record's start, as the check does); each threshold is the level of the
    member's absolute low-passed nominal residual for ``pfa`` false alarms per ``per``
    (:func:`~fdikit.detect.design_threshold`; on a record too short for the target, the nominal
    maximum scaled by extreme-value growth, as the sensor-fault detectors), times ``1 + margin``.

    Parameters
    ----------
    nominal : Signals
        Fault-free data holding every member and reference channel.
    groups, references, band_hz, announce, warmup, rates, rate_hz, prefix
        As :class:`PeerCheck`.
    fit_hz : float, optional
        Fit the coefficients on the member and its regressors (the peers' median, the references,
        the rates) low-passed alike (first order, this cut-off in Hz, from the record's start): the
        map at the frequencies below it. Where a peer's high-frequency noise is large (a yaw rate
        from wheel-speed differences), the sample-wise fit shrinks the gain on the peers (errors in
        the regressor) and the prediction follows the member's slow changes only in part: a
        residual read in 0.5 s block means (the fault typing's gain test) then keeps a slope on the
        prediction that no fault made. Default: the samples as they are.
    skip : int
        Samples at the start left out of the fit and of the thresholds.
    pfa, per, margin
        The false-alarm target (see :func:`~fdikit.detect.design_threshold`).

    Returns
    -------
    PeerCheck

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> U = 20 + np.cumsum(rng.normal(0, 0.05, 2000))
    >>> x = U[:, None] * [1.0, 1.01, 0.99] + 0.01 * rng.standard_normal((2000, 3))
    >>> nom = Signals(np.arange(2000) * 0.02, x[None], ["a", "b", "c"])
    >>> pc = design_peer_check(nom, {"w": ["a", "b", "c"]})
    >>> f = x.copy(); f[1000:, 1] *= 0.98                  # b reads 2 % low from 20 s
    >>> out = pc.run(Signals(nom.t, f[None], ["a", "b", "c"]))
    >>> bool(out["peer:b:isolated"][0, 1100] == 1.0), float(out["peer:a:isolated"][0].max())
    (True, 0.0)
    """
    from .sensor.calibrate import _threshold

    refs = {g: list((references or {}).get(g, [])) for g in groups}
    rts = {g: list((rates or {}).get(g, [])) for g in groups}
    dt = float(np.mean(np.diff(nominal.t)))
    # a probe with zero coefficients gives the rate channels' estimates as the check forms them
    probe = PeerCheck(groups, {m: [0.0] * (2 + len(refs[g]) + len(rts[g])) for g, ms in groups.items()
                               for m in ms}, {m: 1.0 for ms in groups.values() for m in ms}, dt,
                      references=refs, band_hz=band_hz, announce=announce, warmup=0, rates=rts,
                      rate_hz=rate_hz)
    rate = probe.rate_estimates(nominal.values[:, :, nominal.index(probe.input_names)])
    if fit_hz is not None and not (np.isfinite(fit_hz) and fit_hz > 0):
        raise DataError(f"fit_hz must be > 0 (Hz) or None, got {fit_hz!r}")
    a_fit = None if fit_hz is None else 1.0 - np.exp(-2.0 * np.pi * float(fit_hz) * dt)

    def col(v):                                        # (R, T) -> the fitted samples, low-passed
        if a_fit is not None:
            v = v.copy()
            for k in range(1, v.shape[1]):
                v[:, k] = v[:, k - 1] + a_fit * (v[:, k] - v[:, k - 1])
        return v[:, skip:].ravel()

    coef: dict[str, list[float]] = {}
    for g, ms in groups.items():
        for m in ms:
            peers = col(np.median([nominal[p] for p in ms if p != m], axis=0))
            X = np.column_stack([col(np.ones_like(nominal[m])), peers]
                                + [col(nominal[r]) for r in refs[g]]
                                + [col(rate[:, :, probe.rate_channels.index(r)]) for r in rts[g]])
            c = np.linalg.lstsq(X, col(nominal[m]), rcond=None)[0]
            coef[m] = [float(v) for v in c]
    probe = PeerCheck(groups, coef, {m: 1.0 for ms in groups.values() for m in ms}, dt,
                      references=refs, band_hz=band_hz, announce=announce, warmup=0, rates=rts,
                      rate_hz=rate_hz)
    out = probe.run(nominal)
    chans = [f"{probe.prefix}:{m}:r" for m in probe.members]
    z = np.abs(out.values[:, skip:][:, :, out.index(chans)])
    thr = _threshold(z, pfa, per, margin, probe.dt, 1, "design_peer_check")
    return PeerCheck(groups, coef, {m: float(v) for m, v in zip(probe.members, thr, strict=True)}, probe.dt,
                     references=refs, band_hz=band_hz, announce=announce, warmup=warmup, rates=rts,
                     rate_hz=rate_hz, prefix=prefix)
