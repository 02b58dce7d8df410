"""Records of a monitor run as JSON-ready dicts: onset and cleared events, time gaps and held
(invalid) samples, one record each, in the order batch and follow mode write them (the lines of
``fdikit monitor --events``); the summary and the per-sample table of a batch run.

A record has ``t``, ``run`` and ``sample``, and one of:

* an event: ``kind`` (``"onset"``, ``"change"`` or ``"cleared"``), ``hypothesis``, ``value``,
  ``size`` (``None`` where not estimated), ``episode`` and ``announcement`` (``True`` for an
  onset); a cleared event also has ``label: "not seen any more"`` -- the alarm stayed below its
  clear level for the decision's ``clear_after``, which is all the monitor knows: a persistent
  fault whose residual decays (a sensor bias an observer absorbs) ends its episode the same way,
  so a cleared episode says the fault is no longer seen, not that it is gone; a change event (an
  open episode now announced under a revised name, e.g. its fault type, see
  :class:`~fdikit.monitor.Decision` ``groups``) also has ``previous``, the name it replaces;
* a gap: ``gap: True``, ``t_start`` and ``n_missing`` (at the first sample after the gap);
* a held sample: ``invalid`` (the reason).

Follow mode adds records of input lines it refuses: ``line`` (1-based) and ``invalid``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["batch_records", "batch_summary", "event_record", "gap_record", "invalid_record", "record_order",
           "stats_frame", "status_counts", "step_records", "summary_lines", "write_records", "write_stats"]


#: What a cleared episode means: the alarm stopped, which a fault that persists can do too.
NOT_SEEN = "not seen any more"


def event_record(e) -> dict:
    """An onset or cleared event as one JSON record (``announcement`` is True for an onset).

    Parameters
    ----------
    e : Event
        An event of :class:`fdikit.monitor.Monitor` (an onset without ``kind`` counts as one).

    Returns
    -------
    dict

    Examples
    --------
    >>> from fdikit.monitor import Event
    >>> event_record(Event(0, 12, 0.24, "sensor:speed", 31.5))["announcement"]
    True
    >>> event_record(Event(0, 90, 1.8, "sensor:speed", 0.0, "cleared"))["label"]
    'not seen any more'
    """
    kind = getattr(e, "kind", "onset")
    size = getattr(e, "size", None)
    rec = {"t": e.t, "run": e.run, "sample": e.k, "kind": kind, "hypothesis": e.hypothesis,
           "value": e.value, "size": None if size is None or not np.isfinite(size) else float(size),
           "episode": int(getattr(e, "episode", 0)), "announcement": kind == "onset"}
    if kind == "cleared":
        rec["label"] = NOT_SEEN
    elif kind == "change":
        rec["previous"] = getattr(e, "previous", None)
    return rec


def gap_record(g) -> dict:
    """A time gap (the state held, nothing judged): at its first sample after it.

    Parameters
    ----------
    g : Gap
        A gap of :class:`fdikit.monitor.Monitor`.

    Returns
    -------
    dict

    Examples
    --------
    >>> from fdikit.monitor import Gap
    >>> gap_record(Gap(0, 0.5, 0.8, 14, 40))
    {'t': 0.8, 'run': 0, 'sample': 40, 'gap': True, 't_start': 0.5, 'n_missing': 14}
    """
    return {"t": g.t_end, "run": g.run, "sample": g.k, "gap": True, "t_start": g.t_start,
            "n_missing": int(g.n_missing)}


def invalid_record(t: float, run: int, k: int, why: str) -> dict:
    """A held (invalid) sample with its reason.

    Examples
    --------
    >>> invalid_record(0.5, 0, 50, "speed: NaN")
    {'t': 0.5, 'run': 0, 'sample': 50, 'invalid': 'speed: NaN'}
    """
    return {"t": float(t), "run": run, "sample": k, "invalid": why}


def record_order(d: dict) -> tuple:
    """Sort key of records: by sample; at one sample the gap that ended at it, its held reason,
    cleared events, onsets, then changes.

    Examples
    --------
    >>> recs = [{"sample": 3, "kind": "onset"}, {"sample": 3, "gap": True}, {"sample": 2, "invalid": "x"}]
    >>> [r["sample"] for r in sorted(recs, key=record_order)], sorted(recs, key=record_order)[1]["gap"]
    ([2, 3, 3], True)
    """
    kind = d.get("kind")
    rank = (0 if d.get("gap") else 1 if "invalid" in d else 2 if kind == "cleared"
            else 4 if kind == "change" else 3)
    return (d["sample"], rank, d.get("run", 0), d.get("hypothesis", ""))


def status_counts(res) -> dict:
    """Samples per status (``ok``, ``cannot_judge``, ``warmup``), over every run.

    Parameters
    ----------
    res : MonitorResult

    Returns
    -------
    dict of str to int

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> status_counts(SimpleNamespace(status=np.array([[2, 2, 0, 1, 0]])))
    {'ok': 2, 'cannot_judge': 1, 'warmup': 2}
    """
    status = getattr(res, "status", None)
    names = getattr(res, "STATUS_NAMES", ("ok", "cannot_judge", "warmup"))
    if status is None:
        return {"ok": int(res.valid.sum()) if res.valid is not None else 0,
                "cannot_judge": len(res.invalid)}
    return {n: int(np.sum(status == i)) for i, n in enumerate(names)}


def batch_records(sig, res) -> list[dict]:
    """Every record of a batch run, in the order follow mode writes them.

    Parameters
    ----------
    sig : Signals
        The monitor's input (its time axis names the held samples).
    res : MonitorResult

    Returns
    -------
    list of dict

    Examples
    --------
    >>> from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
    >>> cfg = load_config("monitor.toml")  # doctest: +SKIP
    >>> sig = map_channels(cfg, read_log(cfg, "log.csv"))  # doctest: +SKIP
    >>> records = batch_records(sig, build_monitor(cfg).run(sig))  # doctest: +SKIP
    """
    records = [event_record(e)
               for e in (*res.events, *getattr(res, "cleared", []), *getattr(res, "changes", []))]
    records += [invalid_record(sig.t[k], r, k, why) for r, k, why in res.invalid]
    records += [gap_record(g) for g in getattr(res, "gaps", [])]
    records.sort(key=record_order)
    return records


def step_records(mon, t: float, k: int, events) -> list[dict]:
    """The records of one stepped sample (follow mode), as the batch run writes them.

    Parameters
    ----------
    mon : Monitor
        The monitor just stepped (its ``last_gap`` and ``last_invalid``).
    t : float
        The sample's time (s).
    k : int
        The sample's index in the stream.
    events : list of Event
        The events the step returned.

    Returns
    -------
    list of dict
        Sorted by :func:`record_order`.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> step_records(SimpleNamespace(last_gap=None, last_invalid="speed: NaN"), 0.5, 50, [])
    [{'t': 0.5, 'run': 0, 'sample': 50, 'invalid': 'speed: NaN'}]
    """
    recs = []
    gap = getattr(mon, "last_gap", None)
    if gap is not None:
        recs.append(gap_record(gap._replace(k=k) if hasattr(gap, "_replace") else gap))
    if mon.last_invalid is not None:
        recs.append(invalid_record(t, 0, k, mon.last_invalid))
    recs += [event_record(e) for e in events]
    return sorted(recs, key=record_order)


def stats_frame(sig, res):
    """Every sample's residuals and statistics, its valid flag and its status code, as a table.

    Parameters
    ----------
    sig : Signals
    res : MonitorResult

    Returns
    -------
    pandas.DataFrame
        Columns ``t``, the residuals, the statistics (run 0), ``valid`` and, where the result has
        one, ``status`` (int8: 0 ok, 1 cannot judge, 2 warm-up).

    Examples
    --------
    >>> stats_frame(sig, res).to_parquet("stats.parquet", index=False)  # doctest: +SKIP
    """
    import pandas as pd

    df = pd.DataFrame({"t": sig.t})
    for s in (res.residuals, res.statistics):
        for i, ch in enumerate(s.names):
            df[ch] = s.values[0, :, i]
    df["valid"] = res.valid[0] if res.valid is not None else True
    status = getattr(res, "status", None)
    if status is not None:
        df["status"] = status[0].astype(np.int8)   # STATUS_NAMES[code]: 0 ok, 1 cannot_judge, 2 warmup
    return df


def write_records(path, records: list[dict]) -> None:
    """Write records as JSON Lines (``fdikit monitor --events``), atomically
    (:func:`fdikit.base.outputs.open_output`: never half a file; a full disk is a DataError naming it).

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "ev.jsonl")
    >>> write_records(p, [{"t": 0.5, "invalid": "x: NaN"}])
    >>> open(p).read()
    '{"t": 0.5, "invalid": "x: NaN"}\\n'
    """
    import json

    from ..base.outputs import open_output

    with open_output(path, "w") as fh:
        for rec in records:
            fh.write(json.dumps(rec) + "\n")


def write_stats(path, sig, res) -> None:
    """Write :func:`stats_frame` as Parquet (``fdikit monitor --stats``), atomically: a stop or a
    full disk while it is written leaves no file that looks valid.

    Examples
    --------
    >>> write_stats("stats.parquet", sig, res)  # doctest: +SKIP
    """
    from ..base.outputs import open_output

    frame = stats_frame(sig, res)
    with open_output(path, "wb") as fh:
        frame.to_parquet(fh, index=False)


def batch_summary(cfg, log: Any, sig, res, *, t_start: float) -> dict:
    """The summary of a batch run (``fdikit monitor LOG --json``).

    Parameters
    ----------
    cfg : MonitorConfig
    log : path-like
        The log that was read.
    sig : Signals
        The monitor's input.
    res : MonitorResult
    t_start : float
        ``time.perf_counter()`` at the start of the run (for ``wall_seconds``).

    Returns
    -------
    dict
        ``config``, ``log``, ``samples``, ``duration_s``, ``channels``, the first 100 events,
        cleared events and gaps with their counts, ``first_event``, ``invalid_samples``,
        ``status`` (:func:`status_counts`), ``max_statistics`` and ``wall_seconds``.

    Examples
    --------
    >>> summary = batch_summary(cfg, "log.csv", sig, res, t_start=t0)  # doctest: +SKIP
    >>> summary["n_events"], summary["status"]  # doctest: +SKIP
    (1, {'ok': 950, 'cannot_judge': 0, 'warmup': 50})
    """
    return {
        "config": str(cfg.path), "log": str(log), "samples": sig.n_samples,
        "duration_s": float(sig.t[-1] - sig.t[0]) if sig.n_samples else 0.0,
        "channels": sig.names, "n_events": len(res.events),
        "events": [event_record(e) for e in res.events[:100]],
        "first_event": event_record(res.events[0]) if res.events else None,
        "invalid_samples": len(res.invalid),
        "status": status_counts(res),
        "n_cleared": len(getattr(res, "cleared", [])),
        "cleared": [event_record(e) for e in getattr(res, "cleared", [])[:100]],
        "n_changes": len(getattr(res, "changes", [])),
        "changes": [event_record(e) for e in getattr(res, "changes", [])[:100]],
        "n_gaps": len(getattr(res, "gaps", [])),
        "gaps": [gap_record(g) for g in getattr(res, "gaps", [])[:100]],
        "max_statistics": {n: float(np.max(res.statistics.values[..., i]))
                           for i, n in enumerate(res.statistics.names)},
        "wall_seconds": round(time.perf_counter() - t_start, 3),
    }


def summary_lines(summary: dict, records: list[dict]) -> list[str]:
    """The text of a batch run (``fdikit monitor LOG`` without ``--json``): the counts, then one
    line per gap and per event.

    Parameters
    ----------
    summary : dict
        From :func:`batch_summary`.
    records : list of dict
        From :func:`batch_records`.

    Returns
    -------
    list of str

    Examples
    --------
    >>> summary = {"samples": 100, "n_events": 1, "n_cleared": 0, "invalid_samples": 0, "n_gaps": 0,
    ...            "status": {"ok": 90, "cannot_judge": 0, "warmup": 10}}
    >>> rec = {"t": 0.5, "kind": "onset", "hypothesis": "sensor:speed", "value": 31.5, "size": None,
    ...        "episode": 0}
    >>> first, event = summary_lines(summary, [rec])
    >>> first
    '100 samples, 1 announcements (0 not seen any more), ... status: 90 ok, 0 cannot judge, 10 warmup'
    >>> event
    '  t = 0.500 s  sensor:speed  (31.5)  [episode 0]'
    """
    st = summary["status"]
    out = [f"{summary['samples']} samples, {summary['n_events']} announcements "
           f"({summary['n_cleared']} {NOT_SEEN}), {summary['invalid_samples']} invalid samples held, "
           f"{summary['n_gaps']} gaps; status: " + ", ".join(f"{v} {k.replace('_', ' ')}"
                                                          for k, v in st.items())]
    for rec in records:
        if rec.get("gap"):
            out.append(f"  t = {rec['t']:.3f} s  gap of {rec['n_missing']} samples since "
                       f"t = {rec['t_start']:.3f} s: cannot judge, warm-up after it")
        elif "kind" in rec:
            size = "" if rec["size"] is None else f", size {rec['size']:.4g}"
            what = NOT_SEEN if rec["kind"] == "cleared" else f"({rec['value']:.4g}{size})"
            if rec["kind"] == "change":
                what = f"(revised from {rec.get('previous')}) {what}"
            out.append(f"  t = {rec['t']:.3f} s  {rec['hypothesis']}  {what}  [episode {rec['episode']}]")
    return out
