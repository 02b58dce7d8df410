"""The intermittent-fault detector: bursts of a large residual that come and go, counted over a
window (:class:`IntermittentDetector`, its compiled burst kernel, and
:func:`design_intermittent`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from ...errors import DataError
from ...signals import Signals
from .base import _per_channel, _SensorDetector, _window
from .calibrate import _nominal

__all__ = ["IntermittentDetector", "design_intermittent"]


@njit(cache=True)
def _burst_kernel(x, mu0, side, level, release, gap, W, out, on, quiet, buf, pos, cnt):  # pragma: no cover
    """Burst counts: x (R, T, C) -> out (R, T, C) onsets within the last W samples (``side`` 0:
    |r - mu0|; +-1: the signed deviation)."""
    R, T, C = x.shape
    for r in range(R):
        for c in range(C):
            for k in range(T):
                d = x[r, k, c] - mu0[c]
                a = abs(d) if side[c] == 0 else side[c] * d
                onset = 0
                if on[r, c] == 0:
                    if a > level[c]:
                        on[r, c] = 1
                        quiet[r, c] = 0
                        onset = 1
                else:
                    if a < release[c]:
                        quiet[r, c] += 1
                        if quiet[r, c] >= gap:
                            on[r, c] = 0
                    else:
                        quiet[r, c] = 0
                p = pos[r, c]
                cnt[r, c] += onset - buf[r, c, p]
                buf[r, c, p] = onset
                pos[r, c] = (p + 1) % W
                out[r, k, c] = cnt[r, c]


class IntermittentDetector(_SensorDetector):
    """Bursts of a fault that come and go: episodes of a large residual counted over a window.

    An episode starts when ``|r - mu0| > level`` and ends once ``|r - mu0| < release`` has held
    for ``gap`` samples (hysteresis and debounce: noise near the level does not make a new
    episode of every crossing). The statistic is the number of episode onsets in the last ``W``
    samples over ``min_bursts``: a permanent fault is one episode, an intermittent one several.

    Parameters
    ----------
    inputs : sequence of str
        Residual channels (band-limit them first: a burst is then a clear hump).
    level : float or sequence
        Onset level of ``|r - mu0|`` per channel.
    W : int
        Window over which onsets are counted (samples).
    min_bursts : int
        Onsets within ``W`` that make the fault intermittent (output ``>= 1``).
    mu0 : float or sequence
        Nominal mean per channel.
    release : float or sequence, optional
        Level below which an episode may end (default ``level / 2``).
    gap : int
        Samples below ``release`` that end an episode.
    signed : bool
        Count episodes above ``+level`` and below ``-level`` separately (which sensor of a
        difference is intermittent): two outputs per input.
    warmup : int
        Samples after a reset (and after a gap, :meth:`resume`) that are not taken in: the output
        is 0 there (filter transients at the start of a log).

    Notes
    -----
    Outputs ``"<input>:intermittent"`` per input (alarm at >= 1); with ``signed``,
    ``"<input>:intermittent+"`` and ``"<input>:intermittent-"``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(60.0)
    >>> r = np.where((t % 20 >= 5) & (t % 20 < 10), 1.0, 0.0)     # on 5 samples of every 20
    >>> d = IntermittentDetector(["r"], level=0.5, W=50, min_bursts=3, gap=2)
    >>> out = d.run(Signals(t, r, ["r"]))["r:intermittent"][0]
    >>> out[[5, 25, 45]].round(3).tolist()
    [0.333, 0.667, 1.0]
    """

    _state_attrs = ("_on", "_quiet", "_buf", "_pos", "_cnt", "_k", "_R")

    def __init__(
        self,
        inputs: Sequence[str],
        level=1.0,
        W: int = 500,
        min_bursts: int = 3,
        *,
        mu0=0.0,
        release=None,
        gap: int = 5,
        signed: bool = False,
        warmup: int = 0,
    ):
        self._set_warmup(warmup)
        self.input_names = [str(s) for s in ([inputs] if isinstance(inputs, str) else inputs)]
        c = len(self.input_names)
        if c == 0:
            raise DataError("IntermittentDetector needs at least one input channel")
        self.W = _window(W, "IntermittentDetector window W")
        self.min_bursts = _window(min_bursts, "IntermittentDetector min_bursts")
        self.gap = _window(gap, "IntermittentDetector gap")
        self.mu0 = _per_channel(mu0, c, "IntermittentDetector mu0", self.input_names)
        self.level = _per_channel(level, c, "IntermittentDetector level", self.input_names, positive=True)
        self.release = (
            0.5 * self.level
            if release is None
            else _per_channel(release, c, "IntermittentDetector release", self.input_names, positive=True)
        )
        if np.any(self.release > self.level):
            raise DataError(
                f"IntermittentDetector release {self.release.tolist()} must not exceed level "
                f"{self.level.tolist()}"
            )
        self.signed = bool(signed)
        if self.signed:
            self.output_names = [f"{s}:intermittent{g}" for s in self.input_names for g in "+-"]
            self._side = np.tile([1, -1], c).astype(np.int64)
        else:
            self.output_names = [f"{s}:intermittent" for s in self.input_names]
            self._side = np.zeros(c, np.int64)
        self.reset(1)

    def _repr_items(self):
        return [
            ("inputs", list(self.input_names)),
            ("level", self.level.tolist()),
            ("W", self.W),
            ("min_bursts", self.min_bursts),
            ("mu0", self.mu0.tolist()),
            ("release", self.release.tolist()),
            ("gap", self.gap),
            ("signed", self.signed),
            ("warmup", self.warmup),
        ]

    def reset(self, runs: int = 1) -> None:
        c = len(self.output_names)
        self._R = int(runs)
        self._on = np.zeros((runs, c), np.int64)
        self._quiet = np.zeros((runs, c), np.int64)
        self._buf = np.zeros((runs, c, self.W), np.int64)
        self._pos = np.zeros((runs, c), np.int64)
        self._cnt = np.zeros((runs, c), np.int64)
        self._k = 0

    def _compute(self, x: np.ndarray) -> np.ndarray:
        m = 2 if self.signed else 1
        if m > 1:
            x = np.ascontiguousarray(np.repeat(x, m, axis=2))
        R, T, C = x.shape
        rep = lambda a: np.repeat(a, m)  # noqa: E731
        out = np.empty((R, T, C))
        _burst_kernel(
            x,
            rep(self.mu0),
            self._side,
            rep(self.level),
            rep(self.release),
            self.gap,
            self.W,
            out,
            self._on,
            self._quiet,
            self._buf,
            self._pos,
            self._cnt,
        )
        return out / self.min_bursts


def design_intermittent(
    nominal: Signals,
    inputs: Sequence[str],
    W: int,
    *,
    min_bursts: int = 3,
    gap: int = 5,
    margin: float = 0.5,
    release: float = 0.5,
    signed: bool = False,
    skip: int = 0,
) -> IntermittentDetector:
    """An :class:`IntermittentDetector` calibrated on nominal data: ``mu0`` is each residual's mean
    and the onset level is the largest nominal ``|r - mu0|`` times ``1 + margin`` (no nominal
    sample starts an episode), the release level ``release`` times that.

    Parameters
    ----------
    nominal : Signals
    inputs : sequence of str
    W, min_bursts, gap, signed :
        See :class:`IntermittentDetector`.
    margin : float
        Relative margin of the level over the largest nominal deviation.
    release : float
        Release level as a fraction of the onset level (0 < release <= 1).
    skip : int
        Samples left out at the start of every run; the detector's ``warmup``.

    Returns
    -------
    IntermittentDetector

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(3)
    >>> t = np.arange(3000) * 0.02
    >>> nom = Signals(t, 0.1 * rng.standard_normal(t.size), ["r"])
    >>> d = design_intermittent(nom, ["r"], W=500)
    >>> bool(d.run(nom)["r:intermittent"].max() == 0)
    True
    """
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    s = _nominal(nominal, inputs, skip)
    if not (np.isfinite(margin) and margin >= 0):
        raise DataError(f"design_intermittent: margin must be finite and >= 0, got {margin}")
    if not 0 < release <= 1:
        raise DataError(f"design_intermittent: release must be in (0, 1], got {release}")
    r = s.values[:, skip:][:, :, s.index(inputs)].reshape(-1, len(inputs))
    mu0 = r.mean(axis=0)
    level = np.maximum(np.abs(r - mu0).max(axis=0), 1e-300) * (1.0 + margin)
    return IntermittentDetector(
        inputs, level, W, min_bursts, mu0=mu0, release=release * level, gap=gap, signed=signed, warmup=skip
    )
