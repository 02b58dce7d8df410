"""Identify a model: :func:`identify` fits, scores and selects the innovation model of one or many
records, and returns it as an :class:`Identification`.

Every candidate order is fitted on the pooled estimation data (N4SID or ARX), completed to its
innovation form (Kalman gain ``K`` from ``Q``, ``R``, ``S``), and scored by its one-step-ahead
prediction of the held-out data, its free-run simulation of them, and the information criteria
(AIC, BIC) of its innovations on the estimation data; the criterion chosen selects the order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import DataError, ModelError
from ...model.linear import LinearFaultModel
from .arx import arx_pooled
from .fit import fit_percent, simulate_free
from .innovation import kalman_gain, predict_one_step
from .n4sid import block_rows_fit, n4sid_pooled, samples_needed
from .records import Segment, as_records, split_records

__all__ = ["CRITERIA", "Identification", "identify"]

#: Order-selection criteria of :func:`identify`.
CRITERIA = ("bic", "aic", "prediction", "simulation")
#: ARX ridge weights tried in turn by ``regularization="auto"``.
RIDGE_GRID = (0.0, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)


@dataclass
class Identification:
    """What :func:`identify` returns: the model, its innovation form and its info record (unpacks as
    ``model, info``).

    Attributes
    ----------
    model : LinearFaultModel
        Discrete (``dt`` of the records), inputs and outputs named as in the records, in deviation
        variables (``info["u_offset"]``, ``info["y_offset"]``).
    info : dict
        ``method``, ``order``, ``criterion`` and ``order_scores`` (order -> score of the criterion),
        ``orders_tried`` (per order: held-out one-step-ahead ``fit`` per output, ``fit_free_run``,
        ``aic``, ``bic``, ``spectral_radius``), ``fit`` (held-out one-step-ahead fit % per output of
        the chosen order, pooled over the records), ``fit_per_record`` (record -> output -> fit %),
        ``fit_free_run``, ``singular_values`` (N4SID), ``block_rows`` or ``lags``, ``reduced_outputs``
        (principal components kept, or None), ``marginal_poles`` and ``integrators`` (poles on the
        unit circle the data support), ``kalman`` (how ``K`` was found), ``estimation_samples``,
        ``validation_samples``, ``records``, ``u_offset``, ``y_offset``, ``spectral_radius``,
        ``noise_covariance`` (``R``), ``innovation_covariance``.
    K : ndarray (n, p)
        Predictor (Kalman) gain of the innovation form ``x+ = A x + B u + K e``, ``y = C x + D u + e``.
    Q, R, S : ndarray
        Covariances of the process noise (n, n), measurement noise (p, p) and their cross term (n, p).
    Re : ndarray (p, p)
        Covariance of the innovations ``e``.
    """

    model: LinearFaultModel
    info: dict[str, Any] = field(default_factory=dict)
    K: np.ndarray | None = None
    Q: np.ndarray | None = None
    R: np.ndarray | None = None
    S: np.ndarray | None = None
    Re: np.ndarray | None = None

    def __iter__(self):
        return iter((self.model, self.info))

    @property
    def fit(self) -> dict[str, float]:
        """Held-out one-step-ahead fit % per output of the chosen model."""
        return dict(self.info["fit"])

    def _deviations(self, records: Any, run: int | None) -> list[Segment]:
        m = self.model
        segs, _ = as_records(records, m.inputs, m.outputs, run=run, dt=m.dt)
        u0 = np.array([self.info["u_offset"][k] for k in m.inputs]).reshape(-1)
        y0 = np.array([self.info["y_offset"][k] for k in m.outputs])
        return [Segment(s.u - u0, s.y - y0, s.record) for s in segs]

    def predict(self, records: Any, *, run: int | None = 0, estimate_x0: bool = True) -> list[np.ndarray]:
        """One-step-ahead output predictions (T, p), one array per record (offsets added back)."""
        m = self.model
        y0 = np.array([self.info["y_offset"][k] for k in m.outputs])
        return [predict_one_step(m.A, m.B, m.C, m.D, self.K, s.u, s.y, estimate_x0=estimate_x0) + y0
                for s in self._deviations(records, run)]

    def innovations(self, records: Any, *, run: int | None = 0,
                    estimate_x0: bool = False) -> list[np.ndarray]:
        """The innovations ``e = y - y^[k|k-1]`` (T, p) of the Kalman predictor on each record (the
        residual of a fault detector built on the identified model; white when the model is right).
        From ``x0 = 0`` by default: skip the first samples (the predictor's transient)."""
        m = self.model
        return [s.y - predict_one_step(m.A, m.B, m.C, m.D, self.K, s.u, s.y, estimate_x0=estimate_x0)
                for s in self._deviations(records, run)]

    def innovation_filter(self):
        """The Kalman residual generator as a :class:`~fdikit.residuals.FilterDesign`:
        ``x^+ = (A - K C) x^ + (B - K D) u + K y``, ``r = y - C x^ - D u`` (channels ``e:<output>``).
        It reads deviation variables: subtract ``info["u_offset"]`` and ``info["y_offset"]`` first."""
        from ...residuals import FilterDesign

        m = self.model
        A, B, C, D, K = m.A, m.B_of("u"), m.C, m.D_of("u"), self.K
        p = C.shape[0]
        return FilterDesign(A - K @ C, B - K @ D, K.copy(), -C, -D, np.eye(p), float(m.dt), list(m.inputs),
                            list(m.outputs), [f"e:{y}" for y in m.outputs],
                            {"method": "identified innovation (Kalman) predictor",
                             "innovation_covariance": self.Re})


def _pca(est: list[Segment], k: int):
    """Scale (p,), the k leading principal directions (p, k) of the scaled outputs, the covariance of
    the discarded part (p, p) and the variance fraction kept."""
    Y = np.concatenate([s.y for s in est])
    sd = Y.std(axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    Z = Y / sd
    cov = Z.T @ Z / Z.shape[0]
    w, V = np.linalg.eigh(cov)
    order = np.argsort(w)[::-1]
    w, V = w[order], V[:, order]
    P = V[:, :k]
    Pp = np.eye(len(sd)) - P @ P.T
    return sd, P, Pp @ cov @ Pp, float(w[:k].sum() / max(w.sum(), 1e-300))


def _lift(mod, sd, P, cov_perp):
    """A model of the principal components as a model of the (scaled back) outputs."""
    A, B, C, D, Q, R, S = mod
    Ds = np.diag(sd)
    return (A, B, Ds @ P @ C, Ds @ P @ D, Q, Ds @ (P @ R @ P.T + cov_perp) @ Ds, S @ P.T @ Ds)


def _free_run(A, B, C, D, val: list[Segment], Yv: np.ndarray, outputs: list[str]) -> dict[str, Any]:
    """Held-out free-run simulation fit (initial state fitted per record)."""
    with np.errstate(all="ignore"):
        ys = [simulate_free(A, B, C, D, s.u, estimate_x0=s.y) for s in val]
        fs = fit_percent(Yv, np.concatenate(ys))
    return {"fit_free_run": dict(zip(outputs, fs.tolist())),
            "mean_fit_free_run": float(np.mean(fs)) if np.all(np.isfinite(fs)) else -math.inf}


def _loglik_terms(E: np.ndarray, yvar: np.ndarray) -> float:
    """``N log det(E' E / N + 1e-10 diag(var y))`` of innovations E (N, p): the floor (far below any
    measured noise) makes exact fits of noiseless data tie, so the penalty decides between them."""
    N = E.shape[0]
    sign, logdet = np.linalg.slogdet(E.T @ E / N + np.diag(1e-10 * yvar))
    return float(N * logdet) if sign > 0 else -math.inf


def identify(
    records: Any,
    inputs: Sequence[str],
    outputs: Sequence[str],
    *,
    method: str = "n4sid",
    order: int | None = None,
    orders: Sequence[int] | None = None,
    criterion: str = "bic",
    block_rows: int | None = None,
    reduce_outputs: int | str | None = "auto",
    regularization: float | str = "auto",
    validation: float = 0.3,
    held_out: Any = None,
    order_tol: float = 1.0,
    marginal_tol: float = 1e-2,
    run: int | None = 0,
    dt: float | None = None,
    name: str = "identified",
) -> Identification:
    """Fit a discrete linear innovation model to nominal records (see the module docstring).

    Parameters
    ----------
    records : Signals, array (T, m + p), or a list of them
        One record, or many records / segments of any lengths (pooled without joining them end to
        end). Arrays hold the inputs then the outputs as columns.
    inputs, outputs : sequence of str
        Channel names of the known inputs ``u`` and the measured outputs ``y``.
    method : {"n4sid", "arx"}
    order : int, optional
        Fixed model order (N4SID states, or ARX lags). Default: selected from ``orders``.
    orders : sequence of int, optional
        Candidates (default ``1 .. 10`` states for N4SID, ``1 .. 6`` lags for ARX).
    criterion : {"bic", "aic", "prediction", "simulation"}
        Order selection: the smallest information criterion of the innovations on the estimation
        data (``N log det(cov e) + c k``, ``k`` the parameters, ``c = log N`` or 2), or the smallest
        order whose mean held-out fit (one-step-ahead ``"prediction"`` or free-run ``"simulation"``)
        is within ``order_tol`` percentage points of the best.
    block_rows : int, optional
        N4SID block rows (default ``max(10, 2 * max order // p + 1)``, fewer when the samples do not
        support them: the largest number that does).
    reduce_outputs : int, "auto" or None
        N4SID on the ``k`` leading principal components of the (standardised) outputs; ``"auto"``
        does so only when the samples cannot support enough block rows for all outputs.
    regularization : float or "auto"
        ARX ridge weight on the standardised regressors (0: least squares; see
        :func:`~fdikit.estimate.identify.arx.arx_pooled`); ``"auto"``: least squares unless its model
        is unstable beyond a marginal mode, else the smallest weight of ``RIDGE_GRID`` that is not
        (``info["regularization"]``: lags -> weight used).
    validation : float
        Fraction at the end of every record held out for validation, in (0, 1).
    held_out : records, optional
        Whole records that validate instead (then every record of ``records`` estimates).
    order_tol : float
        Percentage points of mean validation fit within which the smallest order is preferred.
    marginal_tol : float
        Poles with modulus up to ``1 + marginal_tol`` are accepted as marginal (integrators) and
        listed in ``info``; a candidate with a pole beyond is rejected.
    run : int or None
        Which run of a Signals (None: every run is a record).
    dt : float, optional
        Sample time of array records (s).
    name : str
        Model name.

    Returns
    -------
    Identification
        ``model`` (LinearFaultModel, discrete, named, deviation variables), the innovation form
        (``K``, ``Q``, ``R``, ``S``, ``Re``) and ``info`` (held-out fit per output and per record,
        the order curve, offsets, marginal poles).

    Raises
    ------
    DataError
        Unknown channels, non-uniform sampling, NaN, too few samples (naming the samples needed
        and the alternatives).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=600)
    >>> y = np.zeros(600)
    >>> for k in range(1, 600):
    ...     y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    >>> sig = Signals(np.arange(600) * 0.1, np.c_[u, y], ["u", "y"])
    >>> model, info = identify(sig, ["u"], ["y"], method="arx", criterion="prediction")
    >>> info["order"], info["fit"]["y"] > 99.0, model.dt
    (1, True, 0.1)
    >>> ident = identify([sig, sig], ["u"], ["y"], method="arx", order=1)    # many records
    >>> ident.K.shape, ident.info["records"]
    ((2, 1), 2)
    """
    inputs, outputs = [str(s) for s in inputs], [str(s) for s in outputs]
    if method not in ("n4sid", "arx"):
        raise ModelError(f"method must be 'n4sid' or 'arx', got {method!r}")
    if criterion not in CRITERIA:
        raise ModelError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    if held_out is None and not (isinstance(validation, int | float) and 0 < validation < 1):
        raise DataError(f"validation must be a fraction in (0, 1), got {validation}")
    segs, dt = as_records(records, inputs, outputs, run=run, dt=dt)
    held = None
    if held_out is not None:
        held, dt_h = as_records(held_out, inputs, outputs, run=run, dt=dt)
        if abs(dt_h - dt) > 1e-6 * dt:
            raise DataError(f"the held-out records are sampled every {dt_h} s, the records every {dt} s")
    est, val = split_records(segs, validation, held)
    nrec = len(est)
    Ue, Ye = np.concatenate([s.u for s in est]), np.concatenate([s.y for s in est])
    Ne = Ye.shape[0]
    u_off, y_off = Ue.mean(axis=0), Ye.mean(axis=0)
    est = [Segment(s.u - u_off, s.y - y_off, s.record) for s in est]
    val = [Segment(s.u - u_off, s.y - y_off, s.record) for s in val]
    p, m = len(outputs), len(inputs)
    info: dict[str, Any] = {"method": method, "estimation_samples": Ne,
                            "estimation_samples_per_record": [int(s.n) for s in est],
                            "validation_samples": int(sum(s.n for s in val)), "records": nrec,
                            "u_offset": dict(zip(inputs, u_off.tolist())),
                            "y_offset": dict(zip(outputs, y_off.tolist())), "dt": dt, "criterion": criterion,
                            "reduced_outputs": None}
    models: dict[int, tuple] = {}
    if method == "n4sid":
        cand = [int(order)] if order is not None else list(orders or [])
        if not cand:
            cand = list(range(1, 11))
        wanted = int(block_rows) if block_rows is not None else max(10, 2 * max(cand) // p + 1)
        k_out = p
        if isinstance(reduce_outputs, int) and not isinstance(reduce_outputs, bool):
            if not 1 <= reduce_outputs <= p:
                raise DataError(f"reduce_outputs must lie in 1 .. {p}, got {reduce_outputs}")
            k_out = int(reduce_outputs)
        elif reduce_outputs not in ("auto", None):
            raise DataError(f"reduce_outputs must be an integer, 'auto' or None, got {reduce_outputs!r}")
        if block_rows is not None:
            i = wanted
            if block_rows_fit(Ne, k_out + m, nrec, i) < i:
                raise DataError(f"{Ne} estimation samples are too few for {i} block rows and {k_out + m} "
                                f"channels: need {samples_needed(i, k_out + m, nrec)}; give fewer "
                                "block_rows (or none: chosen automatically)")
        else:
            i = block_rows_fit(Ne, k_out + m, nrec, wanted)
            i_min = max(1, -(-min(cand) // k_out))
            if i < i_min and reduce_outputs == "auto":
                for k in range(k_out - 1, 0, -1):
                    ik = block_rows_fit(Ne, k + m, nrec, wanted)
                    if ik >= max(1, -(-min(cand) // k)):
                        k_out, i = k, ik
                        break
            if i < max(1, -(-min(cand) // k_out)):
                raise DataError(f"{Ne} estimation samples are too few for N4SID on {p} outputs and {m} "
                                f"inputs: one block row needs {samples_needed(1, p + m, nrec)} (with "
                                f"{nrec} record(s)); give more or longer records, reduce_outputs='auto' "
                                "(principal components of the outputs), or method='arx'")
        cand = [n for n in cand if 1 <= n <= i * k_out]
        if not cand:
            raise DataError(f"no candidate order fits block_rows {i} x {k_out} outputs")
        if k_out < p:
            sd, P, cov_perp, kept = _pca(est, k_out)
            est_z = [Segment(s.u, (s.y / sd) @ P, s.record) for s in est]
            raw, sv = n4sid_pooled(est_z, cand, i)
            raw = {n: _lift(mod, sd, P, cov_perp) for n, mod in raw.items()}
            info["reduced_outputs"] = {"components": k_out, "variance_kept": kept}
        else:
            raw, sv = n4sid_pooled(est, cand, i)
        for n, (A, B, C, D, Q, R, S) in raw.items():
            if np.all(np.isfinite(A)) and np.all(np.isfinite(C)):
                K, Re, how = kalman_gain(A, C, Q, R, S)
            else:
                K, Re, how = np.zeros((n, p)), R, "not finite"
            models[n] = (A, B, C, D, Q, R, S, K, Re, how)
        info.update(block_rows=i, singular_values=sv.tolist())
    else:
        cand = [int(order)] if order is not None else list(orders or range(1, 7))
        if any(n < 1 for n in cand):
            raise DataError(f"ARX lags must be >= 1, got {cand}")
        ridge: dict[int, float] = {}
        for n in cand:
            grid = RIDGE_GRID if regularization == "auto" else [float(regularization)]
            for lam in grid:
                A, B, C, D, Q, R, S, K = arx_pooled(est, n, lam)
                # collinear channels (many outputs, few samples) make least squares unstable:
                # "auto" takes the smallest ridge weight whose model is stable up to a marginal mode
                if np.all(np.isfinite(A)) and np.max(np.abs(np.linalg.eigvals(A))) <= 1.0 + marginal_tol:
                    break
            ridge[n] = lam
            models[n] = (A, B, C, D, Q, R, S, K, R, "arx")
        info.update(lags=None, regularization=ridge)
    # ------------------------------------------------------------------ score every candidate
    tried: dict[int, dict[str, Any]] = {}
    Yv = np.concatenate([s.y for s in val])
    yvar = np.maximum(np.concatenate([s.y for s in est]).var(axis=0), 1e-300)
    warm = min(min(s.n for s in est) // 4, 2 * info.get("block_rows", max(models)) + 2)
    for n, (A, B, C, D, _q, _r, _s, K, _re, _how) in models.items():
        eig = np.linalg.eigvals(A) if A.size else np.zeros(0)
        rho = float(np.max(np.abs(eig))) if eig.size else 0.0
        rho_p = float(np.max(np.abs(np.linalg.eigvals(A - K @ C)))) if A.size else 0.0
        finite = np.all(np.isfinite(A)) and np.all(np.isfinite(K))
        if not finite or rho > 1.0 + marginal_tol or rho_p >= 1.0:
            tried[n] = {"fit": None, "spectral_radius": rho, "predictor_spectral_radius": rho_p,
                        "rejected": "unstable beyond a marginal mode, unstable predictor, or not finite"}
            continue
        yp = [predict_one_step(A, B, C, D, K, s.u, s.y) for s in val]
        fit = fit_percent(Yv, np.concatenate(yp))
        per_rec = {int(s.record): dict(zip(outputs, fit_percent(s.y, yh).tolist())) for s, yh in zip(val, yp)}
        # innovations on the estimation data from x0 = 0, past the predictor's start
        E = np.concatenate([(s.y - predict_one_step(A, B, C, D, K, s.u, s.y, estimate_x0=False))[warm:]
                            for s in est])
        npar = n * (2 * p + m) + p * m if method == "n4sid" else n * p * (p + m)
        ll = _loglik_terms(E, yvar)
        tried[n] = {"fit": dict(zip(outputs, fit.tolist())), "mean_fit": float(np.mean(fit)),
                    "fit_per_record": per_rec, "aic": ll + 2.0 * npar,
                    "bic": ll + math.log(E.shape[0]) * npar, "parameters": npar, "spectral_radius": rho,
                    "predictor_spectral_radius": rho_p}
        if criterion == "simulation":
            tried[n].update(_free_run(A, B, C, D, val, Yv, outputs))
    ok = {n: v for n, v in tried.items() if v["fit"] is not None}
    if not ok:
        raise DataError(f"every candidate model is unstable beyond a marginal mode (|pole| > 1 + "
                        f"{marginal_tol}) or has an unstable predictor: {tried}")
    if criterion in ("aic", "bic"):
        scores = {n: v[criterion] for n, v in ok.items()}
        chosen = min(scores, key=lambda n: (scores[n], n))
    else:
        key = "mean_fit" if criterion == "prediction" else "mean_fit_free_run"
        scores = {n: v[key] for n, v in ok.items()}
        best = max(scores.values())
        chosen = min(n for n, s in scores.items() if s >= best - order_tol)
    A, B, C, D, Q, R, S, K, Re, how = models[chosen]
    if "fit_free_run" not in tried[chosen]:
        tried[chosen].update(_free_run(A, B, C, D, val, Yv, outputs))
    eig = np.linalg.eigvals(A) if A.size else np.zeros(0)
    marginal = eig[np.abs(np.abs(eig) - 1.0) <= marginal_tol]
    info.update(order=chosen, orders_tried=tried, order_scores=scores, fit=tried[chosen]["fit"],
                fit_per_record=tried[chosen]["fit_per_record"], fit_free_run=tried[chosen]["fit_free_run"],
                spectral_radius=tried[chosen]["spectral_radius"], noise_covariance=np.asarray(R).tolist(),
                innovation_covariance=np.asarray(Re).tolist(), kalman=how,
                marginal_poles=[complex(z) if abs(z.imag) > 0 else float(z.real) for z in marginal],
                integrators=int(np.sum(np.abs(marginal - 1.0) <= marginal_tol)))
    if info["integrators"]:
        info["note"] = (f"{info['integrators']} pole(s) within {marginal_tol} of 1 (integrators) are kept: "
                        "the data show them; free-run simulation drifts, the Kalman predictor is stable")
    if method == "arx":
        info["lags"] = chosen
    model = LinearFaultModel(A, B if m else np.zeros((A.shape[0], 0)), C, D if m else None, dt=dt,
                             inputs=inputs, outputs=outputs, states=[f"x{k}" for k in range(A.shape[0])],
                             name=name)
    return Identification(model, info, K=np.asarray(K), Q=np.asarray(Q), R=np.asarray(R), S=np.asarray(S),
                          Re=np.asarray(Re))
