"""Nonlinear model protocol: ``x' = f(t, x, u, p)``, ``y = h(t, x, u, p)`` with named parameters.

Conventions (shared by :mod:`fdikit.sim` and :func:`fdikit.model.linearize`):

* ``x`` has shape ``(runs, n)`` and ``u`` shape ``(runs, m)``; ``f`` returns ``(runs, n)`` and
  ``h`` returns ``(runs, p)``. Models are written once, vectorised over runs (a single
  evaluation is ``runs == 1``).
* ``p`` is a mapping from parameter name to a float or to an array of shape ``(runs,)`` (one
  value per run: Monte Carlo and parametric faults ``param:<name>`` use this); write models so
  that both broadcast against ``x``, e.g. ``np.reshape(p["k"], (-1, 1)) * x``.
* ``u`` holds the model's inputs in the order of ``inputs``; the input groups
  (controls, disturbances, faults, noise) name which of them are which.
* Optional analytic Jacobians ``jac_x(t, x, u, p)`` -> ``(runs, n, n)`` etc.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..errors import ModelError

__all__ = ["NonlinearModel", "NonlinearModelProtocol"]


@runtime_checkable
class NonlinearModelProtocol(Protocol):
    """What fdikit needs of a nonlinear plant."""

    states: list[str]
    inputs: list[str]
    outputs: list[str]
    params: dict[str, float]

    def f(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray: ...

    def h(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray: ...


class NonlinearModel:
    """A nonlinear model from two callables, or a base class for plants that override f and h.

    Parameters
    ----------
    f, h : callable ``(t, x, u, p) -> array``
        State derivative ``(runs, n)`` and output ``(runs, p)``; see the module docstring.
    states, inputs, outputs : sequence of str
    params : mapping name -> float
        Nominal parameter values.
    groups : mapping, optional
        Input group of each input name: ``{"u": [...], "d": [...], "w": [...]}``; inputs not
        listed are controls.
    jac_x, jac_u : callable, optional
        Analytic Jacobians ``(runs, n, n)`` and ``(runs, n, m)``.
    units : mapping, optional
        Units of states, inputs, outputs and parameters by name.
    name : str

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import NonlinearModel
    >>> m = NonlinearModel(lambda t, x, u, p: -np.reshape(p["k"], (-1, 1)) * x**3 + u,
    ...                    lambda t, x, u, p: x, ["x"], ["u"], ["y"], {"k": 2.0})
    >>> m.f(0.0, np.array([[1.0]]), np.array([[0.5]]), m.params).tolist()
    [[-1.5]]
    """

    def __init__(
        self,
        f: Callable | None = None,
        h: Callable | None = None,
        states: Sequence[str] = (),
        inputs: Sequence[str] = (),
        outputs: Sequence[str] = (),
        params: Mapping[str, float] | None = None,
        *,
        groups: Mapping[str, Sequence[str]] | None = None,
        jac_x: Callable | None = None,
        jac_u: Callable | None = None,
        units: Mapping[str, str] | None = None,
        name: str = "",
    ):
        if f is not None:
            self._f = f
        if h is not None:
            self._h = h
        self.states = list(states)
        self.inputs = list(inputs)
        self.outputs = list(outputs)
        self.params = {k: float(v) for k, v in (params or {}).items()}
        self.units = dict(units or {})
        self.name = name
        self._jac_x = jac_x
        self._jac_u = jac_u
        for what, names in (("state", self.states), ("input", self.inputs), ("output", self.outputs)):
            if len(set(names)) != len(names):
                raise ModelError(f"duplicated {what} names in {names}")
        self.groups = {"u": [], "d": [], "w": []}
        listed = set()
        for g, names in (groups or {}).items():
            if g not in ("u", "d", "w"):
                raise ModelError(f"unknown input group {g!r} (use 'u', 'd' or 'w'; faults are "
                                 "declared by name: actuator:, sensor:, param:)")
            for s in names:
                if s not in self.inputs:
                    raise ModelError(f"group {g!r} names unknown input {s!r}; inputs: {self.inputs}")
            self.groups[g] = list(names)
            listed |= set(names)
        self.groups["u"] = self.groups["u"] or [s for s in self.inputs if s not in listed]

    # -- the protocol ----------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        return len(self.states)

    def f(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        if not hasattr(self, "_f"):
            raise NotImplementedError("give f or override NonlinearModel.f")
        return self._f(t, x, u, p)

    def h(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        if not hasattr(self, "_h"):
            raise NotImplementedError("give h or override NonlinearModel.h")
        return self._h(t, x, u, p)

    def jac_x(self, t, x, u, p):
        """Analytic state Jacobian ``(runs, n, n)``, or ``None`` when not provided."""
        return None if self._jac_x is None else self._jac_x(t, x, u, p)

    def jac_u(self, t, x, u, p):
        """Analytic input Jacobian ``(runs, n, m)``, or ``None`` when not provided."""
        return None if self._jac_u is None else self._jac_u(t, x, u, p)

    # -- helpers ---------------------------------------------------------------------------
    def param_values(self, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Nominal parameters updated with ``overrides``; unknown names raise."""
        p = dict(self.params)
        for k, v in (overrides or {}).items():
            if k not in p:
                raise ModelError(f"unknown parameter {k!r}; parameters: {sorted(p)}")
            p[k] = v
        return p

    def __repr__(self) -> str:
        return (f"NonlinearModel{(' ' + repr(self.name)) if self.name else ''}: "
                f"states={self.states}, inputs={self.inputs}, outputs={self.outputs}, "
                f"params={sorted(self.params)}")
