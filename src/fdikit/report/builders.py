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
(``fdikit demo`` collects all of its sections into one page that way).
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
from .decimate import true_intervals
from .html import Report, check_output_path, heatmap_figure, stacked_time_figure

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

#: Channels per stacked figure: beyond it a group is split into several figures.
PANELS_PER_FIGURE = 12


# ---------------------------------------------------------------------------------------- helpers
def _version() -> str:
    from .. import __version__

    return __version__


def event_records(events: Sequence[Any]) -> list[dict]:
    """Events as dicts ``{t, run, sample, hypothesis, value, kind, episode, size}`` (from
    :class:`fdikit.monitor.Event` objects, or dicts as ``fdikit monitor --events`` writes them;
    held-sample and gap records dropped). ``kind`` is ``"onset"`` (an announcement) or
    ``"cleared"``; records of an older fdikit, which had no kind, are onsets."""
    out = []
    for e in events:
        if isinstance(e, Mapping):
            if "invalid" in e or e.get("gap") or "hypothesis" not in e:
                continue
            size = e.get("size")
            out.append(
                {
                    "t": float(e["t"]),
                    "run": int(e.get("run", 0)),
                    "sample": e.get("sample", e.get("k")),
                    "hypothesis": str(e["hypothesis"]),
                    "value": e.get("value"),
                    "kind": str(e.get("kind", "onset")),
                    "episode": e.get("episode"),
                    "size": None if size is None else float(size),
                }
            )
        else:
            size = getattr(e, "size", None)
            out.append(
                {
                    "t": float(e.t),
                    "run": int(e.run),
                    "sample": int(e.k),
                    "hypothesis": str(e.hypothesis),
                    "value": float(e.value),
                    "kind": str(getattr(e, "kind", "onset")),
                    "episode": getattr(e, "episode", None),
                    "size": None if size is None else float(size),
                }
            )
    out.sort(key=lambda d: (d["t"], d["run"], d["hypothesis"], d["kind"] != "onset"))
    return out


def episode_spans(events: Sequence[Mapping[str, Any]], t_end: float | None = None) -> list[dict]:
    """Pair each onset with its cleared event: ``{hypothesis, run, t_onset, t_cleared, open}``.

    An episode with no cleared event is still open at the end of the record (``t_end``, or its
    onset time when ``t_end`` is not given).

    Examples
    --------
    >>> ev = [{"t": 1.0, "run": 0, "hypothesis": "a", "kind": "onset", "episode": 0},
    ...       {"t": 3.0, "run": 0, "hypothesis": "a", "kind": "cleared", "episode": 0},
    ...       {"t": 5.0, "run": 0, "hypothesis": "a", "kind": "onset", "episode": 1}]
    >>> [(e["t_onset"], e["t_cleared"], e["open"]) for e in episode_spans(ev, 9.0)]
    [(1.0, 3.0, False), (5.0, 9.0, True)]
    """
    open_: dict[tuple, dict] = {}
    out: list[dict] = []
    for e in sorted(events, key=lambda d: (d["t"], d.get("kind", "onset") != "onset")):
        key = (e.get("run", 0), e["hypothesis"])
        if e.get("kind", "onset") == "onset":
            if key in open_:  # an onset without a cleared event before it: close the old one here
                out.append({**open_.pop(key), "t_cleared": float(e["t"]), "open": False})
            open_[key] = {"hypothesis": e["hypothesis"], "run": key[0], "t_onset": float(e["t"]),
                          "size": e.get("size")}
        elif key in open_:
            out.append({**open_.pop(key), "t_cleared": float(e["t"]), "open": False})
    for ep in open_.values():
        out.append({**ep, "t_cleared": float(t_end) if t_end is not None else ep["t_onset"], "open": True})
    out.sort(key=lambda d: (d["t_onset"], d["hypothesis"]))
    return out


