"""Design of a fault detection filter for a target and its nuisances: the exact unknown input
observer, the optimal stochastic fault detection filter, and the front ends choosing between
them and designing one filter per target.

Source note: only the abstract of Chen, Mingori & Speyer (2003) and the table of contents of
R. H. Chen's dissertation (2000) were readable with the search tools. The discrete steady-state
formulation below (nuisance as white noise of intensity ``Q2 / gamma`` in a Kalman predictor,
projector ``H`` from the smallest ``(C, A)``-invariant subspace of the nuisance, which reduces
to ``C F_hat_2`` with ``F_hat_2 = [A^delta_i f_i]`` of Chen & Speyer when those are independent)
is derived here to have the properties the abstract and the notes state: the limit
``gamma -> 0`` recovers the UIO's structure, the nuisance transmission vanishes like ``gamma``
(both checked in the tests), and near the limit the filter has fast weakly observable modes.
The paper's weighting of the target fault in its cost is not modelled (the target enters only
through the separability and visibility checks)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.linalg as sla

from ...errors import ConditionError, ModelError
from ...model.linear import LinearFaultModel
from ...model.structure import invariant_zeros, rank, unobservable_modes
from .analysis import _check_target_visible, internal_form
from .directions import _complement_rows, _orth, _target_nuisance, conditioned_invariant_subspace
from .form import _EPS, FilterDesign, _discrete
from .reduction import reduce_filter

__all__ = ["design_filter_set", "design_optimal_fdf", "design_uio", "fault_detection_filter"]

# ---------------------------------------------------------------------------------- exact UIO
def _stabilising_gain(A1: np.ndarray, C: np.ndarray, poles: Any, Q: Any, R: Any) -> tuple[np.ndarray, str]:
    n, p = A1.shape[0], C.shape[0]
    if poles is not None:
        from scipy.signal import place_poles

        poles = np.asarray(poles)
        if poles.size != n:
            raise ModelError(f"need {n} poles for the UIO, got {poles.size}")
        return place_poles(A1.T, C.T, poles).gain_matrix.T, "poles"
    Qm = np.eye(n) if Q is None else np.atleast_2d(np.asarray(Q, float))
    Rm = np.eye(p) if R is None else np.atleast_2d(np.asarray(R, float))
    if Qm.shape != (n, n) or Rm.shape != (p, p):
        raise ModelError(f"Q must be {(n, n)} and R {(p, p)}, got {Qm.shape} and {Rm.shape}")
    P = sla.solve_discrete_are(A1.T, C.T, Qm, Rm)
    # predictor gain of the dual LQ problem: A1 - K1 C Schur stable
    return A1 @ P @ C.T @ np.linalg.inv(C @ P @ C.T + Rm), "riccati"


def design_uio(
    model: LinearFaultModel,
    target: Any,
    nuisance: Any,
    *,
    dt: float | None = None,
    poles: Any = None,
    Q: Any = None,
    R: Any = None,
    sensor: str = "auto",
    name: str | None = None,
) -> FilterDesign:
    """Exact unknown input observer (Chen, Patton & Zhang 1996) decoupling the nuisance faults.

    With nuisance directions ``E`` (:func:`fault_directions`), ``H = E (C E)^+``, ``T = I - H C``,
    ``A1 = T A``, ``F = A1 - K1 C`` and ``K = K1 + F H``, the discrete observer is::

        z[k+1] = F z + (T B - K D) u + K y,    x_hat = z + H (y - D u),    r = y - D u - C x_hat

    and its error ``e = x - x_hat`` obeys ``e[k+1] = F e + T E mu2`` with ``T E = 0``: the nuisance
    never reaches ``r = C e``.

    Parameters
    ----------
    model : LinearFaultModel
        Discrete, or continuous with ``dt`` (ZOH).
    target : str or sequence
        Target fault(s) (names declared on the model).
    nuisance : str or sequence
        Nuisance faults: names, or ``(label, directions (n, k))`` in the discrete state space.
    dt : float, optional
        Sample time (s).
    poles : array_like (n,), optional
        Discrete eigenvalues of ``F`` (pole placement on ``(A1, C)``; needs ``(C, A1)`` observable).
        Default: ``K1`` from the discrete Riccati equation on ``(A1, C)`` with weights ``Q``
        (default I) and ``R`` (default I), which only needs detectability.
    sensor : {"auto", "state", "output"}
        Treatment of nuisance faults with an output direction (:func:`fault_direction_split`);
        output-space directions are removed by a projection ``P`` (``P d = 0``) of the
        measurements and the observer is designed on ``(A, B, P C, P D)``.

    Returns
    -------
    FilterDesign
        ``p`` residuals ``"<name>:<output>"`` (``p - l`` residuals ``"<name>:<i>"`` after
        projecting out ``l`` output directions); ``info`` has ``rank_CE``, ``rank_E``,
        ``unobservable_modes`` of ``(C, A1)``, ``eigenvalues`` and ``spectral_radius`` of ``F``,
        ``H``, ``T``, ``K1``, the projection ``P``.

    Raises
    ------
    ConditionError
        ``"rank(CE) = rank(E)"`` with both ranks; ``"detectability of (C, A1)"`` with the
        unstable unobservable modes; ``"target visibility"`` when the target is decoupled too.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> d = design_uio(m, "actuator:u0", ["actuator:u1"])
    >>> d.info["rank_CE"], d.info["rank_E"]
    (1, 1)
    """
    md = _discrete(model, dt)
    tnames, nnames, E1, _, E, Yd = _target_nuisance(md, target, nuisance, sensor)
    A, B, n = md.A, md.B, md.n_states
    # output-space nuisance directions (sensor faults outside range C) are projected out first
    Pd = _complement_rows(_orth(Yd), md.n_outputs)
    C, D = Pd @ md.C, Pd @ md.D
    p = C.shape[0]
    if p == 0:
        raise ConditionError("residual dimension", "the nuisance output directions span all "
                             f"{md.n_outputs} outputs: no measurement is left", {"outputs": md.n_outputs})
    rE, rCE = rank(E), rank(C @ E)
    info: dict[str, Any] = {"method": "uio", "target": tnames, "nuisance": nnames, "rank_E": rE,
                            "rank_CE": rCE, "output_nuisance_directions": Yd.shape[1], "P": Pd,
                            "conditions": {}}
    if rCE != rE:
        raise ConditionError("rank(CE) = rank(E)",
                             f"the nuisance directions E ({n} x {E.shape[1]}) have rank {rE} but C E has "
                             f"rank {rCE}: no exact unknown input observer exists (use the optimal "
                             "stochastic filter)", {"rank_E": rE, "rank_CE": rCE})
    info["conditions"]["rank(CE) = rank(E)"] = f"{rCE} = {rE}"
    Eo = _orth(E)  # same H for any basis of range(E) when rank(CE) = rank(E); better conditioned
    H = Eo @ np.linalg.pinv(C @ Eo) if Eo.shape[1] else np.zeros((n, p))
    T = np.eye(n) - H @ C
    A1 = T @ A
    um = unobservable_modes(A1, C)
    bad = um[np.abs(um) >= 1 - 100 * _EPS * max(1.0, np.linalg.norm(A1, 2))]
    if bad.size:
        raise ConditionError("detectability of (C, A1)",
                             f"A1 = (I - E (CE)^+ C) A has {bad.size} unobservable mode(s) on or outside "
                             f"the unit circle: {np.round(bad, 6).tolist()}",
                             {"unstable_unobservable_modes": bad.tolist(), "unobservable_modes": um.tolist()})
    info["conditions"]["detectability of (C, A1)"] = f"unobservable modes {np.round(um, 6).tolist()}"
    K1, how = _stabilising_gain(A1, C, poles, Q, R)
    F = A1 - K1 @ C  # Chen, Patton & Zhang (1996): F = A - HCA - K1 C
    K = K1 + F @ H  # K2 = F H makes the error independent of x
    eig = np.linalg.eigvals(F)
    rho = float(np.max(np.abs(eig))) if n else 0.0
    if rho >= 1:
        raise ConditionError("stability", f"UIO matrix F has spectral radius {rho:.6g} >= 1",
                             {"eigenvalues": eig.tolist()})
    I_CH = np.eye(p) - C @ H
    nm = name or f"uio[{','.join(tnames)}]"
    rnames = [f"{nm}:{y}" for y in md.outputs] if Yd.shape[1] == 0 else [f"{nm}:{i}" for i in range(p)]
    design = FilterDesign(
        A=F, Bu=T @ B - K @ D, By=K @ Pd, C=-C, Du=-I_CH @ D, Dy=I_CH @ Pd, dt=float(md.dt),
        u_names=list(md.inputs), y_names=list(md.outputs), residual_names=rnames, info=info)
    info.update(gain_method=how, eigenvalues=eig, spectral_radius=rho, unobservable_modes=um,
                H=H, T=T, K1=K1, order=n, reduction=None)
    info["target_markov_max"] = _check_target_visible(design, md, tnames, E1)
    design.internal = internal_form(design, md)
    return design


# ---------------------------------------------------------------------------------- optimal stochastic FDF
def design_optimal_fdf(
    model: LinearFaultModel,
    target: Any,
    nuisance: Any,
    *,
    gamma: float = 1e-6,
    dt: float | None = None,
    Q2: Any = None,
    Qw: Any = None,
    V: Any = None,
    reduce: str | None = "residualize",
    order: int | None = None,
    fast_modulus: float = 0.05,
    weak_observability: float = 1e-4,
    sensor: str = "auto",
    name: str | None = None,
) -> FilterDesign:
    """Optimal stochastic fault detection filter (Chen, Mingori & Speyer 2003), steady state, discrete.

    1. Nuisance directions ``F2`` and target directions ``F1`` (:func:`fault_directions`).
    2. Output directions of the nuisance ``C S2*`` with ``S2*`` the smallest ``(C, A)``-invariant
       subspace containing ``F2`` (:func:`conditioned_invariant_subspace`; ``C F_hat_2`` of the
       paper); ``H = I - C S2* (C S2*)^+`` annihilates them. The residual is ``r = Hr (y - C x_hat
       - D u)`` with ``Hr`` (p - s, p) orthonormal rows, ``Hr^T Hr = H`` (so ``|r| = |H (y - ...)|``).
    3. Steady-state discrete Riccati equation (predictor form)::

           P = A P A' - A P C' (C P C' + V)^-1 C P A' + Qw + F2 Q2 F2' / gamma
           L = A P C' (C P C' + V)^-1,     x_hat[k+1] = A x_hat + B u + L (y - C x_hat - D u)

       the nuisance weighted by ``1/gamma``. As ``gamma -> 0`` the filter corrects the nuisance
       directions in one step where it can (``(A - L C) f -> 0`` for ``C f != 0``), the
       nuisance subspace ``S2*`` becomes unobservable from ``r`` with eigenvalues -> 0 (the UIO
       structure; in continuous time they go to ``-infinity``), and the nuisance transmission
       falls in proportion to ``gamma``. Discrete time is used because the monitor runs at a fixed sample
       rate; a continuous model is discretised by ZOH first. (See the module's source note:
       the paper's target-fault weighting is not modelled.)
    4. Model reduction (ng-chen-speyer, Section IV-C): the fast (``|z| <= fast_modulus``) and the weakly
       observable (relative modal observability from ``r`` below ``weak_observability``)
       filter modes, which approximate the nuisance subspace, are removed by
       :func:`reduce_filter` (``reduce="residualize"``: steady-state correction, exact DC gain;
       ``"truncate"``; ``None``: keep the full filter).

    Parameters
    ----------
    model : LinearFaultModel
    target, nuisance : str or sequence
        Fault names (or ``(label, directions)`` for nuisances given as explicit directions).
    gamma : float
        Nuisance weighting (> 0); smaller blocks harder.
    dt : float, optional
        Sample time (s) for a continuous model.
    Q2 : array_like (k2, k2), optional
        Nuisance intensity shape (default I).
    Qw : array_like (n, n), optional
        Process-noise covariance (default ``Bw Bw'`` of the model plus ``1e-6 I``).
    V : array_like (p, p), optional
        Measurement-noise covariance (default ``Dw Dw'`` plus ``1e-6 I``, or I without noise group).
    reduce : {"residualize", "truncate", None}
    order : int, optional
        Reduced order (the ``order`` most observable modes are kept); default: drop the modes
        with ``|z| <= fast_modulus`` or observability below ``weak_observability``.
    fast_modulus : float
        Modulus below which a discrete mode counts as fast (0.05: faster than ``dt / 3``).
    weak_observability : float
        Relative modal observability (:func:`modal_observability`) below which a mode is dropped.
    sensor : {"auto", "state", "output"}
        Treatment of faults with an output direction (:func:`fault_direction_split`): output-space
        nuisance directions are removed by a projection ``P`` of the measurements (``P d = 0``)
        before steps 2-3, which then use ``P C``, ``P D`` and ``P V P'``.

    Returns
    -------
    FilterDesign
        ``info`` has ``gamma``, ``rank_E``/``rank_CE`` of the nuisance (whether an exact UIO
        would exist), ``nuisance_output_rank``, ``nuisance_invariant_zeros`` (discrete: the
        fixed modes an exact UIO would have; an unstable one rules the UIO out but not this
        filter, whose eigenvalues are always inside the unit circle), ``H``, ``L``, ``P``,
        ``eigenvalues`` of the full filter, ``full`` (the unreduced :class:`FilterDesign`),
        ``order`` and ``reduction``.

    Raises
    ------
    ConditionError
        ``"residual dimension"`` when the nuisance output directions fill the output space;
        ``"target visibility"`` when the target does not reach the residual; ``"riccati"`` when
        the Riccati equation has no stabilising solution.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> A = [[0.9, 0.1, 0.0], [0.0, 0.8, 0.1], [0.05, 0.0, 0.7]]
    >>> m = LinearFaultModel(A, [[0.0], [0.0], [1.0]], np.eye(3)[:2], dt=0.01,
    ...                      faults=["actuator:u0", ("leak", [1.0, 0.0, 0.0], None)])
    >>> d = design_optimal_fdf(m, "actuator:u0", ["leak"], gamma=1e-6, reduce=None)
    >>> d.residual_names, d.info["nuisance_output_rank"]
    (['fdf[actuator:u0]:0'], 1)
    """
    if not (gamma > 0 and np.isfinite(gamma)):
        raise ModelError(f"gamma must be a positive number, got {gamma}")
    md = _discrete(model, dt)
    tnames, nnames, F1, Y1, F2, Yd = _target_nuisance(md, target, nuisance, sensor)
    A, B, n = md.A, md.B, md.n_states
    # output-space nuisance directions (sensor faults outside range C) are projected out first
    Pd = _complement_rows(_orth(Yd), md.n_outputs)
    C, D = Pd @ md.C, Pd @ md.D
    p = C.shape[0]
    S2 = conditioned_invariant_subspace(A, C, F2)
    Y2 = _orth(C @ S2)  # nuisance output directions (C F_hat_2 of the paper)
    s = Y2.shape[1]
    if s >= p:
        raise ConditionError("residual dimension",
                             f"the nuisance output directions span all {md.n_outputs} outputs "
                             f"({Yd.shape[1]} direct, rank C S2* = {s}); the projected residual "
                             "H (y - C x_hat) would be identically zero",
                             {"nuisance_output_rank": s + Yd.shape[1], "outputs": md.n_outputs})
    Hr = _complement_rows(Y2, p) @ Pd  # (p_out - l - s, p_out), orthonormal rows
    H = Hr.T @ Hr
    # output separability: the target must add output directions to the nuisance's
    s12 = rank(np.hstack([C @ conditioned_invariant_subspace(A, C, np.hstack([F2, F1])), Pd @ Y1]))
    if s12 <= s:
        raise ConditionError("target visibility",
                             f"target {tnames} adds no output direction to the nuisance's (rank C S* = {s} "
                             f"with and without it): target and nuisance are not output separable",
                             {"nuisance_output_rank": s, "joint_output_rank": s12})
    k2 = F2.shape[1]
    po = md.n_outputs
    Q2m = np.eye(k2) if Q2 is None else np.atleast_2d(np.asarray(Q2, float))
    Bw, Dw = md.B_of("w"), md.D_of("w")
    Qwm = Bw @ Bw.T + 1e-6 * np.eye(n) if Qw is None else np.atleast_2d(np.asarray(Qw, float))
    if V is None:
        Vm = Dw @ Dw.T + 1e-6 * np.eye(po) if Dw.size and np.any(Dw) else np.eye(po)
    else:
        Vm = np.atleast_2d(np.asarray(V, float))
    if Q2m.shape != (k2, k2) or Qwm.shape != (n, n) or Vm.shape != (po, po):
        raise ModelError(f"Q2 must be {(k2, k2)}, Qw {(n, n)} and V {(po, po)}; got {Q2m.shape}, "
                         f"{Qwm.shape}, {Vm.shape}")
    Vp = Pd @ Vm @ Pd.T
    Qtot = Qwm + F2 @ Q2m @ F2.T / gamma  # nuisance weighted by 1/gamma (ng-chen-speyer, Riccati eq.)
    Qtot = 0.5 * (Qtot + Qtot.T)
    try:
        P = sla.solve_discrete_are(A.T, C.T, Qtot, Vp)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ConditionError("riccati", f"the filter Riccati equation has no stabilising solution "
                             f"(gamma = {gamma:g}): {exc}", {"gamma": gamma}) from None
    P = 0.5 * (P + P.T)
    L = A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + Vp)  # gain on the projected outputs P y
    Af = A - L @ C
    eig = np.linalg.eigvals(Af)
    rho = float(np.max(np.abs(eig))) if n else 0.0
    if not rho < 1:
        raise ConditionError("stability", f"filter A - L C has spectral radius {rho:.6g} >= 1 "
                             f"(gamma = {gamma:g})", {"eigenvalues": eig.tolist()})
    nm = name or f"fdf[{','.join(tnames)}]"
    full = FilterDesign(
        A=Af, Bu=B - L @ D, By=L @ Pd, C=-Hr @ md.C, Du=-Hr @ md.D, Dy=Hr.copy(), dt=float(md.dt),
        u_names=list(md.inputs), y_names=list(md.outputs),
        residual_names=[f"{nm}:{i}" for i in range(Hr.shape[0])])
    rE, rCE = rank(F2), rank(C @ F2)
    # invariant zeros of the nuisance channel (A, F2, C): the fixed modes of an exact UIO (its
    # unobservable modes of (C, A1)); the stochastic filter stays stable when one is unstable
    zeros = invariant_zeros(A, F2, C) if F2.shape[1] else np.zeros(0, complex)
    info: dict[str, Any] = {
        "method": "optimal_fdf", "target": tnames, "nuisance": nnames, "gamma": float(gamma),
        "discrete": True, "rank_E": rE, "rank_CE": rCE, "exact_uio_rank_condition": rE == rCE,
        "output_nuisance_directions": Yd.shape[1],
        "nuisance_subspace_dim": S2.shape[1], "nuisance_output_rank": s,
        "target_output_rank": rank(np.hstack([C @ conditioned_invariant_subspace(A, C, F1), Pd @ Y1])),
        "nuisance_invariant_zeros": zeros,
        "P_out": Pd, "H": H, "Hr": Hr, "L": L, "P": P, "eigenvalues": eig, "spectral_radius": rho,
        "conditions": {"residual dimension": f"{p} outputs - {s} nuisance output directions = {p - s}",
                       "output separability": f"rank C S*(F1, F2) = {s12} > rank C S*(F2) = {s}"},
    }
    full.info = dict(info, order=n, reduction=None)
    info["target_markov_max"] = _check_target_visible(full, md, tnames, F1)
    info["conditions"]["target visibility"] = f"largest Markov parameter {info['target_markov_max']:.3e}"
    full.info["target_markov_max"] = info["target_markov_max"]
    full.internal = internal_form(full, md)
    if reduce is None:
        return full
    red = reduce_filter(full, order, fast_modulus=fast_modulus, weak_observability=weak_observability,
                        method=reduce)
    red.info = dict(info, full=full, **red.info)
    red.internal = internal_form(red, md)
    return red


# ---------------------------------------------------------------------------------- front ends
def fault_detection_filter(model: LinearFaultModel, target: Any, nuisance: Any = (), *,
                           method: str = "auto", **kwargs: Any) -> FilterDesign:
    """Design a filter sensitive to ``target`` and blind to ``nuisance``.

    ``method="uio"``: :func:`design_uio`; ``"optimal"``: :func:`design_optimal_fdf`; ``"auto"``:
    the exact UIO when ``rank(C E) = rank(E)`` holds (and the design succeeds), else the optimal
    stochastic filter. Keyword arguments go to the chosen design function (``dt``, ``gamma``,
    ``poles``, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> fault_detection_filter(m, "actuator:u0", ["actuator:u1"]).info["method"]
    'uio'
    """
    uio_kw = {k: v for k, v in kwargs.items() if k in ("dt", "poles", "Q", "R", "name", "sensor")}
    opt_kw = {k: v for k, v in kwargs.items() if k not in ("poles", "Q", "R")}
    if method == "uio":
        return design_uio(model, target, nuisance, **uio_kw)
    if method == "optimal":
        return design_optimal_fdf(model, target, nuisance, **opt_kw)
    if method != "auto":
        raise ModelError(f"method must be 'auto', 'uio' or 'optimal', got {method!r}")
    try:
        return design_uio(model, target, nuisance, **uio_kw)
    except ConditionError as exc:
        if exc.condition not in ("rank(CE) = rank(E)", "detectability of (C, A1)"):
            raise
        d = design_optimal_fdf(model, target, nuisance, **opt_kw)
        d.info["uio_failed"] = str(exc)
        return d


def design_filter_set(model: LinearFaultModel, targets: Sequence[str], nuisance: Any = (), *,
                      method: str = "auto", name: str = "set", **kwargs: Any) -> dict[str, FilterDesign]:
    """One filter per target, the other targets (and ``nuisance``) as nuisances.

    Parameters
    ----------
    model : LinearFaultModel
    targets : sequence of str
        Faults of the set (e.g. ng-chen-speyer, Section IV-B: two faults per set).
    nuisance : sequence
        Nuisances common to every filter (e.g. the nonlinearity direction).
    method, kwargs
        As :func:`fault_detection_filter`.
    name : str
        Prefix of the residual names: ``"<name>/<target>:<i>"``.

    Returns
    -------
    dict
        ``{target: FilterDesign}``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> sorted(design_filter_set(m, ["actuator:u0", "actuator:u1"]))
    ['actuator:u0', 'actuator:u1']
    """
    targets = list(targets)
    common = [nuisance] if isinstance(nuisance, str) else list(nuisance or [])
    out = {}
    for t in targets:
        others = [s for s in targets if s != t] + common
        out[t] = fault_detection_filter(model, t, others, method=method, name=f"{name}/{t}", **kwargs)
    return out
