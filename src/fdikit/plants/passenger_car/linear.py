"""Linear passenger-car models: linearisation about straight driving, decoupling, reduction.

Paper 1, Section III: the nonlinear model is linearised by central differences about straight
driving on a flat road at 20 and 24 m/s; the linear longitudinal and lateral dynamics decouple;
the fast modes are removed by dynamic truncation with a steady-state correction (singular
perturbation / residualisation) to 10 longitudinal states (throttle, brake -> 5 sensors) and 6
lateral states (steering -> 4 sensors). Balanced residualisation (balanced truncation with
matched DC gain) is offered as an option.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import ModelError
from ...model.linear import GROUPS, LinearFaultModel
from .model import (
    LATERAL_INPUTS,
    LATERAL_OUTPUTS,
    LATERAL_REDUCED,
    LATERAL_STATES,
    LONGITUDINAL_INPUTS,
    LONGITUDINAL_OUTPUTS,
    LONGITUDINAL_REDUCED,
    LONGITUDINAL_STATES,
    OUTPUTS,
    PassengerCar,
)

__all__ = [
    "ACTUATOR_FAULTS",
    "SENSOR_FAULTS",
    "CarLinearization",
    "balanced_residualization",
    "block",
    "decoupling_residue",
    "frequency_response_error",
    "linearize_car",
    "residualize_states",
]

#: The paper's faults (Section IV-B, Fig. 2 and the lateral list of Section IV-E).
SENSOR_FAULTS = [f"sensor:{y}" for y in OUTPUTS]
ACTUATOR_FAULTS = ["actuator:throttle", "actuator:brake", "actuator:steer"]


# ---------------------------------------------------------------------------------- reduction
def residualize_states(model: LinearFaultModel, keep: Sequence[str]) -> LinearFaultModel:
    """Dynamic truncation with steady-state correction: residualise every state not in ``keep``.

    With ``x = (x1, x2)`` (kept, removed), setting ``x2' = 0`` gives (singular perturbation,
    Kokotovic, Khalil & O'Reilly 1986, ch. 2)::

        A_r = A11 - A12 A22^-1 A21      B_r = B1 - A12 A22^-1 B2
        C_r = C1 - C2 A22^-1 A21        D_r = D - C2 A22^-1 B2

    for every input group (controls, disturbances, faults, noise), so the DC gain of every
    channel is kept exactly.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous-time model.
    keep : sequence of str
        Names of the states to keep (in this order).

    Returns
    -------
    LinearFaultModel
        Same inputs, outputs and faults; states ``keep``.

    Raises
    ------
    ModelError
        Unknown state names, a discrete model, or a singular ``A22`` (a removed state with an
        integrator cannot be residualised).

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 1.0], [0.0, -100.0]], [[0.0], [100.0]], [[1.0, 0.0]])
    >>> r = residualize_states(m, ["x0"])
    >>> r.A.tolist(), r.B.tolist()
    ([[-1.0]], [[1.0]])
    """
    if model.dt is not None:
        raise ModelError("residualize_states needs a continuous-time model")
    keep = list(keep)
    ik = model.state_index(keep)
    ir = [i for i in range(model.n_states) if i not in ik]
    A = model.A
    A22 = A[np.ix_(ir, ir)]
    if ir:
        cond = np.linalg.cond(A22)
        if not np.isfinite(cond) or cond > 1e14:
            raise ModelError(f"cannot residualise {[model.states[i] for i in ir]}: their block A22 is "
                             f"singular (condition number {cond:.3g})")
    A12 = A[np.ix_(ik, ir)]
    C2 = model.C[:, ir]
    # X = A22^-1 [A21, B2 of every group]
    groups = {g: (model.B_of(g), model.D_of(g)) for g in GROUPS}
    rhs = np.hstack([A[np.ix_(ir, ik)]] + [groups[g][0][ir] for g in GROUPS]) if ir else None
    if ir:
        X = np.linalg.solve(A22, rhs)
    k = len(ik)
    Ar = A[np.ix_(ik, ik)] - (A12 @ X[:, :k] if ir else 0.0)
    Cr = model.C[:, ik] - (C2 @ X[:, :k] if ir else 0.0)
    new_groups = {}
    col = k
    for g in GROUPS:
        B, D = groups[g]
        w = B.shape[1]
        if ir:
            Xg = X[:, col:col + w]
            new_groups[g] = (B[ik] - A12 @ Xg, D - C2 @ Xg)
        else:
            new_groups[g] = (B[ik], D)
        col += w
    return model.with_matrices(Ar, Cr, new_groups, states=keep)


def balanced_residualization(model: LinearFaultModel, order: int) -> LinearFaultModel:
    """Balanced truncation with matched DC gain (balanced residualisation) to ``order`` states.

    :func:`control.balred` with ``method="matchdc"`` (SLICOT AB09ND, balancing-free square-root
    singular perturbation approximation) on the transfer from ALL input groups (controls,
    disturbances, faults, noise) to the outputs, so that every group keeps its DC gain. States
    of the result are named ``z0..``.

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 0.0], [0.0, -50.0]], [[1.0], [1.0]], [[1.0, 1.0]])
    >>> r = balanced_residualization(m, 1)
    >>> round(float((r.D - r.C @ np.linalg.solve(r.A, r.B))[0, 0]), 9)  # DC gain 1 + 1/50
    1.02
    """
    import control as ct

    if model.dt is not None:
        raise ModelError("balanced_residualization needs a continuous-time model")
    if not 0 < order <= model.n_states:
        raise ModelError(f"order must be in 1..{model.n_states}, got {order}")
    eig = np.linalg.eigvals(model.A)
    if np.max(eig.real) >= 0:
        raise ModelError(f"balanced reduction needs a stable model; largest real part of an eigenvalue "
                         f"is {np.max(eig.real):.3g}")
    sizes = [model.B_of(g).shape[1] for g in GROUPS]
    Bs = np.hstack([model.B_of(g) for g in GROUPS])
    Ds = np.hstack([model.D_of(g) for g in GROUPS])
    red = ct.balred(ct.ss(model.A, Bs, model.C, Ds), order, method="matchdc")
    new_groups, c = {}, 0
    for g, w in zip(GROUPS, sizes, strict=True):
        new_groups[g] = (np.asarray(red.B)[:, c:c + w], np.asarray(red.D)[:, c:c + w])
        c += w
    return model.with_matrices(np.asarray(red.A), np.asarray(red.C), new_groups,
                               states=[f"z{i}" for i in range(order)])


def frequency_response_error(full: LinearFaultModel, reduced: LinearFaultModel, *, f_max: float = 5.0,
                             n_freq: int = 200, inputs: Sequence[str] | None = None,
                             floor: float = 1e-3) -> dict[str, Any]:
    """Relative frequency-response error of a reduced model, channel by channel, up to ``f_max``.

    For every output ``i`` and input ``j``::

        e_ij = max_{0 <= w <= 2 pi f_max} |G_ij(jw) - Gr_ij(jw)| / max(|G_ij(jw)|, floor * max_w |G_ij|)

    (the floor keeps a channel's own transmission zeros, e.g. the zero DC gain from throttle to
    the accelerometer, from dividing by zero).

    Returns
    -------
    dict
        ``max`` (worst channel), ``per_channel`` (outputs x inputs), ``dc_abs`` (largest absolute
        DC-gain difference), ``dc_rel`` (the same relative, with the floor), ``f_5pct`` (lowest
        frequency in Hz where some channel
        exceeds 5 %, or None), ``inputs``, ``outputs``, ``f_max``.

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 1.0], [0.0, -100.0]], [[0.0], [100.0]], [[1.0, 0.0]])
    >>> e = frequency_response_error(m, residualize_states(m, ["x0"]), f_max=0.1)
    >>> e["dc_abs"] < 1e-12, round(e["max"], 3)
    (True, 0.006)
    """
    inputs = list(inputs) if inputs is not None else list(full.input_names("u"))
    ju = [full.input_names().index(s) for s in inputs]
    jr = [reduced.input_names().index(s) for s in inputs]
    io_f = [full.outputs.index(s) for s in reduced.outputs]
    Bf, Df = full.B_all[:, ju], full.D_all[np.ix_(io_f, ju)]
    Cf = full.C[io_f]
    Br, Dr = reduced.B_all[:, jr], reduced.D_all[:, jr]
    w = np.r_[0.0, np.logspace(-3, np.log10(2 * np.pi * f_max), n_freq)]

    def resp(A, B, C, D):
        n = A.shape[0]
        return np.array([C @ np.linalg.solve(1j * wi * np.eye(n) - A, B) + D for wi in w])

    G = resp(full.A, Bf, Cf, Df)
    Gr = resp(reduced.A, Br, reduced.C, Dr)
    mag = np.abs(G)
    den = np.maximum(mag, floor * mag.max(axis=0, keepdims=True) + 1e-300)
    rel = np.abs(G - Gr) / den
    per = rel.max(axis=0)
    over = np.flatnonzero((rel > 0.05).any(axis=(1, 2)))
    dc_abs = float(np.max(np.abs(G[0] - Gr[0])))
    dc_rel = float(np.max(np.abs(G[0] - Gr[0]) / den[0]))
    return {"max": float(per.max()), "per_channel": per, "dc_abs": dc_abs, "dc_rel": dc_rel,
            "f_5pct": float(w[over[0]] / (2 * np.pi)) if over.size else None,
            "inputs": inputs, "outputs": list(reduced.outputs), "f_max": f_max}


# ---------------------------------------------------------------------------------- linearisation
def block(full: LinearFaultModel, states: Sequence[str], inputs: Sequence[str], outputs: Sequence[str],
          disturbances: Sequence[str] = (), faults: Sequence[str] = (), name: str = "") -> LinearFaultModel:
    """Sub-model of ``full`` on some states, control inputs, disturbances and outputs, with faults
    re-declared on them ("actuator:<input>", "sensor:<output>").

    Examples
    --------
    >>> m = LinearFaultModel(np.diag([-1.0, -2.0]), np.eye(2), np.eye(2), inputs=["a", "b"])
    >>> block(m, ["x1"], ["b"], ["y1"]).A.tolist()
    [[-2.0]]
    """
    i_s = full.state_index(states)
    i_o = full.output_index(outputs)
    iu = [full.input_names().index(s) for s in inputs]
    idd = [full.input_names().index(s) for s in disturbances]
    B_all, D_all = full.B_all, full.D_all
    return LinearFaultModel(
        full.A[np.ix_(i_s, i_s)], B_all[np.ix_(i_s, iu)], full.C[np.ix_(i_o, i_s)], D_all[np.ix_(i_o, iu)],
        states=list(states), inputs=list(inputs), outputs=list(outputs),
        Bd=B_all[np.ix_(i_s, idd)] if idd else None, Dd=D_all[np.ix_(i_o, idd)] if idd else None,
        disturbances=list(disturbances) or None, faults=list(faults), name=name)


def decoupling_residue(full: LinearFaultModel) -> dict[str, float]:
    """Largest longitudinal/lateral cross term of A, B, C, D, each relative to the largest entry of
    that matrix (paper 1, Section III: the blocks decouple exactly in straight driving)."""
    L, T = full.state_index(LONGITUDINAL_STATES), full.state_index(LATERAL_STATES)
    uL = [full.input_names().index(s) for s in [*LONGITUDINAL_INPUTS, "slope"] if s in full.input_names()]
    uT = [full.input_names().index(s) for s in LATERAL_INPUTS]
    yL = full.output_index([y for y in OUTPUTS if y not in LATERAL_OUTPUTS])
    yT = full.output_index(LATERAL_OUTPUTS)
    A, B, C, D = full.A, full.B_all, full.C, full.D_all

    def rel(M, *blocks):
        scale = np.max(np.abs(M)) or 1.0
        return max(float(np.max(np.abs(M[np.ix_(r, c)]), initial=0.0)) for r, c in blocks) / scale

    out = {"A": rel(A, (L, T), (T, L)), "B": rel(B, (L, uT), (T, uL)), "C": rel(C, (yL, T), (yT, L)),
           "D": rel(D, (yL, uT), (yT, uL))}
    out["max"] = max(out.values())
    return out


@dataclass
class CarLinearization:
    """Linear models of the car at one operating point (see :func:`linearize_car`).

    Attributes
    ----------
    speed : float
        Operating speed (m/s).
    x0, u0 : ndarray
        Operating state (22,) and input (4,) of the nonlinear model.
    full : LinearFaultModel
        All 22 states; controls throttle, brake, steer; disturbance slope; the paper's faults.
    longitudinal, lateral : LinearFaultModel
        The decoupled blocks (14 and 8 states) with the paper's inputs, outputs and faults.
    longitudinal_reduced, lateral_reduced : LinearFaultModel
        10- and 6-state models.
    decoupling : dict
        :func:`decoupling_residue` of ``full``.
    fr_error : dict
        :func:`frequency_response_error` of each reduced block.
    method : str
        Reduction method used.
    """

    speed: float
    x0: np.ndarray
    u0: np.ndarray
    full: LinearFaultModel
    longitudinal: LinearFaultModel
    lateral: LinearFaultModel
    longitudinal_reduced: LinearFaultModel
    lateral_reduced: LinearFaultModel
    decoupling: dict[str, float]
    fr_error: dict[str, dict[str, Any]] = field(default_factory=dict)
    method: str = "residualize"

    def summary(self) -> dict[str, Any]:
        """JSON-able summary: names, eigenvalues of full and reduced blocks, decoupling, errors."""
        def eig(m):
            e = np.linalg.eigvals(m.A)
            e = e[np.argsort(-np.abs(e))]
            return [[float(v.real), float(v.imag)] for v in e]

        out: dict[str, Any] = {"speed": self.speed, "method": self.method,
                               "throttle_trim_deg": float(self.u0[0]),
                               "engine_speed_trim_rpm": float(self.x0[1] * 30 / np.pi),
                               "decoupling_residue": self.decoupling}
        for key in ("longitudinal", "lateral"):
            fullm, red = getattr(self, key), getattr(self, key + "_reduced")
            fe = self.fr_error.get(key, {})
            out[key] = {
                "states": fullm.states, "inputs": fullm.input_names("u"), "outputs": fullm.outputs,
                "faults": fullm.fault_names, "reduced_states": red.states,
                "eigenvalues_full": eig(fullm), "eigenvalues_reduced": eig(red),
                "fr_error_max": fe.get("max"), "fr_error_dc_abs": fe.get("dc_abs"),
                "fr_error_f_max_hz": fe.get("f_max"), "fr_error_first_5pct_hz": fe.get("f_5pct"),
                "fr_error_per_channel": np.asarray(fe.get("per_channel", [])).tolist(),
            }
        return out


def linearize_car(speed: float = 20.0, *, car: PassengerCar | None = None, method: str = "residualize",
                  f_max: float = 5.0) -> CarLinearization:
    """Linearise the car about straight driving on a flat road at ``speed`` and reduce it.

    Parameters
    ----------
    speed : float
        Operating speed (m/s); the paper uses 20 and 24.
    car : PassengerCar, optional
        The nonlinear model (default parameters if omitted).
    method : {"residualize", "balanced"}
        ``"residualize"``: the paper's dynamic truncation with steady-state correction of the
        named fast states (wheel spin ``w_f, w_r``; wheel hop ``ds_f, ds_r, dd_f, dd_r``), keeping
        :data:`LONGITUDINAL_REDUCED` and :data:`LATERAL_REDUCED`. ``"balanced"``: balanced
        residualisation to 10 and 6 states (states ``z0..``; DC kept, more accurate).
    f_max : float
        Upper frequency (Hz) of the reported frequency-response error.

    Returns
    -------
    CarLinearization

    Examples
    --------
    >>> lin = linearize_car(20.0)                               # doctest: +SKIP
    >>> lin.longitudinal_reduced.n_states, lin.lateral_reduced.n_states  # doctest: +SKIP
    (10, 6)
    """
    from ...model.linearize import linearize

    car = car or PassengerCar()
    x0, u0 = car.cruise(speed)
    full = linearize(car, x0, u0, faults=SENSOR_FAULTS + ACTUATOR_FAULTS, name=f"car @ {speed:g} m/s")
    long_faults = ([f"actuator:{u}" for u in LONGITUDINAL_INPUTS]
                   + [f"sensor:{y}" for y in LONGITUDINAL_OUTPUTS])
    lat_faults = [f"actuator:{u}" for u in LATERAL_INPUTS] + [f"sensor:{y}" for y in LATERAL_OUTPUTS]
    lon = block(full, LONGITUDINAL_STATES, LONGITUDINAL_INPUTS, LONGITUDINAL_OUTPUTS, ["slope"], long_faults,
                name=f"car longitudinal @ {speed:g} m/s")
    lat = block(full, LATERAL_STATES, LATERAL_INPUTS, LATERAL_OUTPUTS, (), lat_faults,
                name=f"car lateral @ {speed:g} m/s")
    if method == "residualize":
        lon_r = residualize_states(lon, LONGITUDINAL_REDUCED)
        lat_r = residualize_states(lat, LATERAL_REDUCED)
    elif method == "balanced":
        lon_r = balanced_residualization(lon, len(LONGITUDINAL_REDUCED))
        lat_r = balanced_residualization(lat, len(LATERAL_REDUCED))
    else:
        raise ModelError(f"unknown reduction method {method!r}; use 'residualize' or 'balanced'")
    fr = {"longitudinal": frequency_response_error(lon, lon_r, f_max=f_max),
          "lateral": frequency_response_error(lat, lat_r, f_max=f_max)}
    return CarLinearization(float(speed), x0, u0, full, lon, lat, lon_r, lat_r, decoupling_residue(full), fr,
                            method)
