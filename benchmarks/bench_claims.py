"""Claims vs measured for every example config and the RAV4 monitor (issue 26, item 9's table).

For each ``examples/*/monitor*.toml``: ``fdikit design`` (artifacts in a temporary folder), then
``fdikit validate`` (:func:`fdikit.evaluate.validate`) on fresh nominal logs the design never saw:
simulated with other seeds than the design's (``fdikit example-log``'s simulators; the DC motor's
``examples/own-system/simulate_logs.py``), and for the RAV4 the held-out second half of the real
minute in ``../shared/data/rav4-highway/`` (its design calibrates on the first half; skipped when
the data are absent). The passenger car and the RAV4 recipes state an announcement-rate claim from
their design data (:func:`fdikit.evaluate.announcement_claim`: the car's nominal drives of its
calibration's kinds, 2 x 10 s; the RAV4's calibration half, 30 s, in-sample), so their intervals
are wide: 0 announcements in 20 s bound the rate by 663 per hour. Measured (this bench): car 0 in
56 s of fresh logs ([0, 237] /h, inside [0, 663]); RAV4 0 in the held-out 30 s ([0, 443] /h,
inside [0, 443]). The aircraft config has no ``[decision]``: it reconstructs faults and decides
nothing, so it claims no rate. Prints per config every claim (threshold, family, announcements): the
claimed rate and interval, the measured rate and interval, the verdict; an announcement row
without a claim is measured all the same. The last line is one JSON object.

Run: ``python benchmarks/bench_claims.py [--only NAME ...]`` from the repository root.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Fresh nominal logs per example (count, simulated seconds or None for the system's default).
LOGS = {"two-mass": (60, None), "abs": (30, None), "abs-extended": (30, None), "aircraft-smo": (2, None),
        "passenger-car": (4, None), "own-system": (20, 300.0)}
SEED0 = 1000     # the designs use seeds 0 and 11: the logs here use 1000, 1001, ...


def _name(path: Path) -> str:
    return path.parent.name + ("" if path.stem == "monitor" else "-" + path.stem.removeprefix("monitor_"))


def _own_system_logs(n: int, seconds: float):
    """``n`` nominal runs of the DC motor in one Signals (the log's source columns), simulated at once."""
    from fdikit import Signals

    spec = importlib.util.spec_from_file_location("own_system_logs",
                                                  ROOT / "examples/own-system/simulate_logs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    t, cols = mod.logs(minutes=seconds / 60.0, seed=SEED0, runs=n)["nominal"]
    return [Signals(t, np.stack(list(cols.values()), axis=2), list(cols), check=False)]


def _example_logs(cfg_path: Path, out: Path, n: int, seconds) -> list[str]:
    from fdikit.demo.example_logs import write_example_logs

    return [write_example_logs(cfg_path, out / f"log{k}", seed=SEED0 + k,
                               duration=seconds)["logs"]["nominal"] for k in range(n)]


def _rav4_held_out(cfg):
    from fdikit import Signals
    from fdikit.monitor.config import read_log
    from fdikit.systems.car.rav4 import default_data_path

    blf = default_data_path() / "drive.blf"
    if not blf.exists():
        return None
    raw = read_log(cfg, blf)
    half = float((raw.t[-1] - raw.t[0]) / 2)
    k = int(np.argmax(raw.t - raw.t[0] > half))
    return [Signals(raw.t[k:], raw.values[:, k:], raw.names, raw.units, check=False)]


def _uav_fresh_flights(cfg, src: Path, out: Path):
    """Fresh nominal flights of the UAV example (seed 1: flights 1000.., the design's are 0..)."""
    from fdikit.monitor.config import read_log

    subprocess.run([sys.executable, str(src / "simulate_flights.py"), str(out), "--seed", "1",
                    "--failures", "0"], check=True, capture_output=True)
    return [read_log(cfg, p) for p in sorted(out.glob("nominal_*.ulg"))]


def run(path: Path, tmp: Path) -> dict:
    from fdikit.evaluate import claims_table, validate
    from fdikit.monitor.config import load_config, run_design

    name = _name(path)
    if name == "uav":   # the design identifies its plant from simulated flights beside the config
        src = tmp / "uav-src"
        shutil.copytree(path.parent, src, ignore=shutil.ignore_patterns("designs*", "flights*"))
        subprocess.run([sys.executable, str(src / "simulate_flights.py"), str(src / "flights")], check=True,
                       capture_output=True)
        path = src / path.name
    cfg = load_config(path)
    cfg.artifacts = tmp / name / "designs"
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_design(cfg)
    design_s = time.perf_counter() - t0
    out = tmp / name / "logs"
    out.mkdir(parents=True)
    t0 = time.perf_counter()
    if name == "rav4-lateral":
        logs = _rav4_held_out(cfg)
        what = "the held-out second half of the real RAV4 minute"
    elif name == "uav":
        logs = _uav_fresh_flights(cfg, path.parent, out)
        what = f"{len(logs)} fresh simulated nominal flights (simulate_flights.py --seed 1)"
    elif name == "own-system":
        n, sec = LOGS[name]
        logs = _own_system_logs(n, sec)
        what = f"{n} simulated nominal runs of {sec:g} s (seed {SEED0})"
    else:
        n, sec = LOGS[name]
        logs = _example_logs(path, out, n, sec)
        what = f"{n} simulated nominal logs (fdikit example-log, seeds {SEED0}...)"
    logs_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = validate(cfg, logs)
    validate_s = time.perf_counter() - t0
    print(f"== {name}: {what}")
    for line in claims_table(res):
        print("  " + line)
    decides = bool(cfg.decision)
    if not decides:
        print("  (no [decision] in this config: it makes no false-alarm decision, so it states no rate; "
              "the announcements are counted all the same)")
    stated = [c for c in res["claims"] if c.get("interval") is not None]
    if stated:
        print(f"  measured on {res['hours'] * 3600:.4g} s judged of nominal data the design never saw")
    print(f"  (design {design_s:.1f} s, logs {logs_s:.1f} s, validate {validate_s:.1f} s)")
    return {"logs": what, "hours": res["hours"], "rates": res["rates"], "contradicted": res["contradicted"],
            "decides": decides,
            "claims": [{"name": c["name"], "per": c["per"], "target": c.get("target"),
                        "claimed": c.get("interval"), "measured": c["measured"]["rate"],
                        "measured_interval": c["measured"]["interval"], "events": c["measured"]["events"],
                        "verdict": c["verdict"]} for c in res["claims"]],
            "design_s": round(design_s, 2), "validate_s": round(validate_s, 2)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="example names (e.g. two-mass own-system rav4-lateral)")
    a = ap.parse_args()
    paths = sorted(ROOT.glob("examples/*/monitor*.toml"))
    if a.only:
        paths = [p for p in paths if _name(p) in a.only]
    tmp = Path(tempfile.mkdtemp(prefix="bench_claims_"))
    results, skipped = {}, {}
    try:
        for p in paths:
            name = _name(p)
            if name == "rav4-lateral":
                from fdikit.systems.car.rav4 import default_data_path

                if not (default_data_path() / "drive.blf").exists():
                    skipped[name] = "RAV4 data not found"
                    print(f"== {name}: skipped (no data at {default_data_path()})")
                    continue
            results[name] = run(p, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    n_claims = sum(sum(c["claimed"] is not None for c in r["claims"]) for r in results.values())
    bad = {k: r["contradicted"] for k, r in results.items() if r["contradicted"]}
    print(json.dumps({"benchmark": "claims", "configs": results, "skipped": skipped, "claims": n_claims,
                      "contradicted": bad}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
