"""Issue 31, item 3: a noise-aware SMO design that is no worse than the default design on clean
data and keeps its predicted error at the stated noise -- the default design runs beside it as a
clean branch and an online noise estimate (``estimate_noise_std``) chooses per sample."""

import json
import warnings

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.model.random_systems import as_fault_model, random_fault_system
from fdikit.residuals.smo import (
    SLIDING,
    SlidingModeReconstructor,
    design_reconstructor,
    estimate_noise_std,
    integrate_observers,
    simulate_plant,
)

H = 1e-5
SIGMA = 5e-5  # stated noise (output units; outputs of these systems are O(0.1-1))


# ----------------------------------------------------------------------------- the estimate
def test_the_noise_estimate_reads_white_noise_and_not_a_smooth_signal():
    rng = np.random.default_rng(3)
    t = np.arange(40000) * 1e-4
    smooth = np.column_stack([np.sin(2 * t), 0.3 * np.cos(7 * t)])
    noisy = smooth + np.array([1e-3, 2e-6]) * rng.standard_normal(smooth.shape)
    est = estimate_noise_std(noisy)
    assert np.all(np.isnan(est[:4]))
    np.testing.assert_allclose(np.median(est[5000:], axis=0), [1e-3, 2e-6], rtol=0.1)
    # a smooth signal leaves rounding only: far below any noise worth stating
    assert np.nanmax(estimate_noise_std(smooth)[1000:]) < 1e-12


def test_the_noise_estimate_is_not_fooled_by_a_jump():
    # a log-mean: a unit step on top of 1e-4 noise moves the estimate by a few per cent, where a
    # variance estimate over the same window would jump by orders of magnitude
    rng = np.random.default_rng(4)
    y = 1e-4 * rng.standard_normal((20000, 1))
    y[10000:] += 1.0
    est = estimate_noise_std(y)[:, 0]
    assert est[10000:10300].max() < 1.3 * est[9999]
    assert 0.8e-4 < est[9999] < 1.25e-4


def test_the_noise_estimate_names_bad_input():
    y = np.zeros((100, 2))
    y[37, 1] = np.nan
    with pytest.raises(DataError, match="sample 37, channel 1"):
        estimate_noise_std(y)
    with pytest.raises(DataError, match="window"):
        estimate_noise_std(np.zeros((10, 1)), window=0)


# ----------------------------------------------------------------------------- the design
@pytest.fixture(scope="module", params=[0, 2])
def designs(request):
    A, M, C, Q = random_fault_system(request.param)
    m = as_fault_model(A, M, C, Q)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec0 = design_reconstructor(m, hinf_check=False, check_horizon=0.3)
        recn = design_reconstructor(m, noise_std=SIGMA, hinf_check=False, check_horizon=0.3)
    return (A, M, C, Q), rec0, recn


def _fault_run(A, M, C, t_end=0.6):
    t = np.arange(round(t_end / H) + 1) * H
    q = M.shape[1]
    win = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.1, 0.0, 1.0))
    f = (np.sin(10.0 * t) * win)[:, None] * np.where(np.arange(q) % 2 == 0, 1.0, -0.7)[None, :]
    return t, f, simulate_plant(A, M, C, f, H)


def _rms(rec, Y, f, sel):
    fh = integrate_observers(rec, np.zeros((1, Y.shape[1], 0)), Y)[0]
    return float(np.sqrt(np.mean(np.sum((fh[sel] - f[sel]) ** 2, axis=1))))


def test_on_clean_data_the_noise_design_is_the_default_design(designs):
    (A, M, C, _Q), rec0, recn = designs
    ad = recn.info["noise"]["adaptive"]
    assert recn.clean_branch is not None and 0 < ad["switch"] < 1
    t, f, Y = _fault_run(A, M, C)
    sel = t >= 0.3
    e0, en = _rms(rec0, Y, f, sel), _rms(recn, Y, f, sel)
    # tolerance 1e-9 (fault units): after the estimator's warm-up the output is the default's
    assert en <= e0 + 1e-9
    # the noise branch alone lags (its low-pass): what the issue measured as 0.071 median
    assert _rms(recn.noise_branch(), Y, f, sel) > 10 * e0
    assert ad["clean_data"]["error"] <= ad["clean_data"]["clean_branch_error"] + 1e-12


def test_at_the_stated_noise_the_design_keeps_its_prediction(designs):
    (A, M, C, _Q), rec0, recn = designs
    t, f, Y = _fault_run(A, M, C)
    sel = t >= 0.3
    Yn = Y + SIGMA * np.random.default_rng(11).standard_normal(Y.shape)  # another realisation
    en = _rms(recn, Yn, f, sel)
    assert en <= 1.5 * recn.info["noise"]["predicted_error"]
    assert en <= 1.01 * _rms(recn.noise_branch(), Yn, f, sel)
    assert en < 0.1 * _rms(rec0, Yn, f, sel)  # the default alone is ruined by this noise
    assert recn.info["noise"]["adaptive"]["at_noise_std"]["noise_branch_share"] > 0.99


def test_the_switch_follows_noise_that_starts_mid_record(designs):
    (A, M, C, _Q), _rec0, recn = designs
    t, _f, Y = _fault_run(A, M, C)
    k1 = t.size // 2
    Yn = Y.copy()
    Yn[:, k1:] += SIGMA * np.random.default_rng(12).standard_normal(Yn[:, k1:].shape)
    U = np.zeros((1, t.size, 0))
    out = integrate_observers(recn, U, Yn)
    clean = integrate_observers(recn.clean_branch, U, Yn)
    noise = integrate_observers(recn.noise_branch(), U, Yn)
    np.testing.assert_array_equal(out[0, 100:k1], clean[0, 100:k1])
    settle = k1 + 2000  # the estimate's memory is 256 samples
    np.testing.assert_array_equal(out[0, settle:], noise[0, settle:])


