"""The nonlinearity direction of ng-chen-speyer, Section IV-A.

The fault detection filters are designed on a linear model linearised at one operating point;
the error of that linear model along real manoeuvres is modelled as a slowly varying one- or
two-dimensional additive term in the linear state equation, ``x' = A x + B u + E_n mu(t)``, and
``E_n`` is then treated as a nuisance fault by the unknown input observer. Here ``E_n`` is
estimated from nonlinear simulations: along the trajectories of the automated car the
state-equation mismatch

    e(t) = f(x(t), u(t), d(t)) - A (x(t) - x0) - B (u(t) - u0) - B_d (d(t) - d0)

is collected for the states of one block (longitudinal or lateral), scaled per state by its RMS,
and its dominant left singular vectors are the directions. They are declared as faults
``"nonlinearity:<i>"`` of the full block and carried through the same model reduction.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import ModelError
from ...model.linear import LinearFaultModel
from .linear import CarLinearization, balanced_residualization, reduce_fast_modes_named, residualize_states
from .model import LATERAL_REDUCED, LATERAL_STATES, LONGITUDINAL_REDUCED, LONGITUDINAL_STATES

__all__ = ["NonlinearityDirections", "nonlinearity_directions"]


@dataclass
class NonlinearityDirections:
    """Result of :func:`nonlinearity_directions`.

    Attributes
    ----------
    block : str
        ``"longitudinal"`` or ``"lateral"``.
    E : ndarray (n_block, k)
        Directions in the full block's state coordinates: an orthonormal basis of the span of the
        dominant scaled singular vectors mapped back to the state-equation units.
    singular_values : ndarray
        Of the scaled mismatch matrix (all of them).
    energy : ndarray (k,)
        Fraction of the mismatch energy each direction captures.
    model : LinearFaultModel
        The full block with the directions declared as faults ``"nonlinearity:<i>"``.
    reduced : LinearFaultModel
        The reduced block with them (same reduction as the :class:`CarLinearization`).
    samples : int
    """

    block: str
    E: np.ndarray
    singular_values: np.ndarray
    energy: np.ndarray
    model: LinearFaultModel
    reduced: LinearFaultModel
    samples: int


def nonlinearity_directions(lin: CarLinearization, block: str = "longitudinal", k: int = 1, *,
                            kinds: Sequence[str] = ("speed_change", "curve"), duration: float = 12.0,
                            dt: float = 2e-3, results: Sequence | None = None) -> NonlinearityDirections:
    """Estimate the nonlinearity direction(s) of one block from nonlinear simulations.

    Parameters
    ----------
    lin : CarLinearization
        The linear models (operating point ``lin.x0, lin.u0``).
    block : {"longitudinal", "lateral"}
    k : int
        Number of directions (the paper uses one or two).
    kinds : sequence of str
        Nominal driving scenarios (:func:`~fdikit.systems.car.driving.driving_scenario`)
        simulated at ``lin.speed`` when ``results`` is not given.
    duration, dt : float
        Their length and integration step (s).
    results : sequence of (SimResult, slope), optional
        Simulations of a :class:`DrivingCar` to use instead (states and commanded inputs kept).

    Returns
    -------
    NonlinearityDirections

    Examples
    --------
    >>> nd = nonlinearity_directions(linearize_car(20.0), k=2)   # doctest: +SKIP
    >>> nd.reduced.fault_names[-2:]                              # doctest: +SKIP
    ['nonlinearity:1', 'nonlinearity:2']
    """
    from .driving import DrivingCar, simulate_drive

    if block not in ("longitudinal", "lateral"):
        raise ModelError(f"block must be 'longitudinal' or 'lateral', got {block!r}")
    states = LONGITUDINAL_STATES if block == "longitudinal" else LATERAL_STATES
    if results is None:
        results = []
        for kind in kinds:
            slope = 0.02 if kind == "curve" else 0.0
            results.append((simulate_drive(kind, lin.speed, duration=duration, dt=dt), slope))
    car = DrivingCar().car
    full = lin.full
    iS = full.state_index(states)
    A, Bu, Bd = full.A, full.B_of("u"), full.B_of("d")
    cols = []
    for res, slope in results:
        X = res.x.values[:, :, :22].reshape(-1, 22)
        U = res.u.values.reshape(-1, 3)
        D = np.full((X.shape[0], 1), slope)
        Uf = np.column_stack([U, D])
        f = car.f(0.0, X, Uf, car.params)
        dx, du, dd = X - lin.x0, U - lin.u0[:3], D - lin.u0[3]
        lin_f = dx @ A.T + du @ Bu.T + dd @ Bd.T
        cols.append((f - lin_f)[:, iS])
    M = np.concatenate(cols).T  # (n_block, N)
    if not np.all(np.isfinite(M)):
        raise ModelError("the state-equation mismatch is not finite along the simulations")
    scale = np.sqrt(np.mean(M**2, axis=1))
    scale = np.where(scale > 1e-12 * max(scale.max(), 1e-300), scale, 1.0)
    U_, s, _ = np.linalg.svd(M / scale[:, None], full_matrices=False)
    # back to the state-equation units; orthonormal basis of the same span (the scaled singular
    # vectors are orthogonal, their unscaled images need not be)
    E, _ = np.linalg.qr(U_[:, :k] * scale[:, None])
    E *= np.sign(E[np.argmax(np.abs(E), axis=0), range(k)])
    energy = s[:k] ** 2 / np.sum(s**2)
    base = lin.longitudinal if block == "longitudinal" else lin.lateral
    names = [f"nonlinearity:{i + 1}" for i in range(k)]
    model = base.with_faults(*[(n, E[:, i], None) for i, n in enumerate(names)])
    keep = LONGITUDINAL_REDUCED if block == "longitudinal" else LATERAL_REDUCED
    if lin.method == "modal":
        reduced = reduce_fast_modes_named(model, keep)
    elif lin.method == "residualize":
        reduced = residualize_states(model, keep)
    else:
        reduced = balanced_residualization(model, len(keep))
    return NonlinearityDirections(block, E, s, energy, model, reduced, int(M.shape[1]))
