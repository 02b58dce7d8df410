"""Output-error parameter estimation with subset selection (luo-et-al, Section VIII, Appendix B).

The parameters ``theta`` of a model are found by re-simulating the model and minimising the
weighted sum of squared output errors

    r(i, theta) = y(i) - y_hat(i | theta)                              # luo-et-al eq. (43)
    theta_N = argmin_theta V_N(theta)                                  # luo-et-al eq. (44)
    V_N(theta) = 1/2 sum_i r(i, theta)' Lambda^-1 r(i, theta)          # luo-et-al eq. (45)

with scipy's trust-region-reflective ``least_squares`` (bounds). Any subset of the model's named
parameters may be estimated; the others stay at their nominal values. This is the *subset
selection* of Section VIII: once a parametric fault has been isolated (GLRT, SVM), only the
isolated parameter is estimated, which is far better conditioned than estimating all the
interesting parameters as a block.

The model enters only through a *simulator*: a callable ``simulate(params: dict) -> (T, p)``
that returns the noise-free outputs for a full parameter dictionary. Optionally it has a
``batch(list_of_params) -> (k, T, p)`` method, used to evaluate the finite-difference Jacobian
columns in one (parallel) pass. :class:`ModelSimulator` provides one for any
:class:`~fdikit.model.NonlinearModel` through :func:`fdikit.sim.simulate` (per-run parameter
arrays); a system can bring its own (e.g. :class:`fdikit.systems.abs.estimation.ABSSimulator`).

The ABS re-simulator and Table VI of luo-et-al are in :mod:`fdikit.systems.abs.estimation`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..errors import DataError, ModelError

__all__ = [
    "ModelSimulator",
    "OutputErrorResult",
    "output_error",
    "output_error_covariance",
]

# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------
@dataclass
class OutputErrorResult:
    """Outcome of :func:`output_error`.

    Attributes
    ----------
    names : tuple of str
        Estimated parameters, in order.
    theta : dict
        Estimates ``{name: value}`` (units of the model's parameters).
    theta0 : dict
        Starting values actually used (after the optional grid scan).
    params : dict
        The full parameter dictionary at the estimate (nominal values for the others).
    cost : float
        ``V_N(theta_N)`` of eq. (45).
    rms : float
        Root mean square of the weighted output errors, ``sqrt(2 V_N / (N M))``.
    std : dict
        Asymptotic standard deviations ``sqrt(diag(s^2 (J'J)^-1))`` with ``s^2 = 2 V_N/(N M - n)``
        (NaN when ``J'J`` is singular): a precision indicator valid for white output errors.
    jac : ndarray (N·M, n)
        Jacobian of the weighted residual vector with respect to ``theta`` (physical units).
    at_bound : dict of bool
        Whether each estimate sits on one of its bounds (within 1e-9 relative).
    nfev, njev : int
        Simulator calls for residuals and for Jacobians (a batched Jacobian counts once).
    status : int
        ``least_squares`` status (or 5 when the cost threshold stopped the search).
    message : str
    success : bool
    elapsed : float
        Wall-clock time, s.
    """

    names: tuple[str, ...]
    theta: dict[str, float]
    theta0: dict[str, float]
    params: dict[str, float]
    cost: float
    rms: float
    std: dict[str, float]
    jac: np.ndarray
    at_bound: dict[str, bool]
    nfev: int
    njev: int
    status: int
    message: str
    success: bool
    elapsed: float

    def relative_error(self, truth: Mapping[str, float]) -> dict[str, float]:
        """``|theta_hat - truth| / |truth|`` for every estimated name present in ``truth``."""
        return {k: abs(self.theta[k] - float(truth[k])) / abs(float(truth[k]))
                for k in self.names if k in truth}


# --------------------------------------------------------------------------------------------
# Simulators
# --------------------------------------------------------------------------------------------
class ModelSimulator:
    """Noise-free re-simulation of any NonlinearModel with :func:`fdikit.sim.simulate`.

    Parameters
    ----------
    model : NonlinearModel
        The model (``params`` holds its nominal parameters).
    scenario : fdikit.faults.Scenario
        Duration, steps, inputs or controller, initial state of the experiment. Its noise and
        faults are dropped (the model predictions of eq. (43) are noise free); its ``params``
        are the fixed values of the parameters not estimated.
    method : {"rk4", "euler"}
    outputs : sequence of str, optional
        Output channels compared with the measurements (default all).

    Notes
    -----
    ``batch`` simulates several parameter sets in one vectorised pass using per-run parameter
    arrays, so a finite-difference Jacobian costs about one simulation.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import NonlinearModel
    >>> from fdikit.faults import Scenario
    >>> from fdikit.estimate import ModelSimulator
    >>> m = NonlinearModel(lambda t, x, u, p: -np.reshape(p["a"], (-1, 1)) * x + u,
    ...                    lambda t, x, u, p: x, ["x"], ["u"], ["y"], {"a": 1.0})
    >>> sim = ModelSimulator(m, Scenario(duration=1.0, dt=0.01, sample_time=0.1, inputs=[1.0]))
    >>> sim({"a": 2.0}).shape
    (11, 1)
    """

    def __init__(self, model: Any, scenario: Any, *, method: str = "rk4",
                 outputs: Sequence[str] | None = None):
        from ..faults import Scenario

        if not isinstance(scenario, Scenario):
            raise DataError(f"scenario must be a fdikit.faults.Scenario, got {type(scenario).__name__}")
        self.model = model
        base = dict(model.params)
        for k, v in (scenario.params or {}).items():
            if k not in base:
                raise ModelError(f"scenario overrides unknown parameter {k!r}; parameters: {sorted(base)}")
            base[k] = v
        self.params = {k: float(v) for k, v in base.items()}
        self.scenario = replace(scenario, faults=(), noise=None, params=None)
        self.method = method
        self.outputs = None if outputs is None else list(outputs)

    def batch(self, params_list: Sequence[Mapping[str, float]]) -> np.ndarray:
        """Outputs ``(k, T, p)`` for ``k`` full parameter dictionaries, one vectorised pass."""
        from ..sim import simulate

        k = len(params_list)
        P = {name: np.array([float(p[name]) for p in params_list]) for name in self.params}
        sc = replace(self.scenario, params=P)
        res = simulate(self.model, sc, runs=k, method=self.method, outputs=self.outputs)
        return res.y.values

    def __call__(self, params: Mapping[str, float]) -> np.ndarray:
        """Outputs ``(T, p)`` for one full parameter dictionary."""
        return self.batch([params])[0]


class _Stop(Exception):
    pass


def _weight_root(weight: Any, T: int, M: int) -> np.ndarray:
    """``W`` with ``W' W = Lambda^-1`` (eq. (45)): shape (M, M), or (T, M, M) for a per-sample ``Lambda(i)``.

    ``weight`` may be None (identity), a vector (M,) of variances, a matrix (M, M), an array
    (T, M) of per-sample variances or (T, M, M) of per-sample covariances; every ``Lambda`` must
    be symmetric positive definite.
    """
    if weight is None:
        return np.eye(M)
    L = np.asarray(weight, dtype=float)
    if L.shape == (M,):
        L = np.diag(L)
    elif L.shape == (T, M) and L.shape != (M, M):
        L = L[:, :, None] * np.eye(M)[None]
    if L.shape not in ((M, M), (T, M, M)):
        raise DataError(f"weight Lambda must be ({M}, {M}), a vector of {M} variances, ({T}, {M}) or "
                        f"({T}, {M}, {M}) per sample, for {T} samples of {M} outputs; got shape {L.shape}")
    if not np.all(np.isfinite(L)):
        raise DataError("weight Lambda has NaN/inf entries")
    if not np.allclose(L, np.swapaxes(L, -1, -2), rtol=1e-10, atol=1e-12):
        raise DataError("weight Lambda must be symmetric")
    w, V = np.linalg.eigh(L)
    bad = w.min(axis=-1) <= 1e-14 * np.maximum(w.max(axis=-1), 1e-300)
    if np.any(bad):
        where = "" if L.ndim == 2 else f" at sample {int(np.argmax(bad))}"
        raise DataError(f"weight Lambda must be positive definite (eq. (45) uses its inverse){where}; "
                        f"eigenvalues {np.atleast_2d(w)[int(np.argmax(np.atleast_1d(bad)))].tolist()}")
    return np.swapaxes(V / np.sqrt(w)[..., None, :], -1, -2)  # W = diag(w)^-1/2 V'


def output_error(
    simulator: Callable[[dict[str, float]], Any],
    y: Any,
    names: Sequence[str],
    *,
    nominal: Mapping[str, float] | None = None,
    theta0: Mapping[str, float] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    weight: Any = None,
    scan: int = 0,
    diff_step: float | None = None,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
    max_nfev: int = 200,
    cost_threshold: float | None = None,
) -> OutputErrorResult:
    """Estimate a chosen subset of named parameters by output error (luo-et-al, eqs. (43)-(45)).

    Parameters
    ----------
    simulator : callable ``simulate(params: dict) -> (T, p)``
        Noise-free model outputs for a full parameter dictionary (same sampling as ``y``). If it
        has ``batch(list_of_dicts) -> (k, T, p)``, Jacobian columns are simulated in one batch.
        :class:`ModelSimulator` is a ready one (any NonlinearModel).
    y : array_like (T, p) or Signals with one run
        Measured outputs ``y(i)``, i = 1..N (units of the simulator's outputs).
    names : sequence of str
        Parameters to estimate (the subset); all others stay at ``nominal``.
    nominal : mapping, optional
        The full parameter dictionary (default ``simulator.params``). ``names`` must be keys.
    theta0 : mapping, optional
        Starting values of the estimated parameters (default their nominal values).
    bounds : mapping name -> (lo, hi), optional
        Bounds of the trust-region-reflective search (default unbounded); ``lo < hi``.
    weight : array_like, optional
        ``Lambda`` of eq. (45): (p, p), or (p,) variances; default identity, as in the paper. A
        per-sample ``Lambda(i)`` of shape (T, p, p) or (T, p) generalises eq. (45) to
        ``1/2 sum_i r(i)' Lambda(i)^-1 r(i)`` (e.g. the output-error covariance of a Monte Carlo
        calibration, see :func:`output_error_covariance`). Symmetric positive definite.
    scan : int
        If > 0, first evaluate ``V_N`` on a grid of ``scan`` points per estimated parameter
        between its bounds (all bounds must then be finite) and start from the best grid point
        (a guard against the local minima of a closed-loop, switching model); 0: no scan.
    diff_step : float, optional
        Relative forward-difference step of the Jacobian (default ``sqrt(eps)``, right for
        smooth models; a switching closed loop such as the ABS needs ~1e-3).
    ftol, xtol, gtol, max_nfev
        ``scipy.optimize.least_squares`` stopping rules.
    cost_threshold : float, optional
        Stop as soon as ``V_N < cost_threshold`` (the paper's rule, c = 1e-5 for the ABS).

    Returns
    -------
    OutputErrorResult

    Raises
    ------
    ModelError
        Unknown parameter names.
    DataError
        Bad bounds, a start outside them, mismatched shapes between ``y`` and the simulator, NaN.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.estimate import output_error
    >>> t = np.linspace(0.0, 2.0, 41)
    >>> sim = lambda p: np.stack([p["a"] * np.exp(-p["b"] * t)], axis=1)
    >>> y = sim({"a": 2.0, "b": 1.5})
    >>> r = output_error(sim, y, ["b"], nominal={"a": 2.0, "b": 1.0}, bounds={"b": (0.1, 5.0)})
    >>> round(r.theta["b"], 8)
    1.5
    """
    t_start = time.perf_counter()
    from ..signals import Signals

    if isinstance(y, Signals):
        if y.values.ndim == 3:
            if y.values.shape[0] != 1:
                raise DataError(f"output_error takes one record; got Signals with {y.values.shape[0]} runs")
            y = y.values[0]
        else:
            y = y.values
    Y = np.asarray(y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.ndim != 2 or Y.shape[0] < 1:
        raise DataError(f"measurements y must be (T, p), got shape {np.shape(y)}")
    if not np.all(np.isfinite(Y)):
        i, j = np.argwhere(~np.isfinite(Y))[0]
        raise DataError(f"measurements y have NaN/inf at sample {i}, channel {j}")
    T, M = Y.shape
    if nominal is None:
        nominal = getattr(simulator, "params", None)
        if nominal is None:
            raise DataError("give `nominal` (the full parameter dictionary): the simulator has no .params")
    base = {k: float(v) for k, v in nominal.items()}
    names = tuple(names)
    if len(names) == 0:
        raise DataError("names is empty: choose at least one parameter to estimate")
    if len(set(names)) != len(names):
        raise DataError(f"duplicated parameter names in {list(names)}")
    unknown = [k for k in names if k not in base]
    if unknown:
        raise ModelError(f"unknown parameter(s) {unknown}; parameters: {sorted(base)}")
    n = len(names)
    for what, d in (("theta0", theta0), ("bounds", bounds)):
        extra = [k for k in (d or {}) if k not in names]
        if extra:
            raise ModelError(f"{what} names parameter(s) {extra} that are not estimated ({list(names)})")
    lo = np.full(n, -np.inf)
    hi = np.full(n, np.inf)
    for j, k in enumerate(names):
        if bounds and k in bounds:
            b = bounds[k]
            if np.shape(b) != (2,):
                raise DataError(f"bounds[{k!r}] must be a pair (lo, hi), got {b!r}")
            lo[j], hi[j] = float(b[0]), float(b[1])
            if np.isnan(lo[j]) or np.isnan(hi[j]) or not lo[j] < hi[j]:
                raise DataError(f"bounds[{k!r}] = ({lo[j]:g}, {hi[j]:g}) needs lo < hi")
    x0 = np.array([float((theta0 or {}).get(k, base[k])) for k in names])
    for j, k in enumerate(names):
        if not np.isfinite(x0[j]):
            raise DataError(f"start value of {k!r} is not finite: {x0[j]}")
        if not lo[j] <= x0[j] <= hi[j]:
            raise DataError(f"start value {k} = {x0[j]:g} lies outside its bounds [{lo[j]:g}, {hi[j]:g}]")
    # scaled coordinates z = theta / s, s = |nominal| (1 for zero): all unknowns O(1)
    s = np.array([abs(base[k]) if base[k] != 0 else 1.0 for k in names])
    W = _weight_root(weight, T, M)
    batch = getattr(simulator, "batch", None)
    counts = {"nfev": 0, "njev": 0}
    best = {"cost": np.inf, "z": None}

    def params_at(theta: np.ndarray) -> dict[str, float]:
        p = dict(base)
        p.update({k: float(v) for k, v in zip(names, theta)})
        return p

    def check(out: Any, what: str) -> np.ndarray:
        out = np.asarray(out, dtype=float)
        if out.ndim == 1 and M == 1:
            out = out[:, None]
        if out.shape != (T, M):
            raise DataError(f"simulator returned shape {out.shape} at {what}, but y is {(T, M)}")
        if not np.all(np.isfinite(out)):
            i, j = np.argwhere(~np.isfinite(out))[0]
            raise DataError(f"simulator returned NaN/inf at sample {i}, channel {j} for {what}")
        return out

    def resid_of(yhat: np.ndarray) -> np.ndarray:
        e = Y - yhat  # eq. (43)
        if W.ndim == 2:
            return (e @ W.T).ravel()  # weighted so that ||.||^2 / 2 = eq. (45)
        return np.einsum("tij,tj->ti", W, e).ravel()

    def fun(z: np.ndarray) -> np.ndarray:
        th = z * s
        counts["nfev"] += 1
        r = resid_of(check(simulator(params_at(th)), f"{dict(zip(names, th))}"))
        c = 0.5 * float(r @ r)
        if c < best["cost"]:
            best["cost"], best["z"] = c, z.copy()
        if cost_threshold is not None and c < cost_threshold:
            raise _Stop
        return r

    h_rel = float(diff_step) if diff_step is not None else float(np.sqrt(np.finfo(float).eps))
    zlo, zhi = lo / s, hi / s

    def jac(z: np.ndarray, r0: np.ndarray | None = None) -> np.ndarray:
        counts["njev"] += 1
        if r0 is None:
            r0 = fun(z)
        h = h_rel * np.maximum(np.abs(z), 1e-3)
        zs = []
        for j in range(n):
            zj = z.copy()
            step = h[j] if z[j] + h[j] <= zhi[j] else -h[j]  # stay inside the bounds
            zj[j] += step
            zs.append((zj, step))
        if batch is not None:
            outs = np.asarray(batch([params_at(zj * s) for zj, _ in zs]), dtype=float)
            if outs.shape[0] != n:
                raise DataError(f"simulator.batch returned {outs.shape[0]} records for {n} parameter sets")
            rs = [resid_of(check(outs[j], f"Jacobian column {names[j]}")) for j in range(n)]
        else:
            rs = [resid_of(check(simulator(params_at(zj * s)), f"Jacobian column {names[j]}"))
                  for j, (zj, _) in enumerate(zs)]
        J = np.empty((r0.size, n))
        for j, ((_, step), rj) in enumerate(zip(zs, rs)):
            J[:, j] = (rj - r0) / step
        return J

    last: dict[str, Any] = {}

    def fun_cached(z):
        r = fun(z)
        last["z"], last["r"] = z.copy(), r
        return r

    def jac_cached(z):
        r0 = last["r"] if ("z" in last and np.array_equal(last["z"], z)) else None
        return jac(z, r0)

    z0 = x0 / s
    status, message, stopped = 0, "", False
    try:
        if scan and scan > 0:
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
                raise DataError("scan needs finite bounds for every estimated parameter")
            if int(scan) ** n > 20000:
                raise DataError(f"scan grid of {int(scan)}^{n} points is too large (max 20000)")
            axes = [np.linspace(zlo[j], zhi[j], int(scan)) for j in range(n)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, n)
            grid = np.vstack([z0, grid])
            if batch is not None:
                for a in range(0, grid.shape[0], 64):
                    chunk = grid[a:a + 64]
                    outs = np.asarray(batch([params_at(z * s) for z in chunk]), dtype=float)
                    counts["nfev"] += len(chunk)
                    for z, o in zip(chunk, outs):
                        r = resid_of(check(o, "scan"))
                        c = 0.5 * float(r @ r)
                        if c < best["cost"]:
                            best["cost"], best["z"] = c, z.copy()
            else:
                for z in grid:
                    fun(z)
            z0 = best["z"].copy()
        # strictly inside the bounds for TRF
        with np.errstate(invalid="ignore"):  # inf bounds stay inf
            pad_lo = np.where(np.isfinite(zlo), 1e-10 * np.maximum(1.0, np.abs(zlo)), 0.0)
            pad_hi = np.where(np.isfinite(zhi), 1e-10 * np.maximum(1.0, np.abs(zhi)), 0.0)
        z0 = np.clip(z0, zlo + pad_lo, zhi - pad_hi)
        sol = least_squares(fun_cached, z0, jac=jac_cached, bounds=(zlo, zhi), method="trf",
                            x_scale=1.0, ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev)
        status, message = int(sol.status), str(sol.message)
    except _Stop:
        stopped = True
        status, message = 5, f"V_N below cost_threshold {cost_threshold:g}"
    z_hat = best["z"]
    theta0_used = dict(zip(names, (z0 * s).tolist()))
    th = z_hat * s
    r = resid_of(check(simulator(params_at(th)), "the estimate"))
    cost = 0.5 * float(r @ r)
    J = jac(z_hat, r) / s[None, :]  # d r / d theta of the weighted residual vector
    JtJ = J.T @ J
    dof = max(T * M - n, 1)
    s2 = 2.0 * cost / dof
    try:
        cov = s2 * np.linalg.inv(JtJ)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        if np.linalg.cond(JtJ) > 1e14:
            std = np.full(n, np.nan)
    except np.linalg.LinAlgError:
        std = np.full(n, np.nan)
    at_bound = {k: bool(np.isclose(th[j], lo[j], rtol=1e-9, atol=0) or np.isclose(th[j], hi[j], rtol=1e-9,
                                                                                    atol=0))
                for j, k in enumerate(names)}
    return OutputErrorResult(
        names=names, theta=dict(zip(names, th.tolist())), theta0=theta0_used, params=params_at(th),
        cost=cost, rms=float(np.sqrt(2.0 * cost / (T * M))), std=dict(zip(names, std.tolist())), jac=J,
        at_bound=at_bound, nfev=counts["nfev"], njev=counts["njev"], status=status, message=message,
        success=stopped or status > 0, elapsed=time.perf_counter() - t_start)


def output_error_covariance(y_runs: Any, y_hat: Any, *, floor: float = 0.0) -> np.ndarray:
    """Per-sample output-error covariance ``Lambda(i) = mean_runs r r'`` from a calibration Monte Carlo.

    ``r(i) = y(i) - y_hat(i)`` for noisy records ``y_runs`` of a known (e.g. nominal) system and
    its noise-free re-simulation ``y_hat``. Used as ``weight`` of :func:`output_error` it is the
    Gaussian maximum-likelihood weighting of eq. (45) for errors independent across samples
    (process noise makes them correlated in time, so this is a heuristic there).

    Parameters
    ----------
    y_runs : array_like (R, T, p)
        Calibration records (R >= 2).
    y_hat : array_like (T, p)
        Noise-free outputs of the same system.
    floor : float
        Added to the diagonal (e.g. the measurement-noise variance), keeps ``Lambda(i)``
        positive definite where all runs agree (a car at rest).

    Returns
    -------
    ndarray (T, p, p)

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.estimate.output_error import output_error_covariance
    >>> L = output_error_covariance(np.random.default_rng(0).normal(size=(4000, 3, 1)), np.zeros((3, 1)))
    >>> L.shape, bool(np.all(np.abs(L - 1.0) < 0.1))
    ((3, 1, 1), True)
    """
    Y = np.asarray(getattr(y_runs, "values", y_runs), dtype=float)
    Yh = np.asarray(y_hat, dtype=float)
    if Y.ndim != 3 or Y.shape[0] < 2 or Yh.shape != Y.shape[1:]:
        raise DataError(f"y_runs must be (R >= 2, T, p) and y_hat (T, p); got {Y.shape} and {Yh.shape}")
    r = Y - Yh[None]
    L = np.einsum("rti,rtj->tij", r, r) / Y.shape[0]
    return L + float(floor) * np.eye(Y.shape[2])[None]


# --------------------------------------------------------------------------------------------
# Table VI
