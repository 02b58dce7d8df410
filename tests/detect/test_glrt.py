import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.detect import GLRT, Hold, TimeGated, design_threshold, glrt_statistic


def brute_force_glrt(r, mu0, sigma2, W):
    """Eq. (24) of luo-et-al evaluated literally, window by window."""
    g = np.empty(len(r))
    for k in range(len(r)):
        best = 0.0
        for j in range(max(0, k - W + 1), k + 1):
            s = np.sum(r[j : k + 1] - mu0)
            best = max(best, s * s / (k - j + 1))
        g[k] = best / (2 * sigma2)
    return g


@pytest.mark.parametrize("W", [1, 3, 10, 50])
def test_glrt_equals_brute_force(W):
    rng = np.random.default_rng(W)
    r = rng.normal(0.3, 2.0, size=300)
    r[150:] += 1.0
    np.testing.assert_allclose(glrt_statistic(r, 0.3, 4.0, W), brute_force_glrt(r, 0.3, 4.0, W),
                               rtol=1e-12, atol=1e-12)


def test_constant_shift_closed_form():
    d, sigma2, W = 0.7, 0.2, 25
    g = glrt_statistic(np.full(200, 5.0 + d), 5.0, sigma2, W)
    np.testing.assert_allclose(g[W - 1 :], W * d * d / (2 * sigma2), rtol=1e-12)
    # before the window is full the longest window (k + 1 samples) wins
    np.testing.assert_allclose(g[: W - 1], np.arange(1, W) * d * d / (2 * sigma2), rtol=1e-12)


def test_long_record_does_not_drift():
    # a persistent offset over a million samples: a global running sum would lose digits
    r = np.full(1_000_000, 1e6 + 0.1)
    g = glrt_statistic(r, 1e6, 1.0, 10)
    np.testing.assert_allclose(g[-1], 10 * 0.1**2 / 2, rtol=1e-6)


def test_batch_equals_streaming_multichannel():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(4, 120, 2))
    s = Signals(np.arange(120) * 0.01, v, ["a", "b"])
    test = GLRT(["a", "b"], mu0=[0.0, 0.1], sigma2=[1.0, 2.0], W=7)
    batch = test.run(s).values
    test.reset(4)
    stream = np.stack([test.step(v[:, k]) for k in range(120)], axis=1)
    np.testing.assert_array_equal(batch, stream)
    for run in range(4):
        np.testing.assert_allclose(batch[run, :, 1], brute_force_glrt(v[run, :, 1], 0.1, 2.0, 7), rtol=1e-12)


def test_calibrate_from_nominal():
    rng = np.random.default_rng(2)
    nominal = Signals(np.arange(500.0), rng.normal(0.5, 0.3, size=(40, 500, 1)), ["r"])
    test = GLRT.calibrate(nominal, ["r"], W=20)
    assert abs(test.mu0[0] - 0.5) < 0.01 and abs(test.sigma2[0] / 0.09 - 1) < 0.03


def test_threshold_design_meets_target_on_fresh_data():
    rng = np.random.default_rng(3)
    W, Z, pfa = 20, 5, 0.02
    design_runs = glrt_statistic(rng.normal(size=(3000, 400)), 0.0, 1.0, W)
    d = design_threshold(design_runs, pfa, Z=Z, margin=0.05)
    assert d.achieved_pfa <= pfa
    fresh = glrt_statistic(rng.normal(size=(3000, 400)), 0.0, 1.0, W)
    s = Signals(np.arange(400.0), fresh[..., None], ["g"])
    alarms = Hold(["g"], d.threshold, Z=Z, absolute=False).run(s)["g:alarm"].any(axis=1)
    se = np.sqrt(pfa * (1 - pfa) / 3000)
    assert alarms.mean() <= pfa + 3 * se
    # and the threshold is not wastefully high: without the margin about pfa of the runs alarm
    d0 = design_threshold(design_runs, pfa, Z=Z, margin=0.0)
    assert abs(np.mean(d0.critical_values >= d0.threshold) - pfa) <= 1 / 3000 + 1e-12
    # zero target: above every nominal run
    assert design_threshold(design_runs, 0.0, Z=Z).achieved_pfa == 0.0


def test_time_gated():
    t = np.arange(10.0)
    g = np.array([[0, 0, 0, 0, 0, 0, 5, 5, 5, 5],   # rises after T: outcome 1
                  [0, 5, 0, 0, 0, 0, 5, 5, 5, 5],   # above before T: stays 0
                  [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]], float)
    s = Signals(t, g[..., None], ["g"])
    tg = TimeGated(["g"], q=1.0, T=4.0)
    out = tg.run(s)["g:gated"]
    np.testing.assert_array_equal(out[0], [0, 0, 0, 0, 0, 0, 1, 1, 1, 1])
    assert not out[1].any() and not out[2].any()
    tg.reset(3)
    stream = np.stack([tg.step_at(t[k], g[:, k : k + 1])[:, 0] for k in range(10)], axis=1)
    np.testing.assert_array_equal(stream, out)


def test_bad_input():
    s = Signals(np.arange(5.0), np.zeros((5, 1)), ["r"])
    with pytest.raises(DataError, match="shorter than the GLRT window W = 10"):
        GLRT(["r"], W=10).run(s)
    with pytest.raises(DataError, match="W must be an integer >= 1"):
        GLRT(["r"], W=0)
    with pytest.raises(DataError, match="sigma2 must be positive"):
        GLRT(["r"], sigma2=0.0)
    v = np.zeros((1, 20, 1))
    v[0, 12, 0] = np.nan
    with pytest.raises(DataError, match="'r' is not finite at sample 12"):
        GLRT(["r"], W=5).run(Signals(np.arange(20.0), v, ["r"], check=False))
    with pytest.raises(DataError, match="must be in"):
        design_threshold(np.zeros((3, 10)), 1.5)
