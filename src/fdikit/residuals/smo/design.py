"""Design of the SMO fault reconstructor (ng-tan-edwards-kuang): conditions, canonical forms,
LMIs, sized switching gains and boundary layers, self-check -> :class:`SlidingModeReconstructor`."""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from ...design.smo_lmi import primary_smo_lmi, secondary_smo_lmi_search
from ...errors import ConditionError, DataError, ModelError
from ...model.linear import LinearFaultModel
from .canonical import augment, fictitious_system, lemma1_form, lemma4_form
from .conditions import check_conditions
from .gains import hinf_norm, injection_peak_gains
from .noise import _noise_design, _simulated_noise_design, _switch_design, noise_response
from .runtime import SlidingModeReconstructor
from .selfcheck import self_check
from .validation import _mat, _pos, _spd

__all__ = ["DELTA_LADDER", "MAX_STEP_ERROR", "NOISE_WARN", "design_reconstructor"]

def _as_omega(A_Omega, B_Omega, omega_d, h):
    omega_d = _pos(omega_d, "omega_d")
    A_O = -omega_d * np.eye(h) if A_Omega is None else _mat(A_Omega, (h, h), "A_Omega")
    B_O = omega_d * np.eye(h) if B_Omega is None else _mat(B_Omega, (h, h), "B_Omega")
    if h and np.linalg.eigvals(A_O).real.max() >= 0:
        raise DataError(f"A_Omega must be stable; eigenvalues {np.linalg.eigvals(A_O)}")
    return A_O, B_O


#: Largest relative self-check step error a design may leave: above it the step is too large for
#: the observer dynamics and the design is refused.
MAX_STEP_ERROR = 1.0

#: A noise-aware design whose predicted error exceeds this fraction of ``fault_bound`` warns.
NOISE_WARN = 0.1


def _finite_check(sc: dict | None) -> bool:
    """A self-check with finite numbers (or no self-check)."""
    if sc is None:
        return True
    xg = sc.get("xi_gain")
    return bool(np.isfinite(sc["step_error"]) and (xg is None or np.isfinite(xg)))


def _step_refusal(tried: list, dt: float, details: dict, why: str) -> ConditionError:
    """The refusal of a design whose sampled observers fail on their own model, with the numbers."""
    from .noise import _linear_runtime

    eig = []
    rads = []
    for _d1, _d2, rec, _sc in tried:
        Phi = _linear_runtime(rec)[0]
        rads.append(float(np.abs(np.linalg.eigvals(Phi)).max()) if Phi.size else 0.0)
    for key, A_, Gl_, C_ in _observer_mats(details):
        ev = np.linalg.eigvals(A_ - Gl_ @ C_)
        eig.append((key, float(np.abs(ev).max())))
    lam = max((v for _k, v in eig), default=0.0)
    hint = (f"the fastest linear observer mode has |lambda| = {lam:.4g} rad/s, so dt should be well "
            f"below {1.0 / lam:.3g} s" if lam > 0 else "reduce dt")
    return ConditionError(
        "step", f"dt = {dt:g} s is too large for the observer dynamics: {why}; the runtime step's "
        f"spectral radius is {', '.join(f'{r:.4g}' for r in rads)} for the layers tried (>= 1: "
        f"unstable); {hint}. Use a smaller dt (resample the data faster) or a smaller D1 / "
        f"gamma_o (slower observers)",
        {"dt": dt, "self_checks": [sc for *_x, sc in tried], "step_spectral_radius": rads,
         "observer_max_abs_eig": dict(eig)})


def _observer_mats(details: dict) -> list:
    """``(name, A, Gl, C)`` of each observer of a design (canonical coordinates)."""
    out = []
    if "canonical" in details and "primary_gains" in details:
        cf, g1 = details["canonical"], details["primary_gains"]
        out.append(("primary", cf.A, g1.Gl, cf.C))
    g2 = details.get("secondary_gains")
    if g2 is not None:
        A2, C2 = details["secondary_system"]
        out.append(("secondary", A2, g2.Gl, C2))
    return out


