"""ABS residual generators (luo-et-al, Section V) and the parity signal helpers."""

import numpy as np
import pytest
from scipy.interpolate import make_smoothing_spline
from scipy.signal import sosfilt

from fdikit.errors import DataError
from fdikit.residuals.parity import (
    CausalDerivative,
    CausalLowPass,
    butter_sos,
    causal_spline_derivative,
    lowpass,
    spline_derivative,
    spline_lam,
)
from fdikit.signals import Signals
from fdikit.systems.abs.plant import PARAMS, Scenario, mu, simulate, slip
from fdikit.systems.abs.residuals import (
    ABSObserver,
    ParityR1,
    ParityR2,
    linear_part,
    observer_gain,
    r2_magnitude_study,
)


@pytest.fixture(scope="module")
def short_runs():
    res = simulate(None, Scenario(t_end=4.0), runs=3, seed=5)
    return res.y.concat_channels(res.u)


# ------------------------------------------------------------------ parity helpers
def test_causal_spline_derivative_equals_refitting_every_window():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.normal(size=60))
    dt, window, lam = 0.01, 12, spline_lam(4.0, 0.01)
    d = causal_spline_derivative(x, dt, window=window, lam=lam)
    t = np.arange(window) * dt
    for k in (window - 1, 30, 59):  # brute force: a new smoothing spline on each window
        spl = make_smoothing_spline(t, x[k - window + 1:k + 1], lam=lam)
        assert d[k] == pytest.approx(float(spl.derivative()(t[-1])), rel=1e-9, abs=1e-9)
    # before the window is full: padded with the first sample
    xp = np.r_[np.full(window - 1, x[0]), x[:5]]
    spl = make_smoothing_spline(t, xp[-window:], lam=lam)
    assert d[4] == pytest.approx(float(spl.derivative()(t[-1])), rel=1e-9, abs=1e-9)


def test_spline_derivatives_without_smoothing():
    # lam = 0: the natural interpolating cubic spline; exact for a cubic away from the ends
    # (the natural end conditions f'' = 0 perturb the first/last knots only, decaying ~0.27 per knot)
    t = np.arange(60) * 0.01
    x = 2.0 + 3.0 * t - 4.0 * t**2 + 5.0 * t**3
    for order, ref in ((1, 3 - 8 * t + 15 * t**2), (2, -8 + 30 * t)):
        d = spline_derivative(x, 0.01, lam=0.0, order=order)
        np.testing.assert_allclose(d[20:-20], ref[20:-20], atol=1e-6 * 10**order)
    # the causal end-point derivative is exact for a line, whatever the smoothing
    for lam in (0.0, 1e-3):
        dc = causal_spline_derivative(1.5 - 0.7 * t, 0.01, window=10, lam=lam)
        np.testing.assert_allclose(dc[9:], -0.7, atol=1e-9)  # once the window is full


def test_spline_lam_sets_the_half_power_frequency():
    # gain of the offline smoother on a sinusoid at the cut-off, away from the record ends: ~1/2
    dt, fc = 0.01, 3.0
    t = np.arange(3000) * dt
    x = np.sin(2 * np.pi * fc * t)
    s = spline_derivative(x, dt, lam=spline_lam(fc, dt), order=0)
    gain = np.std(s[500:-500]) / np.std(x[500:-500])
    assert gain == pytest.approx(0.5, abs=0.05)


def test_lowpass_causal_matches_sosfilt_and_streaming():
    sos = butter_sos(10, 10.0, 100.0)
    rng = np.random.default_rng(2)
    x = rng.normal(size=(2, 80, 3))
    y = lowpass(x, sos, axis=1)
    # independent: plain sosfilt on the signal minus its first value, plus that value (steady start)
    ref = sosfilt(sos, x - x[:, :1], axis=1) + x[:, :1]
    np.testing.assert_allclose(y, ref, atol=1e-10)
    f = CausalLowPass(sos)
    f.reset(2, 3)
    ys = np.stack([f.step(x[:, k]) for k in range(80)], axis=1)
    np.testing.assert_allclose(ys, y, atol=1e-12)
    d = CausalDerivative(8, 0.01, 1e-5)
    d.reset(2, 3)
    ds = np.stack([d.step(x[:, k]) for k in range(80)], axis=1)
    np.testing.assert_allclose(ds, causal_spline_derivative(x, 0.01, window=8, lam=1e-5, axis=1), atol=1e-9)
    # 10 Hz Butterworth: -3 dB at the cut-off, zero phase has the squared gain
    from scipy.signal import sosfreqz

    _, h = sosfreqz(sos, worN=[10.0], fs=100.0)
    assert abs(h[0]) == pytest.approx(2**-0.5, rel=1e-6)


