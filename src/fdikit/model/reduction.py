"""Model reduction of linear fault models, keeping input/output names and input groups.

* :func:`residualize` eliminates named physical states by setting their derivatives to zero
  (singular perturbation / steady-state correction).
* :func:`reduce_fast_modes` is dynamic truncation with steady-state correction: the fastest
  modes (largest ``|lambda|``) are separated by an ordered real Schur form and a Sylvester
  block-diagonalisation, then residualised, so the DC gain of every input group is kept exactly.
* :func:`balanced_truncation` is the square-root balanced truncation (or, with
  ``method="matchdc"``, balanced residualisation) with the Hankel singular values.
* :func:`frequency_response_error` compares a reduced model with the full one per frequency
  band (e.g. "within 5 % below 5 Hz").

All reductions act on every input group ``u, d, f, w`` at once (the columns of ``B_all`` /
``D_all``) and return a :class:`~fdikit.model.linear.LinearFaultModel` built with
:meth:`~fdikit.model.linear.LinearFaultModel.with_matrices`, so input names, groups and fault
names are unchanged; outputs keep their names.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import ConditionError, ModelError
from .linear import GROUPS, LinearFaultModel
from .structure import default_tol

__all__ = [
    "FrequencyResponseError",
    "balanced_truncation",
    "dc_gain",
    "frequency_response",
    "frequency_response_error",
    "reduce_fast_modes",
    "residualize",
]


def _continuous(model: LinearFaultModel, what: str) -> None:
    if not isinstance(model, LinearFaultModel):
        raise ModelError(f"{what} needs a LinearFaultModel, got {type(model).__name__}")
    if model.is_discrete:
        raise ModelError(f"{what}: model {model.name!r} is discrete (dt = {model.dt}); "
                         "reduce the continuous model, then discretise")


def _split_groups(model: LinearFaultModel, B: np.ndarray, D: np.ndarray) -> dict:
    sl = model.group_slices()
    return {g: (B[:, sl[g]], D[:, sl[g]]) for g in GROUPS}


def _singular_perturbation(A, B, C, D, keep, drop, what: str):
    """x2 quasi-steady: 0 = A21 x1 + A22 x2 + B2 v  (Kokotovic, Khalil & O'Reilly 1986, ch. 2)."""
    A22 = A[np.ix_(drop, drop)]
    if A22.size:
        s = np.linalg.svd(A22, compute_uv=False)
        if s[-1] <= default_tol(A22.shape, max(s[0], np.linalg.norm(A, 2))) * 1e2:
            raise ConditionError(
                "residualization",
                f"{what}: the residualised block A22 ({len(drop)} x {len(drop)}) is singular "
                f"(smallest singular value {s[-1]:.3e}, largest {s[0]:.3e}); a state with a "
                "zero (integrator) mode cannot be set to steady state",
                {"sigma_min": float(s[-1]), "sigma_max": float(s[0])},
            )
        cond = s[0] / s[-1]
        lu = sla.lu_factor(A22)
        X = sla.lu_solve(lu, np.hstack([A[np.ix_(drop, keep)], B[drop]]))  # A22^-1 [A21, B2]
        XA, XB = X[:, :len(keep)], X[:, len(keep):]
    else:
        cond = 1.0
        XA, XB = np.zeros((0, len(keep))), np.zeros((0, B.shape[1]))
    A12, C2 = A[np.ix_(keep, drop)], C[:, drop]
    Ar = A[np.ix_(keep, keep)] - A12 @ XA
    Br = B[keep] - A12 @ XB
    Cr = C[:, keep] - C2 @ XA
    Dr = D - C2 @ XB
    return Ar, Br, Cr, Dr, float(cond)


def residualize(model: LinearFaultModel, states: Sequence[str]) -> LinearFaultModel:
    """Eliminate named states by setting their derivatives to zero (steady-state correction).

    With ``x = [x1; x2]`` (``x2`` the named states) and every input group ``v``::

        x1' = (A11 - A12 A22^-1 A21) x1 + (B1 - A12 A22^-1 B2) v
        y   = (C1  - C2  A22^-1 A21) x1 + (D  - C2  A22^-1 B2) v

    The DC gain ``D - C A^-1 B`` of every group is unchanged (when ``A`` is invertible), and the
    reduced model is accurate below the eliminated states' bandwidth.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous-time model.
    states : sequence of str
        Names of the states to eliminate (e.g. fast actuator or tyre-force states).

    Returns
    -------
    LinearFaultModel
        ``n - len(states)`` states, keeping the remaining state names, all input names and
        groups, output names.

    Raises
    ------
    ConditionError
        ``condition="residualization"`` when ``A22`` is singular (numbers in the message).
    ModelError
        Unknown state name, discrete model.

    Examples
    --------
    A fast actuator lag (time constant 10 ms) ahead of a slow plant:

    >>> from fdikit.model import LinearFaultModel, residualize
    >>> m = LinearFaultModel([[-1.0, 1.0], [0.0, -100.0]], [[0.0], [100.0]], [[1.0, 0.0]],
    ...                      states=["v", "F"], inputs=["cmd"], outputs=["v_m"])
    >>> r = residualize(m, ["F"])
    >>> r.states, r.A.tolist(), r.B.tolist()
    (['v'], [[-1.0]], [[1.0]])
    """
    _continuous(model, "residualize")
    drop = model.state_index(states)
    if len(set(drop)) != len(drop):
        raise ModelError(f"residualize: duplicated state names in {list(states)}")
    keep = [i for i in range(model.n_states) if i not in drop]
    Ar, Br, Cr, Dr, _ = _singular_perturbation(model.A, model.B_all, model.C, model.D_all, keep, drop,
                                                f"residualize({list(states)})")
    return model.with_matrices(Ar, Cr, _split_groups(model, Br, Dr),
                               states=[model.states[i] for i in keep])


def _ordered_schur(A: np.ndarray, order: int):
    """Real Schur form with the ``order`` eigenvalues of smallest modulus leading."""
    ev = np.linalg.eigvals(A)
    mags = np.sort(np.abs(ev))
    n = A.shape[0]
    if order == 0 or order == n:
        return None
    lo, hi = mags[order - 1], mags[order]
    if not hi > lo * (1 + 1e-9) + 1e-300:
        raise ModelError(
            f"reduce_fast_modes: order {order} splits modes of equal modulus |lambda| = {lo:.6g} "
            f"(a complex pair or repeated eigenvalue); choose order {int(np.sum(mags < lo * (1 - 1e-9)))} "
            f"or {int(np.sum(mags <= lo * (1 + 1e-9)))}"
        )
    thr = 0.5 * (lo + hi)
    T, Z, sdim = sla.schur(A, output="real", sort=lambda re, im: np.hypot(re, im) < thr)
    if sdim != order:  # pragma: no cover - guarded by the gap test above
        raise ModelError(f"reduce_fast_modes: Schur reordering selected {sdim} modes, expected {order}")
    return T, Z


def reduce_fast_modes(model: LinearFaultModel, order: int) -> LinearFaultModel:
    """Keep the ``order`` slowest modes and residualise the fast ones (DC gain kept exactly).

    1. Ordered real Schur form ``A = Z T Z^T`` with the ``order`` eigenvalues of smallest
       ``|lambda|`` leading (``scipy.linalg.schur`` with a sort function).
    2. Block-diagonalisation: ``X`` solves the Sylvester equation ``T11 X - X T22 = -T12``
       (``scipy.linalg.solve_sylvester``), so that ``z = [[I, -X], [0, I]] Z^T x`` has
       ``A_z = diag(T11, T22)`` with slow modes ``z1`` and fast modes ``z2`` decoupled.
    3. Residualisation of ``z2`` (``z2' = 0``): ``A_r = T11``, ``B_r = B1``,
       ``C_r = C1``, ``D_r = D - C2 T22^-1 B2`` for every input group. The reduced model has
       exactly the slow eigenvalues and the DC gain ``D - C A^-1 B`` of the full model.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous-time model.
    order : int
        Number of (slowest) modes to keep, ``0 <= order <= n``; a complex pair counts as two and
        cannot be split.

    Returns
    -------
    LinearFaultModel
        States ``m0 .. m{order-1}`` (slow modal coordinates, real block-triangular ``A``),
        input names, groups and output names of ``model``.

    Raises
    ------
    ModelError
        Discrete model, order out of range, order that splits modes of equal modulus.
    ConditionError
        ``condition="residualization"`` when a fast mode is at zero (cannot happen for
        ``order >= 1`` unless several eigenvalues are zero) or the slow/fast separation is
        numerically ill-posed.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel, reduce_fast_modes
    >>> m = LinearFaultModel(np.diag([-1.0, -50.0]), [[1.0], [50.0]], [[1.0, 1.0]])
    >>> r = reduce_fast_modes(m, 1)
    >>> r.A.round(12).tolist(), r.D.round(12).tolist()    # DC gain 1 + 1 = 2 kept
    ([[-1.0]], [[1.0]])
    """
    _continuous(model, "reduce_fast_modes")
    n = model.n_states
    order = int(order)
    if not 0 <= order <= n:
        raise ModelError(f"reduce_fast_modes: order must be in [0, {n}], got {order}")
    if order == n:
        return model.copy()
    A, B, C, D = model.A, model.B_all, model.C, model.D_all
    names = [f"m{i}" for i in range(order)]
    if order == 0:
        Ar, Br, Cr, Dr, _ = _singular_perturbation(A, B, C, D, [], list(range(n)), "reduce_fast_modes(0)")
        return model.with_matrices(Ar, Cr, _split_groups(model, Br, Dr), states=names)
    T, Z = _ordered_schur(A, order)
    k = order
    T11, T12, T22 = T[:k, :k], T[:k, k:], T[k:, k:]
    X = sla.solve_sylvester(T11, -T22, -T12)
    if not np.all(np.isfinite(X)):
        raise ConditionError("mode separation", "the Sylvester equation separating slow and fast "
                             "modes has no finite solution (shared eigenvalues)", {})
    # z = S^-1 Z^T x with S = [[I, X], [0, I]]; x = Z S z
    Bz = Z.T @ B
    Bz[:k] -= X @ Bz[k:]
    Cz = C @ Z
    Cz[:, k:] += Cz[:, :k] @ X
    Az = sla.block_diag(T11, T22)
    Ar, Br, Cr, Dr, _ = _singular_perturbation(Az, Bz, Cz, D, list(range(k)), list(range(k, n)),
                                               f"reduce_fast_modes({order})")
    return model.with_matrices(Ar, Cr, _split_groups(model, Br, Dr), states=names)


def _gramian_factor(A: np.ndarray, BB: np.ndarray) -> np.ndarray:
    """L with L L^T = P, P the solution of A P + P A^T + BB^T = 0 (semidefinite-safe)."""
    P = sla.solve_continuous_lyapunov(A, -BB @ BB.T)
    P = 0.5 * (P + P.T)
    w, V = np.linalg.eigh(P)
    return V * np.sqrt(np.clip(w, 0.0, None))


def balanced_truncation(
    model: LinearFaultModel,
    order: int,
    *,
    method: str = "truncate",
    groups: Sequence[str] = GROUPS,
) -> tuple[LinearFaultModel, np.ndarray]:
    """Balanced truncation (square-root method) or balanced residualisation of a stable model.

    Square-root algorithm (Laub, Heath, Paige & Ward 1987; Tombs & Postlethwaite 1987):

    1. Gramians ``A P + P A^T + B B^T = 0`` and ``A^T Q + Q A + C^T C = 0``
       (``scipy.linalg.solve_continuous_lyapunov``), factors ``P = Lc Lc^T``, ``Q = Lo Lo^T``
       (symmetric eigen-decomposition, safe for semidefinite Gramians).
    2. SVD ``Lo^T Lc = U S V^T``; the Hankel singular values are ``diag(S)``.
    3. ``W = Lo U1 S1^-1/2``, ``T = Lc V1 S1^-1/2`` (``W^T T = I``); the reduced model is
       ``(W^T A T, W^T B, C T, D)`` for ``method="truncate"``; for ``"matchdc"`` the balanced
       realisation of the minimal part is formed and the states ``order+1 ..`` are residualised
       (balanced singular perturbation: exact DC gain).

    Both obey ``sigma_(r+1) <= ||G - G_r||_inf <= 2 * sum_(i > r) sigma_i``.

    Parameters
    ----------
    model : LinearFaultModel
        Continuous-time, asymptotically stable model.
    order : int
        Reduced order ``r``, ``0 <= r <= n``.
    method : {"truncate", "matchdc"}
    groups : sequence of str
        Input groups whose columns define the controllability Gramian (default all: ``u, d, f,
        w``); the bound holds for the transfer from these groups. Other groups are projected
        with the same transformation.

    Returns
    -------
    reduced : LinearFaultModel
        States ``b0 .. b{r-1}``; input names, groups and output names of ``model``.
    hsv : ndarray (n,)
        Hankel singular values of the full model (from the chosen groups), decreasing.

    Raises
    ------
    ConditionError
        ``condition="stability"`` with the unstable eigenvalues; ``condition="minimality"``
        when ``order`` exceeds the number of nonzero Hankel singular values.
    ModelError
        Discrete model, bad order or method.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel, balanced_truncation
    >>> m = LinearFaultModel(np.diag([-1.0, -2.0, -30.0]), np.ones((3, 1)), np.ones((1, 3)))
    >>> r, hsv = balanced_truncation(m, 2)
    >>> r.n_states, bool(hsv[0] > hsv[1] > hsv[2] > 0)
    (2, True)
    """
    _continuous(model, "balanced_truncation")
    if method not in ("truncate", "matchdc"):
        raise ModelError(f"balanced_truncation: method must be 'truncate' or 'matchdc', got {method!r}")
    n = model.n_states
    order = int(order)
    if not 0 <= order <= n:
        raise ModelError(f"balanced_truncation: order must be in [0, {n}], got {order}")
    A, C = model.A, model.C
    ev = np.linalg.eigvals(A)
    bad = ev[ev.real >= -100 * np.finfo(float).eps * max(1.0, np.linalg.norm(A, 2))]
    if bad.size:
        raise ConditionError("stability", f"balanced truncation needs an asymptotically stable model; "
                             f"{bad.size} eigenvalue(s) with Re >= 0: {np.round(bad, 6).tolist()}",
                             {"unstable_eigenvalues": bad.tolist()})
    for g in groups:
        if g not in GROUPS:
            raise ModelError(f"unknown input group {g!r}; groups are {GROUPS}")
    Bg = np.hstack([model.B_of(g) for g in groups]) if groups else np.zeros((n, 0))
    Lc = _gramian_factor(A, Bg)
    Lo = _gramian_factor(A.T, C.T)
    U, hsv, Vt = np.linalg.svd(Lo.T @ Lc)
    tol = default_tol((n, n), hsv[0]) if hsv.size and hsv[0] > 0 else 0.0
    kmin = int(np.sum(hsv > tol))
    names = [f"b{i}" for i in range(order)]
    B, D = model.B_all, model.D_all
    if order > kmin:
        raise ConditionError("minimality", f"order {order} exceeds the number of nonzero Hankel singular "
                             f"values ({kmin}; hsv = {np.array2string(hsv, precision=3)}); the "
                             f"minimal realisation has order {kmin}", {"hsv": hsv.tolist()})
    k = order if method == "truncate" else kmin
    s = hsv[:k] ** -0.5
    W = (Lo @ U[:, :k]) * s
    T = (Lc @ Vt[:k].T) * s
    Ab, Bb, Cb = W.T @ A @ T, W.T @ B, C @ T
    if method == "matchdc" and order < k:
        Ab, Bb, Cb, D, _ = _singular_perturbation(Ab, Bb, Cb, D, list(range(order)), list(range(order, k)),
                                                  "balanced residualisation")
    return model.with_matrices(Ab, Cb, _split_groups(model, Bb, D), states=names), hsv


# ---------------------------------------------------------------------------------- frequency response
def frequency_response(model: LinearFaultModel, freqs_hz, group: str = "u") -> np.ndarray:
    """Frequency response of one input group, ``G(j 2 pi f)`` (or ``G(e^{j 2 pi f dt})``).

    Parameters
    ----------
    model : LinearFaultModel
    freqs_hz : array_like (F,)
        Frequencies in Hz.
    group : str
        Input group (``"u"``, ``"d"``, ``"f"``, ``"w"``).

    Returns
    -------
    ndarray complex (F, p, m)

    Examples
    --------
    >>> from fdikit.model import LinearFaultModel
    >>> from fdikit.model.reduction import frequency_response
    >>> G = frequency_response(LinearFaultModel([[-1.0]], [[1.0]], [[1.0]]), [0.0])
    >>> G[0].real.tolist()
    [[1.0]]
    """
    f = np.atleast_1d(np.asarray(freqs_hz, float))
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise ModelError("freqs_hz must be finite and >= 0")
    s = 2j * np.pi * f if model.dt is None else np.exp(2j * np.pi * f * model.dt)
    n = model.n_states
    B, D = model.B_of(group), model.D_of(group)
    M = s[:, None, None] * np.eye(n) - model.A  # (F, n, n)
    if n:
        X = np.linalg.solve(M, np.broadcast_to(B.astype(complex), (f.size, *B.shape)))
        return model.C @ X + D
    return np.broadcast_to(D.astype(complex), (f.size, *D.shape)).copy()


def dc_gain(model: LinearFaultModel, group: str = "u") -> np.ndarray:
    """Steady-state gain ``D - C A^-1 B`` (continuous) or ``D + C (I - A)^-1 B`` (discrete).

    Examples
    --------
    >>> from fdikit.model import LinearFaultModel
    >>> from fdikit.model.reduction import dc_gain
    >>> dc_gain(LinearFaultModel([[-2.0]], [[1.0]], [[4.0]])).tolist()
    [[2.0]]
    """
    n = model.n_states
    M = -model.A if model.dt is None else np.eye(n) - model.A
    return model.C @ np.linalg.solve(M, model.B_of(group)) + model.D_of(group)


@dataclass(frozen=True)
class FrequencyResponseError:
    """Relative frequency-response error of a reduced model.

    Attributes
    ----------
    freqs_hz : ndarray (F,)
    rel_error : ndarray (F,) or (F, p, m)
        ``sigma_max(G - G_r) / sigma_max(G)`` per frequency (``mode="matrix"``) or
        ``|G_ij - G_r,ij| / |G_ij|`` per channel (``mode="channel"``).
    bands : tuple of (f_lo, f_hi, max_rel_error, at_hz)
        Largest error inside each band ``f_lo <= f <= f_hi`` and the frequency where it occurs
        (per channel: the maximum over channels).
    """

    freqs_hz: np.ndarray
    rel_error: np.ndarray
    bands: tuple[tuple[float, float, float, float], ...]

    @property
    def max(self) -> float:
        """Largest relative error over all frequencies (and channels)."""
        return float(np.max(self.rel_error))


def frequency_response_error(
    full: LinearFaultModel,
    reduced: LinearFaultModel,
    freqs_hz,
    group: str = "u",
    *,
    bands: Sequence[float] | None = None,
    mode: str = "matrix",
) -> FrequencyResponseError:
    """Max relative error of a reduced model's frequency response, per frequency band.

    Parameters
    ----------
    full, reduced : LinearFaultModel
        Same input names in ``group`` and same outputs.
    freqs_hz : array_like (F,)
        Evaluation grid in Hz (use a dense one: the band maxima are taken over it).
    group : str
        Input group compared.
    bands : sequence of float, optional
        Band edges in Hz, e.g. ``[0, 5, 20]`` for bands 0-5 Hz and 5-20 Hz; default one band
        over the whole grid.
    mode : {"matrix", "channel"}
        ``"matrix"``: ``sigma_max(G - G_r) / sigma_max(G)``; ``"channel"``: per input/output
        pair ``|G_ij - G_r,ij| / |G_ij|`` (``inf`` where ``G_ij = 0`` but the error is not).

    Returns
    -------
    FrequencyResponseError

    Examples
    --------
    ``G = 1/(s+1)`` against its DC gain ``G_r = 1``: the relative error is ``2 pi f``.

    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel, frequency_response_error
    >>> full = LinearFaultModel([[-1.0]], [[1.0]], [[1.0]])
    >>> static = LinearFaultModel(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])
    >>> e = frequency_response_error(full, static, np.linspace(0, 0.1, 11), bands=[0, 0.05, 0.1])
    >>> [round(b[2], 6) for b in e.bands]
    [0.314159, 0.628319]
    """
    if full.input_names(group) != reduced.input_names(group):
        raise ModelError(f"group {group!r} inputs differ: {full.input_names(group)} vs "
                         f"{reduced.input_names(group)}")
    if full.outputs != reduced.outputs:
        raise ModelError(f"outputs differ: {full.outputs} vs {reduced.outputs}")
    if mode not in ("matrix", "channel"):
        raise ModelError(f"mode must be 'matrix' or 'channel', got {mode!r}")
    f = np.atleast_1d(np.asarray(freqs_hz, float))
    G = frequency_response(full, f, group)
    dG = G - frequency_response(reduced, f, group)
    if mode == "matrix":
        num = np.linalg.norm(dG, 2, axis=(1, 2)) if G.size else np.zeros(f.size)
        den = np.linalg.norm(G, 2, axis=(1, 2)) if G.size else np.zeros(f.size)
    else:
        num, den = np.abs(dG), np.abs(G)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(num == 0, 0.0, num / den)
    edges = [float(f.min()), float(f.max())] if bands is None else [float(b) for b in bands]
    if len(edges) < 2 or np.any(np.diff(edges) <= 0):
        raise ModelError(f"bands must be increasing edges (at least two), got {edges}")
    out = []
    per_f = rel.reshape(f.size, -1).max(axis=1) if rel.ndim > 1 else rel
    for lo, hi in itertools.pairwise(edges):
        sel = np.nonzero((f >= lo) & (f <= hi))[0]
        if sel.size == 0:
            raise ModelError(f"no grid frequency in the band [{lo}, {hi}] Hz")
        i = sel[int(np.argmax(per_f[sel]))]
        out.append((lo, hi, float(per_f[i]), float(f[i])))
    return FrequencyResponseError(f, rel, tuple(out))
