"""Monitor core with a real component pair: observer residual + threshold-with-hold."""

import numpy as np
import pytest
from scipy.signal import dlsim

from fdikit import ConditionError, DataError, Signals
from fdikit.detect import Hold, consecutive_count
from fdikit.model import LinearFaultModel
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import ObserverResidual, design_observer_residual, internal_form

DT = 0.01


@pytest.fixture
def plant():
    # a damped two-mass system, continuous, with a sensor fault on the second output
    A = [[0, 1, 0, 0], [-2, -0.4, 1, 0], [0, 0, 0, 1], [1, 0, -1, -0.3]]
    B = [[0], [1], [0], [0]]
    C = [[1, 0, 0, 0], [0, 0, 1, 0]]
    return LinearFaultModel(A, B, C, states=["x1", "v1", "x2", "v2"], inputs=["force"],
                            outputs=["pos1", "pos2"], Bw=np.eye(4) * 0.01, noises=list("abcd"),
                            Dd=[[0.0], [1.0]], disturbances=["offset"],
                            faults=["sensor:pos2", "actuator:force"], name="two-mass")


def _record(plant, runs=3, T=600, bias_at=300, bias=0.5, seed=1):
    md = plant.discretize(DT)
    rng = np.random.default_rng(seed)
    t = np.arange(T) * DT
    u = np.sin(0.7 * t)[:, None]
    Y = []
    for _ in range(runs):
        y = dlsim((md.A, md.B, md.C, md.D, DT), u, t)[1]
        y = y + 0.002 * rng.standard_normal(y.shape)
        y[bias_at:, 1] += bias
        Y.append(np.column_stack([u, y]))
    return Signals(t, np.stack(Y), ["force", "pos1", "pos2"])


def test_internal_form_is_exact(plant):
    d = design_observer_residual(plant, dt=DT)
    G = internal_form(d, plant)
    md = plant.discretize(DT)
    Ae = d.A - d.L @ d.C
    for z in np.exp(1j * 2 * np.pi * np.array([0.0, 0.3, 2.0, 20.0]) * DT):
        # composition of plant and observer ...
        Gz = G.C @ np.linalg.solve(z * np.eye(G.n_states) - G.A, G.B_all) + G.D_all
        sl = G.group_slices()
        # ... equals the closed-form error dynamics C (zI - A + LC)^-1 (B_g - L D_g) + D_g
        for g in ("d", "f", "w"):
            ref = d.C @ np.linalg.solve(z * np.eye(4) - Ae, md.B_of(g) - d.L @ md.D_of(g)) + md.D_of(g)
            np.testing.assert_allclose(Gz[:, sl[g]], ref, rtol=1e-9, atol=1e-12)
        # the controls are exactly decoupled
        assert np.max(np.abs(Gz[:, sl["u"]])) < 1e-9
    # the sensor fault reaches the residual, with a DC gain that is not zero
    G0 = G.C @ np.linalg.solve(np.eye(G.n_states) - G.A, G.B_of("f")) + G.D_of("f")
    assert abs(G0[1, 0]) > 0.01


def test_pole_placement_and_conditions(plant):
    poles = [0.5, 0.6, 0.7, 0.8]
    d = design_observer_residual(plant, dt=DT, method="poles", poles=poles)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(d.A - d.L @ d.C).real), poles, atol=1e-8)
    # an unstable mode the sensors cannot see: not detectable
    bad = LinearFaultModel([[1.1, 0], [0, 0.5]], [[1], [1]], [[0, 1]], dt=0.1)
    with pytest.raises(ConditionError, match="detectability"):
        design_observer_residual(bad)


def test_batch_equals_streaming_and_detects(plant):
    sig = _record(plant)
    gen = ObserverResidual(design_observer_residual(plant, dt=DT, Q=np.eye(4) * 1e-8, R=np.eye(2) * 4e-6))
    hold = Hold(["r:pos1", "r:pos2"], 0.05, Z=5)
    mon = Monitor([gen], [hold], Decision(["r:pos1:alarm", "r:pos2:alarm"], names={
        "r:pos1:alarm": "pos1", "r:pos2:alarm": "pos2"}))
    batch = mon.run(sig)
    stream = mon.stream(sig)
    np.testing.assert_array_equal(batch.residuals.values, stream.residuals.values)
    np.testing.assert_array_equal(batch.statistics.values, stream.statistics.values)
    assert batch.events == stream.events
    for run in range(sig.runs):
        ev = batch.first_event(run)
        assert ev is not None and ev.hypothesis == "pos2"
        # the bias enters at sample 300; Z = 5 samples of hold make the earliest alarm sample 304
        assert 304 <= ev.k <= 310
    # before the fault the residuals are small: no alarm
    assert not batch.statistics.values[:, :300].any()
    # the stages are fixed (the streaming plan is built from them): a stage swapped in place would
    # run in batch but not in streaming, so it is refused; a changed chain is a new Monitor
    with pytest.raises(TypeError):
        mon.processors[0] = Hold(["r:pos1", "r:pos2"], 0.5, Z=5)
    with pytest.raises(TypeError):
        mon.generators[0] = gen


