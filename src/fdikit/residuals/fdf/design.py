"""Fault detection filters: exact unknown input observer and optimal stochastic fault detection filter.

A fault detection filter watches one *target* fault and blocks *nuisance* faults (other faults,
and the linearisation error of a nonlinear plant modelled as a fault; ng-chen-speyer, Sections II and
IV-A). Two designs are offered, both in discrete time at the sample rate of the monitor:

* :func:`design_uio` - the exact unknown input observer of Chen, Patton & Zhang (1996), for a
  nuisance distribution ``E`` with ``rank(C E) = rank(E)`` and ``(C, A1)`` detectable. The
  nuisance-to-residual transfer is zero (to rounding).
* :func:`design_optimal_fdf` - the optimal stochastic fault detection filter of Chen, Mingori &
  Speyer (Automatica 39 (2003) 377-390), here in its steady-state *discrete-time* form: a
  Kalman-type filter whose process-noise model carries the nuisance directions with the large
  intensity ``Q2 / gamma`` and whose residual is the projected output error ``r = H (y - C x_hat)``,
  ``H`` annihilating the output directions of the nuisance. As ``gamma -> 0`` the nuisance
  subspace becomes unobservable from ``r`` (the UIO's geometric structure) and its eigenvalues go
  to ``z = 0`` (the discrete image of ``-infinity``); short of the limit these fast, weakly
  observable modes are removed by model reduction (ng-chen-speyer, Section IV-C,
  :func:`reduce_filter`).

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
*output* direction that the designs project out of the measurements (``P y`` with ``P d = 0``).

Source note: only the abstract of Chen, Mingori & Speyer (2003) and the table of contents of
R. H. Chen's dissertation (2000) were readable with the search tools. The discrete steady-state
formulation below (nuisance as white noise of intensity ``Q2 / gamma`` in a Kalman predictor,
projector ``H`` from the smallest ``(C, A)``-invariant subspace of the nuisance, which reduces
to ``C F_hat_2`` with ``F_hat_2 = [A^delta_i f_i]`` of Chen & Speyer when those are independent)
is derived here to have the properties the abstract and the notes state: the limit
``gamma -> 0`` recovers the UIO's structure, the nuisance transmission vanishes like ``gamma``
(both checked in the tests), and near the limit the filter has fast weakly observable modes.
The paper's weighting of the target fault in its cost is not modelled (the target enters only
through the separability and visibility checks).

Every design is a plain-matrix :class:`FilterDesign` (the *implementation form*)

    xi[k+1] = A xi[k] + Bu u[k] + By y[k]
    r[k]    = C xi[k] + Du u[k] + Dy y[k]

run by :class:`FaultDetectionFilter` (batch ``run`` and streaming ``step``, bitwise equal);
its ``internal`` attribute holds the internal form against the design model, and
:func:`internal_form` composes any design with any :class:`~fdikit.model.linear.LinearFaultModel`
into the transfer from every input group (controls, disturbances, faults, noise) to ``r``; the
design's ``info`` records the conditions checked, ranks, ``gamma``, eigenvalues and reduction.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from numba import njit

from ...base.stage import ResidualGenerator
from ...errors import ConditionError, ModelError
from ...model.linear import GROUPS, LinearFaultModel
from ...model.structure import default_tol, invariant_zeros, rank, unobservable_modes
from ...signals import Signals

__all__ = [
    "FaultDetectionFilter",
    "FilterDesign",
    "conditioned_invariant_subspace",
    "design_filter_set",
    "design_optimal_fdf",
    "design_uio",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "filter_frequency_response",
    "internal_form",
    "modal_observability",
    "reduce_filter",
    "residual_covariance",
    "stack_designs",
]

_EPS = np.finfo(float).eps


# ---------------------------------------------------------------------------------- design object
@dataclass
class FilterDesign:
    """Implementation form of a discrete linear residual generator (plain matrices).

    ``xi[k+1] = A xi + Bu u + By y``, ``r = C xi + Du u + Dy y``.

    Attributes
    ----------
    A : ndarray (nf, nf)
    Bu : ndarray (nf, m)
        Gain on the controls ``u`` (channels ``u_names``).
    By : ndarray (nf, p)
        Gain on the measurements ``y`` (channels ``y_names``).
    C : ndarray (q, nf)
    Du : ndarray (q, m)
    Dy : ndarray (q, p)
    dt : float
        Sample time (s).
    u_names, y_names : list of str
    residual_names : list of str
        ``q`` residual channel names.
    info : dict
        Method, target and nuisance, conditions checked with their ranks, ``gamma``, filter
        eigenvalues, reduction order (see the design functions).
    internal : LinearFaultModel or None
        Internal form against the design model (:func:`internal_form`), set by the design
        functions: the transfer from every input group of the model to the residual.
    """

    A: np.ndarray
    Bu: np.ndarray
    By: np.ndarray
    C: np.ndarray
    Du: np.ndarray
    Dy: np.ndarray
    dt: float
    u_names: list[str]
    y_names: list[str]
    residual_names: list[str]
    info: dict[str, Any] = field(default_factory=dict)
    internal: LinearFaultModel | None = field(default=None, repr=False)

    @property
    def order(self) -> int:
        """Number of filter states ``nf``."""
        return self.A.shape[0]

    def to_dict(self, *, inline: int = 100) -> dict[str, Any]:
        """Matrices and names (``info`` omitted) as plain data.

        A matrix with at most ``inline`` entries is a nested list (readable and editable in an
        artifact's JSON manifest); a larger one stays a float array (stored exactly in the
        artifact's NPZ; a 60-state filter bank's JSON was 1.7 MB of decimal text). Pass
        ``inline=None`` for lists throughout (JSON-ready).
        """
        def conv(a: np.ndarray):
            return a.tolist() if inline is None or a.size <= inline else np.array(a, float)

        out: dict[str, Any] = {k: conv(getattr(self, k)) for k in ("A", "Bu", "By", "C", "Du", "Dy")}
        out.update(dt=self.dt, u_names=self.u_names, y_names=self.y_names,
                   residual_names=self.residual_names)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FilterDesign:
        """Inverse of :meth:`to_dict`."""
        mats = {k: np.asarray(d[k], float) for k in ("A", "Bu", "By", "C", "Du", "Dy")}
        nf, q = len(d["A"]), len(d["residual_names"])
        m, p = len(d["u_names"]), len(d["y_names"])
        for k, shp in {"A": (nf, nf), "Bu": (nf, m), "By": (nf, p), "C": (q, nf), "Du": (q, m),
                       "Dy": (q, p)}.items():
            mats[k] = mats[k].reshape(shp)
        return cls(**mats, dt=float(d["dt"]), u_names=list(d["u_names"]), y_names=list(d["y_names"]),
                   residual_names=list(d["residual_names"]))


# ---------------------------------------------------------------------------------- helpers
def _discrete(model: LinearFaultModel, dt: float | None) -> LinearFaultModel:
    if not isinstance(model, LinearFaultModel):
        raise ModelError(f"a LinearFaultModel is needed, got {type(model).__name__}")
    if model.is_discrete:
        if dt is not None and abs(dt - model.dt) > 1e-12 * max(1.0, model.dt):
            raise ModelError(f"model is discrete with dt = {model.dt}, cannot design for dt = {dt}")
        return model
    if dt is None:
        raise ModelError("a continuous model needs the sample time dt of the filter")
    return model.discretize(dt)


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


def _markov_visible(Af: np.ndarray, B: np.ndarray, Cf: np.ndarray, D: np.ndarray, steps: int) -> float:
    """Largest |Markov parameter| of (Af, B, Cf, D) over ``steps`` samples."""
    best = float(np.max(np.abs(D))) if D.size else 0.0
    X = B.copy()
    for _ in range(steps):
        if X.size == 0:
            break
        best = max(best, float(np.max(np.abs(Cf @ X))))
        X = Af @ X
    return best


def _fault_transfer_columns(md: LinearFaultModel, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(B, D) columns of named model faults (zeros for explicit directions)."""
    Bs, Ds = [], []
    for s in names:
        if s in md.fault_names:
            b, d = md.fault_direction(s)
            Bs.append(b)
            Ds.append(d)
    n, p = md.n_states, md.n_outputs
    return (np.column_stack(Bs) if Bs else np.zeros((n, 0)), np.column_stack(Ds) if Ds else np.zeros((p, 0)))