def _noise_choice(build, sig, user, lpf_tau, fault_rate, rho1, rho2, g1, g2, dt, f_amp, horizon):
    """The noise-aware design: boundary layers and low-pass chosen by simulated error.

    The analytic design (:func:`_noise_design`, linear boundary-layer model) is one candidate;
    with ``horizon`` (the self-check is on) every candidate of :func:`_simulated_noise_design` is
    run with the noise and the smallest simulated error wins, which is the predicted error
    (``predicted_by = "simulation"``). Without ``horizon`` the analytic design is used as is.
    """
    try:
        analytic = _noise_design(build, sig, user, lpf_tau, fault_rate, rho1, rho2, g1, g2, dt)
        refusal = None
    except ConditionError as exc:
        analytic, refusal = None, exc
    if horizon is None:
        if refusal is not None:
            raise refusal
        rec, out = analytic
        out["predicted_by"] = "linear model"
        return rec, out
    sim = _simulated_noise_design(build, sig, user, lpf_tau, f_amp, fault_rate, dt, horizon,
                                  analytic, DELTA_LADDER)
    if sim is None:
        if refusal is not None:
            raise refusal
        raise ConditionError("noise design", f"every boundary layer tried gives a non-finite run with "
                             f"noise_std = {sig.tolist()} at dt = {dt} s; reduce dt", {})
    d1, d2, tau, score, table, std = sim
    rec = build(d1, d2, tau)
    out = dict(analytic[1]) if analytic is not None else {"noise_std": sig.tolist()}
    if analytic is None or (d1, d2, tau) != (out["delta"], out["delta2"], out["lpf_tau"]):
        nr = noise_response(rec, sig)
        out.update(noise_gain=nr["gain"], e1_rms=nr["e1_rms"], e2_rms=nr["e2_rms"],
                   linear_model_fhat_std=nr["fhat_std"])
        lam = [float(np.linalg.eigvalsh(np.linalg.inv(g.Po)).min()) for g in (g1, g2) if g is not None]
        rhos = [r for r, g in ((rho1, g1), (rho2, g2)) if g is not None]
        ds = [d for d, g in ((d1, g1), (d2, g2)) if g is not None]
        out["lag_s"] = tau + sum(d / (r * lm) for d, r, lm in zip(ds, rhos, lam))
        out["lag_error_bound"] = fault_rate * out["lag_s"]
    out.update(delta=d1, delta2=d2, lpf_tau=tau, predicted_error=score, predicted_by="simulation",
               fhat_noise_std=std, candidates=table, analytic_predicted_error=(
                   analytic[1]["predicted_error"] if analytic is not None else None),
               note="layers and low-pass chosen by the simulated error (largest RMS of ||fhat - f|| "
                    "over the second half of a step and of a sinusoid whose rate peaks at fault_rate, "
                    "white noise noise_std on every output); predicted_error is that error (fault "
                    "units); fhat_noise_std: std of fhat - f in the step run; candidates: every layer "
                    "tried with its best lpf_tau and error; noise_gain, lag_s: linear model")
    return rec, out


def _secondary(A2, M2, C2, Q2, D1m, gamma_o, retry, cond):
    """:func:`secondary_smo_lmi_search`; a refusal also names the invariant zeros (the sliding
    motion of (46) has them as fixed modes) and what a lightly damped or slow zero asks for."""
    try:
        return secondary_smo_lmi_search(A2, M2, C2, Q2, D1=D1m, gamma_o=gamma_o, retry=retry)
    except ConditionError as exc:
        z = np.asarray(cond.zeros)
        if exc.condition != "LMI" or exc.details.get("gamma_o_works") is not None:
            raise
        if not z.size:
            raise ConditionError(exc.condition, f"{exc} Invariant zeros of (A, M, C): none (the "
                                 f"sliding motion has no fixed mode; what fails is the scaling of "
                                 f"the LMIs or the filter inequality (47)).",
                                 {**exc.details, "invariant_zeros": [], "closest_zero_damping": None}
                                 ) from None
        zc = z[np.argmax(z.real)]
        damp = float(-zc.real / abs(zc)) if abs(zc) > 0 else 1.0
        zs = ", ".join(f"{v.real:.4g}{v.imag:+.4g}j" for v in z)
        hint = (f"the zero closest to the imaginary axis, {zc.real:.4g}{zc.imag:+.4g}j (damping "
                f"{damp:.3g}), is a fixed mode of the sliding motion (46)")
        if damp < 0.05 or zc.real > -0.1:
            hint += (": a lightly damped or slow zero leaves (46)-(47) almost infeasible; try a "
                     "larger gamma_o (e.g. gamma_o=1e4), a narrower uncertainty filter (smaller "
                     "omega_d) or removing the disturbance channels that excite that mode")
        raise ConditionError(exc.condition, f"{exc} Invariant zeros of (A, M, C): {zs}; {hint}.",
                             {**exc.details, "invariant_zeros": z.tolist(),
                              "closest_zero_damping": damp}) from None


#: Boundary layers tried by the accuracy sizing of :func:`design_reconstructor` (largest first).
DELTA_LADDER = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)


