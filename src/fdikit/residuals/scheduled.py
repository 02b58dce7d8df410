"""Gain scheduling by residual blending: a bank of residual filters designed at several operating
points, run in parallel, whose residual is the linear interpolation, in a measured scheduling
variable, between the two filters designed at the nearest points. Every filter runs all the time,
so its state is always current when the operating point moves into its range.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from ..base.stage import ResidualGenerator
from ..errors import DataError
from ..signals import Signals
from .fdf import FaultDetectionFilter, FilterDesign

__all__ = ["ScheduledFilter"]


class ScheduledFilter(ResidualGenerator):
    """Residual filters designed at several operating points, blended by a scheduling variable.

    ``r = (1 - w) r_i + w r_(i+1)`` with ``p_i <= v < p_(i+1)`` and ``w = (v - p_i) / (p_(i+1) -
    p_i)``; ``v`` is clipped to ``[p_0, p_last]``.

    Parameters
    ----------
    points : sequence of float
        The operating points of the designs (e.g. speeds, m/s), increasing.
    filters : sequence of FilterDesign or ResidualGenerator
        One per point (a design is run by :class:`~fdikit.residuals.FaultDetectionFilter`), all
        reading the same channels and producing the same residuals.
    variable : str
        The scheduling channel. When it is one of the filters' measurements it is read from there
        (times ``scale``); otherwise it is an extra known input, appended to ``u_names``.
    scale : float
        Factor from the measured channel to the scheduling variable (e.g. a wheel radius over 2 for
        a sum of two wheel speeds in rad/s -> speed in m/s).

    Examples
    --------
    >>> mk = lambda g: FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                             np.zeros((1, 1)), np.array([[g]]), 0.1, ["u"], ["y"], ["r"])
    >>> f = ScheduledFilter([10.0, 20.0], [mk(1.0), mk(3.0)])
    >>> f.u_names, f.y_names
    (['u', 'speed'], ['y'])
    >>> f.reset(1)
    >>> float(f.step([0.0, 15.0], [1.0])[0, 0])       # halfway: (1 + 3) / 2
    2.0
    """

    _state_attrs = ("filters",)

    def __init__(self, points: Sequence[float], filters: Sequence[Any], *, variable: str = "speed",
                 scale: float = 1.0):
        self.speeds = np.asarray(points, float)
        if self.speeds.ndim != 1 or self.speeds.size < 1 or not np.all(np.isfinite(self.speeds)) \
                or np.any(np.diff(self.speeds) <= 0):
            raise DataError(f"scheduling points must be finite and increasing, got {points}")
        filters = list(filters)
        if len(filters) != self.speeds.size:
            raise DataError(f"{self.speeds.size} scheduling points but {len(filters)} filters")
        if not np.isfinite(scale) or scale == 0:
            raise DataError(f"scale must be finite and nonzero, got {scale}")
        self.designs = [f for f in filters if isinstance(f, FilterDesign)]
        if self.designs and len(self.designs) != len(filters):
            raise DataError("give either designs (FilterDesign) or residual generators, not both")
        self.filters = [FaultDetectionFilter(f) if isinstance(f, FilterDesign) else f for f in filters]
        f0 = self.filters[0]
        for f in self.filters:
            if (list(f.u_names), list(f.y_names), list(f.output_names)) != \
                    (list(f0.u_names), list(f0.y_names), list(f0.output_names)):
                raise DataError("scheduled filters must read and produce the same channels")
        self.variable, self.scale = str(variable), float(scale)
        self.y_names = list(f0.y_names)
        self._iv = self.y_names.index(self.variable) if self.variable in self.y_names else None
        self.u_names = list(f0.u_names) + ([] if self._iv is not None else [self.variable])
        self.output_names = list(f0.output_names)
        self.reset(1)

    @property
    def points(self) -> np.ndarray:
        """The operating points (the ``speeds`` attribute, named for the common case)."""
        return self.speeds

    def reset(self, runs: int = 1) -> None:
        for f in self.filters:
            f.reset(runs)

    def _weights(self, v: np.ndarray) -> np.ndarray:
        """(..., K) interpolation weights for scheduling values ``v`` (...)."""
        K = self.speeds.size
        W = np.zeros((*v.shape, K))
        if K == 1:
            W[..., 0] = 1.0
            return W
        vc = np.clip(v, self.speeds[0], self.speeds[-1])
        i = np.clip(np.searchsorted(self.speeds, vc, side="right") - 1, 0, K - 2)
        w = (vc - self.speeds[i]) / (self.speeds[i + 1] - self.speeds[i])
        np.put_along_axis(W, i[..., None], (1.0 - w)[..., None], axis=-1)
        np.put_along_axis(W, (i + 1)[..., None], w[..., None], axis=-1)
        return W

    def _blend(self, R: list[np.ndarray], v: np.ndarray) -> np.ndarray:
        W = self._weights(v)
        out = np.zeros_like(R[0])
        for k, r in enumerate(R):
            out += W[..., k, None] * r
        return out

    def _step(self, u, y):
        if self._iv is None:
            R = [f._step(u[:, :-1], y) for f in self.filters]
            return self._blend(R, u[:, -1])
        R = [f._step(u, y) for f in self.filters]
        return self._blend(R, self.scale * y[:, self._iv])

    def _plain_filters(self) -> bool:
        """True when every filter is a plain :class:`FaultDetectionFilter` (its batch run is
        :meth:`FaultDetectionFilter._run_values` of its inputs)."""
        return all(type(f).run is FaultDetectionFilter.run and type(f)._inputs is ResidualGenerator._inputs
                   for f in self.filters)

    def _variable(self, signals: Signals) -> np.ndarray:
        v = signals.values[:, :, signals.index([self.variable])[0]]
        return self.scale * v if self._iv is not None else v

    def run(self, signals: Signals) -> Signals:
        if not self._plain_filters():
            R = [f.run(signals).values for f in self.filters]
            return Signals(signals.t, self._blend(R, self._variable(signals)), self.output_names, check=False)
        # the filters read the same channels: their inputs gathered once, their residuals into
        # one array, blended in one compiled pass (the arithmetic of _blend)
        f0 = self.filters[0]
        u, y = f0._inputs(signals)
        if signals.n_samples > 1:
            dts = np.diff(signals.t)
            for f in self.filters:
                f._check_dt(dts, signals)
        v = self._variable(signals)
        uy = np.ascontiguousarray(np.concatenate([u, y], axis=2), dtype=float)
        R = np.empty((len(self.filters), signals.runs, signals.n_samples, len(self.output_names)))
        for k, f in enumerate(self.filters):
            f.reset(signals.runs)
            f._run_values(uy, R[k])
        W = np.ascontiguousarray(self._weights(v))
        out = np.empty(R.shape[1:])
        _blend_kernel(R, W, out)
        return Signals(signals.t, out, self.output_names, check=False)


@njit(cache=True)
def _blend_kernel(R, W, out):  # pragma: no cover - compiled
    """out = sum_k W[..., k] R[k], summed from 0.0 in the order of k (as :meth:`ScheduledFilter._blend`):
    R (K, runs, T, q), W (runs, T, K), out (runs, T, q)."""
    K = R.shape[0]
    for i in range(R.shape[1]):
        for t in range(R.shape[2]):
            for c in range(R.shape[3]):
                acc = 0.0
                for k in range(K):
                    acc += W[i, t, k] * R[k, i, t, c]
                out[i, t, c] = acc
