"""Write example logs for examples/own-system/monitor.toml: nominal, and one per fault.

    python examples/own-system/simulate_logs.py OUT_DIR [--minutes 2] [--seed 0]

Each log is a CSV with the columns the config maps (t, V, I, W, T). The plant, its noise and the
sample time are read from the config itself, so the logs always match the design.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np

from fdikit.faults import Bias, Noise, Scenario
from fdikit.monitor.declarative import noise_from_config, plant_from_config, sample_time
from fdikit.sim import simulate

HERE = Path(__file__).resolve().parent
#: Fault sizes of the example logs, in the channel's unit (10 to 30 noise standard deviations: a sensor
#: bias is partly absorbed by the filters, see the design report's signature gains).
FAULTS = {"actuator:V": 0.3, "sensor:i_meas": 0.1, "sensor:w_meas": 0.2, "sensor:temp_meas": 0.3}
COLUMNS = {"V": "V", "i_meas": "I", "w_meas": "W", "temp_meas": "T"}


def logs(minutes: float = 2.0, seed: int = 0, onset: float = 30.0, runs: int = 1):
    """``{name: (t, {column: values (runs, T)})}`` for the nominal log and one log per fault."""
    design = tomllib.loads((HERE / "monitor.toml").read_text())["design"]
    model = plant_from_config(design, HERE)
    noise = noise_from_config(design, model, HERE)
    dt = sample_time(design, model)
    R = [noise["measurement"][y] for y in model.outputs]
    out = {}
    for k, (name, faults) in enumerate([("nominal", [])] + [(f, [Bias(f, m, start=onset)])
                                                           for f, m in FAULTS.items()]):
        sc = Scenario(duration=60.0 * minutes, dt=dt, faults=faults,
                      inputs=lambda t: 2.0 * np.sin(0.3 * t) + 0.5 * np.sin(1.7 * t),
                      noise=Noise(measurement=R, process=noise["process"]))
        res = simulate(model, sc, runs=runs, seed=seed + 101 * k, keep=("y", "u"))
        cols = {"V": res.u.values[:, :, 0]}
        cols.update({COLUMNS[y]: res.y.values[:, :, j] for j, y in enumerate(model.outputs)})
        out[name] = (res.y.t, cols)
    return out


def write(out_dir: str | Path, minutes: float = 2.0, seed: int = 0) -> list[Path]:
    """Write the logs as CSV files into ``out_dir``; returns their paths."""
    import pandas as pd

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, (t, cols) in logs(minutes, seed).items():
        p = out_dir / f"{name.replace(':', '_')}.csv"
        pd.DataFrame({"t": t, **{c: v[0] for c, v in cols.items()}}).to_csv(p, index=False)
        paths.append(p)
    return paths


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="folder for the CSV logs")
    ap.add_argument("--minutes", type=float, default=2.0, help="length of each log, minutes (default 2)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    a = ap.parse_args()
    for p in write(a.out, a.minutes, a.seed):
        print(p)
