"""Residual banks (issue 15, item 2): exact decoupling and signatures through the internal form, the
design-time sensitivity check (the DC-motor bug), the isolability report."""

import warnings

import numpy as np
import pytest

from fdikit.errors import ConditionError
from fdikit.faults import Bias, Noise, Scenario
from fdikit.model import LinearFaultModel, dc_gain
from fdikit.residuals import FaultDetectionFilter, design_uio, internal_form
from fdikit.residuals.bank import SensitivityWarning, check_sensitivity, design_residual_bank
from fdikit.sim import simulate

DT = 0.01
MEAS_STD = 0.05


def dc_motor():
    """Armature current i (A), speed w (rad/s), voltage V; faults on both sensors and the actuator."""
    R, L, K, J, b = 1.0, 0.5, 0.01, 0.01, 0.1          # the classic small DC motor
    A = [[-R / L, -K / L], [K / J, -b / J]]
    return LinearFaultModel(A, [[1 / L], [0.0]], np.eye(2), states=["i", "w"], inputs=["V"],
                            outputs=["i_meas", "w_meas"],
                            faults=["actuator:V", "sensor:i_meas", "sensor:w_meas"])


NOISE = {"process": [1e-6, 1e-6], "measurement": [MEAS_STD ** 2, MEAS_STD ** 2]}


def test_dc_motor_default_uio_weights_are_useless_and_the_check_says_so():
    # issue 15: "With the default UIO weights, the residual's DC gain was 0.016 for a unit sensor bias; a
    # 2 V actuator fault never alarmed, and nothing warned."  Here: the residual blind to the speed sensor
    # (it reads the current only), designed with design_uio's default Q = R = I.
    m = dc_motor()
    d = design_uio(m, ["actuator:V", "sensor:i_meas"], ["sensor:w_meas"], dt=DT, sensor="output")
    G = dc_gain(internal_form(d, m), "f")
    assert abs(G[0, 1]) < 0.05 and abs(G[0, 0]) < 0.05          # 0.032 for a unit bias and per volt
    with pytest.warns(SensitivityWarning, match=r"'r_i'.*'actuator:V'.*DC gain 0\.03"):
        weak = check_sensitivity(d, m, ["actuator:V", "sensor:i_meas"], noise=NOISE,
                                 fault_sizes={"actuator:V": 2.0}, name="r_i")
    assert {f for _, f, _ in weak} == {"actuator:V", "sensor:i_meas"}
    with pytest.raises(ConditionError, match="residual sensitivity") as exc:
        check_sensitivity(d, m, "actuator:V", noise=NOISE, fault_sizes=2.0, on_weak="raise", name="r_i")
    assert exc.value.details["weak"] == [("r_i", "actuator:V")]


def _shift_in_noise_stds(design, m, fault):
    """Simulated: mean residual shift after a 2 V actuator fault, in residual noise standard deviations."""
    sc = Scenario(duration=6.0, dt=DT, inputs=lambda t: 6.0 + 0 * t, x0=None,
                  faults=[Bias(fault, 2.0, start=3.0)],
                  noise=Noise(process=[1e-6, 1e-6], measurement=[MEAS_STD ** 2] * 2,
                              process_mode="increment"))
    res = simulate(m.discretize(DT), sc, runs=20, seed=3)
    r = FaultDetectionFilter(design).run(res.signals()).values[:, :, 0]
    t = res.t
    before = r[:, (t > 2.0) & (t < 3.0)]
    after = r[:, t > 5.0]
    return abs(after.mean() - before.mean()) / before.std()


def test_dc_motor_bank_sees_the_2V_actuator_fault_the_default_weights_miss():
    m = dc_motor()
    default = design_uio(m, ["actuator:V", "sensor:i_meas"], ["sensor:w_meas"], dt=DT, sensor="output")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SensitivityWarning)
        bank = design_residual_bank(m, DT, noise=NOISE, fault_sizes={"actuator:V": 2.0})
    mine = next(r for r in bank.residuals if r.decoupled == ["sensor:w_meas"]).design
    # independent of the internal form: simulated noisy runs, residual shift in its own noise stds
    assert _shift_in_noise_stds(default, m, "actuator:V") < 2.0          # never alarms (about 1.3)
    assert _shift_in_noise_stds(mine, m, "actuator:V") > 20.0            # the bank's noise-based weights
    i, j = bank.faults.index("actuator:V"), bank.residual_names.index("r[~sensor:w_meas]")
    assert bank.signature.useful[i, j] and bank.signature.snr_dc[i, j] > 20


