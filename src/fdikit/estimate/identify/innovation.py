"""The innovation model of an identified system: the steady-state Kalman gain from the noise
covariances, one-step-ahead prediction, and the whiteness (Ljung-Box) test of the innovations.

The model ``x[k+1] = A x + B u + w``, ``y = C x + D u + v`` with ``cov([w; v]) = [[Q, S], [S', R]]``
has the innovation form ``x[k+1] = A x + B u + K e``, ``y = C x + D u + e``, ``cov(e) = C P C' + R``,
with ``P`` the stabilising solution of the filter Riccati equation and the predictor gain
``K = (A P C' + S)(C P C' + R)^-1``. The one-step-ahead predictor
``x^[k+1] = (A - K C) x^ + (B - K D) u + K y`` gives the innovations ``e = y - C x^ - D u``; they are
white when the model is right (the Kalman residual of a fault detector).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["kalman_gain", "ljung_box", "predict_one_step"]


def kalman_gain(A: Any, C: Any, Q: Any, R: Any, S: Any) -> tuple[np.ndarray, np.ndarray, str]:
    """Predictor gain ``K`` (n, p) and innovation covariance (p, p) of the noise covariances.

    The stabilising Riccati solution when it exists (``method = "riccati"``); else, for a model
    whose states are Kalman states already (N4SID), ``K = S R^-1`` and ``cov(e) = R``
    (``method = "residuals"``).

    Examples
    --------
    >>> K, Re, how = kalman_gain([[0.9]], [[1.0]], [[1.0]], [[1.0]], [[0.0]])
    >>> round(float(K[0, 0]), 4), round(float(Re[0, 0]), 4), how
    (0.5377, 2.4839, 'riccati')
    """
    import scipy.linalg as sla

    A, C, Q, R, S = (np.atleast_2d(np.asarray(M, float)) for M in (A, C, Q, R, S))
    try:
        with np.errstate(all="ignore"):
            P = sla.solve_discrete_are(A.T, C.T, Q, R, s=S)
        Re = C @ P @ C.T + R
        K = np.linalg.solve(Re.T, (A @ P @ C.T + S).T).T
        rho = np.max(np.abs(np.linalg.eigvals(A - K @ C))) if A.size else 0.0
        if np.all(np.isfinite(K)) and rho < 1.0:
            return K, 0.5 * (Re + Re.T), "riccati"
    except (np.linalg.LinAlgError, ValueError):
        pass
    K = np.linalg.lstsq(R.T, S.T, rcond=None)[0].T
    return K, R.copy(), "residuals"


def predict_one_step(A: Any, B: Any, C: Any, D: Any, K: Any, u: Any, y: Any, *,
                     estimate_x0: bool = True) -> np.ndarray:
    """One-step-ahead predictions ``y^[k|k-1]`` (T, p) of outputs ``y`` (T, p) from inputs ``u`` (T, m).

    With ``estimate_x0`` the initial state is the least-squares fit of the prediction to ``y`` (the
    predictor's free response is ``C (A - K C)^k x0``); otherwise ``x0 = 0``.

    Examples
    --------
    >>> import numpy as np
    >>> y = np.array([[1.0], [2.0], [3.0]])          # a random walk: the prediction is the last output
    >>> predict_one_step([[1.0]], [[0.0]], [[1.0]], [[0.0]], [[1.0]], np.zeros((3, 1)), y,
    ...                  estimate_x0=False).ravel().tolist()
    [0.0, 1.0, 2.0]
    """
    A, C, K = (np.atleast_2d(np.asarray(M, float)) for M in (A, C, K))
    y = np.asarray(y, float).reshape(len(y), -1)
    T, p = y.shape
    n = A.shape[0]
    u = np.asarray(u, float).reshape(T, -1)
    B = np.asarray(B, float).reshape(n, u.shape[1])
    D = np.asarray(D, float).reshape(p, u.shape[1])
    Ap, Bp = A - K @ C, B - K @ D
    x = np.zeros(n)
    yh = np.empty((T, p))
    for k in range(T):
        yh[k] = C @ x + D @ u[k]
        x = Ap @ x + Bp @ u[k] + K @ y[k]
    if estimate_x0 and n:
        O = np.empty((T, p, n))
        O[0] = C
        for k in range(1, T):
            O[k] = O[k - 1] @ Ap                                 # C (A - K C)^k
        x0 = np.linalg.lstsq(O.reshape(-1, n), (y - yh).ravel(), rcond=None)[0]
        yh = yh + O @ x0
    return yh


def ljung_box(e: Any, lags: int = 20, *, dof: int = 0) -> dict[str, np.ndarray]:
    """Ljung-Box portmanteau test of whiteness of each channel of ``e`` (T, p).

    ``Q = T (T + 2) sum_{k=1..h} rho_k^2 / (T - k)``, chi-squared with ``h - dof`` degrees of freedom
    under whiteness (Ljung & Box, 1978).

    Returns
    -------
    dict
        ``statistic`` (p,), ``pvalue`` (p,), ``lags``.

    Examples
    --------
    >>> import numpy as np
    >>> r = ljung_box(np.random.default_rng(0).normal(size=(2000, 1)), 10)
    >>> bool(r["pvalue"][0] > 0.05)
    True
    """
    from scipy.stats import chi2

    e = np.asarray(e, float)
    e = e[:, None] if e.ndim == 1 else e
    T = e.shape[0]
    h = int(lags)
    x = e - e.mean(axis=0)
    den = np.sum(x * x, axis=0)
    rho = np.array([np.sum(x[k:] * x[:-k], axis=0) / den for k in range(1, h + 1)])    # (h, p)
    Qs = T * (T + 2) * np.sum(rho ** 2 / (T - np.arange(1, h + 1))[:, None], axis=0)
    return {"statistic": Qs, "pvalue": chi2.sf(Qs, max(h - dof, 1)), "lags": h}
