"""The thresholds of a declarative design and the false-alarm claims they state: set on simulated
noise of the declared model (model-based rates), or on real nominal logs, time-blocked (each log's
first half fits the whitening and the thresholds, its second half measures them; with two records
or more, each record left out in turn is measured by a design refitted on the others). The claimed
intervals count the records' own levels (:func:`~fdikit.monitor.declarative_smoothing.record_tau`),
and the samples a plant was identified on neither fit nor measure.

A user runs the monitor on a *new* record, whose rate varies with its own level: with three records
or more and a per-sample target without a hold (raw or smoothed statistics), each threshold is the
quantile level of the fit parts at which the mean of the left-out records' rates (each record left
out in turn, measured against that level of the others; records weighted alike) meets the target,
and the claim is "per sample on a new record", its interval the t-interval over the records
(:func:`_new_record_levels`). Fewer records (they cannot show a spread of levels), other targets, or
left-out designs that are refused keep the pooled thresholds (the last two say so).

Each design returns its *claims*: plain dicts that :func:`fdikit.evaluate.validate` re-measures on
new nominal logs and the design report lists::

    {"name": "threshold r1", "kind": "threshold" | "family" | "decision",
     "channels": ["r1:alarm"],            # monitor statistics whose alarm the claim is about
     "per": "hour" | "sample" | "run" | seconds,  "target": 0.025,
     "interval": [lo, hi],                # the claimed rate's interval (upper bound: lo = 0)
     "basis": "model" | "nominal logs", "method": "empirical" | "gpd" | "gaussian chi bound", ...}

On real logs, every claim is measured on the held-out halves (:func:`fdikit.detect.rates.
measure_alarm_rate`) and a design whose measured interval misses its claimed one is refused
unless ``accept_miscalibrated``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals

__all__ = ["logged_thresholds", "simulated_thresholds"]


def _whitening(raw, groups: dict[str, list[str]], vals: np.ndarray) -> np.ndarray:
    """Whitening of each residual's channels by their nominal covariance (``vals`` (runs, T, C))."""
    W = np.zeros((len(raw.residual_names), len(raw.residual_names)))
    for name, chans in groups.items():
        idx = [raw.residual_names.index(c) for c in chans]
        S = np.atleast_2d(np.cov(vals[:, :, idx].reshape(-1, len(idx)).T))
        w, V = np.linalg.eigh(0.5 * (S + S.T))
        if w.max() <= 0:
            raise DataError(f"residual {name!r} carries no noise in the nominal simulation")
        keep = w > 1e-9 * w.max()
        W[np.ix_(idx, idx)] = (V[:, keep] / np.sqrt(w[keep])) @ V[:, keep].T
    return W


def _white_design(raw, W: np.ndarray, groups: dict[str, list[str]]):
    from ..residuals import FilterDesign

    return FilterDesign(raw.A, raw.Bu, raw.By, W @ raw.C, W @ raw.Du, W @ raw.Dy, raw.dt, list(raw.u_names),
                        list(raw.y_names), list(raw.residual_names),
                        {**raw.info, "whitening": W, "groups": groups})


def _per(alarm) -> str | float:
    return {"sample": "sample", "run": float(alarm.run_length or 0.0), "hour": "hour"}[alarm.per]


def _claims(names: list[str], td: dict, alarm, basis: str) -> list[dict]:
    """Per-threshold, family and decision claims of a threshold design ``td``."""
    per = _per(alarm)
    ci = np.atleast_2d(np.asarray(td["ci"], float))
    target = np.broadcast_to(np.asarray(td.get("target", alarm.pfa / len(names)), float), (len(names),))
    method = td.get("method")
    methods = method if isinstance(method, list) else [method] * len(names)
    out = [{"name": f"threshold {n}", "kind": "threshold", "channels": [f"{n}:alarm"], "per": per,
            "target": float(target[i]), "interval": [float(ci[i, 0]), float(ci[i, 1])], "basis": basis,
            "method": methods[i], "hold": alarm.hold} for i, n in enumerate(names)]
    fam = [float(np.max(ci[:, 0])), float(np.sum(ci[:, 1]))]   # Bonferroni: max lo <= family <= sum hi
    out.append({"name": "family (any threshold)", "kind": "family", "channels": [f"{n}:alarm" for n in names],
                "per": per, "target": float(alarm.pfa), "interval": fam, "basis": basis,
                "method": "Bonferroni over the thresholds", "hold": alarm.hold})
    if per != "sample":
        out.append({"name": "decision (announcements)", "kind": "decision", "channels": [], "per": per,
                    "target": float(alarm.pfa), "interval": [0.0, fam[1]], "basis": basis,
                    "method": "at most the family's alarm onsets", "hold": alarm.hold})
    return out


