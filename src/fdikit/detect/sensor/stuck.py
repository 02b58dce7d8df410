"""The stuck-sensor detector: a measured signal that stopped moving while the model says it should
move (:class:`StuckDetector`, its compiled kernel, and :func:`design_stuck`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...errors import DataError
from ...signals import Signals
from .base import _SensorDetector
from .calibrate import _dt, _nominal, _threshold

__all__ = ["StuckDetector", "design_stuck"]


@njit(cache=True)
def _stuck_kernel(x, e, tol, inv_scale, has_e, nmin, out, anchor, pmin, pmax, n, started):  # pragma: no cover
    """x, e (R, T) measured and expected; state (R,) arrays; out (R, T)."""
    R, T = x.shape
    for r in range(R):
        for k in range(T):
            v = x[r, k]
            if started[r] == 0 or abs(v - anchor[r]) > tol:
                started[r] = 1
                anchor[r] = v
                pmin[r] = e[r, k]
                pmax[r] = e[r, k]
                n[r] = 0
            else:
                n[r] += 1
                if e[r, k] < pmin[r]:
                    pmin[r] = e[r, k]
                if e[r, k] > pmax[r]:
                    pmax[r] = e[r, k]
            if has_e:
                out[r, k] = (pmax[r] - pmin[r]) * inv_scale if n[r] >= nmin else 0.0
            else:
                out[r, k] = n[r] * inv_scale


class StuckDetector(_SensorDetector):
    """A measured signal that stopped moving while the model says it should move.

    A *flat run* starts whenever the measured signal moves by more than ``tol`` from the value at
    the run's start (the anchor). Over the current flat run the statistic is the range of the
    expected signal, ``g = (max e - min e) / scale``: how far the model (another sensor, a
    prediction of this one) moved while the sensor did not. A quantised signal legitimately
    repeats its value when nothing happens (a steering wheel held straight), and then the expected
    signal does not move either, so ``g`` stays small. Without an expected signal the statistic is
    the number of samples the signal has been flat (the "recent past" test: a signal that never
    stays frozen this long in nominal data).

    Parameters
    ----------
    measured : str
        The measured channel.
    expected : str, optional
        A channel in the same units that the model expects the measurement to follow (low-pass it
        if it is noisy: its range over the flat run is the evidence).
    tol : float
        Largest change of the measurement still counted as "not moved" (its quantisation step, or
        0 for exact repetition), in its units.
    scale : float
        Unit of ``g``: the expected signal's range (units of the signal), or samples without one.
    threshold : float
        Threshold of ``g`` (in units of ``scale``); the output is ``g / threshold``.
    min_samples : int
        With an expected signal: ``g`` counts only once the flat run has lasted this many
        samples (longer than the signal is ever frozen in nominal data; 0: always).
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Notes
    -----
    Outputs ``"<measured>:stuck"`` (alarm at >= 1).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(8.0)
    >>> x = [0, 1, 2, 3, 3, 3, 3, 3]                       # frozen from sample 3
    >>> e = [0, 1, 2, 3, 4, 5, 6, 7]                       # ... the model says it kept rising
    >>> d = StuckDetector("x", "e", threshold=2.0)
    >>> d.run(Signals(t, np.c_[x, e], ["x", "e"]))["x:stuck"].tolist()
    [[0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.5, 2.0]]
    """

    _state_attrs = ("_anchor", "_pmin", "_pmax", "_n", "_started", "_k", "_R")

    def __init__(
        self,
        measured: str,
        expected: str | None = None,
        *,
        tol: float = 0.0,
        scale: float = 1.0,
        threshold: float = 1.0,
        min_samples: int = 0,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        if isinstance(min_samples, bool) or int(min_samples) != min_samples or min_samples < 0:
            raise DataError(f"StuckDetector min_samples must be an integer >= 0, got {min_samples!r}")
        self.min_samples = int(min_samples)
        self.measured = str(measured)
        self.expected = None if expected is None else str(expected)
        self.input_names = [self.measured] + ([self.expected] if self.expected is not None else [])
        if self.expected == self.measured:
            raise DataError(
                f"StuckDetector: the expected channel must differ from the measured one ({self.measured!r})"
            )
        for name, v in (("tol", tol), ("scale", scale), ("threshold", threshold)):
            if not np.isfinite(v) or v < 0 or (name != "tol" and v == 0):
                raise DataError(
                    f"StuckDetector {name} must be finite and {'>= 0' if name == 'tol' else '> 0'}, got {v}"
                )
        self.tol, self.scale, self.threshold = float(tol), float(scale), float(threshold)
        self.output_names = [f"{self.measured}:stuck"]
        self.reset(1)

    def _repr_items(self):
        return [
            ("measured", self.measured),
            ("expected", self.expected),
            ("tol", self.tol),
            ("scale", self.scale),
            ("threshold", self.threshold),
            ("min_samples", self.min_samples),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        self._R = int(runs)
        self._anchor = np.zeros(runs)
        self._pmin = np.zeros(runs)
        self._pmax = np.zeros(runs)
        self._n = np.zeros(runs, np.int64)
        self._started = np.zeros(runs, np.int64)
        self._k = 0

    def _compute(self, x: np.ndarray) -> np.ndarray:
        R, T, _ = x.shape
        m = np.ascontiguousarray(x[:, :, 0])
        e = np.ascontiguousarray(x[:, :, 1]) if self.expected is not None else m
        out = np.empty((R, T))
        _stuck_kernel(
            m,
            e,
            self.tol,
            1.0 / (self.scale * self.threshold),
            self.expected is not None,
            self.min_samples,
            out,
            self._anchor,
            self._pmin,
            self._pmax,
            self._n,
            self._started,
        )
        return out[:, :, None]


def design_stuck(
    nominal: Signals,
    measured: str,
    expected: str | None = None,
    *,
    tol: float = 0.0,
    min_samples: int | None = None,
    quantile: float = 0.5,
    pfa: float = 0.0,
    per: str | float = "hour",
    margin: float = 0.5,
    Z: int = 1,
    skip: int = 0,
) -> StuckDetector:
    """A :class:`StuckDetector` calibrated on nominal data.

    The scale of the statistic is the standard deviation of the expected signal's increments
    (its noise: the range over a flat run is then in noise units). The threshold is the level of
    the statistic on the nominal data for the target (``pfa`` per ``per``, as
    :func:`~fdikit.detect.design_threshold`; ``pfa = 0``: just above the largest nominal value),
    times ``1 + margin``. With ``min_samples`` (a flat run must last longer than any the nominal
    data hold) the threshold is instead the ``quantile`` of the expected signal's range over
    windows of ``min_samples`` samples (how much it moves in that time in ordinary driving) times
    ``1 + margin``, and at least the largest gated nominal value times ``1 + margin``.

    Parameters
    ----------
    nominal : Signals
        Fault-free record(s) holding ``measured`` (and ``expected``).
    measured, expected : str
        See :class:`StuckDetector`.
    tol : float
        See :class:`StuckDetector`.
    min_samples : int, optional
        See :class:`StuckDetector`; ``"auto"``: one more than the longest nominal flat run.
    quantile : float
        Quantile of the expected signal's windowed range used with ``min_samples``.
    pfa, per, margin, Z :
        False-alarm target (see :func:`~fdikit.detect.design_threshold`; a target per unit of time
        that the data are too short for falls back to extreme-value scaling of the nominal
        maximum, ``ln(n_target) / ln(n_eff)`` effective samples), relative margin on the
        threshold and the hold the alarm will use.
    skip : int
        Samples left out at the start of every run (transients); the detector's ``warmup``.

    Returns
    -------
    StuckDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(2000) * 0.02
    >>> truth = np.sin(0.5 * t)
    >>> nom = Signals(t, np.c_[np.round(truth, 2), truth + 0.01 * rng.standard_normal(t.size)], ["x", "e"])
    >>> d = design_stuck(nom, "x", "e", tol=0.0)
    >>> bool(d.run(nom)["x:stuck"].max() < 1)
    True
    """
    names = [measured] + ([expected] if expected is not None else [])
    s = _nominal(nominal, names, skip)
    if expected is not None:
        e = s[expected][:, skip:]
        scale = float(np.std(np.diff(e, axis=1)))
        if not scale > 0:
            raise DataError(f"expected channel {expected!r} does not vary on the nominal data: no scale")
    else:
        scale = 1.0
    if min_samples == "auto":
        flat = StuckDetector(measured, None, tol=tol, warmup=skip).run(s).values[:, skip:, 0]
        min_samples = int(flat.max()) + 1
    nmin = int(min_samples or 0)
    d = StuckDetector(measured, expected, tol=tol, scale=scale, threshold=1.0, min_samples=nmin, warmup=skip)
    g = d.run(s).values[:, skip:]
    if nmin > 0 and expected is not None:
        if not 0 < quantile < 1:
            raise DataError(f"design_stuck: quantile must be in (0, 1), got {quantile}")
        from numpy.lib.stride_tricks import sliding_window_view

        if e.shape[1] <= nmin:
            raise DataError(
                f"design_stuck: nominal records of {e.shape[1]} samples are shorter than min_samples = {nmin}"
            )
        w = sliding_window_view(e, nmin + 1, axis=1)
        moving = float(np.quantile(np.ptp(w, axis=2), quantile)) / scale
        thr = max(moving, float(g.max())) * (1.0 + margin)
    else:
        thr = float(_threshold(g, pfa, per, margin, _dt(s), Z, "design_stuck")[0])
    return StuckDetector(
        measured, expected, tol=tol, scale=scale, threshold=max(thr, 1e-12), min_samples=nmin, warmup=skip
    )