def _check_target_visible(design: FilterDesign, md: LinearFaultModel, target: list[str],
                          F1: np.ndarray) -> float:
    """Target must reach the residual: largest Markov parameter of the target transfer."""
    Bt, Dt = _fault_transfer_columns(md, target)
    if Bt.shape[1] == 0:  # explicit directions only
        Bt, Dt = F1, np.zeros((md.n_outputs, F1.shape[1]))
    Af = np.block([[md.A, np.zeros((md.n_states, design.order))], [design.By @ md.C, design.A]])
    B = np.vstack([Bt, design.By @ Dt])
    Cf = np.hstack([design.Dy @ md.C, design.C])
    vis = _markov_visible(Af, B, Cf, design.Dy @ Dt, Af.shape[0] + 1)
    scale = max(1.0, float(np.max(np.abs(B))) if B.size else 1.0) * max(1.0, float(np.abs(Cf).max()))
    if vis <= 1e6 * _EPS * scale:
        raise ConditionError(
            "target visibility",
            f"target {target} does not reach the residual (largest Markov parameter {vis:.3e}); "
            "it lies in the nuisance's detection space (the faults are not output separable)",
            {"largest_markov_parameter": vis})
    return vis


# ---------------------------------------------------------------------------------- exact UIO
def _stabilising_gain(A1: np.ndarray, C: np.ndarray, poles: Any, Q: Any, R: Any) -> tuple[np.ndarray, str]:
    n, p = A1.shape[0], C.shape[0]
    if poles is not None:
        from scipy.signal import place_poles

        poles = np.asarray(poles)
        if poles.size != n:
            raise ModelError(f"need {n} poles for the UIO, got {poles.size}")
        return place_poles(A1.T, C.T, poles).gain_matrix.T, "poles"
    Qm = np.eye(n) if Q is None else np.atleast_2d(np.asarray(Q, float))
    Rm = np.eye(p) if R is None else np.atleast_2d(np.asarray(R, float))
    if Qm.shape != (n, n) or Rm.shape != (p, p):
        raise ModelError(f"Q must be {(n, n)} and R {(p, p)}, got {Qm.shape} and {Rm.shape}")
    P = sla.solve_discrete_are(A1.T, C.T, Qm, Rm)
    # predictor gain of the dual LQ problem: A1 - K1 C Schur stable
    return A1 @ P @ C.T @ np.linalg.inv(C @ P @ C.T + Rm), "riccati"