def test_dc_motor_bank_structure_signature_and_weak_entry_named():
    m = dc_motor()
    with pytest.warns(SensitivityWarning) as rec:
        bank = design_residual_bank(m, DT, noise=NOISE, fault_sizes={"actuator:V": 2.0})
    # two outputs, three faults: no dedicated scheme, the generalised one
    assert bank.info["structure_rule"] == "generalised"
    assert "dedicated scheme" in bank.info["skipped"]
    assert bank.signature.matrix.tolist() == [[0, 1, 1], [1, 0, 1], [1, 1, 0]]
    # the current-sensor bias barely reaches the residual blind to the actuator (it looks like a voltage
    # fault in the current): 2 noise stds, below 3 -> named
    msgs = [str(w.message) for w in rec]
    assert any("'r[~actuator:V]'" in s and "'sensor:i_meas'" in s and "2 noise standard" in s for s in msgs)
    assert [(r, f) for r, f, _ in bank.weak] == [("r[~actuator:V]", "sensor:i_meas")]
    with pytest.raises(ConditionError, match=r"r\[~actuator:V\].*sensor:i_meas"):
        design_residual_bank(m, DT, noise=NOISE, fault_sizes={"actuator:V": 2.0}, on_weak="raise")
    rep = bank.isolability()
    assert rep.detectable == bank.faults
    assert ("actuator:V", "sensor:w_meas") in rep.isolable
    # the weak entry is the only one separating V from the current sensor besides r[~sensor:i_meas]
    assert ("actuator:V", "sensor:i_meas") in rep.isolable


def _random_system(seed, n=4, p=3, m=2):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A = 0.9 * A / max(abs(np.linalg.eigvals(A)))
    B = rng.normal(size=(n, m))
    C = rng.normal(size=(p, n))
    faults = [f"actuator:u{k}" for k in range(m)] + ["sensor:y0"]
    return LinearFaultModel(A, B, C, dt=DT, faults=faults)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_systems_exact_decoupling_and_signature_through_internal_form(seed):
    m = _random_system(seed)
    bank = design_residual_bank(m, on_weak="ignore")
    M = internal_form(bank.generator().design, m)            # recomputed from the fused generator
    F = M.fault_names
    for r in bank.residuals:
        rows = [M.outputs.index(c) for c in r.channels]
        for j, f in enumerate(F):
            # transfer fault -> residual from its Markov parameters (independent of the frequency grid)
            b = M.B_of("f")[:, j]
            marks = [np.abs(M.D_of("f")[rows, j]).max()]
            x = b.copy()
            for _ in range(M.n_states + 1):
                marks.append(np.abs(M.C[rows] @ x).max())
                x = M.A @ x
            peak = max(marks)
            if f in r.decoupled:
                assert peak < 1e-9, (r.name, f, peak)
                assert bank.signature.matrix[bank.faults.index(f), bank.residual_names.index(r.name)] == 0
            else:
                assert peak > 1e-6, (r.name, f, peak)
                assert bank.signature.matrix[bank.faults.index(f), bank.residual_names.index(r.name)] == 1
    expected = (1 - np.eye(3)) if bank.info["structure_rule"] == "generalised" else np.eye(3)
    assert bank.signature.matrix.tolist() == expected.astype(int).tolist()


