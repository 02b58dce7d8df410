"""Benchmark: load and decode the real 53,800-frame RAV4 BLF log (target <= 2 s).

Prints the timings, then one JSON object as the last line.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import can

from fdikit.io import read_can_log

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "rav4-highway"
SIGNALS = [
    "KINEMATICS.YAW_RATE", "KINEMATICS.ACCEL_X", "KINEMATICS.ACCEL_Y",
    "WHEEL_SPEEDS.WHEEL_SPEED_FL", "WHEEL_SPEEDS.WHEEL_SPEED_FR",
    "WHEEL_SPEEDS.WHEEL_SPEED_RL", "WHEEL_SPEEDS.WHEEL_SPEED_RR",
    "STEER_ANGLE_SENSOR.STEER_ANGLE", "STEER_ANGLE_SENSOR.STEER_RATE",
    "BRAKE_MODULE.BRAKE_PRESSURE", "ENGINE_RPM.RPM", "GAS_PEDAL.GAS_PEDAL", "SPEED.SPEED",
]


def main(repeats: int = 5) -> dict:
    blf, dbc = DATA / "drive.blf", DATA / "toyota_rav4.dbc"
    if not blf.exists():
        out = {"benchmark": "can_load", "skipped": f"no data at {DATA}"}
        print(json.dumps(out))
        return out
    t0 = time.perf_counter()
    n_frames = sum(1 for _ in can.LogReader(str(blf)))
    t_read = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        s = read_can_log(blf, dbc, SIGNALS, rate=100.0, units="si")
        times.append(time.perf_counter() - t0)
    best, worst = min(times), max(times)
    print(f"frames in log          : {n_frames}")
    print(f"python-can read only   : {t_read:.3f} s")
    print(f"read + decode {len(SIGNALS)} signals + resample to 100 Hz: "
          f"best {best:.3f} s, worst {worst:.3f} s "
          f"(target <= 2 s)")
    print(f"grid                   : {s.n_samples} samples x {s.n_channels} channels, "
          f"{int((~s.valid).sum())} invalid")
    out = {"benchmark": "can_load", "frames": n_frames, "signals": len(SIGNALS), "grid_samples": s.n_samples,
           "read_only_s": round(t_read, 4), "load_decode_best_s": round(best, 4),
           "load_decode_worst_s": round(worst, 4), "target_s": 2.0, "meets_target": bool(worst <= 2.0)}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