def design_uio(
    model: LinearFaultModel,
    target: Any,
    nuisance: Any,
    *,
    dt: float | None = None,
    poles: Any = None,
    Q: Any = None,
    R: Any = None,
    sensor: str = "auto",
    name: str | None = None,
) -> FilterDesign:
    """Exact unknown input observer (Chen, Patton & Zhang 1996) decoupling the nuisance faults.

    With nuisance directions ``E`` (:func:`fault_directions`), ``H = E (C E)^+``, ``T = I - H C``,
    ``A1 = T A``, ``F = A1 - K1 C`` and ``K = K1 + F H``, the discrete observer is::

        z[k+1] = F z + (T B - K D) u + K y,    x_hat = z + H (y - D u),    r = y - D u - C x_hat

    and its error ``e = x - x_hat`` obeys ``e[k+1] = F e + T E mu2`` with ``T E = 0``: the nuisance
    never reaches ``r = C e``.

    Parameters
    ----------
    model : LinearFaultModel
        Discrete, or continuous with ``dt`` (ZOH).
    target : str or sequence
        Target fault(s) (names declared on the model).
    nuisance : str or sequence
        Nuisance faults: names, or ``(label, directions (n, k))`` in the discrete state space.
    dt : float, optional
        Sample time (s).
    poles : array_like (n,), optional
        Discrete eigenvalues of ``F`` (pole placement on ``(A1, C)``; needs ``(C, A1)`` observable).
        Default: ``K1`` from the discrete Riccati equation on ``(A1, C)`` with weights ``Q``
        (default I) and ``R`` (default I), which only needs detectability.
    sensor : {"auto", "state", "output"}
        Treatment of nuisance faults with an output direction (:func:`fault_direction_split`);
        output-space directions are removed by a projection ``P`` (``P d = 0``) of the
        measurements and the observer is designed on ``(A, B, P C, P D)``.

    Returns
    -------
    FilterDesign
        ``p`` residuals ``"<name>:<output>"`` (``p - l`` residuals ``"<name>:<i>"`` after
        projecting out ``l`` output directions); ``info`` has ``rank_CE``, ``rank_E``,
        ``unobservable_modes`` of ``(C, A1)``, ``eigenvalues`` and ``spectral_radius`` of ``F``,
        ``H``, ``T``, ``K1``, the projection ``P``.

    Raises
    ------
    ConditionError
        ``"rank(CE) = rank(E)"`` with both ranks; ``"detectability of (C, A1)"`` with the
        unstable unobservable modes; ``"target visibility"`` when the target is decoupled too.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> d = design_uio(m, "actuator:u0", ["actuator:u1"])
    >>> d.info["rank_CE"], d.info["rank_E"]
    (1, 1)
    """
    md = _discrete(model, dt)
    tnames, nnames, E1, _, E, Yd = _target_nuisance(md, target, nuisance, sensor)
    A, B, n = md.A, md.B, md.n_states
    # output-space nuisance directions (sensor faults outside range C) are projected out first
    Pd = _complement_rows(_orth(Yd), md.n_outputs)
    C, D = Pd @ md.C, Pd @ md.D
    p = C.shape[0]
    if p == 0:
        raise ConditionError("residual dimension", "the nuisance output directions span all "
                             f"{md.n_outputs} outputs: no measurement is left", {"outputs": md.n_outputs})
    rE, rCE = rank(E), rank(C @ E)
    info: dict[str, Any] = {"method": "uio", "target": tnames, "nuisance": nnames, "rank_E": rE,
                            "rank_CE": rCE, "output_nuisance_directions": Yd.shape[1], "P": Pd,
                            "conditions": {}}
    if rCE != rE:
        raise ConditionError("rank(CE) = rank(E)",
                             f"the nuisance directions E ({n} x {E.shape[1]}) have rank {rE} but C E has "
                             f"rank {rCE}: no exact unknown input observer exists (use the optimal "
                             "stochastic filter)", {"rank_E": rE, "rank_CE": rCE})
    info["conditions"]["rank(CE) = rank(E)"] = f"{rCE} = {rE}"
    Eo = _orth(E)  # same H for any basis of range(E) when rank(CE) = rank(E); better conditioned
    H = Eo @ np.linalg.pinv(C @ Eo) if Eo.shape[1] else np.zeros((n, p))
    T = np.eye(n) - H @ C
    A1 = T @ A
    um = unobservable_modes(A1, C)
    bad = um[np.abs(um) >= 1 - 100 * _EPS * max(1.0, np.linalg.norm(A1, 2))]
    if bad.size:
        raise ConditionError("detectability of (C, A1)",
                             f"A1 = (I - E (CE)^+ C) A has {bad.size} unobservable mode(s) on or outside "
                             f"the unit circle: {np.round(bad, 6).tolist()}",
                             {"unstable_unobservable_modes": bad.tolist(), "unobservable_modes": um.tolist()})
    info["conditions"]["detectability of (C, A1)"] = f"unobservable modes {np.round(um, 6).tolist()}"
    K1, how = _stabilising_gain(A1, C, poles, Q, R)
    F = A1 - K1 @ C  # Chen, Patton & Zhang (1996): F = A - HCA - K1 C
    K = K1 + F @ H  # K2 = F H makes the error independent of x
    eig = np.linalg.eigvals(F)
    rho = float(np.max(np.abs(eig))) if n else 0.0
    if rho >= 1:
        raise ConditionError("stability", f"UIO matrix F has spectral radius {rho:.6g} >= 1",
                             {"eigenvalues": eig.tolist()})
    I_CH = np.eye(p) - C @ H
    nm = name or f"uio[{','.join(tnames)}]"
    rnames = [f"{nm}:{y}" for y in md.outputs] if Yd.shape[1] == 0 else [f"{nm}:{i}" for i in range(p)]
    design = FilterDesign(
        A=F, Bu=T @ B - K @ D, By=K @ Pd, C=-C, Du=-I_CH @ D, Dy=I_CH @ Pd, dt=float(md.dt),
        u_names=list(md.inputs), y_names=list(md.outputs), residual_names=rnames, info=info)
    info.update(gain_method=how, eigenvalues=eig, spectral_radius=rho, unobservable_modes=um,
                H=H, T=T, K1=K1, order=n, reduction=None)
    info["target_markov_max"] = _check_target_visible(design, md, tnames, E1)
    design.internal = internal_form(design, md)
    return design


