"""Issue 31: the SMO reconstructor keeps its word -- validated inputs, finite self-checks,
refusals with numbers, noise designs that never crash, a status that is not "sliding" while the
estimate is wrong after a fault jump."""

import warnings

import numpy as np
import pytest

from fdikit.errors import ConditionError, DataError, ModelError
from fdikit.model.linear import LinearFaultModel
from fdikit.model.random_systems import as_fault_model, random_fault_system
from fdikit.residuals.smo import SLIDING, design_reconstructor, integrate_observers, simulate_plant

try:  # the design's module (self_check is looked up there)
    from fdikit.residuals.smo import design as smo_design
except ImportError:  # a single-module smo (before the package)
    import fdikit.residuals.smo as smo_design


def _model(seed):
    A, M, C, Q = random_fault_system(seed)
    return (A, M, C, Q), as_fault_model(A, M, C, Q)


# ----------------------------------------------------------------------------- validation
def test_a_1d_control_matrix_of_the_wrong_length_is_named():
    (A, _M, C, _Q), _m = _model(1)
    with pytest.raises(ModelError, match="B given as a 1-D array"):
        LinearFaultModel(A, np.ones(A.shape[0] - 1), C)


def test_a_non_finite_fault_direction_is_refused():
    (A, M, C, _Q), _m = _model(1)
    b = M[:, 0].copy()
    b[2] = np.nan
    with pytest.raises(ModelError, match="non-finite"):
        LinearFaultModel(A, np.zeros((A.shape[0], 0)), C, faults=[("f0", b, None)])


def test_D1_must_be_positive_definite():
    (_A, _M, C, _Q), m = _model(1)
    with pytest.raises(DataError, match="D1 must be symmetric positive definite"):
        design_reconstructor(m, D1=-np.eye(C.shape[0]), check=False, hinf_check=False)


def test_a_step_too_large_for_the_observers_is_refused_with_numbers():
    _sys, m = _model(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ConditionError, match="too large for the observer dynamics") as ei:
            design_reconstructor(m, dt=0.5, hinf_check=False)
    assert ei.value.condition == "step"
    assert max(ei.value.details["step_spectral_radius"]) > 1.0


def test_the_lmi_refusal_says_why_and_what_to_try():
    (_A, _M, C, _Q), m = _model(4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ConditionError, match="What to try") as ei:
            design_reconstructor(m, D1=1e-3 * np.eye(C.shape[0]), check=False, hinf_check=False)
    assert "badly scaled" in ei.value.details["why"]
    # and it names the invariant zeros, the fixed modes of the sliding motion (46)
    assert "Invariant zeros of (A, M, C)" in str(ei.value)
    assert "invariant_zeros" in ei.value.details and "closest_zero_damping" in ei.value.details


# ----------------------------------------------------------------------------- finite ladder
def _fake_checks(monkeypatch, nan_layers):
    real = smo_design.self_check

    def fake(rec, **kw):
        sc = real(rec, **kw)
        if rec.secondary["delta"] in nan_layers:
            sc = {**sc, "step_error": float("nan")}
        return sc

    monkeypatch.setattr(smo_design, "self_check", fake)


def test_a_nan_self_check_is_never_chosen(monkeypatch):
    _sys, m = _model(1)
    _fake_checks(monkeypatch, {1e-5})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(m, accuracy=1e-14, check_horizon=0.1, hinf_check=False)
    assert rec.secondary["delta"] != 1e-5
    assert np.isfinite(rec.info["self_check"]["step_error"])
    tried = rec.info["boundary_layers"]["tried"]
    assert tried[0]["skipped"] == "non-finite self-check"


def test_no_finite_self_check_refuses_the_design(monkeypatch):
    _sys, m = _model(1)
    _fake_checks(monkeypatch, set(smo_design.DELTA_LADDER))
    with pytest.raises(ConditionError, match="non-finite self-check"):
        design_reconstructor(m, check_horizon=0.05, hinf_check=False)


