"""What a filter design does on a model: its internal form (the transfer from every input group
to the residual), target visibility, the filter's frequency response and the residual covariance."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as sla

from ...errors import ConditionError, ModelError
from ...model.linear import GROUPS, LinearFaultModel
from .form import _EPS, FilterDesign, _discrete

__all__ = ["filter_frequency_response", "internal_form", "residual_covariance"]

def internal_form(design: Any, model: LinearFaultModel) -> LinearFaultModel:
    """Transfer from every input group of ``model`` to the residual, by composing plant and filter.

    ``design`` is a :class:`FilterDesign` or any design with an ``as_filter()`` method (for
    example :class:`~fdikit.residuals.ObserverDesign`).

    Plant ``x[k+1] = A x + sum_g B_g v_g``, ``y = C x + sum_g D_g v_g`` (discretised at the
    design's ``dt`` when continuous) in series with the filter; composite state ``[x; xi]``::

        [x; xi][k+1] = [[A, 0], [By C, Af]] [x; xi] + [B_g; By D_g (+ Bu)] v_g
        r            = [Dy C, Cf] [x; xi] + (Dy D_g (+ Du)) v_g

    (``Bu``, ``Du`` only for the controls). The design may read a subset of the model's channels
    (matched by name). Returns a :class:`LinearFaultModel` with the model's input groups and
    the residual channels as outputs.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel, dc_gain
    >>> from fdikit.residuals.fdf import design_uio
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> G = dc_gain(internal_form(design_uio(m, "actuator:u0", ["actuator:u1"]), m), "f")
    >>> bool(np.abs(G[:, 1]).max() < 1e-12), bool(np.abs(G[:, 0]).max() > 0.1)
    (True, True)
    """
    if not isinstance(design, FilterDesign) and hasattr(design, "as_filter"):
        design = design.as_filter()
    md = _discrete(model, design.dt)
    missing = [s for s in design.y_names if s not in md.outputs] + \
        [s for s in design.u_names if s not in md.inputs]
    if missing:
        raise ModelError(f"the design reads channels {missing} that model {md.name!r} does not have "
                         f"(inputs {md.inputs}, outputs {md.outputs})")
    # the filter's gains on the model's channels (zero columns for channels it does not read)
    By = np.zeros((design.order, md.n_outputs))
    Dy = np.zeros((len(design.residual_names), md.n_outputs))
    By[:, md.output_index(design.y_names)], Dy[:, md.output_index(design.y_names)] = design.By, design.Dy
    iu = [md.inputs.index(s) for s in design.u_names]
    Bu = np.zeros((design.order, len(md.inputs)))
    Du = np.zeros((len(design.residual_names), len(md.inputs)))
    Bu[:, iu], Du[:, iu] = design.Bu, design.Du
    n, nf = md.n_states, design.order
    A = np.block([[md.A, np.zeros((n, nf))], [By @ md.C, design.A]])
    C = np.hstack([Dy @ md.C, design.C])
    groups = {}
    for g in GROUPS:
        Bg, Dg = md.B_of(g), md.D_of(g)
        Bo, Do = By @ Dg, Dy @ Dg
        if g == "u":
            Bo, Do = Bo + Bu, Do + Du
        groups[g] = (np.vstack([Bg, Bo]), Do)
    states = [*md.states, *(f"xi{i}" for i in range(nf))]
    return md.with_matrices(A, C, groups, states=states, outputs=design.residual_names)


def filter_frequency_response(design: FilterDesign, freqs_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """Frequency responses ``G_ru`` (F, q, m) and ``G_ry`` (F, q, p) of the filter alone.

    ``G(e^{j 2 pi f dt}) = D + C (zI - A)^-1 B``; with a plant response ``G_yg`` the residual's
    response to group ``g`` is ``G_ry G_yg (+ G_ru for the controls)``, an independent check of
    :func:`internal_form`.

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.array([[-1.0]]), 0.1, [], ["y"], ["r"])
    >>> Gu, Gy = filter_frequency_response(d, [0.0])
    >>> Gy[0].real.tolist()            # -1 + 1 / (1 - 0.5)
    [[1.0]]
    """
    f = np.atleast_1d(np.asarray(freqs_hz, float))
    z = np.exp(2j * np.pi * f * design.dt)
    nf = design.order
    out = []
    for Bm, Dm in ((design.Bu, design.Du), (design.By, design.Dy)):
        if nf:
            M = z[:, None, None] * np.eye(nf) - design.A
            X = np.linalg.solve(M, np.broadcast_to(Bm.astype(complex), (f.size, *Bm.shape)))
            out.append(design.C @ X + Dm)
        else:
            out.append(np.broadcast_to(Dm.astype(complex), (f.size, *Dm.shape)).copy())
    return out[0], out[1]


def _markov_visible(Af: np.ndarray, B: np.ndarray, Cf: np.ndarray, D: np.ndarray, steps: int) -> float:
    """Largest |Markov parameter| of (Af, B, Cf, D) over ``steps`` samples."""
    best = float(np.max(np.abs(D))) if D.size else 0.0
    X = B.copy()
    for _ in range(steps):
        if X.size == 0:
            break
        best = max(best, float(np.max(np.abs(Cf @ X))))
        X = Af @ X
    return best


def _fault_transfer_columns(md: LinearFaultModel, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(B, D) columns of named model faults (zeros for explicit directions)."""
    Bs, Ds = [], []
    for s in names:
        if s in md.fault_names:
            b, d = md.fault_direction(s)
            Bs.append(b)
            Ds.append(d)
    n, p = md.n_states, md.n_outputs
    return (np.column_stack(Bs) if Bs else np.zeros((n, 0)), np.column_stack(Ds) if Ds else np.zeros((p, 0)))


