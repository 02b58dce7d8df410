"""Measured false-alarm rates with their confidence intervals, and the verdict of a claimed rate
against a measured one.

A claim (what a design states about its false alarms) and a measurement (what nominal data show)
are both a rate with an interval; :func:`verdict` says whether the measurement's interval meets
the claim's (``"inside"``), lies wholly above it (``"above"``: more false alarms than claimed) or
wholly below (``"below"``: fewer; the design is conservative or its interval too narrow).

:func:`measure_alarm_rate` measures an alarm indicator over nominal records in the units of a
target (:func:`~fdikit.detect.design_threshold`'s ``per``):

``"sample"``
    the fraction of alarmed samples; Clopper-Pearson interval on the *effective* samples
    ``n / tau`` (``tau`` the integrated autocorrelation time of the indicator, so a correlated
    record is not taken for ``n`` independent samples);
``"run"``
    the fraction of records (runs) with at least one alarm; Clopper-Pearson over the records;
a duration in seconds, or ``"second"``, ``"minute"``, ``"hour"``, ``"day"``
    alarm onsets (episodes, 0 -> 1 transitions) per that much time; exact Poisson (Garwood)
    interval of the onset count over the exposure.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import DataError
from .threshold_design import TIME_UNITS

__all__ = ["VERDICTS", "measure_alarm_rate", "per_seconds", "poisson_interval", "proportion_interval",
           "verdict"]

#: The verdicts of :func:`verdict`.
VERDICTS = ("inside", "above", "below")


def per_seconds(per: str | float) -> float | None:
    """Seconds of a per-time target (``"hour"`` -> 3600, a number -> itself); None for ``"sample"``
    and ``"run"``.

    Examples
    --------
    >>> per_seconds("hour"), per_seconds(60.0), per_seconds("sample")
    (3600.0, 60.0, None)
    """
    if isinstance(per, str):
        if per in ("sample", "run"):
            return None
        if per not in TIME_UNITS:
            raise DataError(f"per must be 'sample', 'run', a duration in s or one of {list(TIME_UNITS)}, "
                            f"got {per!r}")
        return float(TIME_UNITS[per])
    u = float(per)
    if not (u > 0 and np.isfinite(u)):
        raise DataError(f"a per-time rate needs a positive duration in s, got per = {per!r}")
    return u


def poisson_interval(k: float, exposure: float, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson rate: ``k`` events in ``exposure`` units.

    Examples
    --------
    >>> lo, hi = poisson_interval(0, 1.0)
    >>> lo, round(hi, 3)                 # no event in one hour: at most 3.689 an hour
    (0.0, 3.689)
    """
    from scipy.stats import chi2

    if not exposure > 0:
        raise DataError(f"a rate needs a positive exposure, got {exposure}")
    a = (1.0 - level) / 2.0
    lo = 0.0 if k <= 0 else float(chi2.ppf(a, 2.0 * k)) / 2.0
    hi = float(chi2.ppf(1.0 - a, 2.0 * k + 2.0)) / 2.0
    return lo / exposure, hi / exposure


