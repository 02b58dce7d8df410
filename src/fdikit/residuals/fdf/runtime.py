"""The runtime of a filter design: :class:`FaultDetectionFilter` (batch ``run`` and streaming
``reset``/``step`` on the same compiled row update)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...base.stage import ResidualGenerator
from ...errors import ModelError
from ...signals import Signals
from .form import FilterDesign
from .kernels import _row_chunks, _run_kernel_chunked, _sparse_rows, _step_kernel

__all__ = ["FaultDetectionFilter"]

class FaultDetectionFilter(ResidualGenerator):
    """Runtime of a :class:`FilterDesign`: batch ``run`` and streaming ``reset``/``step``.

    Both paths call the same compiled row update (numba, strict IEEE arithmetic in a fixed
    order), sample by sample, so their outputs are bitwise equal; the batch path loops over
    runs and samples inside compiled code. The update multiplies the structural nonzeros of
    ``[[C, Dv], [A, Bv]]`` only (a stacked bank is block-diagonal), in the dense product's order.

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.array([[-1.0]]), 0.1, [], ["y"], ["r"])
    >>> f = FaultDetectionFilter(d)
    >>> f.reset(1)
    >>> [float(f.step(np.zeros(0), [1.0])[0, 0]) for _ in range(3)]
    [-1.0, 0.0, 0.5]
    """

    def __init__(self, design: FilterDesign, x0: Any = None):
        self.design = design
        self.u_names = list(design.u_names)
        self.y_names = list(design.y_names)
        self.output_names = list(design.residual_names)
        nf = design.order
        self.x0 = np.zeros(nf) if x0 is None else np.asarray(x0, float).reshape(nf)
        self._A = np.ascontiguousarray(design.A, dtype=float)
        self._C = np.ascontiguousarray(design.C, dtype=float)
        self._Bv = np.ascontiguousarray(np.hstack([design.Bu, design.By]), dtype=float)
        self._Dv = np.ascontiguousarray(np.hstack([design.Du, design.Dy]), dtype=float)
        self._rows = _sparse_rows(np.block([[self._C, self._Dv], [self._A, self._Bv]]))
        self._chunks = _row_chunks(*self._rows)
        self.reset(1)

    _state_attrs = ("_xi",)

    def reset(self, runs: int = 1) -> None:
        self._xi = np.ascontiguousarray(np.tile(self.x0, (runs, 1)))

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        if u.shape[0] != self._xi.shape[0]:
            raise ModelError(f"sample has {u.shape[0]} runs but the filter was reset for "
                             f"{self._xi.shape[0]}")
        r = np.empty((u.shape[0], self._C.shape[0]))
        uy = np.ascontiguousarray(np.concatenate((u, y), axis=1), dtype=float)
        _step_kernel(self._xi, uy, *self._rows, r)
        return r

    def run(self, signals: Signals) -> Signals:
        """Residuals over a record (all runs at once, compiled time recursion)."""
        u, y = self._inputs(signals)
        if signals.n_samples > 1:
            self._check_dt(np.diff(signals.t), signals)
        self.reset(signals.runs)
        v = np.ascontiguousarray(np.concatenate([u, y], axis=2), dtype=float)
        return Signals(signals.t, self._run_values(v), self.output_names, check=False)

    def _check_dt(self, dts: np.ndarray, signals: Signals) -> None:
        """Refuse a record (sample steps ``dts``) not sampled at the design's ``dt``."""
        if np.max(np.abs(dts - self.design.dt)) > 1e-6 * self.design.dt:
            raise ModelError(f"signals are sampled at {signals.dt:g} s but the filter was designed "
                             f"for dt = {self.design.dt:g} s")

    def _run_values(self, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Residuals (R, T, q) of the inputs ``v = [u, y]`` (R, T, m, contiguous float), from the
        current state (advanced to the end), into ``out`` when given (contiguous)."""
        if out is None:
            out = np.empty((v.shape[0], v.shape[1], len(self.output_names)))
        chunks = getattr(self, "_chunks", None)
        if chunks is None:  # an object restored without __init__
            chunks = self._chunks = _row_chunks(*self._rows)
        _run_kernel_chunked(self._xi, v, *chunks, out)
        return out