# ---------------------------------------------------------------------------------- optimal stochastic FDF
def design_optimal_fdf(
    model: LinearFaultModel,
    target: Any,
    nuisance: Any,
    *,
    gamma: float = 1e-6,
    dt: float | None = None,
    Q2: Any = None,
    Qw: Any = None,
    V: Any = None,
    reduce: str | None = "residualize",
    order: int | None = None,
    fast_modulus: float = 0.05,
    weak_observability: float = 1e-4,
    sensor: str = "auto",
    name: str | None = None,
) -> FilterDesign:
    """Optimal stochastic fault detection filter (Chen, Mingori & Speyer 2003), steady state, discrete.

    1. Nuisance directions ``F2`` and target directions ``F1`` (:func:`fault_directions`).
    2. Output directions of the nuisance ``C S2*`` with ``S2*`` the smallest ``(C, A)``-invariant
       subspace containing ``F2`` (:func:`conditioned_invariant_subspace`; ``C F_hat_2`` of the
       paper); ``H = I - C S2* (C S2*)^+`` annihilates them. The residual is ``r = Hr (y - C x_hat
       - D u)`` with ``Hr`` (p - s, p) orthonormal rows, ``Hr^T Hr = H`` (so ``|r| = |H (y - ...)|``).
    3. Steady-state discrete Riccati equation (predictor form)::

           P = A P A' - A P C' (C P C' + V)^-1 C P A' + Qw + F2 Q2 F2' / gamma
           L = A P C' (C P C' + V)^-1,     x_hat[k+1] = A x_hat + B u + L (y - C x_hat - D u)

       the nuisance weighted by ``1/gamma``. As ``gamma -> 0`` the filter corrects the nuisance
       directions in one step where it can (``(A - L C) f -> 0`` for ``C f != 0``), the
       nuisance subspace ``S2*`` becomes unobservable from ``r`` with eigenvalues -> 0 (the UIO
       structure; in continuous time they go to ``-infinity``), and the nuisance transmission
       falls in proportion to ``gamma``. Discrete time is used because the monitor runs at a fixed sample
       rate; a continuous model is discretised by ZOH first. (See the module's source note:
       the paper's target-fault weighting is not modelled.)
    4. Model reduction (ng-chen-speyer, Section IV-C): the fast (``|z| <= fast_modulus``) and the weakly
       observable (relative modal observability from ``r`` below ``weak_observability``)
       filter modes, which approximate the nuisance subspace, are removed by
       :func:`reduce_filter` (``reduce="residualize"``: steady-state correction, exact DC gain;
       ``"truncate"``; ``None``: keep the full filter).

    Parameters
    ----------
    model : LinearFaultModel
    target, nuisance : str or sequence
        Fault names (or ``(label, directions)`` for nuisances given as explicit directions).
    gamma : float
        Nuisance weighting (> 0); smaller blocks harder.
    dt : float, optional
        Sample time (s) for a continuous model.
    Q2 : array_like (k2, k2), optional
        Nuisance intensity shape (default I).
    Qw : array_like (n, n), optional
        Process-noise covariance (default ``Bw Bw'`` of the model plus ``1e-6 I``).
    V : array_like (p, p), optional
        Measurement-noise covariance (default ``Dw Dw'`` plus ``1e-6 I``, or I without noise group).
    reduce : {"residualize", "truncate", None}
    order : int, optional
        Reduced order (the ``order`` most observable modes are kept); default: drop the modes
        with ``|z| <= fast_modulus`` or observability below ``weak_observability``.
    fast_modulus : float
        Modulus below which a discrete mode counts as fast (0.05: faster than ``dt / 3``).
    weak_observability : float
        Relative modal observability (:func:`modal_observability`) below which a mode is dropped.
    sensor : {"auto", "state", "output"}
        Treatment of faults with an output direction (:func:`fault_direction_split`): output-space
        nuisance directions are removed by a projection ``P`` of the measurements (``P d = 0``)
        before steps 2-3, which then use ``P C``, ``P D`` and ``P V P'``.

    Returns
    -------
    FilterDesign
        ``info`` has ``gamma``, ``rank_E``/``rank_CE`` of the nuisance (whether an exact UIO
        would exist), ``nuisance_output_rank``, ``nuisance_invariant_zeros`` (discrete: the
        fixed modes an exact UIO would have; an unstable one rules the UIO out but not this
        filter, whose eigenvalues are always inside the unit circle), ``H``, ``L``, ``P``,
        ``eigenvalues`` of the full filter, ``full`` (the unreduced :class:`FilterDesign`),
        ``order`` and ``reduction``.

    Raises
    ------
    ConditionError
        ``"residual dimension"`` when the nuisance output directions fill the output space;
        ``"target visibility"`` when the target does not reach the residual; ``"riccati"`` when
        the Riccati equation has no stabilising solution.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> A = [[0.9, 0.1, 0.0], [0.0, 0.8, 0.1], [0.05, 0.0, 0.7]]
    >>> m = LinearFaultModel(A, [[0.0], [0.0], [1.0]], np.eye(3)[:2], dt=0.01,
    ...                      faults=["actuator:u0", ("leak", [1.0, 0.0, 0.0], None)])
    >>> d = design_optimal_fdf(m, "actuator:u0", ["leak"], gamma=1e-6, reduce=None)
    >>> d.residual_names, d.info["nuisance_output_rank"]
    (['fdf[actuator:u0]:0'], 1)
    """
    if not (gamma > 0 and np.isfinite(gamma)):
        raise ModelError(f"gamma must be a positive number, got {gamma}")
    md = _discrete(model, dt)
    tnames, nnames, F1, Y1, F2, Yd = _target_nuisance(md, target, nuisance, sensor)
    A, B, n = md.A, md.B, md.n_states
    # output-space nuisance directions (sensor faults outside range C) are projected out first
    Pd = _complement_rows(_orth(Yd), md.n_outputs)
    C, D = Pd @ md.C, Pd @ md.D
    p = C.shape[0]
    S2 = conditioned_invariant_subspace(A, C, F2)
    Y2 = _orth(C @ S2)  # nuisance output directions (C F_hat_2 of the paper)
    s = Y2.shape[1]
    if s >= p:
        raise ConditionError("residual dimension",
                             f"the nuisance output directions span all {md.n_outputs} outputs "
                             f"({Yd.shape[1]} direct, rank C S2* = {s}); the projected residual "
                             "H (y - C x_hat) would be identically zero",
                             {"nuisance_output_rank": s + Yd.shape[1], "outputs": md.n_outputs})
    Hr = _complement_rows(Y2, p) @ Pd  # (p_out - l - s, p_out), orthonormal rows
    H = Hr.T @ Hr
    # output separability: the target must add output directions to the nuisance's
    s12 = rank(np.hstack([C @ conditioned_invariant_subspace(A, C, np.hstack([F2, F1])), Pd @ Y1]))
    if s12 <= s:
        raise ConditionError("target visibility",
                             f"target {tnames} adds no output direction to the nuisance's (rank C S* = {s} "
                             f"with and without it): target and nuisance are not output separable",
                             {"nuisance_output_rank": s, "joint_output_rank": s12})
    k2 = F2.shape[1]
    po = md.n_outputs
    Q2m = np.eye(k2) if Q2 is None else np.atleast_2d(np.asarray(Q2, float))
    Bw, Dw = md.B_of("w"), md.D_of("w")
    Qwm = Bw @ Bw.T + 1e-6 * np.eye(n) if Qw is None else np.atleast_2d(np.asarray(Qw, float))
    if V is None:
        Vm = Dw @ Dw.T + 1e-6 * np.eye(po) if Dw.size and np.any(Dw) else np.eye(po)
    else:
        Vm = np.atleast_2d(np.asarray(V, float))
    if Q2m.shape != (k2, k2) or Qwm.shape != (n, n) or Vm.shape != (po, po):
        raise ModelError(f"Q2 must be {(k2, k2)}, Qw {(n, n)} and V {(po, po)}; got {Q2m.shape}, "
                         f"{Qwm.shape}, {Vm.shape}")
    Vp = Pd @ Vm @ Pd.T
    Qtot = Qwm + F2 @ Q2m @ F2.T / gamma  # nuisance weighted by 1/gamma (ng-chen-speyer, Riccati eq.)
    Qtot = 0.5 * (Qtot + Qtot.T)
    try:
        P = sla.solve_discrete_are(A.T, C.T, Qtot, Vp)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ConditionError("riccati", f"the filter Riccati equation has no stabilising solution "
                             f"(gamma = {gamma:g}): {exc}", {"gamma": gamma}) from None
    P = 0.5 * (P + P.T)
    L = A @ P @ C.T @ np.linalg.inv(C @ P @ C.T + Vp)  # gain on the projected outputs P y
    Af = A - L @ C
    eig = np.linalg.eigvals(Af)
    rho = float(np.max(np.abs(eig))) if n else 0.0
    if not rho < 1:
        raise ConditionError("stability", f"filter A - L C has spectral radius {rho:.6g} >= 1 "
                             f"(gamma = {gamma:g})", {"eigenvalues": eig.tolist()})
    nm = name or f"fdf[{','.join(tnames)}]"
    full = FilterDesign(
        A=Af, Bu=B - L @ D, By=L @ Pd, C=-Hr @ md.C, Du=-Hr @ md.D, Dy=Hr.copy(), dt=float(md.dt),
        u_names=list(md.inputs), y_names=list(md.outputs),
        residual_names=[f"{nm}:{i}" for i in range(Hr.shape[0])])
    rE, rCE = rank(F2), rank(C @ F2)
    # invariant zeros of the nuisance channel (A, F2, C): the fixed modes of an exact UIO (its
    # unobservable modes of (C, A1)); the stochastic filter stays stable when one is unstable
    zeros = invariant_zeros(A, F2, C) if F2.shape[1] else np.zeros(0, complex)
    info: dict[str, Any] = {
        "method": "optimal_fdf", "target": tnames, "nuisance": nnames, "gamma": float(gamma),
        "discrete": True, "rank_E": rE, "rank_CE": rCE, "exact_uio_rank_condition": rE == rCE,
        "output_nuisance_directions": Yd.shape[1],
        "nuisance_subspace_dim": S2.shape[1], "nuisance_output_rank": s,
        "target_output_rank": rank(np.hstack([C @ conditioned_invariant_subspace(A, C, F1), Pd @ Y1])),
        "nuisance_invariant_zeros": zeros,
        "P_out": Pd, "H": H, "Hr": Hr, "L": L, "P": P, "eigenvalues": eig, "spectral_radius": rho,
        "conditions": {"residual dimension": f"{p} outputs - {s} nuisance output directions = {p - s}",
                       "output separability": f"rank C S*(F1, F2) = {s12} > rank C S*(F2) = {s}"},
    }
    full.info = dict(info, order=n, reduction=None)
    info["target_markov_max"] = _check_target_visible(full, md, tnames, F1)
    info["conditions"]["target visibility"] = f"largest Markov parameter {info['target_markov_max']:.3e}"
    full.info["target_markov_max"] = info["target_markov_max"]
    full.internal = internal_form(full, md)
    if reduce is None:
        return full
    red = reduce_filter(full, order, fast_modulus=fast_modulus, weak_observability=weak_observability,
                        method=reduce)
    red.info = dict(info, full=full, **red.info)
    red.internal = internal_form(red, md)
    return red


