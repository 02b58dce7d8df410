"""ABS benchmark plant (luo-et-al, Sections II-III): model, faults, noise, determinism."""

import json
import subprocess
import sys

import numpy as np
import pytest

from fdikit.errors import DataError, ModelError
from fdikit.model import NonlinearModelProtocol
from fdikit.systems.abs import plant as absp
from fdikit.systems.abs.plant import (
    FAULT_CLASSES,
    PARAM_NAMES,
    ABSPlant,
    Scenario,
    mu,
    simulate,
    slip,
)

G = 9.81
QUIET = {"snr_db": None, "meas_var": 0.0}


@pytest.fixture(scope="module")
def plant():
    return ABSPlant()


@pytest.fixture(scope="module")
def nominal(plant):
    """Noise-free nominal stop, true states at every 1 ms step."""
    return simulate(plant, Scenario(**QUIET), keep_states=True, state_stride=1)


# ------------------------------------------------------------------ model pieces
def test_mu_table_matches_burckhardt_closed_form():
    c1, c2, c3 = 1.2801, 23.99, 0.52  # Burckhardt, dry asphalt
    lam = np.linspace(0, 1, 1001)
    exact = c1 * (1 - np.exp(-c2 * lam)) - c3 * lam
    # linear interpolation error <= h^2/8 max|mu''| = 0.01^2/8 * c1 c2^2
    bound = 0.01**2 / 8 * c1 * c2**2
    assert np.max(np.abs(mu(lam) - exact)) <= bound
    assert np.allclose(mu(-lam), -mu(lam))
    peak = lam[np.argmax(mu(lam))]
    assert 0.14 <= peak <= 0.20 and 1.15 < mu(peak) < 1.18


def test_slip_definition():
    assert slip(80.0, 100.0) == pytest.approx(0.2)
    assert slip(0.0, 5.0) == pytest.approx(1.0)
    assert slip(0.0, 0.0) == 0.0


def test_plant_is_a_named_nonlinear_model(plant):
    assert isinstance(plant, NonlinearModelProtocol)
    assert plant.states == ["omega_w", "omega_v", "T_b", "dT_b", "P_s", "P_m"]
    assert plant.groups["w"] == ["w1", "w2", "w3", "w4", "w5", "w6"]
    assert set(PARAM_NAMES) == set(plant.params)
    with pytest.raises(ModelError, match="unknown ABS parameter 'Kf'"):
        ABSPlant({"Kf": 1.0})


def test_f_matches_hand_computed_equation_19(plant):
    p = plant.params
    x = np.array([[60.0, 75.0, 900.0, 120.0, 9.0, 14.0]])
    u = np.zeros((1, 9))
    u[0, :3] = [7.0, 0.6, 0.0]
    u[0, 3:] = [1, 2, 3, 4, 5, 6]
    lam = 0.2
    m = 1.2801 * (1 - np.exp(-23.99 * lam)) - 0.52 * lam  # on a grid point: the table is exact
    dP = 14.0 - 9.0
    q_in = p["C_in"] * 0.6 * p["A_0"] * np.sqrt(2 * dP * 1e6 / p["rho"])
    expect = [
        (p["R_w"] * p["N_v"] * m - 900.0) / p["I_w"] + 1,
        -4 * p["N_v"] * m / (p["R_w"] * p["M_v"]) + 2,
        120.0 + 3,
        p["omega_n"] ** 2 * (p["K_f"] * 9.0 - 2 * p["zeta"] * 120.0 / p["omega_n"] - 900.0) + 4,
        p["beta_s"] * q_in / p["V_s"] + 5,
        p["K_m"] * 7000.0 / p["A_m"] / 1e6 / p["tau_m"] - 14.0 / p["tau_m"] + 6,
    ]
    assert np.allclose(plant.f(0.0, x, u, p)[0], expect, rtol=1e-12)
    # eq. (30): with N_v = m g/4 and M_v = 4 m, dx2/dt = -g mu/(4 R_w)
    assert expect[1] - 2 == pytest.approx(-G * m / (4 * p["R_w"]), rel=1e-12)


