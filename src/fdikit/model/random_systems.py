"""Random linear systems with a chosen fault structure, for trying a design on systems it was not
written for.

:func:`random_fault_system` draws ``x' = A x + M f + Q xi``, ``y = C x`` with a relative degree
and invariant zeros of ``(A, M, C)`` chosen by ``kind``, hidden by a random change of state
coordinates and a random mixing of the outputs. ``benchmarks/bench_smo_random.py`` and the SMO
tests draw their systems from it at fixed seeds.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import null_space

from ..errors import DataError
from .linear import LinearFaultModel

__all__ = ["KINDS", "as_fault_model", "random_fault_system"]

#: The kinds of :func:`random_fault_system`.
KINDS = ("rd2", "rd2_zero", "slow_zero", "unstable_zero", "rd3")


def _siso_block(num_roots, den_roots):
    """Controllable companion form of prod(s - z) / prod(s - p) (monic)."""
    den = np.poly(den_roots).real
    num = np.poly(num_roots).real if len(num_roots) else np.array([1.0])
    n = len(den) - 1
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1] = -den[1:][::-1]
    B = np.zeros((n, 1))
    B[-1] = 1.0
    c = np.zeros((1, n))
    c[0, :len(num)] = num[::-1]
    return A, B, c


def random_fault_system(seed: int, kind: str = "rd2"
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, M, C, Q)`` of a random stable system (n = 6-9 states, p = 3-4 outputs, h = 1-2 xi).

    Parameters
    ----------
    seed : int
        Seed of the generator (``numpy.random.default_rng``); the same seed gives the same system.
    kind : str
        ``"rd2"``: ``C M = 0`` and ``rank C A M = q`` (relative degree two, q = 1-2 faults;
        generically no invariant zeros). ``"rd2_zero"``: q = 1 with an invariant zero drawn
        log-uniformly in [-2, -0.01]. ``"slow_zero"``: a zero at -0.01. ``"unstable_zero"``: a
        zero at +0.5 (condition B2 of the SMO fails). ``"rd3"``: relative degree three (B1 fails).

    Returns
    -------
    A (n, n), M (n, q), C (p, n), Q (n, h) : ndarray

    Examples
    --------
    >>> from fdikit.model.random_systems import random_fault_system
    >>> A, M, C, Q = random_fault_system(0)
    >>> A.shape[0] in range(6, 10), float(abs(C @ M).max()) < 1e-12
    (True, True)
    """
    if kind not in KINDS:
        raise DataError(f"kind must be one of {list(KINDS)}, got {kind!r}")
    rng = np.random.default_rng(seed)
    n, p, h = int(rng.integers(6, 10)), int(rng.integers(3, 5)), int(rng.integers(1, 3))
    q = int(rng.integers(1, 3)) if kind == "rd2" else 1
    if kind == "rd2":
        while True:
            A = rng.standard_normal((n, n))
            A -= (np.linalg.eigvals(A).real.max() + rng.uniform(0.3, 2.0)) * np.eye(n)
            C = rng.standard_normal((p, n))
            M = null_space(C) @ rng.standard_normal((n - p, q))
            M[np.abs(M) < 1e-15] = 0.0
            if np.linalg.matrix_rank(C @ A @ M) == q:
                break
    else:
        poles = -rng.uniform(0.5, 4.0, 3)
        zeros = {"rd2_zero": [-10 ** rng.uniform(-2, np.log10(2.0))], "slow_zero": [-0.01],
                 "unstable_zero": [0.5], "rd3": []}[kind]
        Af, bf, cf = _siso_block(zeros, poles)
        nr = n - 3
        Ar = rng.standard_normal((nr, nr))
        Ar -= (np.linalg.eigvals(Ar).real.max() + rng.uniform(0.3, 2.0)) * np.eye(nr)
        # fault block and the rest uncoupled: outputs 2..p do not see f, so the block's zero is a
        # zero of the whole system
        A = np.block([[Af, np.zeros((3, nr))], [np.zeros((nr, 3)), Ar]])
        M = np.vstack([bf, np.zeros((nr, 1))])
        C = np.block([[cf, np.zeros((1, nr))], [np.zeros((p - 1, 3)), rng.standard_normal((p - 1, nr))]])
        S = rng.standard_normal((n, n)) + 3 * np.eye(n)
        Si = np.linalg.inv(S)
        A, M, C = S @ A @ Si, S @ M, (rng.standard_normal((p, p)) + 2 * np.eye(p)) @ C @ Si
    Q = rng.standard_normal((n, h)) * 10 ** rng.uniform(-2, 0)
    return A, M, C, Q


def as_fault_model(A, M, C, Q=None, *, name: str = "random") -> LinearFaultModel:
    """The :class:`LinearFaultModel` of ``x' = A x + M f + Q xi``, ``y = C x`` (faults ``f0..``,
    disturbances ``xi0..``, no control input)."""
    A = np.asarray(A, float)
    n = A.shape[0]
    M = np.asarray(M, float)
    Q = np.zeros((n, 0)) if Q is None else np.asarray(Q, float)
    return LinearFaultModel(A, np.zeros((n, 0)), C, Bd=Q if Q.shape[1] else None, name=name,
                            faults=[(f"f{j}", M[:, j], None) for j in range(M.shape[1])],
                            disturbances=[f"xi{k}" for k in range(Q.shape[1])] or None)