# ----------------------------------------------------------------------------- noise
def test_noise_design_with_an_unstable_step_refuses_clearly_instead_of_crashing():
    _sys, m = _model(1)
    with pytest.raises(ConditionError, match="no low-pass time constant gives a stable runtime step"):
        design_reconstructor(m, noise_std=1e-5, dt=1e-3, check=False, hinf_check=False)


def test_a_large_predicted_noise_error_warns_with_the_number():
    _sys, m = _model(1)
    with pytest.warns(UserWarning, match="predicted reconstruction error is"):
        rec = design_reconstructor(m, noise_std=1e-5, check=False, hinf_check=False)
    assert rec.info["noise"]["predicted_error"] > 0.1


# ----------------------------------------------------------------------------- status
@pytest.fixture(scope="module")
def designs():
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in (1, 2):
            (A, M, C, _Q), m = _model(seed)
            rec = design_reconstructor(m, hinf_check=False, check_horizon=0.3)
            g = rec.info["gains"]
            small = design_reconstructor(m, hinf_check=False, check_horizon=0.3,
                                         rho=g["rho"] / 5, rho2=g["rho2"] / 5)
            out[seed] = ((A, M, C), rec, small)
    return out


def _silent_errors(rec, A, M, C, shape):
    dt = rec.dt
    t = np.arange(round(0.8 / dt) + 1) * dt
    q = M.shape[1]
    d = np.where(np.arange(q) % 2 == 0, 1.0, -1.0) / np.sqrt(q)
    s = {"square": np.where(np.sin(2 * np.pi * (t - 0.2)) >= 0, 1.0, -1.0) * (t >= 0.2),
         "step": 0.5 * (t >= 0.2) + 0.5 * (t >= 0.5),
         "ramp": np.clip((t - 0.2) / 0.3, 0.0, 1.0)}[shape]
    f = s[:, None] * d
    Y = simulate_plant(A, M, C, f, dt)
    fh, st = integrate_observers(rec, np.zeros((1, t.size, 0)), Y, return_status=True)
    # y[k] cannot see f[k] yet (one sample of causal delay): score against f[k] or f[k-1]
    fprev = np.vstack([f[:1], f[:-1]])
    err = np.minimum(np.linalg.norm(fh[0] - f, axis=1), np.linalg.norm(fh[0] - fprev, axis=1))
    return int(np.sum((err > 0.05) & (st[0, :, 0] == SLIDING))), fh


@pytest.mark.parametrize("shape", ["square", "step"])
@pytest.mark.parametrize("gains", ["default", "undersized"])
def test_no_wrong_estimate_is_called_sliding(designs, shape, gains):
    for (A, M, C), rec, small in designs.values():
        n_bad, _fh = _silent_errors(rec if gains == "default" else small, A, M, C, shape)
        assert n_bad == 0


def test_the_status_does_not_change_fhat(designs):
    (A, M, C), rec, _small = designs[1]
    n_on, fh = _silent_errors(rec, A, M, C, "square")
    assert n_on == 0
    old = rec.transient_level
    try:
        rec.transient_level = 0.0
        n_off, fh_off = _silent_errors(rec, A, M, C, "square")
    finally:
        rec.transient_level = old
    assert np.array_equal(fh, fh_off)
    assert n_off > 0  # without the transient test the jumps are called sliding