# ---------------------------------------------------------------------------------- reduction
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


# ---------------------------------------------------------------------------------- front ends
def fault_detection_filter(model: LinearFaultModel, target: Any, nuisance: Any = (), *,
                           method: str = "auto", **kwargs: Any) -> FilterDesign:
    """Design a filter sensitive to ``target`` and blind to ``nuisance``.

    ``method="uio"``: :func:`design_uio`; ``"optimal"``: :func:`design_optimal_fdf`; ``"auto"``:
    the exact UIO when ``rank(C E) = rank(E)`` holds (and the design succeeds), else the optimal
    stochastic filter. Keyword arguments go to the chosen design function (``dt``, ``gamma``,
    ``poles``, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> fault_detection_filter(m, "actuator:u0", ["actuator:u1"]).info["method"]
    'uio'
    """
    uio_kw = {k: v for k, v in kwargs.items() if k in ("dt", "poles", "Q", "R", "name", "sensor")}
    opt_kw = {k: v for k, v in kwargs.items() if k not in ("poles", "Q", "R")}
    if method == "uio":
        return design_uio(model, target, nuisance, **uio_kw)
    if method == "optimal":
        return design_optimal_fdf(model, target, nuisance, **opt_kw)
    if method != "auto":
        raise ModelError(f"method must be 'auto', 'uio' or 'optimal', got {method!r}")
    try:
        return design_uio(model, target, nuisance, **uio_kw)
    except ConditionError as exc:
        if exc.condition not in ("rank(CE) = rank(E)", "detectability of (C, A1)"):
            raise
        d = design_optimal_fdf(model, target, nuisance, **opt_kw)
        d.info["uio_failed"] = str(exc)
        return d


def design_filter_set(model: LinearFaultModel, targets: Sequence[str], nuisance: Any = (), *,
                      method: str = "auto", name: str = "set", **kwargs: Any) -> dict[str, FilterDesign]:
    """One filter per target, the other targets (and ``nuisance``) as nuisances.

    Parameters
    ----------
    model : LinearFaultModel
    targets : sequence of str
        Faults of the set (e.g. ng-chen-speyer, Section IV-B: two faults per set).
    nuisance : sequence
        Nuisances common to every filter (e.g. the nonlinearity direction).
    method, kwargs
        As :func:`fault_detection_filter`.
    name : str
        Prefix of the residual names: ``"<name>/<target>:<i>"``.

    Returns
    -------
    dict
        ``{target: FilterDesign}``.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> sorted(design_filter_set(m, ["actuator:u0", "actuator:u1"]))
    ['actuator:u0', 'actuator:u1']
    """
    targets = list(targets)
    common = [nuisance] if isinstance(nuisance, str) else list(nuisance or [])
    out = {}
    for t in targets:
        others = [s for s in targets if s != t] + common
        out[t] = fault_detection_filter(model, t, others, method=method, name=f"{name}/{t}", **kwargs)
    return out