def test_numba_kernel_rhs_agrees_with_model_f_on_random_states(plant):
    rng = np.random.default_rng(0)
    n = 500
    x = np.column_stack([
        rng.uniform(0, 100, n), rng.uniform(0.5, 100, n), rng.uniform(-200, 2000, n),
        rng.uniform(-5e3, 5e3, n), rng.uniform(0, 16, n), rng.uniform(0, 16, n),
    ])
    x[:20, 1] = 0.0  # car at rest
    x[20:40, 0] = x[20:40, 1] * 1.05  # negative slip
    u = np.column_stack([rng.uniform(0, 8, n), rng.uniform(0, 1, n), rng.uniform(0, 1, n)])
    # per-run parameters (parametric faults) as (runs,) arrays
    over = {"K_f": rng.uniform(90, 110, n), "R_w": rng.uniform(0.25, 0.33, n),
            "I_w": rng.uniform(4.5, 5.5, n)}
    P = plant.param_matrix(n, over)
    p = plant.param_values(over)
    dx_nb = absp._rhs_batch(x, u, P, absp._MU_TAB)
    dx_np = plant.f(0.0, x, np.column_stack([u, np.zeros((n, 6))]), p)
    scale = np.abs(dx_np).max(axis=0) + 1.0
    assert np.max(np.abs(dx_nb - dx_np) / scale) < 1e-12


# ------------------------------------------------------------------ closed-loop behaviour
def test_nominal_stop_behaves_like_the_paper(plant, nominal):
    x = nominal.x.values[0]
    t = nominal.x.t
    ev = {k: v[0] for k, v in nominal.events.items()}
    lam = slip(x[:, 0], x[:, 1])
    assert np.isfinite(ev["t_abs_on"]) and ev["t_abs_on"] > 0.5  # ABS engages after braking
    assert np.isfinite(ev["t_stop"]) and ev["t_stop"] < 12.5  # the car stops inside the record
    assert ev["t_stop"] - 0.5 > 8.0  # ... and brakes over most of it
    active = (t >= ev["t_abs_on"]) & (t < ev["t_abs_off"])
    assert 0.12 < lam[active].mean() < 0.22  # slip regulated near the 0.2 target
    assert np.quantile(lam[active], 0.95) < 0.3
    # the deceleration can never exceed the friction limit g mu_max / 4 of eq. (30)
    R_w = plant.params["R_w"]
    i0, i1 = np.flatnonzero(active)[[0, -1]]
    decel = (x[i0, 1] - x[i1, 1]) * R_w / (t[i1] - t[i0])
    assert 0.6 * G * MU_MAX / 4 < decel <= G * MU_MAX / 4
    # stopping distance equals the integral of the speed
    dist = np.sum(x[t >= 0.5, 1]) * R_w * 1e-3
    assert ev["stop_distance"] == pytest.approx(dist, rel=1e-9)


MU_MAX = float(np.max(mu(np.linspace(0, 1, 10001))))


def test_sanity_noise_free_and_noisy(plant, nominal):
    x = nominal.x.values[0]
    t = nominal.x.t
    dv = np.diff(x[:, 1])
    assert np.all(dv <= 1e-12)  # vehicle speed non-increasing
    assert np.all(dv[t[:-1] < 0.5] == 0.0)  # constant before the brake is applied
    lam = slip(x[:, 0], x[:, 1])
    assert lam.min() >= 0.0 and lam.max() <= 1.0
    res = simulate(plant, Scenario(snr_db=17.0), runs=20, seed=4, keep_states=True)
    xs = res.x.values
    lam = slip(xs[..., 0], xs[..., 1])
    assert lam.min() > -0.02 and lam.max() <= 1.0
    assert xs[..., 0].min() >= 0 and xs[..., 1].min() >= 0
    # with process noise the speed may rise by noise only: bounded by 6 sigma of one 10 ms block
    sig = np.sqrt(res.process_noise_var[1]) * 1e-3 * np.sqrt(10)
    assert np.diff(xs[..., 1], axis=1).max() < 6 * sig


