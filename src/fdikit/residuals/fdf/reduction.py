"""Model reduction of a discrete filter (ng-chen-speyer, Section IV-C): modal observability and
the removal of fast and weakly observable modes."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ...errors import ModelError
from .form import FilterDesign

__all__ = ["modal_observability", "reduce_filter"]

def modal_observability(design: FilterDesign) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of the filter and how observable each mode is from the residual.

    For each eigenvalue ``z_i`` of ``A`` with unit right eigenvector ``v_i`` the measure is
    ``|C v_i| / |C|_2`` (0: unobservable; near 0: weakly observable). In the limit
    ``gamma -> 0`` the modes spanning the nuisance subspace become unobservable from ``r``.

    Returns
    -------
    eigenvalues : ndarray complex (nf,)
    observability : ndarray (nf,)

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.diag([0.9, 0.5]), np.zeros((2, 0)), np.ones((2, 1)), np.array([[1.0, 1e-6]]),
    ...                  np.zeros((1, 0)), np.zeros((1, 1)), 0.01, [], ["y"], ["r"])
    >>> z, o = modal_observability(d)
    >>> z.real.tolist(), np.round(o, 9).tolist()
    ([0.9, 0.5], [1.0, 1e-06])
    """
    w, V = np.linalg.eig(design.A)
    V = V / np.linalg.norm(V, axis=0)
    cn = float(np.linalg.norm(design.C, 2)) if design.C.size else 0.0
    obs = np.linalg.norm(design.C @ V, axis=0) / cn if cn else np.zeros(w.size)
    return w, obs


def reduce_filter(design: FilterDesign, order: int | None = None, *, fast_modulus: float = 0.05,
                  weak_observability: float = 1e-4, method: str = "residualize") -> FilterDesign:
    """Remove the fast and weakly observable modes of a discrete filter (ng-chen-speyer, Section IV-C).

    Near the limit ``gamma -> 0`` the optimal filter has fast modes (``|z|`` near 0) and weakly
    observable modes approximating the nuisance's detection space. The modes to drop are

    * ``order`` given: all but the ``order`` most observable modes
      (:func:`modal_observability`);
    * otherwise: the modes with ``|z| <= fast_modulus`` or relative observability below
      ``weak_observability``.

    The kept modes are moved to the leading block of an ordered real Schur form of ``A``, the
    two blocks are decoupled by a Sylvester equation, and the dropped block ``xi2`` is either
    set to its quasi-steady state ``xi2 = (I - A22)^-1 B2 v`` (``"residualize"``: the discrete
    dynamic truncation with steady-state correction, exact DC gain) or dropped (``"truncate"``).

    Parameters
    ----------
    design : FilterDesign
    order : int, optional
        Number of modes kept.
    fast_modulus : float
        ``|z|`` at or below which a mode is fast (0.05: time constant shorter than ``dt / 3``).
    weak_observability : float
        Relative modal observability below which a mode is dropped.
    method : {"residualize", "truncate"}

    Returns
    -------
    FilterDesign
        ``info``: ``order``, ``reduction`` (method), ``dropped_eigenvalues``,
        ``dropped_observability`` (their modal observability) and ``kept_observability``.

    Raises
    ------
    ModelError
        Bad order or method; a split that separates modes with the same eigenvalue or
        observability (complex pairs are kept or dropped together).

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.diag([0.9, 0.01]), np.zeros((2, 0)), np.array([[0.1], [1.0]]),
    ...                  np.array([[1.0, 1.0]]), np.zeros((1, 0)), np.zeros((1, 1)), 0.01, [], ["y"], ["r"])
    >>> r = reduce_filter(d)
    >>> r.order, round(float(r.Dy[0, 0]), 6)     # fast mode -> feedthrough 1/(1 - 0.01)
    (1, 1.010101)
    """
    if method not in ("residualize", "truncate"):
        raise ModelError(f"method must be 'residualize' or 'truncate', got {method!r}")
    A = design.A
    n = A.shape[0]
    w, obs = modal_observability(design)
    if order is None:
        keep = (np.abs(w) > fast_modulus) & (obs >= weak_observability)
    else:
        order = int(order)
        if not 0 <= order <= n:
            raise ModelError(f"reduce_filter: order must be in [0, {n}], got {order}")
        idx = np.argsort(-obs, kind="stable")
        keep = np.zeros(n, bool)
        keep[idx[:order]] = True
        if 0 < order < n and obs[idx[order - 1]] <= obs[idx[order]] * (1 + 1e-9):
            raise ModelError(f"reduce_filter: order {order} splits modes of equal observability "
                             f"{obs[idx[order]]:.6g} (a complex pair?); choose order {order - 1} or "
                             f"{order + 1}")
    # complex pairs must be kept or dropped together
    for i in range(n):
        j = int(np.argmin(np.abs(w - np.conj(w[i]))))
        if keep[i] != keep[j]:
            raise ModelError(f"reduce_filter: the split separates the complex pair {w[i]:.6g}")
    k = int(np.sum(keep))
    Bv = np.hstack([design.Bu, design.By])
    Dv = np.hstack([design.Du, design.Dy])
    m = design.Bu.shape[1]
    if 0 < k < n:
        kept_z, drop_z = w[keep], w[~keep]
        gap = float(np.min(np.abs(kept_z[:, None] - drop_z[None, :])))
        if gap <= 1e-8 * max(1.0, float(np.max(np.abs(w)))):
            raise ModelError(f"reduce_filter: a kept and a dropped mode share the eigenvalue "
                             f"(gap {gap:.3e}); they cannot be separated")

        def _is_kept(re: float, im: float) -> bool:
            return bool(keep[int(np.argmin(np.abs(w - complex(re, im))))])

        T, Z, sdim = sla.schur(A, output="real", sort=_is_kept)
        if sdim != k:  # pragma: no cover - guarded by the gap test
            raise ModelError(f"reduce_filter: Schur reordering selected {sdim} modes, expected {k}")
        X = sla.solve_sylvester(T[:k, :k], -T[k:, k:], -T[:k, k:])
        Bz = Z.T @ Bv
        Bz[:k] -= X @ Bz[k:]
        Cz = design.C @ Z
        Cz[:, k:] += Cz[:, :k] @ X
        A11, A22 = T[:k, :k], T[k:, k:]
    elif k == n:
        A11, A22, Bz, Cz = A, np.zeros((0, 0)), Bv, design.C
    else:
        A11, A22, Bz, Cz = np.zeros((0, 0)), A, Bv, design.C
    B1, B2, C1, C2 = Bz[:k], Bz[k:], Cz[:, :k], Cz[:, k:]
    Dr = Dv.copy()
    if method == "residualize" and k < n:
        Dr = Dv + C2 @ np.linalg.solve(np.eye(n - k) - A22, B2)
    out = FilterDesign(np.array(A11), B1[:, :m].copy(), B1[:, m:].copy(), C1.copy(), Dr[:, :m].copy(),
                       Dr[:, m:].copy(), design.dt, list(design.u_names), list(design.y_names),
                       list(design.residual_names))
    out.info = {"order": k, "reduction": method, "dropped_eigenvalues": w[~keep],
                "dropped_observability": obs[~keep], "kept_observability": obs[keep]}
    return out
