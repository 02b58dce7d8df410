"""Fit measures of an identified model: the fit % of a prediction and the free-run (simulation)
response of a state-space model to measured inputs."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DataError

__all__ = ["fit_percent", "simulate_free"]


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
