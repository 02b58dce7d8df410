"""Existence conditions of SMO fault reconstruction: A1, A2 (Tan & Edwards 2003) and B1, B2
(ng-tan-edwards-kuang, Theorem 1), with the rank decisions behind each verdict."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import ConditionError, DataError
from ...model.structure import invariant_zeros, is_detectable, is_observable, rank_decision
from .validation import _mat, _norm2, _pos

__all__ = ["RANK_ATOL_SCALE", "SMOConditions", "check_conditions"]

#: Default absolute rank tolerance, relative to the scale of the factors a matrix is formed from
#: (``||C|| ||A|| ||M||`` for ``C A M``): see :func:`check_conditions`.
RANK_ATOL_SCALE = 1e-10


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
