"""Apply a list of faults to the signals of a model, vectorised over runs.

The simulator (and anyone replaying recorded data with synthetic faults) calls

* :meth:`FaultInjector.actuator` on the true control input ``u`` (runs, m) before the plant,
* :meth:`FaultInjector.sensor` on the clean measurement ``y`` (runs, p),
* :meth:`FaultInjector.params` on the parameter dict,
* :meth:`FaultInjector.fault_inputs` for the additive fault inputs declared on a linear model,

each at one time ``t``. Faults on the same channel are applied in the order they are listed.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import DataError, ModelError
from .signals import TIME_TOL, BoundFault, Fault, Parametric

__all__ = ["FaultInjector"]


class FaultInjector:
    """Resolve fault targets against a model's names and apply the faults per time step.

    Parameters
    ----------
    faults : iterable of Fault
    inputs : sequence of str
        Control inputs that ``actuator:<input>`` may name (columns of ``u``).
    outputs : sequence of str
        Outputs that ``sensor:<output>`` may name (columns of ``y``).
    params : sequence of str
        Parameters that ``param:<name>`` may name.
    fault_inputs : sequence of str
        Additive fault inputs (declared on a linear model) that a plain name may name.
    model_name : str
        Used in error messages.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.faults import Bias, FaultInjector
    >>> inj = FaultInjector([Bias("sensor:v", 0.5, start=1.0)], outputs=["v", "w"])
    >>> inj.bind(np.arange(2))
    >>> inj.sensor(1.0, np.zeros((2, 2))).tolist()
    [[0.5, 0.0], [0.5, 0.0]]
    """

    def __init__(
        self,
        faults: Iterable[Fault],
        *,
        inputs: Sequence[str] = (),
        outputs: Sequence[str] = (),
        params: Sequence[str] = (),
        fault_inputs: Sequence[str] = (),
        model_name: str = "",
    ):
        self.faults = list(faults)
        self.names = {"actuator": list(inputs), "sensor": list(outputs), "param": list(params),
                      "input": list(fault_inputs)}
        self.model_name = model_name
        self._targets: list[tuple[str, int]] = []
        for f in self.faults:
            if not isinstance(f, Fault):
                raise DataError(f"faults must be Fault objects (Bias, Ramp, ...), got {f!r}")
            if f.target in self.names["input"] and f.kind != "input":
                # a linear model may declare a fault input named like "param:K_f" (a linearised
                # parametric fault direction): the declared name wins.
                self._targets.append(("input", self._check_input(f)))
            else:
                self._targets.append((f.kind, self._resolve(f)))
        self._bound: list[BoundFault] = []
        self.eps = TIME_TOL

    def valid_targets(self) -> list[str]:
        """Every target string this model accepts."""
        out = [f"actuator:{s}" for s in self.names["actuator"]]
        out += [f"sensor:{s}" for s in self.names["sensor"]]
        out += [f"param:{s}" for s in self.names["param"]]
        out += list(self.names["input"])
        return out

    def _resolve(self, f: Fault) -> int:
        what = {"actuator": "actuator input", "sensor": "sensor output", "param": "parameter",
                "input": "fault input"}[f.kind]
        names = self.names[f.kind]
        if f.channel not in names:
            model = f" of model {self.model_name!r}" if self.model_name else ""
            raise ModelError(f"fault target {f.target!r}: unknown {what} {f.channel!r}{model}; "
                             f"valid targets: {self.valid_targets()}")
        if isinstance(f, Parametric) and f.kind != "param":
            raise ModelError(f"fault target {f.target!r}: a Parametric fault needs a 'param:<name>' "
                             "target (use Gain or Bias on signals)")
        if f.kind == "input":
            return self._check_input(f)
        return names.index(f.channel)

    def _check_input(self, f: Fault) -> int:
        if not type(f).additive:
            raise ModelError(f"fault target {f.target!r} is an additive fault input (0 when healthy); "
                             f"a {type(f).__name__} fault has no meaning there: use Bias, Ramp, "
                             "Sinusoid or Intermittent")
        return self.names["input"].index(f.target)

    # ------------------------------------------------------------------ per batch
    def bind(self, run_ids: Any, total: int | None = None, *, eps: float = TIME_TOL) -> None:
        """Resolve per-run magnitudes for the runs ``run_ids`` and clear the memories.

        ``total`` is the batch size when the run ids are ``range(total)`` (then per-run arrays
        must have exactly that length); ``eps`` is a time tolerance for the window tests (s).
        """
        ids = np.asarray(run_ids, dtype=int).reshape(-1)
        self._bound = [f.bind(ids, total) for f in self.faults]
        self.runs = ids.size
        self.eps = float(eps)

    def _of(self, kind: str) -> list[tuple[BoundFault, int]]:
        if len(self._bound) != len(self.faults):
            raise DataError("FaultInjector.bind(run_ids) must be called before applying faults")
        return [(b, j) for b, (k, j) in zip(self._bound, self._targets) if k == kind]

    def has(self, kind: str) -> bool:
        """Whether any fault targets ``kind`` (``actuator``, ``sensor``, ``param``, ``input``)."""
        return any(k == kind for k, _ in self._targets)

    def _columns(self, kind: str, t: float, a: np.ndarray) -> np.ndarray:
        out, copied = a, False
        for b, j in self._of(kind):
            if not b.fault.is_active(t, self.eps):
                continue
            if not copied:
                out = np.array(a, dtype=float, copy=True)
                copied = True
            out[:, j] = b.fault._apply(t, out[:, j], b.vals, b.mem)
        return out

    def actuator(self, t: float, u: np.ndarray) -> np.ndarray:
        """Faulty true input at time ``t``; ``u`` shape (runs, m). Does not modify ``u``."""
        return self._columns("actuator", t, u)

    def sensor(self, t: float, y: np.ndarray) -> np.ndarray:
        """Faulty measurement at time ``t``; ``y`` shape (runs, p). Does not modify ``y``."""
        return self._columns("sensor", t, y)

    def params(self, t: float, p: Mapping[str, Any]) -> dict[str, Any]:
        """Parameters at time ``t``: a new dict where faulty entries become (runs,) arrays."""
        out = dict(p)
        for b, j in self._of("param"):
            if b.fault.is_active(t, self.eps):
                name = self.names["param"][j]
                out[name] = b.fault._apply(t, out[name], b.vals, b.mem)
        return out

    def fault_inputs(self, t: float, runs: int) -> np.ndarray:
        """Values of the additive fault inputs at time ``t``, shape (runs, n_fault_inputs)."""
        out = np.zeros((runs, len(self.names["input"])))
        return self._columns("input", t, out)
