"""Benchmark: SMO fault reconstruction on random systems that meet B1/B2 (issue 17).

Generates relative-degree-2 systems at fixed seeds (n = 6-9 states, p = 3-4 outputs, q = 1-2
faults, h = 1-2 uncertainty channels; a quarter of them with a stable invariant zero built in)
and, for each, designs the cascaded observers with the default (sized) gains and reconstructs
steps, ramps, sinusoids (0.5 and 2 Hz) and a chirp (0.1 -> 2 Hz) at xi = 0; checks that every
loss of sliding is flagged (also with gains deliberately 5x too small); simulates smooth ``xi``
against the claimed L2 bound ``||fhat - f||_2 <= gamma-bar ||xi||_2``; and measures the rmse ratio
with white measurement noise of three levels (noise-aware design). Also: a relative-degree-3
system must give B1's error, an unstable invariant zero B2's, and the aircraft keeps its numbers.

Run: ``python benchmarks/bench_smo_random.py [--systems 40]``; prints figures, the last line is
one JSON object.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np

from fdikit.errors import ConditionError
from fdikit.faults import Bias, Chirp, Ramp, Sinusoid
from fdikit.model.linear import LinearFaultModel
from fdikit.model.random_systems import as_fault_model, random_fault_system
from fdikit.residuals.smo import (
    SATURATED,
    SLIDING,
    check_conditions,
    design_reconstructor,
    integrate_observers,
    simulate_plant,
)

H = 1e-5          # step (s)
T_END = 3.0       # simulated time (s)
SETTLE = 1.0      # scoring window starts (s)
NOISE_LEVELS = (1e-5, 1e-4, 1e-3)


# ----------------------------------------------------------------------------- generator
# the systems come from fdikit.model.random_systems (the tests draw theirs from it too)
random_system = random_fault_system


def as_model(A, M, C, Q) -> LinearFaultModel:
    return as_fault_model(A, M, C, Q)


def kinds(count: int) -> list[tuple[int, str]]:
    """The benchmark's systems: every fourth has a built-in stable zero."""
    return [(seed, "rd2_zero" if seed % 4 == 3 else "rd2") for seed in range(count)]


# ----------------------------------------------------------------------------- signals
def fault_shapes(t: np.ndarray) -> dict[str, np.ndarray]:
    """Unit-bounded fault shapes starting at 0.5 s (Fault classes of fdikit.faults)."""
    shapes = {"step": Bias("f", 1.0, start=0.5), "ramp": Ramp("f", 0.4, start=0.5),
              "sine_0.5Hz": Sinusoid("f", 1.0, 0.5, start=0.5),
              "sine_2Hz": Sinusoid("f", 1.0, 2.0, start=0.5),
              "chirp": Chirp("f", 1.0, f0=0.1, f1=2.0, sweep_time=2.5, start=0.5)}
    return {k: f.signal(t)[0] for k, f in shapes.items()}


def directions(q: int) -> np.ndarray:
    return np.array([1.0]) if q == 1 else np.array([0.8, -0.6])


def rmse_ratio(fh, f, sel):
    return float(np.sqrt(np.mean((fh[sel] - f[sel]) ** 2)) / np.sqrt(np.mean(f[sel] ** 2)))


def smooth_xi(t, h_dim, seed):
    """Smooth disturbance input (sum of sinusoids under a raised-cosine window), ||xi||_inf <= 1."""
    rng = np.random.default_rng(1000 + seed)
    win = np.clip(t / 0.5, 0, 1)
    win = 0.5 - 0.5 * np.cos(np.pi * win)
    xi = np.zeros((t.size, h_dim))
    for k in range(h_dim):
        for w in rng.uniform(0.5, 8.0, 3):
            xi[:, k] += np.sin(w * t + rng.uniform(0, 2 * np.pi))
    xi *= win[:, None]
    return xi / max(1.0, np.linalg.norm(xi, axis=1).max())


def simulate_with_xi(rec, A, M, C, Q, f, xi):
    """Plant with the uncertainty filter xi~' = A_Omega xi~ + B_Omega xi (the design's default)."""
    n, h = A.shape[0], Q.shape[1]
    aug = rec.details["augmented"]
    AO, BO = aug.A_Omega, aug.B_Omega
    Aa = np.block([[AO, np.zeros((h, n))], [Q, A]])
    Ba = np.block([[np.zeros((h, M.shape[1])), BO], [M, np.zeros((n, h))]])
    Ca = np.hstack([np.zeros((C.shape[0], h)), C])
    return simulate_plant(Aa, Ba, Ca, np.column_stack([f, xi]), H)


