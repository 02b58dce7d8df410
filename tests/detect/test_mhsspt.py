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


def _log_brute_force(logf, p, pi):
    """Bayes over every change time in the log domain (scipy's logsumexp): log posteriors of H0..HM."""
    from scipy.special import logsumexp

    k, H = logf.shape
    c0 = np.concatenate([[0.0], np.cumsum(logf[:, 0])])  # log prod_{i < theta} f0
    out = np.full(H, -np.inf)
    out[0] = k * np.log1p(-p) + c0[k]
    for j in range(1, H):
        cj = np.concatenate([[0.0], np.cumsum(logf[:, j])])
        theta = np.arange(1, k + 1)
        terms = (np.log(p) + (theta - 1) * np.log1p(-p) + np.log(pi[j - 1]) + c0[theta - 1]
                 + (cj[k] - cj[theta - 1]))
        out[j] = logsumexp(terms)
    return out - logsumexp(out)


def test_recursion_equals_log_domain_bayes_across_hundreds_of_nats():
    """Posteriors that fall to 1e-200 and come back (the terms the recursion drops below double
    rounding must not matter): equal to the log-domain brute force over all change times."""
    rng = np.random.default_rng(3)
    dens = {"H0": UniformMeanGaussian([0, 0], [0, 0], [0.1, 0.1]),
            "a": UniformMeanGaussian([1, 0], [2, 0], [0.1, 0.1]),
            "b": UniformMeanGaussian([0, 1], [0, 1.5], [0.1, 0.2])}
    p, pi = 1e-3, [0.4, 0.6]
    test = MHSSPT(["x1", "x2"], dens, p=p, pi=pi)
    x = rng.normal(0.0, 0.1, (60, 2))
    x[20:35, 0] += 1.4   # fault a: H0 and b fall by hundreds of nats
    x[35:, 1] += 1.2     # then b
    test.run(Signals(np.arange(60.0), x, ["x1", "x2"]))
    logf = test.loglik(x)
    test.reset(1)
    for k in range(60):
        test.step(x[k])
        ref = _log_brute_force(logf[:k + 1], p, pi)
        got = test.log_posterior()[0]
        big = ref > -700
        np.testing.assert_allclose(got[big], ref[big], rtol=1e-10, atol=1e-9)
    assert ref[1] < -100 and test.log_posterior()[0, 2] > -1e-6  # a came and went; b holds


def test_tabulated_densities_match_exact_and_round_trip():
    rng = np.random.default_rng(4)
    dens = {"H0": UniformMeanGaussian([0.2, 0.1], [0.2, 0.1], [0.05, 0.02]),
            "f:small": UniformMeanGaussian([0.5, 0.1], [1.0, 0.2], [0.06, 0.03]),
            "f:large": UniformMeanGaussian([1.0, 0.2], [2.0, 0.4], [0.08, 0.04])}
    exact = MHSSPT(["a", "b"], dens, p=1e-3, groups={"f": ["f:small", "f:large"]})
    tab = MHSSPT(["a", "b"], dens, p=1e-3, groups={"f": ["f:small", "f:large"]}, tabulate=1 / 32)
    assert 0 < tab.table_error < 1.3e-4  # (1/32)^2 / 8 per component
    x = np.abs(rng.normal([0.2, 0.1], [0.05, 0.02], (40, 300, 2)))
    x[20:, 150:] += [1.3, 0.2]
    x[25, 200] = [30.0, -5.0]  # off the table: the exact formula
    ll_e, ll_t = exact.loglik(x), tab.loglik(x)
    assert np.abs(ll_t - ll_e).max() <= 2 * tab.table_error + 1e-12  # two components per hypothesis
    assert np.abs(ll_t[25, 200] - ll_e[25, 200]).max() < 1e-9
    s = Signals(np.arange(300.0), x, ["a", "b"])
    Pe, Pt = exact.run(s).values, tab.run(s).values
    assert np.abs(Pt - Pe).max() < 1e-3 and Pt[20:, -1, -1].min() > 0.99
    # streaming (one run at a time, no threads) = batch (40 streams in parallel threads), bitwise
    tab.reset(1)
    one = np.concatenate([tab.step(x[33, k]) for k in range(300)])
    np.testing.assert_array_equal(one, Pt[33])
    back = MHSSPT.from_dict(tab.to_dict())
    assert back.tabulate == tab.tabulate
    np.testing.assert_array_equal(back.run(s).values, Pt)


