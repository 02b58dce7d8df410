"""The SMO design's self-check: the reconstructor run on its own design model (a step of every
fault, a smooth disturbance) and what it achieves there."""

from __future__ import annotations

import numpy as np

from ...errors import ModelError
from .plant import simulate_plant
from .runtime import SlidingModeReconstructor, integrate_observers
from .status import SLIDING

__all__ = ["self_check"]

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