def read_events_jsonl(path: str | os.PathLike) -> tuple[list[dict], list[dict]]:
    """Read an events file of ``fdikit monitor --events``: (announcements, held-sample records).

    Raises
    ------
    DataError
        Missing file, or a line that is not a JSON object (naming the file and line).
    """
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such events file")
    ann, held = [], []
    with p.open() as fh:
        for lineno, line in enumerate(fh, start=1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError as exc:
                raise DataError(f"{p}, line {lineno}: not JSON ({exc.msg})") from None
            if not isinstance(rec, dict):
                raise DataError(f"{p}, line {lineno}: expected a JSON object, got {type(rec).__name__}")
            if "invalid" in rec:
                held.append(rec)
            elif rec.get("gap"):  # a time gap: its missing samples were held ("cannot judge")
                continue
            elif "hypothesis" in rec and "t" in rec:
                ann.append(rec)
            else:
                raise DataError(
                    f"{p}, line {lineno}: neither an announcement (keys t, hypothesis) nor a "
                    f"held sample (key invalid): keys {sorted(rec)}"
                )
    return event_records(ann), held


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


def monitor_thresholds(monitor: Any) -> dict[str, tuple[float, bool]]:
    """Thresholds of a monitor's processors: ``{channel: (threshold, absolute)}``.

    Any processor with ``input_names`` and a ``threshold`` (one or one per input, e.g.
    :class:`fdikit.detect.Hold`) contributes; ``absolute`` says the rule is ``|x| > threshold``.
    """
    out: dict[str, tuple[float, bool]] = {}
    for p in getattr(monitor, "processors", []) or []:
        names = getattr(p, "input_names", None)
        thr = getattr(p, "threshold", None)
        if not names or thr is None:
            continue
        try:
            thr = np.broadcast_to(np.asarray(thr, float), (len(names),))
        except ValueError:
            continue
        for n, v in zip(names, thr):
            if np.isfinite(v):
                out[str(n)] = (float(v), bool(getattr(p, "absolute", False)))
    return out


def _kind(name: str, y: np.ndarray) -> str:
    """``"binary"`` (an alarm, 0/1), ``"probability"`` (``P:...`` in [0, 1]) or ``"statistic"``."""
    fin = y[np.isfinite(y)]
    zero_one = fin.size == 0 or bool(np.all((fin == 0) | (fin == 1)))
    alarm_name = name.endswith((":alarm", ":gated")) or ":alarm:" in name or name.startswith("A:")
    if alarm_name and zero_one:
        return "binary"
    if name.startswith("P:") and (fin.size == 0 or (fin.min() >= -1e-9 and fin.max() <= 1 + 1e-9)):
        return "probability"
    if zero_one and fin.size:
        return "binary"
    return "statistic"


def _panels(
    sig: Signals,
    run: int,
    thresholds: Mapping[str, tuple[float, bool]] | None = None,
    invalid: Mapping[str, list] | None = None,
) -> list[dict]:
    panels = []
    for j, (n, u) in enumerate(zip(sig.names, sig.units)):
        p: dict[str, Any] = {"title": n, "ylabel": n, "unit": u, "traces": [(n, sig.values[run, :, j])]}
        if thresholds and n in thresholds:
            v, absolute = thresholds[n]
            p["thresholds"] = [("threshold", v)] + ([("-threshold", -v)] if absolute else [])
        if invalid and invalid.get(n):
            p["invalid"] = invalid[n]
        panels.append(p)
    return panels


def _stacked(
    rep: Report, t, panels: list[dict], title: str, *, held=(), events=(), caption: str | None = None
):
    for i in range(0, len(panels), PANELS_PER_FIGURE):
        chunk = panels[i : i + PANELS_PER_FIGURE]
        part = "" if len(panels) <= PANELS_PER_FIGURE else f" ({i // PANELS_PER_FIGURE + 1})"
        rep.figure(
            stacked_time_figure(
                t, chunk, title=title + part, held=held, events=events, max_points=rep.max_points
            ),
            caption=caption,
        )


def _held_mask(T: int, run: int, valid=None, invalid=None) -> np.ndarray:
    held = np.zeros(T, bool)
    if valid is not None:
        v = np.asarray(valid, bool)
        v = v[run] if v.ndim == 2 else v
        if v.shape == (T,):
            held |= ~v
    for rec in invalid or ():
        if isinstance(rec, Mapping):
            r, k = int(rec.get("run", 0)), rec.get("sample")
        else:
            r, k = int(rec[0]), rec[1]
        if r == run and k is not None and 0 <= int(k) < T:
            held[int(k)] = True
    return held


# ------------------------------------------------------------------------------------ sections
def add_events(
    rep: Report,
    events: Sequence[Any],
    t_range: tuple[float, float] | None = None,
    *,
    held: Sequence[tuple[float, float]] = (),
    title: str = "Events",
) -> list[dict]:
    """The events timeline and the event table.

    One row per hypothesis: each fault episode is a bar from its onset (a diamond: the
    announcement) to its cleared event (a circle), or to the end of the record while it is still
    open; held stretches of samples ("cannot judge") are a grey row. Returns the event records
    (onsets and cleared events)."""
    ev = event_records(events)
    onsets = [e for e in ev if e["kind"] == "onset"]
    cleared = [e for e in ev if e["kind"] == "cleared"]
    spans = episode_spans(ev, t_range[1] if t_range is not None else None)
    rep.section(
        title,
        f"{len(onsets)} announcement(s) (fault episodes), {len(cleared)} cleared"
        + (f", {len(held)} held stretch(es) of samples" if held else "")
        + ". Each episode is a bar from its announcement (diamond) to its cleared event (circle).",
    )
    rows = sorted({e["hypothesis"] for e in ev})
    data: list[dict] = []
    if held:
        xs: list[float | None] = []
        for a, b in held:
            xs += [a, b, None]
        data.append(
            {
                "type": "scatter",
                "mode": "lines",
                "name": "held samples",
                "x": xs,
                "y": ["held samples" if x is not None else None for x in xs],
                "line": {"width": 10, "color": "rgba(120,120,120,0.6)"},
            }
        )
    for h in rows:
        sp = [e for e in spans if e["hypothesis"] == h]
        if sp:
            xs = []
            for e in sp:
                xs += [e["t_onset"], e["t_cleared"], None]
            data.append(
                {
                    "type": "scatter",
                    "mode": "lines",
                    "name": f"{h} episodes",
                    "x": xs,
                    "y": [h if x is not None else None for x in xs],
                    "line": {"width": 6},
                    "opacity": 0.45,
                    "hoverinfo": "skip",
                }
            )
        es = [e for e in onsets if e["hypothesis"] == h]
        data.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": h,
                "x": [e["t"] for e in es],
                "y": [h] * len(es),
                "marker": {"size": 11, "symbol": "diamond"},
                "text": [f"{h} announced at t = {e['t']:.3f} s (run {e['run']}, value {e['value']}"
                         + (f", size {e['size']:.4g}" if e["size"] is not None else "") + ")" for e in es],
                "hoverinfo": "text",
            }
        )
        cs = [e for e in cleared if e["hypothesis"] == h]
        if cs:
            data.append(
                {
                    "type": "scatter",
                    "mode": "markers",
                    "name": f"{h} cleared",
                    "x": [e["t"] for e in cs],
                    "y": [h] * len(cs),
                    "marker": {"size": 9, "symbol": "circle-open"},
                    "text": [f"{h} cleared at t = {e['t']:.3f} s" for e in cs],
                    "hoverinfo": "text",
                }
            )
    if not data:
        data.append({"type": "scatter", "mode": "markers", "name": "no events", "x": [], "y": []})
    layout: dict[str, Any] = {
        "title": {"text": "events timeline"},
        "height": int(160 + 34 * (len(rows) + 1)),
        "margin": {"l": 170, "r": 30, "t": 50, "b": 50},
        "xaxis": {"title": {"text": "time (s)"}},
        "yaxis": {"title": {"text": "announced fault (–)"}, "type": "category"},
        "showlegend": False,
    }
    if t_range is not None:
        layout["xaxis"]["range"] = [t_range[0], t_range[1]]
    rep.figure({"data": data, "layout": layout})
    if spans:
        rep.table(
            [
                {
                    "onset t (s)": round(e["t_onset"], 4),
                    "cleared t (s)": "open" if e["open"] else round(e["t_cleared"], 4),
                    "run": e["run"],
                    "hypothesis (fault)": e["hypothesis"],
                    "size": None if e.get("size") is None else round(float(e["size"]), 6),
                }
                for e in spans
            ],
            caption="fault episodes",
            css_class="events",
        )
    rep.data.setdefault("events", []).extend(onsets)
    rep.data.setdefault("cleared", []).extend(cleared)
    return ev


