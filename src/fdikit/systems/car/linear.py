"""Linear passenger-car models: linearisation about straight driving, decoupling, reduction.

Ng, Chen & Speyer, Section III: the nonlinear model is linearised by central differences about straight
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
from ...model.linear import LinearFaultModel
from ...model.reduction import balanced_truncation, reduce_fast_modes, residualize
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
    "channel_response_error",
    "decoupling_residue",
    "linearize_car",
    "reduce_fast_modes_named",
    "residualize_states",
]

#: The paper's faults (Section IV-B, Fig. 2 and the lateral list of Section IV-E).
SENSOR_FAULTS = [f"sensor:{y}" for y in OUTPUTS]
#: Actuator faults of the paper: throttle, brake and steering.
ACTUATOR_FAULTS = ["actuator:throttle", "actuator:brake", "actuator:steer"]


# ---------------------------------------------------------------------------------- reduction
def residualize_states(model: LinearFaultModel, keep: Sequence[str]) -> LinearFaultModel:
    """Residualise every state not in ``keep`` (:func:`fdikit.model.residualize`), kept states in
    the order of ``keep``.

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 1.0], [0.0, -100.0]], [[0.0], [100.0]], [[1.0, 0.0]])
    >>> r = residualize_states(m, ["x0"])
    >>> r.A.tolist(), r.B.tolist()
    ([[-1.0]], [[1.0]])
    """
    keep = list(keep)
    model.state_index(keep)  # unknown names raise
    drop = [s for s in model.states if s not in keep]
    red = residualize(model, drop)
    if red.states != keep:
        idx = red.state_index(keep)
        P = np.eye(len(keep))[idx]
        red = red.similarity_transform(P, states=keep)
    return red


def reduce_fast_modes_named(model: LinearFaultModel, keep: Sequence[str]) -> LinearFaultModel:
    """Keep the ``len(keep)`` slowest modes (:func:`fdikit.model.reduce_fast_modes`: modal
    truncation with steady-state correction of the fast modes, exact DC gain and exact slow
    eigenvalues) and express the reduced state in named physical coordinates.

    On the slow invariant subspace ``x = V m`` (``A V = V A_m``, ``C V = C_m``; ``V`` solved by
    least squares, unique when ``(C_m, A_m)`` is observable), the kept states' values are
    ``xi = S V m`` with ``S`` selecting ``keep``; when ``M = S V`` is invertible the reduced model
    is transformed to ``xi``: ``(M A_m M^-1, M B_m, C_m M^-1, D_m)``. The input-output behaviour is
    that of :func:`fdikit.model.reduce_fast_modes`; the states read "the named states of the
    car when its fast modes have settled".

    Raises
    ------
    ModelError
        When the named states do not parameterise the slow subspace (``M`` singular) or the slow
        subspace cannot be recovered.

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 1.0], [0.0, -100.0]], [[0.0], [100.0]], [[1.0, 0.0]])
    >>> r = reduce_fast_modes_named(m, ["x0"])
    >>> r.states, np.round(r.A, 9).tolist()
    (['x0'], [[-1.0]])
    """
    keep = list(keep)
    ik = model.state_index(keep)
    k = len(keep)
    red = reduce_fast_modes(model, k)
    A, C = model.A, model.C
    Am, Cm = red.A, red.C
    n = model.n_states
    # unknown V (n x k), column-major vec: (I kron A - Am^T kron I) vec V = 0 ; (I kron C) vec V = vec Cm
    K1 = np.kron(np.eye(k), A) - np.kron(Am.T, np.eye(n))
    K2 = np.kron(np.eye(k), C)
    scale = np.abs(A).max() or 1.0
    lhs = np.vstack([K1 / scale, K2])
    rhs = np.concatenate([np.zeros(n * k), Cm.reshape(-1, order="F")])
    v, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
    V = v.reshape(n, k, order="F")
    res = np.abs(A @ V - V @ Am).max() / (scale * max(np.abs(V).max(), 1e-300))
    if not np.isfinite(res) or res > 1e-6:
        raise ModelError(f"slow invariant subspace not recovered (relative residual {res:.3g}); "
                         "is (C, A) of the reduced model observable?")
    M = V[ik]
    cond = np.linalg.cond(M)
    if not np.isfinite(cond) or cond > 1e10:
        raise ModelError(f"the states {keep} do not parameterise the {k} slowest modes "
                         f"(condition number {cond:.3g})")
    return red.similarity_transform(M, states=keep)


def balanced_residualization(model: LinearFaultModel, order: int) -> LinearFaultModel:
    """Balanced residualisation (:func:`fdikit.model.balanced_truncation` with ``method="matchdc"``,
    Gramians of all input groups), states ``b0..``.

    Examples
    --------
    >>> m = LinearFaultModel([[-1.0, 0.0], [0.0, -50.0]], [[1.0], [1.0]], [[1.0, 1.0]])
    >>> r = balanced_residualization(m, 1)
    >>> round(float((r.D - r.C @ np.linalg.solve(r.A, r.B))[0, 0]), 9)  # DC gain 1 + 1/50
    1.02
    """
    red, _hsv = balanced_truncation(model, order, method="matchdc")
    return red


def channel_response_error(full: LinearFaultModel, reduced: LinearFaultModel, *, f_max: float = 5.0,
                             n_freq: int = 200, inputs: Sequence[str] | None = None,
                             floor: float = 1e-3) -> dict[str, Any]:
    """Relative frequency-response error of a reduced model, channel by channel, up to ``f_max``.

    For every output ``i`` and input ``j``::

        e_ij = max_{0 <= w <= 2 pi f_max} |G_ij(jw) - Gr_ij(jw)| / max(|G_ij(jw)|, floor * max_w |G_ij|)

    (the floor keeps a channel's own transmission zeros, e.g. the zero DC gain from throttle to
    the accelerometer, from dividing by zero; a channel that is structurally zero is measured
    against 1e-9 of its output's largest response).

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
    >>> e = channel_response_error(m, residualize_states(m, ["x0"]), f_max=0.1)
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
    # floors: a share of the channel's own peak (its transmission zeros), and 1e-9 of the output's
    # largest response over all inputs (channels that are structurally zero, e.g. brake -> throttle
    # sensor)
    row = mag.max(axis=(0, 2), keepdims=True)
    den = np.maximum(np.maximum(mag, floor * mag.max(axis=0, keepdims=True)), 1e-9 * row + 1e-300)
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
    that matrix (ng-chen-speyer, Section III: the blocks decouple exactly in straight driving)."""
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
        :func:`channel_response_error` of each reduced block.
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
    method: str = "modal"

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


def linearize_car(speed: float = 20.0, *, car: PassengerCar | None = None, method: str = "modal",
                  f_max: float = 5.0, parity_outputs: bool = False) -> CarLinearization:
    """Linearise the car about straight driving on a flat road at ``speed`` and reduce it.

    Parameters
    ----------
    speed : float
        Operating speed (m/s); the paper uses 20 and 24.
    car : PassengerCar, optional
        The nonlinear model (default parameters if omitted).
    method : {"modal", "residualize", "balanced"}
        ``"modal"`` (default): dynamic truncation with steady-state correction of the fast MODES
        (the 10 / 6 slowest modes kept exactly, the others residualised), expressed in the named
        states :data:`LONGITUDINAL_REDUCED` / :data:`LATERAL_REDUCED` of the slow subspace
        (:func:`reduce_fast_modes_named`). ``"residualize"``: residualisation of the named fast
        states themselves (wheel spin ``w_f, w_r``; wheel-hop rates ``ds_f, ds_r, dd_f, dd_r``).
        ``"balanced"``: balanced residualisation to 10 and 6 states (states ``b0..``).
        All three keep the DC gain exactly.
    f_max : float
        Upper frequency (Hz) of the reported frequency-response error.
    parity_outputs : bool
        Also give the longitudinal block the throttle and brake measurements (``throttle_meas``,
        ``brake_meas``) and their sensor faults, for the parity equations of Section IV-D. The
        paper's filters use the 5 outputs without them (default).

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
    lon_outputs = LONGITUDINAL_OUTPUTS + (["throttle_meas", "brake_meas"] if parity_outputs else [])
    long_faults = ([f"actuator:{u}" for u in LONGITUDINAL_INPUTS]
                   + [f"sensor:{y}" for y in lon_outputs])
    lat_faults = [f"actuator:{u}" for u in LATERAL_INPUTS] + [f"sensor:{y}" for y in LATERAL_OUTPUTS]
    lon = block(full, LONGITUDINAL_STATES, LONGITUDINAL_INPUTS, lon_outputs, ["slope"], long_faults,
                name=f"car longitudinal @ {speed:g} m/s")
    lat = block(full, LATERAL_STATES, LATERAL_INPUTS, LATERAL_OUTPUTS, (), lat_faults,
                name=f"car lateral @ {speed:g} m/s")
    if method == "modal":
        lon_r = reduce_fast_modes_named(lon, LONGITUDINAL_REDUCED)
        lat_r = reduce_fast_modes_named(lat, LATERAL_REDUCED)
    elif method == "residualize":
        lon_r = residualize_states(lon, LONGITUDINAL_REDUCED)
        lat_r = residualize_states(lat, LATERAL_REDUCED)
    elif method == "balanced":
        lon_r = balanced_residualization(lon, len(LONGITUDINAL_REDUCED))
        lat_r = balanced_residualization(lat, len(LATERAL_REDUCED))
    else:
        raise ModelError(f"unknown reduction method {method!r}; use 'modal', 'residualize' or 'balanced'")
    fr = {"longitudinal": channel_response_error(lon, lon_r, f_max=f_max),
          "lateral": channel_response_error(lat, lat_r, f_max=f_max)}
    return CarLinearization(float(speed), x0, u0, full, lon, lat, lon_r, lat_r, decoupling_residue(full), fr,
                            method)