def test_tabulated_direct_outputs_equal_the_log_posterior_path():
    """The bulk path (the normalised posteriors the recursion forms, straight from the compiled
    kernel) = log posteriors then exp (the path a subclass that changes ``_advance`` takes), to
    rounding: the two differ in the last bits, and hypotheses more than 40 nats below the lead
    (probability < 4.3e-18) are exactly 0 on the bulk path."""

    class Via(MHSSPT):
        def _advance(self, x):
            return super()._advance(x)

    rng = np.random.default_rng(8)
    dens = {"H0": UniformMeanGaussian([0.0], [0.0], [0.1]), "a": UniformMeanGaussian([0.5], [1.0], [0.1]),
            "b": UniformMeanGaussian([1.0], [3.0], [0.2])}
    x = np.abs(rng.normal(0.0, 0.1, (30, 400, 1)))
    x[10:, 200:] += 0.8
    s = Signals(np.arange(400.0), x, ["r"])
    kw = {"groups": {"ab": ["a", "b"]}, "tabulate": 1 / 32, "q": 0.01}
    direct, via = MHSSPT(["r"], dens, 1e-3, **kw).run(s).values, Via(["r"], dens, 1e-3, **kw).run(s).values
    np.testing.assert_allclose(direct, via, rtol=1e-13, atol=1e-17)
    assert (direct[..., :3] == via[..., :3]).mean() > 0.3  # most values agree bitwise even so
    np.testing.assert_allclose(direct[..., 3], direct[..., 1] + direct[..., 2], rtol=0, atol=0)


def test_bulk_call_refuses_the_first_non_finite_input():
    """A bulk run (checked by the parallel scan) names the first bad value: run, then sample, then
    channel -- the same as the element-wise check of a small call."""
    dens = {"H0": UniformMeanGaussian([0.0, 0.0], [0.0, 0.0], [0.1, 0.1]),
            "a": UniformMeanGaussian([0.5, 0.5], [1.0, 1.0], [0.1, 0.1])}
    x = np.zeros((8, 600, 2))
    x[5, 2, 0] = np.inf
    x[3, 50, 1] = np.nan
    x[3, 70, 0] = np.nan
    for tab in (None, 1 / 32):
        test = MHSSPT(["r1", "r2"], dens, 1e-3, tabulate=tab)
        with pytest.raises(DataError, match=r"'r2' is not finite at sample 50 \(run 3\)"):
            test.run(Signals(np.arange(600.0), x, ["r1", "r2"], check=False))
        # the channel order of the record differs from the test's: the copy path, same answer
        with pytest.raises(DataError, match=r"'r2' is not finite at sample 50 \(run 3\)"):
            test.run(Signals(np.arange(600.0), x[:, :, ::-1], ["r2", "r1"], check=False))


def test_cubic_tables_agree_with_the_exact_densities_to_1e_7_nats():
    """Hermite cubics on the distinct components: the measured error (four points per interval)
    is small, a random probe against the independent scipy formula agrees within it, points off
    the grid take the exact formula, and the linear table is far coarser."""
    from fdikit.detect.mhsspt import tabulate_umg_cubic

    rng = np.random.default_rng(11)
    dens = {"H0": UniformMeanGaussian([0.2, 0.1, 0.0], [0.2, 0.1, 0.4], [0.05, 0.02, 0.1]),
            "f:small": UniformMeanGaussian([0.5, 0.1, 0.0], [1.0, 0.2, 0.4], [0.06, 0.03, 0.1]),
            "f:large": UniformMeanGaussian([1.0, 0.2, 0.3], [2.0, 0.4, 3.0], [0.08, 0.04, 0.3])}
    kw = {"groups": {"f": ["f:small", "f:large"]}}
    exact = MHSSPT(["a", "b", "c"], dens, p=1e-3, **kw)
    cubic = MHSSPT(["a", "b", "c"], dens, p=1e-3, tabulate=1 / 16, interpolation="cubic", **kw)
    linear = MHSSPT(["a", "b", "c"], dens, p=1e-3, tabulate=1 / 32, **kw)
    assert 0 < cubic.table_error < 1e-7 and linear.table_error > 1e3 * cubic.table_error
    x = rng.uniform([-0.3, -0.2, -1.0], [2.5, 0.6, 4.0], (5, 400, 3))
    x[2, 7] = [40.0, -9.0, 50.0]  # off the tables: the exact formula
    ll_e, ll_c = exact.loglik(x), cubic.loglik(x)
    assert np.abs(ll_c - ll_e).max() <= 3 * cubic.table_error + 1e-12  # three components each
    assert np.abs(ll_c[2, 7] - ll_e[2, 7]).max() < 1e-12
    ref = np.stack([d.logpdf(x) for d in dens.values()], axis=-1)  # scipy's log_ndtr, not the kernel
    assert np.abs(ll_c - ref).max() < 1e-6
    # the table function alone, one point component and one range
    t = tabulate_umg_cubic(np.array([0.0, 1.0]), np.array([0.0, 3.0]), np.array([0.5, 0.7]),
                           np.array([True, False]), np.log(np.array([1.0, 2.0])), np.array([0, 1, 2]))
    assert t["nG"].tolist()[0] > 100 and t["error"] < 1e-7
    with pytest.raises(DataError, match="interpolation must be 'linear' or 'cubic'"):
        MHSSPT(["a", "b", "c"], dens, p=1e-3, tabulate=1 / 16, interpolation="spline")


