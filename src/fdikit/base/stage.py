"""The interfaces every stage shares: residual generators and residual processors.

Every stage works in two forms that must give identical numbers:

* **batch**: ``run(signals) -> Signals`` over a whole record, vectorised over runs (and over
  time where the algorithm allows);
* **streaming**: ``reset(runs)`` then ``step(...)`` once per sample, for live data.

A :class:`ResidualGenerator` consumes named input channels ``u`` (known inputs) and ``y``
(measurements) and produces named residual channels (and, for reconstructors, fault
estimates). A :class:`ResidualProcessor` consumes named residual channels and produces test
statistics, probabilities or alarms. :class:`fdikit.monitor.Monitor` chains them with a
decision rule. Streaming state is declared per class in ``_state_attrs``
(:class:`~fdikit.base.state.Stateful`), which gives checkpoint and restore.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import DataError
from ..signals import Signals, check_finite
from .state import Stateful

__all__ = ["ResidualGenerator", "ResidualProcessor"]


def _as_batch(x: Any, n: int, what: str, names: Sequence[str]) -> np.ndarray:
    """A sample as a ``(runs, n)`` float array; 1-D input is one run."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[None]
    if x.ndim != 2 or x.shape[1] != n:
        raise DataError(f"{what} sample must have shape (runs, {n}) for channels {list(names)}, "
                        f"got {x.shape}")
    return x


def _plain_step(obj: Any, base: type) -> bool:
    """True when ``obj.step`` is the base class's checked wrapper around ``obj._step``."""
    return isinstance(obj, base) and type(obj).step is base.step and hasattr(obj, "_step")


class ResidualGenerator(Stateful):
    """Base class of residual generators (observers, filters, parity equations, SMOs).

    Subclasses set ``u_names`` (known-input channels), ``y_names`` (measured channels),
    ``output_names`` (what they produce) and implement :meth:`reset` and :meth:`_step`.
    :meth:`run` defaults to a loop over :meth:`step`; subclasses override it with a vectorised
    form and a test asserts both agree. Subclasses list their streaming state in
    ``_state_attrs`` (see :class:`~fdikit.base.state.Stateful`) for checkpoint and restore.
    """

    u_names: list[str]
    y_names: list[str]
    output_names: list[str]
    output_units: list[str] | None = None
    #: True for a class whose ``_step`` refuses non-finite input itself (with its own sample count)
    _checks_finite: bool = False

    def reset(self, runs: int = 1) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def step(self, u_k: Any, y_k: Any) -> np.ndarray:
        """Advance one sample. ``u_k``: (runs, n_u), ``y_k``: (runs, n_y) -> (runs, n_out).

        A NaN or inf is refused with a :class:`DataError` naming the channel, before any state
        changes (a :class:`~fdikit.monitor.Monitor` with ``on_invalid="hold"`` holds such samples
        instead)."""
        u = _as_batch(u_k, len(self.u_names), "input", self.u_names)
        y = _as_batch(y_k, len(self.y_names), "measurement", self.y_names)
        if not self._checks_finite and not np.isfinite(u.sum() + y.sum()):  # before any state changes
            check_finite(u, self.u_names, what="input")
            check_finite(y, self.y_names, what="measurement")
        return self._step(u, y)

    def _inputs(self, signals: Signals) -> tuple[np.ndarray, np.ndarray]:
        u = signals.values[:, :, signals.index(self.u_names)] if self.u_names else \
            np.zeros((signals.runs, signals.n_samples, 0))
        y = signals.values[:, :, signals.index(self.y_names)]
        return u, y

    def run(self, signals: Signals) -> Signals:
        """Residuals over a whole record (default: streaming loop; subclasses vectorise)."""
        u, y = self._inputs(signals)
        self.reset(signals.runs)
        out = np.empty((signals.runs, signals.n_samples, len(self.output_names)))
        for k in range(signals.n_samples):
            out[:, k] = self._step(u[:, k], y[:, k])
        return Signals(signals.t, out, self.output_names, self.output_units, check=False)


class ResidualProcessor(Stateful):
    """Base class of residual processors (threshold rules, GLRT, CUSUM, MHSSPT).

    Subclasses set ``input_names`` and ``output_names`` and implement :meth:`reset` and
    :meth:`_step`; :meth:`run` defaults to the streaming loop.
    """

    input_names: list[str]
    output_names: list[str]

    def reset(self, runs: int = 1) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def _step(self, r: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def step(self, r_k: Any) -> np.ndarray:
        """Advance one sample: ``r_k`` (runs, n_in) -> (runs, n_out)."""
        return self._step(_as_batch(r_k, len(self.input_names), "residual", self.input_names))

    def run(self, signals: Signals) -> Signals:
        r = signals.values[:, :, signals.index(self.input_names)]
        self.reset(signals.runs)
        out = np.empty((signals.runs, signals.n_samples, len(self.output_names)))
        for k in range(signals.n_samples):
            out[:, k] = self._step(r[:, k])
        return Signals(signals.t, out, self.output_names, check=False)
