"""Temporal smoothing of a declarative design's detection features: ``[design.detect]``.

::

    [design.detect]
    smoothing = "ewma"                 # "none" (default) or "ewma": the EWMA of every feature
    lambda = "auto"                    # the EWMA constant in (0, 1], or "auto"
    # candidates = [0.05, 0.1, 0.2, 0.3, 1.0]    # the values "auto" chooses from

The core's EWMA (:class:`fdikit.detect.EWMA`, :func:`fdikit.detect.design_ewma`) between the
features (norms of the whitened residuals) and the hold: a small fault that raises a feature a
little on every sample is integrated over about ``1 / lambda`` samples, the noise averaged down.
Its limits are set on real nominal logs only (``[design].nominal_log``, or the logs an identified
plant came from), on the fit halves of the time-blocked split of
:func:`fdikit.monitor.declarative_thresholds.logged_thresholds`, and every claim is measured on the
held-out halves, smoothed the same way: the smoothed statistic is strongly autocorrelated, so the
effective samples count with an autocorrelation time no smaller than that of the EWMA of white
noise (``(2 - lambda) / lambda``) nor than the spectral estimate (:func:`~fdikit.detect.design_ewma`),
nor, over many records, than that of records each at their own level (:func:`record_tau`: the
EWMA averages the noise down but not a level that differs between nominal runs).

``lambda = "auto"`` looks at the fit halves only: among the candidates it takes the **smallest**
constant (the strongest smoothing, the smallest persistent shift detected) whose limits those data
support, i.e. hold at least one effective exceedance of the per-feature target; 1 (no smoothing)
is the last resort. A per-sample target without a hold uses the split-conformal limit of
:func:`~fdikit.detect.design_ewma`; other targets :func:`~fdikit.detect.design_threshold` on the
smoothed features. The Gaussian chi bound is never a fallback here: an EWMA of a chi statistic is
not chi distributed, so a target the data cannot support is refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals

__all__ = ["DETECT_KEYS", "SmoothingSpec", "record_tau", "smoothed_thresholds", "smoothing_from_config"]

#: Keys of ``[design.detect]`` and their types.
DETECT_KEYS: dict[str, type | tuple[type, ...]] = {"smoothing": str, "lambda": (int, float, str),
                                                   "candidates": list}
DEFAULT_CANDIDATES = (0.05, 0.1, 0.2, 0.3, 1.0)


@dataclass(frozen=True)
class SmoothingSpec:
    """The smoothing a ``[design.detect]`` table asks for.

    Attributes
    ----------
    kind : str
        ``"none"`` or ``"ewma"``.
    lam : float or None
        The EWMA constant; None for ``"auto"``.
    candidates : tuple of float
        The constants ``"auto"`` chooses from.
    """

    kind: str = "none"
    lam: float | None = None
    candidates: tuple[float, ...] = DEFAULT_CANDIDATES

    @property
    def active(self) -> bool:
        """True when the features are smoothed."""
        return self.kind == "ewma"


def _lam(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0.0 < v <= 1.0):
        raise DataError(f"config: {what} must be a number in (0, 1] (the EWMA constant: 0.1 remembers about "
                        f"10 samples, 1 is no smoothing), got {v!r}")
    return float(v)


def smoothing_from_config(design: Mapping[str, Any], *, where: str = "design") -> SmoothingSpec:
    """The :class:`SmoothingSpec` of ``[design.detect]`` (default: no smoothing).

    Parameters
    ----------
    design : mapping
        The ``[design]`` table.
    where : str
        The table's name in messages.

    Returns
    -------
    SmoothingSpec

    Raises
    ------
    DataError
        An unknown key, a smoothing other than ``"none"``/``"ewma"``, a constant outside (0, 1] or
        not ``"auto"``, candidates that are not constants in (0, 1]; the message names the key.

    Examples
    --------
    >>> smoothing_from_config({"detect": {"smoothing": "ewma", "lambda": 0.1}}).lam
    0.1
    >>> smoothing_from_config({"detect": {"smoothing": "cusum"}})
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: config: [design.detect].smoothing must be "none" or "ewma", got 'cusum'
    """
    spec = design.get("detect", {})
    if not isinstance(spec, Mapping):
        raise DataError(f"config: [{where}.detect] must be a table, got {type(spec).__name__}")
    for k in spec:
        if k not in DETECT_KEYS:
            raise DataError(f"config: unknown key {k!r} in [{where}.detect]; allowed: {sorted(DETECT_KEYS)}")
    if not isinstance(spec.get("smoothing", ""), str):
        raise DataError(f"config: [{where}.detect].smoothing must be str, got {spec['smoothing']!r}")
    if not isinstance(spec.get("candidates", []), list):
        raise DataError(f"config: [{where}.detect].candidates must be a list of numbers in (0, 1], got "
                        f"{spec['candidates']!r}")
    kind = spec.get("smoothing", "none")
    if kind not in ("none", "ewma"):
        raise DataError(f"config: [{where}.detect].smoothing must be \"none\" or \"ewma\", got {kind!r}")
    if kind == "none":
        extra = [k for k in ("lambda", "candidates") if k in spec]
        if extra:
            raise DataError(f"config: [{where}.detect].{extra[0]} needs smoothing = \"ewma\"")
        return SmoothingSpec()
    cands = spec.get("candidates", list(DEFAULT_CANDIDATES))
    if not cands:
        raise DataError(f"config: [{where}.detect].candidates must name at least one EWMA constant")
    cands = tuple(sorted({_lam(c, f"[{where}.detect].candidates[{i}]") for i, c in enumerate(cands)}))
    lam = spec.get("lambda", "auto")
    if isinstance(lam, str):
        if lam != "auto":
            raise DataError(f"config: [{where}.detect].lambda must be \"auto\" or a number in (0, 1], got "
                            f"{lam!r}")
        return SmoothingSpec("ewma", None, cands)
    if "candidates" in spec:
        raise DataError(f"config: [{where}.detect].candidates is for lambda = \"auto\"; lambda = {lam!r} "
                        "is given")
    return SmoothingSpec("ewma", _lam(lam, f"[{where}.detect].lambda"), cands)


def _smooth(ew, feats: list[Signals]) -> list[Signals]:
    return [ew.run(f) for f in feats]


def record_tau(z: list[np.ndarray], tau_w: float) -> float:
    """Autocorrelation time of records that each sit at their own level.

    ``(1 - rho) tau_w + rho n_mean``, ``rho`` the share of the variance between the records' means
    (one-way random effects, the within part of their variance removed). A statistic (smoothed or
    not) averages its noise down but not a level that differs from record to record: pooled, such
    records count as few effective samples. Used by the smoothed and the raw thresholds of a
    declarative design alike.

    Parameters
    ----------
    z : list of (T_i,) arrays
        The statistic on every record.
    tau_w : float
        Its autocorrelation time within the records, samples.

    Returns
    -------
    float
        The autocorrelation time, samples: ``tau_w`` with fewer than 3 records (they cannot show a
        spread of levels).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> same = [rng.standard_normal(500) for _ in range(6)]
    >>> record_tau(same, 1.0) < 3.0, record_tau([x + 3 * k for k, x in enumerate(same)], 1.0) > 100.0
    (True, True)
    """
    z = [r for r in z if r.size > 1]
    if len(z) < 3:
        return float(tau_w)
    n = np.array([r.size for r in z], float)
    means = np.array([r.mean() for r in z])
    within = np.array([r.var() for r in z])
    total = float(np.var(np.concatenate(z)))
    between = max(0.0, float(np.var(means, ddof=1)) - float(np.mean(within * tau_w / n)))
    rho = min(1.0, between / total) if total > 0 else 0.0
    return float((1.0 - rho) * tau_w + rho * n.mean())


_record_tau = record_tau      # the former private name (tests)


def _design_one(names: list[str], f_fit: list[Signals], lam: float, alarm, dt: float, level: float,
                per) -> dict[str, Any]:
    """Limits of the EWMA at ``lam`` of every feature, set on the fit halves; ``supported`` False
    (with ``why``) when the data cannot show the target."""
    from ..detect import EWMA, design_ewma, design_threshold, ewma_tau, held_out_limit

    start = np.array([float(np.mean(np.concatenate([f.values[0][:, i] for f in f_fit])))
                      for i in range(len(names))])
    ew = EWMA(names, lam, start)
    sm = _smooth(ew, f_fit)
    if per == "sample" and alarm.hold == 1:
        each = float(alarm.pfa) / len(names)
        ds, rec = [], []
        for i in range(len(names)):
            d = design_ewma([f.values[0][:, i] for f in f_fit], lam, 1.0 - each, confidence=level,
                            start=float(start[i]))
            z = [s.values[0][:, i] for s in sm]
            t_rec = record_tau(z, d.tau)
            h = held_out_limit(z, 1.0 - each, confidence=level, min_tau=max(d.tau, t_rec))
            ds.append(h)
            rec.append(t_rec)
        ok = all(h["supported"] for h in ds)
        td = {"threshold": [h["limit"] for h in ds], "ci": [h["interval"] for h in ds], "target": each,
              "method": "split-conformal quantile of the EWMA",
              "effective_samples": [h["effective_samples"] for h in ds], "tau": [h["tau"] for h in ds],
              "tau_records": rec, "tau_white": ewma_tau(lam), "pfa": float(alarm.pfa), "per": "sample"}
        ne = min(h["effective_samples"] for h in ds)
        why = None if ok else (f"{ne:.0f} effective samples (autocorrelation time "
                               f"{max(h['tau'] for h in ds):.1f}, records' own levels included) hold "
                               f"{ne * each:.2g} effective exceedances of {each:.3g} per sample (at least 1 "
                               "needed)")
        return {"ewma": ew, "td": td, "supported": ok, "why": why, "smoothed": sm}
    try:
        td = dict(design_threshold(sm, alarm.pfa, per=per, Z=alarm.hold, dt=dt, family_wise=True))
    except DataError as exc:
        return {"ewma": ew, "td": None, "supported": False, "why": str(exc), "smoothed": sm}
    return {"ewma": ew, "td": td, "supported": True, "why": None, "smoothed": sm}


def smoothed_thresholds(spec: SmoothingSpec, names: list[str], f_fit: list[Signals], alarm, dt: float,
                        *, level: float = 0.95, source: str = "the nominal logs") -> dict[str, Any]:
    """The EWMA of the features and its thresholds, set on the fit halves of the nominal logs.

    Parameters
    ----------
    spec : SmoothingSpec
        From :func:`smoothing_from_config` (``spec.active``).
    names : list of str
        The features (the EWMA's inputs).
    f_fit : list of Signals
        The features on the fit half of every record (one run each).
    alarm : AlarmTarget
        The false-alarm target (per feature: ``pfa / len(names)``, Bonferroni).
    dt : float
        Sample time, s.
    level : float
        Confidence level of the stated intervals.
    source : str
        What the logs are, for messages.

    Returns
    -------
    dict
        ``ewma`` (the :class:`~fdikit.detect.EWMA` stage, started at each feature's mean on the fit
        halves), ``names`` (its outputs: the hold's inputs), ``thr`` (thresholds), ``td`` (the
        threshold design with ``smoothing``: the constant, how it was chosen and every candidate's
        limits on the fit halves).

    Raises
    ------
    DataError
        The fit halves cannot support the target at the given constant (or at any candidate for
        ``"auto"``): the message names the constant(s), the effective samples and the source.
    """
    per = {"sample": "sample", "run": float(alarm.run_length or 0.0), "hour": "hour"}[alarm.per]
    lams = list(spec.candidates) if spec.lam is None else [spec.lam]
    tried, chosen = {}, None
    for lam in lams:                   # ascending: the first supported is the strongest smoothing
        d = _design_one(names, f_fit, lam, alarm, dt, level, per)
        row = {"supported": d["supported"]}
        if d["td"] is not None:
            row["limit"] = np.atleast_1d(np.asarray(d["td"]["threshold"], float)).tolist()
            if "effective_samples" in d["td"]:
                row["effective_samples"] = np.atleast_1d(d["td"]["effective_samples"]).tolist()
        if d["why"]:
            row["why"] = d["why"]
        tried[str(lam)] = row
        if d["supported"] and chosen is None:
            chosen = (lam, d)
            if spec.lam is None:
                break
    if chosen is None:
        what = (f"lambda = {lams[0]:g}" if spec.lam is not None else
                f"any of the candidates {list(lams)} (lambda = \"auto\")")
        reasons = "; ".join(f"lambda {k}: {v.get('why', 'unsupported')}" for k, v in tried.items())
        raise DataError(f"config: [design.detect]: the fit halves of {source} "
                        f"({sum(f.n_samples for f in f_fit) * dt / 3600:.3g} h in {len(f_fit)} record(s)) "
                        f"cannot support the target pfa = {alarm.pfa:g} per {alarm.per} (hold {alarm.hold}) "
                        f"with the EWMA at {what}: {reasons}. Give more or longer nominal logs, a larger "
                        "constant or target, or smoothing = \"none\"")
    lam, d = chosen
    td = dict(d["td"])
    td["smoothing"] = {"kind": "ewma", "lambda": lam, "chosen": "given" if spec.lam is not None else
                       "auto: the smallest candidate the fit halves support",
                       "start": d["ewma"].start.tolist(), "candidates": tried}
    return {"ewma": d["ewma"], "names": list(d["ewma"].output_names),
            "thr": np.atleast_1d(np.asarray(td["threshold"], float)), "td": td}