# ------------------------------------------------------------------ r1, eq. (25)
def test_r1_batch_equals_streaming(short_runs):
    g = ParityR1(0.01)
    b = g.run(short_runs).values
    g.reset(short_runs.runs)
    u, y = g._inputs(short_runs)
    s = np.stack([g.step(u[:, k], y[:, k]) for k in range(short_runs.n_samples)], axis=1)
    np.testing.assert_allclose(s, b, rtol=1e-9, atol=1e-9)
    with pytest.raises(DataError, match="offline"):
        ParityR1(0.01, variant="zero_phase").step(np.zeros((1, 0)), y[:, 0])


def test_r1_by_hand_on_a_steady_deceleration():
    # y2 decelerating at a constant rate, y1 at a fixed slip: r1 = dy2/dt + 4 N_v mu / (R_w M_v)
    t = np.arange(300) * 0.01
    y2 = 80.0 - 6.0 * t
    y1 = 0.9 * y2
    g = ParityR1(0.01)
    r = g.run(Signals(t, np.stack([y1, y2], -1), ["omega_w", "omega_v"]))["r1"][0]
    p = PARAMS
    expect = -6.0 + 4 * p["N_v"] * float(mu(0.1)) / (p["R_w"] * p["M_v"])
    np.testing.assert_allclose(r[150:], expect, atol=1e-3)


def _mean_r1(fault, magnitude):
    sc = Scenario(fault=fault, magnitude=magnitude, snr_db=None, meas_var=0.0)
    res = simulate(None, sc, runs=1, seed=0, keep_states=True)
    r1 = ParityR1(0.01).run(res.y.concat_channels(res.u))["r1"][0]
    x = res.x.values[0]
    R_true = float(np.broadcast_to(res.params["R_w"], (1,))[0])
    p = PARAMS
    # eq. (25) evaluated on the true states with the true dynamics dx2/dt = -4 N_v mu/(R_true M_v)
    m = mu(slip(x[:, 0], x[:, 1]))
    expect = 4 * p["N_v"] * m / p["M_v"] * (1 / p["R_w"] - 1 / R_true)
    sl = slice(150, 900)  # braking, ABS active, car still moving
    return float(np.mean(r1[sl])), float(np.mean(expect[sl]))


def test_r1_ignores_kf_and_iw_faults_but_sees_rw():
    base, _ = _mean_r1("F0", None)
    for fault in ("F3", "F4"):
        for m in (-0.1, 0.1):
            val, expect = _mean_r1(fault, m)
            assert expect == 0.0  # eq. (25) contains neither K_f nor I_w
            assert abs(val - base) < 0.05, (fault, m, val, base)
    val, expect = _mean_r1("F2.2", -0.25)
    assert expect < -2.0
    assert val - base == pytest.approx(expect, rel=0.1)


# ------------------------------------------------------------------ r2, eq. (26)
def test_r2_batch_equals_streaming_and_is_dominated_by_noise(short_runs):
    g = ParityR2(0.01)
    b = g.run(short_runs).values
    g.reset(short_runs.runs)
    u, y = g._inputs(short_runs)
    s = np.stack([g.step(u[:, k], y[:, k]) for k in range(short_runs.n_samples)], axis=1)
    np.testing.assert_allclose(s, b, rtol=1e-8, atol=1e-6 * np.abs(b).max())
    res = simulate(None, Scenario(), runs=4, seed=2)
    out = r2_magnitude_study(res.y, res.u)
    assert out["rms_r2_causal"] > out["rms_torque_term"]  # nominal r2 larger than the term it balances
    assert out["fault_to_noise_kf10_causal"] < 0.2  # a 10 % K_f change is buried


