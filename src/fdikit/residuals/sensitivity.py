"""Residuals together with their first-order signatures for plant parameter changes.

A residual generator built on a model with parameter ``theta`` responds to a plant whose
parameter is ``theta (1 + delta)`` with, to first order, ``r = r_0 + delta sig``. The signature
``sig`` is measured on the data themselves by twin generators whose models carry
``theta (1 + h)`` for each parameter of interest: a model ``h`` too large sees what a plant ``h``
too small would show, so ``sig = (r_base - r_twin) / h``. The twins read the same inputs and
measurements and run beside the base generator (streaming or batch, same numbers), so the
signature follows the actual operating point (for the ABS: every slip cycle of this stop).

The signatures feed :class:`fdikit.detect.DirectionalGLRT`, whose amplitude estimate is then
the relative parameter change ``delta`` itself. This is the local (score-test) view of
parameter-fault detection: the most powerful test for a small change of one parameter, where a
test for a change in the residual *mean* sees nothing because the signature changes sign.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..base.stage import ResidualGenerator
from ..errors import DataError
from ..signals import Signals

__all__ = ["ParameterSensitivity"]


class ParameterSensitivity(ResidualGenerator):
    """A residual generator and its parameter signatures from twin generators.

    Parameters
    ----------
    base : ResidualGenerator
        The generator on the nominal model.
    twins : mapping label -> ResidualGenerator
        For each parameter label, the same generator on a model whose parameter is scaled by
        ``1 + steps[label]``; all must read the same channels and write the same outputs as
        ``base``.
    steps : float or mapping label -> float
        Relative steps ``h`` (non-zero, ``|h| < 1``).
    outputs : sequence of str, optional
        Base outputs that get signatures (default: all).

    Notes
    -----
    Outputs the base outputs followed by ``"sig:<output>:<label>"`` for every label and output:
    the residual change per unit relative change of the plant parameter.

    Examples
    --------
    >>> from fdikit.systems.abs.residuals import observer_sensitivity
    >>> from fdikit.systems.abs.plant import Scenario, simulate
    >>> gen = observer_sensitivity(0.01, ["I_w"])
    >>> gen.output_names
    ['r3', 'r4', 'sig:r3:I_w', 'sig:r4:I_w']
    >>> res = simulate(None, Scenario(t_end=3.0, v0=15.0), runs=2, seed=0)
    >>> gen.run(res.y.concat_channels(res.u)).values.shape
    (2, 300, 4)
    """

    def __init__(self, base: ResidualGenerator, twins: Mapping[str, ResidualGenerator], steps: Any = 0.01,
                 *, outputs=None):
        if not twins:
            raise DataError("ParameterSensitivity needs at least one twin generator")
        self.base = base
        self.labels = [str(k) for k in twins]
        self.twins = [twins[k] for k in twins]
        st = steps if isinstance(steps, Mapping) else dict.fromkeys(self.labels, steps)
        missing = [k for k in self.labels if k not in st]
        if missing:
            raise DataError(f"ParameterSensitivity: no step for {missing}")
        self.steps = {k: float(st[k]) for k in self.labels}
        for k, h in self.steps.items():
            if not (np.isfinite(h) and h != 0.0 and abs(h) < 1.0):
                raise DataError(f"ParameterSensitivity: relative step of {k!r} must be finite, non-zero "
                                f"and |h| < 1, got {h}")
        for k, g in zip(self.labels, self.twins):
            for attr in ("u_names", "y_names", "output_names"):
                if list(getattr(g, attr)) != list(getattr(base, attr)):
                    raise DataError(f"ParameterSensitivity: twin {k!r} has {attr} {list(getattr(g, attr))}, "
                                    f"the base generator {list(getattr(base, attr))}")
        outs = list(base.output_names) if outputs is None else [str(o) for o in outputs]
        unknown = [o for o in outs if o not in base.output_names]
        if unknown:
            raise DataError(f"ParameterSensitivity: outputs {unknown} are not among "
                            f"{list(base.output_names)}")
        self.signed = outs
        self._cols = [list(base.output_names).index(o) for o in outs]
        self.u_names = list(base.u_names)
        self.y_names = list(base.y_names)
        self.output_names = list(base.output_names) + [f"sig:{o}:{k}" for k in self.labels for o in outs]
        bu = list(base.output_units) if base.output_units else [""] * len(base.output_names)
        self.output_units = bu + [bu[c] for _ in self.labels for c in self._cols]
        self.reset(1)

    _state_attrs = ("base", "twins")

    def reset(self, runs: int = 1) -> None:
        self.base.reset(runs)
        for g in self.twins:
            g.reset(runs)

    def _combine(self, r0: np.ndarray, rs: list[np.ndarray]) -> np.ndarray:
        parts = [r0] + [(r0[..., self._cols] - r[..., self._cols]) / self.steps[k]
                        for k, r in zip(self.labels, rs)]
        return np.concatenate(parts, axis=-1)

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        r0 = self.base._step(u, y)
        return self._combine(r0, [g._step(u, y) for g in self.twins])

    def run(self, signals: Signals) -> Signals:
        r0 = self.base.run(signals).values
        out = self._combine(r0, [g.run(signals).values for g in self.twins])
        return Signals(signals.t, out, self.output_names, self.output_units, check=False)

    def to_dict(self) -> dict:
        """The design as plain data: each generator's class path and design, the steps and outputs."""
        from ..base.artifacts import _class_path

        def one(g):
            where = _class_path(g)
            if where is None:
                raise DataError(f"{type(g).__name__} cannot be saved (no to_dict/from_dict)")
            return {"class": where, "design": g.to_dict()}

        return {"base": one(self.base), "twins": {k: one(g) for k, g in zip(self.labels, self.twins)},
                "steps": dict(self.steps), "outputs": list(self.signed)}

    @classmethod
    def from_dict(cls, d: Mapping) -> ParameterSensitivity:
        """Rebuild from :meth:`to_dict` (only fdikit classes are imported)."""
        from ..base.artifacts import _resolve

        def one(e):
            where = str(e["class"])
            return _resolve(where.rpartition(":")[2], where).from_dict(e["design"])

        return cls(one(d["base"]), {k: one(e) for k, e in d["twins"].items()}, d["steps"],
                   outputs=d.get("outputs"))