# ------------------------------------------------------------------ faults
def _pair(plant, fault, magnitude, **kw):
    base = dict(QUIET, **kw)
    a = simulate(plant, Scenario(**base), keep_states=True, state_stride=1, seed=2)
    b = simulate(plant, Scenario(fault=fault, magnitude=magnitude, **base), keep_states=True,
                 state_stride=1, seed=2)
    return a, b


def _parity_r1(plant, x, dt=1e-3):
    """Eq. (25) on the true states with nominal parameters: dx2/dt + 4 N_v mu / (R_w M_v)."""
    p = plant.params
    lam = slip(x[:-1, 0], x[:-1, 1])
    return np.diff(x[:, 1]) / dt + 4 * p["N_v"] * mu(lam) / (p["R_w"] * p["M_v"])


def test_sensor_fault_changes_only_the_wheel_speed_measurement(plant):
    sc = Scenario(snr_db=23.0)
    a = simulate(plant, sc, runs=3, seed=9, keep_states=True)
    b = simulate(plant, Scenario(fault="F1.2", magnitude=-0.07, snr_db=23.0), runs=3, seed=9,
                 keep_states=True)
    assert np.array_equal(a.x.values, b.x.values)  # true states untouched
    assert np.array_equal(a.y["omega_v"], b.y["omega_v"])
    # same noise stream: y1_fault - y1_nominal = -0.07 * omega_w
    assert np.allclose(b.y["omega_w"] - a.y["omega_w"], -0.07 * a.x["omega_w"], atol=1e-9)


@pytest.mark.parametrize("fault,mag", [("F3", 0.1), ("F4", -0.1), ("F5", 0.5)])
def test_kf_iw_taum_faults_leave_parity_r1_zero(plant, fault, mag):
    a, b = _pair(plant, fault, mag)
    xa, xb = a.x.values[0], b.x.values[0]
    moving = xb[1:, 1] > 0  # the step that clamps the speed at rest is excluded
    r1 = _parity_r1(plant, xb)[moving]
    assert np.max(np.abs(r1)) < 1e-9  # eq. (25) unaffected
    assert np.max(np.abs(xb[:, 0] - xa[:, 0])) > 0.5  # but the wheel speed changes


def test_rw_fault_breaks_parity_r1(plant):
    _, b = _pair(plant, "F2.2", -0.25)
    xb = b.x.values[0]
    t = b.x.t[:-1]
    sel = (xb[1:, 1] > 0) & (t > b.events["t_abs_on"][0])
    r1 = _parity_r1(plant, xb)[sel]
    # true dx2/dt = -4 N_v mu/(0.75 R_w M_v): residual = -(1/0.75 - 1) * 4 N_v mu /(R_w M_v)
    p = plant.params
    lam = slip(xb[:-1, 0], xb[:-1, 1])[sel]
    expect = -(1 / 0.75 - 1) * 4 * p["N_v"] * mu(lam) / (p["R_w"] * p["M_v"])
    assert np.allclose(r1, expect, rtol=1e-6, atol=1e-9)
    assert np.abs(r1).mean() > 2.0


def test_kf_fault_scales_torque_path_only(plant):
    a, b = _pair(plant, "F3", -0.08)
    xa, xb = a.x.values[0], b.x.values[0]
    t = a.x.t
    # before the brake acts nothing differs; the master-cylinder pressure never differs
    assert np.array_equal(xa[t < 0.5], xb[t < 0.5])
    assert np.array_equal(xa[:, 5], xb[:, 5])
    # before the first valve action the wheel pressure is the same, the torque is 8 % lower
    early = (t > 0.55) & (t < min(a.events["t_abs_on"][0], b.events["t_abs_on"][0]) - 0.01)
    assert np.allclose(xb[early, 4], xa[early, 4], rtol=1e-12)
    assert np.allclose(xb[early, 2], 0.92 * xa[early, 2], rtol=1e-9)


