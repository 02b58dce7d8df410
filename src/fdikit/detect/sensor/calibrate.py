"""Calibration of a sensor-fault detector on nominal data: the checked nominal record, its sample
time, and the threshold of a statistic for a false-alarm target (with the extreme-value
fallback for records too short for it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...errors import DataError
from ...signals import Signals


def _nominal(nominal: Signals, names: Sequence[str], skip: int) -> Signals:
    if not isinstance(nominal, Signals):
        raise DataError(f"nominal data must be Signals, got {type(nominal).__name__}")
    missing = [n for n in names if n not in nominal.names]
    if missing:
        raise DataError(f"nominal data lack channels {missing}; they have {list(nominal.names)}")
    if int(skip) != skip or skip < 0 or skip >= nominal.n_samples - 1:
        raise DataError(f"skip must be an integer in [0, {nominal.n_samples - 1}), got {skip}")
    return nominal


def _threshold(
    stat: np.ndarray,
    pfa: float,
    per,
    margin: float,
    dt: float | None,
    Z: int,
    what: str,
    floor_chi2: bool = False,
) -> np.ndarray:
    """Threshold(s) of statistics (runs, T, C) for the target (see :func:`design_threshold`).

    When the nominal data are too short for the target (``design_threshold`` refuses: too few
    effective samples for a tail fit; the usual case of a short real record), a target per unit
    of time falls back to extreme-value scaling: the maximum of ``n`` effective samples of a
    statistic with an exponential tail (a GLR is chi-square-like) grows as ``ln n``, so the
    threshold is the nominal maximum times ``ln(n_target) / ln(n_eff)``, with ``n_eff = n / tau``
    the effective samples of the data and ``n_target`` those of the operating time in which one
    false alarm is allowed (``tau`` the integrated autocorrelation time,
    :func:`fdikit.detect.tail.block_length`). Rough, conservative for lighter tails. With
    ``floor_chi2`` (GLR statistics) the threshold is never below the chi-square(1) level of the
    target per sample.
    """
    from ..glrt import TIME_UNITS, design_threshold
    from ..tail import block_length

    if not (np.isfinite(margin) and margin >= 0):
        raise DataError(f"{what}: margin must be finite and >= 0, got {margin}")
    try:
        d = design_threshold(stat, pfa, per=per, Z=Z, margin=margin, absolute=False, dt=dt)
        thr = np.atleast_1d(np.asarray(d.threshold, float))
    except DataError:
        timed = not (isinstance(per, str) and per in ("run", "sample"))
        if not (pfa > 0 and timed and dt):
            raise
        unit = TIME_UNITS[per] if isinstance(per, str) else float(per)
        thr = np.empty(stat.shape[2])
        for c in range(stat.shape[2]):
            x = stat[:, :, c]
            tau = block_length(x)["tau"]
            n_eff = max(x.size / tau, np.e)
            n_target = max(unit / pfa / dt / tau, n_eff)
            thr[c] = float(x.max()) * np.log(n_target) / np.log(n_eff) * (1.0 + margin)
    floor = 1e-12
    if floor_chi2 and pfa > 0 and dt and not (isinstance(per, str) and per in ("run", "sample")):
        # never below the level of a chi-square(1) GLR of white noise for the target per sample: a
        # statistic that is 0 on most nominal data (an indifference zone, a gate) is still tested
        from scipy.stats import chi2

        unit = TIME_UNITS[per] if isinstance(per, str) else float(per)
        floor = float(chi2.isf(min(pfa * dt / unit, 0.5), 1))
    return np.maximum(thr, floor)


def _dt(s: Signals) -> float | None:
    return float((s.t[-1] - s.t[0]) / (s.n_samples - 1)) if s.n_samples > 1 else None