def design_reconstructor(
    model: LinearFaultModel,
    faults: list[str] | None = None,
    disturbances: list[str] | None = None,
    *,
    A_Omega: Any = None,
    B_Omega: Any = None,
    omega_d: float = 10.0,
    V1: Any = None,
    V2: Any = None,
    D1: Any = None,
    gamma_o: float = 100.0,
    gamma_o_retry: bool = True,
    Af: Any = None,
    fault_bound: float = 1.0,
    fault_rate: float | None = None,
    xi_bound: float = 0.0,
    margin: float = 0.5,
    rho: float | None = None,
    delta: float | None = None,
    rho2: float | None = None,
    delta2: float | None = None,
    noise_std: Any = None,
    lpf_tau: float | None = None,
    dt: float = 1e-5,
    tol: float | None = None,
    atol: float | None = None,
    rtol: float | None = None,
    hinf_check: bool = True,
    scheme: str = "implicit",
    level: float = 0.9,
    accuracy: float = 1e-3,
    check: bool = True,
    check_horizon: float = 1.0,
    settle: float | None = None,
) -> SlidingModeReconstructor:
    """Design a robust SMO fault reconstructor; single observer or cascade, chosen automatically.

    The model is ``x' = A x + B u + M f + Q xi~``, ``y = C x`` with the faults ``f`` (group
    ``f``) and the uncertainty ``xi~`` (group ``d``), which is band-limited by the filter
    ``xi~' = A_Omega xi~ + B_Omega xi`` (ng-tan-edwards-kuang (3)). **gamma-bar**
    (``info["l2_bound"]``) bounds the L2 gain from ``xi``, the *input* of that filter, to the
    reconstruction error: ``||fhat - f||_2 <= gamma-bar ||xi||_2`` while both observers slide
    (after the reaching phase, for zero initial errors); it is not the gain from the
    disturbance ``xi~`` put in the model (with the default filter, ``-omega_d I`` / ``omega_d I``,
    the two agree at low frequency). ``error_transfer()`` returns this transfer ``G(s)`` (40).

    Gains. Unless given, the switching gains are sized from what is known about the signals:
    ``rho = (1 + margin) (g_f fault_bound + g_xi xi_bound)`` (and the same for ``rho2`` with the
    secondary observer's gains), where ``g_f, g_xi`` are the peak gains from ``f`` and ``xi`` to
    the equivalent injection (:func:`injection_peak_gains`): an ideal sliding motion then needs
    at most ``1 / (1 + margin)`` of the cap, which keeps the injection inside its boundary layer
    (``||e_y|| <= delta / margin``). ``info["gains"]`` has the gains and
    ``info["reconstructible"]`` the range: the largest ``||f||`` (at ``xi_bound``) and
    ``||xi||`` (at ``fault_bound``) for which sliding is kept. A reconstructor whose given
    ``rho`` is too small for ``fault_bound`` says so (``info["reconstructible"]["ok"]`` and a
    warning); at run time the ``sliding_status`` outputs flag every loss of sliding.

    Measurement noise. With ``noise_std`` (per-output standard deviation of white measurement
    noise), the boundary layers and the low-pass on ``fhat`` are chosen by *simulated* error, as
    the noise-free layers are: every candidate (the layers of :data:`DELTA_LADDER`, layers scaled
    with ``||noise_std||``, the analytic design below, then a coordinate refinement of the
    secondary and primary layers) is run by the compiled runtime on a step of every fault and a
    sinusoid whose rate peaks at ``fault_rate``, with white noise of ``noise_std`` on every
    output, and every low-pass time constant is tried on its output; the smallest RMS error over
    the runs' second halves wins and is ``info["noise"]["predicted_error"]`` (fault units;
    ``predicted_by = "simulation"``, every candidate in ``info["noise"]["candidates"]``). A
    predicted error above ``NOISE_WARN * fault_bound`` warns with the number. The noise-free
    layers are candidates, so at negligible noise the design is no worse than the default one.
    Clean branch: the low-pass such noise needs lags a noise-free signal, so the default design
    (the ladder below) is kept beside the noise-aware one (``clean_branch`` of the runtime) and
    the runtime chooses per sample by its own estimate of the noise
    (:func:`~fdikit.residuals.smo.estimate_noise_std`): the default design while the noise is
    below ``switch * noise_std``, the noise-aware design above (a blend within a factor
    ``NOISE_BAND``). ``switch`` is where the noise-aware design becomes the better one, found by
    running both on the scenario above with the noise scaled down from ``noise_std``; both the
    switched reconstructor's simulated errors, on clean data and at ``noise_std``, are in
    ``info["noise"]["adaptive"]``. On clean data the output is then the default design's.
    With ``check=False`` the analytic design is used: layers from the noise (``delta >= 3
    ||noise||`` at the primary, ``>= 3`` RMS output errors at the secondary) and a loop bandwidth
    ``5 / lpf_tau``, ``lpf_tau`` minimising the linear-model error ``sqrt((fault_rate * lag)^2 +
    fhat_std^2)`` (:func:`noise_response`; ``predicted_by = "linear model"``). Without
    ``noise_std``, no filter,
    and the boundary layers are sized for ``accuracy``: the largest ``delta = delta2`` of
    :data:`DELTA_LADDER` (1e-5 down to 1e-9) for which the design's :func:`self_check` (a step of
    every fault on its own model, run by the compiled runtime) leaves a relative error
    ``<= accuracy``. A boundary layer leaves an error in ``fhat`` that grows as ``delta / |z|``
    near a slow invariant zero ``z``; the paper's ``1e-5`` is enough for the aircraft but not for
    a zero at ``-0.02``. ``info["boundary_layers"]`` lists the layers tried and what each gave.

    What the bound claims. The self-check also runs a smooth ``xi`` without fault and measures
    ``||fhat||_2 / ||xi||_2`` for the observers as implemented (step ``dt``, layers ``delta``),
    and the same for sinusoidal ``xi`` across the band up to a tenth of the Nyquist limit
    (:func:`band_frequencies`, including the H-inf peak frequency of the xi -> fhat path).
    ``info["l2_bound_claimed"]`` is True when every probe is within gamma-bar
    (``info["l2_bound_worst_ratio"]`` and ``info["l2_bound_worst_w"]``: the worst measured gain
    over gamma-bar and its frequency, 0 for the smooth probe); it is False where gamma-bar
    lies below the floor of the sampled observers (an LMI gamma-bar near its lower limit 1e-7
    means perfect decoupling in continuous time, which a fixed-step observer with a boundary layer
    does not reach), and ``info["l2_bound_implemented"]`` then gives the measured gain, with a note
    in ``info["l2_bound_note"]``. The layer sizing prefers layers that let gamma-bar be claimed.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous model; group ``f`` holds the fault directions ``M`` and group ``d`` the
        uncertainty directions ``Q``. Faults and disturbances must not reach the outputs directly
        (``D_f = D_d = 0``).
    faults, disturbances : list of str, optional
        Names to use (default: all of the group).
    A_Omega, B_Omega : array_like (h, h), optional
        Disturbance filter (3); default ``-omega_d I`` and ``omega_d I``.
    omega_d : float
        Disturbance bandwidth (rad/s) of the default filter (paper: 10).
    V1 : (n, n), V2 : (p, p) array_like, optional
        Weights of the primary LMI (42); default ``100 I`` (paper; scaled down by up to 1e-5 when
        (42) is infeasible, ``info["V1_scale"]``: ``G(s)`` does not depend on it) and ``I``.
    D1 : (pbar, pbar) array_like, optional
        Weight of (47); default ``10 I`` (paper).
    gamma_o : float
        Level of (47) (paper: 100), tried first.
    gamma_o_retry : bool
        When (47) is infeasible at ``gamma_o``, use the first level of
        :data:`fdikit.design.smo_lmi.GAMMA_O_FACTORS` that works (``info["gamma_o"]``); with
        ``False`` the error names it.
    Af : (r, r) array_like, optional
        Filter (28) of the relative-degree-one fault channels; default ``10 I``.
    fault_bound : float
        Bound on ``||f(t)||`` (model fault units) the gains are sized for (default 1).
    fault_rate : float, optional
        Bound on ``||f'(t)||`` (units/s); used by the noise design (default ``10 fault_bound``).
    xi_bound : float
        Bound on ``||xi(t)||`` (the uncertainty filter's input) the gains are sized for.
    margin : float
        Relative margin of the sized gains (> 0).
    rho, rho2 : float, optional
        Switching gains of the primary (24) and secondary (39) observers (default: sized).
    delta, delta2 : float, optional
        Boundary layers (default: sized for ``accuracy``, see above, or from ``noise_std``).
    noise_std : float or array_like (p,), optional
        Measurement noise standard deviation per output (output units).
    lpf_tau : float, optional
        Time constant (s) of the low-pass on ``fhat`` (default: 0 without noise, optimised with).
    dt : float
        Integration step = sample time of the data the runtime accepts (s).
    tol, atol, rtol : float, optional
        Rank tolerances (see :func:`check_conditions`); decisions in
        ``info["conditions"]["rank_decisions"]`` and ``info["rank_decisions_lemma4"]``.
    hinf_check : bool
        Compute the H-infinity norm of ``G(s)`` (40) independently of the LMI.
    scheme : {"implicit", "explicit"}
        Euler step with the switched term at the new time (default; no numerical chattering)
        or the plain explicit Euler step.
    level : float
        Status threshold: sliding while ``||nu|| <= level rho``.
    accuracy : float
        Relative reconstruction error (of ``fault_bound``) the boundary-layer sizing aims at
        (default 1e-3); a warning says when no layer of the ladder reaches it.
    check : bool
        Run :func:`self_check` (default True; about 0.3 s per second of ``check_horizon`` at
        ``dt = 1e-5``). With False the layers are ``1e-5`` unless given and nothing is claimed
        (``info["l2_bound_claimed"]`` is None).
    check_horizon : float
        Length (s) of the self-check runs (scored over their second half).
    settle : float, optional
        Seconds the error must stay inside the boundary layer after a loss of sliding before the
        status says sliding again (default: three time constants of the slowest mode of the
        sliding motion, ``info["sliding_settle"]``; a slow invariant zero makes it long, because
        the reconstruction really takes that long to recover).

    Returns
    -------
    SlidingModeReconstructor
        ``info["case"]`` is ``"single"`` or ``"cascade"``; ``info["l2_bound"]`` is gamma-bar,
        ``info["l2_bound_claimed"]`` whether the implementation achieves it (see above);
        ``info["self_check"]`` what the design achieved on its own model;
        ``info["solver"]`` the LMI solver records (status, iterations, refinement, largest
        constraint violation); ``info["gamma_o"]`` the level of (47) used.

    Raises
    ------
    ConditionError
        Naming the failed condition (``"rank M = q"``, ``"rank C = p"``, ``"detectability"``,
        ``"B1"``, ``"A2"``/``"B2"``, ``"LMI"``) with its numbers.
    DataError
        A parameter out of range or a matrix of the wrong shape, named.

    Examples
    --------
    >>> from fdikit.systems import aircraft
    >>> from fdikit.residuals import design_reconstructor
    >>> rec = design_reconstructor(aircraft.model())
    >>> rec.info["case"], rec.info["pbar"], rec.info["rank_CM"], round(rec.info["l2_bound"], 4)
    ('cascade', 3, 0, 1.3131)
    >>> rec.output_names
    ['fhat:actuator:rudder_cmd', 'sliding_status', 'sliding_status:primary', 'sliding_status:secondary']
    """
    t0 = time.perf_counter()
    if not isinstance(model, LinearFaultModel):
        raise DataError(f"model must be a LinearFaultModel, got {type(model).__name__}")
    if model.is_discrete:
        raise ModelError(f"model {model.name!r} is discrete; the SMO design needs a continuous model")
    if scheme not in ("implicit", "explicit"):
        raise ModelError(f"scheme must be 'implicit' or 'explicit', got {scheme!r}")
    dt = _pos(dt, "dt")
    fault_bound = _pos(fault_bound, "fault_bound")
    xi_bound = _pos(xi_bound, "xi_bound", allow_zero=True)
    margin = _pos(margin, "margin")
    fault_rate = 10.0 * fault_bound if fault_rate is None else _pos(fault_rate, "fault_rate", allow_zero=True)
    gamma_o = _pos(gamma_o, "gamma_o")
    accuracy = _pos(accuracy, "accuracy")
    check_horizon = _pos(check_horizon, "check_horizon")
    user = {"rho": rho, "rho2": rho2, "delta": delta, "delta2": delta2}
    for key, v in user.items():
        if v is not None:
            user[key] = _pos(v, key)
    if lpf_tau is not None:
        lpf_tau = _pos(lpf_tau, "lpf_tau", allow_zero=True)
    fnames = model.fault_names if faults is None else list(faults)
    dnames = model.input_names("d") if disturbances is None else list(disturbances)
    if not fnames:
        raise ModelError(f"model {model.name!r} declares no faults to reconstruct")
    fi = [model._lookup(model.fault_names, f, "fault") for f in fnames]
    di = [model._lookup(model.input_names("d"), d, "disturbance") for d in dnames]
    M = model.B_of("f")[:, fi]
    Q = model.B_of("d")[:, di] if di else np.zeros((model.n_states, 0))
    if np.abs(model.D_of("f")[:, fi]).max(initial=0.0) > 0 or \
            (di and np.abs(model.D_of("d")[:, di]).max(initial=0.0) > 0):
        raise ModelError("the SMO reconstructor handles actuator faults and state disturbances: "
                         "D_f and D_d must be zero")
    A, B, C = model.A, model.B, model.C
    if np.abs(model.D).max(initial=0.0) > 0:
        raise ModelError("the SMO reconstructor needs D_u = 0 (strictly proper plant)")
    _n, p, q, h = A.shape[0], C.shape[0], M.shape[1], Q.shape[1]
    sig = None
    if noise_std is not None:
        sig = np.asarray(noise_std, float)
        if sig.ndim > 1 or (sig.ndim == 1 and sig.size != p) or not np.all(np.isfinite(sig)) or \
                np.any(sig < 0):
            raise DataError(f"noise_std must be a finite scalar or {p} values >= 0 (one per output "
                            f"{list(model.outputs)}), got {noise_std!r}")
        sig = np.broadcast_to(sig, (p,)).astype(float)
        if not sig.any():
            sig = None
    cond = check_conditions(A, M, C, Q, tol=tol, atol=atol, rtol=rtol)
    case = cond.require()
    A_O, B_O = _as_omega(A_Omega, B_Omega, omega_d, h)
    l1 = lemma1_form(A, B, M, C, Q, tol=tol, rank_CM=cond.rank_CM)
    aug = augment(l1, A_O, B_O)
    na = aug.n
    V1_given = V1 is not None
    V1 = 100.0 * np.eye(na) if V1 is None else _spd(_mat(V1, (na, na), f"V1 (augmented state: {na})"), "V1")
    V2 = np.eye(p) if V2 is None else _spd(_mat(V2, (p, p), "V2"), "V2")
    info: dict[str, Any] = {"case": case, "conditions": cond.as_dict(), "rank_CM": cond.rank_CM,
                            "n_aug": na, "h": h, "q": q, "p": p}
    details: dict[str, Any] = {"conditions": cond, "lemma1": l1, "augmented": aug, "model": (A, M, C, Q)}
    solver: dict[str, Any] = {}
    t_lmi = 0.0
    if case == "cascade":
        cf = lemma4_form(aug, tol=tol)
        details["canonical"] = cf
        info["rank_decisions_lemma4"] = {k: v.as_dict() for k, v in cf.rank_decisions.items()}
        pbar, r = cf.pbar, cf.r
        if Af is None:
            Af = 10.0 * np.eye(r)
        else:
            Af = _mat(Af, (r, r), "Af")
            if r and np.linalg.eigvals(-Af).real.max() >= 0:
                raise DataError(f"-Af must be stable; eigenvalues of Af {np.linalg.eigvals(Af)}")
        ts = time.perf_counter()
        # (42) is a Riccati-type inequality that a large V1 can make infeasible; G(s) does not
        # depend on the primary design (the paper's key observation), so a default V1 that fails
        # is scaled down until (42) holds.
        scales = [1.0] if V1_given else [1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5]
        tried1 = []
        for sc in scales:
            try:
                g1 = primary_smo_lmi(cf.A, cf.C, V1 * sc, V2)
            except ConditionError as exc:
                tried1.append({"V1_scale": sc, "message": str(exc)})
                if sc == scales[-1]:
                    raise ConditionError(exc.condition, f"{exc} (V1 scaled by {scales})",
                                         {**exc.details, "V1_tried": tried1}) from None
                continue
            tried1.append({"V1_scale": sc, "ok": True})
            break
        t_lmi += time.perf_counter() - ts
        solver["primary"] = {**g1.solver, "V1_tried": tried1}
        info["V1_scale"] = tried1[-1]["V1_scale"]
        fs = fictitious_system(cf, g1.L, Af)
        details["primary_gains"], details["fictitious"] = g1, fs
        A2, M2, C2, Q2 = fs.A, fs.M, fs.C, fs.Q
        B2 = np.zeros((A2.shape[0], B.shape[1]))
        D1m = 10.0 * np.eye(pbar) if D1 is None else _spd(_mat(D1, (pbar, pbar), "D1"), "D1")
        ts = time.perf_counter()
        g2 = _secondary(A2, M2, C2, Q2, D1m, gamma_o, gamma_o_retry, cond)
        t_lmi += time.perf_counter() - ts
        T = cf.T
        Tv = T.T @ np.linalg.solve(g1.Po, np.eye(p))
        n4 = cf.blocks[3]
        Zsel = np.arange(n4 - (pbar - r), n4)
        info["trace_X"] = g1.trace_X
        g1f, g1x = injection_peak_gains(cf.A, cf.M, cf.Q, cf.C, g1.L, g1.Po)
    else:
        pbar, r = p, q
        Af = np.zeros((0, 0))
        A2, M2, C2, Q2, B2 = aug.A, aug.M, aug.C, aug.Q, aug.B
        D1m = 10.0 * np.eye(pbar) if D1 is None else _spd(_mat(D1, (pbar, pbar), "D1"), "D1")
        ts = time.perf_counter()
        g2 = _secondary(A2, M2, C2, Q2, D1m, gamma_o, gamma_o_retry, cond)
        t_lmi += time.perf_counter() - ts
        Tv = np.zeros((0, 0))
        Zsel = np.zeros(0, dtype=np.int64)
        g1f = g1x = 0.0
    solver["secondary"] = g2.solver
    details["secondary_gains"] = g2
    details["secondary_system"] = (A2, C2)
    nb, pb = A2.shape[0], C2.shape[0]
    Tb = C2[:, nb - pb:]
    g2f, g2x = injection_peak_gains(A2, M2, Q2, C2, g2.L, g2.Po)
    # gains sized from the bounds (see the docstring)
    need1 = g1f * fault_bound + g1x * xi_bound
    need2 = g2f * fault_bound + g2x * xi_bound
    rho_v = user["rho"] if user["rho"] is not None else (1.0 + margin) * need1
    rho2_v = user["rho2"] if user["rho2"] is not None else (1.0 + margin) * need2
    if case != "cascade" and user["rho"] is None:
        rho_v = 1.0  # no primary observer
    rho_v, rho2_v = max(rho_v, 1e-12), max(rho2_v, 1e-12)

    def cap(rv, gf, gx, xb):
        return float("inf") if gf == 0 else (rv - gx * xb) / gf

    f_max = min(cap(rho_v, g1f, g1x, xi_bound) if case == "cascade" else float("inf"),
                cap(rho2_v, g2f, g2x, xi_bound))
    obs = [(rho2_v, g2f, g2x)] + ([(rho_v, g1f, g1x)] if case == "cascade" else [])
    xi_max = min((rv - gf * fault_bound) / gx if gx > 0 else float("inf") for rv, gf, gx in obs)
    ok = bool(f_max >= fault_bound * (1.0 + 1e-12) and xi_max >= xi_bound)
    info["gains"] = {"rho": rho_v, "rho2": rho2_v, "sized": {k: user[k] is None for k in ("rho", "rho2")},
                     "margin": margin, "fault_bound": fault_bound, "fault_rate": fault_rate,
                     "xi_bound": xi_bound,
                     "injection_peak_gain_primary": {"fault": g1f, "xi": g1x},
                     "injection_peak_gain_secondary": {"fault": g2f, "xi": g2x},
                     "needed_primary": need1, "needed_secondary": need2}
    info["reconstructible"] = {"fault_bound_max": f_max, "xi_bound_max": xi_max, "ok": ok,
                               "note": "largest ||f|| (at xi_bound) and ||xi|| (at fault_bound) for "
                                       "which an ideal sliding motion is kept by rho, rho2 (peak-gain "
                                       "bound; after the reaching phase)"}
    if not ok:
        warnings.warn(f"the switching gains (rho = {rho_v:.4g}, rho2 = {rho2_v:.4g}) cannot keep sliding for "
                      f"||f|| <= {fault_bound:g} and ||xi|| <= {xi_bound:g}: the reconstructible range is "
                      f"||f|| <= {f_max:.4g}; the sliding_status outputs will flag the losses",
                      stacklevel=2)
    Wrec = g2.W @ np.linalg.solve(Tb, np.linalg.solve(g2.Po, np.eye(pb)))  # W Tbar^-1 Pobar^-1
    Wf = l1.T2.T @ Wrec  # back to the original fault coordinates (T2 orthogonal)
    # G(s) of (40)
    k2 = nb - pb
    A1b, A3b, Q1b, Q2b = A2[:k2, :k2], A2[k2:, :k2], Q2[:k2], Q2[k2:]
    AG = A1b + g2.L @ A3b
    BG = Q1b + g2.L @ Q2b
    CG = g2.W @ A3b
    DG = g2.W @ Q2b
    details["G"] = (AG, BG, CG, DG)
    # the sliding motion's slowest mode: how long a loss of sliding takes to wash out of fhat
    ev_G = np.linalg.eigvals(AG) if AG.size else np.zeros(0)
    slow_mode = float(np.min(-ev_G.real)) if ev_G.size else float("inf")
    if settle is None:
        settle_v = 3.0 / slow_mode if np.isfinite(slow_mode) and slow_mode > 0 else 0.0
    else:
        settle_v = _pos(settle, "settle", allow_zero=True)
    info["sliding_settle"] = {"settle_s": settle_v, "slowest_sliding_mode": slow_mode,
                              "sized": settle is None,
                              "note": "after a loss of sliding the status stays 'not sliding' until the "
                                      "error has stayed in the boundary layer settle_s seconds (three time "
                                      "constants of the slowest eigenvalue of the sliding motion, eq. (40))"}
    info.update({"pbar": int(pbar), "r": int(r), "l2_bound": g2.gamma, "lmi_seconds": t_lmi,
                 "l2_bound_from": "xi, the input of the uncertainty filter xi~' = A_Omega xi~ + B_Omega xi",
                 "W_Tinv_Poinv": Wrec, "Po_bar": g2.Po, "gamma_o": g2.gamma_o, "solver": solver,
                 "Po": details["primary_gains"].Po if case == "cascade" else None})
    if hinf_check and h:
        hn = hinf_norm(AG, BG, CG, DG)
        info["hinf_check"] = {"hinf_bisection": hn["bisection"], "hinf_sweep": hn["sweep"],
                              "w_peak": hn["w_peak"],
                              "within_bound": bool(hn["bisection"] <= g2.gamma * (1 + 1e-6))}

    def build(d1, d2, tau):
        primary = ({"A": cf.A, "B": cf.B, "C": cf.C, "Gl": g1.Gl, "Gn": g1.Gn, "rho": rho_v, "delta": d1}
                   if case == "cascade" else
                   {"A": np.zeros((0, 0)), "B": np.zeros((0, B.shape[1])), "C": np.zeros((0, 0)),
                    "Gl": np.zeros((0, 0)), "Gn": np.zeros((0, 0)), "rho": rho_v, "delta": d1})
        secondary = {"A": A2, "B": B2, "C": C2, "Gl": g2.Gl, "Gn": g2.Gn, "rho": rho2_v, "delta": d2}
        return SlidingModeReconstructor(
            cascade=(case == "cascade"), primary=primary, secondary=secondary,
            Tv=np.ascontiguousarray(Tv), Zsel=np.asarray(Zsel, dtype=np.int64),
            Af=np.ascontiguousarray(Af), Wf=np.ascontiguousarray(Wf),
            r=int(r if case == "cascade" else 0), dt=float(dt), u_names=list(model.inputs),
            y_names=list(model.outputs), output_names=[f"fhat:{f}" for f in fnames], info=info,
            details=details, scheme=scheme, level=level, lpf_tau=tau, settle=settle_v)

    # self-check amplitudes: inside the reconstructible range
    f_chk = min(fault_bound, 0.5 * f_max) if np.isfinite(f_max) and f_max > 0 else fault_bound
    xi_chk = xi_bound if xi_bound > 0 else (min(1.0, 0.5 * xi_max) if np.isfinite(xi_max) and xi_max > 0
                                            else 1.0)
    gam = g2.gamma

    def checked(d1, d2, tau, step_error_max=None, xi_first=None):
        rec_ = build(d1, d2, tau)
        # a layer of the ladder stops its xi runs at the first that shows it cannot claim gamma-bar
        sc = self_check(rec_, fault_bound=f_chk, xi_amplitude=xi_chk if h else 0.0,
                        horizon=check_horizon, step_error_max=step_error_max,
                        xi_gain_max=gam if step_error_max is not None else None,
                        xi_first=xi_first) if check else None
        return rec_, sc

    # the default (noise-free) design: the boundary-layer ladder; with noise_std it is the
    # clean branch of the noise-aware design
    tau0 = 0.0 if lpf_tau is None or sig is not None else lpf_tau
    ladder = ([None] if user["delta"] is not None and user["delta2"] is not None
              else list(DELTA_LADDER))
    tried = []
    for dl in ladder:
        d1 = user["delta"] if user["delta"] is not None else dl
        d2 = user["delta2"] if user["delta2"] is not None else dl
        # a layer that misses the accuracy skips its xi runs (most of a large plant's check)
        prev = [x[3] for x in tried if x[3] is not None and x[3].get("xi_worst_index") is not None]
        rec, sc = checked(d1, d2, tau0, accuracy if len(ladder) > 1 else None,
                          prev[-1]["xi_worst_index"] if prev else None)
        tried.append((d1, d2, rec, sc))
        if not _finite_check(sc):
            continue  # a NaN / inf self-check is never chosen (recorded in info)
        # the first accurate layer that claims gamma-bar is the one picked below: stop there
        if sc is None or (sc["step_error"] <= accuracy and
                          (sc["xi_gain"] is None or sc["xi_gain"] <= gam)):
            break
    usable = [x for x in tried if _finite_check(x[3])]
    if not usable:
        raise _step_refusal(tried, dt, details, "every boundary layer tried gives a non-finite "
                            "self-check (the observers diverge at this step)")
    if usable[-1][3] is not None and len(usable) > 1:
        # the largest layer that is accurate and claims gamma-bar; else accurate; else the best
        acc = [x for x in usable if x[3]["step_error"] <= accuracy]
        claim = [x for x in acc if x[3]["xi_gain"] is None or x[3]["xi_gain"] <= gam]
        if claim:
            pick = claim[0]
        elif acc and acc[0][3]["xi_gain"] is not None:
            # no layer claims gamma-bar: the largest whose xi gain is within 10 % of the least
            # (a layer whose xi runs stopped at the first that missed gamma-bar is completed)
            for x in acc:
                if x[3].get("xi_partial"):
                    full = self_check(x[2], fault_bound=f_chk, xi_amplitude=xi_chk, horizon=check_horizon)
                    x[3].clear()
                    x[3].update(full)
            g_min = min(x[3]["xi_gain"] for x in acc)
            pick = next(x for x in acc if x[3]["xi_gain"] <= 1.1 * g_min)
        elif acc:
            pick = acc[0]
        else:
            pick = min(usable, key=lambda x: x[3]["step_error"])
        d1, d2, rec, sc = pick
    else:
        d1, d2, rec, sc = usable[-1]
    if sc is not None and (sc.get("xi_skipped") or sc.get("xi_partial")):
        sc = self_check(rec, fault_bound=f_chk, xi_amplitude=xi_chk, horizon=check_horizon)
    if sc is not None and sc["step_error"] > MAX_STEP_ERROR:
        raise _step_refusal(tried, dt, details, f"the best self-check leaves a step error of "
                            f"{sc['step_error']:.3g} (relative to the fault, > {MAX_STEP_ERROR:g})")
    info["noise"] = None
    info["boundary_layers"] = {
        "delta": d1, "delta2": d2, "sized": user["delta"] is None or user["delta2"] is None,
        "accuracy": accuracy,
        "tried": [{"delta": a, "delta2": b_, **(c or {}),
                   **({} if _finite_check(c) else {"skipped": "non-finite self-check"})}
                  for a, b_, _r, c in tried],
        "note": "largest layer of DELTA_LADDER whose self-check step error is <= accuracy "
                "(relative to fault_bound) and whose xi gain allows claiming gamma-bar; a layer "
                "whose self-check is not finite is skipped"}
    if sig is not None:
        rec0, sc0 = rec, sc
        rec, info["noise"] = _noise_choice(build, sig, user, lpf_tau, fault_rate, rho_v, rho2_v,
                                           g1 if case == "cascade" else None, g2, dt, f_chk,
                                           check_horizon if check else None)
        # white noise moves the output error every step: the transient test of the status
        # (runtime.TRANSIENT_LEVEL) would flag every sample; fhat is low-passed instead
        rec.transient_level = 0.0
        info["noise"]["status_transient_level"] = 0.0
        sc = self_check(rec, fault_bound=f_chk, xi_amplitude=xi_chk if h else 0.0,
                        horizon=check_horizon) if check else None
        nz = [(info["noise"]["delta"], info["noise"]["delta2"], rec, sc)]
        if not _finite_check(sc):
            raise _step_refusal(nz, dt, details, "the noise-sized boundary layers give a non-finite "
                                "self-check")
        if sc is not None and sc["step_error"] > MAX_STEP_ERROR:
            raise _step_refusal(nz, dt, details, f"the noise-sized design leaves a self-check step "
                                f"error of {sc['step_error']:.3g} (relative to the fault, > "
                                f"{MAX_STEP_ERROR:g})")
        pe = info["noise"]["predicted_error"]
        if pe > NOISE_WARN * fault_bound:
            how = ("simulated on a step and a sinusoid at fault_rate with this noise" if
                   info["noise"]["predicted_by"] == "simulation" else "linear boundary-layer model")
            warnings.warn(f"with noise_std = {sig.tolist()} the predicted reconstruction error is "
                          f"{pe:.3g} ({pe / fault_bound:.1%} of fault_bound = {fault_bound:g}, {how}; "
                          f"lpf_tau {info['noise']['lpf_tau']:.3g} s, noise std of fhat "
                          f"{np.linalg.norm(info['noise']['fhat_noise_std']):.3g}): the estimate is "
                          f"not accurate at this noise level; info['noise']", stacklevel=2)
        if check and (rec.primary["delta"], rec.secondary["delta"], rec.lpf_tau) != (
                rec0.primary["delta"], rec0.secondary["delta"], rec0.lpf_tau):
            sw = _switch_design(rec, rec0, sig, f_chk, fault_rate, check_horizon)
            rec.clean_branch = rec0
            rec.noise_switch = {k: sw[k] for k in ("noise_std", "switch", "band", "window", "warmup")}
            rec._check_branch()
            info["noise"]["adaptive"] = {**sw, "clean_branch_self_check": sc0}
        else:
            info["noise"]["adaptive"] = {"switch": None, "note": (
                "the noise-aware design is the default design" if check else
                "no clean branch: the switch is designed by simulation, which check=False turns off")}
    info["self_check"] = sc
    if sc is not None:
        if sig is None and sc["step_error"] > accuracy:
            warnings.warn(f"the reconstructor misses its accuracy on its own model: a step of "
                          f"{f_chk:.4g} leaves an error of {sc['step_error']:.3g} (relative; target "
                          f"accuracy = {accuracy:g}) with delta = {rec.primary['delta']:g}, delta2 = "
                          f"{rec.secondary['delta']:g}, dt = {dt:g}; info['self_check']", stacklevel=2)
        claimed = sc["xi_gain"] is None or sc["xi_gain"] <= gam
        info["l2_bound_claimed"] = bool(claimed)
        info["l2_bound_implemented"] = sc["xi_gain"]
        if sc["xi_gain"] is not None:
            info["l2_bound_worst_ratio"] = sc["xi_gain"] / gam if gam > 0 else float("inf")
            info["l2_bound_worst_w"] = sc["xi_worst_w"]
            info["l2_bound_band_rad_s"] = sc.get("xi_band_rad_s")
        if not claimed:
            where = (f"a sinusoidal xi at {sc['xi_worst_w']:.3g} rad/s" if sc["xi_worst_w"] else
                     "a smooth xi")
            info["l2_bound_note"] = (
                f"gamma-bar = {gam:.3g} is below what the sampled observers achieve (dt = {dt:g}, "
                f"delta2 = {rec.secondary['delta']:g}): the self-check measured "
                f"||fhat||_2 / ||xi||_2 = {sc['xi_gain']:.3g} on {where} (probes up to "
                f"{sc.get('xi_band_rad_s') or 8.0:.3g} rad/s); the bound is not claimed")
    else:
        info["l2_bound_claimed"] = None
        info["l2_bound_implemented"] = None
    details.pop("self_check_plant_runs", None)  # the self-check's plant runs (memory)
    info["design_seconds"] = time.perf_counter() - t0
    return rec
