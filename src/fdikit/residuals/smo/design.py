"""Robust actuator fault reconstruction with sliding mode observers (ng-tan-edwards-kuang).

Ng, Tan, Edwards & Kuang: K. Y. Ng, C. P. Tan, C. Edwards, Y. C. Kuang, "New result in robust actuator fault
reconstruction with application to an aircraft", IEEE CCA 2007 -- and, for the relative-degree-one
case, C. P. Tan & C. Edwards, IJRNC 13:443-463, 2003.

The system is

    x~' = A~ x~ + B~ u + M~ f + Q~ xi~,   y = C~ x~,   xi~' = A_Omega xi~ + B_Omega xi      (1)-(3)

with ``f`` (q) the actuator faults to reconstruct and ``xi~`` (h) the uncertainty, band-limited by
the filter ``(A_Omega, B_Omega)``. :func:`design_reconstructor` checks the existence conditions
(:func:`check_conditions`), then

* if A1 holds (rank C~M~ = q, relative degree one) designs **one** robust SMO (Tan & Edwards
  2003) on the augmented system (7)-(8);
* otherwise, if B1 and B2 hold, builds the canonical form of Lemmas 1 and 4 (orthogonal / QR /
  SVD steps only), designs the **primary** SMO (15)-(18) by the LMI (42)-(44), forms the
  fictitious relative-degree-one system (25)-(36) from the primary's equivalent output injection
  and designs the **secondary** SMO (37)-(39) by the LMIs (46)-(47), which minimise the L2 gain
  from ``xi`` to the reconstruction ``f^ = W T^-1 Po^-1 nu_eq``.

The runtime :class:`SlidingModeReconstructor` is a :class:`~fdikit.monitor.ResidualGenerator`
whose outputs are the fault reconstructions ``fhat:<fault>``. It integrates the observers with a
fixed step equal to the sample time of the data (see :func:`integrate_observers`): explicit Euler
for the linear part and an implicit (backward) step for the smoothed switching term (24), which
removes the numerical chattering of an explicit switched term; batch :meth:`run` and streaming
:meth:`step` call the same compiled kernel and agree to the last bit.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit

from ...base.stage import ResidualGenerator
from ...design.smo_lmi import primary_smo_lmi, secondary_smo_lmi_search
from ...errors import ConditionError, DataError, ModelError
from ...model.linear import LinearFaultModel
from ...model.structure import invariant_zeros, is_detectable, is_observable, rank, rank_decision
from ...signals import Signals, check_finite

__all__ = [
    "AugmentedSystem",
    "CanonicalForm",
    "FictitiousSystem",
    "Lemma1Form",
    "SMOConditions",
    "SlidingModeReconstructor",
    "check_conditions",
    "design_reconstructor",
    "fictitious_system",
    "hinf_norm",
    "injection_peak_gains",
    "integrate_observers",
    "lemma1_form",
    "lemma4_form",
    "noise_response",
    "peak_gain",
    "self_check",
    "simulate_plant",
    "sliding_episodes",
]

#: Sliding status codes of the ``sliding_status`` outputs.
SLIDING, NOT_SLIDING, SATURATED = 0, 1, 2
STATUS_LABELS = {SLIDING: "sliding", NOT_SLIDING: "not sliding", SATURATED: "saturated"}

#: Default absolute rank tolerance, relative to the scale of the factors a matrix is formed from
#: (``||C|| ||A|| ||M||`` for ``C A M``): see :func:`check_conditions`.
RANK_ATOL_SCALE = 1e-10


# ================================================================================ validation
def _mat(X: Any, shape: tuple[int | None, int | None], what: str) -> np.ndarray:
    """``X`` as a finite 2-D float array of ``shape`` (``None``: any size), or DataError naming it.

    A 1-D array is a column when the row count is fixed (``(n,)`` -> ``(n, 1)``); nothing is
    reshaped otherwise, so a transposed matrix is refused, never silently reshaped.
    """
    a = np.asarray(X, dtype=float)
    if a.ndim == 1 and shape[0] is not None and a.size == shape[0] and shape[1] in (None, 1):
        a = a.reshape(-1, 1)
    elif a.ndim == 0 and shape == (1, 1):
        a = a.reshape(1, 1)
    if a.ndim == 1 and a.size == 0 and shape[0] is not None:
        a = a.reshape(shape[0], 0)
    if a.ndim != 2:
        raise DataError(f"{what} must be a 2-D matrix of shape {_shape_text(shape)}, got shape {a.shape}")
    for i, want in enumerate(shape):
        if want is not None and a.shape[i] != want:
            hint = " (transposed?)" if None not in shape and a.shape == shape[::-1] else ""
            raise DataError(f"{what} must have shape {_shape_text(shape)}, got {a.shape}{hint}")
    if not np.all(np.isfinite(a)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise DataError(f"{what} contains a non-finite value at {bad}")
    return a


def _shape_text(shape) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"


def _pos(x: Any, what: str, *, allow_zero: bool = False) -> float:
    """A finite positive float (or >= 0 with ``allow_zero``), or DataError naming the parameter."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise DataError(f"{what} must be a number, got {x!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise DataError(f"{what} must be finite and {'>= 0' if allow_zero else '> 0'}, got {x!r}")
    return v


def _norm2(X: np.ndarray) -> float:
    return float(np.linalg.norm(X, 2)) if X.size else 0.0


# ================================================================================ conditions
@dataclass
class SMOConditions:
    """Existence conditions of SMO fault reconstruction, with the numbers behind each verdict.

    Attributes
    ----------
    n, p, q, h : int
        States, outputs, faults, disturbances.
    rank_M, rank_C, rank_CM, rank_H : int
        Ranks of ``M``, ``C``, ``C M`` and of ``H = [[C A M, C M], [C M, 0]]`` (49).
    zeros : ndarray of complex
        Invariant zeros of ``(A, M, C)``.
    observable, detectable : bool
        Of ``(A, C)``.
    A1, A2, B1, B2, full_rank_M, full_rank_C : bool
        The verdicts (A2 and B2 are the same test: every invariant zero has ``Re < 0``).
    rank_decisions : dict
        Per matrix (``"M"``, ``"C"``, ``"CM"``, ``"H"``): the rank, all singular values and the
        absolute and relative tolerances of the decision (:class:`~fdikit.model.structure.RankDecision`).
    """

    n: int
    p: int
    q: int
    h: int
    rank_M: int
    rank_C: int
    rank_CM: int
    rank_H: int
    zeros: np.ndarray
    observable: bool
    detectable: bool
    full_rank_M: bool
    full_rank_C: bool
    A1: bool
    A2: bool
    B1: bool
    B2: bool
    rank_decisions: dict = field(default_factory=dict)

    @property
    def max_zero_real(self) -> float | None:
        return float(self.zeros.real.max()) if self.zeros.size else None

    @property
    def case(self) -> str:
        """``"single"`` (A1 holds), ``"cascade"`` (B1 holds, A1 not) or ``"none"``."""
        if self.A1:
            return "single"
        return "cascade" if self.B1 else "none"

    def as_dict(self) -> dict:
        return {
            "n": self.n, "p": self.p, "q": self.q, "h": self.h,
            "rank_M": self.rank_M, "rank_C": self.rank_C, "rank_CM": self.rank_CM,
            "rank_H": self.rank_H, "rank_H_needed_B1": self.rank_CM + self.rank_M,
            "zeros_real": [float(z.real) for z in self.zeros],
            "zeros_imag": [float(z.imag) for z in self.zeros],
            "observable": self.observable, "detectable": self.detectable,
            "full_rank_M": self.full_rank_M, "full_rank_C": self.full_rank_C,
            "A1": self.A1, "A2": self.A2, "B1": self.B1, "B2": self.B2, "case": self.case,
            "rank_decisions": {k: v.as_dict() for k, v in self.rank_decisions.items()},
        }

    def require(self) -> str:
        """Raise :class:`ConditionError` naming the first failed condition; else return the case."""
        d = self.as_dict()
        if not self.full_rank_M:
            raise ConditionError("rank M = q", f"rank M = {self.rank_M} < q = {self.q}", d)
        if not self.full_rank_C:
            raise ConditionError("rank C = p", f"rank C = {self.rank_C} < p = {self.p}", d)
        if not self.detectable:
            raise ConditionError("detectability", "(A, C) has an unstable unobservable mode", d)
        if not self.A1 and not self.B1:
            raise ConditionError(
                "B1", f"rank [[CAM, CM], [CM, 0]] = {self.rank_H} but rank CM + rank M = "
                f"{self.rank_CM} + {self.rank_M} = {self.rank_CM + self.rank_M} (and A1 fails: "
                f"rank CM = {self.rank_CM} < rank M = {self.rank_M})", d)
        if not self.B2 or not self.A2:
            bad = ", ".join(f"{z.real:.6g}{z.imag:+.6g}j" for z in self.zeros if z.real >= 0)
            name = "A2" if self.A1 else "B2"
            raise ConditionError(name, f"invariant zeros of (A, M, C) not stable: {bad} "
                                 f"(all zeros: {np.round(self.zeros, 6).tolist()})", d)
        return self.case


def check_conditions(A: Any, M: Any, C: Any, Q: Any = None, *, tol: float | None = None,
                     atol: float | None = None, rtol: float | None = None,
                     zero_margin: float = 1e-9) -> SMOConditions:
    """Check the conditions A1, A2 (Tan & Edwards 2003) and B1, B2 (ng-tan-edwards-kuang, Theorem 1).

    Rank decisions
    --------------
    A singular value of ``X`` (``M``, ``C``, ``C M`` or ``H`` (49)) counts as non-zero when it
    exceeds ``max(atol_X, rtol * sigma_max(X))``. The absolute part ``atol_X`` defaults to
    :data:`RANK_ATOL_SCALE` times the scale of the factors ``X`` is formed from (``||M||``,
    ``||C||``, ``||C|| ||M||``, ``max(||C|| ||A|| ||M||, ||C|| ||M||)``), so a product that is zero
    up to rounding (``C A M = 1e-16`` for unit factors) has rank 0, whatever its own norm; the
    relative part defaults to ``max(rows, cols) * eps``. Each decision, with its singular values
    and tolerances, is in ``rank_decisions``.

    Parameters
    ----------
    A : array_like (n, n)
    M : array_like (n, q)
        Fault directions (a 1-D array of length ``n`` is one fault).
    C : array_like (p, n)
    Q : array_like (n, h), optional
        Disturbance directions (only its size is reported).
    tol : float, optional
        One absolute rank threshold for every decision (overrides ``atol`` and ``rtol``).
    atol : float, optional
        Absolute rank threshold for every decision (default: scaled as above).
    rtol : float, optional
        Relative rank threshold (default ``max(rows, cols) * eps``).
    zero_margin : float
        A zero counts as stable when ``Re(z) < -zero_margin``.

    Returns
    -------
    SMOConditions

    Raises
    ------
    DataError
        A matrix of the wrong shape (named, e.g. a transposed ``M``) or with NaN/inf.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals.smo import check_conditions
    >>> A = np.array([[0.0, 1.0], [-1.0, -1.0]]); M = np.array([[0.0], [1.0]]); C = np.array([[1.0, 0.0]])
    >>> c = check_conditions(A, M, C)
    >>> c.A1, c.B1, c.B2, c.rank_CM
    (False, True, True, 0)
    """
    A = _mat(A, (None, None), "A")
    n = A.shape[0]
    if A.shape != (n, n):
        raise DataError(f"A must be square, got shape {A.shape}")
    M = _mat(M, (n, None), "M")
    C = _mat(C, (None, n), "C")
    p, q = C.shape[0], M.shape[1]
    h = 0 if Q is None else _mat(Q, (n, None), "Q (disturbance directions)").shape[1]
    if q == 0:
        raise DataError("M has no columns: there is no fault to reconstruct")
    nA, nM, nC = _norm2(A), _norm2(M), _norm2(C)
    H = np.block([[C @ A @ M, C @ M], [C @ M, np.zeros((p, q))]])  # ng-tan-edwards-kuang, eq. (49)
    scales = {"M": nM, "C": nC, "CM": nC * nM, "H": max(nC * nA * nM, nC * nM)}
    mats = {"M": M, "C": C, "CM": C @ M, "H": H}
    dec = {}
    for key, X in mats.items():
        if tol is not None:
            dec[key] = rank_decision(X, atol=_pos(tol, "tol", allow_zero=True), rtol=0.0)
        else:
            a = RANK_ATOL_SCALE * scales[key] if atol is None else _pos(atol, "atol", allow_zero=True)
            dec[key] = rank_decision(X, atol=a, rtol=None if rtol is None else _pos(rtol, "rtol",
                                                                                     allow_zero=True))
    rM, rC, rCM, rH = (dec[k].rank for k in ("M", "C", "CM", "H"))
    z = np.asarray(invariant_zeros(A, M, C, np.zeros((p, q))), complex)
    stable = bool(np.all(z.real < -zero_margin)) if z.size else True
    return SMOConditions(
        n=n, p=p, q=q, h=h, rank_M=rM, rank_C=rC, rank_CM=rCM, rank_H=rH, zeros=z,
        observable=bool(is_observable(A, C)), detectable=bool(is_detectable(A, C)),
        full_rank_M=rM == q, full_rank_C=rC == p,
        A1=(rCM == rM == q), A2=stable, B1=(rH == rCM + rM), B2=stable, rank_decisions=dec,
    )


# ================================================================================ Lemma 1
@dataclass
class Lemma1Form:
    """The coordinates of Lemma 1 (ng-tan-edwards-kuang, eqs. (4)-(5)).

    ``x_new = T1 x``, ``f_new = T2 f = col(f1, f2)`` with ``f2`` of size ``r``. In the new
    coordinates ``C = [0 Ttil]`` (``Ttil`` orthogonal), ``M = [[0, 0], [M11, 0], [0, 0], [0, M22]]``
    with row blocks ``(n-p-(q-r), q-r, p-r, r)``.

    Attributes
    ----------
    T1, T1inv : ndarray (n, n)
    T2 : ndarray (q, q)
        Orthogonal.
    A, B, M, Q, C : ndarray
        The matrices in the new coordinates.
    Ttil : ndarray (p, p)
    M11 : ndarray (q-r, q-r), M22 : ndarray (r, r)
    r : int
    """

    T1: np.ndarray
    T1inv: np.ndarray
    T2: np.ndarray
    A: np.ndarray
    B: np.ndarray
    M: np.ndarray
    Q: np.ndarray
    C: np.ndarray
    Ttil: np.ndarray
    M11: np.ndarray
    M22: np.ndarray
    r: int


def _complete_svd(X: np.ndarray, tol: float | None):
    U, s, Vt = np.linalg.svd(X, full_matrices=True)
    k = rank(X, tol) if X.size else 0
    return U, s, Vt, k


def lemma1_form(A: Any, B: Any, M: Any, C: Any, Q: Any, *, tol: float | None = None,
                rank_CM: int | None = None) -> Lemma1Form:
    """Lemma 1 of ng-tan-edwards-kuang by SVD / QR steps (no inverse of an ill-conditioned matrix).

    Steps: (i) SVD of ``C`` gives an orthonormal basis ``Vn`` of its kernel; (ii) SVD of ``C M``
    gives the orthogonal output rotation ``Ttil`` and fault rotation ``T2`` that put the rank-``r``
    part of ``C M`` in the last rows/columns; (iii) a shear ``x1 -> x1 - M1b M22^-1 x2`` (``M22``
    diagonal of singular values) clears the ``f2`` columns of ``M1``; (iv) a QR of the remaining
    block with a row permutation puts ``M11`` at the bottom of the non-output states.

    Parameters
    ----------
    A : (n, n), B : (n, m), M : (n, q), C : (p, n), Q : (n, h) array_like
    tol : float, optional
        Rank tolerance.
    rank_CM : int, optional
        The rank of ``C M`` decided elsewhere (:func:`check_conditions`), used instead of a new
        decision so that both agree.

    Returns
    -------
    Lemma1Form

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.residuals.smo import lemma1_form
    >>> A = np.array([[0.0, 1.0], [-1.0, -1.0]]); C = np.array([[1.0, 0.0]])
    >>> F = lemma1_form(A, np.zeros((2, 0)), [[0.0], [1.0]], C, np.zeros((2, 0)))
    >>> F.r, bool(np.allclose(F.C[:, :1], 0.0))
    (0, True)
    """
    A = _mat(A, (None, None), "A")
    n = A.shape[0]
    if A.shape != (n, n):
        raise DataError(f"A must be square, got shape {A.shape}")
    B = _mat(B, (n, None), "B")
    M = _mat(M, (n, None), "M")
    Q = _mat(Q, (n, None), "Q")
    C = _mat(C, (None, n), "C")
    p, q = C.shape[0], M.shape[1]
    Uc, sc, Vtc, kc = _complete_svd(C, tol)
    if kc != p:
        raise ConditionError("rank C = p", f"rank C = {kc} < p = {p}", {"singular_values": sc})
    Vn = Vtc[p:].T  # (n, n-p) kernel of C
    Cpinv = Vtc[:p].T @ np.diag(1.0 / sc[:p]) @ Uc.T  # right inverse, conditioned like C
    CM = C @ M
    Um, _sm, Vtm, r = _complete_svd(CM, tol)
    if rank_CM is not None:
        r = int(rank_CM)
    Ttil = np.hstack([Um[:, r:], Um[:, :r]])  # range of CM in the last r output coordinates
    T2 = np.vstack([Vtm[r:], Vtm[:r]])  # f2 = last r components
    # stage 1: x -> [Vn^T x; Ttil^T C x]
    S1 = np.vstack([Vn.T, Ttil.T @ C])
    S1i = np.hstack([Vn, Cpinv @ Ttil])
    Mn = S1 @ M @ T2.T
    nm, qr = n - p, q - r
    M22 = Mn[n - r:, qr:]
    # stage 2: shear the f2 columns out of the non-output rows
    K = np.zeros((nm, p))
    if r:
        K[:, p - r:] = -np.linalg.solve(M22.T, Mn[:nm, qr:].T).T
    S2 = np.eye(n)
    S2[:nm, nm:] = K
    S2i = np.eye(n)
    S2i[:nm, nm:] = -K
    M1a = (S2 @ Mn)[:nm, :qr]
    # stage 3: QR of M1a, M11 to the bottom of the non-output states
    if qr:
        Qm, _Rm = np.linalg.qr(M1a, mode="complete")
        perm = np.r_[np.arange(qr, nm), np.arange(qr)]
        X = Qm.T[perm]
    else:
        X = np.eye(nm)
    S3 = np.eye(n)
    S3[:nm, :nm] = X
    S3i = S3.T.copy()
    T1 = S3 @ S2 @ S1
    T1inv = S1i @ S2i @ S3i
    An, Bn, Mf, Qn, Cn = T1 @ A @ T1inv, T1 @ B, T1 @ M @ T2.T, T1 @ Q, C @ T1inv
    M11 = Mf[nm - qr:nm, :qr]
    M22 = Mf[n - r:, qr:]
    return Lemma1Form(T1, T1inv, T2, An, Bn, Mf, Qn, Cn, Cn[:, nm:], M11, M22, r)


# ================================================================================ augmentation
@dataclass
class AugmentedSystem:
    """The augmented system (7)-(10): state ``[xi~; x~]`` in Lemma-1 coordinates for ``x~``.

    The state is ordered ``[xi~ (h); x~1 (n~-p); x~2 (p)]`` so that the last ``p`` states are the
    output states. ``n = h + n~``.
    """

    A: np.ndarray
    B: np.ndarray
    M: np.ndarray
    Q: np.ndarray
    C: np.ndarray
    A_Omega: np.ndarray
    B_Omega: np.ndarray
    l1: Lemma1Form

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def p(self) -> int:
        return self.C.shape[0]


def augment(l1: Lemma1Form, A_Omega: np.ndarray, B_Omega: np.ndarray) -> AugmentedSystem:
    """Augment the Lemma-1 form with the disturbance filter (3): ng-tan-edwards-kuang, eqs. (7)-(10)."""
    nt = l1.A.shape[0]
    h = l1.Q.shape[1]
    A = np.block([[A_Omega, np.zeros((h, nt))], [l1.Q, l1.A]])  # ng-tan-edwards-kuang, eq. (7)
    B = np.vstack([np.zeros((h, l1.B.shape[1])), l1.B])
    M = np.vstack([np.zeros((h, l1.M.shape[1])), l1.M])
    Qa = np.vstack([B_Omega, np.zeros((nt, h))])
    C = np.hstack([np.zeros((l1.C.shape[0], h)), l1.C])  # ng-tan-edwards-kuang, eq. (8)
    return AugmentedSystem(A, B, M, Qa, C, A_Omega, B_Omega, l1)


# ================================================================================ Lemma 4
@dataclass
class CanonicalForm:
    """The canonical form of Lemma 4 (ng-tan-edwards-kuang, eqs. (11)-(13)).

    ``x_can = T5 x_aug``. State blocks ``(n1, n2, n3, n4, n5) = (n-p-(pbar-r), pbar-q, q-r, p-r, r)``.

    Attributes
    ----------
    T5, T5inv : ndarray (n, n)
    A, B, M, Q, C : ndarray
    T : ndarray (p, p)
        Orthogonal, ``C = [0 T]``.
    pbar, r, q : int
    blocks : tuple of int
        ``(n1, n2, n3, n4, n5)``.
    Ao : ndarray (pbar-r, pbar-r)
        ``[A42^o A43^o]`` (13), square and invertible.
    M11, M22 : ndarray
    """

    T5: np.ndarray
    T5inv: np.ndarray
    A: np.ndarray
    B: np.ndarray
    M: np.ndarray
    Q: np.ndarray
    C: np.ndarray
    T: np.ndarray
    pbar: int
    r: int
    q: int
    blocks: tuple[int, int, int, int, int]
    Ao: np.ndarray
    M11: np.ndarray
    M22: np.ndarray
    rank_decisions: dict = field(default_factory=dict)

    def structure_residuals(self) -> dict[str, float]:
        """Largest magnitude of every block that (11)-(13) says is zero."""
        n1, n2, n3, n4, _n5 = self.blocks
        nn = n1 + n2 + n3
        k = n2 + n3
        A, M, Q, C = self.A, self.M, self.Q, self.C
        qr = self.q - self.r
        out = {
            "A41": np.abs(A[nn:nn + n4, :n1]).max(initial=0.0),  # (11)
            "A42A43_top": np.abs(A[nn:nn + n4 - k, n1:nn]).max(initial=0.0),  # (13)
            "M_block1_2": np.abs(M[:n1 + n2]).max(initial=0.0),  # (12)
            "M_block3_f2": np.abs(M[n1 + n2:nn, qr:]).max(initial=0.0),
            "M_block4": np.abs(M[nn:nn + n4]).max(initial=0.0),
            "M_block5_f1": np.abs(M[nn + n4:, :qr]).max(initial=0.0),
            "Q_output": np.abs(Q[nn:]).max(initial=0.0),
            "C_nonoutput": np.abs(C[:, :nn]).max(initial=0.0),
            "T_orthogonality": np.abs(self.T @ self.T.T - np.eye(self.T.shape[0])).max(initial=0.0),
        }
        return {key: float(v) for key, v in out.items()}


def lemma4_form(aug: AugmentedSystem, *, tol: float | None = None) -> CanonicalForm:
    """Lemma 4 of ng-tan-edwards-kuang (proof in its appendix VI-C), with orthogonal X3, X4, X6.

    ``R1 = [Q~21 A~31 A~32]`` (the first ``p-r`` rows of ``A3``) is rotated by its SVD,
    ``X4 R1 X3^T = [[0, 0], [0, U]]`` (51); then a QR of ``[M_a12; M_a13]`` gives the orthogonal
    ``X6`` and the left inverse ``X5`` (triangular solve) of ``T4``.

    Parameters
    ----------
    aug : AugmentedSystem
    tol : float, optional
        Absolute rank threshold; default ``max(RANK_ATOL_SCALE * scale, rtol * sigma_max)`` with
        ``scale = ||A||`` for ``R1`` and ``||M||`` for ``[M_a12; M_a13]`` (decisions in
        ``rank_decisions``).

    Returns
    -------
    CanonicalForm

    Raises
    ------
    ConditionError
        ``"B1"`` when ``rank [M_a12; M_a13] < q - r`` (i.e. ``A~32`` is column-rank deficient).
    """
    A, B, M, Q, C = aug.A, aug.B, aug.M, aug.Q, aug.C
    n, p, q = A.shape[0], C.shape[0], M.shape[1]
    r = aug.l1.r
    nm = n - p
    qr = q - r
    R1 = A[nm:nm + p - r, :nm]  # ng-tan-edwards-kuang, eq. (50)
    dec = {}

    def decide(X, scale, key):
        d = rank_decision(X, atol=tol, rtol=0.0) if tol is not None else \
            rank_decision(X, atol=RANK_ATOL_SCALE * scale)
        dec[key] = d
        return d.rank

    if R1.size:
        Ur, _sr, Vtr = np.linalg.svd(R1, full_matrices=True)
        k = decide(R1, _norm2(A), "R1")
    else:
        Ur, _sr, Vtr, k = np.eye(p - r), np.zeros(0), np.eye(nm), 0
    X4 = np.vstack([Ur[:, k:].T, Ur[:, :k].T])
    X3 = np.vstack([Vtr[k:], Vtr[:k]])
    T3 = np.eye(n)
    T3[:nm, :nm] = X3
    T3[nm:nm + p - r, nm:nm + p - r] = X4
    Ma = T3 @ M
    n1 = nm - k
    Mst = Ma[n1:nm, :qr]
    Ma11 = Ma[:n1, :qr]
    if qr:
        rMst = decide(Mst, _norm2(M), "M_a12_a13") if Mst.size else 0
        if k < qr or rMst < qr:
            raise ConditionError("B1", f"rank [M_a12; M_a13] = {rMst} < "
                                 f"q - r = {qr}: A~32 is not of full column rank (Lemma 3)",
                                 {"rank_R1": k, "q_minus_r": qr,
                                  "rank_decisions": {key: d.as_dict() for key, d in dec.items()}})
        Qf, Rf = np.linalg.qr(Mst, mode="complete")
        perm = np.r_[np.arange(qr, k), np.arange(qr)]
        X6 = Qf.T[perm]
        X5 = np.linalg.solve(Rf[:qr], Qf[:, :qr].T)  # X5 Mst = I (left inverse)
    else:
        X6 = np.eye(k)
        X5 = np.zeros((0, k))
    X7 = np.eye(nm)
    X7[:n1, n1:] = -Ma11 @ X5
    X7[n1:, n1:] = X6
    X7i = np.eye(nm)
    X7i[:n1, n1:] = Ma11 @ X5 @ X6.T
    X7i[n1:, n1:] = X6.T
    T4 = np.eye(n)
    T4[:nm, :nm] = X7
    T4i = np.eye(n)
    T4i[:nm, :nm] = X7i
    T5 = T4 @ T3
    T5i = T3.T @ T4i
    Ab, Bb, Mb, Qb, Cb = T5 @ A @ T5i, T5 @ B, T5 @ M, T5 @ Q, C @ T5i
    pbar = k + r
    n2, n3, n4, n5 = pbar - q, qr, p - r, r
    Ao = Ab[nm + n4 - k:nm + n4, n1:nm]
    M11 = Mb[n1 + n2:nm, :qr]
    M22 = Mb[nm + n4:, qr:]
    return CanonicalForm(T5, T5i, Ab, Bb, Mb, Qb, Cb, Cb[:, nm:], pbar, r, q, (n1, n2, n3, n4, n5),
                         Ao, M11, M22, dec)


# ================================================================================ fictitious system
@dataclass
class FictitiousSystem:
    """The fictitious relative-degree-one system (29)-(36) in the coordinates (33)-(36).

    State ``x_bar = Tcal [e1; v_f]`` of size ``nbar = n - p + r``, output ``y_bar = [Z v1; v_f]``
    of size ``pbar``.

    Attributes
    ----------
    A, M, C, Q : ndarray
        ``(A_bar, M_bar, C_bar, Q_bar)``; ``C = [0 Tbar]``, ``M = [0; M2]`` with ``Mo`` (bottom
        ``q`` rows of ``M2``) invertible.
    Af : ndarray (r, r)
        The low-pass filter of (28) (``-Af`` stable).
    Z : ndarray (pbar-r, p-r)
        ``[0 I]`` of (27).
    Tcal : ndarray (nbar, nbar)
    """

    A: np.ndarray
    M: np.ndarray
    C: np.ndarray
    Q: np.ndarray
    Af: np.ndarray
    Z: np.ndarray
    Tcal: np.ndarray


def fictitious_system(cf: CanonicalForm, L: np.ndarray, Af: np.ndarray) -> FictitiousSystem:
    """Form the fictitious system of ng-tan-edwards-kuang, eqs. (25)-(36).

    Note: eq. (32) prints ``Mcal = [-(M1 + L M2); 0]``; the filter equation (28) carries
    ``A_f M22 f2``, so the second block row is ``[0, A_f M22]`` (then (34) follows).

    Parameters
    ----------
    cf : CanonicalForm
    L : ndarray (n-p, p)
        Primary sliding gain.
    Af : ndarray (r, r)

    Returns
    -------
    FictitiousSystem
    """
    _n1, _n2, _n3, n4, _n5 = cf.blocks
    n, p, r, q = cf.A.shape[0], cf.C.shape[0], cf.r, cf.q
    nm = n - p
    k = cf.pbar - r
    A1, A3 = cf.A[:nm, :nm], cf.A[nm:, :nm]
    M1, M2 = cf.M[:nm], cf.M[nm:]
    Q1 = cf.Q[:nm]
    A311, A312 = A3[:n4], A3[n4:]
    Z = np.hstack([np.zeros((k, n4 - k)), np.eye(k)])  # ng-tan-edwards-kuang, eq. (27)
    nb = nm + r
    Acal = np.block([[A1 + L @ A3, np.zeros((nm, r))], [-Af @ A312, -Af]])  # ng-tan-edwards-kuang, eq. (31)
    Mcal = np.vstack([-(M1 + L @ M2), np.hstack([np.zeros((r, q - r)), Af @ cf.M22])])  # (32)+(28)
    Ccal = np.block([[-Z @ A311, np.zeros((k, r))], [np.zeros((r, nm)), np.eye(r)]])  # eq. (32)
    Qcal = np.vstack([-Q1, np.zeros((r, Q1.shape[1]))])  # ng-tan-edwards-kuang, eq. (31)
    Tcal = np.eye(nb)
    Tcal[:nm, nm:] = np.linalg.solve(Af.T, L[:, p - r:].T).T if r else np.zeros((nm, 0))
    Tcali = np.eye(nb)
    Tcali[:nm, nm:] = -Tcal[:nm, nm:]
    return FictitiousSystem(Tcal @ Acal @ Tcali, Tcal @ Mcal, Ccal @ Tcali, Tcal @ Qcal, Af, Z, Tcal)


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


# ================================================================================ runtime kernel
def _mv_py(A, x, out, add):
    """``out = A x`` (``add=False``) or ``out += A x``; no allocation."""
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(A.shape[1]):
            acc += A[i, j] * x[j]
        out[i] = out[i] + acc if add else acc


_mv = njit(cache=True, inline="always")(_mv_py)


def _smo_step_py(h, A, B, C, Gl, Gn, rho, delta, SV, Smu, u, y, x, e, started, nu, dx, xt, w, wt,
                 implicit):
    """One step of ``x' = A x + B u - Gl e + Gn nu``, ``nu = -rho e / (||e|| + delta)``.

    Explicit Euler for the linear part; the switched term (24) is taken at the new time
    (implicit): with ``S = C Gn = Po^-1`` s.p.d. (``S = SV diag(Smu) SV^T``) and
    ``w = C (x + h (A x + B u - Gl e)) - y_new``, solve ``e+ = w - h rho S e+ / (||e+|| + delta)``
    for ``s = ||e+||`` by a safeguarded Newton iteration (bracket ``[0, ||w||]``, unique root).
    On the first sample the state is kept and ``e = C x - y``. ``dx, xt, w, wt`` are work arrays.

    With ``implicit=False`` the plain explicit Euler step is used instead: ``e = C x - y`` and
    ``nu(e)`` from the current state (output), then ``x += h (A x + B u - Gl e + Gn nu)``.
    """
    n, p = A.shape[0], C.shape[0]
    if not implicit:
        _mv(C, x, e, False)
        ne = 0.0
        for i in range(p):
            e[i] -= y[i]
            ne += e[i] * e[i]
        ne = np.sqrt(ne)
        for i in range(p):
            nu[i] = -rho * e[i] / (ne + delta)  # ng-tan-edwards-kuang, eq. (24)
        _mv(A, x, dx, False)
        _mv(Gn, nu, dx, True)
        for i in range(n):
            acc = 0.0
            for j in range(p):
                acc += Gl[i, j] * e[j]
            dx[i] -= acc
        if B.shape[1] > 0:
            _mv(B, u, dx, True)
        for i in range(n):
            x[i] += h * dx[i]
        return
    if started:
        _mv(A, x, dx, False)
        for i in range(n):
            acc = 0.0
            for j in range(p):
                acc += Gl[i, j] * e[j]
            dx[i] -= acc
        if B.shape[1] > 0:
            _mv(B, u, dx, True)
        for i in range(n):
            xt[i] = x[i] + h * dx[i]
        hh = h
    else:
        for i in range(n):
            xt[i] = x[i]
        hh = 0.0
    _mv(C, xt, w, False)
    nw2 = 0.0
    for i in range(p):
        w[i] -= y[i]
    for i in range(p):
        acc = 0.0
        for j in range(p):
            acc += SV[j, i] * w[j]
        wt[i] = acc
        nw2 += acc * acc
    nw = np.sqrt(nw2)
    if hh > 0.0 and nw > 0.0:
        g = hh * rho
        lo, hi = 0.0, nw
        # start: root of the scalar problem with the smallest eigenvalue (an upper bound)
        mu0 = Smu[0]
        b = delta + g * mu0 - nw
        s = 0.5 * (-b + np.sqrt(b * b + 4.0 * nw * delta))
        for _ in range(100):
            c = g / (s + delta)
            n2 = 0.0
            dn = 0.0
            for i in range(p):
                d = 1.0 + c * Smu[i]
                z = wt[i] / d
                n2 += z * z
                dn += z * z * Smu[i] / d
            N = np.sqrt(n2)
            F = s - N
            if F > 0.0:
                hi = s
            else:
                lo = s
            if abs(F) <= 1e-14 * (nw + delta) or hi - lo <= 1e-15 * (nw + delta):
                break
            dF = 1.0 - (dn * c / (s + delta)) / N if N > 0.0 else 1.0
            sn = s - F / dF if dF > 0.0 else -1.0
            if not (lo < sn < hi):
                sn = 0.5 * (lo + hi)
            s = sn
        c = g / (s + delta)
        for i in range(p):
            wt[i] = wt[i] / (1.0 + c * Smu[i])
        _mv(SV, wt, e, False)
    else:
        for i in range(p):
            e[i] = w[i]
    ne = 0.0
    for i in range(p):
        ne += e[i] * e[i]
    ne = np.sqrt(ne)
    for i in range(p):
        nu[i] = -rho * e[i] / (ne + delta)  # ng-tan-edwards-kuang, eq. (24)
    if started:
        _mv(Gn, nu, dx, True)
        for i in range(n):
            x[i] += h * dx[i]


_smo_step = njit(cache=True, inline="always")(_smo_step_py)


def _status_py(e, SV, Smu, delta, level, Vprev, started, settle_n):
    """Sliding status of one observer after its step; updates ``Vprev`` (``[e^T Po e, hold]``).

    ``SLIDING`` while ``||nu|| / rho = ||e|| / (||e|| + delta) <= level`` (inside the boundary
    layer); otherwise ``NOT_SLIDING`` while the Lyapunov function ``e^T Po e`` (``Po = S^-1``)
    decreases (reaching) and ``SATURATED`` when it does not (the injection is at its cap and
    cannot hold the error). After a sample outside the layer, the status stays ``NOT_SLIDING``
    for ``settle_n`` more samples inside it (``Vprev[1]`` counts them down): the reduced-order
    error that a loss of sliding leaves decays only with the sliding motion, so ``fhat`` is the
    equivalent injection again before it is the fault again.
    """
    p = e.shape[0]
    if p == 0:
        return 0
    ne = 0.0
    V = 0.0
    for i in range(p):
        ne += e[i] * e[i]
        acc = 0.0
        for j in range(p):
            acc += SV[j, i] * e[j]
        V += acc * acc / Smu[i]
    ne = np.sqrt(ne)
    code = 0
    if ne > level * (ne + delta):
        code = 1 if (not started or V < Vprev[0]) else 2
        Vprev[1] = settle_n
    elif Vprev[1] > 0.0:
        Vprev[1] -= 1.0
        code = 1
    Vprev[0] = V
    return code


_status = njit(cache=True, inline="always")(_status_py)


def _kernel_py(h, cascade, A1, B1, C1, Gl1, Gn1, rho1, del1, S1V, S1mu, Tv, r, Zsel, Af,
               A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, Wf,
               U, Y, x1, e1, x2, e2, vf, started, out, implicit, level, a_lp, flp, V1p, V2p,
               settle_n):
    """Fixed-step integration of the primary and secondary (or single) observers.

    Per sample ``k``: primary step with ``y[k]`` -> ``nu`` (15)-(18), (24); ``v = T^T Po^-1 nu``
    (23); ``ybar = [Z v1; v_f]`` with ``v_f`` advanced by Euler (27)-(28); secondary step with
    ``ybar`` (37)-(39); ``f^ = Wf nubar``, low-passed by ``flp = a_lp flp + (1 - a_lp) f^`` when
    ``a_lp > 0``. ``out[run, k]`` holds ``q`` reconstructions, then the combined, primary and
    secondary sliding status (:func:`_status`).
    """
    runs, T = Y.shape[0], Y.shape[1]
    n1, p1 = A1.shape[0], C1.shape[0]
    n2, p2 = A2.shape[0], C2.shape[0]
    q = Wf.shape[0]
    pr = p1 - r
    ybar = np.zeros(p2)
    nu1 = np.zeros(p1)
    nu2 = np.zeros(p2)
    v = np.zeros(p1)
    dx1, xt1, w1, wt1 = np.zeros(n1), np.zeros(n1), np.zeros(p1), np.zeros(p1)
    dx2, xt2, w2, wt2 = np.zeros(n2), np.zeros(n2), np.zeros(p2), np.zeros(p2)
    dvf = np.zeros(r)
    for run in range(runs):
        for k in range(T):
            u = U[run, k]
            st0 = started[run]
            c1 = 0
            if cascade:
                _smo_step(h, A1, B1, C1, Gl1, Gn1, rho1, del1, S1V, S1mu, u, Y[run, k],
                          x1[run], e1[run], st0, nu1, dx1, xt1, w1, wt1,
                          implicit)
                c1 = _status(e1[run], S1V, S1mu, del1, level, V1p[run], st0, settle_n)
                _mv(Tv, nu1, v, False)  # ng-tan-edwards-kuang, eq. (23)
                for i in range(Zsel.shape[0]):
                    ybar[i] = v[Zsel[i]]  # ng-tan-edwards-kuang, eq. (27)
                if r > 0:
                    if st0:
                        for i in range(r):
                            acc = 0.0
                            for j in range(r):
                                acc += Af[i, j] * (v[pr + j] - vf[run, j])
                            dvf[i] = acc
                        for i in range(r):
                            vf[run, i] += h * dvf[i]  # ng-tan-edwards-kuang, eq. (28)
                    for i in range(r):
                        ybar[p2 - r + i] = vf[run, i]
                _smo_step(h, A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, u, ybar,
                          x2[run], e2[run], st0, nu2, dx2, xt2, w2, wt2,
                          implicit)
            else:
                _smo_step(h, A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, u, Y[run, k],
                          x2[run], e2[run], st0, nu2, dx2, xt2, w2, wt2,
                          implicit)
            c2 = _status(e2[run], S2V, S2mu, del2, level, V2p[run], st0, settle_n)
            started[run] = True
            for i in range(q):
                acc = 0.0
                for j in range(p2):
                    acc += Wf[i, j] * nu2[j]
                # f^ = W Tbar^-1 Pobar^-1 nubar_eq
                if a_lp > 0.0:
                    if st0:
                        flp[run, i] = a_lp * flp[run, i] + (1.0 - a_lp) * acc
                    else:
                        flp[run, i] = acc
                    out[run, k, i] = flp[run, i]
                else:
                    out[run, k, i] = acc
            out[run, k, q] = float(max(c1, c2))
            out[run, k, q + 1] = float(c1)
            out[run, k, q + 2] = float(c2)


_kernel = njit(cache=True)(_kernel_py)


# ================================================================================ design object
@dataclass
class SlidingModeReconstructor(ResidualGenerator):
    """Runtime of the SMO fault reconstructor: plain matrices, fixed-step integration.

    Produced by :func:`design_reconstructor`. Inputs: the model's control channels ``u_names``
    and measured outputs ``y_names``, sampled every ``dt`` seconds (the integration step).
    Outputs: ``fhat:<fault>``, the reconstruction of each fault in the model's fault units, then
    the sliding status ``sliding_status`` (the worse of the two observers),
    ``sliding_status:primary`` and ``sliding_status:secondary``, per sample:
    ``0`` sliding (:data:`SLIDING`: the injection is inside its boundary layer, ``||nu|| <=
    level * rho``, so ``fhat`` is the equivalent injection), ``1`` not sliding
    (:data:`NOT_SLIDING`: reaching, the error is outside the layer but falling; or recovering:
    back in the layer for less than ``settle`` seconds after a loss) and ``2``
    saturated (:data:`SATURATED`: the injection is at its cap and the error is not falling: the
    gain is too small for the fault and ``fhat`` is clipped). A :class:`~fdikit.monitor.Decision`
    on ``sliding_status`` with ``level=1`` announces every loss of sliding as an event;
    :func:`sliding_episodes` lists them from a batch result.

    Attributes
    ----------
    cascade : bool
        Two observers (relative degree > 1) or one (A1 holds).
    primary : dict of ndarray
        ``A, B, C, Gl, Gn, rho, delta`` of the primary observer (canonical coordinates).
    secondary : dict of ndarray
        ``A, B, C, Gl, Gn, rho, delta`` of the secondary (or single) observer.
    Tv : ndarray (p, p)
        ``T^T Po^-1`` mapping the primary injection to ``v`` (23).
    Zsel : ndarray of int
        Components of ``v`` forming ``Z v1`` (27).
    Af : ndarray (r, r)
    Wf : ndarray (q, pbar)
        ``T2^T W Tbar^-1 Pobar^-1``: secondary injection -> fault (original fault coordinates).
    r : int
    dt : float
        Step (s).
    info : dict
        Case, conditions, ranks, pbar, L2 bound, H-infinity check, gains and the reconstructible
        range, noise design, solver records, timings (see :func:`design_reconstructor`).
    scheme : {"implicit", "explicit"}
        Treatment of the switched term in the Euler step (see :func:`integrate_observers`).
    level : float
        Boundary-layer level of the status: sliding while ``||nu|| <= level * rho`` (0 < level < 1).
    lpf_tau : float
        Time constant (s) of the first-order low-pass on ``fhat`` (0: none).
    settle : float
        After a loss of sliding, the status stays "not sliding" until the error has stayed inside
        the boundary layer this long (s): the time the sliding motion needs to wash out what the
        loss left (:func:`design_reconstructor` sets three time constants of its slowest mode).
    """

    cascade: bool
    primary: dict
    secondary: dict
    Tv: np.ndarray
    Zsel: np.ndarray
    Af: np.ndarray
    Wf: np.ndarray
    r: int
    dt: float
    u_names: list[str]
    y_names: list[str]
    output_names: list[str]
    info: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict, repr=False)
    scheme: str = "implicit"
    level: float = 0.9
    lpf_tau: float = 0.0
    settle: float = 0.0

    STATUS_NAMES = ("sliding_status", "sliding_status:primary", "sliding_status:secondary")

    def __post_init__(self):
        if self.scheme not in ("implicit", "explicit"):
            raise ModelError(f"scheme must be 'implicit' or 'explicit', got {self.scheme!r}")
        self.dt = _pos(self.dt, "dt")
        self.level = _pos(self.level, "level")
        if not self.level < 1.0:
            raise DataError(f"level must be in (0, 1), got {self.level}")
        self.lpf_tau = _pos(self.lpf_tau, "lpf_tau", allow_zero=True)
        self.settle = _pos(self.settle, "settle", allow_zero=True)
        self.u_names, self.y_names = list(self.u_names), list(self.y_names)
        m, py = len(self.u_names), len(self.y_names)
        for key, d in (("primary", self.primary), ("secondary", self.secondary)):
            d["rho"] = _pos(d["rho"], "rho" if key == "primary" else "rho2")
            d["delta"] = _pos(d["delta"], "delta" if key == "primary" else "delta2")
            A = _mat(d["A"], (None, None), f"{key} A")
            n = A.shape[0]
            if A.shape != (n, n):
                raise DataError(f"{key} A must be square, got {A.shape}")
            C = _mat(d["C"], (None, n), f"{key} C")
            pk = C.shape[0]
            d["A"], d["C"] = np.ascontiguousarray(A), np.ascontiguousarray(C)
            d["B"] = np.ascontiguousarray(_mat(d["B"], (n, m), f"{key} B"))
            d["Gl"] = np.ascontiguousarray(_mat(d["Gl"], (n, pk), f"{key} Gl"))
            d["Gn"] = np.ascontiguousarray(_mat(d["Gn"], (n, pk), f"{key} Gn"))
        n1, p1 = self.primary["C"].shape[1], self.primary["C"].shape[0]
        n2, p2 = self.secondary["C"].shape[1], self.secondary["C"].shape[0]
        self.r = int(self.r)
        self.Zsel = np.ascontiguousarray(np.asarray(self.Zsel, dtype=np.int64).reshape(-1))
        if self.cascade:
            if p1 != py:
                raise DataError(f"the primary observer has {p1} outputs but y_names lists {py}")
            self.Tv = np.ascontiguousarray(_mat(self.Tv, (p1, p1), "Tv"))
            if not 0 <= self.r <= min(p1, p2) or self.Zsel.size != p2 - self.r:
                raise DataError(f"r = {self.r} and {self.Zsel.size} Zsel entries do not fit a secondary "
                                f"observer with {p2} outputs and a primary with {p1}")
            if self.Zsel.size and (self.Zsel.min() < 0 or self.Zsel.max() >= p1):
                raise DataError(f"Zsel must index the {p1} primary injections, got {self.Zsel.tolist()}")
            self.Af = np.ascontiguousarray(_mat(self.Af, (self.r, self.r), "Af"))
        else:
            if p2 != py:
                raise DataError(f"the observer has {p2} outputs but y_names lists {py}")
            if n1 or p1 or self.r or self.Zsel.size:
                raise DataError("a single-observer reconstructor has an empty primary observer, r = 0 "
                                "and no Zsel")
            self.Tv = np.zeros((0, 0))
            self.Af = np.zeros((0, 0))
        self.Wf = np.ascontiguousarray(_mat(self.Wf, (None, p2), "Wf"))
        q = self.Wf.shape[0]
        names = list(self.output_names)
        if len(names) == q:
            names += list(self.STATUS_NAMES)
        if len(names) != q + 3 or tuple(names[q:]) != self.STATUS_NAMES:
            raise DataError(f"output_names must list the {q} fault reconstructions (then the status "
                            f"channels {list(self.STATUS_NAMES)}), got {list(self.output_names)}")
        self.output_names = names
        self.output_units = None
        self._state: dict[str, np.ndarray] | None = None
        for d in (self.primary, self.secondary):
            C, Gn = d["C"], d["Gn"]
            if C.size:
                S = 0.5 * (C @ Gn + (C @ Gn).T)
                mu, V = np.linalg.eigh(S)
                if mu.min() <= 0:
                    raise ConditionError("LMI", f"C Gn is not positive definite (eigenvalues {mu})")
                d["SV"], d["Smu"] = np.ascontiguousarray(V), mu
            else:
                d["SV"], d["Smu"] = np.zeros((0, 0)), np.zeros(0)
        self._dims = (n1, p1, n2, p2)

    @property
    def fault_names(self) -> list[str]:
        """The reconstructed faults (``fhat:<fault>`` without the prefix)."""
        return [n.removeprefix("fhat:") for n in self.output_names[:self.Wf.shape[0]]]

    @property
    def n_faults(self) -> int:
        return int(self.Wf.shape[0])

    # ------------------------------------------------------------------ persistence
    _MATS = ("A", "B", "C", "Gl", "Gn")

    def to_dict(self) -> dict:
        """The runtime (plain gains and matrices) as a JSON-serialisable dict.

        The design-time ``details`` (canonical forms, LMI solutions) are not included; ``info``
        is kept with arrays converted to lists. :meth:`from_dict` rebuilds an identical runtime.
        """
        def obs(d):
            out = {k: np.asarray(d[k]).tolist() for k in self._MATS}
            out["shapes"] = {k: list(np.asarray(d[k]).shape) for k in self._MATS}
            out.update(rho=float(d["rho"]), delta=float(d["delta"]))
            return out

        def plain(v):
            if isinstance(v, dict):
                return {str(k): plain(x) for k, x in v.items()}
            if isinstance(v, list | tuple):
                return [plain(x) for x in v]
            if isinstance(v, np.ndarray):
                if v.dtype.kind == "c":
                    return {"real": v.real.tolist(), "imag": v.imag.tolist()}
                return v.tolist()
            if isinstance(v, (np.floating, np.integer, np.bool_)):
                return v.item()
            return v

        return {
            "kind": "fdikit.SlidingModeReconstructor", "version": 2, "cascade": self.cascade,
            "primary": obs(self.primary), "secondary": obs(self.secondary),
            "Tv": self.Tv.tolist(), "Tv_shape": list(self.Tv.shape), "Zsel": self.Zsel.tolist(),
            "Af": self.Af.tolist(), "Af_shape": list(self.Af.shape), "Wf": self.Wf.tolist(),
            "Wf_shape": list(self.Wf.shape),
            "r": self.r, "dt": self.dt, "u_names": self.u_names, "y_names": self.y_names,
            "output_names": self.output_names, "scheme": self.scheme, "level": self.level,
            "lpf_tau": self.lpf_tau, "settle": self.settle, "info": plain(self.info),
        }

    @classmethod
    def from_dict(cls, d: dict) -> SlidingModeReconstructor:
        """Rebuild a runtime saved by :meth:`to_dict` (also version 1, without the status channels).

        Examples
        --------
        >>> import json
        >>> from fdikit.systems import aircraft
        >>> from fdikit.residuals.smo import SlidingModeReconstructor, design_reconstructor
        >>> rec = design_reconstructor(aircraft.model(), hinf_check=False)
        >>> back = SlidingModeReconstructor.from_dict(json.loads(json.dumps(rec.to_dict())))
        >>> bool((back.Wf == rec.Wf).all()), back.output_names[0], back.output_names[1]
        (True, 'fhat:actuator:rudder_cmd', 'sliding_status')
        """
        if d.get("kind") != "fdikit.SlidingModeReconstructor":
            raise ModelError(f"not a saved SlidingModeReconstructor (kind = {d.get('kind')!r})")

        def obs(o):
            out = {k: np.asarray(o[k], float).reshape(o["shapes"][k]) for k in cls._MATS}
            out.update(rho=o["rho"], delta=o["delta"])
            return out

        names = list(d["output_names"])
        q = int(d["Wf_shape"][0]) if "Wf_shape" in d else len(names)
        return cls(
            cascade=bool(d["cascade"]), primary=obs(d["primary"]), secondary=obs(d["secondary"]),
            Tv=np.asarray(d["Tv"], float).reshape(d["Tv_shape"]),
            Zsel=np.asarray(d["Zsel"], dtype=np.int64),
            Af=np.asarray(d["Af"], float).reshape(d["Af_shape"]),
            Wf=np.asarray(d["Wf"], float).reshape(q, -1), r=int(d["r"]),
            dt=float(d["dt"]), u_names=list(d["u_names"]), y_names=list(d["y_names"]),
            output_names=names, info=dict(d.get("info", {})), scheme=d["scheme"],
            level=float(d.get("level", 0.9)), lpf_tau=float(d.get("lpf_tau", 0.0)),
            settle=float(d.get("settle", 0.0)))

    def error_transfer(self):
        """``G(s)`` of ng-tan-edwards-kuang eq. (40): ``xi`` -> reconstruction error ``f^ - f``.

        ``xi`` is the *input* of the uncertainty filter (3) (``xi~' = A_Omega xi~ + B_Omega xi``),
        not the model's disturbance ``xi~`` itself; gamma-bar (``info["l2_bound"]``) bounds this
        transfer's H-infinity norm.

        Returns
        -------
        control.StateSpace
            Inputs ``xi:<k>``, outputs ``fhat_err:<fault>`` in the model's fault coordinates
            (needs the design-time ``details``, i.e. a runtime made by :func:`design_reconstructor`).
        """
        import control

        if "G" not in self.details:
            raise ModelError("error_transfer needs the design details (not kept by to_dict/from_dict)")
        AG, BG, CG, DG = self.details["G"]
        T2 = self.details["lemma1"].T2
        return control.ss(AG, BG, T2.T @ CG, T2.T @ DG,
                          inputs=[f"xi:{k}" for k in range(BG.shape[1])],
                          outputs=[f"fhat_err:{n}" for n in self.fault_names])

    # ------------------------------------------------------------------ state
    _state_attrs = ("_state",)
    _checks_finite = True  # _advance names the channel, run and sample of a NaN itself

    def reset(self, runs: int = 1) -> None:
        """Zero observer states for ``runs`` parallel runs."""
        runs = int(runs)
        if runs < 1:
            raise DataError(f"runs must be >= 1, got {runs}")
        n1, p1, n2, p2 = self._dims
        self._state = {
            "x1": np.zeros((runs, n1)), "e1": np.zeros((runs, p1)),
            "x2": np.zeros((runs, n2)), "e2": np.zeros((runs, p2)),
            "vf": np.zeros((runs, self.r)), "started": np.zeros(runs, dtype=np.bool_),
            "flp": np.zeros((runs, self.n_faults)), "V1": np.zeros((runs, 2)),
            "V2": np.zeros((runs, 2)), "k": np.zeros(1, dtype=np.int64),
        }

    def _check(self, U: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shapes and finiteness of a block of samples, before any state changes."""
        st = self._state
        U = np.asarray(U, dtype=float)
        Y = np.asarray(Y, dtype=float)
        m, py = len(self.u_names), len(self.y_names)
        if Y.ndim != 3 or Y.shape[2] != py:
            raise DataError(f"measurements must have shape (runs, T, {py}) for channels {self.y_names}, "
                            f"got {Y.shape}")
        if U.ndim != 3 or U.shape[:2] != Y.shape[:2] or U.shape[2] != m:
            raise DataError(f"inputs must have shape {(Y.shape[0], Y.shape[1], m)} for channels "
                            f"{self.u_names}, got {U.shape}")
        if st is None or st["x1"].shape[0] != Y.shape[0]:
            raise DataError(f"call reset({Y.shape[0]}) before stepping {Y.shape[0]} runs")
        k0 = int(st["k"][0])
        check_finite(U, self.u_names, what="reconstructor input", first_sample=k0)
        check_finite(Y, self.y_names, what="reconstructor measurement", first_sample=k0)
        return np.ascontiguousarray(U), np.ascontiguousarray(Y)

    def _advance(self, U: np.ndarray, Y: np.ndarray) -> np.ndarray:
        U, Y = self._check(U, Y)
        st = self._state
        q = self.n_faults
        out = np.zeros((Y.shape[0], Y.shape[1], q + 3))
        a_lp = float(np.exp(-self.dt / self.lpf_tau)) if self.lpf_tau > 0 else 0.0
        P, S = self.primary, self.secondary
        _kernel(float(self.dt), bool(self.cascade), P["A"], P["B"], P["C"], P["Gl"], P["Gn"],
                float(P["rho"]), float(P["delta"]), P["SV"], P["Smu"], self.Tv, int(self.r),
                self.Zsel, self.Af, S["A"], S["B"], S["C"], S["Gl"], S["Gn"], float(S["rho"]),
                float(S["delta"]), S["SV"], S["Smu"], self.Wf, U, Y,
                st["x1"], st["e1"], st["x2"], st["e2"], st["vf"], st["started"], out,
                self.scheme == "implicit", float(self.level), a_lp, st["flp"], st["V1"], st["V2"],
                float(np.ceil(self.settle / self.dt - 1e-9)) if self.settle > 0 else 0.0)
        st["k"][0] += Y.shape[1]
        return out

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._advance(u[:, None, :], y[:, None, :])[:, 0, :]

    def run(self, signals: Signals) -> Signals:
        """Reconstruction and sliding status over a whole record (all runs); same kernel as :meth:`step`.

        ``signals`` must be sampled uniformly at ``dt`` (relative tolerance 1e-6) and finite
        (a NaN or inf raises :class:`DataError` naming the channel, run and sample).
        """
        t = signals.t
        if t.size > 1:
            d = np.diff(t)
            bad = np.flatnonzero(np.abs(d - self.dt) > 1e-6 * self.dt)
            if bad.size:
                raise DataError(f"the reconstructor integrates with step dt = {self.dt} s but the "
                                f"record's sample {bad[0] + 1} follows after {d[bad[0]]} s")
        U, Y = self._inputs(signals)
        self.reset(signals.runs)
        out = self._advance(U, Y)
        return Signals(t, out, self.output_names, check=False)


def sliding_episodes(out: Signals | np.ndarray, t: np.ndarray | None = None, *,
                     channel: str = "sliding_status") -> list[dict]:
    """The losses of sliding in a reconstructor's output: one episode per loss.

    Parameters
    ----------
    out : Signals or ndarray (runs, T)
        :meth:`SlidingModeReconstructor.run`'s output (``channel`` is read), or status codes.
    t : ndarray (T,), optional
        Times (taken from ``out`` when it is a :class:`Signals`).
    channel : str
        Status channel.

    Returns
    -------
    list of dict
        ``run``, ``onset_k``, ``onset_t``, ``worst`` (``"not sliding"`` or ``"saturated"``),
        ``cleared_k``, ``cleared_t`` (``None`` while not cleared), in order of run and onset.
    """
    if isinstance(out, Signals):
        codes = out[channel]
        t = out.t
    else:
        codes = np.atleast_2d(np.asarray(out))
        t = np.arange(codes.shape[1], dtype=float) if t is None else np.asarray(t, float)
    codes = np.atleast_2d(codes)
    res = []
    for run in range(codes.shape[0]):
        off = codes[run] > 0
        edges = np.flatnonzero(np.diff(np.r_[0, off.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2]):
            res.append({"run": run, "onset_k": int(a), "onset_t": float(t[a]),
                        "worst": STATUS_LABELS[int(codes[run, a:b].max())],
                        "cleared_k": int(b) if b < codes.shape[1] else None,
                        "cleared_t": float(t[b]) if b < codes.shape[1] else None})
    return res


def _as_omega(A_Omega, B_Omega, omega_d, h):
    omega_d = _pos(omega_d, "omega_d")
    A_O = -omega_d * np.eye(h) if A_Omega is None else _mat(A_Omega, (h, h), "A_Omega")
    B_O = omega_d * np.eye(h) if B_Omega is None else _mat(B_Omega, (h, h), "B_Omega")
    if h and np.linalg.eigvals(A_O).real.max() >= 0:
        raise DataError(f"A_Omega must be stable; eigenvalues {np.linalg.eigvals(A_O)}")
    return A_O, B_O


def _linear_runtime(rec: SlidingModeReconstructor, gain_factor: float = 1.0
                    ) -> tuple[np.ndarray, np.ndarray, dict]:
    """The runtime step inside the boundary layers (``nu = -k e``) as ``z+ = Phi z + Gam y``.

    ``k = gain_factor * rho / delta`` (``gain_factor = 1``: the largest gain of the layer, at
    ``e = 0``; the gain at ``||e||`` is ``rho / (||e|| + delta)``). ``z = [x1, e1, vf, x2, e2,
    flp]`` and ``y`` the measurements (or an additive error on them). Built by applying the step
    (the kernel's arithmetic, in NumPy) to unit vectors.
    """
    P, S = rec.primary, rec.secondary
    n1, p1, n2, p2 = rec._dims
    r, q, h = rec.r, rec.n_faults, rec.dt
    a = float(np.exp(-h / rec.lpf_tau)) if rec.lpf_tau > 0 else 0.0
    sl = {}
    sizes = (("x1", n1), ("e1", p1), ("vf", r), ("x2", n2), ("e2", p2), ("flp", q))
    o = 0
    for key, size in sizes:
        sl[key] = slice(o, o + size)
        o += size
    N = o

    def obs(d, x, e, y):
        k = gain_factor * d["rho"] / d["delta"]
        pk = d["C"].shape[0]
        xt = x + h * (d["A"] @ x - d["Gl"] @ e)
        w = d["C"] @ xt - y
        en = np.linalg.solve(np.eye(pk) + h * k * (d["C"] @ d["Gn"]), w)
        nu = -k * en
        return xt + h * d["Gn"] @ nu, en, nu

    def step(z, nvec):
        zn = np.zeros(N)
        if rec.cascade:
            x1n, e1n, nu1 = obs(P, z[sl["x1"]], z[sl["e1"]], nvec)
            v = rec.Tv @ nu1
            vfn = z[sl["vf"]] + h * rec.Af @ (v[p1 - r:] - z[sl["vf"]]) if r else np.zeros(0)
            ybar = np.r_[v[rec.Zsel], vfn]
            zn[sl["x1"]], zn[sl["e1"]], zn[sl["vf"]] = x1n, e1n, vfn
        else:
            ybar = nvec
        x2n, e2n, nu2 = obs(S, z[sl["x2"]], z[sl["e2"]], ybar)
        zn[sl["x2"]], zn[sl["e2"]] = x2n, e2n
        fh = rec.Wf @ nu2
        zn[sl["flp"]] = a * z[sl["flp"]] + (1.0 - a) * fh if a > 0 else fh
        return zn

    py = len(rec.y_names)
    Phi = np.column_stack([step(np.eye(N)[i], np.zeros(py)) for i in range(N)]) if N else np.zeros((0, 0))
    Gam = np.column_stack([step(np.zeros(N), np.eye(py)[j]) for j in range(py)])
    return Phi, Gam, sl


def noise_response(rec: SlidingModeReconstructor, noise_std: Any) -> dict:
    """Stationary standard deviations of ``fhat`` and of the output errors for white measurement noise.

    The runtime is linear inside its boundary layers (``nu = -(rho/delta) e``, an upper bound of
    the switching gain ``rho/(||e|| + delta)``), so the response of ``fhat`` to white noise of
    standard deviation ``noise_std`` on the measurements (independent per sample and channel)
    follows from a discrete Lyapunov equation of the step as implemented (:func:`_linear_runtime`).

    Parameters
    ----------
    rec : SlidingModeReconstructor
    noise_std : float or array_like (p,)
        Per-output standard deviation (output units).

    Returns
    -------
    dict
        ``fhat_std`` (q), ``gain`` (q, p): std of each ``fhat`` per unit noise std on each output,
        ``e1_rms``, ``e2_rms`` (RMS norms of the output errors, for the boundary layers),
        ``spectral_radius`` of the step.
    """
    from scipy.linalg import solve_discrete_lyapunov

    py = len(rec.y_names)
    sig = np.broadcast_to(np.asarray(noise_std, float), (py,)).copy()
    Phi, Gam, sl = _linear_runtime(rec)
    rho_s = float(np.abs(np.linalg.eigvals(Phi)).max()) if Phi.size else 0.0
    q = rec.n_faults
    if rho_s >= 1.0:
        inf = float("inf")
        return {"fhat_std": [inf] * q, "gain": np.full((q, py), inf), "e1_rms": inf, "e2_rms": inf,
                "spectral_radius": rho_s}
    gain = np.zeros((q, py))
    cov = None
    for j in range(py):
        X = solve_discrete_lyapunov(Phi, np.outer(Gam[:, j], Gam[:, j]))
        gain[:, j] = np.sqrt(np.maximum(np.diag(X)[sl["flp"]], 0.0))
        cov = X * sig[j] ** 2 if cov is None else cov + X * sig[j] ** 2
    d = np.diag(cov)
    return {"fhat_std": np.sqrt(np.maximum(d[sl["flp"]], 0.0)).tolist(), "gain": gain,
            "e1_rms": float(np.sqrt(max(d[sl["e1"]].sum(), 0.0))),
            "e2_rms": float(np.sqrt(max(d[sl["e2"]].sum(), 0.0))), "spectral_radius": rho_s}


#: Boundary layers tried by the accuracy sizing of :func:`design_reconstructor` (largest first).
DELTA_LADDER = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9)


def _check_signals(rec: SlidingModeReconstructor, horizon: float) -> tuple[np.ndarray, int]:
    """Sample times of a self-check run and the index where its scoring window starts."""
    T = max(round(horizon / rec.dt) + 1, 50)
    return np.arange(T) * rec.dt, T // 2


def self_check(rec: SlidingModeReconstructor, *, fault_bound: float = 1.0, xi_amplitude: float = 0.0,
               horizon: float = 1.0) -> dict:
    """Run the reconstructor on its own design model and measure what it achieves.

    Two simulations with the compiled runtime (zero initial states, the plant discretised
    exactly): a step of every fault at once (amplitude ``fault_bound`` along alternating signs,
    at 10 % of ``horizon``) and, when the model has uncertainty and ``xi_amplitude > 0``, a smooth
    disturbance ``xi`` (three sinusoids between 0.5 and 8 rad/s per channel under a raised-cosine
    window, norm ``<= xi_amplitude``) without fault. Scored over the second half of the run.

    This is what :func:`design_reconstructor` uses to size the boundary layers (the error a
    boundary layer ``delta`` leaves in ``fhat`` grows as ``delta / |z|`` near a slow invariant
    zero ``z``) and to decide whether it can claim gamma-bar: the step and layer of a sampled
    observer have a floor that an LMI gamma-bar near its lower limit (1e-7: perfect decoupling
    in continuous time) does not see.

    Returns
    -------
    dict
        ``step_error`` (largest ``||fhat - f|| / fault_bound`` in the window), ``step_status``
        (the worst sliding status during the step run), ``xi_gain`` (``||fhat||_2 / ||xi||_2``
        over the run, or None), ``xi_sliding`` (the xi run slid throughout its window),
        ``horizon_s``.
    """
    det = rec.details
    if "model" not in det:
        raise ModelError("self_check needs the design details of design_reconstructor (a "
                         "reconstructor loaded from a file does not keep them)")
    A, M, C, Q = det["model"]
    q, h = M.shape[1], Q.shape[1]
    t, k0 = _check_signals(rec, horizon)
    U0 = np.zeros((1, t.size, len(rec.u_names)))
    signs = np.where(np.arange(q) % 2 == 0, 1.0, -1.0) / np.sqrt(q)
    f = np.where(t >= 0.1 * horizon, fault_bound, 0.0)[:, None] * signs[None, :]
    Y = simulate_plant(A, M, C, f, rec.dt)
    fh, st = integrate_observers(rec, U0, Y, return_status=True)
    err = np.linalg.norm(fh[0, k0:] - f[k0:], axis=1)
    out = {"step_error": float(err.max() / fault_bound), "step_status": int(st[0, k0:, 0].max()),
           "xi_gain": None, "xi_sliding": None, "horizon_s": float(t[-1])}
    if h and xi_amplitude > 0:
        aug = det["augmented"]
        n = A.shape[0]
        rng = np.random.default_rng(12345)
        win = np.clip(t / (0.2 * horizon), 0.0, 1.0)
        win = 0.5 - 0.5 * np.cos(np.pi * win)
        xi = np.zeros((t.size, h))
        for j in range(h):
            for w in rng.uniform(0.5, 8.0, 3):
                xi[:, j] += np.sin(w * t + rng.uniform(0, 2 * np.pi))
        xi *= win[:, None]
        xi *= xi_amplitude / max(float(np.linalg.norm(xi, axis=1).max()), 1e-300)
        Aa = np.block([[aug.A_Omega, np.zeros((h, n))], [Q, A]])
        Ba = np.block([[np.zeros((h, q)), aug.B_Omega], [M, np.zeros((n, h))]])
        Ca = np.hstack([np.zeros((C.shape[0], h)), C])
        Yx = simulate_plant(Aa, Ba, Ca, np.column_stack([np.zeros((t.size, q)), xi]), rec.dt)
        fx, sx = integrate_observers(rec, U0, Yx, return_status=True)
        out["xi_gain"] = float(np.sqrt(np.sum(fx[0] ** 2)) / max(np.sqrt(np.sum(xi ** 2)), 1e-300))
        out["xi_sliding"] = bool(np.all(sx[0, k0 // 5:, 0] == SLIDING))
    return out


def design_reconstructor(
    model: LinearFaultModel,
    faults: list[str] | None = None,
    disturbances: list[str] | None = None,
    *,
    A_Omega: Any = None,
    B_Omega: Any = None,
    omega_d: float = 10.0,
    V1: Any = None,
    V2: Any = None,
    D1: Any = None,
    gamma_o: float = 100.0,
    gamma_o_retry: bool = True,
    Af: Any = None,
    fault_bound: float = 1.0,
    fault_rate: float | None = None,
    xi_bound: float = 0.0,
    margin: float = 0.5,
    rho: float | None = None,
    delta: float | None = None,
    rho2: float | None = None,
    delta2: float | None = None,
    noise_std: Any = None,
    lpf_tau: float | None = None,
    dt: float = 1e-5,
    tol: float | None = None,
    atol: float | None = None,
    rtol: float | None = None,
    hinf_check: bool = True,
    scheme: str = "implicit",
    level: float = 0.9,
    accuracy: float = 1e-3,
    check: bool = True,
    check_horizon: float = 1.0,
    settle: float | None = None,
) -> SlidingModeReconstructor:
    """Design a robust SMO fault reconstructor; single observer or cascade, chosen automatically.

    The model is ``x' = A x + B u + M f + Q xi~``, ``y = C x`` with the faults ``f`` (group
    ``f``) and the uncertainty ``xi~`` (group ``d``), which is band-limited by the filter
    ``xi~' = A_Omega xi~ + B_Omega xi`` (ng-tan-edwards-kuang (3)). **gamma-bar**
    (``info["l2_bound"]``) bounds the L2 gain from ``xi``, the *input* of that filter, to the
    reconstruction error: ``||fhat - f||_2 <= gamma-bar ||xi||_2`` while both observers slide
    (after the reaching phase, for zero initial errors); it is not the gain from the
    disturbance ``xi~`` put in the model (with the default filter, ``-omega_d I`` / ``omega_d I``,
    the two agree at low frequency). ``error_transfer()`` returns this transfer ``G(s)`` (40).

    Gains. Unless given, the switching gains are sized from what is known about the signals:
    ``rho = (1 + margin) (g_f fault_bound + g_xi xi_bound)`` (and the same for ``rho2`` with the
    secondary observer's gains), where ``g_f, g_xi`` are the peak gains from ``f`` and ``xi`` to
    the equivalent injection (:func:`injection_peak_gains`): an ideal sliding motion then needs
    at most ``1 / (1 + margin)`` of the cap, which keeps the injection inside its boundary layer
    (``||e_y|| <= delta / margin``). ``info["gains"]`` has the gains and
    ``info["reconstructible"]`` the range: the largest ``||f||`` (at ``xi_bound``) and
    ``||xi||`` (at ``fault_bound``) for which sliding is kept. A reconstructor whose given
    ``rho`` is too small for ``fault_bound`` says so (``info["reconstructible"]["ok"]`` and a
    warning); at run time the ``sliding_status`` outputs flag every loss of sliding.

    Measurement noise. With ``noise_std`` (per-output standard deviation of white measurement
    noise), the boundary layers are sized from the noise (``delta >= 3 ||noise||`` at the
    primary, ``>= 3`` RMS output errors at the secondary) and from a loop bandwidth
    ``5 / lpf_tau``, and ``fhat`` is low-passed with time constant ``lpf_tau``; unless given,
    ``lpf_tau`` minimises the predicted error ``sqrt((fault_rate * lag)^2 + fhat_std^2)``
    (lag = ``lpf_tau`` + the loops' time constants). ``info["noise"]`` reports the choice, the
    lag and the noise-to-estimate gain (:func:`noise_response`). Without ``noise_std``, no filter,
    and the boundary layers are sized for ``accuracy``: the largest ``delta = delta2`` of
    :data:`DELTA_LADDER` (1e-5 down to 1e-9) for which the design's :func:`self_check` (a step of
    every fault on its own model, run by the compiled runtime) leaves a relative error
    ``<= accuracy``. A boundary layer leaves an error in ``fhat`` that grows as ``delta / |z|``
    near a slow invariant zero ``z``; the paper's ``1e-5`` is enough for the aircraft but not for
    a zero at ``-0.02``. ``info["boundary_layers"]`` lists the layers tried and what each gave.

    What the bound claims. The self-check also runs a smooth ``xi`` without fault and measures
    ``||fhat||_2 / ||xi||_2`` for the observers as implemented (step ``dt``, layers ``delta``).
    ``info["l2_bound_claimed"]`` is True when that is within gamma-bar; it is False where gamma-bar
    lies below the floor of the sampled observers (an LMI gamma-bar near its lower limit 1e-7
    means perfect decoupling in continuous time, which a fixed-step observer with a boundary layer
    does not reach), and ``info["l2_bound_implemented"]`` then gives the measured gain, with a note
    in ``info["l2_bound_note"]``. The layer sizing prefers layers that let gamma-bar be claimed.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous model; group ``f`` holds the fault directions ``M`` and group ``d`` the
        uncertainty directions ``Q``. Faults and disturbances must not reach the outputs directly
        (``D_f = D_d = 0``).
    faults, disturbances : list of str, optional
        Names to use (default: all of the group).
    A_Omega, B_Omega : array_like (h, h), optional
        Disturbance filter (3); default ``-omega_d I`` and ``omega_d I``.
    omega_d : float
        Disturbance bandwidth (rad/s) of the default filter (paper: 10).
    V1 : (n, n), V2 : (p, p) array_like, optional
        Weights of the primary LMI (42); default ``100 I`` (paper; scaled down by up to 1e-5 when
        (42) is infeasible, ``info["V1_scale"]``: ``G(s)`` does not depend on it) and ``I``.
    D1 : (pbar, pbar) array_like, optional
        Weight of (47); default ``10 I`` (paper).
    gamma_o : float
        Level of (47) (paper: 100), tried first.
    gamma_o_retry : bool
        When (47) is infeasible at ``gamma_o``, use the first level of
        :data:`fdikit.design.smo_lmi.GAMMA_O_FACTORS` that works (``info["gamma_o"]``); with
        ``False`` the error names it.
    Af : (r, r) array_like, optional
        Filter (28) of the relative-degree-one fault channels; default ``10 I``.
    fault_bound : float
        Bound on ``||f(t)||`` (model fault units) the gains are sized for (default 1).
    fault_rate : float, optional
        Bound on ``||f'(t)||`` (units/s); used by the noise design (default ``10 fault_bound``).
    xi_bound : float
        Bound on ``||xi(t)||`` (the uncertainty filter's input) the gains are sized for.
    margin : float
        Relative margin of the sized gains (> 0).
    rho, rho2 : float, optional
        Switching gains of the primary (24) and secondary (39) observers (default: sized).
    delta, delta2 : float, optional
        Boundary layers (default: sized for ``accuracy``, see above, or from ``noise_std``).
    noise_std : float or array_like (p,), optional
        Measurement noise standard deviation per output (output units).
    lpf_tau : float, optional
        Time constant (s) of the low-pass on ``fhat`` (default: 0 without noise, optimised with).
    dt : float
        Integration step = sample time of the data the runtime accepts (s).
    tol, atol, rtol : float, optional
        Rank tolerances (see :func:`check_conditions`); decisions in
        ``info["conditions"]["rank_decisions"]`` and ``info["rank_decisions_lemma4"]``.
    hinf_check : bool
        Compute the H-infinity norm of ``G(s)`` (40) independently of the LMI.
    scheme : {"implicit", "explicit"}
        Euler step with the switched term at the new time (default; no numerical chattering)
        or the plain explicit Euler step.
    level : float
        Status threshold: sliding while ``||nu|| <= level rho``.
    accuracy : float
        Relative reconstruction error (of ``fault_bound``) the boundary-layer sizing aims at
        (default 1e-3); a warning says when no layer of the ladder reaches it.
    check : bool
        Run :func:`self_check` (default True; about 0.3 s per second of ``check_horizon`` at
        ``dt = 1e-5``). With False the layers are ``1e-5`` unless given and nothing is claimed
        (``info["l2_bound_claimed"]`` is None).
    check_horizon : float
        Length (s) of the self-check runs (scored over their second half).
    settle : float, optional
        Seconds the error must stay inside the boundary layer after a loss of sliding before the
        status says sliding again (default: three time constants of the slowest mode of the
        sliding motion, ``info["sliding_settle"]``; a slow invariant zero makes it long, because
        the reconstruction really takes that long to recover).

    Returns
    -------
    SlidingModeReconstructor
        ``info["case"]`` is ``"single"`` or ``"cascade"``; ``info["l2_bound"]`` is gamma-bar,
        ``info["l2_bound_claimed"]`` whether the implementation achieves it (see above);
        ``info["self_check"]`` what the design achieved on its own model;
        ``info["solver"]`` the LMI solver records (status, iterations, refinement, largest
        constraint violation); ``info["gamma_o"]`` the level of (47) used.

    Raises
    ------
    ConditionError
        Naming the failed condition (``"rank M = q"``, ``"rank C = p"``, ``"detectability"``,
        ``"B1"``, ``"A2"``/``"B2"``, ``"LMI"``) with its numbers.
    DataError
        A parameter out of range or a matrix of the wrong shape, named.

    Examples
    --------
    >>> from fdikit.systems import aircraft
    >>> from fdikit.residuals import design_reconstructor
    >>> rec = design_reconstructor(aircraft.model())
    >>> rec.info["case"], rec.info["pbar"], rec.info["rank_CM"], round(rec.info["l2_bound"], 4)
    ('cascade', 3, 0, 1.3131)
    >>> rec.output_names
    ['fhat:actuator:rudder_cmd', 'sliding_status', 'sliding_status:primary', 'sliding_status:secondary']
    """
    t0 = time.perf_counter()
    if not isinstance(model, LinearFaultModel):
        raise DataError(f"model must be a LinearFaultModel, got {type(model).__name__}")
    if model.is_discrete:
        raise ModelError(f"model {model.name!r} is discrete; the SMO design needs a continuous model")
    if scheme not in ("implicit", "explicit"):
        raise ModelError(f"scheme must be 'implicit' or 'explicit', got {scheme!r}")
    dt = _pos(dt, "dt")
    fault_bound = _pos(fault_bound, "fault_bound")
    xi_bound = _pos(xi_bound, "xi_bound", allow_zero=True)
    margin = _pos(margin, "margin")
    fault_rate = 10.0 * fault_bound if fault_rate is None else _pos(fault_rate, "fault_rate", allow_zero=True)
    gamma_o = _pos(gamma_o, "gamma_o")
    accuracy = _pos(accuracy, "accuracy")
    check_horizon = _pos(check_horizon, "check_horizon")
    user = {"rho": rho, "rho2": rho2, "delta": delta, "delta2": delta2}
    for key, v in user.items():
        if v is not None:
            user[key] = _pos(v, key)
    if lpf_tau is not None:
        lpf_tau = _pos(lpf_tau, "lpf_tau", allow_zero=True)
    fnames = model.fault_names if faults is None else list(faults)
    dnames = model.input_names("d") if disturbances is None else list(disturbances)
    if not fnames:
        raise ModelError(f"model {model.name!r} declares no faults to reconstruct")
    fi = [model._lookup(model.fault_names, f, "fault") for f in fnames]
    di = [model._lookup(model.input_names("d"), d, "disturbance") for d in dnames]
    M = model.B_of("f")[:, fi]
    Q = model.B_of("d")[:, di] if di else np.zeros((model.n_states, 0))
    if np.abs(model.D_of("f")[:, fi]).max(initial=0.0) > 0 or \
            (di and np.abs(model.D_of("d")[:, di]).max(initial=0.0) > 0):
        raise ModelError("the SMO reconstructor handles actuator faults and state disturbances: "
                         "D_f and D_d must be zero")
    A, B, C = model.A, model.B, model.C
    if np.abs(model.D).max(initial=0.0) > 0:
        raise ModelError("the SMO reconstructor needs D_u = 0 (strictly proper plant)")
    _n, p, q, h = A.shape[0], C.shape[0], M.shape[1], Q.shape[1]
    sig = None
    if noise_std is not None:
        sig = np.asarray(noise_std, float)
        if sig.ndim > 1 or (sig.ndim == 1 and sig.size != p) or not np.all(np.isfinite(sig)) or \
                np.any(sig < 0):
            raise DataError(f"noise_std must be a finite scalar or {p} values >= 0 (one per output "
                            f"{list(model.outputs)}), got {noise_std!r}")
        sig = np.broadcast_to(sig, (p,)).astype(float)
        if not sig.any():
            sig = None
    cond = check_conditions(A, M, C, Q, tol=tol, atol=atol, rtol=rtol)
    case = cond.require()
    A_O, B_O = _as_omega(A_Omega, B_Omega, omega_d, h)
    l1 = lemma1_form(A, B, M, C, Q, tol=tol, rank_CM=cond.rank_CM)
    aug = augment(l1, A_O, B_O)
    na = aug.n
    V1_given = V1 is not None
    V1 = 100.0 * np.eye(na) if V1 is None else _mat(V1, (na, na), f"V1 (augmented state: {na})")
    V2 = np.eye(p) if V2 is None else _mat(V2, (p, p), "V2")
    info: dict[str, Any] = {"case": case, "conditions": cond.as_dict(), "rank_CM": cond.rank_CM,
                            "n_aug": na, "h": h, "q": q, "p": p}
    details: dict[str, Any] = {"conditions": cond, "lemma1": l1, "augmented": aug, "model": (A, M, C, Q)}
    solver: dict[str, Any] = {}
    t_lmi = 0.0
    if case == "cascade":
        cf = lemma4_form(aug, tol=tol)
        details["canonical"] = cf
        info["rank_decisions_lemma4"] = {k: v.as_dict() for k, v in cf.rank_decisions.items()}
        pbar, r = cf.pbar, cf.r
        if Af is None:
            Af = 10.0 * np.eye(r)
        else:
            Af = _mat(Af, (r, r), "Af")
            if r and np.linalg.eigvals(-Af).real.max() >= 0:
                raise DataError(f"-Af must be stable; eigenvalues of Af {np.linalg.eigvals(Af)}")
        ts = time.perf_counter()
        # (42) is a Riccati-type inequality that a large V1 can make infeasible; G(s) does not
        # depend on the primary design (the paper's key observation), so a default V1 that fails
        # is scaled down until (42) holds.
        scales = [1.0] if V1_given else [1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5]
        tried1 = []
        for sc in scales:
            try:
                g1 = primary_smo_lmi(cf.A, cf.C, V1 * sc, V2)
            except ConditionError as exc:
                tried1.append({"V1_scale": sc, "message": str(exc)})
                if sc == scales[-1]:
                    raise ConditionError(exc.condition, f"{exc} (V1 scaled by {scales})",
                                         {**exc.details, "V1_tried": tried1}) from None
                continue
            tried1.append({"V1_scale": sc, "ok": True})
            break
        t_lmi += time.perf_counter() - ts
        solver["primary"] = {**g1.solver, "V1_tried": tried1}
        info["V1_scale"] = tried1[-1]["V1_scale"]
        fs = fictitious_system(cf, g1.L, Af)
        details["primary_gains"], details["fictitious"] = g1, fs
        A2, M2, C2, Q2 = fs.A, fs.M, fs.C, fs.Q
        B2 = np.zeros((A2.shape[0], B.shape[1]))
        D1m = 10.0 * np.eye(pbar) if D1 is None else _mat(D1, (pbar, pbar), "D1")
        ts = time.perf_counter()
        g2 = secondary_smo_lmi_search(A2, M2, C2, Q2, D1=D1m, gamma_o=gamma_o, retry=gamma_o_retry)
        t_lmi += time.perf_counter() - ts
        T = cf.T
        Tv = T.T @ np.linalg.solve(g1.Po, np.eye(p))
        n4 = cf.blocks[3]
        Zsel = np.arange(n4 - (pbar - r), n4)
        info["trace_X"] = g1.trace_X
        g1f, g1x = injection_peak_gains(cf.A, cf.M, cf.Q, cf.C, g1.L, g1.Po)
    else:
        pbar, r = p, q
        Af = np.zeros((0, 0))
        A2, M2, C2, Q2, B2 = aug.A, aug.M, aug.C, aug.Q, aug.B
        D1m = 10.0 * np.eye(pbar) if D1 is None else _mat(D1, (pbar, pbar), "D1")
        ts = time.perf_counter()
        g2 = secondary_smo_lmi_search(A2, M2, C2, Q2, D1=D1m, gamma_o=gamma_o, retry=gamma_o_retry)
        t_lmi += time.perf_counter() - ts
        Tv = np.zeros((0, 0))
        Zsel = np.zeros(0, dtype=np.int64)
        g1f = g1x = 0.0
    solver["secondary"] = g2.solver
    details["secondary_gains"] = g2
    nb, pb = A2.shape[0], C2.shape[0]
    Tb = C2[:, nb - pb:]
    g2f, g2x = injection_peak_gains(A2, M2, Q2, C2, g2.L, g2.Po)
    # gains sized from the bounds (see the docstring)
    need1 = g1f * fault_bound + g1x * xi_bound
    need2 = g2f * fault_bound + g2x * xi_bound
    rho_v = user["rho"] if user["rho"] is not None else (1.0 + margin) * need1
    rho2_v = user["rho2"] if user["rho2"] is not None else (1.0 + margin) * need2
    if case != "cascade" and user["rho"] is None:
        rho_v = 1.0  # no primary observer
    rho_v, rho2_v = max(rho_v, 1e-12), max(rho2_v, 1e-12)

    def cap(rv, gf, gx, xb):
        return float("inf") if gf == 0 else (rv - gx * xb) / gf

    f_max = min(cap(rho_v, g1f, g1x, xi_bound) if case == "cascade" else float("inf"),
                cap(rho2_v, g2f, g2x, xi_bound))
    obs = [(rho2_v, g2f, g2x)] + ([(rho_v, g1f, g1x)] if case == "cascade" else [])
    xi_max = min((rv - gf * fault_bound) / gx if gx > 0 else float("inf") for rv, gf, gx in obs)
    ok = bool(f_max >= fault_bound * (1.0 + 1e-12) and xi_max >= xi_bound)
    info["gains"] = {"rho": rho_v, "rho2": rho2_v, "sized": {k: user[k] is None for k in ("rho", "rho2")},
                     "margin": margin, "fault_bound": fault_bound, "fault_rate": fault_rate,
                     "xi_bound": xi_bound,
                     "injection_peak_gain_primary": {"fault": g1f, "xi": g1x},
                     "injection_peak_gain_secondary": {"fault": g2f, "xi": g2x},
                     "needed_primary": need1, "needed_secondary": need2}
    info["reconstructible"] = {"fault_bound_max": f_max, "xi_bound_max": xi_max, "ok": ok,
                               "note": "largest ||f|| (at xi_bound) and ||xi|| (at fault_bound) for "
                                       "which an ideal sliding motion is kept by rho, rho2 (peak-gain "
                                       "bound; after the reaching phase)"}
    if not ok:
        warnings.warn(f"the switching gains (rho = {rho_v:.4g}, rho2 = {rho2_v:.4g}) cannot keep sliding for "
                      f"||f|| <= {fault_bound:g} and ||xi|| <= {xi_bound:g}: the reconstructible range is "
                      f"||f|| <= {f_max:.4g}; the sliding_status outputs will flag the losses",
                      stacklevel=2)
    Wrec = g2.W @ np.linalg.solve(Tb, np.linalg.solve(g2.Po, np.eye(pb)))  # W Tbar^-1 Pobar^-1
    Wf = l1.T2.T @ Wrec  # back to the original fault coordinates (T2 orthogonal)
    # G(s) of (40)
    k2 = nb - pb
    A1b, A3b, Q1b, Q2b = A2[:k2, :k2], A2[k2:, :k2], Q2[:k2], Q2[k2:]
    AG = A1b + g2.L @ A3b
    BG = Q1b + g2.L @ Q2b
    CG = g2.W @ A3b
    DG = g2.W @ Q2b
    details["G"] = (AG, BG, CG, DG)
    # the sliding motion's slowest mode: how long a loss of sliding takes to wash out of fhat
    ev_G = np.linalg.eigvals(AG) if AG.size else np.zeros(0)
    slow_mode = float(np.min(-ev_G.real)) if ev_G.size else float("inf")
    if settle is None:
        settle_v = 3.0 / slow_mode if np.isfinite(slow_mode) and slow_mode > 0 else 0.0
    else:
        settle_v = _pos(settle, "settle", allow_zero=True)
    info["sliding_settle"] = {"settle_s": settle_v, "slowest_sliding_mode": slow_mode,
                              "sized": settle is None,
                              "note": "after a loss of sliding the status stays 'not sliding' until the "
                                      "error has stayed in the boundary layer settle_s seconds (three time "
                                      "constants of the slowest eigenvalue of the sliding motion, eq. (40))"}
    info.update({"pbar": int(pbar), "r": int(r), "l2_bound": g2.gamma, "lmi_seconds": t_lmi,
                 "l2_bound_from": "xi, the input of the uncertainty filter xi~' = A_Omega xi~ + B_Omega xi",
                 "W_Tinv_Poinv": Wrec, "Po_bar": g2.Po, "gamma_o": g2.gamma_o, "solver": solver,
                 "Po": details["primary_gains"].Po if case == "cascade" else None})
    if hinf_check and h:
        hn = hinf_norm(AG, BG, CG, DG)
        info["hinf_check"] = {"hinf_bisection": hn["bisection"], "hinf_sweep": hn["sweep"],
                              "w_peak": hn["w_peak"],
                              "within_bound": bool(hn["bisection"] <= g2.gamma * (1 + 1e-6))}

    def build(d1, d2, tau):
        primary = ({"A": cf.A, "B": cf.B, "C": cf.C, "Gl": g1.Gl, "Gn": g1.Gn, "rho": rho_v, "delta": d1}
                   if case == "cascade" else
                   {"A": np.zeros((0, 0)), "B": np.zeros((0, B.shape[1])), "C": np.zeros((0, 0)),
                    "Gl": np.zeros((0, 0)), "Gn": np.zeros((0, 0)), "rho": rho_v, "delta": d1})
        secondary = {"A": A2, "B": B2, "C": C2, "Gl": g2.Gl, "Gn": g2.Gn, "rho": rho2_v, "delta": d2}
        return SlidingModeReconstructor(
            cascade=(case == "cascade"), primary=primary, secondary=secondary,
            Tv=np.ascontiguousarray(Tv), Zsel=np.asarray(Zsel, dtype=np.int64),
            Af=np.ascontiguousarray(Af), Wf=np.ascontiguousarray(Wf),
            r=int(r if case == "cascade" else 0), dt=float(dt), u_names=list(model.inputs),
            y_names=list(model.outputs), output_names=[f"fhat:{f}" for f in fnames], info=info,
            details=details, scheme=scheme, level=level, lpf_tau=tau, settle=settle_v)

    # self-check amplitudes: inside the reconstructible range
    f_chk = min(fault_bound, 0.5 * f_max) if np.isfinite(f_max) and f_max > 0 else fault_bound
    xi_chk = xi_bound if xi_bound > 0 else (min(1.0, 0.5 * xi_max) if np.isfinite(xi_max) and xi_max > 0
                                            else 1.0)
    gam = g2.gamma

    def checked(d1, d2, tau):
        rec_ = build(d1, d2, tau)
        sc = self_check(rec_, fault_bound=f_chk, xi_amplitude=xi_chk if h else 0.0,
                        horizon=check_horizon) if check else None
        return rec_, sc

    if sig is None:
        tau0 = 0.0 if lpf_tau is None else lpf_tau
        ladder = ([None] if user["delta"] is not None and user["delta2"] is not None
                  else list(DELTA_LADDER))
        tried = []
        for dl in ladder:
            d1 = user["delta"] if user["delta"] is not None else dl
            d2 = user["delta2"] if user["delta2"] is not None else dl
            rec, sc = checked(d1, d2, tau0)
            tried.append((d1, d2, rec, sc))
            if sc is None or (sc["step_error"] <= accuracy and
                              (sc["xi_gain"] is None or sc["xi_gain"] <= 0.5 * gam)):
                break
        if tried[-1][3] is not None and len(tried) > 1:
            # the largest layer that is accurate and claims gamma-bar; else accurate; else the best
            acc = [x for x in tried if x[3]["step_error"] <= accuracy]
            claim = [x for x in acc if x[3]["xi_gain"] is None or x[3]["xi_gain"] <= gam]
            if claim:
                pick = claim[0]
            elif acc and acc[0][3]["xi_gain"] is not None:
                # no layer claims gamma-bar: the largest whose xi gain is within 10 % of the least
                g_min = min(x[3]["xi_gain"] for x in acc)
                pick = next(x for x in acc if x[3]["xi_gain"] <= 1.1 * g_min)
            elif acc:
                pick = acc[0]
            else:
                pick = min(tried, key=lambda x: x[3]["step_error"])
            d1, d2, rec, sc = pick
        else:
            d1, d2, rec, sc = tried[-1]
        info["noise"] = None
        info["boundary_layers"] = {
            "delta": d1, "delta2": d2, "sized": user["delta"] is None or user["delta2"] is None,
            "accuracy": accuracy,
            "tried": [{"delta": a, "delta2": b_, **(c or {})} for a, b_, _r, c in tried],
            "note": "largest layer of DELTA_LADDER whose self-check step error is <= accuracy "
                    "(relative to fault_bound) and whose xi gain allows claiming gamma-bar"}
    else:
        rec, info["noise"] = _noise_design(build, sig, user, lpf_tau, fault_rate, rho_v, rho2_v,
                                           g1 if case == "cascade" else None, g2, dt)
        sc = self_check(rec, fault_bound=f_chk, xi_amplitude=xi_chk if h else 0.0,
                        horizon=check_horizon) if check else None
    info["self_check"] = sc
    if sc is not None:
        if sig is None and sc["step_error"] > accuracy:
            warnings.warn(f"the reconstructor misses its accuracy on its own model: a step of "
                          f"{f_chk:.4g} leaves an error of {sc['step_error']:.3g} (relative; target "
                          f"accuracy = {accuracy:g}) with delta = {rec.primary['delta']:g}, delta2 = "
                          f"{rec.secondary['delta']:g}, dt = {dt:g}; info['self_check']", stacklevel=2)
        claimed = sc["xi_gain"] is None or sc["xi_gain"] <= gam
        info["l2_bound_claimed"] = bool(claimed)
        info["l2_bound_implemented"] = sc["xi_gain"]
        if not claimed:
            info["l2_bound_note"] = (
                f"gamma-bar = {gam:.3g} is below what the sampled observers achieve (dt = {dt:g}, "
                f"delta2 = {rec.secondary['delta']:g}): the self-check measured "
                f"||fhat||_2 / ||xi||_2 = {sc['xi_gain']:.3g} on a smooth xi; the bound is not claimed")
    else:
        info["l2_bound_claimed"] = None
        info["l2_bound_implemented"] = None
    info["design_seconds"] = time.perf_counter() - t0
    return rec


def _noise_design(build, sig, user, lpf_tau, fault_rate, rho1, rho2, g1, g2, dt):
    """Boundary layers and output low-pass for white measurement noise ``sig`` (see design_reconstructor)."""
    sn = float(np.linalg.norm(sig))
    lam1 = float(np.linalg.eigvalsh(np.linalg.inv(g1.Po)).max()) if g1 is not None else 0.0
    lam2 = float(np.linalg.eigvalsh(np.linalg.inv(g2.Po)).max())
    lam2min = float(np.linalg.eigvalsh(np.linalg.inv(g2.Po)).min())
    lam1min = float(np.linalg.eigvalsh(np.linalg.inv(g1.Po)).min()) if g1 is not None else np.inf

    def layers(tau, e2_rms):
        w = 5.0 / tau  # loop bandwidth (rad/s)
        d1 = user["delta"] if user["delta"] is not None else max(1e-5, 3.0 * sn, rho1 * lam1 / w)
        d2 = user["delta2"] if user["delta2"] is not None else max(1e-5, 3.0 * e2_rms, rho2 * lam2 / w)
        return d1, d2

    def evaluate(tau):
        e2 = 0.0
        for _ in range(3):  # the secondary layer depends on its own output error: iterate
            d1, d2 = layers(tau, e2)
            rec = build(d1, d2, tau)
            nr = noise_response(rec, sig)
            if user["delta2"] is not None or d2 >= 3.0 * nr["e2_rms"] * 0.999:
                break
            e2 = nr["e2_rms"]
        lag = tau + (d1 / (rho1 * lam1min) if g1 is not None else 0.0) + d2 / (rho2 * lam2min)
        noise = float(np.linalg.norm(nr["fhat_std"]))
        pred = float(np.hypot(fault_rate * lag, noise))
        return pred, rec, nr, lag, (d1, d2)

    taus = [lpf_tau] if lpf_tau is not None and lpf_tau > 0 else list(np.logspace(np.log10(20 * dt), 0.0, 25))
    best = None
    for tau in taus:
        res = evaluate(float(tau))
        if np.isfinite(res[0]) and (best is None or res[0] < best[0]):
            best = (*res, float(tau))
    if best is None:
        raise ConditionError("noise design", "no low-pass time constant gives a stable runtime step "
                             f"(dt = {dt} s); reduce dt", {"tried": taus})
    pred, rec, nr, lag, (d1, d2), tau = best
    out = {"noise_std": sig.tolist(), "lpf_tau": tau, "lag_s": lag, "delta": d1, "delta2": d2,
           "fhat_noise_std": nr["fhat_std"], "noise_gain": nr["gain"],
           "lag_error_bound": fault_rate * lag, "predicted_error": pred,
           "e1_rms": nr["e1_rms"], "e2_rms": nr["e2_rms"],
           "note": "noise_gain[i][j]: std of fhat_i per unit std of white noise on output j (linear "
                   "boundary-layer model of the step as implemented); lag_s: low-pass + loop time "
                   "constants; lag_error_bound = fault_rate * lag_s"}
    return rec, out


def integrate_observers(rec: SlidingModeReconstructor, U: np.ndarray, Y: np.ndarray, *,
                        return_status: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Run the reconstructor's observers over sampled inputs and outputs.

    The step is ``rec.dt``: explicit Euler for the linear part, implicit for the switched term.
    Implicit treatment of ``nu = -rho e / (||e|| + delta)`` keeps ``e_y`` on its discrete
    sliding surface instead of oscillating across it. An explicit step chatters with amplitude
    about ``h rho ||Po^-1||`` (1e-2 for the aircraft at ``h = 1e-5``, ``rho = 100``,
    ``Po ~ 0.1 I``, far above ``delta = 1e-5``); the chattering primary injection then drives the
    secondary observer off its sliding surface. Measured on the aircraft (15 s, nominal plant):
    RMS(f^ - f)/RMS(f) = 1.3e-5 (implicit, h = 1e-5), 1.1e-4 (implicit, h = 1e-4), 75
    (``scheme="explicit"`` at h = 1e-5 and at 1e-4).

    Parameters
    ----------
    rec : SlidingModeReconstructor
    U : ndarray (runs, T, m)
        Known inputs, ``m = len(rec.u_names)``.
    Y : ndarray (runs, T, p)
        Measurements, ``p = len(rec.y_names)``.
    return_status : bool
        Also return the sliding status codes.

    Returns
    -------
    ndarray (runs, T, q)
        Fault reconstructions.
    ndarray (runs, T, 3) of int8, with ``return_status``
        Combined, primary and secondary sliding status (:data:`SLIDING`, :data:`NOT_SLIDING`,
        :data:`SATURATED`).

    Raises
    ------
    DataError
        ``U`` or ``Y`` of the wrong shape (the compiled kernel never reads past an array), or a
        NaN/inf sample (named by channel, run and sample).
    """
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 3:
        raise DataError(f"Y must have shape (runs, T, {len(rec.y_names)}), got {Y.shape}")
    rec.reset(Y.shape[0])
    out = rec._advance(U, Y)
    q = rec.n_faults
    if return_status:
        return out[:, :, :q], out[:, :, q:].astype(np.int8)
    return out[:, :, :q]


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
