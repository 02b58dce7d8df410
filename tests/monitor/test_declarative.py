"""Declarative plant, noise and false-alarm target of a monitor config (issue 15, item 1)."""

from __future__ import annotations

import numpy as np
import pytest

from fdikit import Signals
from fdikit.errors import DataError
from fdikit.monitor.declarative import (
    AlarmTarget,
    alarm_from_config,
    estimate_noise,
    noise_from_config,
    plant_from_config,
)

MOTOR = {"A": [[-10.0, -1.0], [2.0, -0.5]], "B": [[10.0], [0.0]], "C": [[1.0, 0.0], [0.0, 1.0]],
         "states": ["i", "w"], "inputs": ["V"], "outputs": ["i_meas", "w_meas"]}
FAULTS = {"names": ["actuator:V", "sensor:i_meas", "sensor:w_meas"]}


def test_inline_matrices_faults_and_disturbances():
    m = plant_from_config({"plant": MOTOR, "faults": FAULTS, "disturbances": {"load": [0.0, -1.0]}})
    assert m.fault_names == FAULTS["names"]
    assert m.input_names("d") == ["load"]
    np.testing.assert_array_equal(m.B_of("d").ravel(), [0.0, -1.0])
    np.testing.assert_array_equal(m.B_of("f")[:, 0], [10.0, 0.0])   # actuator:V = the column of B
    assert m.dt is None


def test_file_and_discrete(tmp_path):
    np.savez(tmp_path / "p.npz", A=np.eye(2) * 0.9, B=[[1.0], [0.0]], C=np.eye(2), dt=0.01)
    m = plant_from_config({"plant": {"file": "p.npz"}, "faults": {"names": ["sensor:y1"]}}, tmp_path)
    assert m.dt == 0.01 and m.outputs == ["y0", "y1"]


def test_python_control_and_nonlinear_objects(tmp_path):
    (tmp_path / "my_plant_mod_x7.py").write_text(
        "import control\n"
        "import numpy as np\n"
        "from fdikit.model import NonlinearModel\n"
        "sys = control.ss([[-1.0]], [[2.0]], [[1.0]], [[0.0]], inputs=['u'], outputs=['y'], states=['x'])\n"
        "tank = NonlinearModel(lambda t, x, u, p: u - p['k'] * np.sqrt(np.abs(x)),\n"
        "                      lambda t, x, u, p: x, states=['h'], inputs=['q'], outputs=['h_meas'],\n"
        "                      params={'k': 0.5})\n")
    m = plant_from_config({"plant": {"object": "my_plant_mod_x7:sys"}, "faults": {"names": ["sensor:y"]}},
                          tmp_path)
    assert m.inputs == ["u"] and float(m.B_of("u")[0, 0]) == 2.0
    n = plant_from_config({"plant": {"object": "my_plant_mod_x7:tank",
                                     "operating_point": {"x": {"h": 4.0}, "u": {"q": 1.0}}},
                           "faults": {"names": ["sensor:h_meas"]}}, tmp_path)
    # d/dh (-0.5 sqrt(h)) at h = 4: -0.5 / (2 * 2) = -0.125
    assert abs(float(n.A[0, 0]) + 0.125) < 1e-6


@pytest.mark.parametrize("design,match", [
    ({"faults": FAULTS}, r"\[design.plant\] is missing"),
    ({"plant": {**MOTOR, "file": "x.npz"}, "faults": FAULTS}, "exactly one of"),
    ({"plant": {**MOTOR, "B": [[10.0, 0.0]]}, "faults": FAULTS}, "transposed"),
    ({"plant": {**MOTOR, "C": [[1.0, 0.0, 0.0]]}, "faults": FAULTS}, "C must have 2 columns"),
    ({"plant": {**MOTOR, "A": [[1.0, float("nan")], [0.0, 1.0]]}, "faults": FAULTS},
     r"A\[0\]\[1\] is not finite"),
    ({"plant": {**MOTOR, "outputs": ["a"]}, "faults": FAULTS}, "1 names for 2 outputs"),
    ({"plant": {**MOTOR, "colour": "red"}, "faults": FAULTS}, "unknown key 'colour'"),
    ({"plant": MOTOR}, "which faults should the monitor find"),
    ({"plant": MOTOR, "faults": {"names": ["sensor:nope"]}}, "nope"),
    ({"plant": MOTOR, "faults": FAULTS, "disturbances": {"load": [1.0]}}, "must be 2 finite numbers"),
    ({"plant": {**MOTOR, "dt": -1.0}, "faults": FAULTS}, "positive sample time"),
    ({"plant": {"file": "missing.npz"}, "faults": FAULTS}, "does not exist"),
    ({"plant": {"object": "no_such_module_q:x"}, "faults": FAULTS}, "cannot be imported"),
])
def test_bad_plants_are_named(tmp_path, design, match):
    with pytest.raises(DataError, match=match):
        plant_from_config(design, tmp_path)


def test_noise_given_or_estimated_from_a_nominal_log(tmp_path):
    m = plant_from_config({"plant": MOTOR, "faults": FAULTS})
    nz = noise_from_config({"noise": {"measurement": {"i_meas": 1e-4, "w_meas": 4e-4}}}, m)
    assert nz["measurement"] == {"i_meas": 1e-4, "w_meas": 4e-4} and nz["process"].shape == (2,)
    with pytest.raises(DataError, match="missing"):
        noise_from_config({"noise": {"measurement": {"i_meas": 1e-4}}}, m)
    with pytest.raises(DataError, match="> 0"):
        noise_from_config({"noise": {"measurement": 0.0}}, m)
    # a nominal log: smooth signals plus white noise of known std; the estimate recovers it
    rng = np.random.default_rng(3)
    t = np.arange(30000) * 0.01
    y = np.c_[np.sin(0.5 * t) + rng.normal(0, 0.01, t.size),
              3 * np.cos(0.2 * t) + rng.normal(0, 0.03, t.size)]
    import pandas as pd

    pd.DataFrame({"t": t, "i_meas": y[:, 0], "w_meas": y[:, 1]}).to_csv(tmp_path / "nominal.csv", index=False)
    est = noise_from_config({"noise": {"nominal_log": "nominal.csv"}}, m, tmp_path)["measurement"]
    assert abs(est["i_meas"] ** 0.5 / 0.01 - 1) < 0.05 and abs(est["w_meas"] ** 0.5 / 0.03 - 1) < 0.05


def test_estimate_noise_refuses_a_noiseless_channel():
    t = np.arange(1000) * 0.01
    with pytest.raises(DataError, match="no measurement noise visible"):
        estimate_noise(Signals(t, np.round(t)[None, :, None], ["q"]))


def test_alarm_target_semantics():
    a = alarm_from_config({"alarm": {"pfa": 1e-3, "per": "hour", "hold": 5}})
    assert a == AlarmTarget(1e-3, "hour", None, 5)
    dt = 0.01
    # per hour -> per sample: the probability of no alarm over an hour is (1 - p)^(3600 / dt)
    assert (3600 / dt) * np.log1p(-a.per_sample(dt)) == pytest.approx(np.log1p(-1e-3), rel=1e-12)
    assert AlarmTarget(0.01, "sample").per_sample(dt) == pytest.approx(0.01)
    assert AlarmTarget(0.05, "run", 10.0).per_sample(dt) == pytest.approx(1 - 0.95 ** (1 / 1000))
    for bad in ({"pfa": 0.0}, {"pfa": 2.0}, {"per": "day"}, {"per": "run"}, {"hold": 0}):
        with pytest.raises(DataError):
            alarm_from_config({"alarm": {"pfa": 1e-3, **bad}})
