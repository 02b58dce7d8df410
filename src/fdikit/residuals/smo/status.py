"""Sliding status of the SMO reconstructor: the status codes of its ``sliding_status`` outputs and
the episodes in which sliding was lost."""

from __future__ import annotations

import numpy as np

from ...signals import Signals

__all__ = ["NOT_SLIDING", "SATURATED", "SLIDING", "STATUS_LABELS", "sliding_episodes"]

#: Sliding status codes of the ``sliding_status`` outputs.
SLIDING, NOT_SLIDING, SATURATED = 0, 1, 2
STATUS_LABELS = {SLIDING: "sliding", NOT_SLIDING: "not sliding", SATURATED: "saturated"}


def sliding_episodes(out: Signals | np.ndarray, t: np.ndarray | None = None, *,
                     channel: str = "sliding_status") -> list[dict]:
    """The losses of sliding in a reconstructor's output: one episode per loss.

    Parameters
    ----------
    out : Signals or ndarray (runs, T)
        :meth:`SlidingModeReconstructor.run`'s output (``channel`` is read), or status codes.
    t : ndarray (T,), optional
        Times (taken from ``out`` when it is a :class:`Signals`).
    channel : str
        Status channel.

    Returns
    -------
    list of dict
        ``run``, ``onset_k``, ``onset_t``, ``worst`` (``"not sliding"`` or ``"saturated"``),
        ``cleared_k``, ``cleared_t`` (``None`` while not cleared), in order of run and onset.
    """
    if isinstance(out, Signals):
        codes = out[channel]
        t = out.t
    else:
        codes = np.atleast_2d(np.asarray(out))
        t = np.arange(codes.shape[1], dtype=float) if t is None else np.asarray(t, float)
    codes = np.atleast_2d(codes)
    res = []
    for run in range(codes.shape[0]):
        off = codes[run] > 0
        edges = np.flatnonzero(np.diff(np.r_[0, off.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2]):
            res.append({"run": run, "onset_k": int(a), "onset_t": float(t[a]),
                        "worst": STATUS_LABELS[int(codes[run, a:b].max())],
                        "cleared_k": int(b) if b < codes.shape[1] else None,
                        "cleared_t": float(t[b]) if b < codes.shape[1] else None})
    return res