def stack_designs(designs: Sequence[FilterDesign]) -> FilterDesign:
    """Fuse several filters reading the same channels into one block-diagonal filter.

    The fused filter's residuals are the concatenation of the members' (in order); its inputs
    are the union of their ``u`` and ``y`` channels (first appearance order). Running one fused
    filter costs a few matrix products per sample instead of a few per member.

    Examples
    --------
    >>> import numpy as np
    >>> a = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.zeros((1, 1)), 0.1, [], ["y1"], ["ra"])
    >>> b = FilterDesign(np.array([[0.2]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[2.0]]),
    ...                  np.zeros((1, 0)), np.zeros((1, 1)), 0.1, [], ["y2"], ["rb"])
    >>> s = stack_designs([a, b])
    >>> s.y_names, s.residual_names, s.By.tolist()
    (['y1', 'y2'], ['ra', 'rb'], [[1.0, 0.0], [0.0, 1.0]])
    """
    designs = list(designs)
    if not designs:
        raise ModelError("stack_designs needs at least one design")
    dt = designs[0].dt
    for d in designs:
        if abs(d.dt - dt) > 1e-12 * dt:
            raise ModelError(f"designs have different sample times: {dt} and {d.dt}")
    u_names = list(dict.fromkeys(s for d in designs for s in d.u_names))
    y_names = list(dict.fromkeys(s for d in designs for s in d.y_names))
    res = [s for d in designs for s in d.residual_names]
    if len(set(res)) != len(res):
        raise ModelError(f"residual names collide: {res}")
    nf, q = sum(d.order for d in designs), len(res)
    A = sla.block_diag(*[d.A for d in designs]) if nf else np.zeros((0, 0))
    Bu, By = np.zeros((nf, len(u_names))), np.zeros((nf, len(y_names)))
    C, Du, Dy = np.zeros((q, nf)), np.zeros((q, len(u_names))), np.zeros((q, len(y_names)))
    i = j = 0
    for d in designs:
        iu = [u_names.index(s) for s in d.u_names]
        iy = [y_names.index(s) for s in d.y_names]
        rows, outs = slice(i, i + d.order), slice(j, j + len(d.residual_names))
        Bu[rows, iu], By[rows, iy] = d.Bu, d.By
        C[outs, rows] = d.C
        Du[outs, iu], Dy[outs, iy] = d.Du, d.Dy
        i, j = i + d.order, j + len(d.residual_names)
    return FilterDesign(A, Bu, By, C, Du, Dy, dt, u_names, y_names, res,
                        info={"method": "stack", "members": [d.residual_names for d in designs]})


def residual_covariance(design: FilterDesign, model: LinearFaultModel, group: str = "w") -> np.ndarray:
    """Steady-state covariance (q, q) of the residual driven by unit white noise on one input group.

    The internal form ``(Ai, Bi, Ci, Di)`` of the group gives ``X = Ai X Ai' + Bi Bi'``
    (discrete Lyapunov equation) and ``Cov r = Ci X Ci' + Di Di'``: the residual variance the
    residual processor (e.g. the MHSSPT densities) must expect without faults.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel
    >>> m = LinearFaultModel([[0.5]], [[1.0]], [[1.0]], dt=0.1, Dw=[[1.0]])
    >>> d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((1, 0)),
    ...                  np.zeros((1, 1)), np.eye(1), 0.1, ["u0"], ["y0"], ["r"])
    >>> residual_covariance(d, m).tolist()     # r = y = x + w, x = 0 without inputs: Var = 1
    [[1.0]]
    """
    M = internal_form(design, model)
    Bg, Dg = M.B_of(group), M.D_of(group)
    X = sla.solve_discrete_lyapunov(M.A, Bg @ Bg.T) if M.n_states else np.zeros((0, 0))
    R = M.C @ X @ M.C.T + Dg @ Dg.T
    return 0.5 * (R + R.T)


