"""Exact zero-order-hold simulation of a linear plant, sampled (the design model that the SMO
self-check and the tests drive)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from ...errors import DataError
from .kernel import _mv
from .validation import _mat, _pos

__all__ = ["simulate_plant"]

def _lin_sim_py(Ad, Bd, C, U, x0, Y):
    runs, T = U.shape[0], U.shape[1]
    n = Ad.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    for run in range(runs):
        for i in range(n):
            x[i] = x0[run, i]
        for k in range(T):
            _mv(C, x, Y[run, k], False)
            _mv(Ad, x, xn, False)
            _mv(Bd, U[run, k], xn, True)
            for i in range(n):
                x[i] = xn[i]


_lin_sim = njit(cache=True)(_lin_sim_py)


def simulate_plant(A: Any, B: Any, C: Any, U: np.ndarray, h: float, x0: Any = None) -> np.ndarray:
    """Outputs of ``x' = A x + B w``, ``y = C x`` sampled every ``h`` s, ``w`` held over a step.

    The step uses the exact zero-order-hold discretisation (matrix exponential), so the plant
    itself carries no integration error; only the observers are integrated with Euler steps.

    Parameters
    ----------
    A : (n, n), B : (n, m), C : (p, n) array_like
    U : ndarray (runs, T, m) or (T, m)
        Inputs (here: faults, controls) at the sample times.
    h : float
        Step (s).
    x0 : array_like (runs, n) or (n,), optional
        Initial state (default zero).

    Returns
    -------
    ndarray (runs, T, p)
        ``y[k] = C x(k h)``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals.smo import simulate_plant
    >>> y = simulate_plant([[-1.0]], [[1.0]], [[1.0]], np.ones((1001, 1)), 1e-3)
    >>> abs(float(y[0, -1, 0]) - (1 - float(np.exp(-1.0)))) < 1e-12
    True
    """
    from scipy.linalg import expm

    A = _mat(A, (None, None), "A")
    n = A.shape[0]
    if A.shape != (n, n):
        raise DataError(f"A must be square, got shape {A.shape}")
    B = _mat(B, (n, None), "B")
    C = _mat(C, (None, n), "C")
    h = _pos(h, "h")
    U = np.asarray(U, float)
    if U.ndim == 2:
        U = U[None]
    m = B.shape[1]
    if U.ndim != 3 or U.shape[2] != m:
        raise DataError(f"U must have shape (runs, T, {m}) or (T, {m}), got {np.shape(U)}")
    if not np.all(np.isfinite(U)):
        raise DataError("U contains NaN or inf")
    E = expm(np.block([[A, B], [np.zeros((m, n + m))]]) * h)
    Ad, Bd = E[:n, :n], E[:n, n:]
    try:
        x0 = np.zeros((U.shape[0], n)) if x0 is None else np.broadcast_to(np.asarray(x0, float),
                                                                           (U.shape[0], n)).copy()
    except ValueError:
        raise DataError(f"x0 must have shape ({n},) or ({U.shape[0]}, {n}), got {np.shape(x0)}") from None
    Y = np.zeros((U.shape[0], U.shape[1], C.shape[0]))
    _lin_sim(np.ascontiguousarray(Ad), np.ascontiguousarray(Bd), np.ascontiguousarray(C),
             np.ascontiguousarray(U), x0, Y)
    return Y
