"""Benchmark of fdikit.sim.simulate: 5000 Monte Carlo runs of a 6-state quarter-car braking model.

The model (written here, in the spirit of luo-et-al eq. (19), with its own sensible
parameters) has the states

    omega_w  wheel speed (rad/s)             omega_v  vehicle speed V / R_w (rad/s)
    T_b      brake torque (N m)              dT_b     its derivative (N m/s)
    P_s      wheel-cylinder pressure (MPa)   P_m      master-cylinder pressure (MPa)

with a Burckhardt tyre-road friction mu(slip) = c1 (1 - exp(-c2 slip)) - c3 slip (dry
asphalt), brake torque second order in the wheel-cylinder pressure (luo-et-al eq. (12)),
master cylinder a first-order lag of the pedal force, and an ABS valve that fills the wheel
cylinder from the master cylinder below the target slip and dumps it above, switching
smoothly (tanh) on the slip error. The input is a pedal-force profile: 35 N from 1 s to 6 s
(light braking, about 2 m/s^2), 500 N from 6 s to 8 s (emergency braking, ABS active), released
afterwards. The Monte Carlo runs differ by road friction (c1 scaled by U(0.8, 1.0)) and
vehicle mass (U(1200, 1600) kg), one value per run.

Measured:
1. ``simulate`` of 5000 runs at dt = 1 ms for 12.5 s, RK4, vectorised (noise-free), and the
   same with the paper's noise (process noise 23 dB SNR on every state, measurement noise
   variance 0.004 on the two speeds);
2. the same model, one run at a time, with ``scipy.integrate.solve_ivp`` (RK45, integrated
   piecewise between the pedal steps), default tolerances and tight tolerances, a few runs,
   extrapolated to 5000;
3. accuracy: RK4 at 1 ms against a tight solve_ivp (rtol 1e-10) on the same runs, and
   bitwise equality of run i alone vs inside the batch.

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import math
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

from fdikit.faults import Noise, Scenario
from fdikit.model import NonlinearModel
from fdikit.sim import simulate

PEDAL_STEPS = ((1.0, 35.0), (6.0, 500.0), (8.0, 0.0))  # (time s, pedal force N) from that time on
T_END, DT = 12.5, 1e-3
V0 = 45.0  # initial vehicle speed, m/s


def pedal(t: float) -> float:
    f = 0.0
    for t0, v in PEDAL_STEPS:
        if t >= t0 - 1e-12:
            f = v
    return f


class QuarterCarBraking(NonlinearModel):
    """6-state quarter-car braking model with ABS valve logic, vectorised over runs."""

    def __init__(self):
        params = {
            "M": 1400.0,  # vehicle mass, kg
            "R_w": 0.318,  # wheel radius, m (luo-et-al Table I)
            "I_w": 1.2,  # wheel inertia, kg m^2
            "g": 9.81,
            "K_f": 250.0,  # brake torque gain, N m / MPa
            "w_n": 2 * np.pi * 20.0,  # brake torque natural frequency, rad/s
            "zeta": 0.7,  # brake torque damping ratio
            "tau_in": 0.05,  # wheel-cylinder fill time constant, s
            "tau_out": 0.01,  # wheel-cylinder dump time constant, s
            "tau_m": 0.05,  # master-cylinder time constant, s (paper: tau_m = 0.02 s)
            "k_p": 0.025,  # pedal force to master pressure, MPa / N
            "lam_star": 0.2,  # ABS target slip (luo-et-al Table I)
            "delta": 0.05,  # slip width of the valve switching, -
            "c1": 1.2801, "c2": 23.99, "c3": 0.52,  # Burckhardt dry asphalt
            "c_air": 0.20,  # quarter-car aerodynamic drag coefficient, N s^2 / m^2
            "w_min": 1.0,  # slip denominator floor, rad/s
            "w_lock": 0.5,  # brake torque fades to zero as the wheel stops, rad/s
        }
        super().__init__(states=["omega_w", "omega_v", "T_b", "dT_b", "P_s", "P_m"], inputs=["F_p"],
                         outputs=["omega_w", "omega_v"], params=params, name="quarter-car braking")
        w0 = V0 / params["R_w"]
        self.x0 = np.array([w0, w0, 0.0, 0.0, 0.0, 0.0])

    def f(self, t, x, u, p):
        # one contiguous row per state (the (runs, n) columns are strided): fewer cache misses
        w_w, w_v, Tb, dTb, Ps, Pm = np.ascontiguousarray(x.T)
        R, M = p["R_w"], p["M"]
        dx = np.empty((6, x.shape[0]))
        d0, d1, d2, d3, d4, d5 = dx
        lam = np.maximum(w_v, p["w_min"])
        np.subtract(w_v, w_w, out=d2)
        np.divide(d2, lam, out=lam)  # slip, luo-et-al eq. (14)
        a = np.abs(lam)
        mu = np.multiply(a, -p["c2"])
        np.exp(mu, out=mu)
        np.subtract(1.0, mu, out=mu)
        mu *= p["c1"]
        a *= p["c3"]
        mu -= a
        np.copysign(mu, lam, out=mu)  # Burckhardt mu(slip)
        F = mu
        F *= M
        F *= 0.25 * p["g"]  # tyre force N_v mu, N_v = M g / 4, eq. (13)
        np.divide(w_w, p["w_lock"], out=d0)
        np.tanh(d0, out=d0)
        d0 *= Tb
        np.multiply(F, R, out=d1)
        np.subtract(d1, d0, out=d0)
        d0 /= p["I_w"]  # wheel, eq. (17)-(18)
        np.multiply(w_v, R, out=d1)
        d1 *= d1
        d1 *= p["c_air"]
        d1 += F
        d1 /= M
        d1 *= -4.0 / R  # vehicle, eq. (15)-(16)
        d2[:] = dTb
        wn = p["w_n"]
        np.multiply(Ps, p["K_f"], out=d3)
        d3 -= Tb
        d3 *= wn * wn
        a = np.multiply(dTb, 2.0 * p["zeta"] * wn, out=a)
        d3 -= a  # brake torque, eq. (12)
        s = np.subtract(p["lam_star"], lam, out=lam)
        s /= p["delta"]
        np.tanh(s, out=s)  # ABS valve: fill (s > 0) or dump (s < 0)
        np.minimum(s, 0.0, out=a)
        a *= Ps
        a /= p["tau_out"]
        np.maximum(s, 0.0, out=s)
        np.subtract(Pm, Ps, out=d4)
        d4 *= s
        d4 /= p["tau_in"]
        d4 += a
        np.multiply(u[:, 0], p["k_p"], out=d5)
        d5 -= Pm
        d5 /= p["tau_m"]  # master cylinder
        return dx.T

    def f_reference(self, t, x, u, p):
        """The same equations written plainly (used by the benchmark to check ``f``)."""
        w_w, w_v, Tb, dTb, Ps, Pm = (x[:, i] for i in range(6))
        R, M = p["R_w"], p["M"]
        lam = (w_v - w_w) / np.maximum(w_v, p["w_min"])
        a = np.abs(lam)
        mu = np.copysign(p["c1"] * (1.0 - np.exp(-p["c2"] * a)) - p["c3"] * a, lam)
        F = (0.25 * p["g"]) * M * mu
        dx = np.empty_like(x)
        dx[:, 0] = (R * F - Tb * np.tanh(w_w / p["w_lock"])) / p["I_w"]
        dx[:, 1] = -(F + p["c_air"] * (R * w_v) ** 2) / (0.25 * M * R)
        dx[:, 2] = dTb
        wn = p["w_n"]
        dx[:, 3] = wn * wn * (p["K_f"] * Ps - Tb) - (2.0 * p["zeta"] * wn) * dTb
        s = np.tanh((p["lam_star"] - lam) / p["delta"])
        dx[:, 4] = np.maximum(s, 0.0) * (Pm - Ps) / p["tau_in"] + np.minimum(s, 0.0) * Ps / p["tau_out"]
        dx[:, 5] = (p["k_p"] * u[:, 0] - Pm) / p["tau_m"]
        return dx

    def f_scalar(self, t, z, F_p, p):
        """The same equations for one run in plain Python floats (a fair best case for solve_ivp)."""
        w_w, w_v, Tb, dTb, Ps, Pm = z
        R, M = p["R_w"], p["M"]
        lam = (w_v - w_w) / max(w_v, p["w_min"])
        a = abs(lam)
        mu = math.copysign(p["c1"] * (1.0 - math.exp(-p["c2"] * a)) - p["c3"] * a, lam)
        F = 0.25 * p["g"] * M * mu
        wn = p["w_n"]
        s = math.tanh((p["lam_star"] - lam) / p["delta"])
        return [
            (R * F - Tb * math.tanh(w_w / p["w_lock"])) / p["I_w"],
            -(F + p["c_air"] * (R * w_v) ** 2) / (0.25 * M * R),
            dTb,
            wn * wn * (p["K_f"] * Ps - Tb) - 2.0 * p["zeta"] * wn * dTb,
            max(s, 0.0) * (Pm - Ps) / p["tau_in"] + min(s, 0.0) * Ps / p["tau_out"],
            (p["k_p"] * F_p - Pm) / p["tau_m"],
        ]

    def h(self, t, x, u, p):
        return x[:, :2].copy()


def monte_carlo_params(runs: int, seed: int = 1) -> dict[str, np.ndarray]:
    # one generator per parameter, so that run i gets the same values whatever the batch size
    return {"c1": 1.2801 * np.random.default_rng([seed, 0]).uniform(0.8, 1.0, runs),
            "M": np.random.default_rng([seed, 1]).uniform(1200.0, 1600.0, runs)}


def scenario(runs: int, noise: Noise | None = None) -> Scenario:
    t = np.arange(round(T_END / DT) + 1) * DT
    u = np.array([pedal(tk) for tk in t])[:, None]
    return Scenario(duration=T_END, dt=DT, sample_time=DT, inputs=u, params=monte_carlo_params(runs),
                    noise=noise)


def _vector_rhs(t, z, *, model, u, p):
    # the plain form of the same vectorised equations: faster than the in-place form for one run
    return model.f_reference(t, z[None, :], u, p)[0]


def _scalar_rhs(t, z, *, model, F_p, p):
    return model.f_scalar(t, z, F_p, p)


def solve_ivp_run(model: QuarterCarBraking, params: dict, i: int, rtol: float, atol: float,
                  scalar: bool = False):
    """One run with solve_ivp, piecewise between the pedal steps; states at the 1 ms grid.

    ``scalar=False`` integrates the model's vectorised equations (``f_reference``, the plain
    numpy form of ``f``, which is faster than the in-place form for one run) called with one run;
    ``scalar=True`` the same equations in plain Python floats."""
    p = {k: (float(v[i]) if np.ndim(v) else v) for k, v in params.items()}
    p = model.param_values(p)
    edges = [0.0] + [t0 for t0, _ in PEDAL_STEPS] + [T_END]
    t_grid = np.arange(round(T_END / DT) + 1) * DT
    x = model.x0.copy()
    out, nfev = [], 0
    for a, b in itertools.pairwise(edges):
        uu = np.array([[pedal(a)]])
        Fp = float(uu[0, 0])
        sel = t_grid[(t_grid >= a - 1e-12) & (t_grid <= b + 1e-12)]
        if scalar:
            fun = functools.partial(_scalar_rhs, model=model, F_p=Fp, p=p)
        else:
            fun = functools.partial(_vector_rhs, model=model, u=uu, p=p)
        sol = solve_ivp(fun, (a, b), x, method="RK45", t_eval=sel, rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(sol.message)
        nfev += sol.nfev
        out.append(sol.y.T if not out else sol.y.T[1:])
        x = sol.y[:, -1]
    return np.concatenate(out), nfev


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5000)
    ap.add_argument("--ivp-runs", type=int, default=3)
    ap.add_argument("--no-noise-batch", action="store_true", help="skip the batch with noise")
    args = ap.parse_args(argv)
    model = QuarterCarBraking()
    R = args.runs
    rng = np.random.default_rng(0)
    xs = model.x0 * rng.uniform(0.5, 1.0, (50, 6)) + rng.uniform(0, 10, (50, 6))
    us = rng.uniform(0, 500, (50, 1))
    pp = model.param_values(monte_carlo_params(50))
    d_ref = model.f_reference(0.0, xs, us, pp)
    assert np.allclose(model.f(0.0, xs, us, pp), d_ref, rtol=1e-12, atol=1e-9)
    assert np.allclose([model.f_scalar(0.0, xs[i], us[i, 0], {k: (v[i] if np.ndim(v) else v)
                                                                  for k, v in pp.items()})
                        for i in range(50)], d_ref, rtol=1e-12, atol=1e-9)

    # -------------------------------------------------------------- vectorised batch
    sc = scenario(R)
    t0 = time.perf_counter()
    res = simulate(model, sc, runs=R, seed=0, keep=("y",))
    batch = time.perf_counter() - t0
    y = res.y.values  # (runs, T, 2): wheel and vehicle speed (noise-free here)
    print(f"simulate: {R} runs x {round(T_END / DT)} RK4 steps of {DT * 1e3:g} ms, 6 states, "
          f"measurements kept (runs, {y.shape[1]}, 2): {batch:.2f} s ({batch / R * 1e3:.2f} ms per run)")
    v_end = y[:, -1, 1] * model.params["R_w"]
    slip = (y[:, :, 1] - y[:, :, 0]) / np.maximum(y[:, :, 1], 1.0)
    k6, k8 = round(6.5 / DT), round(8.0 / DT)
    print(f"  final vehicle speed {v_end.min():.1f}..{v_end.max():.1f} m/s; mean slip under ABS "
          f"(6.5-8 s) {slip[:, k6:k8].mean():.3f} (target 0.2), peak slip {slip.max():.3f}")
    del slip

    noisy = None
    if not args.no_noise_batch:
        sc_n = scenario(R, Noise(process_snr_db=23.0, measurement=[0.004, 0.004]))
        t0 = time.perf_counter()
        simulate(model, sc_n, runs=R, seed=0, keep=("y",))
        noisy = time.perf_counter() - t0
        print(f"simulate with noise (process 23 dB SNR on 6 states incl. nominal pass, measurement "
              f"variance 0.004): {noisy:.2f} s")

    # -------------------------------------------------------------- determinism
    ids = [0, 1, R // 2, R - 1]
    alone = simulate(model, sc, run_ids=ids, seed=0, keep=("y", "x"))
    bitwise = bool(np.array_equal(alone.y.values, y[ids]))
    print(f"runs {ids} simulated on their own (run_ids=) equal the batch bitwise: {bitwise}")
    x = alone.x.values  # states of runs 0 and 1 for the accuracy check

    # -------------------------------------------------------------- solve_ivp, one run at a time
    params = sc.params
    rows = []
    for rtol, atol, scalar, label in ((1e-3, 1e-6, False, "vectorised model f, default tolerances"),
                                      (1e-6, 1e-8, False, "vectorised model f, rtol 1e-6, atol 1e-8"),
                                      (1e-3, 1e-6, True, "scalar Python f, default tolerances")):
        secs, nf = [], []
        for i in range(args.ivp_runs):
            t0 = time.perf_counter()
            _, nfev = solve_ivp_run(model, params, i, rtol, atol, scalar)
            secs.append(time.perf_counter() - t0)
            nf.append(nfev)
        per = float(np.mean(secs))
        rows.append((label, per, float(np.mean(nf))))
        print(f"solve_ivp RK45 ({label}): {per:.3f} s per run, {np.mean(nf):.0f} f-evaluations; "
              f"{R} runs extrapolated {per * R:.0f} s; speed-up of the batch {per * R / batch:.0f}x")

    # -------------------------------------------------------------- accuracy of RK4 at 1 ms
    errs = []
    for i in range(min(2, args.ivp_runs)):
        ref, _ = solve_ivp_run(model, params, i, 1e-10, 1e-10)
        scale = np.abs(ref).max(axis=0)
        errs.append(np.max(np.abs(x[i] - ref) / scale, axis=0))
    err = np.max(errs, axis=0)
    print("max error of RK4 at 1 ms vs solve_ivp (rtol 1e-10), relative to each state's max: "
          + ", ".join(f"{s} {e:.1e}" for s, e in zip(model.states, err)))

    speedup = rows[0][1] * R / batch  # against the same f with the faster (default-tolerance) solve_ivp
    print(f"targets (issue 2): {R}-run batch <= 60 s -> {batch:.1f} s; >= 100x faster per run than "
          f"solve_ivp -> {speedup:.0f}x (same model f), {rows[2][1] * R / batch:.0f}x (scalar Python f)")
    out = {
        "runs": R,
        "batch_seconds": round(batch, 3),
        "speedup_vs_solve_ivp": round(speedup, 1),
        "speedup_vs_solve_ivp_tight": round(rows[1][1] * R / batch, 1),
        "speedup_vs_solve_ivp_scalar_f": round(rows[2][1] * R / batch, 1),
        "batch_seconds_with_noise": None if noisy is None else round(noisy, 3),
        "solve_ivp_seconds_per_run": round(rows[0][1], 4),
        "bitwise_alone_equals_batch": bitwise,
        "max_rel_error_rk4_vs_tight_ivp": float(f"{err.max():.3g}"),
    }
    return out


if __name__ == "__main__":
    result = main(sys.argv[1:])
    print(json.dumps(result))