def test_taum_fault_changes_true_pm_but_not_the_known_input(plant):
    a, b = _pair(plant, "F5", 0.3)
    assert np.array_equal(a.u["P_m"], b.u["P_m"])
    t = a.x.t
    sel = (t > 0.5) & (t < 0.6)
    assert np.max(np.abs(a.x.values[0, sel, 5] - b.x.values[0, sel, 5])) > 0.5  # MPa
    # the known input is the nominal master-cylinder pressure, eq. (5) closed form for tau_p = tau_m
    p = plant.params
    tt = np.maximum(a.u.t - 0.5, 0)
    tau = p["tau_m"]
    pss = p["K_m"] * p["K_p"] / p["A_m"] / 1e3
    closed = np.where(a.u.t >= 0.5, pss * (1 - (1 + tt / tau) * np.exp(-tt / tau)), 0)
    assert np.max(np.abs(a.u["P_m"][0] - closed)) < 0.03 * pss  # Euler at 1 ms vs exact


def test_fault_classes_and_drawn_magnitudes(plant):
    for name, fc in FAULT_CLASSES.items():
        res = simulate(plant, Scenario(fault=name, t_end=0.5, **QUIET), runs=40, seed=1)
        m = res.magnitudes
        if fc.param is None:
            assert np.all(m == 0)
            continue
        a = np.abs(m) if fc.symmetric else m
        assert np.all((a >= fc.lo) & (a <= fc.hi)), name
        assert np.unique(m).size == 40
        if fc.symmetric:
            assert (m > 0).any() and (m < 0).any()
        assert np.allclose(res.params[fc.param], plant.params[fc.param] * (1 + m))
    grid = simulate(plant, Scenario(fault="F4", t_end=0.5, grid_step=0.01, **QUIET), runs=200, seed=1)
    sizes = np.round(np.abs(grid.magnitudes) * 100, 9)
    assert set(sizes) == set(range(2, 11))  # ±2 %, ±3 %, ..., ±10 % as in Section VI
    with pytest.raises(DataError, match=r"outside fault class F3"):
        Scenario(fault="F3", magnitude=0.2)
    with pytest.raises(DataError, match="unknown fault 'F9'"):
        Scenario(fault="F9")


# ------------------------------------------------------------------ noise
def test_measurement_noise_variance(plant):
    res = simulate(plant, Scenario(fault="F1.1", magnitude=-0.03), runs=10, seed=7, keep_states=True)
    x = res.x.values  # same 10 ms grid as y
    v1 = res.y["omega_w"] - 0.97 * x[..., 0]
    v2 = res.y["omega_v"] - x[..., 1]
    for v in (v1, v2):
        assert v.var() == pytest.approx(0.004, rel=0.05)
        assert abs(v.mean()) < 4 * np.sqrt(0.004 / v.size)


@pytest.mark.parametrize("snr", [23.0, 17.0])
def test_process_noise_matches_requested_snr(plant, nominal, snr):
    """Recover w_k = (x_{k+1} - x_k)/dt - f(x_k) with the model's f, compare with SNR * mean square."""
    ms = np.mean(nominal.x.values[0] ** 2, axis=0)  # nominal noise-free run, every 1 ms step
    res = simulate(plant, Scenario(snr_db=snr, meas_var=0.0), runs=2, seed=11, keep_states=True,
                   state_stride=1)
    ratio = 10 ** (-snr / 10)
    for r in range(2):
        x = res.x.values[r]
        t = res.x.t
        end = min(res.events["t_abs_off"][r], res.events["t_stop"][r]) - 0.01
        sel = t[:-1] < end
        u = np.zeros((sel.sum(), 9))
        u[:, 0] = plant.pedal_force(t[:-1][sel], 0.5)
        w = (x[1:][sel] - x[:-1][sel]) / 1e-3 - plant.f(0.0, x[:-1][sel], u, plant.params)
        for i in (0, 1, 2, 3, 5):  # x5 is advanced by the exact orifice step, not Euler
            assert w[:, i].var() / ms[i] == pytest.approx(ratio, rel=0.05), (snr, r, i)
    assert np.allclose(res.process_noise_var, ratio * ms, rtol=1e-9)