def add_monitor(
    rep: Report,
    *,
    signals: Signals | None = None,
    result: Any = None,
    residuals: Signals | None = None,
    statistics: Signals | None = None,
    events: Sequence[Any] | None = None,
    valid=None,
    invalid=None,
    thresholds: Mapping[str, Any] | None = None,
    level: float | None = None,
    signal_valid=None,
    signature: Mapping[str, Any] | None = None,
    run: int = 0,
    title_prefix: str = "",
) -> dict:
    """Add the sections of one monitor run (events, signals, residuals, statistics, probabilities,
    alarms, signature) to ``rep``.

    Parameters
    ----------
    signals : Signals, optional
        The monitor's input channels (with units).
    result : MonitorResult, optional
        Supplies ``residuals``, ``statistics``, ``events``, ``valid`` and ``invalid`` (each may
        also be given alone).
    valid : array (runs, T) or (T,), optional
        False where the monitor held the sample (shaded grey in every panel).
    invalid : sequence, optional
        Held samples as ``(run, sample, reason)`` or dicts with ``run`` and ``sample``.
    thresholds : mapping, optional
        ``{channel: threshold}`` or ``{channel: (threshold, absolute)}`` (dashed lines).
    level : float, optional
        Announcement level of the probabilities (a dashed line).
    signal_valid : array (T, C) or (runs, T, C), optional
        False where an input channel had no valid sample in the source (shaded red in its panel;
        default: where its value is NaN or inf).
    signature : mapping, optional
        ``{"matrix": (F, R), "rows": faults, "columns": residuals or tests, "title": str}``.

    Returns
    -------
    dict
        What was added: counts of samples, events and held samples.
    """
    if result is not None:
        residuals = residuals if residuals is not None else getattr(result, "residuals", None)
        statistics = statistics if statistics is not None else getattr(result, "statistics", None)
        if events is None and result is not None:  # onsets and cleared events (episodes)
            events = [*getattr(result, "events", []), *(getattr(result, "cleared", None) or [])]
        valid = valid if valid is not None else getattr(result, "valid", None)
        invalid = invalid if invalid is not None else getattr(result, "invalid", None)
    ref = next((s for s in (signals, residuals, statistics) if s is not None), None)
    if ref is None:
        raise DataError("a monitor report needs signals, residuals or statistics")
    t = ref.t
    T = t.size
    thr: dict[str, tuple[float, bool]] = {}
    for k, v in (thresholds or {}).items():
        thr[k] = (float(v[0]), bool(v[1])) if isinstance(v, tuple | list) else (float(v), False)
    held_mask = _held_mask(T, run, valid, invalid)
    held = true_intervals(t, held_mask)
    ev = event_records(events or [])
    ev_run = [e for e in ev if e["run"] == run]
    marks = [(e["t"], e["hypothesis"]) for e in ev_run if e["kind"] == "onset"]
    add_events(
        rep, ev_run, (float(t[0]), float(t[-1])) if T else None, held=held, title=f"{title_prefix}Events"
    )
    if signals is not None:
        sv = signal_valid
        if sv is None:
            sv = np.isfinite(signals.values[run])
        else:
            sv = np.asarray(sv, bool)
            sv = sv[run] if sv.ndim == 3 else sv
            if sv.ndim == 1:
                sv = np.repeat(sv[:, None], signals.n_channels, axis=1)
        inv = {n: true_intervals(signals.t, ~sv[:, j]) for j, n in enumerate(signals.names)}
        rep.section(
            f"{title_prefix}Signals",
            f"{signals.n_channels} channel(s), {signals.n_samples} samples. "
            "Grey: samples the monitor held (it could not judge them); red: samples with no valid "
            "value in the source; dotted red lines: announcements. One panel per channel, so that "
            "none swamps another.",
        )
        _stacked(
            rep, signals.t, _panels(signals, run, None, inv), "monitor input signals", held=held, events=marks
        )
    if residuals is not None and residuals.n_channels:
        rep.section(
            f"{title_prefix}Residuals",
            "Residuals of the generators; dashed lines: thresholds of the tests that read them directly.",
        )
        _stacked(rep, residuals.t, _panels(residuals, run, thr), "residuals", held=held, events=marks)
    if statistics is not None and statistics.n_channels:
        kinds = {n: _kind(n, statistics.values[run, :, j]) for j, n in enumerate(statistics.names)}
        stat = [n for n, k in kinds.items() if k == "statistic"]
        prob = [n for n, k in kinds.items() if k == "probability"]
        binary = [n for n, k in kinds.items() if k == "binary"]
        if stat:
            rep.section(
                f"{title_prefix}Test statistics",
                "Statistics of the residual processors (GLRTs, norms, ...); dashed lines: their thresholds.",
            )
            _stacked(
                rep,
                statistics.t,
                _panels(statistics.select(stat), run, thr),
                "test statistics",
                held=held,
                events=marks,
            )
        if prob:
            rep.section(
                f"{title_prefix}Fault probabilities",
                "Posterior probability of every fault hypothesis"
                + (f"; dashed line: the announcement level {level:g}." if level is not None else "."),
            )
            P = statistics.select(prob)
            panel = {
                "title": "fault probabilities",
                "ylabel": "probability",
                "unit": "–",
                "range": [-0.03, 1.03],
                "traces": [(n, P.values[run, :, j]) for j, n in enumerate(P.names)],
            }
            if level is not None:
                panel["thresholds"] = [("announcement level", float(level))]
            rep.figure(
                stacked_time_figure(
                    statistics.t,
                    [panel],
                    title="fault probabilities",
                    held=held,
                    events=marks,
                    max_points=rep.max_points,
                    panel_height=300,
                )
            )
        if binary:
            from .html import encode_array

            rep.section(
                f"{title_prefix}Alarms",
                "Alarm channels (1: on), as a raster; each display column "
                "is the largest value of its time bucket, so no single-sample alarm disappears.",
            )
            B = statistics.select(binary)
            nb = min(T, 1500)
            edges = np.linspace(0, T, nb + 1).astype(int)
            z = np.maximum.reduceat(np.nan_to_num(B.values[run], nan=0.0), edges[:-1], axis=0).T
            tb = statistics.t[edges[:-1]]
            rep.figure(
                {
                    "data": [
                        {
                            "type": "heatmap",
                            "z": encode_array(z, "f4"),
                            "x": encode_array(tb),
                            "y": list(B.names),
                            "colorscale": [[0, "#f7fbff"], [1, "#d62728"]],
                            "zmin": 0,
                            "zmax": 1,
                            "colorbar": {"title": {"text": "alarm (0/1)"}},
                        }
                    ],
                    "layout": {
                        "title": {"text": "alarm raster"},
                        "height": int(150 + 22 * len(binary)),
                        "margin": {"l": 200, "r": 30, "t": 50, "b": 50},
                        "xaxis": {"title": {"text": "time (s)"}},
                        "yaxis": {"title": {"text": "alarm channel (–)"}, "type": "category"},
                    },
                }
            )
    if signature is not None:
        add_signature(rep, signature)
    return {
        "samples": T,
        "events": len(ev_run),
        "held_samples": int(held_mask.sum()),
        "held_intervals": len(held),
    }