def proportion_interval(k: float, n: float, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson interval of a proportion ``k / n``; ``k`` and ``n`` may be effective
    (non-integer) counts.

    Examples
    --------
    >>> lo, hi = proportion_interval(0, 300)
    >>> lo, round(hi, 4)
    (0.0, 0.0122)
    """
    from scipy.stats import beta

    if not n > 0:
        raise DataError(f"a proportion needs n > 0 samples, got {n}")
    a = (1.0 - level) / 2.0
    lo = 0.0 if k <= 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k >= n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def _records(alarm) -> list[np.ndarray]:
    if isinstance(alarm, np.ndarray) and alarm.ndim == 2:
        return [np.asarray(a) for a in alarm]
    if isinstance(alarm, np.ndarray) and alarm.ndim == 1:
        return [alarm]
    if isinstance(alarm, Sequence):
        out = [np.asarray(a) for a in alarm]
        for i, a in enumerate(out):
            if a.ndim != 1:
                raise DataError(f"alarm record {i} must be 1-D (samples,), got shape {a.shape}")
        return out
    raise DataError(f"alarm must be an array (T,), (records, T) or a list of 1-D records, got "
                    f"{type(alarm).__name__}")


def measure_alarm_rate(alarm, per: str | float, dt: float, *, level: float = 0.95) -> dict:
    """The rate of an alarm indicator over nominal records, in the units of ``per``, with its
    interval (see the module docstring).

    Parameters
    ----------
    alarm : array (T,), (records, T) or list of 1-D arrays
        True (or > 0.5) where the alarm is on; NaN marks a sample that was not judged (warm-up,
        held): it is left out, and an episode across it counts once.
    per : str or float
        ``"sample"``, ``"run"``, a duration in seconds or ``"second"``/``"minute"``/``"hour"``/``"day"``.
    dt : float
        Sample time, s.
    level : float
        Confidence level of the interval.

    Returns
    -------
    dict
        ``rate``, ``interval`` [lo, hi], ``events`` (alarmed samples, runs with an alarm, or onsets),
        ``samples`` (judged), ``records``, ``hours`` (judged time), ``tau`` and ``n_eff``
        (per sample), ``per``, ``interval_method``.

    Examples
    --------
    >>> a = np.zeros(360_000); a[1000:1005] = 1; a[5000:5003] = 1     # 2 episodes in an hour at 10 ms
    >>> m = measure_alarm_rate(a, "hour", 0.01)
    >>> m["events"], round(m["rate"], 3), [round(v, 3) for v in m["interval"]]
    (2, 2.0, [0.242, 7.225])
    """
    if not (dt > 0 and np.isfinite(dt)):
        raise DataError(f"measuring a rate needs the sample time dt > 0, got {dt}")
    recs = _records(alarm)
    if not recs or all(r.size == 0 for r in recs):
        raise DataError("no nominal samples to measure a false-alarm rate on")
    unit = per_seconds(per)
    judged = [np.isfinite(r.astype(float)) for r in recs]
    on = [np.where(j, r.astype(float) > 0.5, False) for r, j in zip(recs, judged)]
    n = int(sum(int(j.sum()) for j in judged))
    if n == 0:
        raise DataError("every sample of the nominal logs is in warm-up or held: nothing to measure")
    out: dict = {"per": per, "samples": n, "records": len(recs), "hours": n * float(dt) / 3600.0}
    if per == "sample":
        from .tail import block_length

        k = int(sum(int(o.sum()) for o in on))
        tau = 1.0
        if 0 < k < n:
            T = max(o.size for o in on)
            x = np.full((len(on), T), np.nan)
            for i, (o, j) in enumerate(zip(on, judged)):
                x[i, :o.size] = np.where(j, o.astype(float), np.nan)
            try:
                tau = max(1.0, float(block_length(x)["tau"]))
            except DataError:
                tau = 1.0
        out.update(rate=k / n, events=k, tau=tau, n_eff=n / tau,
                   interval=list(proportion_interval(k / tau, n / tau, level)),
                   interval_method="Clopper-Pearson on effective samples (n / tau)")
    elif per == "run":
        k = int(sum(bool(o.any()) for o in on))
        out.update(rate=k / len(on), events=k,
                   interval=list(proportion_interval(k, len(on), level)),
                   interval_method="Clopper-Pearson over the records (runs)")
    else:
        k = 0
        for o, j in zip(on, judged):
            seq = o[j]   # judged samples only: an episode across unjudged samples counts once
            k += int(np.count_nonzero(seq[1:] & ~seq[:-1]) + (1 if seq.size and seq[0] else 0))
        exposure = n * float(dt) / unit
        out.update(rate=k / exposure, events=k, interval=list(poisson_interval(k, exposure, level)),
                   interval_method="exact Poisson (Garwood) on alarm onsets")
    return out


def verdict(claimed: Sequence[float], measured: Sequence[float]) -> str:
    """``"inside"`` when the measured interval meets the claimed one, ``"above"`` when it lies
    wholly above it, ``"below"`` when wholly below.

    Examples
    --------
    >>> verdict([0.0, 0.1], [0.0, 3.7]), verdict([0.0, 0.1], [0.5, 3.7]), verdict([0.2, 0.3], [0.0, 0.1])
    ('inside', 'above', 'below')
    """
    clo, chi = float(claimed[0]), float(claimed[1])
    mlo, mhi = float(measured[0]), float(measured[1])
    if mlo > chi:
        return "above"
    if mhi < clo:
        return "below"
    return "inside"
