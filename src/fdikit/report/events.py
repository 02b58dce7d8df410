"""Events of a monitor run in a report: event records (from Event objects or an events file),
fault episodes as onset-to-cleared spans, and the events timeline section."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import DataError
from .html import Report

__all__ = ["add_events", "episode_spans", "event_records", "read_events_jsonl"]


def event_records(events: Sequence[Any]) -> list[dict]:
    """Events as dicts ``{t, run, sample, hypothesis, value, kind, episode, size}`` (from
    :class:`fdikit.monitor.Event` objects, or dicts as ``fdikit monitor --events`` writes them;
    held-sample and gap records dropped). ``kind`` is ``"onset"`` (an announcement),
    ``"change"`` (the open episode announced under a revised name; ``previous`` the name it
    replaces) or ``"cleared"``; records of an older fdikit, which had no kind, are onsets."""
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
                    "previous": e.get("previous"),
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
                    "previous": getattr(e, "previous", None),
                }
            )
    out.sort(key=lambda d: (d["t"], d["run"], d["hypothesis"], d["kind"] != "onset"))
    return out


def episode_spans(events: Sequence[Mapping[str, Any]], t_end: float | None = None) -> list[dict]:
    """Pair each onset with its cleared event: ``{hypothesis, run, t_onset, t_cleared, open}``,
    by episode number where the records have one (else by hypothesis); ``revised`` lists the
    ``(t, hypothesis)`` of the episode's change events (its fault type revised).

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
        ep = e.get("episode")
        key = (e.get("run", 0), e["hypothesis"]) if ep is None else (e.get("run", 0), "#", ep)
        kind = e.get("kind", "onset")
        if kind == "onset":
            if key in open_:  # an onset without a cleared event before it: close the old one here
                out.append({**open_.pop(key), "t_cleared": float(e["t"]), "open": False})
            open_[key] = {"hypothesis": e["hypothesis"], "run": key[0], "t_onset": float(e["t"]),
                          "size": e.get("size"), "revised": []}
        elif kind == "change":
            if key in open_:
                open_[key]["revised"].append((float(e["t"]), e["hypothesis"]))
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
    changes = [e for e in ev if e["kind"] == "change"]
    spans = episode_spans(ev, t_range[1] if t_range is not None else None)
    rep.section(
        title,
        f"{len(onsets)} announcement(s) (fault episodes), {len(cleared)} cleared"
        + (f", {len(changes)} revised (a change of the announced name within its episode)" if changes else "")
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
        rs = [e for e in changes if e["hypothesis"] == h]
        if rs:
            data.append(
                {
                    "type": "scatter",
                    "mode": "markers",
                    "name": f"{h} (revised to)",
                    "x": [e["t"] for e in rs],
                    "y": [h] * len(rs),
                    "marker": {"size": 10, "symbol": "triangle-right"},
                    "text": [f"{e['previous']} revised to {h} at t = {e['t']:.3f} s" for e in rs],
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
                    "hypothesis (fault)": " → ".join([e["hypothesis"],
                                                      *(h for _t, h in e.get("revised", []))]),
                    "size": None if e.get("size") is None else round(float(e["size"]), 6),
                }
                for e in spans
            ],
            caption="fault episodes",
            css_class="events",
        )
    rep.data.setdefault("events", []).extend(onsets)
    rep.data.setdefault("cleared", []).extend(cleared)
    if changes:
        rep.data.setdefault("changes", []).extend(changes)
    return ev
