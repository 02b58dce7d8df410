"""Decisions read from an MHSSPT's posteriors: the first sample a fault's posterior reaches a
level (:func:`detection_time`) and the most probable hypothesis at the end
(:func:`final_diagnosis`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...signals import Signals

__all__ = ["detection_time", "final_diagnosis"]


def _fault_outputs(out: Signals, outputs: Sequence[str] | None) -> tuple[str, list[str]]:
    h0 = out.names[0]
    if outputs is not None:
        return h0, [str(o) for o in outputs]
    groups = [n for n in out.names if n.startswith("P:")]
    # the hypotheses that a group sums are not decisions of their own: prefer groups, else hypotheses
    members = {n for n in groups if ":" in n[2:] and "P:" + n[2:].rsplit(":", 1)[0] in groups}
    return h0, [n for n in groups[1:] if n not in members]


def detection_time(out: Signals, level: float = 0.9, *, outputs: Sequence[str] | None = None) -> dict:
    """First sample at which a fault's posterior reaches ``level``, per run.

    Parameters
    ----------
    out : Signals
        An MHSSPT's output (``P:<hypothesis>`` channels, H0 first).
    level : float
        Posterior probability that counts as a detection.
    outputs : sequence of str, optional
        Fault outputs to consider (default: every ``P:`` output except H0, a group's member
        hypotheses replaced by the group).

    Returns
    -------
    dict
        ``sample`` (runs,) int (-1: never), ``time`` (runs,) s (nan: never), ``fault`` (list of
        the output that crossed first, or None).

    Examples
    --------
    >>> P = np.array([[0.99, 0.01], [0.5, 0.5], [0.05, 0.95]])
    >>> d = detection_time(Signals(np.arange(3.0), P, ["P:none", "P:f"]))
    >>> d["sample"].tolist(), d["fault"]
    ([2], ['P:f'])
    """
    _, names = _fault_outputs(out, outputs)
    P = out.values[:, :, out.index(names)]
    hit = P >= level
    anyhit = hit.any(axis=2)
    first = np.where(anyhit.any(axis=1), anyhit.argmax(axis=1), -1)
    times = np.where(first >= 0, out.t[np.maximum(first, 0)], np.nan)
    faults = [names[int(np.argmax(P[r, k]))] if k >= 0 else None for r, k in enumerate(first)]
    return {"sample": first, "time": times, "fault": faults}


def final_diagnosis(out: Signals, *, outputs: Sequence[str] | None = None) -> dict:
    """The most probable hypothesis at the last sample of each run (H0 included).

    Returns
    -------
    dict
        ``diagnosis`` (list of output names per run), ``probability`` (runs,).

    Examples
    --------
    >>> P = np.array([[0.99, 0.01], [0.05, 0.95]])
    >>> final_diagnosis(Signals(np.arange(2.0), P, ["P:none", "P:f"]))["diagnosis"]
    ['P:f']
    """
    h0, names = _fault_outputs(out, outputs)
    cols = [h0, *names]
    last = out.values[:, -1, out.index(cols)]
    k = last.argmax(axis=1)
    return {"diagnosis": [cols[i] for i in k], "probability": last[np.arange(last.shape[0]), k]}
