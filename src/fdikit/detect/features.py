"""Residual features: the (low-passed) norm of each group of residual channels, e.g. of each
filter's residual vector (ng-chen-speyer, Section IV-E), as the input of an MHSSPT."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numba import njit

from ..base.stage import ResidualProcessor
from ..errors import DataError
from ..signals import Signals

__all__ = ["FeatureNorms"]


@njit(cache=True)
def _norm_kernel(r, idx, starts, alpha, state, out):  # pragma: no cover - compiled
    """r (runs, T, R); feature j = low-pass of the norm of r[idx[starts[j]:starts[j+1]]]."""
    nf = starts.shape[0] - 1
    for i in range(r.shape[0]):
        for k in range(r.shape[1]):
            for j in range(nf):
                s = 0.0
                for c in range(starts[j], starts[j + 1]):
                    v = r[i, k, idx[c]]
                    s += v * v
                x = state[i, j] + alpha * (np.sqrt(s) - state[i, j])
                state[i, j] = x
                out[i, k, j] = x


class FeatureNorms(ResidualProcessor):
    """Residual features (ng-chen-speyer, Section IV-E): the norm of each group of residual channels.

    ``x_j[k] = x_j[k-1] + alpha (|r_(j)[k]| - x_j[k-1])`` (a first-order low-pass of the norm with
    time constant ``tau``, ``alpha = 1 - exp(-dt / tau)``; ``tau = 0`` gives the plain norm).

    Parameters
    ----------
    groups : mapping feature name -> list of residual channel names
    dt, tau : float
        Sample time and smoothing time constant (s).

    Examples
    --------
    >>> fn = FeatureNorms.from_dict(FeatureNorms({"n": ["a", "b"]}, dt=0.01, tau=0.0).to_dict())
    >>> fn.reset(1)
    >>> fn.step([3.0, 4.0]).tolist()
    [[5.0]]
    """

    _state_attrs = ("_x", "_first")

    def __init__(self, groups: Mapping[str, Sequence[str]], dt: float, tau: float = 0.0):
        self.groups = {str(k): list(v) for k, v in groups.items()}
        self.input_names = list(dict.fromkeys(c for v in self.groups.values() for c in v))
        self.output_names = list(self.groups)
        self._idx = np.array([self.input_names.index(c) for v in self.groups.values() for c in v], np.int64)
        self._starts = np.cumsum([0] + [len(v) for v in self.groups.values()]).astype(np.int64)
        self.dt, self.tau = float(dt), float(tau)
        self.alpha = 1.0 if tau <= 0 else float(1.0 - np.exp(-dt / tau))
        self.reset(1)

    def to_dict(self) -> dict[str, Any]:
        """Configuration as plain data (a design artifact)."""
        return {"groups": self.groups, "dt": self.dt, "tau": self.tau}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FeatureNorms:
        return cls(d["groups"], d["dt"], d["tau"])

    def reset(self, runs: int = 1) -> None:
        self._x = np.zeros((runs, len(self.output_names)))
        self._first = True

    def _run(self, r):
        out = np.empty((r.shape[0], r.shape[1], len(self.output_names)))
        if self._x.shape[0] != r.shape[0]:
            raise DataError(f"sample has {r.shape[0]} runs; features were reset for {self._x.shape[0]}")
        _norm_kernel(np.ascontiguousarray(r), self._idx, self._starts, self.alpha, self._x, out)
        return out

    def _step(self, r):
        return self._run(r[:, None])[:, 0]

    def run(self, signals: Signals) -> Signals:
        r = signals.values[:, :, signals.index(self.input_names)]
        self.reset(signals.runs)
        return Signals(signals.t, self._run(r), self.output_names, check=False)
