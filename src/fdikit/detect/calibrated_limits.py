"""Control limits calibrated on held-out nominal records, with the interval of the rate they give.

The theoretical limits of the data-driven statistics (F distribution for T², Jackson–Mudholkar or
Box for Q: :mod:`fdikit.residuals.datadriven.limits`) assume independent Gaussian samples and a
covariance known exactly. On real process data neither holds: on the Tennessee Eastman sets the
99 % limits of PCA-Q, DPCA-Q and CVA, fitted on ``d00``, alarm on 8-28 % of the nominal test
set ``d00_te``. :func:`calibrate_limits` sets each limit instead at the ``level`` quantile of the
statistic on nominal records **the model did not see** (a later block of the training record, or
other nominal records), and states how sure that is:

* the samples are autocorrelated, so they count as ``n_eff = n / tau`` effective samples (``tau``:
  the integrated autocorrelation time of the exceedance indicator and of the statistic, the
  larger; :func:`fdikit.detect.tail.block_length`, per record);
* the limit is the order statistic of rank ``j = ceil((n + 1) level)`` (split-conformal); the
  exceedance probability of such a limit on a new exchangeable sample is Beta(``n + 1 - j``,
  ``j``) distributed; with ``n_eff`` in place of ``n`` that gives the stated interval
  (``confidence``, central). When ``(1 - level) n_eff < 1`` the records cannot show a rate as
  small as ``1 - level``: the limit is their maximum and the interval says how far that is
  from the target (no extrapolation is claimed).

:func:`fit_calibrated` does both steps on one nominal record: the model on the first part, the
limits on a later block (a gap of a few autocorrelation times between them), or on separate
nominal records given as ``calibration``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from ..errors import DataError
from .tail import block_length

__all__ = ["CalibratedLimits", "calibrate_limits", "fit_calibrated", "held_out_limit", "predictive_interval"]


@dataclass
class CalibratedLimits:
    """Limits set on held-out nominal data and the false-alarm rate they claim.

    Attributes
    ----------
    names : list of str
        The statistics (e.g. ``["T2", "Q"]``).
    limits : ndarray (n_stats,)
        The calibrated limits.
    level : float
        Their confidence level (the target rate is ``1 - level`` per sample and statistic).
    interval : ndarray (n_stats, 2)
        ``confidence`` interval of the per-sample exceedance probability of each limit.
    samples : int
        Held-out samples used (warm-up samples left out).
    effective_samples : ndarray (n_stats,)
        ``samples / tau`` of each statistic.
    theoretical : ndarray (n_stats,) or None
        The generator's theoretical limits at ``level`` (the peers' values), for comparison.
    held_out_rate_theoretical : ndarray (n_stats,) or None
        Rate of the theoretical limits on the same held-out samples.
    supported : ndarray (n_stats,) of bool
        ``(1 - level) n_eff >= 1``: the records hold at least one effective exceedance.
    confidence : float
    records : int
    """

    names: list[str]
    limits: np.ndarray
    level: float
    interval: np.ndarray
    samples: int
    effective_samples: np.ndarray
    theoretical: np.ndarray | None = None
    held_out_rate_theoretical: np.ndarray | None = None
    supported: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    confidence: float = 0.95
    records: int = 1

    def exceed(self, statistics: Any) -> np.ndarray:
        """Alarms ``statistics > limits`` for an array ``(..., n_stats)``."""
        s = np.asarray(statistics, dtype=float)
        if s.shape[-1] != self.limits.size:
            raise DataError(f"statistics have {s.shape[-1]} columns, the limits are for {self.names}")
        return s > self.limits

    def predictive(self, samples: int) -> np.ndarray:
        """Interval (``confidence``) of the rate *measured* on a new nominal record of ``samples``.

        The rate of the limit itself is uncertain (:attr:`interval`), and a finite record adds its
        own binomial noise: with the calibration's autocorrelation time ``tau``, the record counts
        ``samples / tau`` effective samples and its exceedances are beta-binomial.

        Returns
        -------
        ndarray (n_stats, 2)
        """
        return np.array([predictive_interval(self.level, ne, self.samples / ne, samples, self.confidence)
                         for ne in self.effective_samples])

    def to_dict(self) -> dict[str, Any]:
        """Plain data (arrays stay arrays; :mod:`fdikit.base.artifacts`)."""
        return {"names": list(self.names), "limits": self.limits.copy(), "level": self.level,
                "interval": self.interval.copy(), "samples": self.samples,
                "effective_samples": self.effective_samples.copy(),
                "theoretical": None if self.theoretical is None else self.theoretical.copy(),
                "held_out_rate_theoretical": None if self.held_out_rate_theoretical is None
                else self.held_out_rate_theoretical.copy(),
                "supported": self.supported.copy(), "confidence": self.confidence, "records": self.records}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CalibratedLimits:
        """Rebuild from :meth:`to_dict`."""
        def opt(k: str) -> np.ndarray | None:
            return None if d.get(k) is None else np.asarray(d[k], dtype=float)

        return cls(list(d["names"]), np.asarray(d["limits"], float), float(d["level"]),
                   np.asarray(d["interval"], float).reshape(-1, 2), int(d["samples"]),
                   np.asarray(d["effective_samples"], float), opt("theoretical"),
                   opt("held_out_rate_theoretical"), np.asarray(d["supported"], bool),
                   float(d["confidence"]), int(d["records"]))


def _beta_ab(level: float, n_eff: float) -> tuple[float, float]:
    """Beta parameters of the exceedance probability of the rank ``ceil((n + 1) level)`` order
    statistic of ``n_eff`` exchangeable samples: Beta(n + 1 - j, j)."""
    a = max((1.0 - level) * (n_eff + 1.0), 1e-9)
    return a, max(n_eff + 1.0 - a, 1e-9)


def _records(nominal: Any) -> list[np.ndarray]:
    """Nominal data as a list of (T_i, m) arrays (Signals runs, a (runs, T, m) array, or a list)."""
    from ..signals import Signals

    if isinstance(nominal, Signals):
        return list(nominal.values)
    if isinstance(nominal, (list, tuple)):
        out = []
        for i, x in enumerate(nominal):
            if isinstance(x, Signals):
                out += list(x.values)
                continue
            a = np.asarray(x, dtype=float)
            if a.ndim != 2:
                raise DataError(f"nominal record {i} must be (T_i, channels), got shape {a.shape}")
            out.append(a)
        if not out:
            raise DataError("nominal data: an empty list of records")
        return out
    a = np.asarray(nominal, dtype=float)
    if a.ndim == 2:
        return [a]
    if a.ndim == 3:
        return list(a)
    raise DataError(f"nominal data must be (T, m), (runs, T, m) or a list of (T_i, m), got shape {a.shape}")


def _tau(records: list[np.ndarray]) -> float:
    """Integrated autocorrelation time pooled over records (sample-weighted mean of per-record values)."""
    taus, ns = [], []
    for r in records:
        if r.size >= 10 and np.ptp(r) > 0:
            taus.append(float(block_length(r)["tau"]))
            ns.append(r.size)
    if not taus:
        return 1.0
    return float(max(1.0, np.average(taus, weights=ns)))


def held_out_limit(records: Any, level: float, *, confidence: float = 0.95,
                   min_tau: float = 1.0) -> dict[str, Any]:
    """The ``level`` limit of a scalar statistic on held-out nominal records, with its rate's interval.

    Parameters
    ----------
    records : array_like (T,) or list of (T_i,) arrays
        The statistic on nominal samples the model behind it did not see (one record or many).
    level : float
        In (0, 1); the target exceedance rate is ``1 - level``.
    confidence : float
        Of the interval.
    min_tau : float
        Floor of the autocorrelation time (samples): a statistic known to be at least this
        correlated (e.g. an EWMA, :func:`fdikit.detect.design_ewma`) is not credited with more
        effective samples because a short record under-estimates its correlation.

    Returns
    -------
    dict
        ``limit`` (the order statistic of rank ``ceil((n + 1) level)``), ``interval`` (of its
        exceedance probability: Beta(``n_eff + 1 - j``, ``j``) quantiles at ``n_eff`` effective
        samples), ``samples``, ``effective_samples``, ``tau``, ``supported`` (``(1 - level) n_eff >=
        1``: the records hold at least one effective exceedance).

    Examples
    --------
    >>> import numpy as np
    >>> d = held_out_limit(np.random.default_rng(0).standard_normal(20000), 0.99)
    >>> round(d["limit"], 1), [round(v, 4) for v in d["interval"]]
    (2.3, [0.0087, 0.0114])
    """
    level, confidence = float(level), float(confidence)
    if not 0.0 < level < 1.0 or not 0.0 < confidence < 1.0:
        raise DataError(f"level and confidence must lie in (0, 1), got {level} and {confidence}")
    if isinstance(records, (list, tuple)):
        recs = [np.asarray(r, dtype=float).ravel() for r in records]
    else:
        recs = [np.asarray(records, dtype=float).ravel()]
    recs = [r for r in recs if r.size]
    if not recs:
        raise DataError("a held-out limit needs at least one nominal sample")
    for i, r in enumerate(recs):
        if not np.all(np.isfinite(r)):
            raise DataError(f"held-out statistic is not finite in record {i}, sample "
                            f"{int(np.flatnonzero(~np.isfinite(r))[0])}")
    v = np.concatenate(recs)
    n = v.size
    j = min(n, int(np.ceil((n + 1) * level)))          # split-conformal rank
    limit = float(np.sort(v)[j - 1])
    tau = max(_tau(recs), _tau([(r > limit).astype(float) for r in recs]), float(min_tau))
    ne = n / tau
    # exceedance probability of the rank-j order statistic ~ Beta(n + 1 - j, j), at n_eff samples
    a, b = _beta_ab(level, ne)
    alpha = 1.0 - confidence
    iv = [float(stats.beta.ppf(alpha / 2, a, b)), float(stats.beta.ppf(1 - alpha / 2, a, b))]
    return {"limit": limit, "interval": iv, "samples": int(n), "effective_samples": float(ne), "tau": tau,
            "supported": bool((1.0 - level) * ne >= 1.0), "level": level, "confidence": confidence}


def predictive_interval(level: float, effective_samples: float, tau: float, samples: int,
                        confidence: float = 0.95) -> list[float]:
    """Interval of the rate that a new record of ``samples`` measures for a limit from
    :func:`held_out_limit` (beta-binomial: the limit's own uncertainty and the record's noise).

    Examples
    --------
    >>> lo, hi = predictive_interval(0.99, 400.0, 2.0, 960)
    >>> bool(lo < 0.01 < hi)
    True
    """
    m = max(1, round(int(samples) / max(float(tau), 1.0)))
    a, b = _beta_ab(float(level), float(effective_samples))
    d = stats.betabinom(m, a, b)
    alpha = 1.0 - float(confidence)
    return [float(d.ppf(alpha / 2) / m), float(d.ppf(1 - alpha / 2) / m)]


def calibrate_limits(generator: Any, nominal: Any, level: float = 0.99, *, confidence: float = 0.95,
                     warmup: int | None = None) -> CalibratedLimits:
    """Limits of every output of ``generator`` at ``level``, set on held-out nominal records.

    Parameters
    ----------
    generator : residual generator
        Anything with ``run_array(data) -> (runs, T, n_stats)`` and ``output_names`` (e.g.
        :class:`~fdikit.residuals.PCAResidual`, :class:`~fdikit.residuals.CVAResidual`), fitted on
        *other* data; its ``limit(level)`` (if any) is reported beside as the theoretical value.
    nominal : Signals, array_like (T, m) / (runs, T, m), or list of (T_i, m) arrays
        Nominal records the generator did not see.
    level : float
        Confidence level in (0, 1): the target per-sample rate of each limit is ``1 - level``.
    confidence : float
        Of the stated interval of the rate.
    warmup : int, optional
        Samples left out at the start of every record (default: ``generator.warmup_samples``).

    Returns
    -------
    CalibratedLimits

    Raises
    ------
    DataError
        A bad level, no samples after the warm-up, a non-finite statistic (record and sample named).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals import PCAResidual
    >>> rng = np.random.default_rng(1)
    >>> x = rng.standard_normal((6000, 1)) @ np.ones((1, 3)) + 0.3 * rng.standard_normal((6000, 3))
    >>> pca = PCAResidual.fit(x[:2000], n_components=1)
    >>> cal = calibrate_limits(pca, x[2000:4000], 0.99)
    >>> bool(np.all(cal.interval[:, 0] < 0.01) and np.all(0.01 < cal.interval[:, 1]))
    True
    >>> rate = (pca.run_array(x[4000:])[0] > cal.limits).mean(axis=0)      # fresh nominal data
    >>> iv = cal.predictive(2000)                     # what a record of 2000 samples may measure
    >>> bool(np.all((iv[:, 0] <= rate) & (rate <= iv[:, 1])))
    True
    """
    level, confidence = float(level), float(confidence)
    if not 0.0 < level < 1.0 or not 0.0 < confidence < 1.0:
        raise DataError(f"level and confidence must lie in (0, 1), got {level} and {confidence}")
    recs = _records(nominal)
    w = int(getattr(generator, "warmup_samples", 0) if warmup is None else warmup)
    S = []
    for i, x in enumerate(recs):
        s = np.asarray(generator.run_array(x), dtype=float)[0][w:]
        bad = ~np.isfinite(s)
        if bad.any():
            k, c = np.argwhere(bad)[0]
            raise DataError(f"statistic {c} is not finite in nominal record {i}, sample {k + w}")
        if s.shape[0]:
            S.append(s)
    if not S:
        raise DataError(f"no nominal samples after the warm-up of {w} samples per record")
    allS = np.concatenate(S)
    n, n_stats = allS.shape
    names = list(getattr(generator, "output_names", [f"s{i}" for i in range(n_stats)]))
    limits, n_eff = np.empty(n_stats), np.empty(n_stats)
    interval = np.empty((n_stats, 2))
    for c in range(n_stats):
        d = held_out_limit([s[:, c] for s in S], level, confidence=confidence)
        limits[c], n_eff[c], interval[c] = d["limit"], d["effective_samples"], d["interval"]
    theo = rate_theo = None
    if hasattr(generator, "limit"):
        theo = np.asarray(generator.limit(level), dtype=float).reshape(n_stats)
        rate_theo = (allS > theo).mean(axis=0)
    return CalibratedLimits(names, limits, level, interval, int(n), n_eff, theo, rate_theo,
                            (1.0 - level) * n_eff >= 1.0, confidence, len(S))


def fit_calibrated(cls: Any, nominal: Any, *, calibration: Any = None, fraction: float = 0.3,
                   level: float = 0.99, confidence: float = 0.95,
                   **fit_kwargs: Any) -> tuple[Any, CalibratedLimits]:
    """Fit a data-driven generator on one part of the nominal data and calibrate its limits on another.

    Parameters
    ----------
    cls : class
        A generator class with ``fit(data, level=..., **fit_kwargs)`` (e.g.
        :class:`~fdikit.residuals.PCAResidual`, ``DPCAResidual``, ``CVAResidual``).
    nominal : array_like (T, m) or (runs, T, m)
        Nominal training data. Without ``calibration``: one record (T, m), split in time: the model
        on the first ``1 - fraction``, the limits on the last ``fraction`` (its first ``lags``
        samples are the warm-up of the held-out windows, so no window spans both parts).
    calibration : array_like or list of (T_i, m) arrays, optional
        Separate nominal records for the limits (then all of ``nominal`` fits the model).
    fraction : float
        Held-out fraction of the record (when ``calibration`` is None).
    level, confidence : float
        See :func:`calibrate_limits`.
    **fit_kwargs
        Passed to ``cls.fit`` (``n_components``, ``lags``, ``order``, ...).

    Returns
    -------
    generator, CalibratedLimits

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals import PCAResidual
    >>> x = np.random.default_rng(2).standard_normal((3000, 4))
    >>> pca, cal = fit_calibrated(PCAResidual, x, n_components=2)
    >>> cal.samples, pca.n_train
    (900, 2100)
    """
    if calibration is not None:
        gen = cls.fit(nominal, level=level, **fit_kwargs)
        return gen, calibrate_limits(gen, calibration, level, confidence=confidence)
    x = np.asarray(nominal, dtype=float)
    if x.ndim != 2:
        raise DataError("without calibration records, nominal must be ONE record (T, m), got shape "
                        f"{x.shape}")
    if not 0.0 < float(fraction) < 1.0:
        raise DataError(f"fraction must lie in (0, 1), got {fraction}")
    n_cal = round(float(fraction) * x.shape[0])
    if n_cal < 10 or x.shape[0] - n_cal < 10:
        raise DataError(f"a record of {x.shape[0]} samples cannot be split {1 - fraction:.2f} / "
                        f"{fraction:.2f} into a fit part and a held-out block of at least 10 samples each")
    gen = cls.fit(x[:x.shape[0] - n_cal], level=level, **fit_kwargs)
    return gen, calibrate_limits(gen, [x[x.shape[0] - n_cal:]], level, confidence=confidence)
