"""C emitter of the scheduled blend (:class:`~fdikit.residuals.ScheduledFilter`): every filter of
the bank advanced (:class:`~fdikit.codegen.stages.FilterEmitter`), then the interpolation weights
in the scheduling variable and the blend, summed from 0.0 in the filters' order (as
``ScheduledFilter._blend``); registered in :mod:`.registry` when :mod:`fdikit.codegen` is imported.
A subclass that maps its inputs first (e.g. a system's preprocessing) overrides :meth:`inputs`."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from .registry import class_path, register_emitter
from .stages import FilterEmitter, StageEmitter, lit

__all__ = ["ScheduledFilterEmitter"]


class ScheduledFilterEmitter(StageEmitter):
    """:class:`~fdikit.residuals.ScheduledFilter` of plain fault detection filters (or observer
    residuals)."""

    kinds = ("ScheduledFilter",)

    def __init__(self, obj: Any, prefix: str):
        super().__init__(obj, prefix)
        kinds = FilterEmitter.kinds
        bad = [type(f).__name__ for f in obj.filters if type(f).__name__ not in kinds]
        if bad:
            raise DataError(f"stage {type(obj).__name__} cannot be generated yet: its filters {bad} are not "
                            f"{' or '.join(kinds)}")
        self.subs = [FilterEmitter(f, f"{prefix}_f{k}") for k, f in enumerate(obj.filters)]
        self.q = len(obj.output_names)

    def fields(self):
        return [fl for e in self.subs for fl in e.fields()]

    def reset_code(self):
        return "\n".join(c for e in self.subs if (c := e.reset_code()))

    def inputs(self, inp: list[str]) -> tuple[list[str], list[str], list[str], str]:
        """Declarations, the filters' ``u`` and ``y`` expressions and the scheduling variable's
        expression, from the stage's inputs (``u_names`` then ``y_names``)."""
        o = self.obj
        nu = len(o.u_names)
        u, y = inp[:nu], inp[nu:]
        if o._iv is None:
            return [], u[:-1], y, u[-1]
        return [], u, y, f"{lit(o.scale)} * {y[o._iv]}"

    def step_code(self, inp, out):
        o, q, K = self.obj, self.q, len(self.subs)
        decl, u, y, v = self.inputs(inp)
        lines = ["    {", *decl, f"        fdk_real rk[{K}][{max(q, 1)}], W[{K}], sx, w, acc;",
                 "        int p, c;", "        (void)p; (void)w;"]
        for k, e in enumerate(self.subs):
            code = e.step_code([*u, *y], [f"rk[{k}][{c}]" for c in range(q)])
            lines.append("    " + code.replace("\n", "\n    "))
        lines.append(f"        sx = {v};")
        lines += [f"        W[{k}] = FDK_R(0.0);" for k in range(K)]
        if K == 1:
            lines.append("        W[0] = FDK_R(1.0);")
        else:
            sp = ", ".join(f"FDK_R({lit(s)})" for s in o.speeds)
            lines += [f"        {{ static const fdk_real S[{K}] = {{{sp}}};",
                      "          if (sx == sx) { sx = sx > S[0] ? sx : S[0];",
                      f"              sx = sx < S[{K - 1}] ? sx : S[{K - 1}];",
                      "              p = 0;",
                      f"              while (p < {K} && !(sx < S[p])) ++p; }} else p = {K};",
                      f"          p = p - 1 < 0 ? 0 : p - 1; if (p > {K - 2}) p = {K - 2};",
                      "          w = (sx - S[p]) / (S[p + 1] - S[p]);",
                      "          W[p] = FDK_R(1.0) - w; W[p + 1] = w; }"]
        lines += [f"        for (c = 0; c < {q}; ++c) {{ acc = FDK_R(0.0);"]
        lines += [f"            acc += W[{k}] * rk[{k}][c];" for k in range(K)]
        lines += ["            rk[0][c] = acc; }"]
        lines += [f"        {out[c]} = rk[0][{c}];" for c in range(q)]
        lines.append("    }")
        return "\n".join(lines)

    def to_py(self, arrays):
        return {"filters": {"__components__": [{"__component__": e.to_py(arrays)} for e in self.subs]}}

    def from_py(self, state):
        out: dict[str, np.ndarray] = {}
        for e, s in zip(self.subs, state["filters"]["__components__"]):
            out.update(e.from_py(s["__component__"]))
        return out


def _register() -> None:
    from ..residuals.scheduled import ScheduledFilter

    register_emitter(class_path(ScheduledFilter), ScheduledFilterEmitter)


_register()