# ---------------------------------------------------------------------------------- runtime
def _sparse_rows(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compressed rows of ``M`` (its nonzero entries in column order): ``(ptr, col, val)``.

    The filters of a bank are stacked block-diagonally (:func:`stack_designs`), so most of
    ``[[C, Dv], [A, Bv]]`` is structurally zero; the runtime multiplies the nonzeros only, in the
    same column order as the dense product (the skipped terms are exact zeros).
    """
    M = np.asarray(M, float)
    nz = M != 0.0
    ptr = np.zeros(M.shape[0] + 1, np.int64)
    ptr[1:] = np.cumsum(nz.sum(axis=1))
    rows, cols = np.nonzero(nz)
    return ptr, np.ascontiguousarray(cols, dtype=np.int64), np.ascontiguousarray(M[rows, cols])


@njit(cache=True)
def _advance_row(z, nf, ptr, col, val, r, q):  # pragma: no cover - compiled
    """One sample of one run, in place on ``z = [xi, v]`` (nf + m,):
    r = C xi + Dv v; xi <- A xi + Bv v, with ``[[C, Dv], [A, Bv]]`` in compressed rows (q + nf rows);
    the new state is formed in ``r``'s tail scratch ``q[...]`` before it overwrites ``xi``."""
    nr = r.shape[0]
    for a in range(nr):
        acc = 0.0
        for e in range(ptr[a], ptr[a + 1]):
            acc += val[e] * z[col[e]]
        r[a] = acc
    for a in range(nf):
        acc = 0.0
        for e in range(ptr[nr + a], ptr[nr + a + 1]):
            acc += val[e] * z[col[e]]
        q[a] = acc
    for a in range(nf):
        z[a] = q[a]


@njit(cache=True)
def _step_kernel(xi, v, ptr, col, val, r):  # pragma: no cover - compiled
    """All runs, one sample: xi (R, nf) in place, v (R, m), r (R, q)."""
    nf, m = xi.shape[1], v.shape[1]
    z = np.empty(nf + m)
    tmp = np.empty(nf)
    for i in range(xi.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for j in range(m):
            z[nf + j] = v[i, j]
        _advance_row(z, nf, ptr, col, val, r[i], tmp)
        for a in range(nf):
            xi[i, a] = z[a]


@njit(cache=True)
def _run_kernel(xi, v, ptr, col, val, out):  # pragma: no cover - compiled
    """All runs, all samples: v (R, T, m), out (R, T, q); the same row arithmetic as the step."""
    nf, m = xi.shape[1], v.shape[2]
    z = np.empty(nf + m)
    tmp = np.empty(nf)
    for i in range(v.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for k in range(v.shape[1]):
            for j in range(m):
                z[nf + j] = v[i, k, j]
            _advance_row(z, nf, ptr, col, val, out[i, k], tmp)
        for a in range(nf):
            xi[i, a] = z[a]


#: Rows of ``[[C, Dv], [A, Bv]]`` advanced together by :func:`_run_kernel_chunked`.
CHUNK = 4


def _row_chunks(ptr: np.ndarray, col: np.ndarray, val: np.ndarray) -> tuple[np.ndarray, ...]:
    """The compressed rows regrouped for :func:`_run_kernel_chunked`: rows of equal length in
    chunks of :data:`CHUNK`, their terms interleaved (term ``e`` of lane ``w`` at ``CHUNK e + w``,
    each row's terms in their own order); a chunk's unused lanes multiply zeros into the dummy
    row ``n_rows``. Returns ``(length, offset, col, val, row)`` per chunk (``col`` unsigned; rows
    of no terms are in no chunk: they stay 0)."""
    nr = ptr.size - 1
    lens = np.diff(ptr)
    c_len, c_off, c_col, c_val, c_row = [], [0], [], [], []
    for n in np.unique(lens):
        if n == 0:
            continue
        rows = np.flatnonzero(lens == n)
        for s in range(0, rows.size, CHUNK):
            ch = rows[s:s + CHUNK]
            cc = np.zeros((n, CHUNK), np.int64)
            cv = np.zeros((n, CHUNK))
            rr = np.full(CHUNK, nr, np.int64)
            for w, r in enumerate(ch):
                cc[:, w], cv[:, w], rr[w] = col[ptr[r]:ptr[r + 1]], val[ptr[r]:ptr[r + 1]], r
            c_len.append(n)
            c_col.append(cc.ravel())
            c_val.append(cv.ravel())
            c_row.append(rr)
            c_off.append(c_off[-1] + cc.size)

    def cat(a: list, dt: type) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(a), dtype=dt) if a else np.zeros(0, dt)

    return (np.asarray(c_len, np.int64), np.asarray(c_off, np.int64), cat(c_col, np.uint64),
            cat(c_val, np.float64), cat(c_row, np.int64))


@njit(cache=True)
def _run_kernel_chunked(xi, v, c_len, c_off, c_col, c_val, c_row, out):  # pragma: no cover - compiled
    """As :func:`_run_kernel` (bitwise: every row sums the same terms in the same order from 0.0),
    with :data:`CHUNK` rows of equal length advanced together (independent sums the processor
    overlaps, and no loop exit per row): v (R, T, m), out (R, T, q), xi (R, nf) in place."""
    nf, m = xi.shape[1], v.shape[2]
    q = out.shape[2]
    z = np.empty(nf + m)
    res = np.zeros(q + nf + 1)  # rows of no terms stay 0; the last is the unused lanes' dummy
    for i in range(v.shape[0]):
        for a in range(nf):
            z[a] = xi[i, a]
        for k in range(v.shape[1]):
            for j in range(m):
                z[nf + j] = v[i, k, j]
            for g in range(c_len.shape[0]):
                # views and unsigned columns: indices the compiler knows are not negative (no
                # wrap-around test per term)
                n = c_len[g]
                cg = c_col[c_off[g]:c_off[g] + 4 * n]
                vg = c_val[c_off[g]:c_off[g] + 4 * n]
                a0 = 0.0
                a1 = 0.0
                a2 = 0.0
                a3 = 0.0
                for e in range(n):
                    a0 += vg[4 * e] * z[cg[4 * e]]
                    a1 += vg[4 * e + 1] * z[cg[4 * e + 1]]
                    a2 += vg[4 * e + 2] * z[cg[4 * e + 2]]
                    a3 += vg[4 * e + 3] * z[cg[4 * e + 3]]
                w = 4 * g
                res[c_row[w]] = a0
                res[c_row[w + 1]] = a1
                res[c_row[w + 2]] = a2
                res[c_row[w + 3]] = a3
            o = out[i, k]
            for a in range(q):
                o[a] = res[a]
            for a in range(nf):
                z[a] = res[q + a]
        for a in range(nf):
            xi[i, a] = z[a]


class FaultDetectionFilter(ResidualGenerator):
    """Runtime of a :class:`FilterDesign`: batch ``run`` and streaming ``reset``/``step``.

    Both paths call the same compiled row update (numba, strict IEEE arithmetic in a fixed
    order), sample by sample, so their outputs are bitwise equal; the batch path loops over
    runs and samples inside compiled code. The update multiplies the structural nonzeros of
    ``[[C, Dv], [A, Bv]]`` only (a stacked bank is block-diagonal), in the dense product's order.

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.array([[-1.0]]), 0.1, [], ["y"], ["r"])
    >>> f = FaultDetectionFilter(d)
    >>> f.reset(1)
    >>> [float(f.step(np.zeros(0), [1.0])[0, 0]) for _ in range(3)]
    [-1.0, 0.0, 0.5]
    """

    def __init__(self, design: FilterDesign, x0: Any = None):
        self.design = design
        self.u_names = list(design.u_names)
        self.y_names = list(design.y_names)
        self.output_names = list(design.residual_names)
        nf = design.order
        self.x0 = np.zeros(nf) if x0 is None else np.asarray(x0, float).reshape(nf)
        self._A = np.ascontiguousarray(design.A, dtype=float)
        self._C = np.ascontiguousarray(design.C, dtype=float)
        self._Bv = np.ascontiguousarray(np.hstack([design.Bu, design.By]), dtype=float)
        self._Dv = np.ascontiguousarray(np.hstack([design.Du, design.Dy]), dtype=float)
        self._rows = _sparse_rows(np.block([[self._C, self._Dv], [self._A, self._Bv]]))
        self._chunks = _row_chunks(*self._rows)
        self.reset(1)

    _state_attrs = ("_xi",)

    def reset(self, runs: int = 1) -> None:
        self._xi = np.ascontiguousarray(np.tile(self.x0, (runs, 1)))

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        if u.shape[0] != self._xi.shape[0]:
            raise ModelError(f"sample has {u.shape[0]} runs but the filter was reset for "
                             f"{self._xi.shape[0]}")
        r = np.empty((u.shape[0], self._C.shape[0]))
        uy = np.ascontiguousarray(np.concatenate((u, y), axis=1), dtype=float)
        _step_kernel(self._xi, uy, *self._rows, r)
        return r

    def run(self, signals: Signals) -> Signals:
        """Residuals over a record (all runs at once, compiled time recursion)."""
        u, y = self._inputs(signals)
        if signals.n_samples > 1:
            self._check_dt(np.diff(signals.t), signals)
        self.reset(signals.runs)
        v = np.ascontiguousarray(np.concatenate([u, y], axis=2), dtype=float)
        return Signals(signals.t, self._run_values(v), self.output_names, check=False)

    def _check_dt(self, dts: np.ndarray, signals: Signals) -> None:
        """Refuse a record (sample steps ``dts``) not sampled at the design's ``dt``."""
        if np.max(np.abs(dts - self.design.dt)) > 1e-6 * self.design.dt:
            raise ModelError(f"signals are sampled at {signals.dt:g} s but the filter was designed "
                             f"for dt = {self.design.dt:g} s")

    def _run_values(self, v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Residuals (R, T, q) of the inputs ``v = [u, y]`` (R, T, m, contiguous float), from the
        current state (advanced to the end), into ``out`` when given (contiguous)."""
        if out is None:
            out = np.empty((v.shape[0], v.shape[1], len(self.output_names)))
        chunks = getattr(self, "_chunks", None)
        if chunks is None:  # an object restored without __init__
            chunks = self._chunks = _row_chunks(*self._rows)
        _run_kernel_chunked(self._xi, v, *chunks, out)
        return out


# ---------------------------------------------------------------------------------- internal form
def internal_form(design: Any, model: LinearFaultModel) -> LinearFaultModel:
    """Transfer from every input group of ``model`` to the residual, by composing plant and filter.

    ``design`` is a :class:`FilterDesign` or any design with an ``as_filter()`` method (for
    example :class:`~fdikit.residuals.ObserverDesign`).

    Plant ``x[k+1] = A x + sum_g B_g v_g``, ``y = C x + sum_g D_g v_g`` (discretised at the
    design's ``dt`` when continuous) in series with the filter; composite state ``[x; xi]``::

        [x; xi][k+1] = [[A, 0], [By C, Af]] [x; xi] + [B_g; By D_g (+ Bu)] v_g
        r            = [Dy C, Cf] [x; xi] + (Dy D_g (+ Du)) v_g

    (``Bu``, ``Du`` only for the controls). The design may read a subset of the model's channels
    (matched by name). Returns a :class:`LinearFaultModel` with the model's input groups and
    the residual channels as outputs.

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.model import LinearFaultModel, dc_gain
    >>> m = LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
    ...                      faults=["actuator:u0", "actuator:u1"])
    >>> G = dc_gain(internal_form(design_uio(m, "actuator:u0", ["actuator:u1"]), m), "f")
    >>> bool(np.abs(G[:, 1]).max() < 1e-12), bool(np.abs(G[:, 0]).max() > 0.1)
    (True, True)
    """
    if not isinstance(design, FilterDesign) and hasattr(design, "as_filter"):
        design = design.as_filter()
    md = _discrete(model, design.dt)
    missing = [s for s in design.y_names if s not in md.outputs] + \
        [s for s in design.u_names if s not in md.inputs]
    if missing:
        raise ModelError(f"the design reads channels {missing} that model {md.name!r} does not have "
                         f"(inputs {md.inputs}, outputs {md.outputs})")
    # the filter's gains on the model's channels (zero columns for channels it does not read)
    By = np.zeros((design.order, md.n_outputs))
    Dy = np.zeros((len(design.residual_names), md.n_outputs))
    By[:, md.output_index(design.y_names)], Dy[:, md.output_index(design.y_names)] = design.By, design.Dy
    iu = [md.inputs.index(s) for s in design.u_names]
    Bu = np.zeros((design.order, len(md.inputs)))
    Du = np.zeros((len(design.residual_names), len(md.inputs)))
    Bu[:, iu], Du[:, iu] = design.Bu, design.Du
    n, nf = md.n_states, design.order
    A = np.block([[md.A, np.zeros((n, nf))], [By @ md.C, design.A]])
    C = np.hstack([Dy @ md.C, design.C])
    groups = {}
    for g in GROUPS:
        Bg, Dg = md.B_of(g), md.D_of(g)
        Bo, Do = By @ Dg, Dy @ Dg
        if g == "u":
            Bo, Do = Bo + Bu, Do + Du
        groups[g] = (np.vstack([Bg, Bo]), Do)
    states = [*md.states, *(f"xi{i}" for i in range(nf))]
    return md.with_matrices(A, C, groups, states=states, outputs=design.residual_names)


def filter_frequency_response(design: FilterDesign, freqs_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """Frequency responses ``G_ru`` (F, q, m) and ``G_ry`` (F, q, p) of the filter alone.

    ``G(e^{j 2 pi f dt}) = D + C (zI - A)^-1 B``; with a plant response ``G_yg`` the residual's
    response to group ``g`` is ``G_ry G_yg (+ G_ru for the controls)``, an independent check of
    :func:`internal_form`.

    Examples
    --------
    >>> import numpy as np
    >>> d = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.array([[-1.0]]), 0.1, [], ["y"], ["r"])
    >>> Gu, Gy = filter_frequency_response(d, [0.0])
    >>> Gy[0].real.tolist()            # -1 + 1 / (1 - 0.5)
    [[1.0]]
    """
    f = np.atleast_1d(np.asarray(freqs_hz, float))
    z = np.exp(2j * np.pi * f * design.dt)
    nf = design.order
    out = []
    for Bm, Dm in ((design.Bu, design.Du), (design.By, design.Dy)):
        if nf:
            M = z[:, None, None] * np.eye(nf) - design.A
            X = np.linalg.solve(M, np.broadcast_to(Bm.astype(complex), (f.size, *Bm.shape)))
            out.append(design.C @ X + Dm)
        else:
            out.append(np.broadcast_to(Dm.astype(complex), (f.size, *Dm.shape)).copy())
    return out[0], out[1]
