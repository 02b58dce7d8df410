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

from dataclasses import dataclass, field

import numpy as np

from ..errors import ConditionError, DataError

__all__ = [
    "GAMMA_O_FACTORS",
    "PRIMARY_LMI_MAX_STATES",
    "SECONDARY_FULL_MAX_STATES",
    "PrimaryGains",
    "SecondaryGains",
    "primary_smo_lmi",
    "secondary_smo_lmi",
    "secondary_smo_lmi_search",
]

_OK = ("optimal", "optimal_inaccurate")

#: Clarabel settings of the refinement solve of an inaccurate solution (more iterations, tighter
#: tolerances, more iterative refinement of the KKT solves).
REFINE_SETTINGS = {"max_iter": 400, "tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10,
                   "tol_ktratio": 1e-8, "iterative_refinement_max_iter": 50}


#: Clarabel settings of the first solve (empty: Clarabel's defaults).
SOLVER_SETTINGS: dict = {}


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.T)


def _violation(prob) -> float:
    """Largest violation of the program's constraints at the returned point (0 when all hold)."""
    worst = 0.0
    for c in prob.constraints:
        try:
            v = c.violation()
        except (ValueError, TypeError):  # pragma: no cover - a constraint without a value
            return float("inf")
        v = float(np.max(v)) if np.size(v) else 0.0
        worst = max(worst, v if np.isfinite(v) else float("inf"))
    return worst


def _stats(prob, status: str, attempt: str) -> dict:
    st = prob.solver_stats
    return {"attempt": attempt, "status": status,
            "iterations": None if st is None or st.num_iters is None else int(st.num_iters),
            "solve_seconds": None if st is None or st.solve_time is None else float(st.solve_time),
            "value": None if prob.value is None else float(prob.value)}


def _solve(prob, what: str, eps: float = 1e-7) -> tuple[float, dict]:
    """Solve with Clarabel; record the status; refine an inaccurate solution or refuse it.

    The strict LMIs are imposed as ``<= -eps I``. An ``optimal_inaccurate`` answer is solved again
    with :data:`REFINE_SETTINGS`; the result is accepted only when every constraint holds at the
    returned point to within ``eps / 2`` (so each strict inequality still holds with margin
    ``eps / 2``), otherwise :class:`ConditionError` ``"LMI"`` is raised.

    Returns
    -------
    value : float
    record : dict
        ``status`` (final), ``attempts`` (status, iterations, seconds and value of each solve),
        ``max_violation`` (largest constraint violation at the accepted point), ``refined``.
    """
    import cvxpy as cp

    attempts = []

    def run(attempt: str, **settings) -> str:
        try:
            prob.solve(solver=cp.CLARABEL, **settings)
        except cp.error.SolverError as exc:
            attempts.append({"attempt": attempt, "status": "solver_error", "message": str(exc)})
            return "solver_error"
        attempts.append(_stats(prob, prob.status, attempt))
        return prob.status

    status = run("default", **SOLVER_SETTINGS)
    refined = False
    if status == "optimal_inaccurate":
        refined = True
        status = run("refine", **{**SOLVER_SETTINGS, **REFINE_SETTINGS})
    record = {"solver": "CLARABEL", "status": status, "attempts": attempts, "refined": refined}
    if status == "solver_error":
        raise ConditionError("LMI", f"{what} has no solution: the Clarabel solver failed "
                             f"(infeasible or numerically ill-posed: {attempts[-1]['message']})",
                             {"status": "solver_error", "solver": record})
    if status not in _OK:
        raise ConditionError("LMI", f"{what} is {status} (Clarabel)", {"status": status, "solver": record})
    viol = _violation(prob)
    record["max_violation"] = viol
    if status == "optimal_inaccurate" and not viol <= 0.5 * eps:
        raise ConditionError("LMI", f"{what}: Clarabel's solution is inaccurate even after refinement and "
                             f"violates the LMIs by {viol:.3g} (> eps/2 = {0.5 * eps:.3g}); refused",
                             {"status": status, "solver": record})
    record["verified"] = bool(viol <= 0.5 * eps)
    return float(prob.value), record


