"""Identified plants in a monitor config: channel offsets from the identification
(``offset = "identified"``), identify's ``rate`` key, and ``[design.noise] process`` alone
(issue 28 item 6)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError
from fdikit.estimate import Identification
from fdikit.model import LinearFaultModel
from fdikit.monitor.config import build_monitor, identified_offsets, load_config, map_channels, map_sample
from fdikit.monitor.declarative import identification_from_config, noise_from_config

IDENT = 'identify = { logs = ["a.csv"], inputs = ["u"], outputs = ["y"] }'


def _config(tmp_path, offset='"identified"', plant=IDENT):
    p = tmp_path / "m.toml"
    p.write_text(f'[channels.u]\noffset = {offset}\n[channels.y]\nscale = 2.0\noffset = {offset}\n'
                 f'[design.plant]\n{plant}\n[design.faults]\nnames = ["sensor:y"]\n')
    return p


def _report(tmp_path, u=0.5, y=20.0):
    (tmp_path / "designs").mkdir(exist_ok=True)
    (tmp_path / "designs" / "design_report.json").write_text(json.dumps(
        {"identification": {"u_offset": {"u": u}, "y_offset": {"y": y}}}))


def test_identified_offsets_come_from_the_design_report(tmp_path):
    cfg = load_config(_config(tmp_path))
    assert all(np.isnan(c.offset) for c in cfg.channels)        # unknown until the design ran
    with pytest.raises(DataError, match=r"does not exist: run 'fdikit design"):
        identified_offsets(cfg)
    _report(tmp_path)
    sig = Signals(np.arange(3) * 0.1, np.array([[[1.0, 30.0], [2.0, 31.0], [0.5, 29.0]]]), ["u", "y"])
    out = map_channels(cfg, sig)
    np.testing.assert_allclose(out.values[0], [[0.5, 40.0], [1.5, 42.0], [0.0, 38.0]])   # 2 * y - 20
    assert identified_offsets(cfg) == {"u": 0.5, "y": 20.0}
    assert map_sample(load_config(tmp_path / "m.toml"), {"u": 1.0, "y": 30.0}) == {"u": 0.5, "y": 40.0}


def test_identified_offset_errors_name_the_channel(tmp_path):
    with pytest.raises(DataError, match=r"channels.u\]\.offset must be a number or \"identified\""):
        load_config(_config(tmp_path, offset='"mean"'))
    with pytest.raises(DataError, match=r"offset = \"identified\" needs an identified plant"):
        load_config(_config(tmp_path, plant='A = [[-1.0]]\nB = [[1.0]]\nC = [[1.0]]'))
    (tmp_path / "designs").mkdir()
    (tmp_path / "designs" / "design_report.json").write_text(json.dumps(
        {"identification": {"u_offset": {"u": 0.5}, "y_offset": {"z": 1.0}}}))
    with pytest.raises(DataError, match=r"no offset for 'y' \(it has \['u', 'z'\]\)"):
        identified_offsets(load_config(_config(tmp_path)))


def test_build_monitor_resolves_identified_offsets(tmp_path, monkeypatch):
    import fdikit.monitor.config as config

    cfg = load_config(_config(tmp_path))
    _report(tmp_path, u=-1.0, y=3.0)
    monkeypatch.setattr(config, "_check_fresh", lambda cfg, names: None)
    monkeypatch.setattr(config, "load_artifact", lambda path: (_ for _ in ()).throw(RuntimeError("loaded")))
    with pytest.raises(RuntimeError, match="loaded"):
        build_monitor(cfg)
    assert [c.offset for c in cfg.channels] == [-1.0, 3.0]      # resolved before the artifacts load


def test_identify_rate_grids_a_jittered_log(tmp_path):
    rng = np.random.default_rng(0)
    n = 3000
    t = np.arange(n) * 0.02 + rng.uniform(0, 4e-4, n)           # jittered time stamps
    u = rng.normal(size=n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 0.2 * u[k - 1]
    for name in ("a.csv", "b.csv"):
        np.savetxt(tmp_path / name, np.c_[t, u, y + 0.01 * rng.normal(size=n)], delimiter=",",
                   header="t,u,y", comments="")
    spec = {"logs": ["a.csv", "b.csv"], "inputs": ["u"], "outputs": ["y"], "order": 1, "rate": 50.0}
    ident = identification_from_config(spec, tmp_path)
    assert ident.model.dt == pytest.approx(0.02, rel=1e-12)
    with pytest.raises(DataError, match=r"identify\]\.rate must be a positive number"):
        identification_from_config({**spec, "rate": -1.0}, tmp_path)


def test_process_noise_alone_keeps_the_identified_measurement_noise():
    m = LinearFaultModel(np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0], [2.0]]), dt=0.1,
                         inputs=["u"], outputs=["y1", "y2"])
    ident = Identification(m, {}, Q=np.array([[0.3]]), R=np.diag([0.04, 0.09]))
    default = noise_from_config({}, m, identification=ident)
    assert default["measurement"] == {"y1": 0.04, "y2": 0.09} and default["process"].tolist() == [0.3]
    given = noise_from_config({"noise": {"process": 1e-5}}, m, identification=ident)
    assert given["measurement"] == {"y1": 0.04, "y2": 0.09} and given["process"].tolist() == [1e-5]
    with pytest.raises(DataError, match="needs measurement"):            # no identification: as before
        noise_from_config({"noise": {"process": 1e-5}}, m)


def _ar2_logs(tmp_path, names, seed):
    """Nominal CSV logs of a second-order plant with an operating point (u about 2, y about 10)."""
    rng = np.random.default_rng(seed)
    for name in names:
        n = 4000
        u = 2.0 + np.repeat(rng.normal(size=n // 20), 20)
        x = np.zeros(n)
        for k in range(2, n):
            x[k] = 1.5 * x[k - 1] - 0.7 * x[k - 2] + 0.5 * (u[k - 1] - 2.0) + 0.05 * rng.normal()
        y = 10.0 + x + 0.05 * rng.normal(size=n)
        np.savetxt(tmp_path / name, np.c_[np.arange(n) * 0.1, u, y], delimiter=",", header="t,u,y",
                   comments="")


def test_identified_plant_whitens_and_thresholds_on_its_nominal_logs(tmp_path):
    """A first-order model of a second-order plant: noise simulated from the model is far smaller
    than the model's error on real data (whitened on it, the held-out spread is 2.1); the residual
    is whitened on the nominal logs instead, so that on a held-out nominal log it has about unit
    spread."""
    import warnings

    from fdikit import Signals
    from fdikit.io import read_log
    from fdikit.monitor.declarative import design_monitor
    from fdikit.residuals import FaultDetectionFilter

    _ar2_logs(tmp_path, ["a.csv", "b.csv", "held.csv"], seed=1)
    design = {"sample_time": 0.1,
              "plant": {"identify": {"logs": ["a.csv", "b.csv"], "inputs": ["u"], "outputs": ["y"],
                                     "order": 1}},
              "faults": {"names": ["actuator:u"]}, "noise": {"process": 1e-7},
              "alarm": {"pfa": 1.0, "per": "hour", "hold": 5}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = design_monitor(design, tmp_path)
    rep = d["_report"]
    assert rep["threshold_source"] == "the identification's nominal logs", rep["threshold_source"]
    assert rep["nominal_records"] == 2 and rep["rates"] == "measured on held-out nominal logs"
    off = {**rep["identification"]["u_offset"], **rep["identification"]["y_offset"]}
    log = read_log(tmp_path / "held.csv")
    v = log.values[:, :, log.index(["u", "y"])] - np.array([off["u"], off["y"]])
    r = FaultDetectionFilter(d["bank"]).run(Signals(log.t, v, ["u", "y"]))
    spread = float(np.std(r.values[0, 100:]))
    assert 0.7 < spread < 1.4, spread          # whitened on the simulated noise: 2.1
