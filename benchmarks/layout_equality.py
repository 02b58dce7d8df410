"""Record the numbers the layout refactor (issue 14) must keep, and compare two recordings.

Runs, through the command line (so it works on any package layout): the demo's ``--json``, the
aircraft reconstruction (gamma-bar and the rmse ratios), a small ABS campaign at a fixed seed
(D-matrix, sensitivity, specificity; paper and extended tests), every passenger-car scenario
(delays), the RAV4 monitor on the real minute (announcements), ``car linearize`` / ``car fit``,
and the SVM / estimation benchmark (quick). Timing fields are dropped before comparing.

Usage::

    python benchmarks/layout_equality.py record DIR     # one JSON file per command in DIR
    python benchmarks/layout_equality.py compare A B    # equal numbers? last line is JSON
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

RAV4 = "../shared/data/rav4-highway"
SCENARIOS = ["accel_bias_0.4", "accel_bias_0.6", "accel_bias_0.8", "accel_bias_0.6_fast", "brake_actuator",
             "brake_actuator_short", "steering_actuator", "intermittent_front_wheel"]


def commands() -> dict[str, list[str]]:
    fd = [sys.executable, "-m", "fdikit.cli"]
    cmds = {
        "demo": [*fd, "demo", "--json"],
        "reconstruct": [*fd, "reconstruct", "aircraft", "--json"],
        "abs_campaign": [*fd, "abs", "campaign", "--runs", "40", "--seed", "3", "--json", "--no-progress"],
        "abs_campaign_ext": [*fd, "abs", "campaign", "--runs", "30", "--seed", "4", "--tests", "extended",
                             "--json", "--no-progress"],
        "car_linearize": [*fd, "car", "linearize", "--json"],
        "svm_estimation": [sys.executable, "benchmarks/bench_svm_estimation.py", "--quick"],
    }
    for s in SCENARIOS:
        cmds[f"car_scenario_{s}"] = [*fd, "car", "scenario", s, "--json"]
    if Path(RAV4).exists():
        cmds["car_fit"] = [*fd, "car", "fit", RAV4, "--json"]
        cmds["rav4_monitor"] = [*fd, "car", "monitor-log", RAV4, "--json"]
        cmds["rav4_inject"] = [*fd, "car", "monitor-log", RAV4, "--inject", "yaw_rate:0.03@40", "--json"]
    return cmds


#: Keys that hold wall-clock times (they differ from run to run); nothing else is dropped.
TIMING = {"seconds", "wall_seconds", "design_seconds", "lmi_seconds", "fit_seconds", "sim_seconds_two_runs",
          "calibration_s", "fit_s", "predict_s", "train_and_predict_s", "grid_search_s", "block_s",
          "subset_s"}


def _is_timing(key: str) -> bool:
    return key in TIMING


def strip(obj):
    if isinstance(obj, dict):
        return {k: strip(v) for k, v in obj.items() if not _is_timing(k)}
    if isinstance(obj, list):
        return [strip(v) for v in obj]
    return obj


def diff(a, b, path="") -> list[str]:
    out: list[str] = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in {'B' if k not in a else 'A'}")
            else:
                out += diff(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: length {len(a)} != {len(b)}")
        else:
            for i, (x, y) in enumerate(zip(a, b)):
                out += diff(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        pass
    elif a != b:
        out.append(f"{path}: {a!r} != {b!r}")
    return out


def record(dest: Path) -> None:
    dest.mkdir(parents=True, exist_ok=True)
    for name, cmd in commands().items():
        p = subprocess.run(cmd, capture_output=True, text=True)
        lines = [ln for ln in p.stdout.strip().splitlines() if ln.strip()]
        try:
            obj = json.loads(lines[-1]) if lines else None
        except json.JSONDecodeError:
            obj = None
        if obj is None or p.returncode != 0:
            obj = {"error": f"exit {p.returncode}", "stderr": p.stderr[-2000:]}
        (dest / f"{name}.json").write_text(json.dumps(obj, indent=1, sort_keys=True))
        print(f"{name}: exit {p.returncode}", flush=True)


def compare(a: Path, b: Path) -> None:
    report = {}
    for fa in sorted(a.glob("*.json")):
        fb = b / fa.name
        if not fb.exists():
            report[fa.stem] = ["missing in B"]
            continue
        d = diff(strip(json.loads(fa.read_text())), strip(json.loads(fb.read_text())))
        report[fa.stem] = d
        print(f"{fa.stem}: {'equal' if not d else f'{len(d)} differences'}")
        for line in d[:20]:
            print("   ", line)
    print(json.dumps({"equal": all(not d for d in report.values()), "compared": len(report),
                      "differences": {k: len(v) for k, v in report.items() if v}}))


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "record":
        record(Path(sys.argv[2]))
    elif len(sys.argv) >= 4 and sys.argv[1] == "compare":
        compare(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        sys.exit(__doc__)
