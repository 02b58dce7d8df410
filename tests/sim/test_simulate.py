"""Vectorised simulation (fdikit.sim): against scipy, closed forms and brute-force recursions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete, dlsim

import fdikit.sim.core as simcore
from fdikit.errors import DataError, ModelError
from fdikit.faults import (
    Bias,
    Gain,
    Intermittent,
    Noise,
    Parametric,
    Ramp,
    Scenario,
    Sinusoid,
    Stuck,
)
from fdikit.model import LinearFaultModel, NonlinearModel
from fdikit.sim import SimulationError, sample_and_hold, simulate


def random_discrete(seed=0, n=3, m=2, p=2, dt=0.1):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    return (A, rng.normal(size=(n, m)), rng.normal(size=(p, n)), rng.normal(size=(p, m)), dt)


# ---------------------------------------------------------------- linear models vs scipy
def test_discrete_linear_equals_dlsim():
    A, B, C, D, dt = random_discrete()
    model = LinearFaultModel(A, B, C, D, dt=dt, states=["a", "b", "c"], inputs=["u1", "u2"],
                             outputs=["y1", "y2"])
    N = 60
    u = np.random.default_rng(1).normal(size=(N + 1, 2))
    x0 = np.array([0.3, -1.0, 2.0])
    res = simulate(model, Scenario(duration=N * dt, inputs=u, x0=x0), keep=("y", "x", "u"))
    _, y_ref, x_ref = dlsim((A, B, C, D, dt), u, x0=x0)
    np.testing.assert_allclose(res.y.values[0], y_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res.x.values[0], x_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(res.u.values[0], u)
    np.testing.assert_allclose(res.y.t, np.arange(N + 1) * dt, rtol=1e-15)
    assert res.y.names == ["y1", "y2"] and res.x.names == ["a", "b", "c"]


def test_continuous_linear_is_exact_zoh():
    A = np.array([[0.0, 1.0], [-4.0, -0.4]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[1.0, 0.0]])
    model = LinearFaultModel(A, B, C)
    dt, N = 0.05, 80
    u = np.sin(0.3 * np.arange(N + 1))[:, None]
    res = simulate(model, Scenario(duration=N * dt, dt=dt, inputs=u, x0=[1.0, 0.0]))
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, np.zeros((1, 1))), dt, method="zoh")
    _, y_ref, _ = dlsim((Ad, Bd, Cd, Dd, dt), u, x0=[1.0, 0.0])
    np.testing.assert_allclose(res.y.values[0], y_ref, rtol=1e-11, atol=1e-12)


def test_declared_additive_fault_input_is_driven_by_its_name():
    A, B, C, D, dt = random_discrete(seed=3)
    b, d = np.array([1.0, 0.0, -0.5]), np.array([0.0, 2.0])
    model = LinearFaultModel(A, B, C, D, dt=dt, faults=[("slope", b, d), "sensor:y0"])
    N = 40
    u = np.random.default_rng(4).normal(size=(N + 1, 2))
    sc = Scenario(duration=N * dt, inputs=u, faults=[Ramp("slope", 0.5, start=1.0, end=3.0)])
    res = simulate(model, sc)
    t = np.arange(N + 1) * dt
    f = np.where((t >= 1.0 - 1e-9) & (t < 3.0 - 1e-9), 0.5 * (t - 1.0), 0.0)
    _, y_ref, _ = dlsim((A, np.column_stack([B, b]), C, np.column_stack([D, d]), dt),
                        np.column_stack([u, f]))
    np.testing.assert_allclose(res.y.values[0], y_ref, rtol=1e-12, atol=1e-12)


def test_actuator_bias_response_equals_shifted_step_response():
    A, B, C, D, dt = random_discrete(seed=5)
    model = LinearFaultModel(A, B, C, D, dt=dt, inputs=["u1", "u2"])
    N = 50
    sc = Scenario(duration=N * dt, faults=[Bias("actuator:u2", 0.7, start=1.5)])
    y = simulate(model, sc).y.values[0]
    u = np.zeros((N + 1, 2))
    u[15:, 1] = 0.7  # t = 1.5 s is sample 15
    _, y_ref, _ = dlsim((A, B, C, D, dt), u)
    np.testing.assert_allclose(y, y_ref, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------- every fault type on a sensor
def test_every_fault_type_acts_on_the_measurement_only_in_its_window():
    """The plant x' = 1 (x0 = 0) gives y = t exactly; each fault is checked against its formula."""
    model = LinearFaultModel([[0.0]], [[1.0]], [[1.0]], outputs=["v"], inputs=["u"])
    dt = 0.01
    t = np.arange(301) * dt
    win = (t >= 1.0 - 1e-9) & (t < 2.0 - 1e-9)
    cases = [
        (Bias("sensor:v", 0.5, start=1.0, end=2.0), np.where(win, t + 0.5, t)),
        (Ramp("sensor:v", 3.0, start=1.0, end=2.0), np.where(win, t + 3.0 * (t - 1.0), t)),
        (Sinusoid("sensor:v", 0.2, 2.0, start=1.0, end=2.0),
         np.where(win, t + 0.2 * np.sin(2 * np.pi * 2.0 * (t - 1.0)), t)),
        (Intermittent("sensor:v", 1.0, windows=[(1.2, 1.5), (2.5, 2.8)], start=1.0, end=2.0),
         np.where((t >= 1.2 - 1e-9) & (t < 1.5 - 1e-9), t + 1.0, t)),
        (Gain("sensor:v", 0.95, start=1.0, end=2.0), np.where(win, 0.95 * t, t)),
        (Stuck("sensor:v", start=1.0, end=2.0), np.where(win, 1.0, t)),
        (Stuck("sensor:v", -3.0, start=1.0, end=2.0), np.where(win, -3.0, t)),
    ]
    for fault, expected in cases:
        sc = Scenario(duration=3.0, dt=dt, inputs=[1.0], faults=[fault])
        y = simulate(model, sc).y["v"][0]
        np.testing.assert_allclose(y, expected, rtol=0, atol=1e-12, err_msg=type(fault).__name__)