def test_cubic_mhsspt_runs_like_the_exact_test_and_streams_bitwise():
    rng = np.random.default_rng(12)
    dens = {"H0": UniformMeanGaussian([0.2, 0.1], [0.2, 0.1], [0.05, 0.02]),
            "f:small": UniformMeanGaussian([0.5, 0.1], [1.0, 0.2], [0.06, 0.03]),
            "f:large": UniformMeanGaussian([1.0, 0.2], [2.0, 0.4], [0.08, 0.04])}
    kw = {"groups": {"f": ["f:small", "f:large"]}, "q": 0.002}
    exact = MHSSPT(["a", "b"], dens, p=1e-3, **kw)
    cubic = MHSSPT(["a", "b"], dens, p=1e-3, tabulate=1 / 16, interpolation="cubic", **kw)
    x = np.abs(rng.normal([0.2, 0.1], [0.05, 0.02], (40, 300, 2)))
    x[20:, 150:] += [1.3, 0.2]
    s = Signals(np.arange(300.0), x, ["a", "b"])
    Pe, Pc = exact.run(s).values, cubic.run(s).values  # 40 streams: the parallel kernel
    assert np.abs(Pc - Pe).max() < 1e-5 and Pc[20:, -1, -1].min() > 0.99
    cubic.reset(1)
    one = np.concatenate([cubic.step(x[33, k]) for k in range(300)])
    np.testing.assert_array_equal(one, Pc[33])
    back = MHSSPT.from_dict(cubic.to_dict())
    assert (back.tabulate, back.interpolation) == (1 / 16, "cubic")
    np.testing.assert_array_equal(back.run(s).values, Pc)


def test_warmup_mhsspt_with_a_table_takes_the_fused_path_with_its_warmup():
    """WarmupMHSSPT's outputs from the fused table kernel (its warm-up features applied first)
    equal those of the log-posterior path to rounding, batch and streaming alike."""
    from fdikit.detect import WarmupMHSSPT

    class Via(WarmupMHSSPT):
        def _advance(self, x):  # not marked table_direct: the log-posterior path
            return super()._advance(x)

    rng = np.random.default_rng(9)
    dens = {"H0": UniformMeanGaussian([0.0], [0.0], [0.1]), "a": UniformMeanGaussian([0.5], [1.0], [0.1])}
    x = np.abs(rng.normal(0.0, 0.1, (3, 200, 1)))
    x[:, :10] = 5.0  # a start-up transient that the warm-up hides
    x[1, 120:] += 0.8
    s = Signals(np.arange(200.0), x, ["r"])
    for interp in ("linear", "cubic"):
        kw = {"tabulate": 1 / 16, "interpolation": interp, "warmup": 12}
        direct = WarmupMHSSPT(["r"], dens, 1e-3, **kw)
        d, v = direct.run(s).values, Via(["r"], dens, 1e-3, **kw).run(s).values
        np.testing.assert_allclose(d, v, rtol=1e-13, atol=1e-17)
        assert d[:, :20, 1].max() < 0.01 and d[1, -1, 1] > 0.99
        direct.reset(1)
        one = np.concatenate([direct.step(x[1, k]) for k in range(200)])
        np.testing.assert_array_equal(one, d[1])
