"""No model? Identify one: linear state-space models from nominal logs.

:func:`identify` fits a discrete :class:`~fdikit.model.LinearFaultModel` to a record of named inputs
and outputs, so that the model-based designs (fault detection filters, residual banks) apply to a
system known only from data:

* ``method="n4sid"``: subspace identification (N4SID / PO-MOESP of Verhaegen & Verdult, via the
  maintained ``nfoursid`` package); the singular values of the projected Hankel matrix are kept for
  order selection;
* ``method="arx"``: an ARX model ``y[k] = sum_i A_i y[k-i] + sum_i B_i u[k-i] + e[k]`` fitted by
  linear least squares, realised in state space with the past outputs and inputs as states.

The record is split in time: the first part estimates, the held-out last part validates. The order
is chosen on the validation data: the smallest order whose mean fit is within ``order_tol``
percentage points of the best (parsimony). The fit of each output is the simulation fit

    fit % = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)

of the model run from the measured inputs alone (free run; initial state estimated by least squares
from the validation record), the figure of MATLAB's ``compare``. The data are taken as deviations from
the means of the estimation part (the operating point); the offsets are in ``info`` and must be
removed from signals fed to a design made on the identified model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import DataError, ModelError
from ..model.linear import LinearFaultModel
from ..signals import Signals

__all__ = ["Identification", "fit_percent", "identify", "simulate_free"]


@dataclass
class Identification:
    """What :func:`identify` returns: the model and its info record (unpacks as ``model, info``).

    Attributes
    ----------
    model : LinearFaultModel
        Discrete (``dt`` of the record), inputs and outputs named as in the record, in deviation
        variables (``info["u_offset"]``, ``info["y_offset"]``).
    info : dict
        ``method``, ``order``, ``orders_tried`` with the validation ``fit`` (%, per output) of each,
        ``fit`` of the chosen order per output, ``singular_values`` (N4SID), ``block_rows`` or ``lags``,
        ``estimation_samples``, ``validation_samples``, ``u_offset``, ``y_offset``, ``spectral_radius``,
        ``noise_covariance`` (innovation covariance estimate of the chosen model on the estimation data).
    """

    model: LinearFaultModel
    info: dict[str, Any] = field(default_factory=dict)

    def __iter__(self):
        return iter((self.model, self.info))

    @property
    def fit(self) -> dict[str, float]:
        """Validation fit % per output of the chosen model."""
        return dict(self.info["fit"])


def fit_percent(y: Any, y_hat: Any) -> np.ndarray:
    """Fit % per channel, ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` over time, shape (p,).

    Examples
    --------
    >>> import numpy as np
    >>> y = np.c_[np.sin(np.arange(100.0))]
    >>> fit_percent(y, y).tolist(), fit_percent(y, 0 * y + y.mean()).tolist()
    ([100.0], [0.0])
    """
    y, y_hat = np.asarray(y, float), np.asarray(y_hat, float)
    if y.ndim == 1:
        y, y_hat = y[:, None], y_hat[:, None]
    if y.shape != y_hat.shape:
        raise DataError(f"y {y.shape} and y_hat {y_hat.shape} differ in shape")
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
    num = np.linalg.norm(y - y_hat, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, 100.0 * (1.0 - num / den), np.where(num > 0, -np.inf, 100.0))


def simulate_free(A: Any, B: Any, C: Any, D: Any, u: Any, *, estimate_x0: Any = None) -> np.ndarray:
    """Free-run response (T, p) of ``x[k+1] = A x + B u``, ``y = C x + D u`` to inputs ``u`` (T, m).

    With ``estimate_x0`` = measured outputs (T, p), the initial state is the least-squares fit of the
    free response to them (``y - y_zero_state = O x0``); otherwise ``x0 = 0``.

    Examples
    --------
    >>> import numpy as np
    >>> simulate_free([[0.5]], [[1.0]], [[1.0]], [[0.0]], np.ones((3, 1))).ravel().tolist()
    [0.0, 1.0, 1.5]
    """
    A, B, C, D = (np.atleast_2d(np.asarray(M, float)) for M in (A, B, C, D))
    u = np.asarray(u, float)
    u = u[:, None] if u.ndim == 1 else u
    T, n = u.shape[0], A.shape[0]
    x = np.zeros(n)
    y = np.empty((T, C.shape[0]))
    for k in range(T):
        y[k] = C @ x + D @ u[k]
        x = A @ x + B @ u[k]
    if estimate_x0 is not None and n:
        ym = np.asarray(estimate_x0, float).reshape(T, -1)
        O = np.empty((T, C.shape[0], n))
        M = np.eye(n)
        for k in range(T):
            O[k] = C @ M
            M = A @ M
        x0 = np.linalg.lstsq(O.reshape(-1, n), (ym - y).ravel(), rcond=None)[0]
        y = y + (O @ x0)
    return y


def _n4sid(u: np.ndarray, y: np.ndarray, orders: list[int], block_rows: int):
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    cu = [f"u{i}" for i in range(u.shape[1])]
    cy = [f"y{i}" for i in range(y.shape[1])]
    df = pd.DataFrame(np.hstack([u, y]), columns=cu + cy)
    sid = NFourSID(df, output_columns=cy, input_columns=cu, num_block_rows=block_rows)
    sid.subspace_identification()
    sv = np.diag(sid.R32_decomposition.eigenvalues).copy()
    # nfoursid 1.0 recomputes a full SVD (N x N right factor) of the observability estimate for every
    # order; its singular vectors do not depend on the order, so one economy SVD serves all orders
    # (same arithmetic as NFourSID.system_identification, which reduces this decomposition to the rank)
    from nfoursid.utils import Decomposition, Utils

    uh = Utils.block_hankel_matrix(sid.u_array, sid.num_block_rows)
    yh = Utils.block_hankel_matrix(sid.y_array, sid.num_block_rows)
    obs = sid.R32 @ np.linalg.pinv(sid.R22) @ np.concatenate([uh, yh])
    U, s, Vh = np.linalg.svd(obs, full_matrices=False)
    models = {}
    for n in orders:
        sid.x_dim = n
        ss, cov = sid._identify_state_space(Decomposition(U[:, :n], np.diag(s[:n]), Vh[:n]))
        models[n] = (ss.a, ss.b, ss.c, ss.d, cov[: y.shape[1], : y.shape[1]])
    return models, sv


def _arx(u: np.ndarray, y: np.ndarray, lags: int):
    """ARX(lags, lags) by least squares, realised with states [y[k-1..k-na]; u[k-1..k-nb]]."""
    T, p = y.shape
    m = u.shape[1]
    L = lags
    rows = []
    for k in range(L, T):
        rows.append(np.concatenate([y[k - L:k][::-1].ravel(), u[k - L:k][::-1].ravel()]))
    Phi = np.asarray(rows)
    Y = y[L:]
    Theta, *_ = np.linalg.lstsq(Phi, Y, rcond=None)            # (L p + L m, p)
    E = Y - Phi @ Theta
    n = L * (p + m)
    A = np.zeros((n, n))
    B = np.zeros((n, m))
    C = Theta.T.copy()                                          # y[k] = C x[k]
    ny = L * p
    A[:p] = C                                                   # new y[k] enters at the top
    A[p:ny, : ny - p] = np.eye(ny - p)                          # shift the past outputs
    if L > 1:
        A[ny + m:, ny: n - m] = np.eye(n - ny - m)              # shift the past inputs
    B[ny: ny + m] = np.eye(m)                                   # u[k] becomes u[k-1] of x[k+1]
    return A, B, C, np.zeros((p, m)), E.T @ E / max(E.shape[0], 1)


def identify(
    data: Signals,
    inputs: Sequence[str],
    outputs: Sequence[str],
    *,
    method: str = "n4sid",
    order: int | None = None,
    orders: Sequence[int] | None = None,
    block_rows: int | None = None,
    validation: float = 0.3,
    order_tol: float = 1.0,
    run: int = 0,
    name: str = "identified",
) -> Identification:
    """Fit a discrete linear state-space model to a nominal record (see the module docstring).

    Parameters
    ----------
    data : Signals
        A uniformly sampled record with the input and output channels (one run is used).
    inputs, outputs : sequence of str
        Channel names of the known inputs ``u`` and the measured outputs ``y``.
    method : {"n4sid", "arx"}
    order : int, optional
        Fixed model order (N4SID states, or ARX lags). Default: chosen from ``orders``.
    orders : sequence of int, optional
        Candidates (default ``1 .. min(10, block_rows * p)`` for N4SID, ``1 .. 6`` lags for ARX).
    block_rows : int, optional
        Block rows of the N4SID Hankel matrices (default ``max(10, 2 * max order // p + 1)``).
    validation : float
        Fraction of the record (the last part, time order kept) held out for validation, in (0, 1).
    order_tol : float
        Percentage points of mean validation fit within which the smallest order is preferred.
    run : int
        Which run of ``data``.
    name : str
        Model name.

    Returns
    -------
    Identification
        ``model`` (LinearFaultModel, discrete, named inputs and outputs, deviation variables) and
        ``info`` (fit % per output on the held-out data, order selection, offsets, singular values).

    Raises
    ------
    DataError
        Unknown channels, non-uniform sampling, NaN, too few samples for the orders.

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
    >>> model, info = identify(sig, ["u"], ["y"], method="arx")
    >>> info["order"], info["fit"]["y"] > 99.0, model.dt
    (1, True, 0.1)
    """
    if not isinstance(data, Signals):
        raise DataError(f"data must be fdikit.Signals, got {type(data).__name__}")
    inputs, outputs = [str(s) for s in inputs], [str(s) for s in outputs]
    if not outputs:
        raise DataError("identify needs at least one output channel")
    missing = [s for s in inputs + outputs if s not in data.names]
    if missing:
        raise DataError(f"channels {missing} are not in the record (channels: {data.names})")
    if method not in ("n4sid", "arx"):
        raise ModelError(f"method must be 'n4sid' or 'arx', got {method!r}")
    if not 0 < validation < 1:
        raise DataError(f"validation must be a fraction in (0, 1), got {validation}")
    if not 0 <= run < data.runs:
        raise DataError(f"run {run} does not exist (the record has {data.runs})")
    t = data.t
    if t.size < 3:
        raise DataError(f"the record has {t.size} samples; identification needs many more")
    dts = np.diff(t)
    dt = float(f"{float(np.median(dts)):.12g}")     # 0.1, not 0.10000000000000142
    if np.max(np.abs(dts - dt)) > 1e-6 * dt:
        k = int(np.argmax(np.abs(dts - dt))) + 1
        raise DataError(f"the record is not uniformly sampled (sample {k}: step {dts[k - 1]:g} s, "
                        f"median {dt:g} s)")
    u_all = data.values[run][:, data.index(inputs)] if inputs else np.zeros((t.size, 0))
    y_all = data.values[run][:, data.index(outputs)]
    for arr, names in ((u_all, inputs), (y_all, outputs)):
        bad = ~np.isfinite(arr)
        if bad.any():
            k, c = map(int, np.argwhere(bad)[0])
            raise DataError(f"channel {names[c]!r} is not finite at sample {k}: flag or cut bad samples "
                            "first")
    T = t.size
    Te = round(T * (1 - validation))
    if Te < 20 or T - Te < 20:
        raise DataError(f"{T} samples split {Te} / {T - Te} (estimation / validation); need >= 20 each")
    u_off, y_off = u_all[:Te].mean(axis=0), y_all[:Te].mean(axis=0)
    u, y = u_all - u_off, y_all - y_off
    ue, ye, uv, yv = u[:Te], y[:Te], u[Te:], y[Te:]
    p, m = y.shape[1], u.shape[1]
    info: dict[str, Any] = {"method": method, "estimation_samples": Te, "validation_samples": T - Te,
                            "u_offset": dict(zip(inputs, u_off.tolist())),
                            "y_offset": dict(zip(outputs, y_off.tolist())), "dt": dt}
    if method == "n4sid":
        cand = [int(order)] if order is not None else list(orders or [])
        if not cand:
            cand = list(range(1, 11))
        i = int(block_rows) if block_rows is not None else max(10, 2 * max(cand) // p + 1)
        cand = [n for n in cand if 1 <= n <= i * p]
        if not cand:
            raise DataError(f"no candidate order fits block_rows {i} x {p} outputs")
        if Te < 4 * i * (p + m) + 10:
            raise DataError(f"{Te} estimation samples are too few for {i} block rows and {p + m} channels")
        models, sv = _n4sid(ue, ye, cand, i)
        info.update(block_rows=i, singular_values=sv.tolist())
    else:
        cand = [int(order)] if order is not None else list(orders or range(1, 7))
        if any(n < 1 for n in cand):
            raise DataError(f"ARX lags must be >= 1, got {cand}")
        models = {n: _arx(ue, ye, n) for n in cand}
        info.update(lags=None)
    tried = {}
    for n, (A, B, C, D, _) in models.items():
        rho = float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
        if not np.all(np.isfinite(A)) or rho >= 1.0 + 1e-9:
            tried[n] = {"fit": None, "spectral_radius": rho, "rejected": "unstable or not finite"}
            continue
        yh = simulate_free(A, B, C, D, uv, estimate_x0=yv)
        fit = fit_percent(yv, yh)
        tried[n] = {"fit": dict(zip(outputs, fit.tolist())), "mean_fit": float(np.mean(fit)),
                    "spectral_radius": rho}
    ok = {n: v for n, v in tried.items() if v["fit"] is not None}
    if not ok:
        raise DataError(f"every candidate model is unstable on the record: {tried}")
    best = max(v["mean_fit"] for v in ok.values())
    chosen = min(n for n, v in ok.items() if v["mean_fit"] >= best - order_tol)
    A, B, C, D, cov = models[chosen]
    info.update(order=chosen, orders_tried=tried, fit=tried[chosen]["fit"],
                spectral_radius=tried[chosen]["spectral_radius"], noise_covariance=np.asarray(cov).tolist())
    if method == "arx":
        info["lags"] = chosen
    model = LinearFaultModel(A, B if m else np.zeros((A.shape[0], 0)), C, D if m else None, dt=dt,
                             inputs=inputs, outputs=outputs, states=[f"x{k}" for k in range(A.shape[0])],
                             name=name)
    return Identification(model, info)
