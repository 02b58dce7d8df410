"""The MHSSPT with a warm-up (:class:`WarmupMHSSPT`): the no-fault mean features while the
residual generators' start-up transient dies out, and again after every gap.
"""

from __future__ import annotations

import numpy as np

from .core import MHSSPT, table_direct
from .densities import UniformMeanGaussian

__all__ = ["WarmupMHSSPT"]


class WarmupMHSSPT(MHSSPT):
    """:class:`MHSSPT` that sees the no-fault mean features for the first ``warmup`` samples, while
    the residual generators' start-up transient (filter state zero, plant not at the design trim)
    dies out, and again after every gap (:meth:`resume`); afterwards the exact recursion. Batch and
    streaming alike.

    Examples
    --------
    >>> from fdikit.detect import UniformMeanGaussian
    >>> t = WarmupMHSSPT(["r"], {"none": UniformMeanGaussian([0], [0], [1]),
    ...                          "bias": UniformMeanGaussian([2], [4], [1])}, p=1e-3, warmup=5)
    >>> t.reset(1)
    >>> float(t.step([9.0])[0, 1]) < 0.01          # ignored during the warm-up
    True
    """

    _state_attrs = (*MHSSPT._state_attrs, "_warm_from")

    def __init__(self, *args, warmup: int = 0, **kw):
        super().__init__(*args, **kw)
        self.warmup = int(warmup)
        d0 = self.densities[0]
        self._x0 = np.asarray(getattr(d0, "low", np.zeros(len(self.input_names))), float)

    def reset(self, runs: int = 1) -> None:
        super().reset(runs)
        self._warm_from = 0

    def to_dict(self) -> dict:
        """Configuration as plain data (:meth:`MHSSPT.to_dict` and the warm-up length)."""
        return {**super().to_dict(), "warmup": self.warmup}

    @classmethod
    def from_dict(cls, d: dict) -> WarmupMHSSPT:
        dens = {h: UniformMeanGaussian(v["low"], v["high"], v["std"]) for h, v in d["densities"].items()}
        return cls(d["inputs"], dens, d["p"], d["pi"], d["q"], d["groups"], tabulate=d.get("tabulate"),
                   interpolation=d.get("interpolation", "linear"), warmup=d.get("warmup", 0))

    def resume(self, n_held: int) -> None:
        """Data returns after ``n_held`` held samples (:class:`fdikit.monitor.Monitor`,
        ``on_invalid="hold"``): the filters' states went stale over the gap, so the warm-up
        starts again from the next sample."""
        if n_held > 0:
            self._warm_from = self._k

    def _prepare(self, x):
        n = self.warmup - (self._k - self._warm_from)
        if n > 0:
            x = x.copy()
            x[:, :n] = self._x0
        return x

    @table_direct
    def _advance(self, x):
        return super()._advance(self._prepare(x))