def test_parametric_fault_closed_form_and_per_run_change():
    """x' = -k x with k reduced by 50 % (run 0) or 20 % (run 1) from t = 1 s."""
    model = NonlinearModel(lambda t, x, u, p: -np.reshape(p["k"], (-1, 1)) * x, lambda t, x, u, p: x,
                           ["x"], [], ["y"], {"k": 2.0})
    sc = Scenario(duration=2.0, dt=1e-3, x0=[1.0], faults=[Parametric("param:k", [-0.5, -0.2], start=1.0)])
    y = simulate(model, sc, runs=2).y.values[:, :, 0]
    t = np.arange(2001) * 1e-3
    for r, c in enumerate([-0.5, -0.2]):
        after = np.exp(-2.0) * np.exp(-2.0 * (1 + c) * (t - 1.0))
        expected = np.where(t < 1.0 - 1e-9, np.exp(-2.0 * t), after)
        np.testing.assert_allclose(y[r], expected, rtol=1e-10)


# ---------------------------------------------------------------- RK4 / Euler against closed forms
def _rk_error(method, h, T=2.0):
    # x' = cos(t) x - x^3 / 10 has no elementary form; use x' = cos(t) x: x = x0 exp(sin t)
    # plus a state-nonlinear one: z' = -z^3: z = z0 / sqrt(1 + 2 z0^2 t)
    def f(t, x, u, p):
        return np.column_stack([np.cos(t) * x[:, 0], -x[:, 1] ** 3])

    model = NonlinearModel(f, lambda t, x, u, p: x, ["x", "z"], [], ["x", "z"], {})
    res = simulate(model, Scenario(duration=T, dt=h, x0=[1.5, 0.7]), method=method)
    y = res.y.values[0, -1]
    exact = np.array([1.5 * np.exp(np.sin(T)), 0.7 / np.sqrt(1 + 2 * 0.49 * T)])
    return np.abs(y - exact)  # per state


def test_rk4_is_fourth_order_and_euler_first_order():
    e = np.array([_rk_error("rk4", h) for h in (0.04, 0.02, 0.01)])
    orders = np.log2(e[:-1] / e[1:])  # (2 halvings, 2 states)
    assert np.all((orders > 3.8) & (orders < 4.2)), orders
    assert np.all(e[-1] < 1e-9)
    e = np.array([_rk_error("euler", h) for h in (0.004, 0.002, 0.001)])
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert np.all((orders > 0.85) & (orders < 1.15)), orders


