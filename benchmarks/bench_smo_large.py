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

Run: ``python benchmarks/bench_smo_large.py [--sizes 30,60] [--form auto|full]``; the last line
is one JSON object.
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


def case(n: int) -> dict:
    A, M, C, Q = large_system(0, n)
    load0 = os.getloadavg()
    w0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(as_model(A, M, C, Q), hinf_check=False)
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
            "within_budget_wall": wall <= LARGE_BUDGET_S, "within_budget_cpu": cpu <= LARGE_BUDGET_S}


def main(sizes=(30, 60), form: str = "auto") -> dict:
    if form == "full":
        smo_lmi.SECONDARY_FULL_MAX_STATES = 10 ** 9
    rows = []
    for n in sizes:
        rows.append(case(n))
        print(rows[-1], flush=True)
    return {"benchmark": "smo_large", "form": form, "cpu_count": os.cpu_count(), "rows": rows}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="30,60")
    ap.add_argument("--form", default="auto", choices=("auto", "full"))
    a = ap.parse_args()
    print(json.dumps(main(tuple(int(x) for x in a.sizes.split(",")), a.form), default=float))