def test_the_tail_of_the_reaching_after_a_jump_is_not_called_sliding():
    # issue 31, random system 31 (a slow invariant zero at -0.012): after the square wave's
    # 1 -> -1 jump the injection's move falls under transient_level a sample before the
    # estimate is within 5 % (5.4 % off, called sliding without the hold)
    A, M, C, Q = random_fault_system(31, "rd2_zero")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(as_fault_model(A, M, C, Q), hinf_check=False)
    assert rec.transient_hold >= 1
    dt = rec.dt
    t = np.arange(round(0.8 / dt) + 1) * dt
    s = np.where(np.sin(2 * np.pi * (t - 0.1)) >= 0, 1.0, -1.0) * (t >= 0.1)
    f = s[:, None] * (np.array([1.0]) if M.shape[1] == 1 else np.array([0.8, -0.6]))
    Y = simulate_plant(A, M, C, f, dt)
    fprev = np.vstack([f[:1], f[:-1]])
    n_bad, n_flagged = {}, {}
    for hold in (rec.transient_hold, 0):
        rec.transient_hold = hold
        fh, st = integrate_observers(rec, np.zeros((1, t.size, 0)), Y, return_status=True)
        err = np.minimum(np.linalg.norm(fh[0] - f, axis=1), np.linalg.norm(fh[0] - fprev, axis=1))
        n_bad[hold] = int(np.sum((err > 0.05) & (st[0, :, 0] == SLIDING)))
        n_flagged[hold] = int(np.sum(st[0, :, 0] != SLIDING))
    held = max(n_bad)
    assert n_bad[held] == 0 and n_bad[0] > 0
    # the hold costs a few samples per jump (two jumps here), not a stretch
    assert n_flagged[0] < n_flagged[held] <= n_flagged[0] + 2 * 2 * held


def test_the_transient_hold_is_validated_and_saved(designs):
    from fdikit.residuals.smo import SlidingModeReconstructor

    _sys, rec, _small = designs[1]
    back = SlidingModeReconstructor.from_dict(rec.to_dict())
    assert back.transient_hold == rec.transient_hold > 0
    d = rec.to_dict()
    del d["transient_hold"]  # an artifact saved before the hold keeps its old status
    assert SlidingModeReconstructor.from_dict(d).transient_hold == 0
    d["transient_hold"] = -1
    with pytest.raises(DataError, match="transient_hold"):
        SlidingModeReconstructor.from_dict(d)


# ----------------------------------------------------------------------------- L2 bound, whole band
def test_the_band_wide_probe_refuses_a_layer_the_low_frequency_probe_accepted():
    # seed 2: gamma-bar 1.6e-4; the paper's 1e-5 layer meets it on xi at 0.5-8 rad/s (the old
    # probe claimed the bound) and misses it by two orders at 3e4 rad/s
    _sys, m = _model(2)
    rec = design_reconstructor(m, xi_bound=1.0, delta=1e-5, delta2=1e-5, hinf_check=False)
    info, sc = rec.info, rec.info["self_check"]
    assert sc["xi_gain_smooth"] <= info["l2_bound"]  # what the old probe saw
    assert info["l2_bound_claimed"] is False
    assert info["l2_bound_worst_ratio"] > 10 and info["l2_bound_worst_w"] > 1e3
    assert "rad/s" in info["l2_bound_note"]
    probes = sc["xi_probes"]
    assert len(probes) >= 5 and max(p["w"] for p in probes) == pytest.approx(info["l2_bound_band_rad_s"])


# ----------------------------------------------------------------------------- large plants
def test_the_primary_riccati_solution_is_the_lmi_optimum():
    from fdikit.design.smo_lmi import primary_smo_lmi

    _sys, m = _model(2)
    rec = design_reconstructor(m, check=False, hinf_check=False)
    cf = rec.details["canonical"]
    V1, V2 = 100.0 * np.eye(cf.A.shape[0]), np.eye(cf.C.shape[0])
    a = primary_smo_lmi(cf.A, cf.C, V1, V2, method="lmi")
    b = primary_smo_lmi(cf.A, cf.C, V1, V2, method="riccati")
    assert b.solver["solver"] == "riccati" and b.solver["verified"]
    assert b.trace_X == pytest.approx(a.trace_X, rel=1e-4)
    for x, y in ((a.L, b.L), (a.Gl, b.Gl), (a.Po, b.Po)):
        assert np.abs(x - y).max() <= 1e-4 * np.abs(x).max()