# ---------------------------------------------------------------- sample-and-hold and controllers
def test_measurements_are_samples_of_the_fine_grid():
    A, B, C, D, _ = random_discrete(seed=7)
    model = LinearFaultModel(A - 2 * np.eye(3), B, C, D)  # continuous, stable
    u = np.cos(np.arange(1001) * 0.01)[:, None] * [1.0, -0.5]
    fine = simulate(model, Scenario(duration=10.0, dt=0.01, inputs=u), keep=("y", "x"))
    coarse = simulate(model, Scenario(duration=10.0, dt=0.01, sample_time=0.1, inputs=u), keep=("y", "x"))
    assert coarse.y.n_samples == 101
    np.testing.assert_array_equal(coarse.y.values, fine.y.values[:, ::10])
    np.testing.assert_array_equal(coarse.x.values, fine.x.values[:, ::10])
    np.testing.assert_allclose(coarse.y.t, np.arange(101) * 0.1, rtol=1e-14)


class RecordingGain:
    """u = -K y, records the times it was called at; vectorised over runs."""

    def __init__(self, K):
        self.K, self.times, self.resets = np.atleast_2d(K), [], 0

    def reset(self, runs):
        self.resets += 1
        self.times = []

    def __call__(self, t, y):
        self.times.append(t)
        return -(y @ self.K.T)


