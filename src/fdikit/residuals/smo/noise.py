"""Measurement noise through the SMO runtime: the step inside the boundary layers as a linear
map, the stationary noise response of ``fhat``, and the noise-driven sizing of the boundary
layers and of the output low-pass."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ConditionError
from .runtime import SlidingModeReconstructor

__all__ = ["noise_response"]

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
            if not (np.isfinite(nr["e2_rms"]) and np.isfinite(nr["e1_rms"])):
                # the step inside these layers is unstable: this time constant is refused
                return float("inf"), rec, nr, float("inf"), (d1, d2)
            if user["delta2"] is not None or d2 >= 3.0 * nr["e2_rms"] * 0.999:
                break
            e2 = nr["e2_rms"]
        lag = tau + (d1 / (rho1 * lam1min) if g1 is not None else 0.0) + d2 / (rho2 * lam2min)
        noise = float(np.linalg.norm(nr["fhat_std"]))
        pred = float(np.hypot(fault_rate * lag, noise))
        return pred, rec, nr, lag, (d1, d2)

    taus = [lpf_tau] if lpf_tau is not None and lpf_tau > 0 else list(np.logspace(np.log10(20 * dt), 0.0, 25))
    best = None
    refused = []
    for tau in taus:
        res = evaluate(float(tau))
        if not np.isfinite(res[0]):
            refused.append({"lpf_tau": float(tau), "spectral_radius": res[2]["spectral_radius"],
                            "delta": res[4][0], "delta2": res[4][1]})
        elif best is None or res[0] < best[0]:
            best = (*res, float(tau))
    if best is None:
        raise ConditionError("noise design", "no low-pass time constant gives a stable runtime step "
                             f"(dt = {dt} s, noise_std = {sig.tolist()}): the linear step inside every "
                             f"boundary layer tried is unstable (spectral radius >= 1); reduce dt or give "
                             f"larger delta / delta2", {"tried": taus, "refused": refused})
    pred, rec, nr, lag, (d1, d2), tau = best
    out = {"noise_std": sig.tolist(), "lpf_tau": tau, "lag_s": lag, "delta": d1, "delta2": d2,
           "fhat_noise_std": nr["fhat_std"], "noise_gain": nr["gain"],
           "lag_error_bound": fault_rate * lag, "predicted_error": pred,
           "e1_rms": nr["e1_rms"], "e2_rms": nr["e2_rms"], "refused": refused,
           "note": "noise_gain[i][j]: std of fhat_i per unit std of white noise on output j (linear "
                   "boundary-layer model of the step as implemented); lag_s: low-pass + loop time "
                   "constants; lag_error_bound = fault_rate * lag_s; refused: low-pass time constants "
                   "whose step inside the boundary layers is unstable"}
    return rec, out
