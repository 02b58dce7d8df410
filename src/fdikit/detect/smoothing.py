"""Temporal integration of a detection statistic: the EWMA of a T² / residual index and its held-out limit.

A fault that is small or slow (on the Tennessee Eastman sets: IDV 11, a random variation of the
reactor cooling water temperature; IDV 21, a stuck valve) raises a T² or residual index only a
little on each sample; a per-sample limit at 1 % misses most of its samples. Integrating the
statistic over time, the exponentially weighted moving average (Roberts 1959; Montgomery,
*Introduction to Statistical Quality Control*, Section 9.2)

    z_k = lam x_k + (1 - lam) z_{k-1},        z_{-1} = start,

averages the noise down while a persistent shift stays, at the price of a detection delay of
the order of ``1 / lam`` samples. Textbook values are ``lam`` = 0.05-0.25; ``start`` is the mean
of the statistic on nominal data (the steady-state start: no warm-up transient).

The smoothed statistic is strongly autocorrelated (an EWMA of white noise has the integrated
autocorrelation time ``(2 - lam) / lam``: 19 samples at ``lam = 0.1``), so the same nominal
records count as far fewer effective samples. :func:`design_ewma` sets the limit at the ``level``
quantile of the smoothed statistic on held-out nominal records
(:func:`~fdikit.detect.held_out_limit`) with an autocorrelation time no smaller than that of the
EWMA of white noise, nor than the spectral estimate ``tau_x var(x) / var(z)`` (an EWMA keeps the
spectral density at zero frequency and divides the variance), and states the interval of its
rate at those effective samples. :func:`choose_lambda` picks ``lam`` from candidates on nominal
and faulty *training* records only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals
from .calibrated_limits import _tau, held_out_limit, predictive_interval

__all__ = ["EWMA", "EWMADesign", "choose_lambda", "design_ewma", "ewma", "ewma_tau"]


@njit(cache=True)
def _ewma_kernel(x, lam, state, out):  # pragma: no cover - compiled
    """x (runs, T, m); state (runs, m) updated in place; out (runs, T, m)."""
    c = 1.0 - lam
    for i in range(x.shape[0]):
        for k in range(x.shape[1]):
            for j in range(x.shape[2]):
                s = lam * x[i, k, j] + c * state[i, j]
                state[i, j] = s
                out[i, k, j] = s


def _check_lam(lam: Any) -> float:
    lam = float(lam)
    if not 0.0 < lam <= 1.0:
        raise DataError(f"the EWMA constant lam must lie in (0, 1], got {lam}")
    return lam


def ewma_tau(lam: float) -> float:
    """Integrated autocorrelation time ``(2 - lam) / lam`` of the EWMA of white noise (samples).

    Examples
    --------
    >>> round(ewma_tau(0.1), 9), ewma_tau(1.0)
    (19.0, 1.0)
    """
    lam = _check_lam(lam)
    return (2.0 - lam) / lam


def ewma(x: Any, lam: float, start: Any = 0.0) -> np.ndarray:
    """EWMA ``z_k = lam x_k + (1 - lam) z_{k-1}``, ``z_{-1} = start``, along the first axis.

    Parameters
    ----------
    x : array_like (T,) or (T, m)
        The statistic (finite).
    lam : float
        In (0, 1]; 1 returns ``x``.
    start : float or array_like (m,)
        The value before the first sample (the nominal mean of the statistic).

    Returns
    -------
    ndarray, the shape of ``x``

    Examples
    --------
    >>> ewma([1.0, 1.0, 1.0], 0.5).tolist()
    [0.5, 0.75, 0.875]
    """
    lam = _check_lam(lam)
    a = np.asarray(x, dtype=float)
    if a.ndim not in (1, 2):
        raise DataError(f"ewma: x must be (T,) or (T, m), got shape {a.shape}")
    v = a.reshape(a.shape[0], -1)
    bad = ~np.isfinite(v)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise DataError(f"ewma: x is not finite at sample {k}, column {c} ({v[k, c]})")
    state = np.broadcast_to(np.asarray(start, dtype=float), (v.shape[1],)).reshape(1, -1).copy()
    out = np.empty((1, *v.shape))
    _ewma_kernel(np.ascontiguousarray(v[None]), lam, state, out)
    return out[0].reshape(a.shape)


class EWMA(ResidualProcessor):
    """EWMA of each input channel (a T², Q or combined index): temporal integration for slow faults.

    ``z_k = lam x_k + (1 - lam) z_{k-1}`` from ``z_{-1} = start`` (Montgomery, Section 9.2, on a
    scalar statistic). Batch and streaming run one compiled loop and give identical numbers.

    Parameters
    ----------
    inputs : str or sequence of str
        The statistics to smooth.
    lam : float
        Smoothing constant in (0, 1] (0.1: memory of about 10 samples).
    start : float or sequence of float
        Value before the first sample, one for all channels or one per channel (the nominal mean;
        :attr:`EWMADesign.start`).

    Notes
    -----
    Outputs ``"<input>:ewma"``. A non-finite sample is refused with a :class:`DataError` naming
    the channel, before the state changes. Alarms: a :class:`~fdikit.detect.Hold` on the outputs
    with ``absolute=False`` and the limit of :func:`design_ewma`.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> s = Signals(np.arange(4.0), [[1.0], [1.0], [5.0], [5.0]], ["T2"])
    >>> e = EWMA("T2", lam=0.5, start=1.0)
    >>> e.run(s)["T2:ewma"].tolist()
    [[1.0, 1.0, 3.0, 4.0]]
    >>> e.reset(1)
    >>> [float(e.step([v])[0, 0]) for v in (1.0, 1.0, 5.0, 5.0)]
    [1.0, 1.0, 3.0, 4.0]
    """

    _state_attrs = ("_z",)

    def __init__(self, inputs: str | Sequence[str], lam: float = 0.1, start: Any = 0.0):
        if isinstance(inputs, str):
            inputs = [inputs]
        self.input_names = [str(s) for s in inputs]
        if not self.input_names:
            raise DataError("EWMA needs at least one input channel")
        self.lam = _check_lam(lam)
        st = np.asarray(start, dtype=float).ravel()
        if st.size not in (1, len(self.input_names)) or not np.all(np.isfinite(st)):
            raise DataError(f"EWMA: start must be one finite number or one per channel "
                            f"{self.input_names}, got {st.tolist()}")
        self.start = np.broadcast_to(st, (len(self.input_names),)).copy()
        self.output_names = [f"{s}:ewma" for s in self.input_names]
        self.reset(1)

    def __repr__(self) -> str:
        return f"EWMA({self.input_names!r}, lam={self.lam}, start={self.start.tolist()})"

    def to_dict(self) -> dict[str, Any]:
        """Configuration as plain data (a design artifact)."""
        return {"inputs": list(self.input_names), "lam": self.lam, "start": self.start.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EWMA:
        """Rebuild from :meth:`to_dict`."""
        return cls(d["inputs"], d["lam"], d["start"])

    def reset(self, runs: int = 1) -> None:
        """Every run back at ``start``."""
        self._z = np.repeat(self.start[None], runs, axis=0)

    def _step(self, r: np.ndarray) -> np.ndarray:
        if r.shape[0] != self._z.shape[0]:
            raise DataError(f"sample has {r.shape[0]} runs; the EWMA was reset for {self._z.shape[0]}")
        if not np.isfinite(r).all():       # refused before the state changes
            i, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"EWMA: input channel {self.input_names[c]!r} is not finite ({r[i, c]}) "
                            f"in run {i}; the state is unchanged")
        out = np.empty((r.shape[0], 1, r.shape[1]))
        _ewma_kernel(np.ascontiguousarray(r[:, None]), self.lam, self._z, out)
        return out[:, 0]

    def run(self, signals: Signals) -> Signals:
        """The smoothed channels over a whole record (every run from ``start``)."""
        r = signals.values[:, :, signals.index(self.input_names)]
        if not np.isfinite(r).all():
            i, k, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"EWMA: input channel {self.input_names[c]!r} is not finite ({r[i, k, c]}) "
                            f"in run {i}, sample {k}")
        self.reset(signals.runs)
        out = np.empty(r.shape)
        _ewma_kernel(np.ascontiguousarray(r), self.lam, self._z, out)
        return Signals(signals.t, out, self.output_names, check=False)


@dataclass
class EWMADesign:
    """An EWMA and its limit set on held-out nominal records (:func:`design_ewma`).

    Attributes
    ----------
    lam, start : float
        The smoothing constant and the value before the first sample.
    limit : float
        Alarm when the smoothed statistic exceeds it.
    level : float
        Target rate ``1 - level`` per sample.
    interval : list of float
        ``confidence`` interval of the limit's per-sample exceedance probability.
    samples : int
        Held-out samples pooled.
    effective_samples, tau : float
        ``samples / tau``; ``tau`` the autocorrelation time used (samples).
    tau_estimated, tau_white, tau_spectral : float
        The three values whose largest is ``tau``: of the smoothed records, of the EWMA of white
        noise, and ``tau_x var(x) / var(z)``.
    supported : bool
        ``(1 - level) effective_samples >= 1``.
    confidence : float
    """

    lam: float
    start: float
    limit: float
    level: float
    interval: list
    samples: int
    effective_samples: float
    tau: float
    tau_estimated: float
    tau_white: float
    tau_spectral: float
    supported: bool
    confidence: float = 0.95

    def processor(self, inputs: str | Sequence[str]) -> EWMA:
        """The :class:`EWMA` of this design on the channel(s) ``inputs``."""
        return EWMA(inputs, self.lam, self.start)

    def smooth(self, x: Any) -> np.ndarray:
        """The smoothed statistic of one record ``x`` (T,), from :attr:`start`."""
        return ewma(x, self.lam, self.start)

    def predictive(self, samples: int) -> list[float]:
        """Interval (``confidence``) of the rate a new nominal record of ``samples`` measures
        (:func:`~fdikit.detect.predictive_interval`)."""
        return predictive_interval(self.level, self.effective_samples, self.tau, samples, self.confidence)

    def to_dict(self) -> dict[str, Any]:
        """Plain data."""
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EWMADesign:
        """Rebuild from :meth:`to_dict`."""
        return cls(**d)


def _scalar_records(nominal: Any, what: str) -> list[np.ndarray]:
    recs = nominal if isinstance(nominal, (list, tuple)) else [nominal]
    out = []
    for i, r in enumerate(recs):
        a = np.asarray(r, dtype=float)
        if a.ndim != 1:
            raise DataError(f"{what} record {i} must be a scalar statistic (T,), got shape {a.shape}")
        out.append(a)
    return out


def design_ewma(nominal: Any, lam: float = 0.1, level: float = 0.99, *, confidence: float = 0.95,
                warmup: int = 0, start: float | None = None) -> EWMADesign:
    """The EWMA of a scalar statistic and its ``level`` limit, set on held-out nominal records.

    Parameters
    ----------
    nominal : array_like (T,) or list of (T_i,) arrays
        The statistic (e.g. T² of a model fitted on OTHER data) on nominal records.
    lam : float
        EWMA constant in (0, 1].
    level : float
        The target rate is ``1 - level`` per sample.
    confidence : float
        Of the stated interval.
    warmup : int
        Samples of every record smoothed but not pooled (the statistic's own warm-up).
    start : float, optional
        Value before the first sample (default: the mean of the statistic over the pooled
        samples).

    Returns
    -------
    EWMADesign

    Raises
    ------
    DataError
        A record that is not 1-D, non-finite values (record and sample named), no sample after
        the warm-up.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).chisquare(3, 40000)          # a T² of 3 channels, nominal
    >>> d = design_ewma(x[:20000], lam=0.1)
    >>> round(d.start, 1), d.tau >= ewma_tau(0.1)
    (3.0, True)
    >>> rate = float(np.mean(d.smooth(x[20000:]) > d.limit))     # fresh nominal data
    >>> lo, hi = d.predictive(20000)
    >>> bool(lo <= rate <= hi)
    True
    """
    lam = _check_lam(lam)
    recs = _scalar_records(nominal, "nominal")
    w = int(warmup)
    for i, r in enumerate(recs):
        if not np.all(np.isfinite(r)):
            raise DataError(f"nominal statistic is not finite in record {i}, sample "
                            f"{int(np.flatnonzero(~np.isfinite(r))[0])}")
    raw = [r[w:] for r in recs if r.size > w]
    if not raw:
        raise DataError(f"no nominal samples after the warm-up of {w} samples per record")
    x0 = float(np.mean(np.concatenate(raw))) if start is None else float(start)
    sm = [ewma(r, lam, x0)[w:] for r in recs if r.size > w]
    allx, allz = np.concatenate(raw), np.concatenate(sm)
    t_white = ewma_tau(lam)
    vz = float(np.var(allz))
    t_spec = _tau(raw) * float(np.var(allx)) / vz if vz > 0 else t_white
    probe = held_out_limit(sm, level, confidence=confidence)
    d = held_out_limit(sm, level, confidence=confidence, min_tau=max(t_white, t_spec))
    return EWMADesign(lam, x0, d["limit"], float(level), d["interval"], d["samples"], d["effective_samples"],
                      d["tau"], probe["tau"], t_white, t_spec, d["supported"], float(confidence))


def choose_lambda(nominal: Any, faulty: Any, candidates: Sequence[float] = (0.05, 0.1, 0.2, 0.3, 1.0),
                  level: float = 0.99, *, warmup: int = 0, tol: float = 0.0) -> tuple[float, dict]:
    """The EWMA constant that misses fewest samples of faulty TRAINING records at a held-out limit.

    For each candidate, :func:`design_ewma` on ``nominal``, then the missed-detection rate (the
    fraction of samples at or below the limit) of every faulty record, averaged. The smallest mean
    wins; ties (within ``tol``) go to the largest ``lam`` (the shortest memory and delay). Use
    training records only: choosing on the test records would tune the detector to them.

    Parameters
    ----------
    nominal : array_like (T,) or list of (T_i,)
        The statistic on held-out nominal records.
    faulty : list of (T_i,) arrays
        The statistic on faulty training records (every sample faulty).
    candidates : sequence of float
        Values of ``lam`` in (0, 1].
    level : float
        Of the limits.
    warmup : int
        See :func:`design_ewma` (also left out of the faulty records).
    tol : float
        Means within ``tol`` of the smallest count as ties (default 0: exact ties only). The
        faulty records carry no delay cost beyond their first samples, so a wide ``tol`` is the
        way to prefer a shorter memory.

    Returns
    -------
    lam : float
    table : dict
        ``lam -> {"mean_missed": ..., "limit": ..., "effective_samples": ...}``.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> nominal = rng.chisquare(3, 5000)
    >>> faulty = [rng.noncentral_chisquare(3, 1.5, 500) for _ in range(3)]   # a small shift
    >>> lam, table = choose_lambda(nominal, faulty)
    >>> lam < 1.0 and table[lam]["mean_missed"] < table[1.0]["mean_missed"]
    True
    """
    fr = _scalar_records(faulty, "faulty")
    if not fr or not candidates:
        raise DataError("choose_lambda needs faulty training records and candidate values of lam")
    table = {}
    for lam in candidates:
        d = design_ewma(nominal, lam, level, warmup=warmup)
        miss = [float(np.mean(d.smooth(r)[warmup:] <= d.limit)) for r in fr if r.size > warmup]
        table[float(lam)] = {"mean_missed": float(np.mean(miss)), "limit": d.limit,
                             "effective_samples": d.effective_samples}
    best = min(v["mean_missed"] for v in table.values())
    lam = max(k for k, v in table.items() if v["mean_missed"] <= best + tol)
    return lam, table