def test_dedicated_scheme_when_it_exists_and_simulated_decoupling():
    # 4 outputs, 2 actuator faults: each residual can be blind to the other fault (dedicated scheme)
    rng = np.random.default_rng(7)
    A = np.diag([0.9, 0.8, 0.7, 0.6]) + 0.05 * rng.normal(size=(4, 4))
    m = LinearFaultModel(A, rng.normal(size=(4, 2)), np.eye(4), dt=DT, faults=["actuator:u0", "actuator:u1"])
    bank = design_residual_bank(m, on_weak="ignore")
    assert bank.info["structure_rule"] == "dedicated"
    assert bank.signature.matrix.tolist() == [[1, 0], [0, 1]]
    # simulation: a fault on u1 leaves the residual dedicated to u0 exactly as without the fault
    gen = bank.generator()
    sc0 = Scenario(duration=2.0, dt=DT, inputs=lambda t: np.array([np.sin(t), np.cos(3 * t)]))
    sc1 = Scenario(duration=2.0, dt=DT, inputs=lambda t: np.array([np.sin(t), np.cos(3 * t)]),
                   faults=[Bias("actuator:u1", 1.0, start=0.5)])
    r0 = gen.run(simulate(m, sc0).signals())
    r1 = gen.run(simulate(m, sc1).signals())
    ch0 = r0.index(bank.channels("r[actuator:u0]"))
    ch1 = r0.index(bank.channels("r[actuator:u1]"))
    assert np.abs(r1.values[..., ch0] - r0.values[..., ch0]).max() < 1e-9
    assert np.abs(r1.values[..., ch1] - r0.values[..., ch1]).max() > 1e-2


def test_sensitivity_check_fires_on_a_residual_built_to_be_insensitive():
    # f2 differs from f1 by 1e-3 along x2: the residual blind to f1 sees f2 only through that sliver,
    # whose steady state is 1e-3 / (1 - 0.8) = 0.005 (the DC gain below, less what the observer absorbs)
    A = np.diag([0.9, 0.8, 0.7])
    m = LinearFaultModel(A, np.zeros((3, 0)), np.eye(3), dt=DT,
                         faults=[("f1", [1.0, 0.0, 0.0], None), ("f2", [1.0, 1e-3, 0.0], None),
                                 ("f3", [0.0, 0.0, 1.0], None)])
    structure = {"blind_f1": ["f1"], "blind_f3": ["f3"]}
    with pytest.warns(SensitivityWarning, match=r"'blind_f1'.*'f2'.*DC gain 0\.00[45]"):
        bank = design_residual_bank(m, structure=structure, noise={"measurement": [1e-4] * 3})
    assert ("blind_f1", "f2") in [(r, f) for r, f, _ in bank.weak]
    assert bank.signature.matrix.tolist() == [[0, 1], [1, 1], [1, 0]]      # structurally f2 is seen ...
    rep = bank.isolability()                                                # ... but not usefully
    assert "differ only through weak gains" in rep.not_isolable[("f1", "f2")]
    with pytest.raises(ConditionError) as exc:
        design_residual_bank(m, structure=structure, noise={"measurement": [1e-4] * 3}, on_weak="raise")
    assert exc.value.condition == "residual sensitivity" and ("blind_f1", "f2") in exc.value.details["weak"]


def test_isolability_report_equal_signatures_and_no_gain():
    A = np.diag([0.9, 0.8, 0.7])
    m = LinearFaultModel(A, np.zeros((3, 0)), np.eye(3), dt=DT,
                         faults=[("a", [1.0, 0.0, 0.0], None), ("b", [2.0, 0.0, 0.0], None),
                                 ("c", [0.0, 0.0, 1.0], None)])
    bank = design_residual_bank(m, structure={"blind_c": ["c"], "blind_a": ["a"]}, on_weak="ignore")
    rep = bank.isolability()
    assert bank.signature.matrix.tolist() == [[1, 0], [1, 0], [0, 1]]
    assert rep.not_isolable[("a", "b")].startswith("equal signatures")
    assert ("a", "c") in rep.isolable and not rep.fully_isolable
    assert "equal signatures" in rep.to_text()


def test_generator_named_channels_and_disturbance_decoupled():
    rng = np.random.default_rng(4)
    A = np.diag([0.9, 0.8, 0.7, 0.5])
    m = LinearFaultModel(A, rng.normal(size=(4, 2)), np.eye(4), dt=DT, Bd=rng.normal(size=(4, 1)),
                         disturbances=["gust"], faults=["actuator:u0", "actuator:u1"])
    bank = design_residual_bank(m, on_weak="ignore")
    gen = bank.generator()
    assert gen.output_names == [c for r in bank.residuals for c in r.channels]
    assert all(c.startswith(r.name) for r in bank.residuals for c in r.channels)
    Gd = dc_gain(bank.internal_form(), "d")
    assert np.abs(Gd).max() < 1e-9
    assert bank.info["disturbances_decoupled"] == ["disturbance:gust"]
