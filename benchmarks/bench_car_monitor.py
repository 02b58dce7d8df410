"""Benchmark: the full passenger-car health monitor of paper 1 (issue 8).

The full monitor is one :class:`~fdikit.monitor.Monitor`: the six filter sets fused into two block
filters (longitudinal, lateral; :func:`~fdikit.residuals.stack_designs`), the two parity
equations, the residual-norm features of both blocks and both MHSSPTs (15 and 11 hypotheses over 8
and 6 features). The densities are calibrated on synthetic features of the right shapes (the cost
does not depend on their values), so the benchmark needs no simulation of the car.

Measured, for the stage-by-stage ``Monitor`` and for the compiled
:class:`~fdikit.plants.passenger_car.monitor_fused.FusedCarMonitor` (same computation in one
kernel per sample, tabulated densities): streaming cost per sample (one run), batch throughput
(many runs; run-samples per second) and the MHSSPT bank alone (both tests, batch over runs:
stream-samples per second; the exact compiled densities of :class:`~fdikit.detect.MHSSPT`).
Targets (issue 8): streaming <= 20 us per sample, batch >= 1e6 samples/s, MHSSPT bank >= 3e6
stream-samples/s. The last line is one JSON object.

Run: ``python benchmarks/bench_car_monitor.py``
"""

from __future__ import annotations

import json
import time

import numpy as np

from fdikit import Signals
from fdikit.detect.mhsspt import calibrate_densities
from fdikit.monitor import Monitor
from fdikit.plants.passenger_car.monitor import (
    LATERAL_FAULTS,
    LONGITUDINAL_FAULTS,
    _generators,
    build_monitor,
    design_car_monitor,
)
from fdikit.plants.passenger_car.monitor_fused import FusedCarMonitor


def _calibration(n_features: int, faults, seed: int, no_fault: str):
    rng = np.random.default_rng(seed)
    nominal = np.abs(rng.normal(0.2, 0.05, (300, n_features)))
    by = {}
    for j, f in enumerate(faults):
        by[f] = {m: nominal[:60] + m * np.eye(n_features)[j % n_features] for m in (1.0, 2.0, 3.0, 4.0)}
    return calibrate_densities(nominal, by, no_fault=no_fault)


def main() -> dict:
    des = design_car_monitor(20.0)
    mons = {}
    for block, faults in (("longitudinal", LONGITUDINAL_FAULTS), ("lateral", LATERAL_FAULTS)):
        _g, groups = _generators(des, block)
        cal = _calibration(len(groups), list(faults), 1, f"none:{block}")
        mons[block] = build_monitor(des, block, cal, warmup=0.0)
    lon, lat = mons["longitudinal"].monitor, mons["lateral"].monitor
    full = Monitor(lon.generators + lat.generators, lon.processors + lat.processors)
    names = full.input_names
    level = {**des.u0, **des.y0}
    rng = np.random.default_rng(0)

    def signals(runs, T):
        base = np.array([level.get(n, 0.0) for n in names])
        v = base + 0.01 * rng.standard_normal((runs, T, len(names)))
        return Signals(np.arange(T) * des.dt, v, names)

    # ---- streaming, one run
    T = 3000
    sig = signals(1, T)
    full.stream(signals(1, 50))  # compile
    full.reset(1)
    vals = sig.values[:, :, :]
    t0 = time.perf_counter()
    for k in range(T):
        full.step(float(sig.t[k]), vals[:, k], names)
    stream_us = (time.perf_counter() - t0) / T * 1e6
    # ---- batch
    runs, Tb = 200, 3000
    sb = signals(runs, Tb)
    full.run(signals(2, 50))
    t0 = time.perf_counter()
    res = full.run(sb)
    batch_s = time.perf_counter() - t0
    batch_rate = runs * Tb / batch_s
    # ---- MHSSPT bank alone (both tests), on the features of the batch run
    pool = res.residuals
    feats = []
    # processors: [lon features, lon test, lon hold, lat features, lat test, lat hold]
    for p in (full.processors[0], full.processors[3]):
        feats.append(p.run(pool))
    fl, fa = feats
    tests = [full.processors[1], full.processors[4]]
    t0 = time.perf_counter()
    tests[0].run(fl)
    tests[1].run(fa)
    bank_s = time.perf_counter() - t0
    bank_rate = runs * Tb / bank_s
    # ---- fused runtime
    fused = FusedCarMonitor([mons["longitudinal"], mons["lateral"]])
    vf = sig.values[:, :, sig.index(fused.input_names)]
    fused.reset(1)
    fused.step(vf[:, 0])
    fused.reset(1)
    t0 = time.perf_counter()
    for k in range(T):
        fused.step(vf[:, k])
    fused_us = (time.perf_counter() - t0) / T * 1e6
    t0 = time.perf_counter()
    fused.run(sb)
    fused_rate = runs * Tb / (time.perf_counter() - t0)
    out = {
        "stream_us_per_sample": round(stream_us, 2), "target_stream_us": 20.0,
        "fused_stream_us_per_sample": round(fused_us, 2), "fused_batch_samples_per_s": round(fused_rate),
        "fused_table_error_nats": fused.table_error, "fused_table_mb": round(fused.table_bytes / 1e6, 1),
        "batch_samples_per_s": round(batch_rate), "target_batch": 1e6,
        "mhsspt_bank_stream_samples_per_s": round(bank_rate), "target_mhsspt_bank": 3e6,
        "hypotheses": [len(t.hypotheses) for t in tests], "features": [len(t.input_names) for t in tests],
        "filter_states": [g.design.order for g in full.generators if hasattr(g, "design")],
        "residuals": len(full.residual_names), "batch_runs": runs, "batch_samples": Tb,
    }
    print(f"Monitor (stage by stage) streaming: {stream_us:.1f} us/sample (target <= 20)")
    print(f"Monitor batch: {batch_rate:.3g} run-samples/s (target >= 1e6)")
    print(f"FusedCarMonitor streaming: {fused_us:.1f} us/sample; batch {fused_rate:.3g} run-samples/s "
          f"(table error {fused.table_error:.2g} nats, {out['fused_table_mb']} MB)")
    print(f"MHSSPT bank ({out['hypotheses']} hypotheses x {out['features']} features): "
          f"{bank_rate:.3g} stream-samples/s (target >= 3e6)")
    return out


if __name__ == "__main__":
    print(json.dumps(main()))