def test_process_noise_held_over_a_sample_when_asked(plant):
    """noise_hold = 10 ms: the recovered w_k is one draw per 10 ms block, with the same variance."""
    res = simulate(plant, Scenario(snr_db=20.0, meas_var=0.0, noise_hold=0.01, t_end=2.0), runs=1, seed=3,
                   keep_states=True, state_stride=1)
    x, t = res.x.values[0], res.x.t
    u = np.zeros((t.size - 1, 9))
    u[:, 0] = plant.pedal_force(t[:-1], 0.5)
    w = (x[1:] - x[:-1]) / 1e-3 - plant.f(0.0, x[:-1], u, plant.params)
    for i in (0, 1, 2, 3, 5):
        blocks = w[: (w.shape[0] // 10) * 10, i].reshape(-1, 10)
        assert np.max(np.abs(blocks - blocks[:, :1])) < 1e-6 * np.std(w[:, i])  # held within a block
        assert not np.allclose(blocks[1:, 0], blocks[:-1, 0])  # a new draw per block
        assert blocks[:, 0].var() / res.state_mean_square[i] == pytest.approx(0.01, rel=0.3)
    with pytest.raises(DataError, match="noise_hold"):
        Scenario(noise_hold=0.0015)


# ------------------------------------------------------------------ determinism
def test_run_identical_alone_and_in_batches_of_any_size(plant):
    sc = Scenario(fault="F4", t_end=3.0)
    big = simulate(plant, sc, runs=9, seed=5, keep_states=True)
    for i in (0, 4, 8):
        alone = simulate(plant, sc, runs=1, seed=5, first_run=i, keep_states=True)
        assert np.array_equal(alone.y.values[0], big.y.values[i])
        assert np.array_equal(alone.x.values[0], big.x.values[i])
        assert alone.magnitudes[0] == big.magnitudes[i]
    mid = simulate(plant, sc, runs=3, seed=5, first_run=3)
    assert np.array_equal(mid.y.values, big.y.values[3:6])
    other = simulate(plant, sc, runs=1, seed=6, first_run=4)
    assert not np.array_equal(other.y.values[0], big.y.values[4])


def test_run_identical_across_processes(plant, tmp_path):
    sc = Scenario(fault="F2.1", t_end=2.0)
    here = simulate(plant, sc, runs=4, seed=13)
    out = tmp_path / "y.npy"
    code = (
        "import numpy as np, json\n"
        "from fdikit.systems.abs.plant import Scenario, simulate\n"
        "r = simulate(None, Scenario(fault='F2.1', t_end=2.0), runs=1, seed=13, first_run=2)\n"
        f"np.save({str(out)!r}, r.y.values[0])\n"
        "print(json.dumps(float(r.magnitudes[0])))\n"
    )
    cp = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(cp.stdout.strip().splitlines()[-1]) == here.magnitudes[2]
    assert np.array_equal(np.load(out), here.y.values[2])


# ------------------------------------------------------------------ scale
@pytest.mark.slow
@pytest.mark.parametrize("fault", list(FAULT_CLASSES))
def test_no_nan_in_5000_runs_of_every_class(plant, fault):
    res = simulate(plant, Scenario(fault=fault), runs=5000, seed=100)
    assert np.isfinite(res.y.values).all()
    assert np.isfinite(res.events["t_abs_on"]).all()  # ABS engaged in every run
    assert np.isfinite(res.events["mean_slip"]).all()
    assert 0.08 < np.mean(res.events["mean_slip"]) < 0.25


# ------------------------------------------------------------------ known inputs, CLI, demo
def test_valve_openings_reproduce_wheel_cylinder_pressure(plant):
    """Integrating x5 of eq. (19) with the reported 10 ms mean valve openings tracks the true P_s."""
    res = simulate(plant, Scenario(**QUIET), keep_states=True)
    u = res.u.values[0]
    x = res.x.values[0]
    t = res.u.t
    assert np.all((u[:, 1:] >= 0) & (u[:, 1:] <= 1 + 1e-12))
    pre = t < 0.5
    assert np.allclose(u[pre, 1], 1.0) and np.all(u[pre, 2] == 0.0)
    assert np.sum(u[:, 2] > 0.5) >= 10  # pressure releases happen
    # open-loop integration of x5 from the true P_m with the averaged openings (1 ms Euler)
    P_s = 0.0
    rec = np.empty(t.size)
    for k in range(t.size):
        rec[k] = P_s
        for _ in range(10):
            xx = np.array([[0, 0, 0, 0, P_s, x[k, 5]]], float)
            uu = np.zeros((1, 9))
            uu[0, 1:3] = u[k, 1:]
            P_s = min(max(P_s + 1e-3 * plant.f(0.0, xx, uu, plant.params)[0, 4], 0.0), 20.0)
    assert np.mean(np.abs(rec - x[:, 4])) < 0.5  # MPa, of a 14 MPa range
    released = u[:, 2] > 0.9
    assert np.mean(x[released, 4]) < 5.0 < np.mean(x[u[:, 1] > 0.99, 4])


def test_cli_simulate_json(capsys, tmp_path):
    from fdikit.cli import main

    fig = tmp_path / "abs.png"
    rc = main(["abs", "simulate", "--fault", "F3", "--magnitude", "-0.05", "--t-end", "4", "--v0", "12",
               "--json", "--plot", str(fig)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["fault"] == "F3" and out["magnitude_mean"] == -0.05 and out["samples"] == 400
    assert 0.05 < out["mean_slip_abs"] < 0.3 and fig.stat().st_size > 10_000
    assert main(["abs", "simulate", "--fault", "F3", "--magnitude", "0.5"]) == 2
    assert "outside fault class F3" in capsys.readouterr().err


def test_demo_summary_is_one_short_stop():
    d = absp.demo_summary()
    assert d["runs"] == 1 and d["stopped_fraction"] == 1.0
    # stop from 15 m/s: distance at least v0^2 / (2 g mu_max / 4)
    assert d["stopping_distance"] >= 15.0**2 / (2 * G * MU_MAX / 4)


def test_generic_linearisation_of_the_plant(plant):
    """fdikit.model.linearize on ABSPlant gives the closed-form linear entries of eq. (19)/(30)."""
    from fdikit.model.linearize import linearize

    p = plant.params
    u0 = dict.fromkeys(absp.INPUTS, 0.0)
    u0.update(F_p=7.0, u_in=0.5)
    lm = linearize(plant, [60.0, 75.0, 1100.0, 0.0, 11.0, 14.0], u0, faults=["param:K_f"])
    A = lm.A
    assert A[0, 2] == pytest.approx(-1 / p["I_w"], rel=1e-6)
    assert A[3, 2:5] == pytest.approx([-p["omega_n"] ** 2, -2 * p["zeta"] * p["omega_n"],
                                       p["omega_n"] ** 2 * p["K_f"]], rel=1e-6)
    assert A[5, 5] == pytest.approx(-1 / p["tau_m"], rel=1e-6)
    # d(dx5/dt)/dP_s of the orifice: -beta/V C_in u_in A_0 sqrt(2/rho) / (2 sqrt(dP)) (dP in Pa)
    dP = 3e6
    d = -p["beta_s"] / p["V_s"] * p["C_in"] * 0.5 * p["A_0"] * np.sqrt(2 / p["rho"]) / (2 * np.sqrt(dP)) * 1e6
    assert A[4, 4] == pytest.approx(d, rel=1e-5)
    assert lm.B_of("f")[3, 0] == pytest.approx(p["omega_n"] ** 2 * 11.0, rel=1e-6)  # d/dK_f


# ------------------------------------------------------------------ opt-in pedal ramp (experiment)
def test_pedal_ramp_force_is_linear_then_held(plant):
    T, tb, Kp = 3.0, 0.5, plant.params["K_p"]
    t = np.linspace(0.0, 6.0, 601)
    F = plant.pedal_force(t, tb, ramp=T)
    closed = np.clip((t - tb) / T, 0.0, 1.0) * Kp  # K_p reached linearly over T, then held
    assert np.allclose(F, closed, rtol=0, atol=1e-12)
    on = (t > tb) & (t < tb + T)
    assert np.allclose(np.diff(F[on]) / np.diff(t[on]), Kp / T)  # constant slope K_p/T kN/s
    # the step of eq. (4) is the default profile
    assert np.allclose(plant.pedal_force(t, tb), np.where(t >= tb, Kp * (1 - np.exp(-(t - tb) / 0.02)), 0))


def test_pedal_ramp_drives_plant_and_nominal_pm_input_alike(plant):
    T, tb = 3.0, 0.5
    sc = Scenario(pedal="ramp", pedal_ramp=T, t_end=5.0, **QUIET)
    res = simulate(plant, sc, keep_states=True, state_stride=10)
    p = plant.params
    # first-order lag (5) of a ramp, closed form: P_ss/T (s - tau (1 - exp(-s/tau))), then the held value
    tau, pss = p["tau_m"], p["K_m"] * p["K_p"] / p["A_m"] / 1e3
    t = res.u.t
    s = np.clip(t - tb, 0.0, None)
    sr = np.minimum(s, T)
    ramp_part = pss / T * (sr - tau * (1 - np.exp(-sr / tau)))
    closed = np.where(s <= T, ramp_part, pss - (pss - ramp_part) * np.exp(-(s - T) / tau))
    assert np.max(np.abs(res.u["P_m"][0] - closed)) < 5e-3 * pss  # Euler at 1 ms vs exact
    # the plant's true P_m (no fault) is the same trajectory as the observer's nominal input
    assert np.max(np.abs(res.x.values[0, :, 5] - res.u["P_m"][0])) < 1e-9
    # the ABS engages later than with the step (the point of the experiment)
    step = simulate(plant, Scenario(t_end=5.0, **QUIET))
    assert res.events["t_abs_on"][0] > step.events["t_abs_on"][0] + 1.0


def test_default_pedal_is_bitwise_the_step(plant):
    kw = {"fault": "F5", "magnitude": 0.2, "t_end": 3.0, "v0": 15.0}
    a = simulate(plant, Scenario(**kw), runs=3, seed=4, keep_states=True)
    b = simulate(plant, Scenario(pedal="step", **kw), runs=3, seed=4, keep_states=True)
    assert np.array_equal(a.y.values, b.y.values) and np.array_equal(a.u.values, b.u.values)
    assert np.array_equal(a.x.values, b.x.values)
    c = simulate(plant, Scenario(pedal="ramp", pedal_ramp=1.0, **kw), runs=3, seed=4)
    assert not np.array_equal(a.y.values, c.y.values)


def test_pedal_ramp_bad_arguments(capsys):
    from fdikit.cli import main

    with pytest.raises(DataError, match="pedal_ramp > 0"):
        Scenario(pedal="ramp")
    with pytest.raises(DataError, match="only used with pedal='ramp'"):
        Scenario(pedal_ramp=3.0)
    with pytest.raises(DataError, match="'step' or 'ramp'"):
        Scenario(pedal="sine")
    rc = main(["abs", "simulate", "--pedal-ramp", "2", "--t-end", "4", "--v0", "12", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["pedal"] == "ramp" and out["pedal_ramp"] == 2.0
