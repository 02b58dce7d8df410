"""ARX models by linear least squares, pooled over many records, realised in innovation form.

``y[k] = sum_i A_i y[k-i] + sum_i B_i u[k-i] + e[k]`` with ``lags`` past outputs and inputs. The
regressor rows of every record are built inside that record (no row reaches across the boundary of
two records) and stacked. The realisation takes the past outputs and inputs as states,
``x[k] = [y[k-1..k-L]; u[k-1..k-L]]``, so ``y = C x + e`` and the new output ``y[k] = C x + e``
enters the top of the next state: the innovation form has ``K = [I; 0]`` and the noise covariances
``R = cov(e)``, ``S = K R``, ``Q = K R K'``.
"""

from __future__ import annotations

import numpy as np

from .records import Segment

__all__ = ["arx_pooled", "arx_realise"]


def _rows(u: np.ndarray, y: np.ndarray, L: int) -> np.ndarray:
    rows = []
    for k in range(L, y.shape[0]):
        rows.append(np.concatenate([y[k - L:k][::-1].ravel(), u[k - L:k][::-1].ravel()]))
    return np.asarray(rows)


def arx_realise(Theta: np.ndarray, p: int, m: int, L: int):
    """``(A, B, C, D, K)`` of the ARX coefficients ``Theta`` (L p + L m, p) with states
    ``[y[k-1..k-L]; u[k-1..k-L]]``."""
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
    K = np.zeros((n, p))
    K[:p] = np.eye(p)                                           # e[k] enters with y[k]
    return A, B, C, np.zeros((p, m)), K


def arx_pooled(segs: list[Segment], lags: int, regularization: float = 0.0):
    """ARX(lags, lags) of the pooled records.

    Parameters
    ----------
    segs : list of Segment
    lags : int
    regularization : float
        Ridge weight ``lambda`` on the standardised regressors: with ``s_j`` the root mean square of
        regressor ``j``, the coefficients minimise ``||Y - Phi Theta||^2 + lambda N ||diag(s) Theta||^2``
        (``N`` rows); 0 is least squares.

    Returns
    -------
    tuple
        ``(A, B, C, D, Q, R, S, K)`` in innovation form (see the module docstring).
    """
    L = lags
    p, m = segs[0].y.shape[1], segs[0].u.shape[1]
    Phi = np.concatenate([_rows(s.u, s.y, L) for s in segs if s.n > L])
    Y = np.concatenate([s.y[L:] for s in segs if s.n > L])
    if regularization > 0:
        # ridge on the standardised regressors (unit mean square), so the weight means the same for
        # every channel whatever its unit
        sc = np.sqrt(np.mean(Phi * Phi, axis=0))
        sc = np.where(sc > 0, sc, 1.0)
        Ps = Phi / sc
        G = Ps.T @ Ps
        Theta = np.linalg.solve(G + regularization * Ps.shape[0] * np.eye(G.shape[0]), Ps.T @ Y) / sc[:, None]
    else:
        Theta, *_ = np.linalg.lstsq(Phi, Y, rcond=None)            # (L p + L m, p)
    E = Y - Phi @ Theta
    A, B, C, D, K = arx_realise(Theta, p, m, L)
    R = E.T @ E / max(E.shape[0], 1)
    S = K @ R
    return A, B, C, D, S @ K.T, R, S, K
