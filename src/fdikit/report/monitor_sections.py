"""The sections of one monitor run in a report: input signals with held and invalid samples
shaded, residuals with their thresholds, test statistics, fault probabilities, alarms and a
signature matrix (:mod:`.signature`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals
from .decimate import true_intervals
from .events import add_events, event_records
from .html import Report, stacked_time_figure
from .signature import add_signature

__all__ = ["PANELS_PER_FIGURE", "add_monitor", "monitor_thresholds"]

#: Channels per stacked figure: beyond it a group is split into several figures.
PANELS_PER_FIGURE = 12


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
