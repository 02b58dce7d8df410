"""Gain bounds of stable linear systems for the SMO design: the H-infinity norm (an independent
check of gamma-bar) and the peak-to-peak gains that size the switching gains."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ConditionError
from .validation import _mat, _norm2

__all__ = ["hinf_norm", "injection_peak_gains", "peak_gain"]

# ================================================================================ H-infinity norm
def hinf_norm(A: Any, B: Any, C: Any, D: Any, *, rtol: float = 1e-9, n_freq: int = 20000,
              w_range: tuple[float, float] = (1e-4, 1e4)) -> dict:
    """H-infinity norm of a stable continuous system, by two independent methods.

    * Hamiltonian bisection (Boyd, Balakrishnan & Kabamba 1989): ``gamma > ||G||_inf`` iff
      the Hamiltonian matrix of ``(A, B, C, D, gamma)`` has no eigenvalue on the imaginary axis;
    * a dense logarithmic frequency sweep of ``sigma_max(G(jw))`` (a lower bound).

    Parameters
    ----------
    A : (n, n), B : (n, m), C : (l, n), D : (l, m) array_like
        ``n = 0`` (a static gain ``G = D``) is allowed: ``A`` ``(0, 0)``, ``B`` ``(0, m)``,
        ``C`` ``(l, 0)`` (or empty arrays); the sizes ``l, m`` are then read from ``D``.
    rtol : float
        Relative accuracy of the bisection.
    n_freq : int
        Number of sweep frequencies in ``w_range`` (rad/s), plus ``w = 0``.

    Returns
    -------
    dict
        ``bisection`` (upper end of the final bracket), ``sweep`` (max over the grid),
        ``w_peak`` (rad/s, from the sweep). For a static gain both are ``||D||_2``.

    Examples
    --------
    >>> from fdikit.residuals.smo import hinf_norm
    >>> d = hinf_norm([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    >>> round(d["bisection"], 6), round(d["sweep"], 6)
    (1.0, 1.0)
    >>> hinf_norm(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), [[3.0, 4.0]])["bisection"]
    5.0
    """
    A = np.asarray(A, float)
    n = 0 if A.size == 0 else A.shape[0]
    A = A.reshape(n, n) if A.size == 0 else _mat(A, (n, n), "A")
    Dm = np.asarray(D, float)
    if n == 0:
        D = _mat(Dm, (None, None), "D")
        B = np.zeros((0, D.shape[1]))
        C = np.zeros((D.shape[0], 0))
    else:
        B = _mat(B, (n, None), "B")
        C = _mat(C, (None, n), "C")
        D = _mat(Dm.reshape(C.shape[0], B.shape[1]) if Dm.size == C.shape[0] * B.shape[1] else Dm,
                 (C.shape[0], B.shape[1]), "D")
    if n and np.linalg.eigvals(A).real.max() >= 0:
        raise ConditionError("stability", "H-infinity norm of an unstable system",
                             {"eigenvalues": np.linalg.eigvals(A)})
    w = np.r_[0.0, np.logspace(np.log10(w_range[0]), np.log10(w_range[1]), n_freq)]
    I = np.eye(n)
    sig = np.array([np.linalg.svd(C @ np.linalg.solve(1j * wk * I - A, B) + D, compute_uv=False)[0]
                    if n else np.linalg.norm(D, 2) for wk in w])
    sweep = float(sig.max())
    w_peak = float(w[int(sig.argmax())])
    if n == 0:
        return {"bisection": float(np.linalg.norm(D, 2)), "sweep": sweep, "w_peak": w_peak}

    def has_imag_eig(g: float) -> bool:
        R = g * g * np.eye(D.shape[1]) - D.T @ D
        S = g * g * np.eye(D.shape[0]) - D @ D.T
        Ri = np.linalg.inv(R)
        Ah = A + B @ Ri @ D.T @ C
        H = np.block([[Ah, B @ Ri @ B.T], [-C.T @ (g * g * np.linalg.inv(S)) @ C, -Ah.T]])
        ev = np.linalg.eigvals(H)
        return bool(np.any(np.abs(ev.real) < 1e-8 * max(1.0, np.abs(ev).max())))

    lo = max(sweep, float(np.linalg.norm(D, 2)))
    hi = max(2.0 * lo, 1e-12)
    while has_imag_eig(hi):
        hi *= 2.0
    lo = lo * (1.0 - 1e-12)
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if has_imag_eig(mid):
            lo = mid
        else:
            hi = mid
    return {"bisection": float(hi), "sweep": sweep, "w_peak": w_peak}


# ================================================================================ gain sizing
def peak_gain(A: Any, B: Any, C: Any, D: Any, *, max_steps: int = 200_000) -> float:
    """Upper bound of the peak-to-peak gain of a stable system (Euclidean norms at each instant).

    ``sup_t ||y(t)|| <= (||D||_2 + int_0^inf ||C e^(A t) B||_F dt) sup_t ||u(t)||`` for zero initial
    state; the integral is a trapezoid sum on a grid that starts at ``0.02 / max|lambda|`` and
    doubles every 64 steps (capped so that oscillatory modes stay resolved) up to
    ``40 / min(-Re lambda)``.

    Parameters
    ----------
    A : (n, n), B : (n, m), C : (l, n), D : (l, m) array_like
    max_steps : int
        Cap on the number of grid points.

    Returns
    -------
    float

    Examples
    --------
    >>> from fdikit.residuals.smo import peak_gain
    >>> round(peak_gain([[-2.0]], [[1.0]], [[1.0]], [[0.0]]), 4)  # int e^(-2t) dt = 0.5
    0.5
    """
    D = np.atleast_2d(np.asarray(D, float))
    d = _norm2(D)
    A = np.asarray(A, float)
    n = 0 if A.size == 0 else A.shape[0]
    if n == 0:
        return d
    A = A.reshape(n, n)
    B = np.asarray(B, float).reshape(n, -1)
    C = np.asarray(C, float).reshape(-1, n)
    if B.size == 0 or C.size == 0:
        return d
    from scipy.linalg import expm

    ev = np.linalg.eigvals(A)
    if ev.real.max() >= 0:
        raise ConditionError("stability", "peak gain of an unstable system", {"eigenvalues": ev})
    fast = float(np.abs(ev).max())
    slow = float(-ev.real.max())
    osc = float(np.abs(ev.imag).max())
    t_end = 40.0 / slow
    step = 0.02 / fast
    cap = 0.1 / osc if osc > 0 else np.inf
    t, total, count = 0.0, 0.0, 0
    X = B.copy()
    prev = float(np.linalg.norm(C @ X))
    while t < t_end and count < max_steps:
        Phi = expm(A * step)
        for _ in range(64):
            X = Phi @ X
            cur = float(np.linalg.norm(C @ X))
            total += 0.5 * step * (prev + cur)
            prev = cur
            t += step
            count += 1
            if t >= t_end or count >= max_steps:
                break
        step = min(2.0 * step, max(cap, step))
    return d + total


def injection_peak_gains(A: np.ndarray, M: np.ndarray, Q: np.ndarray, C: np.ndarray, L: np.ndarray,
                         Po: np.ndarray) -> tuple[float, float]:
    """Peak gains from the fault and from ``xi`` to an observer's equivalent injection ``nu_eq``.

    For an observer of ``(A, M, Q, C = [0 T])`` with gains ``L``, ``Po``
    (``G_n = [-L T^-1; T^-1] Po^-1``), an ideal sliding motion has
    ``e1' = (A1 + L A3) e1 - (M1 + L M2) f - (Q1 + L Q2) xi`` and
    ``nu_eq = Po T (M2 f + Q2 xi - A3 e1)`` (ng-tan-edwards-kuang eqs. (22)-(23); (38)-(40) for
    the secondary observer). Sliding is kept while ``||nu_eq|| < rho``, i.e. (by
    :func:`peak_gain`) while ``g_f ||f||_inf + g_xi ||xi||_inf < rho``.

    Returns
    -------
    g_f, g_xi : float
    """
    n, p = A.shape[0], C.shape[0]
    k = n - p
    T = C[:, k:]
    A1, A3 = A[:k, :k], A[k:, :k]
    M1, M2, Q1, Q2 = M[:k], M[k:], Q[:k], Q[k:]
    Ae = A1 + L @ A3
    PT = Po @ T
    Ce = -PT @ A3
    gf = peak_gain(Ae, -(M1 + L @ M2), Ce, PT @ M2)
    gx = peak_gain(Ae, -(Q1 + L @ Q2), Ce, PT @ Q2) if Q.shape[1] else 0.0
    return gf, gx
