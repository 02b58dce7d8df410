"""Threshold rules: a statistic above a threshold for Z consecutive samples raises an alarm.

This is the alarm rule of luo-et-al, eq. (34): a test declares a fault at sample k when its
statistic exceeds the threshold at samples k-Z+1, ..., k. ``Z = 1`` is a plain threshold.
"""

from __future__ import annotations

import reprlib
from collections.abc import Mapping, Sequence

import numpy as np

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["ABSOLUTE_DEFAULT", "Hold", "consecutive_count"]

#: The one default of ``absolute`` in :class:`Hold` and :func:`~fdikit.detect.design_threshold`:
#: compare ``|x|`` with the threshold. A residual's false alarms come from both signs; a statistic
#: that is never negative (GLRT, a norm, a probability) is unchanged by it, so one default serves
#: both (pass ``absolute=False`` for a one-sided test of a signed signal).
ABSOLUTE_DEFAULT = True


def consecutive_count(exceed: np.ndarray, axis: int = 1) -> np.ndarray:
    """Length of the current run of ``True`` values along ``axis`` (0 where ``exceed`` is False).

    Vectorised with cumulative maxima: ``c_k = k - (index of the last False at or before k)``.

    Examples
    --------
    >>> consecutive_count(np.array([[1, 1, 0, 1, 1, 1]], bool)).tolist()
    [[1, 2, 0, 1, 2, 3]]
    """
    e = np.moveaxis(np.asarray(exceed, bool), axis, -1)
    T = e.shape[-1]
    k = np.arange(T)
    last_false = np.where(~e, k, -1)
    np.maximum.accumulate(last_false, axis=-1, out=last_false)
    return np.moveaxis(k - last_false, -1, axis) * np.moveaxis(e, -1, axis)


class Hold(ResidualProcessor):
    """Alarm when a statistic exceeds its threshold for ``Z`` consecutive samples (luo-et-al eq. (34)).

    Parameters
    ----------
    inputs : str or sequence of str
        Channels to test (residuals or test statistics); one name is one channel.
    threshold : float, sequence of float, or ThresholdDesign
        One threshold for all channels or one per channel (> 0 when ``absolute``), or the result
        of :func:`~fdikit.detect.design_threshold` (its thresholds, and its ``Z`` and ``absolute``
        unless given here; a design for another number of channels is refused).
    Z : int, optional
        Number of consecutive exceedances required (>= 1). Default: the design's, else 1.
    absolute : bool, optional
        Compare ``|x|`` (default, :data:`ABSOLUTE_DEFAULT`, the same as
        :func:`~fdikit.detect.design_threshold`'s) or the signed ``x`` with the threshold.
        Default: the design's, else :data:`ABSOLUTE_DEFAULT`.

    Notes
    -----
    Outputs one alarm channel per input, named ``"<input>:alarm"``, valued 0.0 or 1.0.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> from fdikit.detect import Hold
    >>> s = Signals(np.arange(6.0), [0, 2, 2, 0, 2, 2], ["r"])
    >>> Hold(["r"], 1.0, Z=2).run(s)["r:alarm"].tolist()
    [[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]]
    """

    def __init__(self, inputs: str | Sequence[str], threshold, Z: int | None = None, *,
                 absolute: bool | None = None):
        if isinstance(inputs, str):   # one channel, not its characters
            inputs = [inputs]
        self.input_names = [str(s) for s in inputs]
        if not self.input_names:
            raise DataError("Hold needs at least one input channel")
        if isinstance(threshold, Mapping) and "threshold" in threshold:   # a ThresholdDesign
            threshold, Z, absolute = self._from_design(threshold, Z, absolute)
        Z = 1 if Z is None else Z
        absolute = ABSOLUTE_DEFAULT if absolute is None else absolute
        try:
            thr = np.asarray(threshold, float)
        except (TypeError, ValueError):
            raise DataError(f"Hold: threshold must be a number, one number per channel or a ThresholdDesign, "
                            f"got {type(threshold).__name__} {reprlib.repr(threshold)}") from None
        if thr.ndim > 1 or (thr.ndim == 1 and thr.size not in (1, len(self.input_names))):
            raise DataError(f"Hold: {thr.size} thresholds given for {len(self.input_names)} channels "
                            f"{self.input_names}; give one threshold, or one per channel")
        thr = np.broadcast_to(thr.ravel() if thr.ndim else thr, (len(self.input_names),)).copy()
        if not np.all(np.isfinite(thr)):
            raise DataError(f"thresholds must be finite, got {thr.tolist()}")
        if absolute and np.any(thr <= 0):
            raise DataError(f"thresholds on |x| must be positive, got {thr.tolist()}")
        if int(Z) != Z or Z < 1:
            raise DataError(f"Z must be an integer >= 1, got {Z}")
        self.threshold = thr
        self.Z = int(Z)
        self.absolute = bool(absolute)
        self.output_names = [f"{s}:alarm" for s in self.input_names]
        self._count = np.zeros((1, len(self.input_names)), int)

    _state_attrs = ("_count",)

    def _from_design(self, design: Mapping, Z, absolute) -> tuple:
        """Thresholds, hold and sign rule of a :func:`~fdikit.detect.design_threshold` result."""
        thr = np.atleast_1d(np.asarray(design["threshold"], float))
        if thr.size not in (1, len(self.input_names)):
            raise DataError(f"Hold: the threshold design is for {thr.size} channels "
                            f"{list(design.get('channels', []))}, the Hold has {len(self.input_names)} "
                            f"inputs {self.input_names}")
        for key, given in (("Z", Z), ("absolute", absolute)):
            if given is not None and key in design and design[key] != given:
                raise DataError(f"Hold: {key} = {given!r} differs from the threshold design's "
                                f"{key} = {design[key]!r}; its rate holds only for the design's rule")
        return (thr, design.get("Z", 1) if Z is None else Z,
                design.get("absolute", ABSOLUTE_DEFAULT) if absolute is None else absolute)

    def to_dict(self) -> dict:
        """Configuration as plain data (see :mod:`fdikit.base.artifacts`)."""
        return {"inputs": list(self.input_names), "threshold": self.threshold.tolist(), "Z": self.Z,
                "absolute": self.absolute}

    @classmethod
    def from_dict(cls, d: dict) -> Hold:
        return cls(d["inputs"], d["threshold"], d["Z"], absolute=d["absolute"])

    def _exceed(self, r: np.ndarray) -> np.ndarray:
        return (np.abs(r) if self.absolute else r) > self.threshold

    def reset(self, runs: int = 1) -> None:
        self._count = np.zeros((runs, len(self.input_names)), int)

    def _step(self, r: np.ndarray) -> np.ndarray:
        if not np.isfinite(r).all():   # refused before the state changes (a Monitor holds such samples)
            run, c = np.argwhere(~np.isfinite(r))[0]
            raise DataError(f"Hold: input channel {self.input_names[c]!r} is not finite ({r[run, c]}) in "
                            f"run {run}; the state is unchanged")
        e = self._exceed(r)
        self._count = (self._count + 1) * e
        return (self._count >= self.Z).astype(float)

    def run(self, signals: Signals) -> Signals:
        r = signals.values[:, :, signals.index(self.input_names)]
        c = consecutive_count(self._exceed(r), axis=1)
        self.reset(signals.runs)
        self._count = c[:, -1].copy() if c.shape[1] else self._count
        return Signals(signals.t, (c >= self.Z).astype(float), self.output_names, check=False)
