"""Benchmark: the generated C monitor against the Python (numba) streaming path (issue 29).

For every example config (``examples/*/monitor.toml``) the config is designed into a temporary
copy, C is generated (``fdikit.codegen.generate``; the generation time is measured), or the stage
that cannot be generated yet is reported by name. For the generated ones, on the same simulated
log (``fdikit example-log`` or the example's own simulator), in the same run:

* ns per sample of the generated C step (double and float32), timed inside a compiled C loop over
  the samples held in memory (no Python in the loop), and of ``Monitor.step`` (the streaming
  path, its arithmetic in numba kernels); wall-clock and process CPU time (on a loaded machine
  the CPU time is the cost of the code, the wall clock also counts the waits for a core);
* the state size (``sizeof`` of the state struct) and the code size (the object file's text and
  data, and the C source) in bytes;
* the equivalence: events equal, statistics bitwise equal (double), the float32 variant's
  largest error relative to each channel's largest magnitude, and whether its events agree.

The RAV4 monitor (``rav4-lateral``: its whole chain, with the peer CUSUM, the fault-type classifier
and its hold, and the decision's ``confirm_after``)
runs on the real minute (``../shared/data/rav4-highway``) with injected faults
(:data:`RAV4_FAULTS`); ``rav4-lateral-peer`` is its chain up to the peer checks
(``stop_after="peer_check"``), the part generated before the classifier had an emitter. The load
average is printed with the results.

An example is a folder of ``examples/`` (its ``monitor.toml``) or ``FOLDER:CONFIG.toml``
(``abs:monitor_extended.toml``, the ABS monitor with the directional tests). ``--quick-design``
designs the ABS monitors from fewer Monte Carlo runs (:data:`QUICK_DESIGN`: the same stages, other
thresholds), for a run in minutes instead of an hour on two cores.

Measured (2026-12-03, this machine, load ~4; the C timer's process CPU time, best of 7 runs of 50
passes): the RAV4 full chain 4.50 -> 2.18 us per sample and its state 258,456 -> 40,728 B once the
fault-type classifier holds its 30 s window as 0.5 s block sums (issue 29; before: three rings of
1,500 samples per sensor rescanned every step); its chain to the peer checks 1.49 us, 3,968 B. By
callgrind, per sample: 46.6k -> 21.6k instructions; the classifier's helpers ~0.5k of them (before
25.8k), the decision over 48 channels (``fdk_decide``) 5.1k, the rest the filters and the MHSSPT.
Then (2026-12-03, load ~1.5, best of 7 runs of 50 passes, before and after alternated) the decision
as bit masks of the channels on / not below the clear level, its names' pass skipped while the same
channels are on, its event passes run only when a unit clears, opens or is renamed; the filters
reading their state in place; one branch per stage for the non-finite refusal: the RAV4 full chain
2.14 -> 1.75 us CPU per sample, 21.7k -> 16.4k instructions (``fdk_decide`` 5.1k -> 0.45k); to the
peer checks 1.48 -> 1.44 us, 13.8k -> 13.3k; outputs and events bitwise equal.

Usage: ``python benchmarks/bench_codegen.py [--repeat 20] [--examples two-mass own-system]
[--quick-design]``. The last printed line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

TIMER_MAIN = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "NAME.h"

int main(int argc, char **argv)
{
    NAME_state s;
    NAME_event ev[CAP_MAX_EVENTS];
    double out[CAP_N_OUT > 0 ? CAP_N_OUT : 1], *data, sink = 0.0;
    long n = 0, cap = 1 << 16, k, r, reps = argc > 1 ? atol(argv[1]) : 10;
    int ne;
    struct timespec a, b, ca, cb;
    data = malloc(sizeof(double) * (CAP_N_IN + 1) * cap);
    while (fread(data + n * (CAP_N_IN + 1), sizeof(double), CAP_N_IN + 1, stdin) == CAP_N_IN + 1) {
        if (++n == cap) { cap *= 2; data = realloc(data, sizeof(double) * (CAP_N_IN + 1) * cap); }
    }
    clock_gettime(CLOCK_MONOTONIC, &a);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ca);
    for (r = 0; r < reps; ++r) {
        NAME_reset(&s);
        for (k = 0; k < n; ++k) {
            double *row = data + k * (CAP_N_IN + 1);
            NAME_step(&s, row[0], row + 1, out, ev, &ne);
            sink += out[0];
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cb);
    printf("%.3f %.3f %g\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / (double)(n * reps),
           ((cb.tv_sec - ca.tv_sec) * 1e9 + (cb.tv_nsec - ca.tv_nsec)) / (double)(n * reps), sink);
    free(data);
    return 0;
}
"""