# ----------------------------------------------------------------------------- main
def main(n_systems: int = 40) -> dict:
    t0 = time.perf_counter()
    t = np.arange(round(T_END / H) + 1) * H
    sel = t >= SETTLE
    shapes = fault_shapes(t)
    rows = []
    designed = 0
    solver_inaccurate = refined = 0
    silent = {"default": 0, "undersized": 0}
    flagged_undersized = 0
    bound_checks = []
    noise = {str(s): [] for s in NOISE_LEVELS}
    for seed, kind in kinds(n_systems):
        A, M, C, Q = random_system(seed, kind)
        n, p, q, h = A.shape[0], C.shape[0], M.shape[1], Q.shape[1]
        c = check_conditions(A, M, C, Q)
        row = {"seed": seed, "kind": kind, "n": n, "p": p, "q": q, "h": h, "B1": c.B1, "B2": c.B2,
               "zeros_real": [float(z.real) for z in c.zeros]}
        try:
            rec = design_reconstructor(as_model(A, M, C, Q))
        except ConditionError as exc:
            row["design_error"] = str(exc)
            rows.append(row)
            print(f"seed {seed:2d} {kind:8s} n={n} p={p} q={q}: DESIGN FAILED {exc}")
            continue
        designed += 1
        for obs in rec.info["solver"].values():
            solver_inaccurate += any(a["status"] == "optimal_inaccurate" for a in obs.get("attempts", []))
            refined += bool(obs.get("refined"))
        row.update(l2_bound=rec.info["l2_bound"], gamma_o=rec.info["gamma_o"], rho=rec.info["gains"]["rho"],
                   rho2=rec.info["gains"]["rho2"], f_max=rec.info["reconstructible"]["fault_bound_max"],
                   hinf=(rec.info.get("hinf_check") or {}).get("hinf_bisection"))
        d = directions(q)
        U0 = np.zeros((1, t.size, 0))
        ratios = {}
        for name, s in shapes.items():
            f = s[:, None] * d[None, :]
            Y = simulate_plant(A, M, C, f, H)
            fh, st = integrate_observers(rec, U0, Y, return_status=True)
            fh, st = fh[0], st[0, :, 0]
            ratios[name] = max(rmse_ratio(fh[:, j], f[:, j], sel) for j in range(q))
            bad = (np.linalg.norm(fh - f, axis=1) > 0.05) & sel & (st == SLIDING)
            silent["default"] += int(bad.sum())
        row["rmse_ratio"] = ratios
        # undersized gains (5x too small) on the step: the losses must be flagged
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the design warns that the gains are too small
            under = design_reconstructor(as_model(A, M, C, Q), rho=rec.info["gains"]["rho"] / 5,
                                         rho2=rec.info["gains"]["rho2"] / 5, hinf_check=False)
        f = shapes["step"][:, None] * d[None, :]
        Y = simulate_plant(A, M, C, f, H)
        fh, st = integrate_observers(under, U0, Y, return_status=True)
        err = np.linalg.norm(fh[0] - f, axis=1)
        big = (err > 0.05) & sel
        silent["undersized"] += int((big & (st[0, :, 0] == SLIDING)).sum())
        flagged_undersized += bool(np.any(st[0, sel, 0] == SATURATED))
        row["undersized_rmse_ratio"] = rmse_ratio(fh[0, :, 0], f[:, 0], sel)
        # L2 bound with smooth xi (no fault, zero initial states), gains sized for ||xi|| <= 1
        recx = design_reconstructor(as_model(A, M, C, Q), xi_bound=1.0, hinf_check=False)
        xi = smooth_xi(t, h, seed)
        Y = simulate_with_xi(recx, A, M, C, Q, np.zeros((t.size, q)), xi)
        fh, st = integrate_observers(recx, U0, Y, return_status=True)
        e2 = float(np.sqrt(np.sum(fh[0] ** 2) * H))
        x2 = float(np.sqrt(np.sum(xi ** 2) * H))
        gam = recx.info["l2_bound"]
        bound_checks.append({"seed": seed, "gamma_bar": gam, "ratio": e2 / (gam * x2),
                             "claimed": bool(recx.info["l2_bound_claimed"]),
                             "implemented_gain_self_check": recx.info["l2_bound_implemented"],
                             "delta2": recx.secondary["delta"],
                             "always_sliding_after_0.1s": bool(np.all(st[0, t >= 0.1, 0] == SLIDING))})
        # measurement noise (first 8 systems): noise-aware design, the 0.5 Hz sinusoid
        if seed < 8:
            f = shapes["sine_0.5Hz"][:, None] * d[None, :]
            Y0 = simulate_plant(A, M, C, f, H)
            rng = np.random.default_rng(7 + seed)
            w = rng.standard_normal(Y0.shape)
            for s in NOISE_LEVELS:
                recn = design_reconstructor(as_model(A, M, C, Q), noise_std=s, hinf_check=False)
                fh = integrate_observers(recn, U0, Y0 + s * w)[0]
                noise[str(s)].append({"seed": seed, "rmse_ratio": max(rmse_ratio(fh[:, j], f[:, j], sel)
                                                                      for j in range(q)),
                                      "lpf_tau": recn.info["noise"]["lpf_tau"],
                                      "predicted_noise_std": recn.info["noise"]["fhat_noise_std"]})
        rows.append(row)
        print(f"seed {seed:2d} {kind:8s} n={n} p={p} q={q} h={h} gamma={row['l2_bound']:.3g} "
              f"rho={row['rho']:.3g} "
              f"rho2={row['rho2']:.3g} worst rmse={max(ratios.values()):.2e} "
              f"L2 ratio={bound_checks[-1]['ratio']:.3f} claimed={bound_checks[-1]['claimed']} "
              f"delta={rec.primary['delta']:.0e}")
    # condition failures that must be named
    cases = {}
    for kind, want in (("rd3", "B1"), ("unstable_zero", "B2")):
        A, M, C, Q = random_system(500, kind)
        try:
            design_reconstructor(as_model(A, M, C, Q))
            cases[kind] = {"expected": want, "got": "designed"}
        except ConditionError as exc:
            cases[kind] = {"expected": want, "got": exc.condition, "message": str(exc)[:200]}
    # the aircraft
    from fdikit.systems.aircraft.reconstruction import run_aircraft

    air = run_aircraft()
    ok_rows = [r for r in rows if "rmse_ratio" in r]
    worst = {k: max(r["rmse_ratio"][k] for r in ok_rows) for k in shapes} if ok_rows else {}
    n_ok = sum(all(v <= 0.01 for v in r["rmse_ratio"].values()) for r in ok_rows)
    # the design claims gamma-bar where its self-check on its own model reaches it (a sampled observer
    # with a boundary layer has a floor that an LMI gamma-bar near 1e-7 does not see); the bound is
    # an ideal-sliding one, so the run must also slide throughout
    bound_claims = [b for b in bound_checks if b["claimed"] and b["always_sliding_after_0.1s"]]
    out = {
        "benchmark": "smo_random",
        "systems": len(rows),
        "kinds": {k: sum(r["kind"] == k for r in rows) for k in ("rd2", "rd2_zero")},
        "designed_fraction": designed / len(rows),
        "reconstructed_fraction_rmse_le_1pct": n_ok / len(rows),
        "worst_rmse_ratio_per_shape": worst,
        "median_rmse_ratio_per_shape": {k: float(np.median([r["rmse_ratio"][k] for r in ok_rows]))
                                        for k in shapes},
        "silent_saturation_samples_default_gains": silent["default"],
        "silent_saturation_samples_undersized_gains": silent["undersized"],
        "undersized_systems_flagged_saturated": flagged_undersized,
        "l2_bound_checks": len(bound_checks),
        "l2_bound_claimed_checks": len(bound_claims),
        "l2_bound_not_claimed": [{"seed": b["seed"], "gamma_bar": b["gamma_bar"],
                                  "implemented_gain_self_check": b["implemented_gain_self_check"],
                                  "measured_gain": b["ratio"] * b["gamma_bar"]}
                                 for b in bound_checks if not b["claimed"]],
        "l2_bound_worst_ratio_claimed": max((b["ratio"] for b in bound_claims), default=None),
        "l2_bound_holds_fraction_claimed": (sum(b["ratio"] <= 1.0 for b in bound_claims) / len(bound_claims)
                                             if bound_claims else None),
        "gamma_bar_range": ([min(b["gamma_bar"] for b in bound_checks),
                             max(b["gamma_bar"] for b in bound_checks)] if bound_checks else None),
        "noise_rmse_ratio": {s: {"median": float(np.median([x["rmse_ratio"] for x in v])),
                                 "max": float(np.max([x["rmse_ratio"] for x in v])),
                                 "median_lpf_tau": float(np.median([x["lpf_tau"] for x in v]))}
                             for s, v in noise.items() if v},
        "solver_inaccurate_designs": solver_inaccurate,
        "solver_refined": refined,
        "gamma_o_retried": sum(r.get("gamma_o", 100.0) != 100.0 for r in ok_rows),
        "condition_cases": cases,
        "aircraft": {"l2_bound": air["l2_bound"], "rmse_ratio": air["rmse_ratio"],
                     "rmse_ratio_nominal": air["rmse_ratio_nominal"], "noise": air.get("noise")},
        "seconds": time.perf_counter() - t0,
    }
    out["targets_met"] = {
        "designed_100pct": out["designed_fraction"] == 1.0,
        "reconstruct_100pct_le_1pct": out["reconstructed_fraction_rmse_le_1pct"] == 1.0,
        "no_silent_saturation": silent["default"] == 0 and silent["undersized"] == 0,
        "l2_bound_where_claimed": out["l2_bound_holds_fraction_claimed"] == 1.0,
        "rd3_gives_B1": cases["rd3"]["got"] == "B1",
        "unstable_zero_gives_B2": cases["unstable_zero"]["got"] == "B2",
        "aircraft_gamma_1.3131": abs(air["l2_bound"] - 1.3131) < 1e-4,
    }
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--systems", type=int, default=40)
    res = main(ap.parse_args().systems)
    print(json.dumps(res, default=float))
