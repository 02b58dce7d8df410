"""Fault directions of a fault detection filter: named faults as state (and output) directions,
and the smallest conditioned-invariant subspace containing them.

Fault directions (:func:`fault_directions`): every declared fault ``(b, d)`` of the *discrete*
model becomes a set of state-space directions. With ``d = 0`` (actuator fault without
feedthrough, additive state fault) it is ``b``. With ``d != 0`` (sensor fault, or a fault with
feedthrough) pick ``f_d`` with ``C f_d = d`` and change variables ``x_bar = x + f_d mu``; then
``y = C x_bar`` and ``x_bar[k+1] = A x_bar + f_d mu[k+1] + (b - A f_d) mu[k]``, so the fault acts
as a state fault along ``[f_d, b - A f_d]`` (for a sensor fault ``b = 0``: ``[f_j, A f_j]``,
signs being irrelevant to the span). Why the minimum-norm ``f_d = C^+ d``: the solutions of
``C f = d`` are ``f_d + k`` with ``k`` in ``ker C``, and every choice is an exact model of the
fault, but the filter must block the whole span ``[f, A f]``: an unmeasured component ``k``
enlarges the nuisance subspace (``A k`` adds a direction, and the smallest conditioned-invariant
subspace containing it may eat residual dimensions or swallow the target). ``C^+ d`` is the
unique solution orthogonal to ``ker C`` (no unmeasured component; Euclidean metric of the
model's state coordinates). When ``d`` is not in the range of ``C`` (``C`` of lower rank than
the number of outputs) no ``f_d`` exists: :func:`fault_direction_split` then keeps ``d`` as an
*output* direction that the designs project out of the measurements (``P y`` with ``P d = 0``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...errors import ConditionError, ModelError
from ...model.linear import LinearFaultModel
from ...model.structure import default_tol
from .form import _EPS, _discrete

__all__ = ["conditioned_invariant_subspace", "fault_direction_split", "fault_directions"]

def _orth(M: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis (n, r) of range(M) with the fdikit rank rule."""
    n = M.shape[0]
    if M.size == 0:
        return np.zeros((n, 0))
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    if tol is None:
        tol = default_tol(M.shape, s[0] if s.size else 0.0)
    return U[:, : int(np.sum(s > tol))]


def _complement_rows(Y: np.ndarray, p: int) -> np.ndarray:
    """Orthonormal rows (p - r, p) spanning the orthogonal complement of range(Y)."""
    if Y.shape[1] == 0:
        return np.eye(p)
    U, _, _ = np.linalg.svd(Y, full_matrices=True)
    return U[:, Y.shape[1]:].T.copy()


def fault_directions(model: LinearFaultModel, faults: str | Sequence[Any], *, dt: float | None = None,
                     ) -> np.ndarray:
    """State-space directions of named faults of a (discretised) model.

    Parameters
    ----------
    model : LinearFaultModel
        Discrete, or continuous with ``dt`` (discretised by ZOH first: the directions are those
        of the sampled model, which is what the filter sees).
    faults : str or sequence
        Fault names declared on the model, or ``(label, M)`` with ``M`` (n, k) explicit
        directions in the discrete model's state space.
    dt : float, optional
        Sample time (s) for a continuous model.

    Returns
    -------
    ndarray (n, k)
        For each fault ``(b, d)``: ``b`` if ``d = 0``; otherwise ``[f_d, b - A f_d]`` with
        ``f_d = C^+ d`` (the minimum-norm solution of ``C f_d = d``; a sensor fault on output
        ``j`` gives ``[f_j, -A f_j]``). Numerically zero columns are dropped.

    Raises
    ------
    ConditionError
        ``"sensor direction"`` when ``d`` is not in the range of ``C`` (no ``f_d`` exists; see
        :func:`fault_direction_split` for the output-space treatment of such faults).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[0.9, 0.1], [0.0, 0.8]], [[0.0], [1.0]], [[1.0, 0.0]], dt=0.1,
    ...                      faults=["actuator:u0", "sensor:y0"])
    >>> fault_directions(m, "actuator:u0").ravel().tolist()
    [0.0, 1.0]
    >>> fault_directions(m, "sensor:y0").round(12).tolist()   # [f_j, -A f_j], C f_j = 1
    [[1.0, -0.9], [0.0, 0.0]]
    """
    return fault_direction_split(model, faults, dt=dt, sensor="state")[0]