def _check_target_visible(design: FilterDesign, md: LinearFaultModel, target: list[str],
                          F1: np.ndarray) -> float:
    """Target must reach the residual: largest Markov parameter of the target transfer."""
    Bt, Dt = _fault_transfer_columns(md, target)
    if Bt.shape[1] == 0:  # explicit directions only
        Bt, Dt = F1, np.zeros((md.n_outputs, F1.shape[1]))
    Af = np.block([[md.A, np.zeros((md.n_states, design.order))], [design.By @ md.C, design.A]])
    B = np.vstack([Bt, design.By @ Dt])
    Cf = np.hstack([design.Dy @ md.C, design.C])
    vis = _markov_visible(Af, B, Cf, design.Dy @ Dt, Af.shape[0] + 1)
    scale = max(1.0, float(np.max(np.abs(B))) if B.size else 1.0) * max(1.0, float(np.abs(Cf).max()))
    if vis <= 1e6 * _EPS * scale:
        raise ConditionError(
            "target visibility",
            f"target {target} does not reach the residual (largest Markov parameter {vis:.3e}); "
            "it lies in the nuisance's detection space (the faults are not output separable)",
            {"largest_markov_parameter": vis})
    return vis


def residual_covariance(design: FilterDesign, model: LinearFaultModel, group: str = "w") -> np.ndarray:
    """Steady-state covariance (q, q) of the residual driven by unit white noise on one input group.

    The internal form ``(Ai, Bi, Ci, Di)`` of the group gives ``X = Ai X Ai' + Bi Bi'``
    (discrete Lyapunov equation) and ``Cov r = Ci X Ci' + Di Di'``: the residual variance the
    residual processor (e.g. the MHSSPT densities) must expect without faults.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[0.5]], [[1.0]], [[1.0]], dt=0.1, Dw=[[1.0]])
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                  np.zeros((1, 1)), np.eye(1), 0.1, ["u0"], ["y0"], ["r"])
    >>> residual_covariance(d, m).tolist()     # r = y = x + w, x = 0 without inputs: Var = 1
    [[1.0]]
    """
    M = internal_form(design, model)
    Bg, Dg = M.B_of(group), M.D_of(group)
    X = sla.solve_discrete_lyapunov(M.A, Bg @ Bg.T) if M.n_states else np.zeros((0, 0))
    R = M.C @ X @ M.C.T + Dg @ Dg.T
    return 0.5 * (R + R.T)
