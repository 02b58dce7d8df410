"""The shipped example configs run end to end: design, a recorded log, monitor."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def cli(*args):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


def test_aircraft_smo_config_reconstructs_the_rudder_fault(tmp_path):
    from fdikit.commands.reconstruct import X0
    from fdikit.plants import aircraft
    from fdikit.residuals.smo import simulate_plant

    shutil.copy(EXAMPLES / "aircraft-smo" / "monitor.toml", tmp_path / "monitor.toml")
    out = cli("design", tmp_path / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    h = 1e-4
    t = np.arange(0.0, 8.0, h)
    f = aircraft.fault_signal(t)
    Y = simulate_plant(aircraft.A_NOMINAL, aircraft.M, aircraft.C, f[:, None], h, x0=X0).reshape(t.size, -1)
    df = pd.DataFrame({"t": t, "rudder_cmd": 0.0, "aileron_cmd": 0.0})
    for i, name in enumerate(aircraft.OUTPUTS):
        df[name] = Y[:, i]
    df.to_csv(tmp_path / "log.csv", index=False)
    out = cli("monitor", tmp_path / "log.csv", "--config", tmp_path / "monitor.toml", "--json",
              "--stats", tmp_path / "fhat.parquet")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["samples"] == t.size
    fhat = pd.read_parquet(tmp_path / "fhat.parquet")["fhat:actuator:rudder_cmd"].to_numpy()
    late = t >= 1.0
    ratio = np.sqrt(np.mean((fhat[late] - f[late]) ** 2) / np.mean(f[late] ** 2))
    assert ratio < 0.01, ratio  # nominal plant: the reconstruction is near exact