def test_hold_mean_time_to_false_alarm():
    # i.i.d. exceedances with probability q: the mean waiting time for Z in a row is sum_{k=1..Z} q^-k
    rng = np.random.default_rng(7)
    q, Z, runs, T = 0.5, 3, 4000, 400
    r = (rng.random((runs, T)) < q).astype(float) * 2.0
    s = Signals(np.arange(T, dtype=float), r[..., None], ["g"])
    alarm = Hold(["g"], 1.0, Z=Z).run(s)["g:alarm"]
    first = np.argmax(alarm > 0, axis=1) + 1  # samples until the first alarm
    assert alarm.any(axis=1).all()
    expected = sum(q ** -k for k in range(1, Z + 1))  # = 14
    se = first.std() / np.sqrt(runs)
    assert abs(first.mean() - expected) < 4 * se


def test_consecutive_count_brute_force():
    rng = np.random.default_rng(3)
    e = rng.random((5, 200)) < 0.6
    c = consecutive_count(e)
    for i in range(5):
        n = 0
        for k in range(200):
            n = n + 1 if e[i, k] else 0
            assert c[i, k] == n


def test_monitor_bad_input(plant):
    sig = _record(plant, runs=1, T=50)
    gen = ObserverResidual(design_observer_residual(plant, dt=DT))
    mon = Monitor([gen], [Hold(["r:pos1"], 0.1)])
    v = sig.values.copy()
    v[0, 20, 2] = np.nan
    bad = Signals(sig.t, v, sig.names, check=False)
    with pytest.raises(DataError, match="channel 'pos2' has a non-finite value .* sample 20"):
        mon.run(bad)
    mon.reset(1)
    with pytest.raises(DataError, match="lacks channel 'pos2'"):
        mon.step(0.0, {"force": 1.0, "pos1": 0.0})
    mon.step(0.0, {"force": 1.0, "pos1": 0.0, "pos2": 0.0})
    with pytest.raises(DataError, match="time is not increasing at sample 1"):
        mon.step(0.0, {"force": 1.0, "pos1": 0.0, "pos2": 0.0})
    with pytest.raises(DataError, match="needs channels"):
        Monitor([gen], [Hold(["r:nope"], 0.1)])
    with pytest.raises(DataError, match="unknown channel 'force'"):
        mon.run(sig.select(["pos1", "pos2"]))
    with pytest.raises(DataError, match="Z must be an integer"):
        Hold(["r:pos1"], 0.1, Z=0)


def test_hold_on_invalid_samples_keeps_state(plant):
    sig = _record(plant, runs=1, T=400)
    bad_k = [100, 101, 102, 250]
    v = sig.values.copy()
    v[0, 100:103, 1] = np.nan
    v[0, 250, 2] = np.inf
    bad = Signals(sig.t, v, sig.names, check=False)

    def build():
        gen = ObserverResidual(design_observer_residual(plant, dt=DT, Q=np.eye(4) * 1e-8, R=np.eye(2) * 4e-6))
        return Monitor([gen], [Hold(gen.output_names, 0.05, Z=5)], on_invalid="hold")

    res = build().run(bad)
    assert np.all(np.isfinite(res.residuals.values)) and np.all(np.isfinite(res.statistics.values))
    assert [k for _, k, _ in res.invalid] == bad_k
    assert "channel 'pos1' has a non-finite value at sample 100" in res.invalid[0][2]
    assert not res.valid[0, bad_k].any() and res.valid[0].sum() == 400 - len(bad_k)
    # held samples repeat the last good output ...
    np.testing.assert_array_equal(res.residuals.values[0, 100], res.residuals.values[0, 99])
    # ... and the components behave as if the bad samples had never arrived
    keep = np.setdiff1d(np.arange(400), bad_k)
    clean = Signals(sig.t[keep], sig.values[:, keep], sig.names)
    ref = build().stream(clean)  # (time has gaps: the batch path would refuse the sample rate)
    np.testing.assert_array_equal(res.residuals.values[0, keep], ref.residuals.values[0])
    # a duplicated time stamp is held too, not raised
    mon = build()
    mon.reset(1)
    mon.step(0.0, {"force": 0.0, "pos1": 0.0, "pos2": 0.0})
    mon.step(0.0, {"force": 0.0, "pos1": 0.0, "pos2": 0.0})
    assert "time is not increasing at sample 1" in mon.last_invalid