def _square(X, n: int, what: str, *, spd: bool = False, invertible: bool = False) -> np.ndarray:
    """``X`` as a finite float ``(n, n)`` matrix, checked (DataError naming ``what``)."""
    X = np.asarray(X, dtype=float)
    if X.shape != (n, n):
        raise DataError(f"{what} must have shape ({n}, {n}), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise DataError(f"{what} contains NaN or inf")
    if spd:
        if not np.allclose(X, X.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(X).max(initial=0.0))):
            raise DataError(f"{what} must be symmetric positive definite; it is not symmetric")
        ev = np.linalg.eigvalsh(_sym(X)) if n else np.zeros(0)
        if ev.size and ev.min() <= 0:
            raise DataError(f"{what} must be symmetric positive definite; smallest eigenvalue {ev.min():.3g}")
    if invertible and n and np.linalg.svd(X, compute_uv=False).min() <= n * np.finfo(float).eps * \
            np.linalg.norm(X, 2):
        raise DataError(f"{what} must be invertible")
    return X


def _positive(x, what: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise DataError(f"{what} must be a positive number, got {x!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise DataError(f"{what} must be finite and > 0, got {x!r}")
    return v


def _canonical(A, C, what: str) -> tuple[np.ndarray, np.ndarray]:
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise DataError(f"{what}: A must be square, got shape {A.shape}")
    n = A.shape[0]
    if C.ndim != 2 or C.shape[1] != n or C.shape[0] > n:
        raise DataError(f"{what}: C must have shape (p, {n}) with p <= {n}, got {C.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(C))):
        raise DataError(f"{what}: A or C contains NaN or inf")
    p = C.shape[0]
    if p and np.abs(C[:, :n - p]).max(initial=0.0) > 1e-9 * max(1.0, np.abs(C).max()):
        raise DataError(f"{what}: C must be in the canonical coordinates C = [0 T] (its first "
                        f"{n - p} columns are not zero)")
    return A, C


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
    solver: dict = field(default_factory=dict)


#: Largest state dimension for which :func:`primary_smo_lmi` (``method="auto"``) solves the LMIs
#: (42)-(43) with Clarabel; above it the equivalent Riccati equation is solved instead. Measured
#: (2 cores): the LMI takes 0.3 s at n = 9, 14.5 s at n = 22 (0.8 s per interior-point
#: iteration: two dense PSD cones of size 2n) and does not finish in 10 min at n = 60; the
#: Riccati solve takes milliseconds.
PRIMARY_LMI_MAX_STATES = 16


def _primary_riccati(A: np.ndarray, C: np.ndarray, V1: np.ndarray, V2: np.ndarray, eps: float
                     ) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """``P, X, trace X`` of the primary program from its Riccati equation (no SDP solver).

    With ``Y = P^-1``, (42) is (Schur complement on ``-V1^-1``) the filter Riccati inequality
    ``A Y + Y A^T + V1 - Y C^T V2^-1 C Y < 0``; every ``Y > 0`` satisfying it lies above the
    stabilising solution ``Y+`` of the equation, and (43) is ``X > Y``. The infimum of
    ``trace X`` is therefore ``trace Y+``, approached but not attained. Here ``Y`` solves the
    equation with ``V1`` enlarged by ``O(eps)`` terms (so that (42) holds with margin ``eps``) and
    ``X = (P - 2 eps I)^-1 + 2 eps I`` (so does (43)); both LMIs are then verified at the point
    (margin ``eps / 2``).
    """
    from scipy.linalg import solve_continuous_are

    n = A.shape[0]
    I = np.eye(n)
    t0 = __import__("time").perf_counter()
    # (42) <= -eps I  <=>  P A + A^T P - C^T V2^-1 C + eps I + P V1e P <= 0 with
    # V1e = (V1^-1 - eps I)^-1; the Riccati equation with V1e + mu I gives -P (mu I) P there, so
    # mu >= eps ||Y||^2 is the margin (Y grows with mu: a few rounds)
    V1e = _sym(np.linalg.inv(np.linalg.inv(V1) - eps * I))

    def are(mu: float) -> np.ndarray:
        try:
            return _sym(solve_continuous_are(A.T, C.T, V1e + mu * I, V2))
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ConditionError("LMI", f"primary observer Riccati equation (42) has no stabilising "
                                 f"solution ({exc}): (A, C) must be detectable",
                                 {"status": "riccati_failed", "solver": {"solver": "riccati"}}) from None

    Y = are(0.0)
    for _ in range(4):
        mu = 4.0 * eps * max(1.0, float(np.linalg.eigvalsh(Y).max())) ** 2
        Y = are(mu)
        if 2.0 * eps * float(np.linalg.eigvalsh(Y).max()) ** 2 <= mu:
            break
    P = _sym(np.linalg.inv(Y))
    # (43) <= -eps I  <=>  P > eps I and X >= (P - eps I)^-1 + eps I
    X = _sym(np.linalg.inv(P - 2.0 * eps * I)) + 2.0 * eps * I
    V1i, V2i = np.linalg.inv(V1), np.linalg.inv(V2)
    L42 = np.block([[P @ A + A.T @ P - C.T @ V2i @ C, P], [P, -V1i]])
    L43 = np.block([[-P, I], [I, -X]])
    # each LMI as "<= -eps I": its largest eigenvalue + eps (the violation, 0 when it holds)
    viol = max(0.0, float(np.linalg.eigvalsh(_sym(L42)).max()) + eps,
               float(np.linalg.eigvalsh(_sym(L43)).max()) + eps)
    rec = {"solver": "riccati", "status": "optimal", "refined": False, "max_violation": viol,
           "attempts": [{"attempt": "riccati", "status": "optimal", "iterations": None,
                         "solve_seconds": __import__("time").perf_counter() - t0,
                         "value": float(np.trace(X))}]}
    rec["verified"] = bool(viol <= 0.5 * eps)
    if not rec["verified"]:
        raise ConditionError("LMI", f"primary observer Riccati solution violates (42)-(43) by "
                             f"{viol:.3g} (> eps/2 = {0.5 * eps:.3g}): the equation is badly "
                             f"conditioned; scale V1 or the model's states",
                             {"status": "riccati_inaccurate", "solver": rec})
    return P, X, float(np.trace(X)), rec


def primary_smo_lmi(A: np.ndarray, C: np.ndarray, V1: np.ndarray, V2: np.ndarray, *,
                    eps: float = 1e-7, method: str = "auto") -> PrimaryGains:
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
    method : {"auto", "lmi", "riccati"}
        ``"lmi"``: the SDP with Clarabel. ``"riccati"``: the same optimum from the stabilising
        solution of the filter Riccati equation (:func:`_primary_riccati`; milliseconds at any
        size). ``"auto"``: the LMI up to :data:`PRIMARY_LMI_MAX_STATES` states, else Riccati.
        ``solver["solver"]`` records which.

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

    A, C = _canonical(A, C, "primary_smo_lmi")
    n, p = A.shape[0], C.shape[0]
    V1 = _square(V1, n, "V1", spd=True)
    V2 = _square(V2, p, "V2", spd=True)
    eps = _positive(eps, "eps")
    if method not in ("auto", "lmi", "riccati"):
        raise DataError(f"method must be 'auto', 'lmi' or 'riccati', got {method!r}")
    if method == "auto":
        method = "lmi" if n <= PRIMARY_LMI_MAX_STATES else "riccati"
    T = C[:, n - p:]
    V2i = np.linalg.inv(V2)
    V1i = np.linalg.inv(V1)
    if method == "riccati":
        Pv, Xv, val, rec = _primary_riccati(A, C, V1, V2, eps)
    else:
        P = cp.Variable((n, n), symmetric=True)
        X = cp.Variable((n, n), symmetric=True)
        I = np.eye(n)
        lmi42 = cp.bmat([[P @ A + A.T @ P - C.T @ V2i @ C, P], [P, -V1i]])  # ng-tan-edwards-kuang, eq. (42)
        lmi43 = cp.bmat([[-P, I], [I, -X]])  # ng-tan-edwards-kuang, eq. (43)
        cons = [0.5 * (lmi42 + lmi42.T) << -eps * np.eye(2 * n),
                0.5 * (lmi43 + lmi43.T) << -eps * np.eye(2 * n)]
        prob = cp.Problem(cp.Minimize(cp.trace(X)), cons)
        val, rec = _solve(prob, "primary observer LMI (42)-(43)", eps)
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
    return PrimaryGains(Pv, Xv, Gl, L, Po, Gn, val, rec)


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
    solver: dict = field(default_factory=dict)
    gamma_o: float = float("nan")


def secondary_smo_lmi(A: np.ndarray, M: np.ndarray, C: np.ndarray, Q: np.ndarray, *,
                      D1: np.ndarray, gamma_o: float, eps: float = 1e-7, form: str = "auto"
                      ) -> SecondaryGains:
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
    form : {"auto", "full", "reduced"}
        ``"full"``: (46)-(47) as written, with ``P11 > 0`` and ``P > 0``. ``"reduced"``: the same
        program with the ``pb`` rows of (47) that belong to the noise channels ``D1`` dropped
        (``Bd`` and ``H`` are zero there, so they form the block ``-gamma_o I`` on their own,
        which holds for any ``gamma_o > eps``) and ``P11 > 0`` dropped (implied by ``P > 0``):
        the same feasible set and optimum, smaller PSD cones (the interior-point step's
        factorisation grows with the cube of their sizes). ``P > 0`` is then checked at the
        returned point and imposed in a second solve only when it fails there. ``"auto"``: ``"full"`` up to
        :data:`SECONDARY_FULL_MAX_STATES` states (``nb``), else ``"reduced"``;
        ``solver["form"]`` records which.

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

    A, C = _canonical(A, C, "secondary_smo_lmi")
    nb, pb = A.shape[0], C.shape[0]
    M = np.asarray(M, dtype=float)
    Q = np.asarray(Q, dtype=float)
    if M.ndim != 2 or M.shape[0] != nb or not 0 < M.shape[1] <= pb:
        raise DataError(f"secondary_smo_lmi: M must have shape ({nb}, q) with 0 < q <= {pb}, got {M.shape}")
    if Q.ndim != 2 or Q.shape[0] != nb:
        raise DataError(f"secondary_smo_lmi: Q must have shape ({nb}, h), got {Q.shape}")
    q, h = M.shape[1], Q.shape[1]
    D1 = _square(D1, pb, "D1", invertible=True)
    gamma_o = _positive(gamma_o, "gamma_o")
    eps = _positive(eps, "eps")
    if form not in ("auto", "full", "reduced"):
        raise DataError(f"form must be 'auto', 'full' or 'reduced', got {form!r}")
    if form == "auto":
        form = "full" if nb <= SECONDARY_FULL_MAX_STATES else "reduced"
    if form == "reduced" and gamma_o <= eps:
        form = "full"  # the dropped block -gamma_o I needs gamma_o > eps
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
        cons += [0.5 * (L46 + L46.T) << -eps * np.eye(dim46)]
        if form == "full":
            cons += [P11 >> eps * np.eye(k)]  # implied by P > 0 below (dropped when reduced)
    else:
        L46 = cp.bmat([[-gam * np.eye(h), (W @ Q2).T], [W @ Q2, -gam * np.eye(q)]])
        cons += [0.5 * (L46 + L46.T) << -eps * np.eye(h + q)]
    # ng-tan-edwards-kuang, eq. (47)
    Dd = np.hstack([D1, np.zeros((pb, h))])
    Bd = np.hstack([np.zeros((nb, pb)), Q])
    R = np.linalg.inv(Dd @ Dd.T)
    E = cp.hstack([-(W @ A3), np.zeros((q, pb))]) if k else cp.Constant(np.zeros((q, nb)))
    H = cp.hstack([np.zeros((q, pb)), W @ Q2])
    if form == "full":
        L47 = cp.bmat([[Pl @ A + A.T @ Pl - gamma_o * C.T @ R @ C, -(Pl @ Bd), E.T],
                       [-(Pl @ Bd).T, -gamma_o * np.eye(pb + h), H.T],
                       [E, H, -gamma_o * np.eye(q)]])
        dim47 = nb + pb + h + q
    else:
        # the D1 columns of Bd and of H are zero: those rows of (47) are -gamma_o I alone
        PQ = -(Pl @ Q) if h else None
        rows47 = [[Pl @ A + A.T @ Pl - gamma_o * C.T @ R @ C, PQ, E.T],
                  [PQ.T if h else None, -gamma_o * np.eye(h), (W @ Q2).T if h else None],
                  [E, W @ Q2 if h else None, -gamma_o * np.eye(q)]]
        if not h:
            rows47 = [[rows47[0][0], E.T], [E, -gamma_o * np.eye(q)]]
        L47 = cp.bmat(rows47)
        dim47 = nb + h + q
    cons += [0.5 * (L47 + L47.T) << -eps * np.eye(dim47)]
    Pcone = [Pl >> eps * np.eye(nb)]
    if form == "full":
        cons += Pcone
    if h == 0:
        cons += [gam == 1.0]  # nothing to attenuate: feasibility only
    prob = cp.Problem(cp.Minimize(gam), cons)
    val, rec = _solve(prob, "secondary observer LMIs (46)-(47)", eps)
    rec["form"] = form
    if form == "reduced":
        # P > 0 left to the check at the point (it held in every case measured); solved with it
        # when it does not hold there
        pmin = float(np.linalg.eigvalsh(_sym(np.asarray(Pl.value))).min())
        rec["P_cone"] = "checked at the point"
        rec["min_eig_P"] = pmin
        if not pmin >= 0.5 * eps:
            first = rec
            prob = cp.Problem(cp.Minimize(gam), cons + Pcone)
            val, rec = _solve(prob, "secondary observer LMIs (46)-(47)", eps)
            rec.update(form=form, P_cone="imposed (the reduced solve gave min eig P = "
                       f"{pmin:.3g})", first_solve=first)
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
    return SecondaryGains(Pv, Gl, L, Po, Gn, Wv, gamma, rec, float(gamma_o))


#: Largest secondary state dimension ``nb`` for which :func:`secondary_smo_lmi` (``form="auto"``)
#: solves (46)-(47) as written; above it the reduced form (same feasible set, smaller cones).
#: Below it the full form keeps the designs' numbers (the aircraft's gamma-bar) bitwise.
SECONDARY_FULL_MAX_STATES = 16


#: Multipliers of ``gamma_o`` tried, in this order, when the secondary LMIs are infeasible.
GAMMA_O_FACTORS = (10.0, 100.0, 1e3, 1e4, 0.1, 0.01)


def secondary_smo_lmi_search(A: np.ndarray, M: np.ndarray, C: np.ndarray, Q: np.ndarray, *,
                             D1: np.ndarray, gamma_o: float, eps: float = 1e-7, retry: bool = True,
                             factors: tuple[float, ...] = GAMMA_O_FACTORS) -> SecondaryGains:
    """:func:`secondary_smo_lmi` at ``gamma_o``; when that fails, at ``gamma_o * factor``.

    ``gamma_o`` is the fixed level of the filter inequality (47) that sets ``G_l``; (46), and so
    gamma-bar, do not depend on it, but (47) may be infeasible at one level and feasible at
    another (e.g. a slow invariant zero needs a larger level).

    Parameters
    ----------
    A, M, C, Q, D1, eps
        As :func:`secondary_smo_lmi`.
    gamma_o : float
        The level tried first.
    retry : bool
        ``True``: return the first level that designs the observer (``solver["gamma_o_tried"]``
        lists the levels and their outcomes). ``False``: raise, naming the level that works.
    factors : tuple of float
        Multipliers of ``gamma_o`` tried in order.

    Returns
    -------
    SecondaryGains
        ``gamma_o`` is the level used.

    Raises
    ------
    ConditionError
        ``"LMI"``: infeasible at ``gamma_o`` (``retry=False``; the message names a level that
        works, if one was found) or at every level tried.
    """
    gamma_o = _positive(gamma_o, "gamma_o")
    tried = []
    levels = [gamma_o] + [gamma_o * float(f) for f in factors]
    first = None
    for go in levels:
        try:
            g = secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go, eps=eps)
        except ConditionError as exc:
            first = first or exc
            tried.append({"gamma_o": go, "ok": False, "status": exc.details.get("status", exc.condition),
                          "message": str(exc)})
            continue
        tried.append({"gamma_o": go, "ok": True, "status": g.solver.get("status")})
        g.solver["gamma_o_tried"] = tried
        if go == gamma_o or retry:
            return g
        raise ConditionError(
            "LMI", f"secondary observer LMIs (46)-(47) fail at gamma_o = {gamma_o:g} ({first}); "
            f"gamma_o = {go:g} designs them: pass gamma_o={go:g} (or let the design retry)",
            {"gamma_o": gamma_o, "gamma_o_works": go, "gamma_o_tried": tried})
    why, advice = _explain_secondary_failure(A, C, D1, gamma_o, tried)
    raise ConditionError(
        "LMI", f"secondary observer LMIs (46)-(47) fail at gamma_o = {gamma_o:g} and at every level tried "
        f"({', '.join(format(t['gamma_o'], 'g') for t in tried)}): {first}. Why: {why}. "
        f"What to try: {advice}",
        {"gamma_o": gamma_o, "gamma_o_works": None, "gamma_o_tried": tried, "why": why, "advice": advice})


def _explain_secondary_failure(A: np.ndarray, C: np.ndarray, D1: np.ndarray, gamma_o: float,
                               tried: list[dict]) -> tuple[str, str]:
    """Why (46)-(47) failed at every level, and what to change (for the refusal's message).

    (47) carries ``gamma_o C^T (D1 D1^T)^-1 C`` next to ``P A + A^T P``: a weight ``D1`` far from
    the scale of ``A`` (or badly conditioned) makes the LMIs numerically hopeless for the solver
    (reported as inaccurate), while a solver that proves infeasibility at every level points at
    the system: (46) needs a stable sliding motion (condition B2: stable invariant zeros).
    """
    D1 = np.asarray(D1, float)
    C = np.asarray(C, float)
    a_scale = max(float(np.linalg.norm(A, 2)), 1e-300)
    dd = D1 @ D1.T
    cond_d = float(np.linalg.cond(dd))
    w_scale = float(np.linalg.norm(C.T @ np.linalg.solve(dd, C), 2))
    ratio = gamma_o * w_scale / a_scale
    statuses = sorted({str(t.get("status")) for t in tried})
    inaccurate = any("inaccurate" in str(t.get("message", "")) or "inaccurate" in str(t.get("status"))
                     for t in tried)
    parts = [f"solver outcomes {statuses}",
             f"gamma_o ||C^T (D1 D1^T)^-1 C|| / ||A|| = {ratio:.3g} at gamma_o = {gamma_o:g}",
             f"cond(D1 D1^T) = {cond_d:.3g}"]
    advice = []
    if inaccurate or ratio > 1e6 or ratio < 1e-6 or cond_d > 1e8:
        parts.insert(0, "the LMIs are badly scaled for the solver (the filter weight of (47) and "
                        "the dynamics differ by many orders of magnitude)")
        advice.append("a D1 of the scale of the default 10 I (D1 = None), well conditioned")
        advice.append("scaling the model's states and outputs to comparable units")
    else:
        parts.insert(0, "the solver finds no P, W with a stable sliding motion (46) that also "
                        "satisfies the filter inequality (47)")
        advice.append("check condition B2 (info['conditions']: invariant zeros must be stable and "
                      "not too close to the imaginary axis)")
        advice.append("another D1 (default 10 I) or gamma_o")
    advice.append("a narrower uncertainty filter (omega_d / A_Omega) or fewer disturbance channels")
    return "; ".join(parts), "; ".join(advice)
