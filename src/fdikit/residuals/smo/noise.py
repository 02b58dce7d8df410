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


#: Boundary layers (the same for both observers) the simulated noise design tries, as multiples
#: of the noise norm ``||noise_std||``; the layers of the noise-free ladder are tried as well.
NOISE_LAYER_FACTORS = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)

#: Multipliers of the best secondary layer, then of the best primary layer, tried after that.
NOISE_LAYER_REFINE = (0.1, 0.3, 3.0, 10.0, 100.0)

#: Seed of the white noise of the simulated noise design (the choice is reproducible).
NOISE_SEED = 2031


def _noise_scenario(details: dict, dt: float, sig: np.ndarray, f_amp: float, fault_rate: float,
                    horizon: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Faults and noisy measurements of the simulated noise design: a step of every fault (at
    10 % of ``horizon``) and, when ``fault_rate > 0``, a sinusoid of amplitude ``f_amp`` whose
    rate peaks at ``fault_rate`` (raised-cosine window over the first 20 %); white noise ``sig``
    on every output (seed :data:`NOISE_SEED`).
    Returns ``F`` (runs, T, q), ``Y`` (runs, T, p) and the first scored sample."""
    from .plant import simulate_plant

    A, M, C, _Q = details["model"]
    q = M.shape[1]
    T = max(round(horizon / dt) + 1, 50)
    t = np.arange(T) * dt
    signs = np.where(np.arange(q) % 2 == 0, 1.0, -1.0) / np.sqrt(q)
    F = [np.where(t >= 0.1 * horizon, f_amp, 0.0)[:, None] * signs[None, :]]
    if fault_rate > 0:
        # under a raised-cosine window over the first 20 % (no reaching phase from a kink at t = 0)
        win = np.clip(t / (0.2 * horizon), 0.0, 1.0)
        win = 0.5 - 0.5 * np.cos(np.pi * win)
        F.append(f_amp * (np.sin(fault_rate / f_amp * t) * win)[:, None] * signs[None, :])
    F = np.stack(F)
    Y = simulate_plant(A, M, C, F, dt)
    Y = Y + sig[None, None, :] * np.random.default_rng(NOISE_SEED).standard_normal(Y.shape)
    return F, Y, T // 2


def _lowpass(fh: np.ndarray, a: float) -> np.ndarray:
    """The runtime's output low-pass ``flp = a flp + (1 - a) fhat`` (first sample passed) along axis 1."""
    from scipy.signal import lfilter

    if a <= 0:
        return fh
    return lfilter([1.0 - a], [1.0, -a], fh, axis=1, zi=a * fh[:, :1, :])[0]


def _simulated_noise_design(build, sig, user, lpf_tau, f_amp, fault_rate, dt, horizon, analytic,
                            ladder):
    """Boundary layers and low-pass chosen by the simulated error at the noise level ``sig``.

    Candidates: the layers of ``ladder`` (the noise-free choices,
    :data:`~fdikit.residuals.smo.design.DELTA_LADDER`), ``||sig||`` times
    :data:`NOISE_LAYER_FACTORS` (both observers), the analytic noise design (``analytic``:
    ``(rec, info)`` of :func:`_noise_design`, or None), then the best secondary layer and the best
    primary layer each times :data:`NOISE_LAYER_REFINE` (a coordinate search: the secondary
    observer sees the primary's injection, not the raw noise). Each is run once by the compiled
    runtime on :func:`_noise_scenario` and every low-pass time constant (0 and 20 dt to 1 s, or
    the given ``lpf_tau``) is applied to its output as the runtime does. The score is the
    largest RMS of ``||fhat - f||`` over the runs' second halves; the smallest wins.

    Returns
    -------
    (d1, d2, tau, score_abs, table, per_run_std)
    """
    from .runtime import integrate_observers

    sn = float(np.linalg.norm(sig))
    taus = ([float(lpf_tau)] if lpf_tau is not None else
            [0.0] + [float(x) for x in np.logspace(np.log10(20 * dt), 0.0, 25)])
    scen = {}
    table = []
    tried = {}

    def run(d1, d2):
        d1 = float(user["delta"] if user["delta"] is not None else d1)
        d2 = float(user["delta2"] if user["delta2"] is not None else d2)
        if (d1, d2) in tried:
            return tried[(d1, d2)]
        rec = build(d1, d2, 0.0)
        if not scen:
            scen["F"], scen["Y"], scen["k0"] = _noise_scenario(rec.details, dt, sig, f_amp, fault_rate,
                                                               horizon)
        F, Y, k0 = scen["F"], scen["Y"], scen["k0"]
        fh = integrate_observers(rec, np.zeros((Y.shape[0], Y.shape[1], len(rec.u_names))), Y)
        res = None
        if not np.all(np.isfinite(fh)):
            table.append({"delta": d1, "delta2": d2, "skipped": "non-finite run"})
        else:
            for tau in taus:
                a = float(np.exp(-dt / tau)) if tau > 0 else 0.0
                err = _lowpass(fh, a)[:, k0:] - F[:, k0:]
                score = float(np.sqrt(np.mean(np.sum(err ** 2, axis=2), axis=1)).max())
                if res is None or score < res[3]:
                    res = (d1, d2, tau, score, err)
            table.append({"delta": d1, "delta2": d2, "lpf_tau": res[2], "error": res[3]})
        tried[(d1, d2)] = res
        return res

    def better(a, b):
        return b if a is None or (b is not None and b[3] < a[3]) else a

    best = None
    # the noise-free layers, then equal layers scaled with the noise, then each layer on its own
    for d in ladder:
        best = better(best, run(d, d))
    for k in NOISE_LAYER_FACTORS:
        best = better(best, run(sn * k, sn * k))
    if analytic is not None:
        best = better(best, run(analytic[1]["delta"], analytic[1]["delta2"]))
    if best is not None:
        for k in NOISE_LAYER_REFINE:
            best = better(best, run(best[0], best[1] * k))
        for k in NOISE_LAYER_REFINE:
            best = better(best, run(best[0] * k, best[1]))
    if best is None:
        return None
    d1, d2, tau, score, err = best
    return d1, d2, tau, score, table, np.std(err[0], axis=0).tolist()


#: Noise levels (multiples of ``noise_std``) at which :func:`_switch_design` compares the branches
#: (from the stated level down), before it bisects the crossing.
SWITCH_LEVELS = tuple(10.0 ** -k for k in range(11))

#: Bisection steps of the switch level (each halves its log-bracket; 4: within a factor 1.16).
SWITCH_BISECT = 4

#: Switch level used when the clean branch is better even at the stated noise: above any ratio
#: the estimate reaches, so the clean branch is always used.
SWITCH_NEVER = 1e12


def _switch_design(noisy, clean, sig, f_amp, fault_rate, horizon) -> dict:
    """The switch rule of a noise-aware reconstructor with a clean branch, by simulation.

    Both branches (``noisy``: the noise-aware design; ``clean``: the default design) run on the
    scenario of the simulated noise design (:func:`_noise_scenario`: a step and a sinusoid at
    ``fault_rate``) with white noise ``s * sig`` for ``s`` in :data:`SWITCH_LEVELS`, from 1 down,
    until the clean branch is the better one; the crossing is then bisected in ``log s``
    (:data:`SWITCH_BISECT` steps) and ``switch`` is its geometric middle. The score is that of the
    noise design (largest RMS of ``||fhat - f||`` over the runs' second halves, fault units).
    The reconstructor with the switch (:mod:`.noise_estimate`) is then run on the clean scenario
    and at the stated noise, and both errors are recorded next to the branches' own.

    Returns
    -------
    dict
        ``switch``, ``noise_std``, ``band``, ``window``, ``warmup`` (the runtime's
        ``noise_switch``), ``levels`` (per level tried: ``s``, ``noise_branch_error``,
        ``clean_branch_error``), ``clean_data`` and ``at_noise_std`` (``error`` of the switched
        reconstructor, ``noise_branch_error``, ``clean_branch_error``, ``noise_branch_share``: the
        fraction of scored samples on the noise branch alone), ``note``.
    """
    from .noise_estimate import NOISE_BAND, NOISE_WARMUP, NOISE_WINDOW, _blend, estimate_noise_std

    dt = noisy.dt
    pos = sig > 0
    F, Y0, k0 = _noise_scenario(noisy.details, dt, np.zeros_like(sig), f_amp, fault_rate, horizon)
    W = np.random.default_rng(NOISE_SEED).standard_normal(Y0.shape)
    U0 = np.zeros((Y0.shape[0], Y0.shape[1], len(noisy.u_names)))
    q = noisy.n_faults
    runs_at = {}

    def noisy_y(s):
        return Y0 + (s * sig)[None, None, :] * W

    def outputs(s):
        """Both branches' outputs (estimates and status) at noise level ``s`` (cached)."""
        if s not in runs_at:
            Y = noisy_y(s)
            outs = []
            for rec in (noisy, clean):
                rec.reset(Y.shape[0])
                outs.append(rec._advance(U0, Y))
            runs_at[s] = (Y, *outs)
        return runs_at[s]

    def score(out):
        fh = out[:, :, :q]
        if not np.all(np.isfinite(fh)):
            return float("inf")
        return float(np.sqrt(np.mean(np.sum((fh[:, k0:] - F[:, k0:]) ** 2, axis=2), axis=1)).max())

    levels = []

    def compare(s):
        _Y, on, oc = outputs(s)
        en, ec = score(on), score(oc)
        levels.append({"s": s, "noise_branch_error": en, "clean_branch_error": ec})
        return en < ec

    hi = lo = None
    for s in SWITCH_LEVELS:
        if not compare(s):
            lo = s
            break
        hi = s
    if hi is None:
        switch = SWITCH_NEVER
    elif lo is None:
        switch = SWITCH_LEVELS[-1]
    else:
        for _ in range(SWITCH_BISECT):
            mid = float(np.sqrt(lo * hi))
            if compare(mid):
                hi = mid
            else:
                lo = mid
        switch = float(np.sqrt(lo * hi))
    ns = {"noise_std": np.where(pos, sig, 0.0).tolist(), "switch": switch, "band": NOISE_BAND,
          "window": NOISE_WINDOW, "warmup": NOISE_WARMUP}
    out = {**ns, "levels": levels}
    for key, s in (("clean_data", 0.0), ("at_noise_std", 1.0)):
        Y, on, oc = outputs(s)
        R = Y.shape[0]
        mixed, ratio = np.empty_like(on), np.empty(Y.shape[:2])
        _blend(np.ascontiguousarray(Y), on, oc, np.asarray(ns["noise_std"]), switch, NOISE_BAND,
               float(NOISE_WINDOW), float(NOISE_WARMUP), np.zeros((R, 4, Y.shape[2])),
               np.zeros((R, 1)), np.zeros((R, Y.shape[2])), mixed, ratio)
        est = estimate_noise_std(Y, NOISE_WINDOW)[:, k0:, pos] / sig[pos]
        out[key] = {"error": score(mixed), "noise_branch_error": score(on),
                    "clean_branch_error": score(oc),
                    "noise_branch_share": float(np.mean(ratio[:, k0:] >= switch * NOISE_BAND)),
                    "median_noise_ratio": float(np.median(est.max(axis=2)))}
    out["note"] = ("per sample the runtime estimates the noise on each output (estimate_noise_std) and "
                   "uses the default design (clean branch) while max_j estimate_j / noise_std_j <= "
                   "switch / band, the noise-aware design above switch * band, a log-linear blend "
                   "between; switch: the noise level (in multiples of noise_std) where the noise-aware "
                   "design becomes the better one, found by simulation (levels); clean_data and "
                   "at_noise_std: the switched reconstructor simulated (error in fault units)")
    return out
