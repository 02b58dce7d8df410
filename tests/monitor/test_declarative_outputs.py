"""A declarative design on a plant with two outputs runs in the monitor (issue 28, item 5).

Each bank residual of such a plant has one channel; its feature (norm) took the residual's own
channel name, and the monitor refused the design ("statistic channel names collide").
"""

from __future__ import annotations

import numpy as np

from fdikit.faults import Bias, Noise, Scenario
from fdikit.monitor.config import build_monitor, load_config, map_channels, run_design
from fdikit.monitor.declarative import plant_from_config
from fdikit.sim import simulate

TOML = """
[monitor]
artifacts = "designs"
on_invalid = "hold"
[log]
format = "csv"
time = "t"
[channels.V]
unit = "V"
[channels.i_meas]
unit = "A"
[channels.w_meas]
unit = "rad/s"
[design]
sample_time = 0.01
[design.plant]
A = [[-2.0, -1.0], [10.0, -4.0]]
B = [[2.0], [0.0]]
C = [[1.0, 0.0], [0.0, 1.0]]
states = ["i", "w"]
inputs = ["V"]
outputs = ["i_meas", "w_meas"]
[design.faults]
names = ["sensor:i_meas", "sensor:w_meas"]
[design.noise]
measurement = { i_meas = 1e-4, w_meas = 4e-4 }
process = 1e-6
[design.alarm]
pfa = 1e-3
per = "sample"
hold = 5
"""


def test_a_two_output_declarative_design_runs_and_isolates(tmp_path):
    (tmp_path / "monitor.toml").write_text(TOML)
    cfg = load_config(tmp_path / "monitor.toml")
    run_design(cfg)
    mon = build_monitor(cfg)
    names = [n for g in mon.generators for n in g.output_names] + \
        [n for p in mon.processors for n in p.output_names]
    assert len(names) == len(set(names)), names
    model = plant_from_config(cfg.design)
    md = model.discretize(0.01)
    noise = Noise(measurement=np.array([1e-4, 4e-4]), process=np.full(2, 1e-6))
    def u(t):
        return np.array([np.sin(0.5 * t)])
    sc = Scenario(duration=30.0, dt=0.01, noise=noise, inputs=u,
                  faults=[Bias("sensor:w_meas", 0.4, start=15.0)])
    sim = simulate(md, sc, runs=1, seed=1, keep=("y", "u"))
    log = map_channels(cfg, sim.u.concat_channels(sim.y))
    res = mon.run(log)
    onsets = [e for e in res.events if e.kind == "onset"]
    assert onsets, "the bias was not announced"
    assert all(e.t >= 15.0 for e in onsets), [(e.t, e.hypothesis) for e in onsets]
    assert onsets[0].hypothesis == "sensor:w_meas", [(e.t, e.hypothesis) for e in onsets]
