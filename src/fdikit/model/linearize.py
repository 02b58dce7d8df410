"""Linearisation of a nonlinear model about an operating point, and trim (equilibrium) search.

:func:`linearize` differentiates ``x' = f(t, x, u, p)``, ``y = h(t, x, u, p)`` by central
differences, all perturbations evaluated in one vectorised call of ``f`` and one of ``h`` (the
:class:`~fdikit.model.nonlinear.NonlinearModel` protocol is vectorised over runs), and returns a
:class:`~fdikit.model.linear.LinearFaultModel` with the model's names, input groups and the
requested fault directions, including linearised parametric faults ``param:<name>``.

:func:`trim` finds an equilibrium (or a steady condition with prescribed derivatives and output
targets) with :func:`scipy.optimize.least_squares`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..errors import ConditionError, ModelError
from .linear import LinearFaultModel

__all__ = ["DEFAULT_REL_STEP", "linearize", "trim"]

#: Default relative step of the central differences: ``eps ** (1/3)`` balances the O(h^2)
#: truncation error against the O(eps / h) rounding error.
DEFAULT_REL_STEP = float(np.finfo(float).eps ** (1.0 / 3.0))


def _vector(v: Any, n: int, what: str, names: Sequence[str]) -> np.ndarray:
    if isinstance(v, Mapping):
        unknown = sorted(set(v) - set(names))
        if unknown:
            raise ModelError(f"{what}: unknown names {unknown}; known: {list(names)}")
        missing = [s for s in names if s not in v]
        if missing:
            raise ModelError(f"{what}: no value for {missing}")
        v = [v[s] for s in names]
    a = np.asarray(v if v is not None else np.zeros(n), dtype=float).reshape(-1)
    if a.size != n:
        raise ModelError(f"{what} must have {n} entries ({list(names)}), got {a.size}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise ModelError(f"{what} is not finite at {[names[i] for i in np.nonzero(bad)[0]]}")
    return a


def _params(model: Any, p: Mapping[str, Any] | None) -> dict[str, float]:
    base = dict(getattr(model, "params", {}) or {})
    for k, v in (p or {}).items():
        if k not in base:
            raise ModelError(f"unknown parameter {k!r}; parameters: {sorted(base)}")
        if np.ndim(v) != 0:
            raise ModelError(f"parameter {k!r}: linearize/trim need one scalar value, "
                             f"got shape {np.shape(v)}")
        base[k] = float(v)
    return base


def _groups(model: Any) -> dict[str, list[str]]:
    inputs = list(model.inputs)
    g = getattr(model, "groups", None) or {}
    d, w = list(g.get("d", [])), list(g.get("w", []))
    u = list(g.get("u", [])) or [s for s in inputs if s not in d and s not in w]
    listed = u + d + w
    missing = [s for s in inputs if s not in listed]
    if missing or len(set(listed)) != len(listed):
        raise ModelError(f"model.groups must assign every input exactly once; unassigned {missing}, "
                         f"groups {dict(u=u, d=d, w=w)}")
    return {"u": u, "d": d, "w": w}


def _steps(names: Sequence[str], values: np.ndarray, steps: Mapping[str, float] | None,
           scales: Mapping[str, float] | None, rel_step: float, abs_step: float) -> np.ndarray:
    """Per-variable step ``h_i = max(rel_step * max(|v_i|, scale_i), abs_step)`` unless given."""
    steps, scales = dict(steps or {}), dict(scales or {})
    h = np.empty(len(names))
    for i, s in enumerate(names):
        if s in steps:
            h[i] = float(steps[s])
        else:
            h[i] = max(rel_step * max(abs(values[i]), float(scales.get(s, 1.0))), abs_step)
        if not (h[i] > 0 and np.isfinite(h[i])):
            raise ModelError(f"finite-difference step for {s!r} must be positive, got {h[i]}")
    return h


def _call(fun, what: str, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any],
          width: int, labels: Sequence[str]) -> np.ndarray:
    out = np.asarray(fun(t, x, u, p), dtype=float)
    runs = x.shape[0]
    if out.shape != (runs, width):
        arrays = sorted(k for k, v in p.items() if np.ndim(v))
        hint = (f"; parameters {arrays} are passed as (runs,) arrays (one value per run, the protocol of "
                "fdikit.model.nonlinear), so the model must broadcast them, e.g. "
                "np.reshape(p['k'], (-1, 1)) * x") if arrays else ""
        raise ModelError(f"model.{what} returned shape {out.shape} for {runs} runs; "
                         f"expected {(runs, width)}{hint}")
    bad = ~np.isfinite(out)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise ModelError(f"model.{what} is not finite (component {c}) when perturbing {labels[r]}; "
                         "reduce the step or check the operating point")
    return out


def linearize(
    model: Any,
    x0: Any,
    u0: Any = None,
    p: Mapping[str, float] | None = None,
    t: float = 0.0,
    *,
    faults: Iterable[Any] = (),
    steps: Mapping[str, float] | None = None,
    scales: Mapping[str, float] | None = None,
    rel_step: float = DEFAULT_REL_STEP,
    abs_step: float = 1e-12,
    method: str = "central",
    name: str | None = None,
) -> LinearFaultModel:
    """Linearise a nonlinear model about ``(x0, u0, p)`` by central differences.

    ``A = df/dx``, ``B = df/du``, ``C = dh/dx``, ``D = dh/du`` at the operating point, each
    column from ``(g(v + h_i e_i) - g(v - h_i e_i)) / (2 h_i)``. All ``2 (n + m)`` perturbed
    points (plus two per parametric fault) are evaluated in ONE call of ``f`` and one of ``h``,
    as a batch of runs.

    Parameters
    ----------
    model : NonlinearModel (protocol)
        ``states``, ``inputs``, ``outputs``, ``params``, vectorised ``f`` and ``h``; optional
        ``groups`` (inputs in ``"d"`` / ``"w"`` become disturbances / noise, the rest controls)
        and ``jac_x`` / ``jac_u``.
    x0 : array_like (n,) or mapping state name -> value
        Operating state, in the states' units.
    u0 : array_like (m,) or mapping input name -> value, optional
        Operating input (zeros by default).
    p : mapping name -> float, optional
        Parameter values overriding ``model.params``.
    t : float
        Time of the operating point (s), for time-varying models.
    faults : iterable
        Fault declarations: ``"actuator:<input>"`` (direction = the input's columns of B and D,
        for an input of any group), ``"sensor:<output>"``, ``"param:<name>"`` (direction
        ``(df/dp, dh/dp)`` by central difference: the linearised parametric fault per unit
        change of the parameter, in the parameter's units) or ``(name, b, d)``.
    steps : mapping name -> float, optional
        Explicit step for some states, inputs or parameters.
    scales : mapping name -> float, optional
        Typical magnitude of a variable (default 1): the default step is
        ``h_i = max(rel_step * max(|v_i|, scale_i), abs_step)``.
    rel_step : float
        Relative step, default ``eps**(1/3) ~ 6.1e-6`` (optimal for central differences).
    abs_step : float
        Smallest step.
    method : {"central", "analytic"}
        ``"analytic"`` takes ``A`` and ``B`` from the model's ``jac_x`` / ``jac_u`` (which must
        not return None); ``C``, ``D`` and parametric directions are still central differences.
    name : str, optional
        Name of the linear model (default the nonlinear model's name).

    Returns
    -------
    LinearFaultModel
        Continuous model in deviation variables ``x - x0``, ``u - u0``, ``y - h(x0, u0)``.

    Raises
    ------
    ModelError
        Bad shapes, unknown names, non-finite model output at a perturbed point, missing
        analytic Jacobian.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import NonlinearModel, linearize
    >>> def f(t, x, u, p):  # p["k"] is a float or a (runs,) array: broadcast over the state axis
    ...     return -np.reshape(p["k"], (-1, 1)) * x**3 + u
    >>> m = NonlinearModel(f, lambda t, x, u, p: x, ["x"], ["u"], ["y"], {"k": 2.0})
    >>> lin = linearize(m, [1.0], [2.0], faults=["param:k"])
    >>> round(float(lin.A[0, 0]), 8), round(float(lin.B_of("f")[0, 0]), 8)   # -3 k x^2, -x^3
    (-6.0, -1.0)
    """
    states, inputs, outputs = list(model.states), list(model.inputs), list(model.outputs)
    n, m, ny = len(states), len(inputs), len(outputs)
    x0 = _vector(x0, n, "x0", states)
    u0 = _vector(u0, m, "u0", inputs)
    pv = _params(model, p)
    groups = _groups(model)
    faults = list(faults)
    pfaults = [f for f in faults if isinstance(f, str) and f.startswith("param:")]
    pnames = [f.partition(":")[2] for f in pfaults]
    for s in pnames:
        if s not in pv:
            raise ModelError(f"fault 'param:{s}': unknown parameter; parameters: {sorted(pv)}")
    if method not in ("central", "analytic"):
        raise ModelError(f"method must be 'central' or 'analytic', got {method!r}")

    hx = _steps(states, x0, steps, scales, rel_step, abs_step)
    hu = _steps(inputs, u0, steps, scales, rel_step, abs_step)
    hp = _steps(pnames, np.array([pv[s] for s in pnames]), steps, scales, rel_step, abs_step)
    k = len(pnames)
    nv = n + m + k
    runs = 2 * nv
    # batch: rows 2i / 2i+1 are +h / -h on variable i (states, then inputs, then parameters)
    X = np.tile(x0, (runs, 1))
    U = np.tile(u0, (runs, 1))
    P: dict[str, Any] = dict(pv)
    sign = np.tile([1.0, -1.0], nv)
    for i in range(n):
        X[2 * i:2 * i + 2, i] += sign[:2] * hx[i]
    for j in range(m):
        U[2 * (n + j):2 * (n + j) + 2, j] += sign[:2] * hu[j]
    for q, s in enumerate(pnames):
        col = np.full(runs, pv[s])
        col[2 * (n + m + q):2 * (n + m + q) + 2] += sign[:2] * hp[q]
        P[s] = col
    labels = [f"{kind} {s!r} {'+' if r == 0 else '-'}h" for kind, names in
              (("state", states), ("input", inputs), ("parameter", pnames)) for s in names for r in (0, 1)]
    h_all = np.concatenate([hx, hu, hp])
    Fv = _call(model.f, "f", t, X, U, P, n, labels)
    Hv = _call(model.h, "h", t, X, U, P, ny, labels)
    dF = ((Fv[0::2] - Fv[1::2]) / (2.0 * h_all[:, None])).T  # (n, nv)
    dH = ((Hv[0::2] - Hv[1::2]) / (2.0 * h_all[:, None])).T  # (ny, nv)
    A, B, C, D = dF[:, :n], dF[:, n:n + m], dH[:, :n], dH[:, n:n + m]
    Fp, Hp = dF[:, n + m:], dH[:, n + m:]

    if method == "analytic":
        x1, u1 = x0[None, :], u0[None, :]
        Ja = model.jac_x(t, x1, u1, pv) if hasattr(model, "jac_x") else None
        Jb = model.jac_u(t, x1, u1, pv) if hasattr(model, "jac_u") else None
        if Ja is None or Jb is None:
            raise ModelError("method='analytic' needs the model's jac_x and jac_u; "
                             f"jac_x is {'missing' if Ja is None else 'given'}, "
                             f"jac_u is {'missing' if Jb is None else 'given'}")
        A = np.asarray(Ja, float).reshape(n, n)
        B = np.asarray(Jb, float).reshape(n, m)

    idx = {s: i for i, s in enumerate(inputs)}

    def cols(g):
        c = [idx[s] for s in groups[g]]
        return B[:, c], D[:, c]

    Bu, Du = cols("u")
    Bd, Dd = cols("d")
    Bw, Dw = cols("w")
    specs: list[Any] = []
    for f in faults:
        if isinstance(f, str) and f.startswith("param:"):
            q = pnames.index(f.partition(":")[2])
            specs.append((f, Fp[:, q], Hp[:, q]))
        elif isinstance(f, str) and f.startswith("actuator:"):
            target = f.partition(":")[2]
            if target not in idx:
                raise ModelError(f"fault {f!r}: unknown input {target!r}; inputs: {inputs}")
            specs.append((f, B[:, idx[target]], D[:, idx[target]]))
        else:
            specs.append(f)
    return LinearFaultModel(
        A, Bu, C, Du, states=states, inputs=groups["u"], outputs=outputs,
        Bd=Bd if groups["d"] else None, Dd=Dd if groups["d"] else None, disturbances=groups["d"] or None,
        Bw=Bw if groups["w"] else None, Dw=Dw if groups["w"] else None, noises=groups["w"] or None,
        faults=specs, name=getattr(model, "name", "") if name is None else name,
    )


def trim(
    model: Any,
    x0: Any,
    u0: Any = None,
    p: Mapping[str, float] | None = None,
    *,
    t: float = 0.0,
    free_states: Sequence[str] | None = None,
    free_inputs: Sequence[str] | None = None,
    targets: Mapping[str, float] | None = None,
    derivatives: Mapping[str, float] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    tol: float = 1e-8,
    max_nfev: int | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Equilibrium or steady condition of a nonlinear model by nonlinear least squares.

    Solves, for the free states and free inputs,

        f_i(t, x, u, p) = derivatives[i]     for the constrained states i (default: all, = 0)
        h_j(t, x, u, p) = targets[j]         for the output targets j

    with :func:`scipy.optimize.least_squares` (trust-region reflective, bounds allowed), starting
    from ``(x0, u0)``; variables that are not free keep their values.

    Parameters
    ----------
    model : NonlinearModel (protocol)
    x0 : array_like (n,) or mapping
        Initial guess of the state (and the value of states that are not free).
    u0 : array_like (m,) or mapping, optional
        Initial guess / fixed value of the inputs (zeros by default).
    p : mapping, optional
        Parameter overrides.
    t : float
        Time (s).
    free_states : sequence of str, optional
        States to solve for (default: all).
    free_inputs : sequence of str, optional
        Inputs to solve for (default: none).
    targets : mapping output name -> value, optional
        Required output values.
    derivatives : mapping state name -> value, optional
        Constrained state derivatives; default every state's derivative is 0 (equilibrium). Give
        e.g. ``{"v": -3.0, "omega": -9.0}`` for a steady deceleration, or a subset of states to
        leave the others unconstrained.
    bounds : mapping name -> (low, high), optional
        Bounds on free variables.
    tol : float
        Largest accepted absolute residual (in the units of the derivatives / outputs).
    max_nfev : int, optional
        Passed to ``least_squares``.

    Returns
    -------
    x : ndarray (n,)
    u : ndarray (m,)
    info : dict
        ``residual_norm`` (2-norm), ``max_residual``, ``residuals`` (by equation name),
        ``nfev``, ``status``, ``message``, ``free`` (names solved for).

    Raises
    ------
    ConditionError
        ``condition="trim"`` when the residual stays above ``tol``; the message names the worst
        equation and its residual.
    ModelError
        Unknown names, no free variable or no equation.

    Examples
    --------
    A tank ``h' = q - k sqrt(h)``: with ``q = 1`` and ``k = 0.5`` the equilibrium is ``h = 4``.

    >>> import numpy as np
    >>> from fdikit.model import NonlinearModel, trim
    >>> tank = NonlinearModel(lambda t, x, u, p: u - p["k"] * np.sqrt(np.abs(x)),
    ...                       lambda t, x, u, p: x, ["h"], ["q"], ["level"], {"k": 0.5})
    >>> x, u, info = trim(tank, [1.0], [1.0])
    >>> round(float(x[0]), 9), info["max_residual"] < 1e-8
    (4.0, True)
    """
    states, inputs, outputs = list(model.states), list(model.inputs), list(model.outputs)
    n, m, ny = len(states), len(inputs), len(outputs)
    x0 = _vector(x0, n, "x0", states)
    u0 = _vector(u0, m, "u0", inputs)
    pv = _params(model, p)
    free_states = list(states if free_states is None else free_states)
    free_inputs = list(free_inputs or [])
    for s in free_states:
        if s not in states:
            raise ModelError(f"free state {s!r} unknown; states: {states}")
    for s in free_inputs:
        if s not in inputs:
            raise ModelError(f"free input {s!r} unknown; inputs: {inputs}")
    derivatives = {s: 0.0 for s in states} if derivatives is None else dict(derivatives)
    targets = dict(targets or {})
    for s in derivatives:
        if s not in states:
            raise ModelError(f"derivative constraint on unknown state {s!r}; states: {states}")
    for s in targets:
        if s not in outputs:
            raise ModelError(f"target on unknown output {s!r}; outputs: {outputs}")
    ix = [states.index(s) for s in free_states]
    iu = [inputs.index(s) for s in free_inputs]
    idd = [states.index(s) for s in derivatives]
    it = [outputs.index(s) for s in targets]
    dval = np.array([float(v) for v in derivatives.values()])
    tval = np.array([float(v) for v in targets.values()])
    eq_names = [f"d{s}/dt" for s in derivatives] + [f"output {s}" for s in targets]
    free = free_states + free_inputs
    if not free:
        raise ModelError("trim: no free state or input to solve for")
    if not eq_names:
        raise ModelError("trim: no equation (derivatives and targets are both empty)")

    def unpack(z):
        x, u = x0.copy(), u0.copy()
        x[ix], u[iu] = z[:len(ix)], z[len(ix):]
        return x, u

    def resid(z):
        x, u = unpack(z)
        r = []
        if idd:
            fx = np.asarray(model.f(t, x[None], u[None], pv), float).reshape(n)
            r.append(fx[idd] - dval)
        if it:
            hx = np.asarray(model.h(t, x[None], u[None], pv), float).reshape(ny)
            r.append(hx[it] - tval)
        out = np.concatenate(r)
        if not np.all(np.isfinite(out)):
            bad = [eq_names[i] for i in np.nonzero(~np.isfinite(out))[0]]
            raise ModelError(f"trim: model is not finite at x={x.tolist()}, u={u.tolist()} ({bad})")
        return out

    z0 = np.concatenate([x0[ix], u0[iu]])
    lo = np.full(len(free), -np.inf)
    hi = np.full(len(free), np.inf)
    for s, (a, b) in (bounds or {}).items():
        if s not in free:
            raise ModelError(f"bound on {s!r}, which is not a free variable; free: {free}")
        lo[free.index(s)], hi[free.index(s)] = a, b
    z0 = np.clip(z0, np.where(np.isfinite(lo), lo, z0), np.where(np.isfinite(hi), hi, z0))
    sol = least_squares(resid, z0, bounds=(lo, hi), method="trf", x_scale="jac",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev)
    r = sol.fun
    x, u = unpack(sol.x)
    info = {
        "residual_norm": float(np.linalg.norm(r)),
        "max_residual": float(np.max(np.abs(r))),
        "residuals": dict(zip(eq_names, r.tolist(), strict=True)),
        "nfev": int(sol.nfev),
        "status": int(sol.status),
        "message": str(sol.message),
        "free": free,
    }
    if not info["max_residual"] <= tol:
        worst = int(np.argmax(np.abs(r)))
        raise ConditionError(
            "trim",
            f"no steady condition found: largest residual {r[worst]:.3e} on {eq_names[worst]} "
            f"(tolerance {tol:g}, residual norm {info['residual_norm']:.3e}, {sol.nfev} evaluations; "
            f"solver: {sol.message}) at x={dict(zip(states, x.round(6).tolist(), strict=True))}, "
            f"u={dict(zip(inputs, u.round(6).tolist(), strict=True))}",
            info,
        )
    return x, u, info
