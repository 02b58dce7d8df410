"""Benchmark: cascaded SMO fault reconstruction on the aircraft of ng-tan-edwards-kuang.

Measures the two LMI designs (primary (42)-(44) and secondary (46)-(47), Clarabel), the 15 s
simulation at h = 1e-5 s (1.5 M steps of plant + both observers) and the reconstruction error.
Targets (issue 3): both LMIs <= 2 s; simulation <= 5 s; gamma-bar <= 1.3131; rmse_ratio <= 0.05
(uncertain) and <= 0.01 (nominal). The last line is one JSON object.

Run: ``python benchmarks/bench_smo.py``
"""

from __future__ import annotations

import json
import time

import numpy as np

from fdikit.residuals.smo import design_reconstructor, integrate_observers, simulate_plant
from fdikit.systems import aircraft
from fdikit.systems.aircraft.reconstruction import X0


def main() -> dict:
    h, t_final, settle = 1e-5, 15.0, 1.0
    # cold design (includes cvxpy problem construction and the first Clarabel call)
    t0 = time.perf_counter()
    rec = design_reconstructor(aircraft.model(), dt=h)
    design_cold = time.perf_counter() - t0
    lmi_cold = rec.info["lmi_seconds"]
    designs = []
    for _ in range(3):
        r2 = design_reconstructor(aircraft.model(), dt=h, hinf_check=False)
        designs.append(r2.info["lmi_seconds"])
    lmi_warm = float(np.median(designs))
    # compile / load the numba kernels on a short run
    tc = time.perf_counter()
    tt = np.arange(100) * h
    integrate_observers(rec, np.zeros((1, 100, 2)),
                        simulate_plant(aircraft.A_TRUE, aircraft.M, aircraft.C, np.zeros((100, 1)), h))
    compile_s = time.perf_counter() - tc
    del tt
    t = np.arange(round(t_final / h) + 1) * h
    f = aircraft.fault_signal(t)
    sel = t >= settle
    res = {}
    for key, A in (("uncertain", aircraft.A_TRUE), ("nominal", aircraft.A_NOMINAL)):
        ts = time.perf_counter()
        Y = simulate_plant(A, aircraft.M, aircraft.C, f[:, None], h, x0=X0)
        tp = time.perf_counter() - ts
        ts = time.perf_counter()
        fh = integrate_observers(rec, np.zeros((1, t.size, 2)), Y)[0, :, 0]
        to = time.perf_counter() - ts
        ratio = float(np.sqrt(np.mean((fh[sel] - f[sel]) ** 2)) / np.sqrt(np.mean(f[sel] ** 2)))
        res[key] = {"plant_s": tp, "observers_s": to, "total_s": tp + to, "rmse_ratio": ratio}
    hc = rec.info["hinf_check"]
    out = {
        "benchmark": "smo_aircraft",
        "steps": int(t.size),
        "h": h,
        "t_final": t_final,
        "l2_bound": rec.info["l2_bound"],
        "l2_bound_paper": 1.3131,
        "hinf_bisection": hc["hinf_bisection"],
        "hinf_sweep": hc["hinf_sweep"],
        "lmi_seconds_cold": lmi_cold,
        "lmi_seconds_warm": lmi_warm,
        "design_seconds_cold": design_cold,
        "numba_compile_or_cache_load_s": compile_s,
        "sim_seconds": res["uncertain"]["total_s"],
        "sim_plant_seconds": res["uncertain"]["plant_s"],
        "sim_observers_seconds": res["uncertain"]["observers_s"],
        "rmse_ratio": res["uncertain"]["rmse_ratio"],
        "rmse_ratio_nominal": res["nominal"]["rmse_ratio"],
        "settle_s": settle,
        "targets_met": {
            "lmi_le_2s": lmi_cold <= 2.0,
            "sim_le_5s": res["uncertain"]["total_s"] <= 5.0,
            "gamma_le_paper": rec.info["l2_bound"] <= 1.3131,
            "hinf_le_gamma": hc["within_bound"],
            "rmse_uncertain_le_0.05": res["uncertain"]["rmse_ratio"] <= 0.05,
            "rmse_nominal_le_0.01": res["nominal"]["rmse_ratio"] <= 0.01,
        },
    }
    print(f"LMIs (primary + secondary): cold {lmi_cold:.3f} s, warm {lmi_warm:.3f} s (target <= 2 s)")
    print(f"gamma-bar {out['l2_bound']:.5f} (paper 1.3131); H-inf of G(s): bisection "
          f"{out['hinf_bisection']:.5f}, sweep {out['hinf_sweep']:.5f}")
    print(f"15 s at h = 1e-5 ({t.size} steps): plant {out['sim_plant_seconds']:.2f} s + observers "
          f"{out['sim_observers_seconds']:.2f} s = {out['sim_seconds']:.2f} s (target <= 5 s); "
          f"numba compile/cache load {compile_s:.2f} s")
    print(f"RMS(f^ - f)/RMS(f), t >= {settle} s: uncertain {out['rmse_ratio']:.4f} (<= 0.05), "
          f"nominal {out['rmse_ratio_nominal']:.2e} (<= 0.01)")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