def _chi_bound(raw, W: np.ndarray, groups: dict[str, list[str]], feats, alarm, dt: float, exc: Exception,
               basis: str) -> tuple[np.ndarray, dict, list[dict]]:
    """Thresholds at the chi quantile of each whitened residual's dimension for the per-sample
    probability of the target (Bonferroni over the residuals), their record and their claims: the
    fallback when the nominal data cannot show the target (see :func:`simulated_thresholds`)."""
    from scipy.stats import chi2

    p_each = alarm.per_sample(dt) / len(groups)
    dims = []
    for g in feats.output_names:
        ix = [raw.residual_names.index(c) for c in groups[g]]
        dims.append(int(np.linalg.matrix_rank(W[np.ix_(ix, ix)])))
    thr = np.array([np.sqrt(chi2.isf(p_each, k)) for k in dims])
    td = {"method": "gaussian chi bound", "reason": str(exc), "per_sample_each": p_each, "dims": dims}
    each = alarm.pfa / len(groups)
    bound = {"ci": [[0.0, each]] * len(groups), "target": [each] * len(groups), "method": td["method"]}
    return thr, td, _claims(feats.output_names, bound, alarm, basis)


def simulated_thresholds(md, raw, groups: dict[str, list[str]], R: np.ndarray, Q: np.ndarray, alarm,
                         dt: float, *, nominal_hours: float | None, seed: int) -> dict[str, Any]:
    """Whitening and thresholds from simulated nominal operation of the discrete plant ``md``
    (noise only: the residuals are decoupled from the known inputs); see
    :func:`fdikit.monitor.declarative.design_monitor`, step 4.

    Returns
    -------
    dict
        ``white`` (the whitened FilterDesign), ``features`` (FeatureNorms), ``thr`` (thresholds),
        ``td`` (the threshold design's record), ``runs``, ``duration`` (s per run), ``claims``.
    """
    from ..detect import FeatureNorms, design_threshold
    from ..faults import Noise, Scenario
    from ..residuals import FaultDetectionFilter
    from ..sim import simulate

    hours = 0.05 if nominal_hours is None else float(nominal_hours)
    runs = 20
    duration = hours * 3600.0 / runs
    sc = Scenario(duration=duration, dt=dt, noise=Noise(measurement=R, process=Q))
    sim = simulate(md.without_faults(), sc, runs=runs, seed=seed, keep=("y", "u"))
    data = sim.u.concat_channels(sim.y) if sim.u.n_channels else sim.y
    gen = FaultDetectionFilter(raw)
    r = gen.run(data)
    warm = min(r.n_samples // 2, round(10.0 / dt) if dt < 1 else 10)
    vals = r.values[:, warm:]
    W = _whitening(raw, groups, vals)
    white = _white_design(raw, W, groups)
    feats = FeatureNorms(groups, dt, 0.0)
    # the whitened filter's output is W times the raw one (C, Du, Dy premultiplied): no second run
    f_nom = feats.run(Signals(r.t, r.values @ W.T, r.names, check=False))
    f_nom = Signals(f_nom.t[warm:], f_nom.values[:, warm:], f_nom.names, check=False)
    per = _per(alarm)
    try:
        td = dict(design_threshold(f_nom, alarm.pfa, per=per, Z=alarm.hold, dt=dt, family_wise=True))
        thr = np.atleast_1d(np.asarray(td["threshold"], float))
        claims = _claims(feats.output_names, td, alarm, "model")
    except DataError as exc:
        # The nominal data cannot show a rate that small (the residuals of slow filters are strongly
        # autocorrelated: few effective samples). The features are norms of whitened Gaussian
        # residuals, so each is chi-distributed with the residual's dimension k: a threshold at the
        # chi quantile of the per-sample probability bounds the fraction of samples over it, and
        # an alarm needs ``hold`` of them, so the alarm onsets per unit time are bounded too
        # (conservative; Bonferroni over the residuals).
        thr, td, claims = _chi_bound(raw, W, groups, feats, alarm, dt, exc, "model")
        p_each = td["per_sample_each"]
        unit = {"hour": "expected false alarms per hour", "sample": "per sample"}.get(
            alarm.per, f"per run of {alarm.run_length} s")
        warnings.warn(f"design: the false-alarm target pfa = {alarm.pfa:g} {unit} (hold {alarm.hold}) "
                      f"cannot be shown by the simulated nominal data ({runs} runs, "
                      f"{runs * duration / 3600:.3g} h at dt = {dt:g} s): {exc}. Falling back to the "
                      f"Gaussian chi bound: thresholds {np.round(thr, 4).tolist()} at a per-sample "
                      f"probability {p_each:.3g} per residual (conservative; nominal_hours sets the "
                      "simulated data)", UserWarning, stacklevel=3)
    return {"white": white, "features": feats, "thr": thr, "td": td, "runs": runs, "duration": duration,
            "claims": claims}


def _conformal(names: list[str], f_fit: list, alarm, level: float):
    """Per-sample thresholds at ``pfa / len(names)`` each (Bonferroni) as the split-conformal
    quantile of every feature over the fit halves (:func:`fdikit.detect.held_out_limit`), with the
    interval of each rate at the effective sample size, the records' own levels counted
    (:func:`~fdikit.monitor.declarative_smoothing.record_tau`, as for smoothed features); ``(None,
    why)`` when a feature's records hold less than one effective exceedance (the target is then not
    supported). A per-sample target without a hold needs no tail model: a quantile is enough where
    a tail fit (:func:`~fdikit.detect.design_threshold`) asks for hundreds of effective exceedances."""
    from ..detect.calibrated_limits import held_out_limit
    from .declarative_smoothing import record_tau

    each = float(alarm.pfa) / len(names)
    thr, ci, neff, taus, rec = [], [], [], [], []
    for i in range(len(names)):
        z = [f.values[0][:, i] for f in f_fit]
        d = held_out_limit(z, 1.0 - each, confidence=level)
        t_rec = record_tau(z, d["tau"])
        if t_rec > d["tau"]:      # records at their own levels: fewer effective samples
            d = held_out_limit(z, 1.0 - each, confidence=level, min_tau=t_rec)
        if not d["supported"]:
            ne = d["effective_samples"]
            return None, (f"feature {names[i]!r}: {ne:.0f} effective samples (autocorrelation time "
                          f"{d['tau']:.1f} samples, the records' own levels counted: {t_rec:.1f}) hold "
                          f"{ne * each:.2g} effective exceedances of {each:.3g} per sample (at least 1 "
                          "needed)")
        thr.append(d["limit"])
        ci.append(d["interval"])
        neff.append(d["effective_samples"])
        taus.append(d["tau"])
        rec.append(t_rec)
    td = {"threshold": thr, "ci": ci, "target": each, "method": "split-conformal quantile",
          "effective_samples": neff, "tau": taus, "tau_records": rec, "pfa": float(alarm.pfa),
          "per": "sample"}
    return (np.asarray(thr, float), td), None


def _level_limit(f_fit: list, k: int, q: float) -> float:
    """The ``q`` quantile (the next sample up) of feature ``k`` pooled over the records ``f_fit``."""
    return float(np.quantile(np.concatenate([f.values[0][:, k] for f in f_fit]), q, method="higher"))


def _over_records(r: np.ndarray, level: float) -> dict:
    """Mean of per-record rates ``r`` with its t-interval over the records and the spread of one new
    record's rate (t prediction interval), both clipped at 0."""
    from scipy.stats import t as student

    J, m = r.size, float(np.mean(r))
    sd = float(np.std(r, ddof=1)) if J > 1 else 0.0
    tq = float(student.ppf(0.5 + level / 2.0, J - 1))
    return {"rate": m, "interval": [max(0.0, m - tq * sd / np.sqrt(J)), m + tq * sd / np.sqrt(J)],
            "spread": [max(0.0, m - tq * sd * np.sqrt(1.0 + 1.0 / J)), m + tq * sd * np.sqrt(1.0 + 1.0 / J)],
            "sd": sd, "records": J, "per_record": r.tolist()}


def _new_record_levels(names: list[str], f_fit: list, folds: list, each: float, level: float) -> dict:
    """Per-sample thresholds for a NEW record, chosen from the records left out in turn.

    Each record's rate varies with its own level, so the rate pooled over the records is not what a
    user sees on the next one. For every feature, the lowest quantile level ``q`` (a grid from
    ``1 - 4 each`` to ``1 - each / 50``) at which the mean over the records of the left-out rate
    (record ``j`` measured against the ``q`` quantile of the others' features, whitening refitted on
    them; records weighted alike) is at most ``each``; the thresholds are the ``q`` quantiles of the
    fit parts ``f_fit``. The claimed interval is the t-interval over the records of that mean.

    Returns
    -------
    dict
        ``levels``, ``thresholds``, ``ci`` (per feature), ``per_feature`` and ``family`` (rates over
        the records, :func:`_over_records`), ``rests_on``; or ``{"supported": False, "why": ...}``
        when even the highest level leaves a mean rate above ``each``.
    """
    grid = 1.0 - each * np.geomspace(4.0, 0.02, 161)       # ascending: the first met is the lowest
    levels, per_feature, alarms = [], [], [np.zeros(z.n_samples, bool) for _, z in folds]
    for k, name in enumerate(names):
        pooled = [np.concatenate([f.values[0][:, k] for f in others]) for others, _ in folds]
        zs = [z.values[0][:, k] for _, z in folds]
        chosen = None
        for q in grid:
            r = np.array([np.mean(zj > np.quantile(pj, q, method="higher")) for pj, zj in zip(pooled, zs)])
            if r.mean() <= each:
                chosen = float(q)
                break
        if chosen is None:
            return {"supported": False, "why": f"feature {name!r}: even at the quantile level {grid[-1]:.6g} "
                    f"the left-out records measure {r.mean():.3g} per sample on average (target {each:.3g})"}
        levels.append(chosen)
        per_feature.append(_over_records(r, level))
        for j, (pj, zj) in enumerate(zip(pooled, zs)):
            alarms[j] |= zj > np.quantile(pj, chosen, method="higher")
    fam = _over_records(np.array([np.mean(a) for a in alarms]), level)
    J = len(folds)
    return {"supported": True, "levels": levels,
            "thresholds": [_level_limit(f_fit, k, q) for k, q in enumerate(levels)],
            "ci": [p["interval"] for p in per_feature], "per_feature": per_feature, "family": fam,
            "claim": "per sample on a new record", "level": level,
            "rests_on": (f"{J} nominal records, each left out in turn: whitening refitted on the others "
                         "(whole, after the warm-up), the threshold at a quantile level of their features, "
                         "measured on the left-out record; the level is the lowest whose mean left-out "
                         "rate (records weighted alike) is at most the target; interval: t over the "
                         f"{J} records at {level:g}; one new record's own rate spreads over "
                         f"{fam['spread'][0]:.3g}..{fam['spread'][1]:.3g} (any threshold)")}


def _record_widened(td: dict, f_fit: list) -> dict:
    """A tail or empirical threshold design's intervals widened for records at their own levels:
    each half-width around the achieved rate times ``sqrt(tau_records / tau)`` (the design effect of
    :func:`~fdikit.monitor.declarative_smoothing.record_tau`; unchanged with fewer than 3 records or
    no spread between them)."""
    from .declarative_smoothing import record_tau

    ci = np.atleast_2d(np.asarray(td["ci"], float)).copy()
    tau = np.broadcast_to(np.atleast_1d(np.asarray(td.get("tau", 1.0), float)), (ci.shape[0],))
    ach = np.broadcast_to(np.atleast_1d(np.asarray(td.get("achieved", np.nan), float)), (ci.shape[0],))
    rec = []
    for i in range(ci.shape[0]):
        t_rec = record_tau([f.values[0][:, i] for f in f_fit], float(tau[i]))
        rec.append(t_rec)
        if t_rec > tau[i] and np.isfinite(ach[i]):
            g = np.sqrt(t_rec / tau[i])
            ci[i] = [max(0.0, ach[i] - (ach[i] - ci[i, 0]) * g), ach[i] + (ci[i, 1] - ach[i]) * g]
    if all(r <= t for r, t in zip(rec, tau)):
        return td
    return {**td, "ci": ci if ci.shape[0] > 1 else ci[0], "tau_records": rec,
            "ci_note": "widened by sqrt(tau_records / tau): the records' own levels"}


def _halves(x: np.ndarray, warm: int) -> tuple[slice, slice]:
    """Fit and measure parts of a record of ``x.shape[0]`` samples after ``warm`` samples."""
    n = x.shape[0]
    mid = warm + (n - warm) // 2
    return slice(warm, mid), slice(mid, n)


def _design_on(raw, groups: dict[str, list[str]], fit_parts: list[np.ndarray], alarm, dt: float, *,
               level: float, fallback: bool, source: str, smoothing) -> dict[str, Any]:
    """Whitening, features, thresholds and claims set on the fit parts ``fit_parts`` (raw residuals,
    (T_i, C) each): one design of :func:`logged_thresholds`, also refitted without a record for the
    record-blocked check. ``warn``: the chi-bound fallback's message (not yet printed)."""
    from ..detect import FeatureNorms, design_threshold

    W = _whitening(raw, groups, np.concatenate(fit_parts)[None])
    white = _white_design(raw, W, groups)
    feats = FeatureNorms(groups, dt, 0.0)

    def features(x):
        s = Signals(np.arange(x.shape[0]) * dt, (x @ W.T)[None], list(raw.residual_names), check=False)
        return feats.run(s)

    f_fit = [features(x) for x in fit_parts]
    per = _per(alarm)
    names, smooth, warn = list(feats.output_names), None, None
    if smoothing is not None and smoothing.active:
        from .declarative_smoothing import smoothed_thresholds

        sm = smoothed_thresholds(smoothing, names, f_fit, alarm, dt, level=level, source=source)
        smooth, names, thr, td = sm["ewma"], sm["names"], sm["thr"], sm["td"]
        claims = _claims(names, td, alarm, f"nominal logs ({td['method']}, EWMA lambda "
                                           f"{td['smoothing']['lambda']:g})")
        ne = np.atleast_1d(td.get("effective_samples", np.nan)).astype(float)
        tau = np.atleast_1d(td.get("tau", np.nan)).astype(float)
        for c in claims:
            c["smoothing"] = {"kind": "ewma", "lambda": td["smoothing"]["lambda"]}
            i = names.index(c["channels"][0][:-len(":alarm")]) if c["kind"] == "threshold" else None
            n_i = ne[min(i, ne.size - 1)] if i is not None else float(np.min(ne))
            t_i = tau[min(i, tau.size - 1)] if i is not None else float(np.max(tau))
            c["rests_on"] = (f"the EWMA (lambda {td['smoothing']['lambda']:g}, {td['smoothing']['chosen']}) "
                             f"of the features on the fit halves of {len(fit_parts)} nominal record(s): "
                             f"{n_i:.0f} effective samples at an autocorrelation time of {t_i:.1f} samples "
                             "(the EWMA's, the data's and the records' own levels, the largest); measured "
                             "on the held-out halves, smoothed the same way")
    else:
        thr = td = claims = None
    try:
        if td is None:
            td = _record_widened(dict(design_threshold(f_fit, alarm.pfa, per=per, Z=alarm.hold, dt=dt,
                                                       family_wise=True)), f_fit)
            thr = np.atleast_1d(np.asarray(td["threshold"], float))
            claims = _claims(feats.output_names, td, alarm, "nominal logs")
    except DataError as exc:
        conf, short = _conformal(feats.output_names, f_fit, alarm, level) \
            if per == "sample" and alarm.hold == 1 else (None, None)
        why = (f"the fit half of {source} ({sum(f.n_samples for f in f_fit) * dt / 3600:.3g} h in "
               f"{len(f_fit)} record(s)) cannot support the target pfa = {alarm.pfa:g} per {alarm.per} "
               f"(hold {alarm.hold}): {exc}" + (f"; nor can its split-conformal quantile: {short}" if short
                                                else ""))
        if conf is not None:      # a per-sample target without a hold: the quantile suffices
            thr, td = conf
            claims = _claims(feats.output_names, td, alarm, "nominal logs (split-conformal quantile)")
        elif not fallback:
            raise DataError(f"config: {source}: {why}. Give more or longer nominal logs, or a larger "
                            "target") from None
        else:
            thr, td, claims = _chi_bound(raw, W, groups, feats, alarm, dt, exc,
                                         "nominal logs (Gaussian bound)")
            warn = (f"design: {why}. Falling back to the Gaussian chi bound of the whitened real "
                    f"residuals: thresholds {np.round(thr, 4).tolist()} at a per-sample probability "
                    f"{td['per_sample_each']:.3g} per residual; the held-out halves measure it (give more "
                    "nominal logs, [design].nominal_log, to set the thresholds on data)")
    return {"white": white, "features": feats, "featurise": features, "f_fit": f_fit, "names": names,
            "smooth": smooth, "thr": thr, "td": td, "claims": claims, "warn": warn}


def _measure(claims: list[dict], hold, stats: list[Signals], per, dt: float,
             level: float) -> list[dict | None]:
    """Every non-decision claim's measured rate (:func:`fdikit.detect.rates.measure_alarm_rate`) on
    the statistics ``stats`` (one run each) under ``hold``; None for a decision claim or no data."""
    from ..detect.rates import measure_alarm_rate

    alarms = [hold.run(f).values[0] for f in stats if f.n_samples]     # (T_i, channels)
    out = []
    for c in claims:
        if c["kind"] == "decision" or not alarms:
            out.append(None)   # announcements need the whole monitor: fdikit validate measures them
            continue
        idx = [hold.output_names.index(n) for n in c["channels"]]
        m = measure_alarm_rate([np.any(al[:, idx] > 0.5, axis=1) for al in alarms], per, dt, level=level)
        out.append({k: m[k] for k in ("rate", "interval", "events", "samples", "hours", "interval_method")})
    return out


def logged_thresholds(raw, groups: dict[str, list[str]], alarm, dt: float, nominal: list,
                      *, accept_miscalibrated: bool = False, level: float = 0.95,
                      fallback: bool = False, source: str = "[design].nominal_log",
                      smoothing=None, in_sample: Mapping[str, int] | None = None) -> dict[str, Any]:
    """Whitening and thresholds set on real nominal logs, time-blocked, with claims measured on
    held-out data: held-out halves, and with two records or more, held-out records.

    Every record (each run of each log) is run through the raw filter; after the filter's warm-up
    its first half fits the whitening and the thresholds (pooled over the records,
    :func:`~fdikit.detect.design_threshold`, family-wise; the records' own levels counted in the
    claimed intervals, :func:`~fdikit.monitor.declarative_smoothing.record_tau`), its second half
    measures them. The thresholds are the fit part's. With two records or more, every record is also
    left out in turn: whitening and thresholds are refitted on the others (each whole, after the warm-up) and
    measured on the whole left-out record (after the warm-up), which the refitted design never saw;
    the pooled rate over the left-out records is a second measurement of every claim
    (``measured_records``). With three records or more and a per-sample target without a hold, the
    thresholds are set for a NEW record from those left-out rates (:func:`_new_record_levels`; the
    claim "per sample on a new record", ``new_record`` in the threshold design), and the left-out
    records are measured at the chosen levels. Samples a plant was identified on (``in_sample``)
    neither fit nor measure (a record with too few others is left out; none left: refused, naming the
    logs).

    Parameters
    ----------
    raw : FilterDesign
        The residual bank's filter, before whitening.
    groups : dict
        Feature name -> the residual channels it takes the norm of.
    alarm : AlarmTarget
        The false-alarm target.
    dt : float
        The monitor's sample time, s (the logs must be on this grid).
    nominal : list of Signals, or dict name -> Signals
        Nominal logs in monitor channels (e.g. :func:`fdikit.monitor.config.nominal_logs`, named
        by their paths); every run of a log is a record.
    accept_miscalibrated : bool
        Keep a design whose measured rate misses its claimed interval (with a printed warning)
        instead of refusing it.
    level : float
        Confidence level of the measured intervals.
    fallback : bool
        When the fit half cannot support the target (too few effective samples for its tail), fall
        back to the Gaussian chi bound of the whitened residuals (with a printed warning, and the
        claims still measured on the held-out halves) instead of refusing. The declarative design
        uses it for the logs a plant was identified from, which the user did not give as
        threshold data.
    source : str
        What the logs are, for messages.
    smoothing : SmoothingSpec, optional
        ``[design.detect]`` (:func:`fdikit.monitor.declarative_smoothing.smoothing_from_config`):
        when active, the thresholds are those of the EWMA of the features, set on the fit halves
        (:func:`~fdikit.monitor.declarative_smoothing.smoothed_thresholds`; never the chi bound), and
        the held-out halves are smoothed the same way (each half from the EWMA's start) to measure
        them.
    in_sample : dict, optional
        Log name -> the number of leading samples of its first run that the plant model was
        identified on (estimated from): those samples are in-sample for the model, its residuals
        smaller there than on new data, so they neither fit nor measure a claim.

    Returns
    -------
    dict
        As :func:`simulated_thresholds`, with ``claims`` carrying ``measured`` (on the held-out
        halves), ``measured_records`` (on the left-out records, two records or more) and
        ``verdict`` (the worse of the two), and ``records``/``fit_hours``/``measure_hours``;
        ``smooth`` (the :class:`~fdikit.detect.EWMA` stage or None), ``names`` (the hold's inputs),
        ``in_sample`` (log -> the samples left out, ``[0, n]``), ``record_check`` (per left-out record:
        its rate, or why it was not refitted) and ``new_record`` (the new-record levels of
        :func:`_new_record_levels`, or None: fewer than 3 records or another target).

    Raises
    ------
    DataError
        A log lacking a channel, off the sample time, with non-finite values; a target the fit part
        cannot support; no sample out of the model's own; a claim the held-out part contradicts
        (unless ``accept_miscalibrated``).
    """
    from ..detect import Hold
    from ..detect.rates import measure_alarm_rate, verdict
    from ..residuals import FaultDetectionFilter

    if not nominal:
        raise DataError("config: [design].nominal_log names no log")
    need = [*raw.u_names, *raw.y_names]
    gen = FaultDetectionFilter(raw)
    recs, where_of, n_in = [], [], []
    items = list(nominal.items()) if isinstance(nominal, Mapping) else \
        [(f"nominal log {i}", s) for i, s in enumerate(nominal)]
    in_sample = dict(in_sample or {})
    for where, log in items:
        missing = [c for c in need if c not in log.names]
        if missing:
            raise DataError(f"{where}: lacks the channels {missing} the residual bank reads (it has "
                            f"{list(log.names)})")
        if log.n_samples < 3:
            raise DataError(f"{where}: {log.n_samples} samples; a nominal log needs many")
        step = float(np.median(np.diff(log.t)))
        if abs(step - dt) > 1e-6 * dt:
            raise DataError(f"{where}: sampled every {step:g} s, the design's sample time is {dt:g} s "
                            "([design].sample_time; resample the log with [log].rate)")
        sel = log.select(need)
        bad = np.argwhere(~np.isfinite(sel.values))
        if bad.size:
            run, k, c = bad[0]
            raise DataError(f"{where}: channel {need[c]!r} is not finite at run {run}, sample {k} (t = "
                            f"{log.t[k]:g} s); a nominal log for thresholds must be complete")
        r = gen.run(sel)
        for j in range(r.runs):
            recs.append(r.values[j])
            where_of.append(where if r.runs == 1 else f"{where} (run {j})")
            n_in.append(int(in_sample.get(where, 0)) if j == 0 else 0)
    warm = round(10.0 / dt) if dt < 1 else 10
    parts, kept = [], []
    for i, (x, k0) in enumerate(zip(recs, n_in)):
        # the samples the plant was identified on neither fit nor measure: its residuals are
        # smaller there than on new data
        w = max(min(x.shape[0] // 2, warm), k0)
        f, m = _halves(x, w)
        if f.stop - f.start < 2 * alarm.hold or m.stop - m.start < 2 * alarm.hold:
            if k0:
                continue
            raise DataError(f"a nominal log of {x.shape[0]} samples is too short: after the filter's "
                            f"warm-up ({w} samples) each half needs more than {2 * alarm.hold} samples")
        parts.append((x[f], x[m], x[w:]))
        kept.append(i)
    own = "; ".join(f"{where_of[i]}: samples 0..{n_in[i] - 1} of {recs[i].shape[0]}"
                    for i in range(len(recs)) if n_in[i])
    if not parts:
        raise DataError(f"config: {source}: too few samples out of the plant model's own: the plant was "
                        f"identified on them ({own}), where its residuals are smaller than on new data. "
                        "Give a nominal log the plant was not identified from ([design].nominal_log), or "
                        "identify on fewer samples ([design.plant].identify.validation)")
    names_all, where_of = where_of, [where_of[i] for i in kept]
    try:
        d = _design_on(raw, groups, [p[0] for p in parts], alarm, dt, level=level, fallback=fallback,
                       source=source, smoothing=smoothing)
    except DataError as exc:
        if not own:
            raise
        raise DataError(f"{exc} (left out of the thresholds and their check, because the plant was "
                        f"identified on them: {own})") from None
    if d["warn"]:
        warnings.warn(d["warn"], UserWarning, stacklevel=3)
    per, names, thr, td, claims, smooth = _per(alarm), d["names"], d["thr"], d["td"], d["claims"], d["smooth"]

    def statistics(dd, x):
        f = dd["featurise"](x)
        return dd["smooth"].run(f) if dd["smooth"] is not None else f

    folds, record_check = [], []
    if smooth is not None and smoothing.lam is None:
        # the left-out records are judged at the deployed constant, not one each refit would choose
        from .declarative_smoothing import SmoothingSpec

        smoothing = SmoothingSpec("ewma", float(td["smoothing"]["lambda"]), smoothing.candidates)
    if len(parts) >= 2:
        for i, p in enumerate(parts):
            row = {"record": where_of[i], "samples": int(p[2].shape[0])}
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    di = _design_on(raw, groups, [q[2] for j, q in enumerate(parts) if j != i], alarm, dt,
                                    level=level, fallback=fallback, source=source, smoothing=smoothing)
            except DataError as exc:
                row["skipped"] = f"the other records cannot support the target: {str(exc)[:300]}"
                record_check.append(row)
                continue
            record_check.append(row)
            folds.append((row, di, statistics(di, p[2])))
    def fit_statistics(dd):
        return [dd["smooth"].run(f) for f in dd["f_fit"]] if dd["smooth"] is not None else dd["f_fit"]

    new_record = None
    if len(parts) >= 3 and len(folds) < 3 and per == "sample" and alarm.hold == 1:
        new_record = {"supported": False, "why": f"only {len(folds)} of {len(parts)} records could be left "
                      "out (the others could not support the target; see record_check): 3 are needed"}
    if new_record is None and len(folds) >= 3 and per == "sample" and alarm.hold == 1:
        # a user runs the monitor on a NEW record: choose each threshold so that the mean of the
        # left-out records' rates (each record weighted alike) meets the target
        for _, di, _z in folds:
            di["fit_stats"] = fit_statistics(di)
        new_record = _new_record_levels(names, fit_statistics(d),
                                        [(di["fit_stats"], z) for _, di, z in folds],
                                        float(alarm.pfa) / len(names), level)
    if new_record is not None:
        if new_record["supported"]:
            thr = np.asarray(new_record.pop("thresholds"), float)
            td = {**{k: v for k, v in td.items() if k not in ("threshold", "ci")}, "threshold": thr.tolist(),
                  "ci": new_record["ci"], "target": float(alarm.pfa) / len(names),
                  "method": "new-record quantile (leave-one-record-out)", "pooled_method": td.get("method"),
                  "pooled_threshold": np.atleast_1d(np.asarray(td["threshold"], float)).tolist(),
                  "new_record": new_record}
            ew = f", EWMA lambda {td['smoothing']['lambda']:g}" if smooth is not None else ""
            claims = _claims(names, td, alarm, f"nominal logs (new record: leave-one-record-out{ew})")
            for c in claims:
                c["per_what"] = "sample on a new record"
                c["rests_on"] = new_record["rests_on"] + (f"; the statistics are the EWMA (lambda "
                                                          f"{td['smoothing']['lambda']:g}) of the features"
                                                          if smooth is not None else "")
                if smooth is not None:
                    c["smoothing"] = {"kind": "ewma", "lambda": td["smoothing"]["lambda"]}
            claims[len(names)]["interval"] = new_record["family"]["interval"]
            claims[len(names)]["method"] = "mean over the left-out records of their any-threshold rate"
        else:
            td = {**td, "new_record": new_record}
            warnings.warn(f"design: the thresholds cannot be set for the target pfa = {alarm.pfa:g} per "
                          f"sample on a new record ({new_record['why']}): the pooled thresholds are kept, "
                          "their claim is the pooled records' rate, not a new record's", UserWarning,
                          stacklevel=3)
    f_meas = [statistics(d, p[1]) for p in parts]
    hold = Hold(names, thr, Z=alarm.hold, absolute=True)
    for c, m in zip(claims, _measure(claims, hold, f_meas, per, dt, level)):
        if m is not None:
            c["measured"] = m
            c["verdict"] = verdict(c["interval"], m["interval"])
    if folds:
        loro = []
        for row, di, z in folds:
            t_i = di["thr"] if new_record is None or not new_record["supported"] else \
                [_level_limit(di["fit_stats"], k, q) for k, q in enumerate(new_record["levels"])]
            al = Hold(di["names"], np.asarray(t_i, float), Z=alarm.hold, absolute=True).run(z).values[0]
            loro.append(al)
            row["thresholds"] = np.atleast_1d(np.asarray(t_i, float)).tolist()
            row["rate"] = float(np.mean(np.any(al > 0.5, axis=1)))    # any threshold, per sample
        for c in claims:
            if c["kind"] == "decision" or not loro:
                continue
            idx = [hold.output_names.index(n) for n in c["channels"]]   # same names in every refit
            m = measure_alarm_rate([np.any(al[:, idx] > 0.5, axis=1) for al in loro], per, dt, level=level)
            c["measured_records"] = {**{k: m[k] for k in ("rate", "interval", "events", "samples", "hours",
                                                          "interval_method")}, "records": len(loro),
                                     "how": "each record left out in turn: whitening and thresholds refitted "
                                            "on the others (whole, after the warm-up), measured on it"}
            c["verdict_records"] = verdict(c["interval"], m["interval"])
            if c.get("verdict", "inside") == "inside":
                c["verdict"] = c["verdict_records"]
    bad = [c for c in claims if c.get("verdict", "inside") != "inside"]
    if bad:
        def line(c):
            out = f"{c['name']}: claimed {c['interval'][0]:.3g}..{c['interval'][1]:.3g} per {c['per']}"
            for key, what in (("measured", "held-out halves"), ("measured_records", "left-out records")):
                if key in c:
                    m = c[key]
                    out += (f", measured {m['rate']:.3g} ({m['interval'][0]:.3g}..{m['interval'][1]:.3g}) on "
                            f"the {what}")
            return out + f", {c['verdict']}"
        msg = (f"the held-out half of the nominal logs (or a left-out record) contradicts {len(bad)} "
               f"claim(s): {'; '.join(line(c) for c in bad)}. "
               "The nominal logs are not stationary enough for these thresholds (records at their own "
               "levels, or too short)")
        if not accept_miscalibrated:
            raise DataError(f"config: {source}: {msg}. Refused; set "
                            "[design].accept_miscalibrated = true to keep it anyway (with a warning)")
        warnings.warn(f"design: {msg}. Kept because [design].accept_miscalibrated = true", UserWarning,
                      stacklevel=3)
    never = {name: [0, k] for name, k in zip(names_all, n_in) if k > 0}
    return {"white": d["white"], "features": d["features"], "thr": thr, "td": td, "claims": claims,
            "records": len(parts), "smooth": smooth, "names": names, "in_sample": never,
            "record_check": record_check, "new_record": new_record,
            "fit_hours": sum(f.n_samples for f in d["f_fit"]) * dt / 3600.0,
            "measure_hours": sum(f.n_samples for f in f_meas) * dt / 3600.0}
