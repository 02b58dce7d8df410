"""LMI designs of the sliding mode observers of ng-tan-edwards-kuang (Ng, Tan, Edwards & Kuang, CCA 2007).

Two convex programs, solved with cvxpy and the Clarabel interior-point solver (SCS was measured
to fail on the primary LMI):

* :func:`primary_smo_lmi` -- the primary observer of Tan & Edwards (2001), ng-tan-edwards-kuang
  eqs. (42)-(44):
  minimise ``trace X`` subject to a Riccati-type LMI in ``P`` and ``X > P^-1``.
* :func:`secondary_smo_lmi` -- the robust observer of Tan & Edwards (2003), ng-tan-edwards-kuang eqs.
  (46)-(47): minimise the L2 gain ``gamma`` from the disturbance to the fault reconstruction.

Both take a system already in the canonical coordinates ``C = [0 T]`` (last ``p`` states are the
output states) and return plain gain matrices. Strict inequalities are imposed with a margin
``eps`` (``<= -eps I``). An infeasible or inaccurate solve raises
:class:`fdikit.errors.ConditionError` with condition ``"LMI"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConditionError

__all__ = ["PrimaryGains", "SecondaryGains", "primary_smo_lmi", "secondary_smo_lmi"]

_OK = ("optimal", "optimal_inaccurate")


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.T)


def _solve(prob, what: str) -> float:
    import cvxpy as cp

    try:
        prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:
        raise ConditionError("LMI", f"{what} has no solution: the Clarabel solver failed "
                             f"(infeasible or numerically ill-posed: {exc})",
                             {"status": "solver_error"}) from None
    if prob.status not in _OK:
        raise ConditionError("LMI", f"{what} is {prob.status} (Clarabel)", {"status": prob.status})
    return float(prob.value)


@dataclass
class PrimaryGains:
    """Gains of the primary SMO (15)-(18) in canonical coordinates ``C = [0 T]``.

    Attributes
    ----------
    P : ndarray (n, n)
        Lyapunov matrix ``P_lmi`` (s.p.d.).
    X : ndarray (n, n)
        Bound on ``P^-1`` whose trace was minimised.
    Gl : ndarray (n, p)
        Linear output-error gain ``P^-1 C^T V2^-1`` (44).
    L : ndarray (n-p, p)
        Sliding-motion gain ``P11^-1 P12`` (44); ``A1 + L A3`` is stable.
    Po : ndarray (p, p)
        s.p.d. scaling of the switched injection, ``T (P22 - P12^T L) T^T``.
    Gn : ndarray (n, p)
        Switched-term gain ``[-L T^T; T^T] Po^-1`` (17); satisfies ``P Gn = C^T``.
    trace_X : float
        Optimal value.
    """

    P: np.ndarray
    X: np.ndarray
    Gl: np.ndarray
    L: np.ndarray
    Po: np.ndarray
    Gn: np.ndarray
    trace_X: float


def primary_smo_lmi(A: np.ndarray, C: np.ndarray, V1: np.ndarray, V2: np.ndarray, *,
                    eps: float = 1e-7) -> PrimaryGains:
    """Primary observer design, ng-tan-edwards-kuang eqs. (42)-(44) (Tan & Edwards 2001).

    Minimise ``trace X`` subject to

        [[P A + A^T P - C^T V2^-1 C, P], [P, -V1^-1]] < 0,      [[-P, I], [I, -X]] < 0.

    Parameters
    ----------
    A : ndarray (n, n)
        System matrix in canonical coordinates (``C = [0 T]``, ``T`` orthogonal).
    C : ndarray (p, n)
    V1 : ndarray (n, n), V2 : ndarray (p, p)
        s.p.d. weights (paper: ``V1 = 100 I``, ``V2 = I``).
    eps : float
        Margin of the strict inequalities.

    Returns
    -------
    PrimaryGains

    Raises
    ------
    ConditionError
        ``"LMI"`` when the program is infeasible or the sliding motion ``A1 + L A3`` is not stable.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.design.smo_lmi import primary_smo_lmi
    >>> A = np.array([[-1.0, 1.0], [0.0, -2.0]]); C = np.array([[0.0, 1.0]])
    >>> g = primary_smo_lmi(A, C, np.eye(2), np.eye(1))
    >>> bool(np.allclose(np.linalg.solve(g.P, C.T), g.Gn, atol=1e-6))
    True
    """
    import cvxpy as cp

    n, p = A.shape[0], C.shape[0]
    T = C[:, n - p:]
    V2i = np.linalg.inv(V2)
    V1i = np.linalg.inv(V1)
    P = cp.Variable((n, n), symmetric=True)
    X = cp.Variable((n, n), symmetric=True)
    I = np.eye(n)
    lmi42 = cp.bmat([[P @ A + A.T @ P - C.T @ V2i @ C, P], [P, -V1i]])  # ng-tan-edwards-kuang, eq. (42)
    lmi43 = cp.bmat([[-P, I], [I, -X]])  # ng-tan-edwards-kuang, eq. (43)
    cons = [0.5 * (lmi42 + lmi42.T) << -eps * np.eye(2 * n),
            0.5 * (lmi43 + lmi43.T) << -eps * np.eye(2 * n)]
    prob = cp.Problem(cp.Minimize(cp.trace(X)), cons)
    val = _solve(prob, "primary observer LMI (42)-(43)")
    Pv, Xv = _sym(P.value), _sym(X.value)
    if np.linalg.eigvalsh(Pv).min() <= 0:
        raise ConditionError("LMI", "primary LMI returned a P that is not positive definite",
                             {"min_eig_P": float(np.linalg.eigvalsh(Pv).min())})
    Gl = np.linalg.solve(Pv, C.T @ V2i)  # ng-tan-edwards-kuang, eq. (44)
    P11, P12, P22 = Pv[:n - p, :n - p], Pv[:n - p, n - p:], Pv[n - p:, n - p:]
    L = np.linalg.solve(P11, P12)  # ng-tan-edwards-kuang, eq. (44)
    Po = _sym(T @ (P22 - P12.T @ L) @ T.T)  # eq. (44) (T and T^T in the order that makes P Gn = C^T)
    Gn = np.vstack([-L @ T.T, T.T]) @ np.linalg.inv(Po)  # ng-tan-edwards-kuang, eq. (17)
    A1, A3 = A[:n - p, :n - p], A[n - p:, :n - p]
    ev = np.linalg.eigvals(A1 + L @ A3)
    if ev.size and ev.real.max() >= 0:
        raise ConditionError("LMI", "the sliding motion A1 + L A3 of the primary design is not stable",
                             {"eigenvalues": ev})
    return PrimaryGains(Pv, Xv, Gl, L, Po, Gn, val)


@dataclass
class SecondaryGains:
    """Gains of the robust SMO (37)-(39) and the reconstruction matrix.

    Attributes
    ----------
    P : ndarray (nb, nb)
        Structured Lyapunov matrix ``P_lmi`` with ``P12 = [P121 0]``.
    Gl : ndarray (nb, pb)
        ``gamma_o P^-1 C^T (Dd Dd^T)^-1``.
    L : ndarray (nb-pb, pb)
        ``[L1 0] = P11^-1 P12`` (38).
    Po : ndarray (pb, pb)
        ``T^-T (P22 - P12^T L) T^-1`` so that ``P Gn = C^T``.
    Gn : ndarray (nb, pb)
        ``[-L T^-1; T^-1] Po^-1`` (38).
    W : ndarray (q, pb)
        ``[W1, Mo^-1]``; the reconstruction is ``W T^-1 Po^-1 nu_eq``.
    gamma : float
        L2 bound from the disturbance to the reconstruction error (the optimal value).
    """

    P: np.ndarray
    Gl: np.ndarray
    L: np.ndarray
    Po: np.ndarray
    Gn: np.ndarray
    W: np.ndarray
    gamma: float


def secondary_smo_lmi(A: np.ndarray, M: np.ndarray, C: np.ndarray, Q: np.ndarray, *,
                      D1: np.ndarray, gamma_o: float, eps: float = 1e-7) -> SecondaryGains:
    """Robust observer design, ng-tan-edwards-kuang eqs. (46)-(47) (Tan & Edwards 2003).

    The system ``(A, M, C, Q)`` must be in the coordinates of (33)-(36): ``C = [0 T]`` with ``T``
    invertible, ``M = [0; M2]`` whose bottom ``q`` rows ``Mo`` are invertible. Minimise ``gamma``
    over ``P11 > 0, P121, P22, W1`` subject to (46) (the bounded real lemma of ``G(s)`` in (40))
    and (47) (an H-infinity filter inequality that fixes ``Gl`` and guarantees (45)).

    In (47) the paper leaves ``E`` undefined; here ``E = [-W A3, 0]`` (q x nb), the state-to-
    reconstruction map of (40) extended by zeros over the output states, which is the
    counterpart of ``H = [0, W Q2]``.

    Parameters
    ----------
    A : ndarray (nb, nb), M : ndarray (nb, q), C : ndarray (pb, nb), Q : ndarray (nb, h)
    D1 : ndarray (pb, pb)
        Output-noise weight (paper: ``10 I``).
    gamma_o : float
        Fixed L2 level of (47) (paper: 100).
    eps : float
        Margin of the strict inequalities.

    Returns
    -------
    SecondaryGains

    Raises
    ------
    ConditionError
        ``"LMI"`` when infeasible (e.g. unstable invariant zeros) or when the result does not
        give a stable observer.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.design.smo_lmi import secondary_smo_lmi
    >>> A = np.array([[-1.0, 1.0, 0.0], [0.5, -1.0, 0.0], [0.0, 1.0, -2.0]])
    >>> M = np.array([[0.0], [0.0], [1.0]]); C = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    >>> Q = np.array([[1.0], [0.0], [0.0]])
    >>> g = secondary_smo_lmi(A, M, C, Q, D1=np.eye(2), gamma_o=10.0)
    >>> bool(g.gamma > 0)
    True
    """
    import cvxpy as cp

    nb, pb, q = A.shape[0], C.shape[0], M.shape[1]
    h = Q.shape[1]
    k = nb - pb  # non-output states
    m1 = pb - q  # free columns of L
    T = C[:, k:]
    Mo = M[nb - q:, :]
    Moi = np.linalg.solve(Mo, np.eye(q))
    A1, A3 = A[:k, :k], A[k:, :k]
    Q1, Q2 = Q[:k], Q[k:]
    P11 = cp.Variable((k, k), symmetric=True) if k else None
    P22 = cp.Variable((pb, pb), symmetric=True)
    P121 = cp.Variable((k, m1)) if (k and m1) else None
    W1 = cp.Variable((q, m1)) if m1 else None
    gam = cp.Variable()
    W = cp.hstack([W1, Moi]) if m1 else cp.Constant(Moi)
    if k:
        P12 = cp.hstack([P121, np.zeros((k, q))]) if m1 else cp.Constant(np.zeros((k, pb)))
        Pl = cp.bmat([[P11, P12], [P12.T, P22]])
    else:
        P12 = None
        Pl = P22
    cons = []
    # ng-tan-edwards-kuang, eq. (46): bounded real lemma of G(s) in (40)
    if k:
        blk11 = P11 @ A1 + A1.T @ P11 + P12 @ A3 + A3.T @ P12.T
        rows = [[blk11, -(P11 @ Q1 + P12 @ Q2), -(W @ A3).T],
                [-(P11 @ Q1 + P12 @ Q2).T, -gam * np.eye(h), (W @ Q2).T],
                [-(W @ A3), W @ Q2, -gam * np.eye(q)]]
        if h == 0:
            rows = [[blk11, -(W @ A3).T], [-(W @ A3), -gam * np.eye(q)]]
        L46 = cp.bmat(rows)
        dim46 = k + h + q if h else k + q
        cons += [0.5 * (L46 + L46.T) << -eps * np.eye(dim46), P11 >> eps * np.eye(k)]
    else:
        L46 = cp.bmat([[-gam * np.eye(h), (W @ Q2).T], [W @ Q2, -gam * np.eye(q)]])
        cons += [0.5 * (L46 + L46.T) << -eps * np.eye(h + q)]
    # ng-tan-edwards-kuang, eq. (47)
    Dd = np.hstack([D1, np.zeros((pb, h))])
    Bd = np.hstack([np.zeros((nb, pb)), Q])
    R = np.linalg.inv(Dd @ Dd.T)
    E = cp.hstack([-(W @ A3), np.zeros((q, pb))]) if k else cp.Constant(np.zeros((q, nb)))
    H = cp.hstack([np.zeros((q, pb)), W @ Q2])
    L47 = cp.bmat([[Pl @ A + A.T @ Pl - gamma_o * C.T @ R @ C, -(Pl @ Bd), E.T],
                   [-(Pl @ Bd).T, -gamma_o * np.eye(pb + h), H.T],
                   [E, H, -gamma_o * np.eye(q)]])
    cons += [0.5 * (L47 + L47.T) << -eps * np.eye(nb + pb + h + q), Pl >> eps * np.eye(nb)]
    if h == 0:
        cons += [gam == 1.0]  # nothing to attenuate: feasibility only
    prob = cp.Problem(cp.Minimize(gam), cons)
    val = _solve(prob, "secondary observer LMIs (46)-(47)")
    Pv = _sym(np.asarray(Pl.value))
    Wv = np.asarray(W.value).reshape(q, pb)
    Gl = gamma_o * np.linalg.solve(Pv, C.T @ R)
    if k:
        L = np.linalg.solve(Pv[:k, :k], Pv[:k, k:])
        L[:, m1:] = 0.0  # exactly zero by the structure P12 = [P121 0] (38)
    else:
        L = np.zeros((0, pb))
    S = _sym(Pv[k:, k:] - Pv[:k, k:].T @ L) if k else Pv
    # Po = T^-T S T^-1 without forming T^-1 explicitly
    Po = _sym(np.linalg.solve(T.T, np.linalg.solve(T.T, S).T))
    Ti = np.linalg.solve(T, np.eye(pb))
    Gn = np.vstack([-L @ Ti, Ti]) @ np.linalg.solve(Po, np.eye(pb))  # ng-tan-edwards-kuang, eq. (38)
    Ao = A - Gl @ C
    ev = np.linalg.eigvals(Ao)
    if ev.real.max() >= 0:
        raise ConditionError("LMI", "the secondary observer A - Gl C from (47) is not stable",
                             {"eigenvalues": ev})
    if np.linalg.eigvalsh(Po).min() <= 0:
        raise ConditionError("LMI", "secondary Po is not positive definite",
                             {"eig_Po": np.linalg.eigvalsh(Po)})
    gamma = float(val) if h else 0.0
    return SecondaryGains(Pv, Gl, L, Po, Gn, Wv, gamma)