# ------------------------------------------------------------------ observer, eqs. (29)-(33)
@pytest.mark.filterwarnings("ignore:Convergence was not reached")  # scipy place_poles' robustness loop
def test_observer_gain_is_the_kalman_bucy_gain():
    import control

    A, C = linear_part()
    qv = np.array([11.5, 14.0, 5659.0, 1408.0, 0.78])
    L = observer_gain(process_var=qv)
    Lc, _, _ = control.lqe(A, np.eye(5), C, np.diag(qv * 1e-3), np.eye(2) * 0.004 * 0.01)
    np.testing.assert_allclose(L, Lc, rtol=1e-6, atol=1e-6)
    L2 = observer_gain(method="place", poles=[-2, -3, -4, -5, -6])
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(A - L2 @ C).real), [-6, -5, -4, -3, -2], atol=1e-6)
    from fdikit.errors import ConditionError

    with pytest.raises(ConditionError, match="hold"):
        observer_gain(method="place", poles=[-2, -3, -4, -5, -200])


def test_observer_batch_equals_streaming(short_runs):
    g = ABSObserver(0.01)
    b = g.run(short_runs).values
    g.reset(short_runs.runs)
    u, y = g._inputs(short_runs)
    s = np.stack([g.step(u[:, k], y[:, k]) for k in range(short_runs.n_samples)], axis=1)
    np.testing.assert_array_equal(s, b)


def test_observer_tracks_noise_free_nominal_and_sees_faults():
    def rms(fault, mag):
        res = simulate(None, Scenario(fault=fault, magnitude=mag, snr_db=None, meas_var=0.0), runs=1, seed=0)
        r = ABSObserver(0.01).run(res.y.concat_channels(res.u)).values[0]
        return np.sqrt(np.mean(r[:1000] ** 2, axis=0))

    # rad/s: with the held injection of eq. (32) the model and plant agree up to the valve
    # openings averaged over each 10 ms interval; a tenth of the measurement noise's 0.063 rad/s
    nom = rms("F0", None)
    assert np.all(nom < 0.0063)
    assert rms("F1.2", -0.05)[0] > 5 * nom[0]  # sensor fault on the wheel speed -> r3
    f22 = rms("F2.2", -0.25)
    assert f22[0] > 5 * nom[0] and f22[1] > 3 * nom[1]
    assert rms("F3", 0.1)[0] > 3 * nom[0]


def test_held_injection_removes_the_sample_and_hold_bias():
    # continuous injection L (y_k - x_hat(t)) against a held measurement of a speed falling at s
    # rad/s^2 settles at the bias r ~ s dt / 2 (the held value is on average dt/2 old); the held
    # injection L (y_k - x_hat_k) of eq. (32) leaves none
    res = simulate(None, Scenario(snr_db=None, meas_var=0.0), runs=1, seed=0)
    sig = res.y.concat_channels(res.u)
    t = sig.t
    win = (t >= 4.0) & (t < 8.0)
    y2 = res.y["omega_v"][0]
    s = float(np.mean(np.diff(y2)[win[:-1]]) / 0.01)  # mean deceleration from the samples
    assert s < -5.0
    cont = ABSObserver(0.01, injection="continuous", v_min=0.0).run(sig)["r4"][0]
    held = ABSObserver(0.01, v_min=0.0).run(sig)["r4"][0]
    assert np.mean(cont[win]) == pytest.approx(s * 0.01 / 2, rel=0.15)
    assert abs(np.mean(held[win])) < 0.01 * abs(s * 0.01 / 2)


def test_observer_residual_validity_below_v_min_and_table_iii_variances():
    res = simulate(None, Scenario(snr_db=23.0), runs=8, seed=11)
    sig = res.y.concat_channels(res.u)
    g = ABSObserver(0.01)
    r = g.run(sig).values
    slow = PARAMS["R_w"] * sig["omega_v"] < 3.0
    assert slow.any() and (~slow).any()
    assert np.all(r[slow] == 0.0) and np.all(r[:, 1:][~slow[:, 1:]] != 0.0)  # sample 0: x_hat = y_0
    # streaming over whole stops (through the v_min region) equals the batch run
    g.reset(sig.runs)
    u, y = g._inputs(sig)
    np.testing.assert_array_equal(np.stack([g.step(u[:, k], y[:, k]) for k in range(sig.n_samples)], 1), r)
    # Table III: sigma^2 of r3 / r4 = 4.5e-3 / 4.0e-3, i.e. the measurement noise variance 0.004 plus
    # little: the observer residual is white measurement noise plus a small process-noise share
    ok = r[:, 1:][~slow[:, 1:]].reshape(-1, 2)
    var = ok.var(axis=0)
    assert np.all(var > 0.004 * 0.9) and np.all(var < 4.5e-3 * 1.25), var
    assert np.all(np.abs(ok.mean(axis=0)) < 0.1 * np.sqrt(0.004))