def test_the_status_is_honest_on_clean_data_after_a_jump(designs):
    # on clean data the status is the default design's (its transient test), not the noise
    # branch's, which has no transient test (white noise would trip it every sample)
    (A, M, C, _Q), _rec0, recn = designs
    t = np.arange(round(0.4 / H) + 1) * H
    q = M.shape[1]
    square = np.where(np.sin(2 * np.pi * 5 * (t - 0.1)) >= 0, 0.5, -0.5) * (t >= 0.1)
    f = square[:, None] * np.ones((1, q))
    Y = simulate_plant(A, M, C, f, H)
    fprev = np.vstack([f[:1], f[:-1]])  # y[k] cannot see f[k] yet: score against f[k] or f[k-1]

    def silent(rec):
        fh, st = integrate_observers(rec, np.zeros((1, t.size, 0)), Y, return_status=True)
        err = np.minimum(np.linalg.norm(fh[0] - f, axis=1), np.linalg.norm(fh[0] - fprev, axis=1))
        return int(np.sum((err > 0.05 * 0.5) & (st[0, :, 0] == SLIDING)))

    assert silent(recn) == 0
    assert silent(recn.noise_branch()) > 0


def test_batch_streaming_checkpoint_and_save_agree(designs):
    (A, M, C, _Q), _rec0, recn = designs
    t, _f, Y = _fault_run(A, M, C, t_end=0.02)
    Yn = Y + SIGMA * np.random.default_rng(13).standard_normal(Y.shape)
    U = np.zeros((1, t.size, 0))
    batch = integrate_observers(recn, U, Yn)
    recn.reset(1)
    half = t.size // 2
    first = recn._advance(U[:, :half], Yn[:, :half])
    state = recn.get_state()
    recn._advance(U[:, half:], Yn[:, half:])  # run on, then restore the checkpoint
    recn.set_state(state)
    rest = np.concatenate([recn._step(U[:, k], Yn[:, k])[:, None] for k in range(half, half + 50)], axis=1)
    np.testing.assert_array_equal(first[:, :, :batch.shape[2]], batch[:, :half])
    np.testing.assert_array_equal(rest[:, :, :batch.shape[2]], batch[:, half:half + 50])
    back = SlidingModeReconstructor.from_dict(json.loads(json.dumps(recn.to_dict())))
    assert back.noise_switch == recn.noise_switch and back.clean_branch is not None
    np.testing.assert_array_equal(integrate_observers(back, U, Yn), batch)


def test_a_bad_switch_is_named(designs):
    _sys, _rec0, recn = designs
    from dataclasses import replace

    with pytest.raises(DataError, match="noise_std"):
        replace(recn, noise_switch={**recn.noise_switch, "noise_std": [1.0]})
    with pytest.raises(DataError, match="window"):
        replace(recn, noise_switch={**recn.noise_switch, "window": 0})
    with pytest.raises(DataError, match="go together"):
        replace(recn, noise_switch=None)


def test_a_single_observer_plant_with_jumps_gets_the_same_promise():
    # relative degree one (C M of full rank, one observer): the measurements' slope jumps with
    # the fault, which a variance estimate would read as noise; the log-mean does not
    rng = np.random.default_rng(1)
    A = -np.diag([1.0, 2.0, 3.0, 4.0, 5.0]) + 0.3 * rng.standard_normal((5, 5))
    C = np.hstack([np.zeros((3, 2)), np.eye(3)])
    M = np.zeros((5, 1))
    M[4, 0] = 1.0
    Q = np.zeros((5, 1))
    Q[0, 0] = 1.0
    m = as_fault_model(A, M, C, Q)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec0 = design_reconstructor(m, hinf_check=False, check_horizon=0.3)
        recn = design_reconstructor(m, noise_std=1e-4, hinf_check=False, check_horizon=0.3)
    assert recn.info["case"] == "single" and recn.clean_branch is not None
    t = np.arange(round(0.6 / H) + 1) * H
    f = (np.where(np.sin(2 * np.pi * 5 * (t - 0.1)) >= 0, 0.5, -0.5) * (t >= 0.1))[:, None]
    Y = simulate_plant(A, M, C, f, H)
    U = np.zeros((1, t.size, 0))
    fh0 = integrate_observers(rec0, U, Y)
    fhn, st = integrate_observers(recn, U, Y, return_status=True)
    np.testing.assert_array_equal(fhn[0, 100:], fh0[0, 100:])  # clean: the default, jumps and all
    fprev = np.vstack([f[:1], f[:-1]])
    err = np.minimum(np.abs(fhn[0, :, 0] - f[:, 0]), np.abs(fhn[0, :, 0] - fprev[:, 0]))
    assert not np.any((err > 0.025) & (st[0, :, 0] == SLIDING))
    Yn = Y + 1e-4 * np.random.default_rng(5).standard_normal(Y.shape)
    sel = t >= 0.3
    e0 = np.sqrt(np.mean((integrate_observers(rec0, U, Yn)[0, sel] - f[sel]) ** 2))
    en = np.sqrt(np.mean((integrate_observers(recn, U, Yn)[0, sel] - f[sel]) ** 2))
    assert en < 0.2 * e0  # measured 0.093 against 0.88
