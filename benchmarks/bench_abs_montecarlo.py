"""Benchmark: ABS Monte Carlo, one fault class, 5000 runs x 12.5 s at 1 ms (luo-et-al campaign size).

Goal (issue 4): <= 10 s warm on this 2-core machine, peak memory <= 4 GiB. Reports

* the cold first call including numba compilation (a subprocess with an empty numba cache),
* the first call in this process (compiled kernel loaded from the numba cache),
* the warm time of the 5000-run campaign and its peak memory (ru_maxrss and tracemalloc),
* the time of a per-run loop of scipy ``solve_ivp`` (RK45 on :meth:`ABSPlant.f`, controller and
  valves re-implemented here in Python, one solve per 1 ms controller period) on a few runs,
  extrapolated to 5000 runs, and how far its stop agrees with the Euler kernel's.

Prints the figures, then one JSON object as the last line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc

import numpy as np
from scipy.integrate import solve_ivp

from fdikit.systems.abs.plant import ABSPlant, Scenario, simulate, slip, summarize

GOAL_S = 10.0
GOAL_MEM_GIB = 4.0


def cold_compile_time() -> float:
    """Seconds for a 2-run simulation in a fresh interpreter with an empty numba cache."""
    code = ("import time; t=time.perf_counter();"
            "from fdikit.systems.abs.plant import Scenario, simulate;"
            "simulate(None, Scenario(fault='F3', t_end=1.0), runs=2);"
            "print(time.perf_counter()-t)")
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=d)
        cp = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                            check=True)
    return float(cp.stdout.strip().splitlines()[-1])


def reference_run(plant: ABSPlant, sc: Scenario) -> dict:
    """One noise-free nominal stop with scipy solve_ivp (RK45) per 1 ms controller period."""
    p = plant.params
    dt = sc.dt
    w0 = sc.v0 / p["R_w"]
    x = np.array([w0, w0, 0.0, 0.0, 0.0, 0.0])
    cmd_in, cmd_out = True, False
    e_in = e_out = 1e3
    duty_in, duty_out = 1.0, 0.0

    def area(opening, e):  # eqs. (8)-(9), normalised by A_0
        if opening:
            return 0.5 + 0.5 * math.tanh((e - p["t_opdelay"]) / p["t_oprate"])
        return 0.5 - 0.5 * math.tanh((e - p["t_cldelay"]) / p["t_clrate"])

    def enter(opening, a):  # elapsed time at which the new law has area a
        a = min(max(a, 1e-15), 1 - 1e-15)
        if opening:
            return max(p["t_opdelay"] + p["t_oprate"] * math.atanh(2 * a - 1), 0.0)
        return max(p["t_cldelay"] + p["t_clrate"] * math.atanh(1 - 2 * a), 0.0)

    e_prev = p["lam_star"] - float(slip(x[0], x[1]))
    t_on = t_stop = math.nan
    lam_active = []
    stopped = False
    for k in range(sc.n_steps):
        t = k * dt
        lam = float(slip(x[0], x[1]))
        e = p["lam_star"] - lam
        edot = (e - e_prev) / p["t_s"]
        e_prev = e
        active = t >= sc.t_brake and not stopped and p["R_w"] * x[1] > sc.v_off
        sat = min(max((e + p["alpha"] * edot) / p["phi"], -1.0), 1.0) if active else 1.0
        if active and not math.isnan(t_on):
            lam_active.append(lam)
        if (sat > 0) != cmd_in:
            e_in = enter(sat > 0, area(cmd_in, e_in))
            cmd_in = sat > 0
        if (sat < 0) != cmd_out:
            e_out = enter(sat < 0, area(cmd_out, e_out))
            cmd_out = sat < 0
            if cmd_out and math.isnan(t_on):
                t_on = t
        if cmd_in:
            duty_in = sat
        if cmd_out:
            duty_out = -sat
        u_in = duty_in * area(cmd_in, e_in)
        u_out = duty_out * area(cmd_out, e_out)
        e_in += dt
        e_out += dt

        def rhs(tt, z, u_in=u_in, u_out=u_out):
            u = np.zeros((1, 9))
            u[0, :3] = [plant.pedal_force(tt, sc.t_brake), u_in, u_out]
            return plant.f(tt, z[None], u, p)[0]

        sol = solve_ivp(rhs, (t, t + dt), x, method="RK45", rtol=1e-6,
                        atol=[1e-6, 1e-6, 1e-4, 1e-2, 1e-6, 1e-6])
        x = sol.y[:, -1].copy()
        if stopped or x[1] <= 0:
            if not stopped:
                t_stop = t + dt
            stopped = True
            x[0] = x[1] = 0.0
        x[0] = max(x[0], 0.0)
    return {"t_abs_on": t_on, "t_stop": t_stop, "mean_slip": float(np.mean(lam_active))}


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=5000)
    ap.add_argument("--fault", default="F3")
    ap.add_argument("--ref-runs", type=int, default=1, help="solve_ivp runs to time (0: skip)")
    ap.add_argument("--no-cold", action="store_true", help="skip the cold-compile subprocess")
    a = ap.parse_args()

    plant = ABSPlant()
    sc = Scenario(fault=a.fault)
    cold = float("nan") if a.no_cold else cold_compile_time()
    print(f"cold first call incl. numba compile (fresh process, empty cache): {cold:.2f} s")

    t0 = time.perf_counter()
    simulate(plant, sc, runs=2, seed=0)
    first = time.perf_counter() - t0
    print(f"first call in this process (kernel from numba cache, 2 runs): {first:.2f} s")

    tracemalloc.start()
    t0 = time.perf_counter()
    res = simulate(plant, sc, runs=a.runs, seed=0)
    warm = time.perf_counter() - t0
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_gib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2  # Linux: KiB
    s = summarize(res)
    steps = a.runs * sc.n_steps
    print(f"warm: {a.runs} runs x {sc.t_end} s at {sc.dt * 1e3:g} ms ({steps / 1e6:.1f} M steps, "
          f"fault {a.fault}): {warm:.2f} s  ({warm / steps * 1e9:.0f} ns/step), goal <= {GOAL_S} s")
    print(f"peak memory: ru_maxrss {rss_gib:.3f} GiB, tracemalloc peak {traced_peak / 2**30:.3f} GiB "
          f"(goal <= {GOAL_MEM_GIB} GiB)")
    print(f"campaign summary: stop {s['stopping_time']:.2f} s after braking, ABS on at "
          f"{s['abs_engaged_at']:.2f} s, mean slip {s['mean_slip_abs']:.3f}")

    ref = {}
    if a.ref_runs > 0:
        nsc = Scenario(fault="F0", snr_db=None, meas_var=0.0)
        t0 = time.perf_counter()
        refs = [reference_run(plant, nsc) for _ in range(a.ref_runs)]
        t_ref = (time.perf_counter() - t0) / a.ref_runs
        ker = simulate(plant, nsc, runs=1).events
        r0 = refs[0]
        ref = {
            "solve_ivp_s_per_run": t_ref,
            "solve_ivp_extrapolated_s": t_ref * a.runs,
            "speedup_vs_solve_ivp": t_ref * a.runs / warm,
            "kernel_vs_rk45": {
                "t_stop": [float(ker["t_stop"][0]), r0["t_stop"]],
                "t_abs_on": [float(ker["t_abs_on"][0]), r0["t_abs_on"]],
                "mean_slip": [float(ker["mean_slip"][0]), r0["mean_slip"]],
            },
        }
        print(f"solve_ivp loop: {t_ref:.1f} s per run -> {t_ref * a.runs:.0f} s for {a.runs} runs "
              f"(extrapolated); kernel is {ref['speedup_vs_solve_ivp']:.0f}x faster")
        print(f"noise-free nominal stop, Euler kernel vs RK45: t_stop {ker['t_stop'][0]:.3f} / "
              f"{r0['t_stop']:.3f} s, ABS on {ker['t_abs_on'][0]:.3f} / {r0['t_abs_on']:.3f} s, "
              f"mean slip {ker['mean_slip'][0]:.4f} / {r0['mean_slip']:.4f}")

    out = {
        "benchmark": "abs_montecarlo",
        "runs": a.runs,
        "fault": a.fault,
        "steps_per_run": sc.n_steps,
        "cold_first_call_s": cold,
        "first_call_cached_s": first,
        "warm_s": warm,
        "goal_s": GOAL_S,
        "meets_goal": bool(warm <= GOAL_S),
        "peak_rss_gib": rss_gib,
        "tracemalloc_peak_gib": traced_peak / 2**30,
        "meets_memory_goal": bool(rss_gib <= GOAL_MEM_GIB),
        "numba_threads": int(__import__("numba").get_num_threads()),
        **ref,
    }
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