# ------------------------------------------------------------------ bad input
def test_bad_input_errors(short_runs):
    v = short_runs.values.copy()
    v[1, 37, 0] = np.nan
    bad = Signals(short_runs.t, v, short_runs.names, check=False)
    for g in (ParityR1(0.01), ABSObserver(0.01), ParityR2(0.01)):
        with pytest.raises(DataError, match="omega_w"):
            g.run(bad)
    g = ABSObserver(0.01)
    g.reset(1)
    with pytest.raises(DataError, match="non-finite"):
        g.step([[14.0, 1.0, 0.0]], [[np.nan, 80.0]])
    short = short_runs.window(0.0, 0.1)
    with pytest.raises(DataError, match="shorter"):
        ParityR1(0.01).run(short)
    with pytest.raises(DataError, match="window"):
        ParityR1(0.01, window=3)
    with pytest.raises(DataError, match="variant"):
        ParityR1(0.01, variant="acausal")


def test_generators_compose_in_a_monitor_batch_equals_streaming(short_runs):
    from fdikit.detect import GLRT, Hold
    from fdikit.monitor import Monitor

    mon = Monitor([ParityR1(0.01), ABSObserver(0.01)],
                  [GLRT(["r1", "r3", "r4"], [0.05, -0.03, -0.03], [0.18, 0.008, 0.005], 10),
                   Hold(["r1:glrt", "r3:glrt", "r4:glrt"], [50.0, 40.0, 20.0], 5, absolute=False)])
    b = mon.run(short_runs)
    s = mon.stream(short_runs)
    np.testing.assert_allclose(s.residuals.values, b.residuals.values, rtol=1e-9, atol=1e-9)
    sv, bv = s.statistics.values, b.statistics.values
    np.testing.assert_allclose(sv[:, :, :3], bv[:, :, :3], rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(s.statistics.values[:, :, 3:], b.statistics.values[:, :, 3:])


# ------------------------------------------------------------------ design artifacts (issue 9)
@pytest.mark.filterwarnings("ignore:Convergence was not reached")  # scipy place_poles' robustness loop
@pytest.mark.parametrize("make", [
    lambda: ParityR1(0.01),
    lambda: ParityR1(0.01, {"R_w": 0.3}, variant="zero_phase", order=8, cutoff_hz=8.0, window=30),
    lambda: ParityR2(0.01, substeps=5),
    lambda: ABSObserver(0.01),
    lambda: ABSObserver(0.01, L=observer_gain(method="place", poles=[-3, -4, -5, -6, -7])),
])
def test_residual_generators_round_trip_as_artifacts(make, short_runs, tmp_path):
    from fdikit.base.artifacts import load_artifact, save_artifact

    g = make()
    path = save_artifact(tmp_path / "gen", g)
    h = load_artifact(path, expect_inputs=g.u_names + g.y_names, expect_outputs=g.output_names)
    assert type(h) is type(g)
    a, b = g.run(short_runs), h.run(short_runs)
    assert a.names == b.names
    np.testing.assert_array_equal(a.values, b.values)  # bitwise equal
    if isinstance(g, ABSObserver):
        np.testing.assert_array_equal(h.L, g.L)
    # streaming (causal variants) from the loaded design equals the batch run of the original
    if getattr(h, "variant", "causal") == "causal":
        h.reset(short_runs.runs)
        u = short_runs.values[:, :, short_runs.index(h.u_names)] if h.u_names else None
        y = short_runs.values[:, :, short_runs.index(h.y_names)]
        for k in range(0, 60):
            out = h.step(u[:, k] if u is not None else np.zeros((y.shape[0], 0)), y[:, k])
            np.testing.assert_allclose(out, a.values[:, k], rtol=1e-9, atol=1e-9)


def test_loaded_r1_refuses_sections_of_another_order():
    d = ParityR1(0.01).to_dict()
    d["sos"] = d["sos"][:3]
    with pytest.raises(DataError, match="Butterworth sections"):
        ParityR1.from_dict(d)