def add_signature(rep: Report, signature: Mapping[str, Any]) -> None:
    """A signature matrix or D-matrix as a heat map (``matrix``, ``rows``, ``columns``, ``title``)."""
    m = np.asarray(signature["matrix"], float)
    title = signature.get("title", "signature matrix")
    rep.section(title.capitalize() if title[:1].islower() else title, signature.get("intro"))
    rep.figure(
        heatmap_figure(
            m,
            signature["columns"],
            signature["rows"],
            title=title,
            colorbar=signature.get("colorbar", "value (–)"),
            text=signature.get("text"),
            x_title=signature.get("x_title", "test / residual"),
            y_title=signature.get("y_title", "fault"),
            zmin=signature.get("zmin"),
            zmax=signature.get("zmax"),
        )
    )


def roc_curve(nominal_scores, faulty_scores, n: int = 200) -> dict[str, list[float]]:
    """ROC of a threshold swept over a test's score (e.g. the largest statistic of each run).

    Parameters
    ----------
    nominal_scores, faulty_scores : array_like (runs,)
        The score of each fault-free and each faulty run; a run alarms when score > threshold.
    n : int
        Number of thresholds (quantiles of the pooled scores, plus the extremes).

    Returns
    -------
    dict
        ``threshold``, ``pf`` (fraction of nominal runs above it), ``pd`` (faulty runs above it),
        each a list from the highest threshold down, and ``auc`` (trapezoidal area).

    Examples
    --------
    >>> r = roc_curve([0.1, 0.2, 0.3], [0.25, 0.5, 0.9])
    >>> r["pf"][0], r["pd"][0], r["pf"][-1], r["pd"][-1], round(r["auc"], 3)
    (0.0, 0.0, 1.0, 1.0, 0.889)
    """
    a = np.asarray(nominal_scores, float).ravel()
    b = np.asarray(faulty_scores, float).ravel()
    if a.size == 0 or b.size == 0:
        raise DataError("roc_curve: needs at least one nominal and one faulty score")
    pooled = np.concatenate([a, b])
    thr = np.unique(
        np.concatenate([np.quantile(pooled, np.linspace(0, 1, n)), pooled if pooled.size <= n else []])
    )
    thr = np.concatenate([[np.inf], thr[::-1], [-np.inf]])
    pf = np.array([(a > x).mean() for x in thr])
    pd = np.array([(b > x).mean() for x in thr])
    auc = float(np.sum(np.diff(pf) * (pd[1:] + pd[:-1]) / 2))
    return {"threshold": thr.tolist(), "pf": pf.tolist(), "pd": pd.tolist(), "auc": auc}