@pytest.mark.slow
def test_a_60_state_random_plant_designs():
    # the time is the benchmark's to print (bench_smo_random.py --large 60)
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_smo_random.py"
    spec = importlib.util.spec_from_file_location("bench_smo_random", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    A, M, C, Q = bench.large_system(0, 60)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(as_fault_model(A, M, C, Q), hinf_check=False)
    assert rec.info["n_aug"] == 62 and rec.info["solver"]["primary"]["solver"] == "riccati"
    assert rec.info["l2_bound"] > 0 and rec.info["l2_bound_claimed"] is not None


# ----------------------------------------------------------------------------- noise by simulation
def test_the_noise_design_chooses_by_simulated_error_and_states_it():
    (A, M, C, _Q), m = _model(0)
    sigma = 5e-5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(m, noise_std=sigma, hinf_check=False, check_horizon=0.5)
    nz = rec.info["noise"]
    assert nz["predicted_by"] == "simulation"
    errs = [c["error"] for c in nz["candidates"] if "error" in c]
    assert nz["predicted_error"] == min(errs)
    assert {c["delta2"] for c in nz["candidates"]} >= set(smo_design.DELTA_LADDER)
    assert (rec.primary["delta"], rec.secondary["delta"], rec.lpf_tau) == (nz["delta"], nz["delta2"],
                                                                             nz["lpf_tau"])
    # independent: another noise realisation, a sinusoid whose rate is fault_rate (default 10)
    h = rec.dt
    t = np.arange(round(0.5 / h) + 1) * h
    f = np.sin(10.0 * t)[:, None]
    Y = simulate_plant(A, M, C, f, h)
    Y = Y + sigma * np.random.default_rng(99).standard_normal(Y.shape)
    fh = integrate_observers(rec, np.zeros((1, t.size, 0)), Y)[0]
    sel = t >= 0.25
    measured = float(np.sqrt(np.mean((fh[sel] - f[sel]) ** 2)))
    assert measured <= 1.5 * nz["predicted_error"]


def test_the_noise_design_beats_the_default_at_its_noise_and_keeps_its_prediction_on_clean_data():
    # even 1e-9 of noise ruins the default's thin layers (they amplify it); the noise design,
    # whose candidates include those layers, is no worse there, and on clean data it stays within
    # the error it predicted (its low-pass lag, not noise, is what remains)
    (A, M, C, _Q), m = _model(0)
    sigma = 1e-9
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec0 = design_reconstructor(m, hinf_check=False, check_horizon=0.5)
        recn = design_reconstructor(m, noise_std=sigma, hinf_check=False, check_horizon=0.5)
    h = rec0.dt
    t = np.arange(round(1.0 / h) + 1) * h
    win = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.2, 0.0, 1.0))
    f = (np.sin(10.0 * t) * win)[:, None]  # rate up to fault_rate = 10 (the default)
    Y = simulate_plant(A, M, C, f, h)
    Yn = Y + sigma * np.random.default_rng(5).standard_normal(Y.shape)
    sel = t >= 0.5

    def rms(rec, Y_):
        return float(np.sqrt(np.mean((integrate_observers(rec, np.zeros((1, t.size, 0)), Y_)[0][sel]
                                      - f[sel]) ** 2)))

    assert rms(recn, Yn) <= rms(rec0, Yn)
    assert rms(recn, Y) <= 1.5 * recn.info["noise"]["predicted_error"]


# ----------------------------------------------------------------------------- ladder cost
def test_a_layer_that_misses_the_accuracy_skips_its_xi_runs_but_the_pick_has_them():
    _sys, m = _model(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(m, hinf_check=False, check_horizon=0.3, accuracy=1e-6)
    tried = rec.info["boundary_layers"]["tried"]
    missed = [x for x in tried if not x["step_error"] <= 1e-6]
    assert missed, "the largest layers miss an accuracy of 1e-6"
    assert all(x.get("xi_skipped") and x["xi_gain"] is None for x in missed)
    assert rec.info["self_check"]["xi_gain"] is not None and not rec.info["self_check"].get("xi_skipped")