def test_closed_loop_sampled_controller_with_actuator_fault_against_recursion():
    """Continuous plant, controller every 0.05 s (5 integration steps): the exact sampled-data
    recursion is the plant discretised at the controller period."""
    A = np.array([[0.0, 1.0], [-1.0, -0.2]])
    B = np.array([[0.0], [1.0]])
    C = np.eye(2)
    model = LinearFaultModel(A, B, C, inputs=["force"])
    K = np.array([[2.0, 1.5]])
    ctrl = RecordingGain(K)
    ts = 0.05
    sc = Scenario(duration=3.0, dt=0.01, sample_time=ts, x0=[1.0, 0.0], controller=ctrl,
                  faults=[Bias("actuator:force", 0.4, start=1.0, end=2.0)])
    res = simulate(model, sc, runs=2, keep=("y", "u"))
    Ad, Bd, *_ = cont2discrete((A, B, C, np.zeros((2, 1))), ts, method="zoh")
    x = np.array([1.0, 0.0])
    ys, us = [], []
    for k in range(61):
        y = C @ x
        u = -K @ y
        ys.append(y)
        us.append(u)
        fault = 0.4 if 1.0 - 1e-9 <= k * ts < 2.0 - 1e-9 else 0.0
        x = Ad @ x + Bd @ (u + fault)
    np.testing.assert_allclose(res.y.values[1], ys, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(res.u.values[0], us, rtol=1e-11, atol=1e-12)  # commanded, fault-free
    np.testing.assert_allclose(ctrl.times, np.arange(61) * ts, rtol=1e-12)
    assert ctrl.resets == 1


# ---------------------------------------------------------------- determinism
def _nl_model():
    def f(t, x, u, p):
        return np.column_stack([x[:, 1], -p["k"] * np.sin(x[:, 0]) - p["c"] * x[:, 1] + u[:, 0]])

    def h(t, x, u, p):
        return np.column_stack([x[:, 0], np.tanh(x[:, 1])])

    return NonlinearModel(f, h, ["angle", "rate"], ["torque", "wind"], ["angle_m", "rate_m"],
                          {"k": 9.81, "c": 0.3}, groups={"u": ["torque"], "d": ["wind"]})


def _full_scenario(R):
    rng = np.random.default_rng(11)
    return Scenario(
        duration=2.0, dt=1e-3, sample_time=5e-3,
        x0=rng.normal(size=(R, 2)) * 0.1,
        controller=lambda t, y: -3.0 * y[:, :1],
        faults=[Bias("sensor:angle_m", rng.normal(size=R) * 0.1, start=0.5, end=1.5),
                Ramp("actuator:torque", 0.3, start=1.0),
                Parametric("param:c", rng.uniform(-0.5, 0.5, R), start=0.7)],
        noise=Noise(process_snr_db=[30.0, 25.0], measurement=[[1e-4, 2e-5], [2e-5, 1e-4]]),
        params={"k": rng.uniform(8.0, 10.0, R)},
        disturbances=lambda t: [0.1 * np.sin(t)],
    )


def test_batch_equals_runs_alone_bitwise(monkeypatch):
    R = 7
    sc = _full_scenario(R)
    batch = simulate(_nl_model(), sc, runs=R, seed=42, keep=("y", "x", "u"))
    for i in (0, 3, 6):
        alone = simulate(_nl_model(), sc, run_ids=[i], seed=42, keep=("y", "x", "u"))
        np.testing.assert_array_equal(alone.y.values[0], batch.y.values[i])
        np.testing.assert_array_equal(alone.x.values[0], batch.x.values[i])
        np.testing.assert_array_equal(alone.u.values[0], batch.u.values[i])
    sub = simulate(_nl_model(), sc, run_ids=[5, 2], seed=42)
    np.testing.assert_array_equal(sub.y.values, batch.y.values[[5, 2]])
    # the noise chunk length only bounds memory: tiny chunks give the same numbers
    monkeypatch.setattr(simcore, "_CHUNK_BYTES", 200)
    chunked = simulate(_nl_model(), sc, runs=R, seed=42)
    np.testing.assert_array_equal(chunked.y.values, batch.y.values)
    # another seed changes the noise, the same seed reproduces it
    other = simulate(_nl_model(), sc, runs=R, seed=43)
    assert not np.array_equal(other.y.values, batch.y.values)


# ---------------------------------------------------------------- noise levels
def test_measurement_noise_by_snr_has_the_requested_variance():
    """y = 1 - exp(-t) sampled; noise variance must be ms(y) * 10^(-SNR/10) per channel."""
    model = LinearFaultModel([[-1.0]], [[1.0]], [[1.0], [2.0]], outputs=["a", "b"])
    dt, N, R = 0.01, 2000, 10
    t = np.arange(N + 1) * dt
    ms = np.mean((1.0 - np.exp(-t)) ** 2)  # closed form of the clean output, channel a
    snr = np.array([10.0, 20.0])
    sc = Scenario(duration=N * dt, dt=dt, inputs=[1.0], noise=Noise(measurement_snr_db=snr))
    res = simulate(model, sc, runs=R, seed=3)
    clean = np.stack([1.0 - np.exp(-t), 2.0 * (1.0 - np.exp(-t))], axis=1)
    e = res.y.values - clean[None]
    want = np.array([ms, 4 * ms]) * 10 ** (-snr / 10)
    np.testing.assert_allclose(res.measurement_std[0] ** 2, want, rtol=1e-6)
    got = e.reshape(-1, 2).var(axis=0)
    n = e.shape[0] * e.shape[1]
    assert np.all(np.abs(got / want - 1) < 4 * np.sqrt(2 / n)), (got, want)
    assert abs(np.corrcoef(e.reshape(-1, 2).T)[0, 1]) < 4 / np.sqrt(n)
    # runs draw independent streams: the noise of two runs is uncorrelated
    m = e.shape[1]
    for a, b in ((0, 1), (2, 9)):
        assert abs(np.corrcoef(e[a, :, 0], e[b, :, 0])[0, 1]) < 4 / np.sqrt(m)


@pytest.mark.parametrize("mode", ["derivative", "psd", "increment"])
def test_process_noise_by_snr_discretisation(mode):
    """Integrator x' = 1 + w (nominal x = t). The per-step increment minus dt is the noise
    contribution: derivative -> w dt, psd -> sqrt(dt) sigma z, increment -> sigma z."""
    dt, N, R = 0.01, 1000, 20
    t = np.arange(N + 1) * dt
    ms = np.mean(t**2)
    snr = 20.0
    var = ms * 10 ** (-snr / 10)
    scale = {"derivative": dt**2, "psd": dt, "increment": 1.0}[mode]
    lin = LinearFaultModel([[0.0]], [[1.0]], [[1.0]])
    nl = NonlinearModel(lambda t, x, u, p: u + 0.0 * x, lambda t, x, u, p: x, ["x"], ["u"], ["y"], {})
    for model in (lin, nl):
        sc = Scenario(duration=N * dt, dt=dt, inputs=[1.0],
                      noise=Noise(process_snr_db=snr, process_mode=mode))
        res = simulate(model, sc, runs=R, seed=1, keep=("y", "x"))
        np.testing.assert_allclose(res.nominal_ms["x"][:, 0], ms, rtol=1e-12)
        inc = np.diff(res.x.values[:, :, 0], axis=1) - dt
        got = inc.var()
        assert abs(got / (var * scale) - 1) < 4 * np.sqrt(2 / inc.size), (type(model).__name__, got)


def test_process_noise_full_covariance():
    """Increment mode with a full covariance: the sample covariance of the increments matches."""
    Q = np.array([[2.0, 0.8], [0.8, 1.0]])
    model = LinearFaultModel(np.zeros((2, 2)), np.zeros((2, 0)), np.eye(2))
    sc = Scenario(duration=20.0, dt=0.01, noise=Noise(process=Q, process_mode="increment"))
    res = simulate(model, sc, runs=5, seed=9, keep=("x",))
    inc = np.diff(res.x.values, axis=1).reshape(-1, 2)
    S = np.cov(inc.T)
    n = inc.shape[0]
    assert np.all(np.abs(S - Q) < 4 * np.sqrt((Q**2 + np.outer(np.diag(Q), np.diag(Q))) / n)), S


# ---------------------------------------------------------------- errors
def test_nan_from_the_model_names_state_run_and_time():
    """z' = z^2 blows up at t = 1 / z0: only run 2 (z0 = 2) does so within 1 s."""
    model = NonlinearModel(lambda t, x, u, p: np.column_stack([x[:, 0] ** 2, -x[:, 1]]),
                           lambda t, x, u, p: x, ["z", "w"], [], ["z", "w"], {})
    x0 = np.array([[0.1, 1.0], [0.2, 1.0], [2.0, 1.0]])
    with pytest.raises(SimulationError) as e:
        simulate(model, Scenario(duration=1.0, dt=0.01, x0=x0), runs=3)
    msg = str(e.value)
    assert "state 'z'" in msg and "run 2" in msg
    t_bad = float(msg.split("at t = ")[1].split(" s")[0])
    assert 0.5 < t_bad <= 1.0


def test_bad_input_raises_clear_errors():
    A, B, C, D, dt = random_discrete()
    lin = LinearFaultModel(A, B, C, D, dt=dt, inputs=["u1", "u2"], outputs=["y1", "y2"])
    sc = Scenario(duration=1.0)
    with pytest.raises(ModelError, match="unknown sensor output 'y9'.*valid targets"):
        simulate(lin, Scenario(duration=1.0, faults=[Bias("sensor:y9", 1.0)]))
    with pytest.raises(DataError, match="inputs have shape \\(5, 2\\)"):
        simulate(lin, Scenario(duration=1.0, inputs=np.zeros((5, 2))))
    with pytest.raises(DataError, match="x0 has shape \\(2,\\); expected \\(3,\\)"):
        simulate(lin, Scenario(duration=1.0, x0=[1.0, 2.0]))
    with pytest.raises(DataError, match="steps at its own dt"):
        simulate(lin, Scenario(duration=1.0, dt=0.05))
    with pytest.raises(DataError, match="unknown output 'y3'"):
        simulate(lin, sc, outputs=["y3"])
    with pytest.raises(DataError, match="keep has unknown item 'z'"):
        simulate(lin, sc, keep=("z",))
    with pytest.raises(DataError, match="runs = 3 but 2 run_ids"):
        simulate(lin, sc, runs=3, run_ids=[0, 1])
    with pytest.raises(DataError, match="per-run values but the batch has 4 runs"):
        simulate(lin, Scenario(duration=1.0, faults=[Bias("sensor:y1", [1.0, 2.0])]), runs=4)
    with pytest.raises(DataError, match="measurement noise has shape \\(3,\\)"):
        simulate(lin, Scenario(duration=1.0, noise=Noise(measurement=[1.0, 1.0, 1.0])))
    with pytest.raises(DataError, match="controller returned shape"):
        simulate(lin, Scenario(duration=1.0, controller=lambda t, y: np.zeros((3, 5))))
    nl = _nl_model()
    with pytest.raises(DataError, match="dt is not set"):
        simulate(nl, Scenario(duration=1.0))
    with pytest.raises(DataError, match="unknown integration method 'rk45'"):
        simulate(nl, Scenario(duration=1.0, dt=0.1), method="rk45")
    with pytest.raises(DataError, match="unknown parameter 'mass'"):
        simulate(nl, Scenario(duration=1.0, dt=0.1, params={"mass": 2.0}))
    bad = NonlinearModel(lambda t, x, u, p: x[:, :1], lambda t, x, u, p: x, ["a", "b"], [], ["a", "b"], {})
    with pytest.raises(SimulationError, match="f returned shape \\(1, 1\\), expected \\(1, 2\\)"):
        simulate(bad, Scenario(duration=1.0, dt=0.1))
    with pytest.raises(DataError, match="callable returned NaN"):
        simulate(nl, Scenario(duration=1.0, dt=0.1, inputs=lambda t: [np.nan]))


def test_keep_and_outputs_select_what_is_stored():
    nl = _nl_model()
    res = simulate(nl, Scenario(duration=0.5, dt=0.01, inputs=[0.1]), runs=2, outputs=["rate_m"], keep=("y",))
    assert res.x is None and res.u is None
    assert res.y.names == ["rate_m"] and res.y.values.shape == (2, 51, 1)


def test_linear_batch_equals_runs_alone_bitwise():
    A = np.array([[0.0, 1.0, 0.0], [-2.0, -0.3, 0.5], [0.0, 0.0, -1.0]])
    B = np.array([[0.0], [1.0], [0.3]])
    C = np.array([[1.0, 0.0, 0.0], [0.2, 0.0, 1.0]])
    model = LinearFaultModel(A, B, C, faults=[("leak", [0.0, 1.0, 0.0], None)])
    R = 6
    rng = np.random.default_rng(2)
    sc = Scenario(duration=1.0, dt=0.01, sample_time=0.02, inputs=rng.normal(size=(R, 101, 1)),
                  faults=[Intermittent("leak", rng.normal(size=R), period=0.3, duty=0.5, start=0.2),
                          Gain("sensor:y1", 1.1, start=0.5)],
                  noise=Noise(process=[0.1, 0.2, 0.0], measurement_snr_db=15.0))
    batch = simulate(model, sc, runs=R, seed=5, keep=("y", "x"))
    for i in range(R):
        alone = simulate(model, sc, run_ids=[i], seed=5, keep=("y", "x"))
        np.testing.assert_array_equal(alone.y.values[0], batch.y.values[i])
        np.testing.assert_array_equal(alone.x.values[0], batch.x.values[i])
    assert batch.measurement_std.shape == (R, 2) and np.all(np.diff(batch.measurement_std[:, 0]) != 0)


def test_sample_and_hold_matches_equation_31_and_signals_join():
    """y_h(t) = y(t_k) on [t_k, t_k + ts): held coarse samples equal the fine samples at the
    last sampling instant."""
    model = LinearFaultModel([[-0.5]], [[1.0]], [[1.0]], inputs=["u"], outputs=["y"])
    u = np.sin(np.arange(501) * 0.01)[:, None]
    fine = simulate(model, Scenario(duration=5.0, dt=0.01, inputs=u))
    coarse = simulate(model, Scenario(duration=5.0, dt=0.01, sample_time=0.1, inputs=u))
    held = sample_and_hold(coarse.y, fine.y.t)
    last = (np.arange(501) // 10) * 10  # index of the last sample at or before each fine time
    np.testing.assert_array_equal(held.values[0, :, 0], fine.y.values[0, last, 0])
    both = coarse.signals()
    assert both.names == ["u", "y"] and both.values.shape == (1, 51, 2)
    with pytest.raises(DataError, match="before the first sample"):
        sample_and_hold(coarse.y, [-1.0])
