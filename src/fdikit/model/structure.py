"""Structural analysis of linear systems: ranks, observability, invariant zeros, relative degree.

Every function works on plain arrays and, where natural, on a
:class:`~fdikit.model.linear.LinearFaultModel` (pass the model in place of ``A``).

Rank decisions
--------------
All rank decisions in fdikit use one rule (NumPy's ``matrix_rank`` rule): a singular value
``sigma_i`` of a matrix ``M`` counts as zero when

    sigma_i <= tol,   tol = max(rows, cols) * eps * sigma_max(M)

with ``eps`` the float64 machine epsilon (see :func:`default_tol`). Algorithms that take many
rank decisions on sub-blocks of one object (the observability staircase, the zero reduction)
apply the rule once to the whole object (``[A; C]`` or the system matrix ``[[A, B], [C, D]]``),
times ``min(rows, cols)`` for the accumulation of rounding errors over the successive
decisions, and use that absolute tolerance for every sub-block, so that a tiny block is never
promoted to full rank by its own small norm. :func:`unobservable_modes` then checks its answer
with the PBH test (and escalates the tolerance up to ``sqrt(eps)`` when the check fails);
:func:`relative_degree` applies the rule to time-scaled Markov parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from ..errors import ModelError
from .linear import LinearFaultModel

__all__ = [
    "RankDecision",
    "RelativeDegree",
    "default_tol",
    "invariant_zeros",
    "is_detectable",
    "is_observable",
    "markov_parameters",
    "observability_matrix",
    "rank",
    "rank_decision",
    "relative_degree",
    "unobservable_modes",
]

_EPS = np.finfo(float).eps


# ---------------------------------------------------------------------------------- helpers
def default_tol(shape: tuple[int, ...], sigma_max: float) -> float:
    """The fdikit rank tolerance ``max(shape) * eps * sigma_max``.

    Parameters
    ----------
    shape : tuple of int
        Shape of the matrix whose rank is decided.
    sigma_max : float
        Its largest singular value (2-norm), or the norm of the larger object it is a block of.

    Returns
    -------
    float
        Absolute tolerance: singular values ``<= tol`` are zero.

    Examples
    --------
    >>> from fdikit.model import default_tol
    >>> default_tol((3, 2), 1.0) / 2.220446049250313e-16
    3.0
    """
    return float(max(shape, default=0) * _EPS * sigma_max)


def _arr(M: Any, what: str) -> np.ndarray:
    M = np.asarray(M, dtype=float)
    if M.ndim == 1:
        M = M[None, :]
    if M.ndim != 2:
        raise ModelError(f"{what} must be a 2-D matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ModelError(f"{what} contains NaN or inf")
    return M


def _system(A: Any, B: Any = None, C: Any = None, D: Any = None, need_B: bool = True):
    """(A, B, C, D, dt) from arrays or from a LinearFaultModel (B may then be a group name)."""
    if isinstance(A, LinearFaultModel):
        model = A
        group = "u" if B is None else B
        if not isinstance(group, str):
            raise ModelError("with a LinearFaultModel, the second argument must be an input group name "
                             f"('u', 'd', 'f' or 'w'), got {type(group).__name__}")
        return model.A, model.B_of(group), model.C, model.D_of(group), model.dt
    A = _arr(A, "A")
    n = A.shape[0]
    if A.shape != (n, n):
        raise ModelError(f"A must be square, got shape {A.shape}")
    if C is None:
        raise ModelError("C is required")
    C = _arr(C, "C")
    if C.shape[1] != n:
        if C.size == 0:
            C = C.reshape(0, n)
        else:
            raise ModelError(f"C must have {n} columns (one per state), got shape {C.shape}")
    p = C.shape[0]
    if B is None:
        if need_B:
            raise ModelError("B is required")
        B = np.zeros((n, 0))
    B = np.asarray(B, dtype=float)
    if B.ndim == 1:
        B = B.reshape(n, -1) if B.size else np.zeros((n, 0))
    if B.ndim != 2 or B.shape[0] != n:
        raise ModelError(f"B must have {n} rows (one per state), got shape {B.shape}")
    if not np.all(np.isfinite(B)):
        raise ModelError("B contains NaN or inf")
    m = B.shape[1]
    if D is None:
        D = np.zeros((p, m))
    D = np.asarray(D, dtype=float).reshape(p, m) if np.size(D) == p * m else np.asarray(D, float)
    if D.shape != (p, m):
        raise ModelError(f"D must have shape {(p, m)} (outputs x inputs), got {D.shape}")
    if not np.all(np.isfinite(D)):
        raise ModelError("D contains NaN or inf")
    return A, B, C, D, None


def _norm2(M: np.ndarray) -> float:
    return float(np.linalg.norm(M, 2)) if M.size else 0.0


# ---------------------------------------------------------------------------------- rank
def rank(M: Any, tol: float | None = None) -> int:
    """Numerical rank by SVD.

    Parameters
    ----------
    M : array_like (r, c)
    tol : float, optional
        Absolute threshold on the singular values; default ``max(r, c) * eps * sigma_max(M)``
        (the fdikit rule, see the module docstring).

    Returns
    -------
    int
        Number of singular values larger than ``tol``.

    Examples
    --------
    >>> from fdikit.model import rank
    >>> rank([[1.0, 2.0], [2.0, 4.0]])
    1
    >>> rank([[1.0, 0.0], [0.0, 1e-9]], tol=1e-6)
    1
    """
    M = _arr(M, "M") if np.ndim(M) else np.atleast_2d(np.asarray(M, float))
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    if tol is None:
        tol = default_tol(M.shape, s[0])
    return int(np.sum(s > tol))


@dataclass
class RankDecision:
    """A rank decision with the numbers behind it.

    Attributes
    ----------
    rank : int
        Number of singular values larger than ``tol``.
    singular_values : ndarray
        All singular values, largest first.
    atol, rtol : float
        The absolute and relative tolerances; ``tol = max(atol, rtol * sigma_max)``.
    tol : float
        The threshold applied.
    """

    rank: int
    singular_values: np.ndarray
    atol: float
    rtol: float
    tol: float

    def as_dict(self) -> dict:
        """Plain-data form (for an ``info`` record)."""
        return {"rank": self.rank, "singular_values": [float(x) for x in self.singular_values],
                "atol": self.atol, "rtol": self.rtol, "tol": self.tol}


def rank_decision(M: Any, *, atol: float = 0.0, rtol: float | None = None) -> RankDecision:
    """Numerical rank with an absolute and a relative tolerance, and the singular values behind it.

    A singular value counts as non-zero when it exceeds ``max(atol, rtol * sigma_max(M))``. With
    the defaults (``atol = 0``, ``rtol = max(rows, cols) * eps``) this is :func:`rank`'s rule; an
    ``atol`` taken from the scale of the factors a product was formed from (e.g.
    ``||C|| ||A|| ||M||`` for ``C A M``) stops a product that is zero up to rounding from being
    promoted to full rank by its own small norm.

    Parameters
    ----------
    M : array_like (r, c)
    atol : float
        Absolute threshold (units of ``M``), >= 0.
    rtol : float, optional
        Relative threshold, >= 0.

    Returns
    -------
    RankDecision

    Examples
    --------
    >>> from fdikit.model.structure import rank_decision
    >>> rank_decision([[1e-16]]).rank, rank_decision([[1e-16]], atol=1e-12).rank
    (1, 0)
    """
    M = _arr(M, "M") if np.ndim(M) else np.atleast_2d(np.asarray(M, float))
    atol = float(atol)
    if not (np.isfinite(atol) and atol >= 0):
        raise ModelError(f"atol must be finite and >= 0, got {atol}")
    r = float(max(M.shape, default=0) * _EPS) if rtol is None else float(rtol)
    if not (np.isfinite(r) and r >= 0):
        raise ModelError(f"rtol must be finite and >= 0, got {rtol}")
    s = np.linalg.svd(M, compute_uv=False) if M.size else np.zeros(0)
    tol = max(atol, r * (float(s[0]) if s.size else 0.0))
    return RankDecision(int(np.sum(s > tol)), s, atol, r, tol)

# ---------------------------------------------------------------------------------- observability
def observability_matrix(A: Any, C: Any = None) -> np.ndarray:
    """Observability matrix ``[C; C A; ...; C A^(n-1)]``.

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel
    C : array_like (p, n)

    Returns
    -------
    ndarray (n p, n)

    Examples
    --------
    >>> from fdikit.model import observability_matrix
    >>> observability_matrix([[0.0, 1.0], [0.0, 0.0]], [[1.0, 0.0]]).tolist()
    [[1.0, 0.0], [0.0, 1.0]]
    """
    A, _, C, _, _ = _system(A, None, C, need_B=False)
    n = A.shape[0]
    blocks, CA = [], C
    for _ in range(n):
        blocks.append(CA)
        CA = CA @ A
    return np.vstack(blocks) if blocks else np.zeros((0, 0))


def _observability_staircase(A: np.ndarray, C: np.ndarray, tol: float | None):
    """Orthogonal observability staircase (dual of the controllability staircase).

    Returns ``(n_obs, Z, At)``: ``Z`` orthogonal with ``At = Z^T A Z`` whose trailing
    ``n - n_obs`` states form an unobservable subsystem ``At[n_obs:, n_obs:]`` that is decoupled
    from ``C Z`` and from the observable states.
    """
    # Work on the controllable pair (A^T, C^T): B_k blocks compressed by SVD.
    n = A.shape[0]
    At = A.T.copy()
    Bk = C.T.copy()
    Z = np.eye(n)
    if tol is None:
        big = np.vstack([A, C]) if C.size else A
        tol = min(big.shape) * default_tol(big.shape, _norm2(big))
    nc = 0
    while nc < n and Bk.size:
        U, s, _ = np.linalg.svd(Bk, full_matrices=True)
        r = int(np.sum(s > tol))
        if r == 0:
            break
        # transform the trailing block by U (orthogonal, (n-nc) x (n-nc))
        At[nc:, :] = U.T @ At[nc:, :]
        At[:, nc:] = At[:, nc:] @ U
        Z[:, nc:] = Z[:, nc:] @ U
        Bk = At[nc + r:, nc:nc + r]
        nc += r
    # At is Z^T A^T Z -> Z^T A Z = At^T
    return nc, Z, At.T


def unobservable_modes(A: Any, C: Any = None, tol: float | None = None) -> np.ndarray:
    """Unobservable eigenvalues of ``(A, C)``: the ``lambda`` with ``rank [A - lambda I; C] < n``.

    The set is the PBH (Popov-Belevitch-Hautus) test's answer, computed robustly in two steps:

    1. An orthogonal observability staircase (Van Dooren 1981; the dual of the controllability
       staircase) separates an unobservable subsystem, whose eigenvalues are returned. This
       avoids deciding ``rank [A - lambda I; C]`` at computed eigenvalues, which fails for
       repeated (defective) unobservable eigenvalues, computed only to ``eps**(1/k)``.
    2. The PBH test checks the result: every eigenvalue ``mu`` of the observable block
       ``(A_o, C_o)`` must have ``sigma_min([A_o - mu I; C_o]) > sqrt(eps) ||[A; C]||_2``. When
       it fails (rounding errors accumulated along a long staircase, typical of single-output
       systems with many states, made a zero coupling look nonzero), the staircase is repeated
       with a tolerance 100 times larger, up to ``sqrt(eps) ||[A; C]||_2``.

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel
    C : array_like (p, n)
    tol : float, optional
        Absolute rank tolerance of the staircase, used as given (no PBH escalation). Default:
        start at ``n (n + p) eps ||[A; C]||_2`` (the fdikit rule on ``[A; C]`` times ``n`` for the
        up to ``n`` successive rank decisions, as in SLICOT's staircase routines) and escalate as
        described above.

    Returns
    -------
    ndarray of complex, shape (k,)
        The ``k = n - rank(observability matrix)`` unobservable modes, sorted by real part
        (with multiplicity). Empty when ``(A, C)`` is observable.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import unobservable_modes
    >>> unobservable_modes(np.diag([-1.0, 2.0]), [[1.0, 0.0]]).real.tolist()
    [2.0]
    """
    A, _, C, _, _ = _system(A, None, C, need_B=False)
    n = A.shape[0]
    if tol is not None:
        nc, _, At = _observability_staircase(A, C, tol)
    else:
        big = np.vstack([A, C])
        norm = _norm2(big)
        t, t_max = min(big.shape) * default_tol(big.shape, norm), np.sqrt(_EPS) * norm
        while True:
            nc, Z, At = _observability_staircase(A, C, t)
            if nc == 0 or t >= t_max or _pbh_ok(At[:nc, :nc], (C @ Z)[:, :nc], t_max):
                break
            t = min(100.0 * t, t_max)
    ev = np.linalg.eigvals(At[nc:, nc:]) if nc < n else np.zeros(0, complex)
    return np.asarray(ev[np.lexsort((ev.imag, ev.real))], dtype=complex)


def _pbh_ok(Ao: np.ndarray, Co: np.ndarray, thresh: float) -> bool:
    """PBH: every eigenvalue mu of Ao has sigma_min([Ao - mu I; Co]) > thresh."""
    k = Ao.shape[0]
    for mu in np.linalg.eigvals(Ao):
        M = np.vstack([Ao - mu * np.eye(k), Co])
        if np.linalg.svd(M, compute_uv=False)[-1] <= thresh:
            return False
    return True


def is_observable(A: Any, C: Any = None, tol: float | None = None) -> bool:
    """True when ``(A, C)`` has no unobservable mode (see :func:`unobservable_modes`).

    Examples
    --------
    >>> from fdikit.model import is_observable
    >>> is_observable([[0.0, 1.0], [0.0, 0.0]], [[1.0, 0.0]]), is_observable([[0.0, 1.0], [0.0, 0.0]],
    ...                                                                       [[0.0, 1.0]])
    (True, False)
    """
    return unobservable_modes(A, C, tol).size == 0


def _stable_mask(ev: np.ndarray, dt: float | None, margin: float) -> np.ndarray:
    if dt is None:
        return ev.real < -margin
    return np.abs(ev) < 1.0 - margin


def is_detectable(A: Any, C: Any = None, *, dt: float | None = None, tol: float | None = None,
                  margin: float | None = None) -> bool:
    """True when every unobservable mode of ``(A, C)`` is stable.

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel
        With a model, ``C`` and ``dt`` are taken from it.
    C : array_like (p, n)
    dt : float or None
        ``None`` (continuous: stable means ``Re(lambda) < -margin``) or a sample time (discrete:
        ``|lambda| < 1 - margin``).
    tol : float, optional
        Rank tolerance of :func:`unobservable_modes`.
    margin : float, optional
        Stability margin; default ``100 * eps * max(1, ||A||_2)`` so that a computed mode on the
        stability boundary (an unobservable integrator at ``1e-17``) is not called stable.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import is_detectable
    >>> is_detectable(np.diag([-1.0, 2.0]), [[0.0, 1.0]]), is_detectable(np.diag([-1.0, 2.0]), [[1.0, 0.0]])
    (True, False)
    >>> is_detectable(np.diag([0.5, 0.9]), [[1.0, 0.0]], dt=0.01)
    True
    """
    if isinstance(A, LinearFaultModel):
        dt = A.dt
    A_, _, C_, _, _ = _system(A, None, C, need_B=False)
    ev = unobservable_modes(A_, C_, tol)
    if margin is None:
        margin = 100 * _EPS * max(1.0, _norm2(A_))
    return bool(np.all(_stable_mask(ev, dt, margin)))


# ---------------------------------------------------------------------------------- zeros
def _compress_rows(A, B, C, D, tol):
    """One Emami-Naeini & Van Dooren reduction: a system with D of full row rank, same finite zeros.

    Repeats, while D is row-rank deficient (r = rank D < p): rotate the outputs so that the
    first p - r rows of D vanish (C -> [C1; C2], D -> [0; D2]); row-compress C1 to its rank rho
    (zero rows belong to the left null structure and are dropped); rotate the states so that
    C1 reads [0, S] with S (rho x rho) nonsingular; those rows pin the last rho states, whose
    columns are eliminated by a unimodular row operation, leaving the reduced system

        A' = A11,  B' = B1,  C' = [A21; C2_1],  D' = [B2; D2]

    (Emami-Naeini & Van Dooren, Automatica 18(4), 1982, Section 3). Only orthogonal
    transformations are applied, so the reduction is backward stable.
    """
    while True:
        n, m = B.shape
        p = C.shape[0]
        if p == 0:
            return A, B, C, D
        if m and D.size:
            U, s, _ = np.linalg.svd(D, full_matrices=True)
            r = int(np.sum(s > tol))
            W = U[:, ::-1].T  # zero rows of W D first, the r nonzero rows last
        else:
            W, r = np.eye(p), 0
        if r == p:
            return A, B, C, D
        Cw, Dw = W @ C, W @ D
        C1, C2, D2 = Cw[:p - r], Cw[p - r:], Dw[p - r:]
        if n == 0:
            return A, B, C2, D2
        _, s1, V1t = np.linalg.svd(C1, full_matrices=True)
        rho = int(np.sum(s1 > tol))
        if rho == 0:  # rows [C1, 0] vanish: left null structure, no finite zeros
            return A, B, C2, D2
        V = np.hstack([V1t[rho:].T, V1t[:rho].T])  # C1 V = [0, S]
        At, Bt, C2t = V.T @ A @ V, V.T @ B, C2 @ V
        k = n - rho
        A = At[:k, :k]
        B = Bt[:k]
        C = np.vstack([At[k:, :k], C2t[:, :k]])
        D = np.vstack([Bt[k:], D2])


def invariant_zeros(A: Any, B: Any = None, C: Any = None, D: Any = None, *,
                    tol: float | None = None) -> np.ndarray:
    """Invariant zeros of ``(A, B, C, D)``, square or not.

    The invariant zeros are the finite ``s`` at which the Rosenbrock system matrix

        P(s) = [[A - s I, B], [C, D]]

    loses rank below its normal rank. They include transmission zeros and, for a tall system
    (more outputs than inputs) the unobservable modes, for a wide one the uncontrollable modes.

    Method (Emami-Naeini & Van Dooren, "Computation of zeros of linear multivariable systems",
    Automatica 18(4), 1982): orthogonal row compressions of ``D`` and ``C`` remove the infinite
    zeros and the left null structure until ``D`` has full row rank; the same reduction on the
    dual system removes the right structure, leaving a system with ``D`` square and invertible
    and the same finite zeros. A column compression ``[C D] V = [0 X]`` then gives a square
    regular pencil ``([A B] V, [I 0] V)`` restricted to its first ``n`` columns, whose generalised
    eigenvalues (``scipy.linalg.eig``, QZ) are the zeros; infinite eigenvalues are discarded.
    This is the algorithm of SLICOT's AB08ND, written here with NumPy SVDs.

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel
        With a model, ``B`` may name an input group (``"u"`` default, ``"f"`` for the fault
        directions ``(A, M, C)`` of ng-tan-edwards-kuang, ...).
    B : array_like (n, m)
    C : array_like (p, n)
    D : array_like (p, m), optional
        Zero by default.
    tol : float, optional
        Absolute rank tolerance for the reduction. Default ``(n+p) * (n+m) * eps * ||S||_2`` with
        ``S = [[A, B], [C, D]]`` (SLICOT AB08ND's default): the fdikit rule applied to ``S``
        with an extra factor ``min(n+p, n+m)``, because the reduction takes up to ``n`` rank
        decisions in succession and rounding errors of earlier steps, amplified by the
        conditioning of the compressed blocks, reach the later ones.

    Returns
    -------
    ndarray of complex, shape (k,)
        The finite invariant zeros (with multiplicity), sorted by real then imaginary part.
        ``k = 0`` when there are none.

    Examples
    --------
    ``G(s) = (s + 2) / ((s + 1)(s + 3))`` has one zero at -2:

    >>> from fdikit.model import invariant_zeros
    >>> z = invariant_zeros([[0.0, 1.0], [-3.0, -4.0]], [[0.0], [1.0]], [[2.0, 1.0]])
    >>> z.real.round(12).tolist(), z.imag.tolist()
    ([-2.0], [0.0])
    """
    A, B, C, D, _ = _system(A, B, C, D)
    n, m = B.shape
    p = C.shape[0]
    if n == 0:
        return np.zeros(0, complex)
    if tol is None:
        S = np.block([[A, B], [C, D]])
        tol = min(S.shape) * default_tol(S.shape, _norm2(S))
    # reduce alternately on the system and its dual until D is square and invertible
    for _ in range(2 * (n + max(m, p)) + 2):
        A, B, C, D = _compress_rows(A, B, C, D, tol)
        A, Bt, Ct, Dt = _compress_rows(A.T, C.T, B.T, D.T, tol)
        A, B, C, D = A.T, Ct.T, Bt.T, Dt.T
        n, m, p = A.shape[0], B.shape[1], C.shape[0]
        if n == 0:
            return np.zeros(0, complex)
        if m == p and (m == 0 or np.linalg.svd(D, compute_uv=False)[-1] > tol):
            break
    else:  # pragma: no cover - the reduction terminates in exact arithmetic
        raise ModelError(f"invariant_zeros: reduction did not reach a square pencil (n={n}, m={m}, p={p})")
    if m:
        # column compression [C D] V = [0 X]: the first n columns of V span its null space
        _, _, Vt = np.linalg.svd(np.hstack([C, D]), full_matrices=True)
        V = np.hstack([Vt[m:].T, Vt[:m].T])
        AB = np.hstack([A, B]) @ V[:, :n]
        E = V[:n, :n]
    else:
        AB, E = A, np.eye(n)
    alpha, beta = sla.eig(AB, E, right=False, homogeneous_eigvals=True)
    finite = np.abs(beta) > 1e3 * _EPS * np.abs(alpha)
    z = alpha[finite] / beta[finite]
    z = np.where(np.abs(z.imag) <= 1e2 * _EPS * np.maximum(1.0, np.abs(z)), z.real + 0j, z)
    return np.asarray(z[np.lexsort((z.imag, z.real))], dtype=complex)


# ---------------------------------------------------------------------------------- Markov / degree
def markov_parameters(A: Any, B: Any = None, C: Any = None, D: Any = None,
                      k: int | None = None) -> np.ndarray:
    """Markov parameters ``H_0 = D``, ``H_i = C A^(i-1) B`` (i = 1..k).

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel (then ``B`` may be a group name)
    B : array_like (n, m)
    C : array_like (p, n)
    D : array_like (p, m), optional
    k : int, optional
        Highest index; default ``n``.

    Returns
    -------
    ndarray (k + 1, p, m)
        ``H[i]`` is the i-th Markov parameter (the impulse response's i-th derivative at 0+ for a
        continuous system, the i-th sample for a discrete one).

    Examples
    --------
    >>> from fdikit.model import markov_parameters
    >>> H = markov_parameters([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]])
    >>> H[:, 0, 0].tolist()
    [0.0, 0.0, 1.0]
    """
    A, B, C, D, _ = _system(A, B, C, D)
    n = A.shape[0]
    k = n if k is None else int(k)
    if k < 0:
        raise ModelError(f"k must be >= 0, got {k}")
    H = np.empty((k + 1, C.shape[0], B.shape[1]))
    H[0] = D
    AiB = B
    for i in range(1, k + 1):
        H[i] = C @ AiB
        AiB = A @ AiB
    return H


@dataclass(frozen=True)
class RelativeDegree:
    """Relative degrees of ``(A, M, C, D)``.

    Attributes
    ----------
    per_input : tuple of (int or None)
        For each input column j, the index of the first nonzero Markov parameter column
        ``H_i[:, j]`` (0 when ``D[:, j] != 0``); ``None`` when the input does not reach the
        output at all.
    overall : int or None
        The smallest ``r`` with ``rank T_(r+1) - rank T_r = rank M`` where ``T_k`` is the block
        lower-triangular Toeplitz matrix of ``H_0 .. H_(k-1)``: the input can be recovered from
        the output and its first ``r`` derivatives (the inherent inversion delay). With ``D = 0``,
        ``r = 1`` is condition A1 of ng-tan-edwards-kuang (``rank CM = rank M``) and
        ``r = 2`` is condition B1 (``rank [[CAM, CM], [CM, 0]] = rank CM + rank M``).
        ``None``: the system is not left invertible (no r <= n + 1 works).
    rank_M, rank_CM : int
        ``rank(M)`` and ``rank(C M)``.
    ranks_T : tuple of int
        ``rank T_1, rank T_2, ...`` as computed.
    """

    per_input: tuple[int | None, ...]
    overall: int | None
    rank_M: int
    rank_CM: int
    ranks_T: tuple[int, ...]

    @property
    def is_one(self) -> bool:
        """``rank(C M) == rank(M)`` (ng-tan-edwards-kuang, condition A1)."""
        return self.rank_CM == self.rank_M


def _toeplitz(H: np.ndarray, k: int) -> np.ndarray:
    p, m = H.shape[1:]
    T = np.zeros((k * p, k * m))
    for i in range(k):
        for j in range(i + 1):
            T[i * p:(i + 1) * p, j * m:(j + 1) * m] = H[i - j]
    return T


def relative_degree(A: Any, B: Any = None, C: Any = None, D: Any = None, *,
                    rtol: float | None = None) -> RelativeDegree:
    """Relative degree of each input column and overall relative degree of ``(A, M, C, D)``.

    The Markov parameters are computed for the time-scaled system ``(A / a, M / a, C, D)`` with
    ``a = ||A||_2``, i.e. ``H_i / a**i``: relative degrees are invariant under this scaling
    (the block Toeplitz matrices change by a block-diagonal congruence), and the scaled
    parameters are all of the size of ``||C|| ||M|| / a`` or ``||D||``, so one relative threshold
    serves all of them (unscaled, ``H_(n+1)`` can be ``||A||**n`` times larger than ``C M``).

    Parameters
    ----------
    A : array_like (n, n) or LinearFaultModel (then ``B`` may be a group name, e.g. ``"f"``)
    B : array_like (n, m)
        Input (or fault distribution ``M``) matrix.
    C : array_like (p, n)
    D : array_like (p, m), optional
    rtol : float, optional
        Relative threshold: a scaled Markov column is nonzero when its norm exceeds
        ``rtol * max(||d_j||, ||C|| ||m_j|| / a)``, and singular values of ``M``, ``C M`` and the
        scaled Toeplitz matrices below ``rtol`` times their reference norm are zero. Default:
        the fdikit rule (``max(shape) * eps``) times ``n + 2`` for the accumulated rounding of the
        matrix powers.

    Returns
    -------
    RelativeDegree

    Examples
    --------
    The remark of ng-tan-edwards-kuang (double integrator, force input, position output):
    ``CM = 0`` but condition B1 holds, relative degree two:

    >>> from fdikit.model import relative_degree
    >>> rd = relative_degree([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]])
    >>> rd.per_input, rd.overall, rd.is_one
    ((2,), 2, False)
    """
    A, B, C, D, _ = _system(A, B, C, D)
    n, m = B.shape
    p = C.shape[0]
    a = _norm2(A) or 1.0
    Hs = markov_parameters(A / a, B / a, C, D, k=n + 1)  # Hs[i] = H_i / a**i
    nC = _norm2(C)
    fac = float(n + 2)

    def thr(shape, ref):
        return (rtol * ref) if rtol is not None else fac * default_tol(shape, ref)

    per: list[int | None] = []
    for j in range(m):
        ref = max(float(np.linalg.norm(D[:, j])), nC * float(np.linalg.norm(B[:, j])) / a)
        col = np.linalg.norm(Hs[:, :, j], axis=1)
        nz = np.nonzero(col > thr((p, 1), ref))[0] if ref > 0 else np.zeros(0, int)
        per.append(int(nz[0]) if nz.size else None)
    nB = _norm2(B)
    rank_M = rank(B, thr(B.shape, nB)) if nB > 0 else 0
    rank_CM = rank(C @ B, thr((p, m), nC * nB)) if nC * nB > 0 else 0
    scale = max(_norm2(D), nC * nB / a)
    ranks: list[int] = [0]
    overall = None
    for k in range(1, n + 3):
        T = _toeplitz(Hs, k)
        ranks.append(rank(T, thr(T.shape, scale)) if scale > 0 else 0)
        if ranks[-1] - ranks[-2] == rank_M:
            overall = k - 1
            break
    return RelativeDegree(tuple(per), overall, rank_M, rank_CM, tuple(ranks[1:]))
