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
    from fdikit.residuals.smo import simulate_plant
    from fdikit.systems import aircraft
    from fdikit.systems.aircraft.reconstruction import X0

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


def _abs_csv(path, fault, magnitude, seed):
    from fdikit.systems.abs.plant import Scenario, simulate

    res = simulate(None, Scenario(fault, magnitude=magnitude), runs=1, seed=seed)
    df = pd.DataFrame({"time": res.u.t, "P_m": 10.0 * res.u["P_m"][0], "u_in": res.u["u_in"][0],
                       "u_out": res.u["u_out"][0], "omega_w": res.y["omega_w"][0],
                       "omega_v": res.y["omega_v"][0]})
    df.to_csv(path, index=False)
    return res


def test_abs_config_detects_rw_fault_and_stays_quiet_on_nominal(tmp_path):
    """examples/abs: the paper's five tests designed from nominal Monte Carlo (fdikit design), then
    run over CSV logs: an R_w fault of -25 % (class F2.2) fires G_P1 (paper: Pd 0.979) and is
    announced once, as the diagnosis F2.2; nominal records announce nothing, the alarms equal
    TestBank.alarms of the same designs, and a checkpoint mid-record continues identically in a
    fresh monitor."""
    from fdikit.detect import TestBank
    from fdikit.monitor import load_artifact
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
    from fdikit.systems.abs.campaign import abs_residuals, paper_tests

    shutil.copy(EXAMPLES / "abs" / "monitor.toml", tmp_path / "monitor.toml")
    out = cli("design", tmp_path / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    _abs_csv(tmp_path / "rw.csv", "F2.2", -0.25, seed=11)
    for k in range(3):
        _abs_csv(tmp_path / f"nom{k}.csv", "F0", None, seed=100 + k)
    out = cli("monitor", tmp_path / "rw.csv", "--config", tmp_path / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    # the monitor announces its diagnosis once (issue 16), not the test firings (G_P1 among them)
    assert [e["hypothesis"] for e in s["events"]] == ["F2.2"], s
    assert s["max_statistics"]["r1:glrt:alarm"] == 1.0, s
    for k in range(3):
        out = cli("monitor", tmp_path / f"nom{k}.csv", "--config", tmp_path / "monitor.toml", "--json")
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["n_events"] == 0, out.stdout
    # the config-built monitor fires exactly the tests the campaign's TestBank fires
    cfg = load_config(tmp_path / "monitor.toml")
    sig = map_channels(cfg, read_log(cfg, tmp_path / "rw.csv"))
    d = cfg.artifacts
    glrt = {r: load_artifact(d / f"glrt_{r}") for r in ("r1", "r3", "r4")}
    holds = {r: load_artifact(d / f"hold_{r}") for r in ("r1", "r3", "r4")}
    bank = TestBank(paper_tests(), {r: float(g.mu0[0]) for r, g in glrt.items()},
                    {r: float(g.sigma2[0]) for r, g in glrt.items()},
                    {t.name: float(holds[t.residual].threshold[0]) for t in paper_tests()})
    fired, _ = bank.alarms(abs_residuals(sig))
    res = build_monitor(cfg).run(sig)
    chans = ["r1:glrt:alarm", "r3:glrt:alarm", "r4:glrt:alarm", "r3:glrt:alarm:gated", "r4:glrt:alarm:gated"]
    mine = (res.statistics.values[0][:, res.statistics.index(chans)] > 0.5).any(axis=0)
    assert mine.tolist() == fired[0].tolist()
    # checkpoint in the middle, restore into a freshly built monitor, continue
    full = build_monitor(cfg).stream(sig)
    mon = build_monitor(cfg)
    mon.reset(1)
    cut = sig.n_samples // 2
    for k in range(cut):
        mon.step(float(sig.t[k]), sig.values[:, k], sig.names)
    mon.save_checkpoint(tmp_path / "ck.npz")
    other = build_monitor(cfg)
    other.load_checkpoint(tmp_path / "ck.npz")
    S = np.stack([other.step(float(sig.t[k]), sig.values[:, k], sig.names)[1]
                  for k in range(cut, sig.n_samples)], 1)
    np.testing.assert_allclose(S, full.statistics.values[:, cut:], rtol=0, atol=1e-12)


def test_abs_extended_config_detects_small_iw_fault(tmp_path):
    """examples/abs/monitor_extended.toml: the directional GLRTs designed by the recipe and run over CSV
    logs through fdikit monitor: an I_w fault of -3 % (class F4) fires G_D_Iw and no change-in-mean
    test, and is announced once as F4 with its estimated size; nominal records announce nothing;
    the config-built monitor fires what TestBank.alarms fires with the same designs."""
    from fdikit.detect import TestBank
    from fdikit.monitor import load_artifact
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
    from fdikit.systems.abs.campaign import abs_residuals, extended_tests

    shutil.copy(EXAMPLES / "abs" / "monitor_extended.toml", tmp_path / "monitor.toml")
    out = cli("design", tmp_path / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    _abs_csv(tmp_path / "iw.csv", "F4", -0.03, seed=12)
    for k in range(3):
        _abs_csv(tmp_path / f"nom{k}.csv", "F0", None, seed=200 + k)
    out = cli("monitor", tmp_path / "iw.csv", "--config", tmp_path / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    # one diagnosis (issue 16): F4, with the size G_D_Iw estimates (the relative I_w change)
    assert [e["hypothesis"] for e in s["events"]] == ["F4"], s["events"]
    assert abs(s["events"][0]["size"] - (-0.03)) < 0.01, s["events"]
    ms = s["max_statistics"]
    assert ms["G_D_Iw:dglrt:alarm"] == 1.0
    assert all(ms[c] == 0.0 for c in ("r1:glrt:alarm", "r3:glrt:alarm", "r4:glrt:alarm")), ms
    for k in range(3):
        out = cli("monitor", tmp_path / f"nom{k}.csv", "--config", tmp_path / "monitor.toml", "--json")
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["n_events"] == 0, out.stdout
    cfg = load_config(tmp_path / "monitor.toml")
    sig = map_channels(cfg, read_log(cfg, tmp_path / "iw.csv"))
    d = cfg.artifacts
    specs = extended_tests()
    glrt = {r: load_artifact(d / f"glrt_{r}") for r in ("r1", "r3", "r4")}
    dgl = {s.name: load_artifact(d / f"dglrt_{s.name}") for s in specs if s.signature}
    mu0 = {r: float(g.mu0[0]) for r, g in glrt.items()}
    s2 = {r: float(g.sigma2[0]) for r, g in glrt.items()}
    assert dgl["G_D_Iw"].mu0.tolist() == [mu0["r3"], mu0["r4"]]
    thr = {s.name: float(load_artifact(d / f"hold_{s.name if s.signature else s.residual}").threshold[0])
           for s in specs}
    bank = TestBank(specs, mu0, s2, thr)
    gens = (load_artifact(d / "r1"), load_artifact(d / "observer"))
    fired, _ = bank.alarms(abs_residuals(sig, gens))
    res = build_monitor(cfg).run(sig)
    chans = ["r1:glrt:alarm", "r3:glrt:alarm", "r4:glrt:alarm", "r3:glrt:alarm:gated", "r4:glrt:alarm:gated",
             "G_D_Iw:dglrt:alarm", "G_D_Kf:dglrt:alarm", "G_D_Rw:dglrt:alarm"]
    mine = (res.statistics.values[0][:, res.statistics.index(chans)] > 0.5).any(axis=0)
    assert mine.tolist() == fired[0].tolist()
