import numpy as np
import pytest
from scipy.stats import norm

from fdikit import DataError, Signals
from fdikit.detect import MHSSPT, UniformMeanGaussian


def brute_force_posterior(logf, p, pi):
    """Bayes' rule over every change time theta = 1..k plus 'no change yet' (notes, checks)."""
    k, H = logf.shape
    f = np.exp(logf)
    post = np.zeros(H)
    post[0] = (1 - p) ** k * np.prod(f[:, 0])
    for theta in range(1, k + 1):
        pre = np.prod(f[: theta - 1, 0])
        for j in range(1, H):
            post[j] += p * (1 - p) ** (theta - 1) * pi[j - 1] * pre * np.prod(f[theta - 1 :, j])
    return post / post.sum()


def test_uniform_mean_density_against_numerical_integral():
    d = UniformMeanGaussian([1.0, -2.0], [3.0, -2.0], [0.5, 0.3])
    x = np.array([2.2, -1.9])
    m = np.linspace(1.0, 3.0, 20001)
    integral = np.trapezoid(norm.pdf(x[0], loc=m, scale=0.5), m) / 2.0
    ref = np.log(integral) + norm.logpdf(x[1], -2.0, 0.3)
    np.testing.assert_allclose(d.logpdf(x), ref, rtol=1e-8)
    # far tails stay finite (no log(0)) and decrease
    far = d.logpdf(np.array([[60.0, -2.0], [-60.0, -2.0], [300.0, -2.0]]))
    assert np.all(np.isfinite(far)) and far[2] < far[0]
    # upper tail where the difference of survival functions is still representable (1e-127)
    tail = d.logpdf(np.array([15.0, -2.0]))
    np.testing.assert_allclose(tail, np.log(norm.sf(12.0 / 0.5) - norm.sf(14.0 / 0.5)) - np.log(2)
                               + norm.logpdf(-2.0, -2.0, 0.3), rtol=1e-9)


def test_recursion_equals_brute_force_bayes():
    rng = np.random.default_rng(0)
    dens = {"H0": UniformMeanGaussian([0, 0], [0, 0], [1, 1]),
            "a": UniformMeanGaussian([1, 0], [2, 0], [1, 1]),
            "b": UniformMeanGaussian([0, 1], [0, 3], [1, 1.5])}
    p, pi = 0.05, [0.3, 0.7]
    test = MHSSPT(["x1", "x2"], dens, p=p, pi=pi)
    x = rng.normal(size=(40, 2))
    x[20:, 1] += 2.0
    P = test.run(Signals(np.arange(40.0), x, ["x1", "x2"])).values[0]
    logf = test.loglik(x)
    for k in (1, 2, 5, 19, 21, 30, 40):
        np.testing.assert_allclose(P[k - 1], brute_force_posterior(logf[:k], p, pi), rtol=1e-9, atol=1e-14)


def test_identical_densities_give_geometric_no_fault_probability():
    d = UniformMeanGaussian([0.0], [1.0], [1.0])
    test = MHSSPT(["r"], {"H0": d, "f1": d, "f2": d}, p=0.01)
    x = np.random.default_rng(1).normal(size=300)
    P0 = test.run(Signals(np.arange(300.0), x, ["r"]))["P:H0"][0]
    np.testing.assert_allclose(P0, 0.99 ** np.arange(1, 301), rtol=1e-10)


def test_log_domain_survives_tiny_likelihoods():
    test = MHSSPT(["r"], {"H0": UniformMeanGaussian([0], [0], [0.01]),
                          "f": UniformMeanGaussian([100], [100], [0.01])}, p=1e-6)
    x = np.r_[np.zeros(5), np.full(5, 100.0), np.full(3, 50.0)]  # 50: 1e-5000 under both
    P = test.run(Signals(np.arange(13.0), x, ["r"])).values[0]
    assert np.all(np.isfinite(P))
    assert P[4, 0] > 0.999999 and P[9, 1] > 0.999999
    np.testing.assert_allclose(P.sum(axis=1), 1.0, rtol=1e-12)


