"""Benchmark: SMO design time on large random plants (issue 31, "n >= 60 within 60 s").

Designs (default gains, self-check on, no H-inf check) the random relative-degree-2 plants of
``bench_smo_random.large_system`` at n = 30 and 60 in one process and reports, per plant, the
wall and CPU seconds of the whole design and of its LMIs, the secondary LMI's form, iterations
and solve seconds, and gamma-bar; ``os.getloadavg()`` before and after (the machine may be
shared: the CPU seconds are the figure that does not depend on the load). ``--form full``
solves the secondary LMI as written at every size (the code before the reduced form) for a
side-by-side measurement.

Measured (2 shared cores, load average 7-20 from other work; the CPU seconds are the figure):
the secondary LMI at n = 60 (nb = 52) takes 51.6 CPU s as written (26 Clarabel iterations,
cvxpy's canonicalisation ~1 s of it) and 21.7 CPU s in the reduced form (31 iterations); the whole
design takes 47.3 CPU s at n = 60 (409 s wall at load 10-15) and 7.8 CPU s at n = 30 (50 s wall
at load 7-10); before (full form, every ladder layer's xi runs) about 120 CPU s at n = 60.

Per phase (``--phases``: CPU seconds of the LMIs, the self-check's plant simulations and observer
runs, by wrapping those functions), n = 60, warm numba cache, load 5-8: before (issue 31's second
session) 50.4 CPU s in all (141 s wall): secondary LMI 20.3, self-check 27.6 (plant simulations
8.5 in 8 calls, observer runs 18.3 in 8 calls: all four layers of the ladder ran the full band of
xi probes), primary 1.4, peak gains 0.5. After (plant runs computed once per design and shared
by the ladder; a layer's xi runs stop at the first probe that shows it cannot claim gamma-bar,
the probe that was worst for the layer before): 34.2 CPU s (86 s wall at load 7-8): secondary
LMI 21.5, self-check 10.2 (plant 2.1 in 2 calls, observers 7.9), primary 1.1, peak gains 0.6;
the design and its numbers are the same (same layer, same self-check). The secondary LMI is
Clarabel's 31 interior-point iterations on PSD cones of 46 and 56 rows; ``direct_solve_method=
"faer"`` measured the same (24 CPU s) and looser tolerances (1e-6) end 16 iterations early at a
17x larger gamma-bar with ``P`` indefinite (then re-solved with the cone): kept as is.
This benchmark after both changes (load 5-7): n = 60 31.7 CPU s, 44 s wall (secondary LMI 20.3,
self-check 9.8); n = 30 4.1 CPU s, 6.1 s wall. A cold numba cache (first run after an install)
added about 37 CPU s of compilation, 8.5 CPU s since the kernel's helpers are no longer
numba-IR inlined (same numbers, bitwise).

Run: ``python benchmarks/bench_smo_large.py [--sizes 30,60] [--form auto|full] [--phases]``; the
last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings

from bench_smo_random import LARGE_BUDGET_S, as_model, large_system
from fdikit.design import smo_lmi
from fdikit.residuals.smo import design_reconstructor

#: (module, attribute, phase) of the functions ``--phases`` times.
PHASES = (("design", "_secondary", "secondary LMI"), ("design", "primary_smo_lmi", "primary LMI"),
          ("design", "injection_peak_gains", "peak gains"), ("design", "self_check", "self-check"),
          ("selfcheck", "simulate_plant", "self-check: plant simulations"),
          ("selfcheck", "integrate_observers", "self-check: observer runs"))


def _timed(phases: dict):
    """Wrap the functions of :data:`PHASES` to add their CPU and wall seconds to ``phases``;
    returns the undo list."""
    from fdikit.residuals.smo import design as d_mod
    from fdikit.residuals.smo import selfcheck as s_mod

    mods = {"design": d_mod, "selfcheck": s_mod}
    undo = []
    for mod_name, attr, key in PHASES:
        mod = mods[mod_name]
        f = getattr(mod, attr)

        def g(*a, _f=f, _key=key, **k):
            c0, w0 = time.process_time(), time.perf_counter()
            try:
                return _f(*a, **k)
            finally:
                v = phases.setdefault(_key, {"cpu_s": 0.0, "wall_s": 0.0, "calls": 0})
                v["cpu_s"] += time.process_time() - c0
                v["wall_s"] += time.perf_counter() - w0
                v["calls"] += 1

        setattr(mod, attr, g)
        undo.append((mod, attr, f))
    return undo


def case(n: int, phases: bool = False) -> dict:
    A, M, C, Q = large_system(0, n)
    per: dict = {}
    undo = _timed(per) if phases else []
    load0 = os.getloadavg()
    w0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            rec = design_reconstructor(as_model(A, M, C, Q), hinf_check=False)
        finally:
            for mod, attr, f in undo:
                setattr(mod, attr, f)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    sec = rec.info["solver"]["secondary"]
    return {"n": n, "p": C.shape[0], "q": M.shape[1], "h": Q.shape[1], "n_aug": rec.info["n_aug"],
            "design_wall_s": wall, "design_cpu_s": cpu, "lmi_wall_s": rec.info["lmi_seconds"],
            "secondary_form": sec.get("form"),
            "secondary_iterations": [a.get("iterations") for a in sec["attempts"]],
            "secondary_solve_s": sum(a.get("solve_seconds") or 0.0 for a in sec["attempts"]),
            "primary_solver": rec.info["solver"]["primary"]["solver"],
            "l2_bound": rec.info["l2_bound"], "l2_bound_claimed": rec.info["l2_bound_claimed"],
            "delta": rec.primary["delta"], "delta2": rec.secondary["delta"],
            "loadavg_before": load0, "loadavg_after": os.getloadavg(),
            "within_budget_wall": wall <= LARGE_BUDGET_S, "within_budget_cpu": cpu <= LARGE_BUDGET_S,
            **({"phases": per} if phases else {})}


def main(sizes=(30, 60), form: str = "auto", phases: bool = False) -> dict:
    if form == "full":
        smo_lmi.SECONDARY_FULL_MAX_STATES = 10 ** 9
    rows = []
    for n in sizes:
        rows.append(case(n, phases))
        print(rows[-1], flush=True)
    return {"benchmark": "smo_large", "form": form, "cpu_count": os.cpu_count(), "rows": rows}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="30,60")
    ap.add_argument("--form", default="auto", choices=("auto", "full"))
    ap.add_argument("--phases", action="store_true", help="CPU and wall seconds per design phase")
    a = ap.parse_args()
    print(json.dumps(main(tuple(int(x) for x in a.sizes.split(",")), a.form, a.phases), default=float))
