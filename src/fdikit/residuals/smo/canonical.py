"""Coordinate changes of the SMO design (ng-tan-edwards-kuang): the form of Lemma 1, the system
augmented with the disturbance filter (7)-(10), the canonical form of Lemma 4 and the fictitious
relative-degree-one system (25)-(36), by orthogonal / QR / SVD steps."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import ConditionError, DataError
from ...model.structure import rank, rank_decision
from .conditions import RANK_ATOL_SCALE
from .validation import _mat, _norm2

__all__ = ["AugmentedSystem", "CanonicalForm", "FictitiousSystem", "Lemma1Form", "augment",
           "fictitious_system", "lemma1_form", "lemma4_form"]

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