#: ``--quick-design``: [design.params] overrides per example config (fewer Monte Carlo runs).
QUICK_DESIGN = {"abs": {"design_runs": 40, "dmatrix_runs": 6}}


def _split(example: str) -> tuple[str, str]:
    folder, _, cfg = example.partition(":")
    return folder, cfg or "monitor.toml"


def _design(example: str, tmp: Path, quick: bool = False) -> tuple[Path, list[Path]]:
    """A designed copy of an example and its logs (CSV)."""
    folder, cfg_name = _split(example)
    ex = tmp / example.replace(":", "-")
    shutil.copytree(ROOT / "examples" / folder, ex, ignore=shutil.ignore_patterns("designs*"))
    cfg = ex / cfg_name
    if quick and folder in QUICK_DESIGN:
        text = cfg.read_text()
        for k, v in QUICK_DESIGN[folder].items():
            lines = [ln for ln in text.splitlines() if not ln.startswith(f"{k} =")]
            i = lines.index("[design.params]")
            text = "\n".join([*lines[:i + 1], f"{k} = {v}", *lines[i + 1:]]) + "\n"
        cfg.write_text(text)
    cli = [sys.executable, "-m", "fdikit.cli"]
    flights = ex / "simulate_flights.py"
    if flights.exists():   # examples/uav: the design identifies the plant from simulated ULog flights
        subprocess.run([sys.executable, str(flights), str(ex / "flights")], check=True, capture_output=True)
    subprocess.run([*cli, "design", str(cfg)], check=True, capture_output=True)
    if flights.exists():
        return cfg, sorted((ex / "flights").glob("failure_*.ulg"))
    logs = tmp / f"{ex.name}-logs"
    sim = ex / "simulate_logs.py"
    if sim.exists():
        subprocess.run([sys.executable, str(sim), str(logs), "--minutes", "1"], check=True,
                       capture_output=True)
        return cfg, sorted(logs.glob("*.csv"))
    r = subprocess.run([*cli, "example-log", str(cfg), "--out", str(logs), "--json"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        return cfg, []
    return cfg, sorted(logs.glob("*.csv"))


def _size(obj: Path) -> int:
    """Text + data + bss of an object file (``size``), else its file size."""
    r = subprocess.run(["size", str(obj)], capture_output=True, text=True)
    if r.returncode == 0:
        return int(r.stdout.splitlines()[1].split()[3])
    return obj.stat().st_size


def bench(example: str, tmp: Path, repeat: int, quick: bool = False) -> dict:
    from fdikit.codegen import generate
    from fdikit.errors import DataError
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log

    out: dict = {"example": example}
    t0 = time.perf_counter()
    try:
        cfgp, logs = _design(example, tmp, quick)
    except subprocess.CalledProcessError as exc:
        return {**out, "refused": f"design failed: {exc.stderr.decode(errors='replace')[-300:]}"}
    out["design_seconds"] = round(time.perf_counter() - t0, 2)
    cdir = tmp / f"{example}-c"
    t0 = time.perf_counter()
    try:
        gen = generate(cfgp, cdir, name="fdk_m")
    except DataError as exc:
        return {**out, "refused": str(exc)}
    out["generation_seconds_cold"] = round(time.perf_counter() - t0, 4)   # with the first imports
    t0 = time.perf_counter()
    gen = generate(cfgp, cdir, name="fdk_m")
    out["generation_seconds"] = round(time.perf_counter() - t0, 4)
    out["stages"] = gen["layout"]["stages"]
    out["code_source_bytes"] = gen["code_bytes"]
    if not logs:
        return {**out, "note": "no example log to run on"}
    cfg = load_config(cfgp)
    mon = build_monitor(cfg)
    log = next((p for p in logs if p.stem == "fault"), logs[-1])
    sig = map_channels(cfg, read_log(cfg, log))
    x = sig.values[0][:, sig.index(gen["layout"]["inputs"])]
    out["log"] = log.name
    if quick and _split(example)[0] in QUICK_DESIGN:
        out["design"] = f"quick: {QUICK_DESIGN[_split(example)[0]]}"
    return _time_monitor(out, mon, cdir, sig.t, x, repeat)


def _time_monitor(out: dict, mon, cdir: Path, t: np.ndarray, x: np.ndarray, repeat: int) -> dict:
    """Time the generated ``fdk_m`` in ``cdir`` (double and float32) and ``mon``'s streaming path
    on the same record; sizes and equivalence."""
    from fdikit.codegen import CFLAGS, CMonitor, compile_shared, find_compiler

    names = list(mon.input_names)
    out["samples"] = int(t.size)
    cc = find_compiler()
    res = {}
    for prec, stem in (("double", "fdk_m"), ("float", "fdk_m_f32")):
        src = cdir / f"{stem}.c"
        objf = cdir / f"{stem}.o"
        subprocess.run([cc, *CFLAGS, "-c", str(src), "-o", str(objf)], check=True)
        main = TIMER_MAIN.replace("NAME", stem).replace("CAP", stem.upper())
        (cdir / f"time_{stem}.c").write_text(main)
        exe = cdir / f"time_{stem}"
        subprocess.run([cc, "-O2", "-ffp-contract=off", f"-I{cdir}", str(cdir / f"time_{stem}.c"), str(src),
                        "-o", str(exe), "-lm"], check=True)
        r = subprocess.run([str(exe), str(repeat)], input=np.column_stack([t, x]).astype(float).tobytes(),
                           capture_output=True, check=True)
        cm = CMonitor(compile_shared([src], cdir / f"lib{stem}.so"), cdir / f"{stem}.layout.json")
        run = cm.run(t, x)
        wall, cpu = (float(v) for v in r.stdout.split()[:2])
        res[prec] = {"ns_per_sample": wall, "cpu_ns_per_sample": cpu, "state_bytes": cm.state_bytes,
                     "code_bytes": _size(objf), "run": run}
    # the Python streaming path, same log, same process (a first pass compiles and warms it)
    mon.reset(1)
    for k in range(min(t.size, 500)):
        mon.step(float(t[k]), x[k][None], names)
    mon.reset(1)
    py_out, py_ev = [], []
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(t.size):
        r_, s_, ev = mon.step(float(t[k]), x[k][None], names)
        py_out.append(np.concatenate([r_[0], s_[0]]))
        py_ev += [(e.k, e.kind, e.hypothesis) for e in ev]
    py_ns = (time.perf_counter() - t0) / t.size * 1e9
    py_cpu_ns = (time.process_time() - c0) / t.size * 1e9
    py_out = np.array(py_out)
    scale = np.maximum(np.abs(py_out).max(axis=0), 1e-300)
    for prec, d in res.items():
        run = d.pop("run")
        ev = [(e["k"], e["kind"], e["hypothesis"]) for e in run["events"]]
        d["events_equal"] = ev == py_ev
        d["max_error_rel_to_channel_scale"] = float(np.max(np.abs(run["out"] - py_out) / scale))
        d["channels_not_bitwise"] = [n for j, n in enumerate([*mon.residual_names, *mon.stat_names])
                                     if not np.array_equal(run["out"][:, j], py_out[:, j])]
        if prec == "double":
            d["bitwise_equal"] = bool(np.array_equal(run["out"], py_out))
        else:
            d["events_differing"] = sorted(set(ev) ^ set(py_ev))
    out.update(python_stream_ns_per_sample=round(py_ns, 1),
               python_stream_cpu_ns_per_sample=round(py_cpu_ns, 1), c=res, events=len(py_ev),
               speedup_double=round(py_ns / res["double"]["ns_per_sample"], 1),
               speedup_double_cpu=round(py_cpu_ns / res["double"]["cpu_ns_per_sample"], 1))
    return out


def synthetic_mhsspt(tmp: Path, repeat: int) -> dict:
    """A monitor no example has yet: a random 6-state filter, residual-norm features and an exact
    MHSSPT (4 hypotheses, a group), on 20 000 random samples with faults."""
    from fdikit.detect import MHSSPT, FeatureNorms, UniformMeanGaussian
    from fdikit.monitor import Decision, Monitor
    from fdikit.residuals import FaultDetectionFilter, FilterDesign

    rng = np.random.default_rng(0)
    n, dt = 6, 0.01
    A = rng.normal(size=(n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    d = FilterDesign(A, rng.normal(size=(n, 1)), rng.normal(size=(n, 3)), rng.normal(size=(6, n)),
                     rng.normal(size=(6, 1)), rng.normal(size=(6, 3)), dt, ["u"], ["y0", "y1", "y2"],
                     [f"r{i}" for i in range(6)])
    feats = FeatureNorms({"a": ["r0", "r1"], "b": ["r2", "r3"], "c": ["r4", "r5"]}, dt, tau=0.05)
    s3 = [0.5, 0.5, 0.5]
    dens = {"none": UniformMeanGaussian([0, 0, 0], [1, 1, 1], s3),
            "fa": UniformMeanGaussian([0, 2, 2], [1, 9, 9], s3),
            "fb": UniformMeanGaussian([2, 0, 2], [9, 1, 9], s3),
            "fc": UniformMeanGaussian([2, 2, 0], [9, 9, 1], s3)}
    mh = MHSSPT(feats.output_names, dens, p=1e-4, groups={"ab": ["fa", "fb"]})
    mon = Monitor([FaultDetectionFilter(d)], [feats, mh], Decision(mh.output_names[1:4], 0.9),
                  on_invalid="hold")
    T = 20000
    t = np.arange(T) * dt
    x = rng.normal(scale=0.3, size=(T, 4))
    x[5000:7000, 1] += 3.0
    x[12000:13000, 3] -= 3.0
    from fdikit.codegen import generate_monitor

    cdir = tmp / "synthetic-c"
    t0 = time.perf_counter()
    gen = generate_monitor(mon, cdir, name="fdk_m")
    out = {"example": "synthetic-mhsspt", "generation_seconds": round(time.perf_counter() - t0, 4),
           "stages": gen["layout"]["stages"], "code_source_bytes": gen["code_bytes"], "log": "random"}
    return _time_monitor(out, mon, cdir, t, x, repeat)


RAV4_DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
#: The faults injected into the real RAV4 minute for the benchmark (CAN names, DBC units).
RAV4_FAULTS = "stuck:STEER_ANGLE_SENSOR@15,YAW_RATE:3.0@40"


def rav4(tmp: Path, repeat: int, stop_after: str | None = None) -> dict:
    """The RAV4 lateral monitor (examples/rav4-lateral) on the real minute with injected faults:
    designed in a temporary copy (once per run), generated whole or up to ``stop_after``."""
    from fdikit.codegen import generate
    from fdikit.errors import DataError
    from fdikit.monitor.config import load_config, run_design

    out: dict = {"example": "rav4-lateral" + ("" if stop_after is None else f" (to {stop_after})")}
    if not (RAV4_DATA / "drive.blf").exists():
        return {**out, "refused": f"RAV4 data not found at {RAV4_DATA}"}
    text = (ROOT / "examples" / "rav4-lateral" / "monitor.toml").read_text()
    text = text.replace('dbc = "../../../shared/data/rav4-highway/toyota_rav4.dbc"',
                        f'dbc = "{(RAV4_DATA / "toyota_rav4.dbc").resolve()}"')
    cfgp = tmp / "rav4" / "monitor.toml"
    if not cfgp.exists():
        cfgp.parent.mkdir(parents=True, exist_ok=True)
        cfgp.write_text(text)
        t0 = time.perf_counter()
        run_design(load_config(cfgp))
        out["design_seconds"] = round(time.perf_counter() - t0, 2)
    cdir = tmp / f"rav4-c-{stop_after or 'all'}"
    t0 = time.perf_counter()
    try:
        gen = generate(cfgp, cdir, name="fdk_m", stop_after=stop_after)
    except DataError as exc:
        return {**out, "refused": str(exc)}
    out["generation_seconds_cold"] = round(time.perf_counter() - t0, 4)
    t0 = time.perf_counter()
    gen = generate(cfgp, cdir, name="fdk_m", stop_after=stop_after)
    out["generation_seconds"] = round(time.perf_counter() - t0, 4)   # config, artifacts, tables, C
    out["emission_seconds"] = round(gen["seconds"], 4)                # the C of both variants
    out["stages"] = gen["layout"]["stages"]
    out["code_source_bytes"] = gen["code_bytes"]
    mon = gen["monitor"]
    from fdikit.systems.car.monitor_rav4 import inject, load_rav4_raw, parse_inject

    sig = inject(load_rav4_raw(RAV4_DATA), parse_inject(RAV4_FAULTS), mon.generators[0].pre)
    out["log"] = f"real minute, inject {RAV4_FAULTS}"
    x = sig.values[0][:, sig.index(gen["layout"]["inputs"])]
    return _time_monitor(out, mon, cdir, sig.t, x, repeat)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=20, help="passes of the C loop over the log")
    ap.add_argument("--examples", nargs="*",
                    default=["two-mass", "own-system", "synthetic-mhsspt", "abs", "abs:monitor_extended.toml",
                             "uav", "passenger-car", "rav4-lateral", "rav4-lateral-peer", "aircraft-smo"])
    ap.add_argument("--quick-design", action="store_true",
                    help="design the ABS monitors from fewer Monte Carlo runs (QUICK_DESIGN)")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for ex in args.examples:
            if ex == "synthetic-mhsspt":
                r = synthetic_mhsspt(Path(d), args.repeat)
            elif ex in ("rav4-lateral", "rav4-lateral-peer"):
                r = rav4(Path(d), args.repeat, None if ex == "rav4-lateral" else "peer_check")
            else:
                r = bench(ex, Path(d), args.repeat, args.quick_design)
            rows.append(r)
            if "refused" in r or "c" not in r:
                print(f"{ex:14s} not generated: {r.get('refused', r.get('note'))}")
                continue
            c64, c32 = r["c"]["double"], r["c"]["float"]
            print(f"{ex:14s} C {c64['ns_per_sample']:8.1f} ns/sample (CPU {c64['cpu_ns_per_sample']:.1f}; "
                  f"float32 {c32['ns_per_sample']:.1f}, CPU {c32['cpu_ns_per_sample']:.1f}), "
                  f"Python stream {r['python_stream_ns_per_sample']:9.1f} ns/sample "
                  f"(CPU {r['python_stream_cpu_ns_per_sample']:.1f}; {r['speedup_double']}x, "
                  f"CPU {r['speedup_double_cpu']}x); "
                  f"state {c64['state_bytes']} B (float32 {c32['state_bytes']} B), code {c64['code_bytes']} "
                  "B; "
                  f"generation {r['generation_seconds']} s; {r['events']} events, "
                  f"equal {c64['events_equal']} "
                  f"(float32 {c32['events_equal']}), bitwise {c64['bitwise_equal']}, "
                  f"float32 error {c32['max_error_rel_to_channel_scale']:.2e}")
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    print(f"load average {load}")
    print(json.dumps({"benchmark": "codegen", "load_average": load, "monitors": rows}, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
