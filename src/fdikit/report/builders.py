"""Reports of monitor runs and campaigns, built from results in memory or from saved files.

* :func:`monitor_report` -- one monitor run: metadata (config, design hash, fdikit version, log
  and channels), signals with held and invalid samples shaded, residuals with their thresholds,
  test statistics, fault probabilities, the events timeline, an optional signature matrix;
* :func:`campaign_report` -- a campaign's JSON (e.g. ``fdikit abs campaign --json``): Pd/Pf per
  test and class, the D-matrix, the confusion matrix, sensitivity and specificity, detection-time
  histograms and, where a threshold was swept, ROC curves;
* :func:`report_from_files` -- either of them from files (``fdikit monitor --events/--stats``,
  the log and the config, or a campaign JSON), for ``fdikit report``.

The ``add_*`` functions put the same sections into a :class:`~fdikit.report.Report` being built
(``fdikit demo`` collects all of its sections into one page that way); they live beside this
module: :mod:`.events`, :mod:`.monitor_sections`, :mod:`.campaign` and :mod:`.signature`, with
the readers of saved results in :mod:`.saved`. Every name of this module's former content is
importable from here.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals
from .campaign import add_campaign, add_roc, roc_curve
from .events import add_events, episode_spans, event_records, read_events_jsonl
from .html import Report, check_output_path
from .monitor_sections import PANELS_PER_FIGURE as PANELS_PER_FIGURE
from .monitor_sections import add_monitor, monitor_thresholds
from .saved import _manifest, _manifest_thresholds, _read_stats
from .signature import add_signature as add_signature

__all__ = [
    "add_campaign",
    "add_events",
    "add_monitor",
    "add_roc",
    "campaign_report",
    "design_hash",
    "episode_spans",
    "event_records",
    "monitor_report",
    "monitor_thresholds",
    "read_events_jsonl",
    "report_from_files",
    "roc_curve",
]


# ---------------------------------------------------------------------------------------- helpers
def _version() -> str:
    from .. import __version__

    return __version__


def design_hash(artifact_paths: Sequence[str | os.PathLike]) -> str | None:
    """SHA-256 (first 16 hex digits) of the design artifacts' files (JSON manifest and NPZ arrays),
    in the given order; None when any of them is missing."""
    h = hashlib.sha256()
    for a in artifact_paths:
        stem = Path(a)
        stem = stem.with_suffix("") if stem.suffix in (".json", ".npz") else stem
        js = stem.with_suffix(".json")
        if not js.is_file():
            return None
        for f in (js, stem.with_suffix(".npz")):
            if f.is_file():
                h.update(f.name.encode())
                h.update(f.read_bytes())
    return h.hexdigest()[:16]

# ------------------------------------------------------------------------------ whole reports
def _metadata(rep: Report, meta: Mapping[str, Any], config_text: str | None = None) -> None:
    rep.section("Run", "What ran, on what, with which design.")
    info = {
        "fdikit version": _version(),
        "generated (UTC)": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S"),
        **meta,
    }
    rep.table(info)
    rep.data["metadata"] = {
        k: (v if isinstance(v, int | float | str | type(None)) else str(v)) for k, v in info.items()
    }
    if config_text is not None:
        rep.pre(config_text, summary="configuration file")


def _channels_table(rep: Report, sig: Signals, sources: Mapping[str, str] | None = None) -> None:
    rows = []
    for j, (n, u) in enumerate(zip(sig.names, sig.units)):
        v = sig.values[..., j]
        fin = v[np.isfinite(v)]
        rows.append(
            {
                "channel": n,
                "unit": u or "–",
                "source": (sources or {}).get(n, n),
                "min": float(fin.min()) if fin.size else None,
                "max": float(fin.max()) if fin.size else None,
                "invalid samples": int((~np.isfinite(v)).sum()),
            }
        )
    rep.table(rows, caption="channels")
    rep.data["channels"] = [{"name": r["channel"], "unit": r["unit"], "source": r["source"]} for r in rows]


def monitor_report(
    path: str | os.PathLike,
    *,
    signals: Signals | None = None,
    result: Any = None,
    monitor: Any = None,
    config: Any = None,
    log: str | os.PathLike | None = None,
    design: str | None = None,
    title: str | None = None,
    meta: Mapping[str, Any] | None = None,
    **kw,
) -> Path:
    """Write the HTML report of one monitor run.

    Parameters
    ----------
    path : path-like
        The ``.html`` file to write (checked first: folder exists and is writable).
    signals : Signals, optional
        The monitor's input channels.
    result : MonitorResult, optional
        What the monitor returned (residuals, statistics, events, held samples).
    monitor : Monitor, optional
        For the thresholds (:func:`monitor_thresholds`) and the announcement level.
    config : path or MonitorConfig, optional
        The configuration: its text, channel sources and the hash of its design artifacts.
    log : path, optional
        The log that was read (named in the metadata).
    design : str, optional
        A design hash to show (default: computed from the config's artifacts when there are).
    title : str, optional
    meta : mapping, optional
        More metadata rows.
    **kw
        Passed to :func:`add_monitor` (``residuals``, ``statistics``, ``events``, ``valid``,
        ``invalid``, ``thresholds``, ``level``, ``signal_valid``, ``signature``, ``run``).

    Returns
    -------
    Path
    """
    p = check_output_path(path)
    cfg = None
    if config is not None:
        from ..monitor.config import MonitorConfig, load_config

        cfg = config if isinstance(config, MonitorConfig) else load_config(config)
    rep = Report(title or (f"fdikit monitor report: {cfg.name}" if cfg else "fdikit monitor report"))
    info: dict[str, Any] = {}
    if cfg is not None:
        info["config"] = str(cfg.path)
        info["monitor"] = cfg.name
        if design is None:
            design = design_hash([cfg.artifacts / a for a in (*cfg.generators, *cfg.processors)])
            info["design hash (sha256 of the artifacts)"] = design or "no design artifacts found"
        info["artifacts"] = ", ".join([*cfg.generators, *cfg.processors])
    if design is not None and "design hash (sha256 of the artifacts)" not in info:
        info["design hash"] = design
    if log is not None:
        info["log"] = str(log)
    ref = signals if signals is not None else getattr(result, "statistics", None)
    if ref is not None and ref.n_samples:
        info["samples"] = ref.n_samples
        info["duration (s)"] = float(ref.t[-1] - ref.t[0])
        info["sample time (s)"] = ref.dt
    info.update(meta or {})
    if monitor is not None:
        kw.setdefault("thresholds", monitor_thresholds(monitor))
        dec = getattr(monitor, "decision", None)
        if dec is not None and getattr(dec, "level", None) is not None:
            kw.setdefault("level", float(dec.level))
    config_text = cfg.path.read_text() if cfg is not None and cfg.path.is_file() else None
    _metadata(rep, info, config_text)
    if signals is not None:
        _channels_table(rep, signals, {c.name: c.source for c in cfg.channels} if cfg else None)
    counts = add_monitor(rep, signals=signals, result=result, **kw)
    rep.data["counts"] = counts
    return rep.write(p)


def campaign_report(
    campaign: Mapping[str, Any],
    path: str | os.PathLike,
    *,
    title: str | None = None,
    source: str | None = None,
) -> Path:
    """Write the HTML report of a campaign (the dict of ``fdikit abs campaign --json``).

    Raises
    ------
    DataError
        When ``campaign`` has none of the recognised keys (see :func:`add_campaign`).
    """
    p = check_output_path(path)
    rep = Report(title or "fdikit campaign report")
    _metadata(rep, {"campaign": source or "(in memory)"})
    add_campaign(rep, campaign, where=source or "campaign")
    return rep.write(p)

def report_from_files(
    path: str | os.PathLike,
    *,
    events: str | os.PathLike | None = None,
    stats: str | os.PathLike | None = None,
    log: str | os.PathLike | None = None,
    config: str | os.PathLike | None = None,
    campaign: str | os.PathLike | None = None,
    title: str | None = None,
) -> dict:
    """Build a report from saved results (what ``fdikit report`` does).

    Either ``campaign`` (a campaign JSON file), or any of ``events`` (JSON Lines of ``fdikit
    monitor --events``), ``stats`` (Parquet of ``--stats``), ``log`` (read with ``config`` when
    given, which also names the channels' units and sources and the design artifacts).

    Returns
    -------
    dict
        ``report`` (path), ``kind`` (``"campaign"`` or ``"monitor"``), ``figures``, ``events``.
    """
    p = check_output_path(path)
    if campaign is not None:
        if any(x is not None for x in (events, stats, log)):
            raise DataError("a campaign report takes the campaign JSON alone (not --events/--stats/--log)")
        cp = Path(campaign)
        if not cp.is_file():
            raise DataError(f"{cp}: no such campaign file")
        try:
            obj = json.loads(cp.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DataError(f"{cp}: not JSON ({exc})") from None
        rep = Report(title or f"fdikit campaign report: {cp.name}")
        _metadata(rep, {"campaign": str(cp)})
        add_campaign(rep, obj, where=str(cp))
        rep.write(p)
        return {"report": str(p), "kind": "campaign", "figures": rep.n_figures}
    if events is None and stats is None and log is None:
        raise DataError("nothing to report: give --campaign, or --events, --stats and/or --log")
    cfg = None
    if config is not None:
        from ..monitor.config import load_config

        cfg = load_config(config)
    ev, held_recs = read_events_jsonl(events) if events is not None else ([], [])
    signals = signal_valid = None
    if log is not None:
        lp = Path(log)
        if not lp.is_file():
            raise DataError(f"{lp}: no such log file")
        if cfg is not None:
            from ..monitor.config import map_channels, read_log

            raw = read_log(cfg, lp)
            signals = map_channels(cfg, raw)
            v = getattr(raw, "valid", None)
            if v is not None:
                v = np.asarray(v, bool)
                idx = raw.index([c.source for c in cfg.channels])
                signal_valid = v[..., idx] if v.ndim >= 2 else v
        else:
            from .. import io

            signals = io.read_log(lp)
            signal_valid = getattr(signals, "valid", None)
    residuals = statistics = None
    valid = None
    if stats is not None:
        sp = Path(stats)
        t, cols, valid = _read_stats(sp)
        res_names: list[str] = []
        if cfg is not None:
            for a in cfg.generators:
                man = _manifest(cfg.artifacts / a)
                outs = ((man or {}).get("channels") or {}).get("outputs") or []
                res_names += [n for n in outs if n in cols and n not in res_names]
        stat_names = [n for n in cols if n not in res_names]
        if res_names:
            residuals = Signals(t, np.column_stack([cols[n] for n in res_names]), res_names, check=False)
        if stat_names:
            statistics = Signals(t, np.column_stack([cols[n] for n in stat_names]), stat_names, check=False)
        if signals is not None and signals.n_samples != t.size:
            raise DataError(
                f"{sp}: {t.size} samples, but the log {log} gives {signals.n_samples}: results of "
                "another log?"
            )
    thresholds: dict[str, tuple[float, bool]] = {}
    level = None
    if cfg is not None:
        for a in cfg.processors:
            thresholds.update(_manifest_thresholds(_manifest(cfg.artifacts / a)))
        if cfg.decision is not None:
            level = float(cfg.decision.get("level", 0.5))
    out = monitor_report(
        p,
        signals=signals,
        residuals=residuals,
        statistics=statistics,
        events=ev,
        valid=valid,
        invalid=held_recs,
        config=cfg,
        log=log,
        thresholds=thresholds,
        level=level,
        signal_valid=signal_valid,
        title=title,
        meta={k: str(v) for k, v in (("events file", events), ("statistics file", stats)) if v is not None},
    )
    return {"report": str(out), "kind": "monitor", "events": sum(e["kind"] == "onset" for e in ev),
            "cleared": sum(e["kind"] == "cleared" for e in ev), "held_samples": len(held_recs)}
