"""Re-measuring a saved design's false-alarm claims on new nominal logs (``fdikit validate``).

A design states claims in its ``design_report.json`` (``claims``: a declarative design's
thresholds, their family and its announcements, see
:mod:`fdikit.monitor.declarative_thresholds`; a recipe's own ``_report``). :func:`validate` runs
the monitor the config builds over each nominal log, measures every claim on the judged samples
(warm-up and held samples left out) with its interval (:mod:`fdikit.detect.rates`: Clopper-Pearson
on effective samples per sample, over the logs per run, exact Poisson on onsets per unit of time)
and gives the verdict per claim: ``inside`` (the measured interval meets the claimed one),
``above`` (more false alarms than claimed) or ``below``. The announcements per hour are always
measured, claimed or not.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals

__all__ = ["announcement_claim", "claims_table", "validate"]


def _runs(cfg, logs) -> list[tuple[str, Signals]]:
    from ..monitor.config import map_channels, read_log

    if isinstance(logs, str | Path | Signals):
        logs = [logs]
    if not len(logs):
        raise DataError("validate: no nominal log given")
    out = []
    for i, lg in enumerate(logs):
        if isinstance(lg, Signals):
            name, raw = f"log {i}", lg
        else:
            name = str(lg)
            if not Path(lg).is_file():
                raise DataError(f"{lg}: no such log file")
            raw = read_log(cfg, lg)
        missing = [f"{c.name} (source column {c.source!r})" for c in cfg.channels
                   if c.source not in raw.names]
        if missing:
            raise DataError(f"{name}: the log lacks the channel(s) {', '.join(missing)} of {cfg.path}; it "
                            f"has {list(raw.names)}")
        out.append((name, map_channels(cfg, raw)))
    return out


def _measure(claim: dict, results: list, level: float) -> dict:
    from ..detect.rates import measure_alarm_rate, per_seconds, poisson_interval, proportion_interval

    per = claim["per"]
    if claim["kind"] == "decision" or not claim.get("channels"):
        unit = per_seconds(per) if per not in ("sample", "run") else None
        k = n = 0
        runs = hits = 0
        for _name, dt, res, judged in results:
            for r in range(judged.shape[0]):
                ev = [e for e in res.events if e.run == r]
                k += len(ev)
                hits += bool(ev)
                runs += 1
            n_judged = int(judged.sum())
            n += n_judged * dt
        if per == "run":
            return {"rate": hits / runs, "interval": list(proportion_interval(hits, runs, level)),
                    "events": hits, "hours": n / 3600.0,
                    "interval_method": "Clopper-Pearson over the logs (runs)"}
        unit = unit or 3600.0
        if n <= 0:
            raise DataError("every sample of the nominal logs is in warm-up or held: nothing to measure")
        return {"rate": k / (n / unit), "interval": list(poisson_interval(k, n / unit, level)), "events": k,
                "hours": n / 3600.0, "interval_method": "exact Poisson (Garwood) on announcements"}
    recs = []
    dts = set()
    for name, dt, res, judged in results:
        st = res.statistics
        missing = [c for c in claim["channels"] if c not in st.names]
        if missing:
            raise DataError(f"claim {claim['name']!r}: the monitor does not output the statistics {missing} "
                            f"(log {name}); is design_report.json from another design? Rerun 'fdikit design'")
        on = np.any(st.values[:, :, st.index(claim["channels"])] > 0.5, axis=2).astype(float)
        recs.extend(np.where(judged, on, np.nan))
        dts.add(round(dt, 12))
    m = measure_alarm_rate(recs, per, min(dts), level=level)
    return {k: m[k] for k in ("rate", "interval", "events", "samples", "hours", "interval_method")
            if k in m} | ({"n_eff": m["n_eff"]} if "n_eff" in m else {})


def announcement_claim(results: Any, basis: str, *, level: float = 0.95, per: str = "hour",
                       name: str = "decision (announcements)") -> dict[str, Any]:
    """The announcement-rate claim of a design, from its monitor run over nominal design data.

    For a design that decides (announces faults) without a designed false-alarm rate, e.g. a
    recipe whose MHSSPT densities and hold were calibrated on nominal records: the announcements
    its monitor makes on those records (or on other nominal data the design generated) give the
    claimed rate and its exact Poisson interval, which :func:`validate` then checks on logs the
    design never saw. On the design's own data the claim is optimistic (in-sample), which the
    out-of-sample measurement shows.

    Parameters
    ----------
    results : MonitorResult or sequence of MonitorResult
        The monitor's results on nominal data (every run a record); samples in warm-up or held
        (``status != 0``, or ``valid`` False) are not counted.
    basis : str
        What the data were (printed in the report).
    level : float
        Confidence level of the interval.
    per : str
        Time unit of the rate (``"hour"``, ``"minute"``, ...).
    name : str
        The claim's name.

    Returns
    -------
    dict
        A ``kind="decision"`` claim: ``per``, ``target`` (None: no designed target), ``interval``,
        ``rate``, ``events``, ``hours`` (judged), ``basis``, ``method``.

    Examples
    --------
    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> res = SimpleNamespace(events=[], status=np.zeros((1, 360_000)), t=np.arange(360_000) * 0.01)
    >>> # a MonitorResult (Monitor.run) has the same events and status, its time in residuals.t
    >>> c = announcement_claim(res, "an hour of simulated nominal driving")
    >>> c["events"], [round(v, 3) for v in c["interval"]]
    (0, [0.0, 3.689])
    """
    from ..detect.rates import per_seconds, poisson_interval

    unit = per_seconds(per)
    if unit is None:
        raise DataError(f"announcement_claim: per must be a unit of time (e.g. 'hour'), got {per!r}")
    items = list(results) if isinstance(results, list | tuple) else [results]
    k, seconds = 0, 0.0
    for i, res in enumerate(items):
        judged = np.asarray(res.status == 0 if getattr(res, "status", None) is not None else res.valid, bool)
        t = np.asarray(res.t if hasattr(res, "t") else res.residuals.t, float)
        if t.size < 2:
            raise DataError(f"announcement_claim: result {i} has {t.size} sample(s); nominal design data "
                            "need many")
        k += len(res.events)
        seconds += float(judged.sum()) * float(np.median(np.diff(t)))
    if seconds <= 0:
        raise DataError("announcement_claim: every sample is in warm-up or held: nothing to claim from")
    lo, hi = poisson_interval(k, seconds / unit, level)
    return {"name": name, "kind": "decision", "channels": [], "per": per, "target": None,
            "interval": [float(lo), float(hi)], "rate": k / (seconds / unit), "events": int(k),
            "hours": seconds / 3600.0, "basis": basis,
            "method": f"{k} announcement(s) in {seconds:.4g} s judged of the design's nominal data; exact "
                      f"Poisson (Garwood) {level:.0%} interval"}


def validate(config, logs, *, level: float = 0.95) -> dict[str, Any]:
    """Re-measure every false-alarm claim of a saved design on new nominal logs.

    Parameters
    ----------
    config : str, Path or MonitorConfig
        The monitor config; its artifacts (``fdikit design CONFIG``) and their
        ``design_report.json`` hold the design and its claims.
    logs : path, Signals, or a sequence of them
        Nominal (fault-free) logs in the config's log format (a Signals: the log's source channels,
        as :func:`fdikit.monitor.config.read_log` returns); every run is a record.
    level : float
        Confidence level of the measured intervals.

    Returns
    -------
    dict
        ``config``, ``logs``, ``samples`` and ``hours`` (judged), ``claims`` (each claim with its
        ``measured`` rate and interval and its ``verdict``; an announcement row with ``claimed``
        None when the design states no decision rate), ``contradicted`` (claims whose verdict is
        not ``inside``), ``rates`` (model-based or measured, as the design says).

    Raises
    ------
    DataError
        A config or design not found (naming what to run), a log that is missing or lacks a
        channel (naming the log and the channel), a claim naming a statistic the monitor lacks.
    """
    from ..detect.rates import verdict
    from ..monitor.config import MonitorConfig, build_monitor, load_config

    cfg = config if isinstance(config, MonitorConfig) else load_config(config)
    if not (cfg.artifacts / f"{(cfg.generators or ['?'])[0]}.json").exists():
        raise DataError(f"{cfg.path}: no saved design in {cfg.artifacts}; run 'fdikit design {cfg.path}' "
                        "first")
    rpath = cfg.artifacts / "design_report.json"
    report = json.loads(rpath.read_text()) if rpath.exists() else {}
    claims = [dict(c) for c in report.get("claims", [])]
    results = []
    for name, sig in _runs(cfg, logs):
        res = build_monitor(cfg).run(sig)
        judged = res.status == 0 if res.status is not None else np.asarray(res.valid, bool)
        dt = float(np.median(np.diff(sig.t))) if sig.n_samples > 1 else 0.0
        results.append((name, dt, res, judged))
    if not any(c["kind"] == "decision" for c in claims):
        per = next((c["per"] for c in claims if c["per"] not in ("sample",)), "hour")
        claims.append({"name": "decision (announcements)", "kind": "decision", "channels": [], "per": per,
                       "target": None, "interval": None, "basis": "none stated"})
    for c in claims:
        c["measured"] = _measure(c, results, level)
        c["verdict"] = "no claim" if c.get("interval") is None else verdict(c["interval"],
                                                                             c["measured"]["interval"])
    bad = [c["name"] for c in claims if c["verdict"] in ("above", "below")]
    n = int(sum(int(j.sum()) for *_, j in results))
    return {"config": str(cfg.path), "logs": [r[0] for r in results], "samples": n,
            "hours": float(sum(r[1] * r[3].sum() for r in results)) / 3600.0,
            "rates": report.get("rates", "not stated"), "claims": claims, "contradicted": bad,
            "confidence": level}


def _per(per) -> str:
    return per if isinstance(per, str) else f"{per:g} s"


def claims_table(result: dict[str, Any]) -> list[str]:
    """Text lines of a :func:`validate` result: claimed and measured side by side, per claim.

    Examples
    --------
    >>> r = {"config": "m.toml", "logs": ["a.csv"], "hours": 0.5, "rates": "model-based", "contradicted": [],
    ...      "claims": [{"name": "threshold r1", "per": "hour", "target": 0.1, "interval": [0.0, 0.1],
    ...                  "measured": {"rate": 0.0, "interval": [0.0, 7.38], "events": 0},
    ...                  "verdict": "inside"}]}
    >>> print(claims_table(r)[-1])
    threshold r1                   hour        0.1  [0, 0.1]                  0  [0, 7.38]         0  inside
    """
    lines = [f"{result['config']}: {len(result['logs'])} nominal log(s), {result['hours']:.3g} h judged; "
             f"rates {result['rates']}",
             f"{'claim':<30} {'per':<6} {'target':>8}  {'claimed':<18} {'measured':>6}  {'interval':<15} "
             f"{'events':>3}  verdict"]
    for c in result["claims"]:
        iv = c.get("interval")
        ci = "-" if iv is None else f"[{iv[0]:.3g}, {iv[1]:.3g}]"
        m = c["measured"]
        tg = "-" if c.get("target") is None else f"{c['target']:.3g}"
        mi = f"[{m['interval'][0]:.3g}, {m['interval'][1]:.3g}]"
        lines.append(f"{c['name'][:30]:<30} {_per(c['per']):<6} {tg:>8}  {ci:<18} {m['rate']:>8.3g}  "
                     f"{mi:<15} {m['events']:>3}  {c['verdict']}")
    return lines

