"""Fleet throughput: `fdikit fleet` over >= 200 RAV4 logs on 1 and 2 Dask workers (issue 19 targets).

The logs are generated from the real RAV4 minute (``../shared/data/rav4-highway/drive.blf``) into
a temporary directory (never into the repository): each log drops the first 0-8 s of the minute
(a time shift of the whole drive and of every onset; absolute times moved by hours), and most get
a bias fault injected into the raw CAN payloads from a random onset on (yaw rate, lateral
acceleration, steering angle or a wheel speed; :func:`fdikit.io.decode.set_signal`), written as
BLF (:func:`fdikit.io.decode.write_blf_table`). Vehicles are 10 directories of 20 routes each.

Measured, for a LocalCluster of 1 and of 2 single-threaded worker processes (numba threads 1):
the wall time of the whole fleet after each worker has warmed up on one log (imports, artifacts,
numba caches: a fleet service pays that once), giving

* vehicle-hours of CAN log per core-hour = driving hours / (wall hours x workers)  (target >= 2000);
* scaling efficiency 1 -> 2 workers = (T1 / T2) / 2                               (target >= 80 %);
* the share of the task time spent loading and decoding (read_log: BLF + DBC + grid).

Also, for reference and less sensitive to other work on the machine, the single-process cost of
one RAV4 minute (load + decode, monitor run; median of 5) and of one whole fleet task in this
process (:func:`fdikit.commands.fleet.process_log` on a generated log: load, decode, monitor,
commit; median of 10). The last line printed is one JSON object.

Run: ``python benchmarks/bench_fleet.py [N_LOGS]`` from the repository root.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
TARGET_VH_PER_CORE_H = 2000.0
TARGET_EFFICIENCY = 0.8
#: (message, signal, bias range in the DBC's unit)
FAULTS = [("KINEMATICS", "YAW_RATE", (2.0, 6.0)), ("KINEMATICS", "ACCEL_Y", (0.5, 2.0)),
          ("STEER_ANGLE_SENSOR", "STEER_ANGLE", (6.0, 20.0)), ("WHEEL_SPEEDS", "WHEEL_SPEED_FL", (1.5, 5.0))]


def make_fleet(out: Path, n_logs: int, seed: int = 0) -> list[Path]:
    """Write ``n_logs`` BLF logs derived from the RAV4 minute under ``out/vehNN/routeNNN.blf``."""
    import cantools

    from fdikit.io.decode import decode_message, read_blf_table, set_signal, write_blf_table

    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    db = cantools.database.load_file(str(DATA / "toyota_rav4.dbc"), strict=False)
    rng = np.random.default_rng(seed)
    paths = []
    for i in range(n_logs):
        crop = rng.uniform(0.0, 8.0)
        keep = ts - ts[0] >= crop
        t, fid, p = ts[keep] + 3600.0 * (i + 1), ids[keep], pay.take(keep)
        kind = int(rng.integers(0, len(FAULTS) + 1))
        if kind < len(FAULTS):
            mname, sname, (lo, hi) = FAULTS[kind]
            msg = db.get_message_by_name(mname)
            onset = t[0] + rng.uniform(10.0, 40.0)
            sel = np.flatnonzero((fid == msg.frame_id) & (t >= onset))
            v, _ = decode_message(msg, [sname], p.take(sel))
            bias = rng.uniform(lo, hi) * rng.choice([-1.0, 1.0])
            new = set_signal(msg, sname, p.take(sel), v[:, 0] + bias)
            p.matrix[sel] = new.matrix
        d = out / f"veh{i % 10:02d}"
        d.mkdir(parents=True, exist_ok=True)
        paths.append(write_blf_table(d / f"route{i:03d}.blf", t, fid, p))
    return paths


def _config(tmp: Path) -> Path:
    from fdikit.monitor.config import load_config, run_design

    text = (ROOT / "examples" / "rav4-lateral" / "monitor.toml").read_text()
    text = text.replace('dbc = "../../../shared/data/rav4-highway/toyota_rav4.dbc"',
                        f'dbc = "{(DATA / "toyota_rav4.dbc").resolve()}"')
    cfg = tmp / "monitor.toml"
    cfg.write_text(text)
    run_design(load_config(cfg))
    return cfg


def _run(cfg: Path, logs: Path, out: Path, workers: int, warm: Path) -> dict:
    from fdikit.commands.fleet import WORKER_ENV, plan, process_log, run_fleet
    from fdikit.evaluate.distributed import Engine

    with Engine(workers, dask=True, env=WORKER_ENV) as eng:
        # warm every worker up on one log each (imports, artifacts, DBC, numba caches)
        warm_tasks = plan([str(warm)], cfg, out.parent / f"warm{workers}")
        t0 = time.perf_counter()
        futs = [eng.client.submit(process_log, warm_tasks[0], pure=False, workers=[w])
                for w in eng.client.scheduler_info(n_workers=-1)["workers"]]
        eng.client.gather(futs)
        warm_s = time.perf_counter() - t0
        tasks = plan([str(logs)], cfg, out)
        rep = run_fleet(tasks, eng)
    rep["warmup_s"] = warm_s
    return rep


def main(argv: list[str]) -> int:
    n_logs = int(argv[1]) if len(argv) > 1 else 200
    if not (DATA / "drive.blf").exists():
        print(json.dumps({"benchmark": "fleet", "skipped": f"no data at {DATA}"}))
        return 0
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log

    load0 = os.getloadavg()[0]
    tmp = Path(tempfile.mkdtemp(prefix="bench_fleet_"))
    try:
        t0 = time.perf_counter()
        logs = tmp / "logs"
        paths = make_fleet(logs, n_logs)
        gen_s = time.perf_counter() - t0
        cfg = _config(tmp)
        # one RAV4 minute in this process: load + decode, monitor (median of 5 after a warm-up)
        c = load_config(cfg)
        mon = build_monitor(c)
        mon.run(map_channels(c, read_log(c, DATA / "drive.blf")))
        loads, runs = [], []
        for _ in range(5):
            a = time.perf_counter()
            sig = map_channels(c, read_log(c, DATA / "drive.blf"))
            b = time.perf_counter()
            mon.run(sig)
            runs.append(time.perf_counter() - b)
            loads.append(b - a)
        one_load, one_run = float(np.median(loads)), float(np.median(runs))
        # one whole fleet task in this process (load + decode + monitor + commit), 10 logs
        from fdikit.commands.fleet import plan, process_log

        inproc = plan([str(logs)], cfg, tmp / "inproc")[:11]
        process_log(inproc[0])
        tasks_s = []
        for task in inproc[1:]:
            a = time.perf_counter()
            process_log(task)
            tasks_s.append(time.perf_counter() - a)
        one_task = float(np.median(tasks_s))
        warm = tmp / "warm.blf"
        shutil.copy(paths[0], warm)
        rep = {w: _run(cfg, logs, tmp / f"out{w}", w, warm) for w in (1, 2)}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    vh = rep[1]["vehicle_hours"]
    thr = {w: vh / (r["wall_seconds"] / 3600.0 * w) for w, r in rep.items()}
    eff = (rep[1]["wall_seconds"] / rep[2]["wall_seconds"]) / 2.0
    share = {w: r["load_decode_share"] for w, r in rep.items()}
    print(f"{n_logs} logs generated from the RAV4 minute in {gen_s:.1f} s "
          f"({vh:.3f} vehicle-hours; {rep[1]['episodes']} episodes announced, {rep[1]['errors']} errors)")
    print(f"one RAV4 minute in process: load + decode {one_load * 1e3:.1f} ms, monitor "
          f"{one_run * 1e3:.1f} ms -> {60.0 / (one_load + one_run):.0f} vehicle-hours per core-hour")
    print(f"one fleet task in process (a generated log, load + decode + monitor + commit): "
          f"{one_task * 1e3:.1f} ms -> {60.0 / one_task:.0f} vehicle-hours per core-hour "
          f"(target <= {60.0 / TARGET_VH_PER_CORE_H * 1e3:.0f} ms)")
    print(f"machine load average (1 min) before / after: {load0:.1f} / {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores (other processes share the cores)")
    for w, r in rep.items():
        print(f"{w} worker(s): {r['wall_seconds']:.2f} s wall ({r['warmup_s']:.1f} s warm-up before), "
              f"{thr[w]:.0f} vehicle-hours per core-hour (target >= {TARGET_VH_PER_CORE_H:.0f}), "
              f"load/decode {100 * share[w]:.0f} % of task time")
    print(f"scaling 1 -> 2 workers: efficiency {100 * eff:.0f} % (target >= {100 * TARGET_EFFICIENCY:.0f} %)")
    out = {"benchmark": "fleet", "logs": n_logs, "vehicle_hours": round(vh, 4),
           "episodes": rep[1]["episodes"], "errors": rep[1]["errors"], "generate_s": round(gen_s, 2),
           "one_log_load_decode_ms": round(one_load * 1e3, 2), "one_log_monitor_ms": round(one_run * 1e3, 2),
           "one_log_vh_per_core_h": round(60.0 / (one_load + one_run), 1),
           "one_task_in_process_ms": round(one_task * 1e3, 2),
           "wall_s": {str(w): round(r["wall_seconds"], 3) for w, r in rep.items()},
           "warmup_s": {str(w): round(r["warmup_s"], 2) for w, r in rep.items()},
           "vh_per_core_h": {str(w): round(v, 1) for w, v in thr.items()},
           "scaling_efficiency": round(eff, 4),
           "load_decode_share": {str(w): round(v, 4) for w, v in share.items()},
           "target_vh_per_core_h": TARGET_VH_PER_CORE_H, "target_efficiency": TARGET_EFFICIENCY,
           "meets_throughput": bool(min(thr.values()) >= TARGET_VH_PER_CORE_H),
           "meets_scaling": bool(eff >= TARGET_EFFICIENCY),
           "load_average_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)]}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
