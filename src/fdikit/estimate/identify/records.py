"""The records of an identification: one or many logs (or segments), checked, split in time and
taken as deviations from one operating point.

A record is a :class:`~fdikit.signals.Signals` (a run of it) or an array ``(T, m + p)`` whose columns
are the inputs then the outputs, in the order named. Records may differ in length; they are never
joined end to end (the estimators pool their data record by record).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import DataError
from ...signals import Signals

__all__ = ["Segment", "as_records", "split_records"]


@dataclass
class Segment:
    """One record's inputs ``u`` (T, m) and outputs ``y`` (T, p), with its index among the records."""

    u: np.ndarray
    y: np.ndarray
    record: int

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.y.shape[0]


def _sample_time(t: np.ndarray, which: str) -> float:
    dts = np.diff(t)
    dt = float(f"{float(np.median(dts)):.12g}")     # 0.1, not 0.10000000000000142
    if np.max(np.abs(dts - dt)) > 1e-6 * dt:
        k = int(np.argmax(np.abs(dts - dt))) + 1
        raise DataError(f"{which} is not uniformly sampled (sample {k}: step {dts[k - 1]:g} s, "
                        f"median {dt:g} s)")
    return dt


def _one(rec: Any, inputs: list[str], outputs: list[str], run: int | None, dt: float | None,
         which: str) -> tuple[list[tuple[np.ndarray, np.ndarray]], float | None]:
    if isinstance(rec, Signals):
        missing = [s for s in inputs + outputs if s not in rec.names]
        if missing:
            raise DataError(f"channels {missing} are not in {which} (channels: {rec.names})")
        runs = range(rec.runs) if run is None else [run]
        if run is not None and not 0 <= run < rec.runs:
            raise DataError(f"run {run} does not exist (the record has {rec.runs})")
        t = rec.t
        if t.size < 3:
            raise DataError(f"{which} has {t.size} samples; identification needs many more")
        d = _sample_time(t, which)
        out = []
        for r in runs:
            u = rec.values[r][:, rec.index(inputs)] if inputs else np.zeros((t.size, 0))
            out.append((u, rec.values[r][:, rec.index(outputs)]))
        return out, d
    arr = np.asarray(rec, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != len(inputs) + len(outputs):
        raise DataError(f"{which} is an array of shape {arr.shape}: expected (samples, "
                        f"{len(inputs) + len(outputs)}) with the columns {inputs + outputs}")
    return [(arr[:, :len(inputs)], arr[:, len(inputs):])], dt


def as_records(records: Any, inputs: Sequence[str], outputs: Sequence[str], *, run: int | None = 0,
               dt: float | None = None) -> tuple[list[Segment], float]:
    """The records as :class:`Segment` s (one per record, or per run with ``run=None``) and their
    common sample time (s).

    Parameters
    ----------
    records : Signals, array (T, m + p), or a list of them
        Arrays carry the inputs then the outputs as columns, sampled every ``dt``.
    inputs, outputs : sequence of str
    run : int or None
        Which run of a multi-run Signals (None: every run is a record).
    dt : float, optional
        Sample time of array records (default: that of the Signals, else 1).

    Raises
    ------
    DataError
        Unknown channels, non-uniform or different sample times, non-finite samples (named).
    """
    inputs, outputs = [str(s) for s in inputs], [str(s) for s in outputs]
    if not outputs:
        raise DataError("identify needs at least one output channel")
    if isinstance(records, Signals) or (isinstance(records, np.ndarray) and records.ndim == 2):
        records = [records]
    if not isinstance(records, Sequence | np.ndarray) or len(records) == 0:
        raise DataError(f"records must be a Signals, an array or a non-empty list of them, got "
                        f"{type(records).__name__}")
    segs: list[Segment] = []
    dts: list[float] = []
    for i, rec in enumerate(records):
        which = "the record" if len(records) == 1 else f"record {i}"
        pairs, d = _one(rec, inputs, outputs, run, dt, which)
        if d is not None:
            dts.append(d)
        for u, y in pairs:
            for arr, names in ((u, inputs), (y, outputs)):
                bad = ~np.isfinite(arr)
                if bad.any():
                    k, c = map(int, np.argwhere(bad)[0])
                    raise DataError(f"channel {names[c]!r} is not finite at sample {k} of {which}: flag "
                                    "or cut bad samples first (a list of the good segments is accepted)")
            segs.append(Segment(np.asarray(u, float), np.asarray(y, float), i))
    if dts and max(dts) - min(dts) > 1e-6 * min(dts):
        raise DataError(f"the records have different sample times {sorted(set(dts))} s; resample them "
                        "to one grid")
    return segs, (dts[0] if dts else float(dt or 1.0))


def split_records(segs: list[Segment], validation: float | None, held_out: list[Segment] | None,
                  min_samples: int = 20) -> tuple[list[Segment], list[Segment]]:
    """Estimation and validation segments: the last ``validation`` fraction of every record is held
    out (time order kept), or whole ``held_out`` records validate and every record estimates."""
    if held_out is not None:
        return segs, held_out
    if validation is None or not 0 < validation < 1:
        raise DataError(f"validation must be a fraction in (0, 1), got {validation}")
    est, val = [], []
    for s in segs:
        T = s.n
        Te = round(T * (1 - validation))
        if Te < min_samples or T - Te < min_samples:
            which = "" if len(segs) == 1 else f" (record {s.record})"
            raise DataError(f"{T} samples split {Te} / {T - Te} (estimation / validation){which}; need "
                            f">= {min_samples} each")
        est.append(Segment(s.u[:Te], s.y[:Te], s.record))
        val.append(Segment(s.u[Te:], s.y[Te:], s.record))
    return est, val