def fault_direction_split(model: LinearFaultModel, faults: str | Sequence[Any], *, dt: float | None = None,
                          sensor: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """State directions and remaining output directions of faults (see :func:`fault_directions`).

    A fault ``(b, d)`` with ``d != 0`` is turned into state directions ``[f_d, b - A f_d]`` when
    ``sensor="state"``, or when ``sensor="auto"`` and ``d`` lies in the range of ``C`` (the
    construction of the notes, which needs ``C f_d = d`` solvable). Otherwise (``sensor="output"``,
    or ``"auto"`` with ``d`` outside the range of ``C``, e.g. when ``C`` has lower rank than the
    number of outputs) it is kept as an *output* direction ``d`` (and a state direction ``b``):
    a filter blind to it discards the component of ``y`` along ``d`` (paper-free generalisation:
    the filter is designed on the projected outputs ``P y`` with ``P d = 0``).

    Returns
    -------
    E : ndarray (n, k)
        State-space directions.
    Y : ndarray (p, l)
        Output-space directions to be projected out.

    Raises
    ------
    ConditionError
        ``"sensor direction"`` with ``sensor="state"`` when ``d`` is not in the range of ``C``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.eye(2) * 0.5, np.zeros((2, 0)), [[1.0, 0.0], [1.0, 0.0]], dt=0.1,
    ...                      faults=["sensor:y1"])
    >>> E, Y = fault_direction_split(m, "sensor:y1")     # e2 is not in range(C): output direction
    >>> E.shape, Y.ravel().tolist()
    ((2, 0), [0.0, 1.0])
    """
    if sensor not in ("auto", "state", "output"):
        raise ModelError(f"sensor must be 'auto', 'state' or 'output', got {sensor!r}")
    md = _discrete(model, dt)
    A, C = md.A, md.C
    n, p = md.n_states, md.n_outputs
    if isinstance(faults, str):
        faults = [faults]
    cols: list[np.ndarray] = []
    ycols: list[np.ndarray] = []
    Cp = np.linalg.pinv(C)
    for spec in faults:
        if isinstance(spec, str):
            b, d = md.fault_direction(spec)
            if np.linalg.norm(d) == 0:
                cols.append(b[:, None])
                continue
            f = Cp @ d
            res = np.linalg.norm(C @ f - d)
            in_range = res <= 1e3 * _EPS * max(1.0, np.linalg.norm(d)) * max(1.0, np.linalg.norm(C, 2)) * n
            if sensor == "output" or (sensor == "auto" and not in_range):
                ycols.append(d[:, None])
                cols.append(b[:, None])
                continue
            if not in_range:
                raise ConditionError(
                    "sensor direction",
                    f"fault {spec!r}: its output direction d = {np.round(d, 6).tolist()} is not in the "
                    f"range of C (residual |C f - d| = {res:.3e}); it cannot be turned into state "
                    "directions", {"fault": spec, "residual": float(res)})
            cols.append(np.column_stack([f, b - A @ f]))
        else:
            try:
                label, M = spec
            except (TypeError, ValueError):
                raise ModelError(f"fault spec {spec!r} must be a fault name or (label, directions)") from None
            M = np.asarray(M, float)
            M = M.reshape(n, -1) if M.ndim < 2 else M
            if M.shape[0] != n or not np.all(np.isfinite(M)):
                raise ModelError(f"directions {label!r} must be finite with {n} rows, got shape {M.shape}")
            cols.append(M)

    def _nonzero(F: np.ndarray) -> np.ndarray:
        if F.size:
            scale = max(1.0, float(np.max(np.abs(F))))
            F = F[:, np.linalg.norm(F, axis=0) > 1e3 * _EPS * scale]
        return F

    E = _nonzero(np.hstack(cols)) if cols else np.zeros((n, 0))
    Y = _nonzero(np.hstack(ycols)) if ycols else np.zeros((p, 0))
    return E, Y


def conditioned_invariant_subspace(A: Any, C: Any, F: Any, *, tol: float | None = None) -> np.ndarray:
    """Smallest ``(C, A)``-invariant subspace containing ``range(F)``; orthonormal basis (n, r).

    The recursion ``S_0 = range(F)``, ``S_{k+1} = range(F) + A (S_k ∩ ker C)`` (Basile &
    Marro) stops after at most ``n`` steps. ``C S*`` are the output directions through which
    faults along ``F`` reach the output error of any observer: for columns with independent
    ``C A^delta_i f_i`` it is ``span{C A^delta_i f_i}``, the ``C F_hat`` of Chen & Speyer.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    >>> S = conditioned_invariant_subspace(A, [[1.0, 0.0, 0.0]], [[0.0], [0.0], [1.0]])
    >>> S.shape[1]   # e3 -> A e3 = e2 -> A e2 = e1 (measured): three directions
    3
    """
    A = np.asarray(A, float)
    C = np.atleast_2d(np.asarray(C, float))
    F = np.asarray(F, float).reshape(A.shape[0], -1)
    n = A.shape[0]
    scale = max(1.0, np.linalg.norm(A, 2), np.linalg.norm(C, 2))
    tol = (n * 1e3 * _EPS * scale) if tol is None else tol
    F0 = _orth(F, tol * max(1.0, float(np.linalg.norm(F, 2))) if F.size else tol)
    S = F0
    for _ in range(n + 1):
        if S.shape[1] == 0:
            return S
        # S ∩ ker C = S N with N the null space of C S
        _, s, Vt = np.linalg.svd(C @ S, full_matrices=True)
        r = int(np.sum(s > tol))
        N = S @ Vt[r:].T
        Snew = _orth(np.hstack([F0, A @ N]), tol)
        if Snew.shape[1] == S.shape[1]:
            return Snew
        S = Snew
    return S  # pragma: no cover - dimension grows at most n times


def _target_nuisance(md: LinearFaultModel, target: Any, nuisance: Any, sensor: str):
    target = [target] if isinstance(target, str) else list(target)
    nuisance = [nuisance] if isinstance(nuisance, str) else list(nuisance or [])
    if not target:
        raise ModelError("a fault detection filter needs a target fault")
    both = [t for t in target if isinstance(t, str) and t in [s for s in nuisance if isinstance(s, str)]]
    if both:
        raise ModelError(f"faults {both} are listed both as target and as nuisance")
    E1, Y1 = fault_direction_split(md, target, sensor=sensor)
    E2, Y2 = fault_direction_split(md, nuisance, sensor=sensor) if nuisance else \
        (np.zeros((md.n_states, 0)), np.zeros((md.n_outputs, 0)))
    label = lambda s: s if isinstance(s, str) else str(s[0])  # noqa: E731
    return [label(s) for s in target], [label(s) for s in nuisance], E1, Y1, E2, Y2