def add_roc(rep: Report, curves: Mapping[str, Mapping[str, Sequence[float]]], *, title: str = "ROC") -> None:
    """ROC curves ``{name: {"pf": [...], "pd": [...], "auc"?: float}}`` (a threshold swept)."""
    data = [
        {
            "type": "scatter",
            "mode": "lines",
            "x": [0, 1],
            "y": [0, 1],
            "name": "chance",
            "line": {"dash": "dot", "color": "grey"},
        }
    ]
    for name, c in curves.items():
        lab = f"{name} (AUC {c['auc']:.3f})" if c.get("auc") is not None else name
        data.append(
            {
                "type": "scatter",
                "mode": "lines+markers",
                "x": list(c["pf"]),
                "y": list(c["pd"]),
                "name": lab,
                "marker": {"size": 4},
            }
        )
    rep.figure(
        {
            "data": data,
            "layout": {
                "title": {"text": title},
                "height": 460,
                "xaxis": {"title": {"text": "false-alarm probability Pf (–)"}, "range": [-0.02, 1.02]},
                "yaxis": {"title": {"text": "detection probability Pd (–)"}, "range": [-0.02, 1.02]},
            },
        }
    )


def add_campaign(rep: Report, c: Mapping[str, Any], *, where: str = "campaign") -> dict:
    """The sections of a campaign result (the JSON of ``fdikit abs campaign``).

    Recognised keys (each optional, at least one needed): ``pd`` {class: {test: Pd}}, ``pf``
    {test: Pf}, ``dmatrix`` {faults, tests, d, pd}, ``confusion`` {class: {label: count}},
    ``sensitivity``, ``sensitivity_exact``, ``specificity``, ``detection_rate``, ``tree``,
    ``detection_time_histogram`` {edges, counts {class: [...]}}, ``roc`` {test: {pf, pd}},
    ``complete`` (the complete diagnoser), ``tests`` {thresholds}, ``runs``, ``snr_db``.
    """
    if not isinstance(c, Mapping):
        raise DataError(f"{where}: a campaign must be a JSON object, got {type(c).__name__}")
    known = (
        "pd",
        "pf",
        "dmatrix",
        "confusion",
        "sensitivity",
        "specificity",
        "detection_time_histogram",
        "roc",
    )
    if not any(k in c for k in known):
        raise DataError(
            f"{where}: not a campaign result: none of the keys {list(known)} (keys: {sorted(c)[:12]})"
        )
    added = []
    meta = {k: c[k] for k in ("snr_db", "magnitudes", "runs", "wall_seconds", "engine") if k in c}
    if meta:
        rep.section("Campaign", "Monte Carlo evaluation of the tests and the diagnosis.")
        rep.table(meta)
        thr = (c.get("tests") or {}).get("thresholds") if isinstance(c.get("tests"), Mapping) else None
        if thr:
            rep.table([{"test": k, "threshold": v} for k, v in thr.items()], caption="designed thresholds")
    pd, pf = c.get("pd"), c.get("pf")
    if pd is not None or pf is not None:
        try:
            tests = list(pf) if pf else list(next(iter(pd.values())))
            classes = (["F0 (Pf)"] if pf else []) + [str(k) for k in (pd or {})]
            z = ([[float(pf[tn]) for tn in tests]] if pf else []) + [
                [float(pd[k].get(tn, np.nan)) for tn in tests] for k in (pd or {})
            ]
        except (AttributeError, KeyError, TypeError, ValueError, StopIteration) as exc:
            raise DataError(
                f"{where}: key 'pd' must be {{class: {{test: Pd}}}} and 'pf' {{test: Pf}} ({exc})"
            ) from None
        rep.section(
            "Pd and Pf per test and class",
            "Fraction of runs in which each test fired: Pf on the nominal class F0, Pd on each fault class.",
        )
        rep.figure(
            heatmap_figure(
                z,
                tests,
                classes,
                title="Pd / Pf per test and class",
                colorbar="probability (–)",
                zmin=0,
                zmax=1,
                x_title="test",
                y_title="class",
            )
        )
        rep.table(
            [{"class": cl, **{tn: v for tn, v in zip(tests, row)}} for cl, row in zip(classes, z)],
            caption="Pd / Pf",
        )
        added.append("pd_pf")
    dm = c.get("dmatrix")
    if isinstance(dm, Mapping) and "d" in dm:
        try:
            d = np.asarray(dm["d"], float)
            text = None
            if dm.get("pd") is not None:
                p = np.asarray(dm["pd"], float)
                text = [
                    [f"{int(d[i, j])} ({p[i, j]:.3f})" for j in range(d.shape[1])] for i in range(d.shape[0])
                ]
            add_signature(
                rep,
                {
                    "matrix": d,
                    "rows": dm["faults"],
                    "columns": dm["tests"],
                    "title": "D-matrix",
                    "text": text,
                    "colorbar": "test fires (0/1)",
                    "zmin": 0,
                    "zmax": 1,
                    "intro": "Learned D-matrix: 1 where the test fires for the fault (in brackets the "
                    "firing fraction)."
                    + (
                        f" Ambiguity groups: {dm.get('ambiguity_groups')}."
                        if dm.get("ambiguity_groups")
                        else ""
                    ),
                },
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise DataError(f"{where}: key 'dmatrix' must have faults, tests and d ({exc})") from None
        added.append("dmatrix")
    conf = c.get("confusion")
    if isinstance(conf, Mapping) and conf:
        true = list(conf)
        labels = list(dict.fromkeys([*true, *(lab for row in conf.values() for lab in row)]))
        counts = np.array([[float(conf[a].get(b, 0)) for b in labels] for a in true])
        frac = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
        text = [
            [f"{int(counts[i, j])}" if counts[i, j] else "" for j in range(len(labels))]
            for i in range(len(true))
        ]
        rep.section(
            "Confusion matrix",
            "Diagnosed class (columns) of the runs of each true class (rows); colour: "
            "fraction of the row, text: number of runs.",
        )
        rep.figure(
            heatmap_figure(
                frac,
                labels,
                true,
                title="confusion matrix",
                colorbar="fraction of runs (–)",
                text=text,
                zmin=0,
                zmax=1,
                x_title="diagnosed",
                y_title="true class",
            )
        )
        added.append("confusion")
    rates = {k: c[k] for k in ("sensitivity", "sensitivity_exact", "specificity", "detection_rate") if k in c}
    tree = c.get("tree")
    if isinstance(tree, Mapping):
        rates.update({f"tree {k}": tree[k] for k in ("sensitivity", "specificity") if k in tree})
    comp = c.get("complete")
    if isinstance(comp, Mapping):
        rates.update(
            {
                f"complete {k}": comp[k]
                for k in ("sensitivity", "sensitivity_exact", "specificity", "svm_error")
                if k in comp
            }
        )
    if rates:
        rep.section(
            "Sensitivity and specificity",
            "Sensitivity: fraction of faulty runs diagnosed correctly; "
            "specificity: fraction of nominal runs diagnosed fault-free.",
        )
        rep.table(
            [{"measure": k, "value (%)": 100 * float(v) if v is not None else None} for k, v in rates.items()]
        )
        ref = c.get("paper_table_v")
        if isinstance(ref, Mapping) and ref:
            rep.table(
                [
                    {"SNR (dB)": k, "paper sensitivity (%)": v[0], "paper specificity (%)": v[1]}
                    for k, v in ref.items()
                ],
                caption="the paper's Table V",
            )
        added.append("rates")
    if isinstance(tree, Mapping) and tree.get("text"):
        rep.pre(tree["text"], summary="diagnostic tree (AO*)")
    if isinstance(comp, Mapping):
        if isinstance(comp.get("tree"), Mapping) and comp["tree"].get("listing"):
            rep.pre(comp["tree"]["listing"], summary="complete diagnoser tree")
        est = comp.get("estimation")
        if isinstance(est, Mapping) and est:
            rep.table(
                [
                    {"class": k, **{kk: vv for kk, vv in v.items() if not isinstance(vv, list | dict)}}
                    for k, v in est.items()
                ],
                caption="fault-size estimation",
            )
    hist = c.get("detection_time_histogram")
    if isinstance(hist, Mapping) and hist.get("counts"):
        try:
            edges = np.asarray(hist["edges"], float)
            centres = 0.5 * (edges[1:] + edges[:-1])
            data = [
                {
                    "type": "bar",
                    "x": centres.tolist(),
                    "y": list(map(float, v)),
                    "name": str(k),
                    "width": float(np.diff(edges).mean()) * 0.9,
                    "opacity": 0.7,
                }
                for k, v in hist["counts"].items()
            ]
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(
                f"{where}: key 'detection_time_histogram' must have edges and counts ({exc})"
            ) from None
        rep.section(
            "Detection times",
            "Histogram of the first-alarm times"
            + (f" of {hist['test']}" if hist.get("test") else " (G_P1 in the ABS campaign)")
            + " per class.",
        )
        rep.figure(
            {
                "data": data,
                "layout": {
                    "title": {"text": "detection-time histogram"},
                    "barmode": "overlay",
                    "height": 420,
                    "xaxis": {"title": {"text": "detection time (s)"}},
                    "yaxis": {"title": {"text": "runs (count)"}},
                },
            }
        )
        added.append("histogram")
    roc = c.get("roc")
    if isinstance(roc, Mapping) and roc:
        rep.section("ROC", "Detection against false-alarm probability as the threshold is swept.")
        add_roc(rep, roc)
        added.append("roc")
    rep.data.setdefault(
        "campaign", {k: c[k] for k in ("snr_db", "runs", "sensitivity", "specificity", "pd", "pf") if k in c}
    )
    return {"sections": added}


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


def _manifest(path: Path) -> dict | None:
    """The JSON manifest of a design artifact (read as text: no class is imported), or None."""
    p = Path(path)
    js = p if p.suffix == ".json" else p.with_name(p.name + ".json")
    try:
        m = json.loads(js.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return m if isinstance(m, dict) else None


def _decode(v: Any) -> Any:
    """A manifest payload value as plain Python (lists, dicts, floats); array references -> None."""
    if isinstance(v, dict):
        if "__dict__" in v:
            return {k: _decode(x) for k, x in v["__dict__"].items()}
        for tag in ("__list__", "__tuple__"):
            if tag in v:
                return [_decode(x) for x in v[tag]]
        if "__float__" in v:
            return float(v["__float__"])
        return None
    return v


def _manifest_thresholds(man: dict | None) -> dict[str, tuple[float, bool]]:
    """Thresholds of a threshold-rule artifact (payload ``inputs`` and ``threshold``, as
    :class:`fdikit.detect.Hold` saves them), read from its manifest."""
    pay = _decode((man or {}).get("payload"))
    if not isinstance(pay, dict) or not isinstance(pay.get("inputs"), list) or "threshold" not in pay:
        return {}
    names, thr = pay["inputs"], pay["threshold"]
    try:
        vals = np.broadcast_to(np.asarray(thr, float), (len(names),))
    except (TypeError, ValueError):
        return {}  # stored in the NPZ, or not a plain rule: no line drawn
    return {
        str(n): (float(v), bool(pay.get("absolute", False))) for n, v in zip(names, vals) if np.isfinite(v)
    }


def _read_stats(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray | None]:
    import pyarrow.parquet as pq

    if not path.is_file():
        raise DataError(f"{path}: no such statistics file")
    try:
        table = pq.read_table(path)
    except Exception as exc:
        raise DataError(f"{path}: not a readable Parquet file ({type(exc).__name__}: {exc})") from None
    cols = table.column_names
    if "t" not in cols:
        raise DataError(f"{path}: the statistics table has no time column 't'; columns: {cols[:12]}")
    t = np.asarray(table.column("t").to_numpy(), float)
    valid = np.asarray(table.column("valid").to_numpy(), bool) if "valid" in cols else None
    out = {}
    for c in cols:
        if c in ("t", "valid"):
            continue
        try:
            out[c] = np.asarray(table.column(c).to_numpy(zero_copy_only=False), float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{path}: column {c!r} is not numeric ({exc})") from None
    return t, out, valid


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
