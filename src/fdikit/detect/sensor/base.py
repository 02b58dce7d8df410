"""The plumbing shared by the sensor-fault detectors: checked samples, warm-up and run-length
bookkeeping, per-channel parameters, and the ring-buffer window of the drift and gain kernels.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from ...base.stage import ResidualProcessor
from ...errors import DataError
from ...signals import Signals

#: Samples evaluated together by the window kernels: the candidate change points are swept once per
#: block, one vectorisable loop over the block's samples per candidate (their accumulators stay in
#: the L1/L2 cache). Long blocks spread the fixed cost of each candidate's loop (views, overlap
#: checks, remainder) over more samples: on the 1-minute, 50 Hz logs of the RAV4 monitor the
#: drift and gain kernels ran 20-30 % faster with 1024 than with 256.
_BLOCK = 1024
#: Blocks shorter than this (streaming, one sample at a time) take the plain per-sample loop.
_SCALAR_BELOW = 16


@njit(cache=True)
def _ring_history(buf, p0, h, out):  # pragma: no cover
    """The last ``h`` samples of a ring buffer (next write at ``p0``), oldest first, into ``out[:h]``."""
    W = buf.size
    for i in range(h):
        q = p0 - h + i
        if q < 0:
            q += W
        out[i] = buf[q]


def _per_channel(v: Any, c: int, what: str, names: Sequence[str], positive: bool = False) -> np.ndarray:
    a = np.asarray(v, float)
    if a.ndim > 1 or (a.ndim == 1 and a.size != c):
        raise DataError(
            f"{what} must be a scalar or one value per channel {list(names)}, got shape {a.shape}"
        )
    a = np.broadcast_to(a, (c,)).copy()
    if not np.all(np.isfinite(a)):
        raise DataError(f"{what} must be finite, got {a.tolist()}")
    if positive and np.any(a <= 0):
        bad = names[int(np.argmax(a <= 0))]
        raise DataError(f"{what} must be positive; channel {bad!r} has {a[int(np.argmax(a <= 0))]}")
    return a


def _window(W: Any, what: str) -> int:
    if isinstance(W, bool) or int(W) != W or W < 1:
        raise DataError(f"{what} must be an integer >= 1, got {W!r}")
    return int(W)


class _SensorDetector(ResidualProcessor):
    """Shared plumbing: checked samples, run length bookkeeping, repr."""

    _what = "detector"

    def _check(self, x: np.ndarray, k0: int) -> None:
        bad = ~np.isfinite(x)
        if bad.any():
            run, k, c = np.argwhere(bad)[0]
            raise DataError(
                f"{type(self).__name__} input {self.input_names[c]!r} is not finite at sample "
                f"{k0 + k} (run {run})"
            )

    def _runs(self, r: np.ndarray) -> None:
        if r.shape[0] != self._R:
            raise DataError(
                f"sample has {r.shape[0]} runs; the {type(self).__name__} was reset for {self._R}"
            )

    def _set_warmup(self, warmup: Any) -> None:
        if isinstance(warmup, bool) or int(warmup) != warmup or warmup < 0:
            raise DataError(f"{type(self).__name__} warmup must be an integer >= 0 (samples), got {warmup!r}")
        self.warmup = int(warmup)

    def run(self, signals: Signals) -> Signals:
        x = signals.values[:, :, signals.index(self.input_names)]
        self._check(x, 0)
        self.reset(signals.runs)
        T = signals.n_samples
        w = min(self.warmup, T)
        out = np.zeros((signals.runs, T, len(self.output_names)))
        if T > w:
            out[:, w:] = self._compute(np.ascontiguousarray(x[:, w:]))
        self._k = T
        return Signals(signals.t, out, self.output_names, check=False)

    def _step(self, r: np.ndarray) -> np.ndarray:
        self._runs(r)
        self._check(r[:, None, :], self._k)
        if self._k < self.warmup:  # warm-up: the sample is not taken in, nothing is tested
            self._k += 1
            return np.zeros((r.shape[0], len(self.output_names)))
        out = self._compute(np.ascontiguousarray(r[:, None, :]))
        self._k += 1
        return out[:, 0]

    def resume(self, n_held: int) -> None:
        """After ``n_held`` held (invalid) samples: start again, with the warm-up (the window would
        span the gap)."""
        self.reset(self._R)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self._repr_items())
        return f"{type(self).__name__}({args})"

    def to_dict(self) -> dict:
        """Configuration as plain data (see :mod:`fdikit.base.artifacts`)."""
        return dict(self._repr_items())

    @classmethod
    def from_dict(cls, d: dict) -> Any:
        return cls(**d)