def test_return_probability_tracks_intermittent_fault_and_groups():
    dens = {"H0": UniformMeanGaussian([0], [0], [1]),
            "small": UniformMeanGaussian([2], [4], [1]),
            "large": UniformMeanGaussian([4], [10], [1])}
    x = np.zeros(300)
    x[50:100] = 5.0
    x[200:250] = 5.0
    s = Signals(np.arange(300.0), x, ["r"])
    kw = {"groups": {"fault": ["small", "large"]}}
    exact = MHSSPT(["r"], dens, p=1e-3, **kw).run(s)["P:fault"][0]
    ret = MHSSPT(["r"], dens, p=1e-3, q=1e-3, **kw).run(s)["P:fault"][0]
    assert exact[60] > 0.99 and exact[150] > 0.99  # absorbing: stays after the fault ends
    assert ret[60] > 0.99 and ret[150] < 0.01 and ret[210] > 0.99 and ret[299] < 0.01


def test_batch_equals_streaming():
    rng = np.random.default_rng(2)
    dens = {"H0": UniformMeanGaussian([0], [0], [1]), "f": UniformMeanGaussian([1], [3], [1])}
    test = MHSSPT(["r"], dens, p=0.01, q=0.001)
    v = rng.normal(size=(3, 80, 1)) + np.r_[np.zeros(40), np.ones(40) * 2][None, :, None]
    batch = test.run(Signals(np.arange(80.0), v, ["r"])).values
    test.reset(3)
    stream = np.stack([test.step(v[:, k]) for k in range(80)], axis=1)
    np.testing.assert_array_equal(batch, stream)


def test_bad_input():
    d = UniformMeanGaussian([0], [0], [1])
    with pytest.raises(DataError, match="p must be in"):
        MHSSPT(["r"], {"H0": d, "f": d}, p=0.0)
    with pytest.raises(DataError, match="needs H0 and at least one"):
        MHSSPT(["r"], {"H0": d}, p=0.1)
    with pytest.raises(DataError, match="2 components for 1 inputs"):
        MHSSPT(["r"], {"H0": d, "f": UniformMeanGaussian([0, 0], [1, 1], [1, 1])}, p=0.1)
    with pytest.raises(DataError, match="std must be positive"):
        UniformMeanGaussian([0], [1], [0])
    with pytest.raises(DataError, match="unknown hypothesis 'g'"):
        MHSSPT(["r"], {"H0": d, "f": d}, p=0.1, groups={"x": ["g"]})
    test = MHSSPT(["r"], {"H0": d, "f": d}, p=0.1)
    v = np.zeros((1, 10, 1))
    v[0, 7] = np.inf
    with pytest.raises(DataError, match="'r' is not finite at sample 7"):
        test.run(Signals(np.arange(10.0), v, ["r"], check=False))


def test_calibration_recovers_ranges_and_isolates():
    from fdikit.detect import calibrate_densities

    rng = np.random.default_rng(5)
    # two features; fault A moves feature 0 by 0.5 per unit magnitude, fault B moves feature 1
    nominal = rng.normal(0.0, 0.2, (2000, 2))
    mags = [1.0, 2.0, 3.0, 4.0]
    feats = {"A": {m: rng.normal([0.5 * m, 0.0], 0.2, (500, 2)) for m in mags},
             "B": {m: rng.normal([0.0, 0.5 * m], 0.2, (500, 2)) for m in mags}}
    cal = calibrate_densities(nominal, feats)
    a_large = cal.densities["A:large"]
    np.testing.assert_allclose(a_large.low, [1.5, 0.0], atol=0.05)  # feature means at magnitudes 3 and 4
    np.testing.assert_allclose(a_large.high, [2.0, 0.0], atol=0.05)
    np.testing.assert_allclose(a_large.std, 0.2, rtol=0.05)
    assert cal.ranges["A:small"] == (1.0, 2.0) and cal.ranges["A:large"] == (3.0, 4.0)
    # an MHSSPT built from it isolates a fresh fault B of magnitude 3.5 after 100 healthy samples
    test = MHSSPT(["f0", "f1"], cal.densities, p=1e-3, groups=cal.groups)
    x = np.vstack([rng.normal(0, 0.2, (100, 2)), rng.normal([0.0, 1.75], 0.2, (100, 2))])
    out = test.run(Signals(np.arange(200.0), x, ["f0", "f1"]))
    assert out["P:B"][0, -1] > 0.99 and out["P:A"][0, -1] < 0.01 and out["P:none"][0, 99] > 0.9
    with pytest.raises(DataError, match="need features at >= 2 magnitudes"):
        calibrate_densities(nominal, {"A": {1.0: feats["A"][1.0]}})
