"""Directional GLRT (known signature, unknown amplitude) and the ParameterSensitivity generator."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.base.artifacts import load_artifact, save_artifact
from fdikit.detect import DirectionalGLRT, directional_statistic, glrt_statistic


def brute_force(r, s, mu0, sigma2, W, min_info=0.0):
    """The statistic of the module docstring evaluated literally (r, s: (T, C))."""
    T = r.shape[0]
    a = ((r - mu0) * s / sigma2).sum(axis=1)
    b = (s * s / sigma2).sum(axis=1)
    g = np.zeros(T)
    eta = np.zeros(T)
    for k in range(T):
        starts = [0] if W is None else range(max(0, k - W + 1), k + 1)
        for j in starts:
            A, B = a[j:k + 1].sum(), b[j:k + 1].sum()
            if B > min_info and 0.5 * A * A / B > g[k]:
                g[k], eta[k] = 0.5 * A * A / B, A / B
    return g, eta


@pytest.mark.parametrize("W", [None, 1, 4, 25])
def test_equals_brute_force_two_channels(W):
    rng = np.random.default_rng(0 if W is None else W)
    T = 240
    s = np.stack([np.sin(np.arange(T) / 7.0), rng.normal(size=T)], -1)
    s[:20] = 0.0  # no signature yet: statistic 0 there
    r = rng.normal(size=(T, 2)) * [0.5, 2.0] + [0.1, -0.3] + 0.4 * s
    mu0, sigma2 = np.array([0.1, -0.3]), np.array([0.25, 4.0])
    sig = Signals(np.arange(T) * 0.01, np.concatenate([r, s], 1)[None], ["a", "b", "sa", "sb"])
    out = DirectionalGLRT(["a", "b"], ["sa", "sb"], mu0, sigma2, W, name="d").run(sig)
    g, eta = brute_force(r, s, mu0, sigma2, W)
    np.testing.assert_allclose(out["d:dglrt"][0], g, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(out["d:eta"][0], eta, rtol=1e-10, atol=1e-12)
    assert np.all(out["d:dglrt"][0, :20] == 0.0)


def test_unit_signature_is_eq24():
    rng = np.random.default_rng(3)
    r = rng.normal(0.2, 1.5, size=(3, 400))
    r[:, 200:] += 1.0
    for W in (1, 10, 50):
        g, _ = directional_statistic(r, np.ones_like(r), 0.2, 2.25, W)
        np.testing.assert_allclose(g, glrt_statistic(r, 0.2, 2.25, W), rtol=1e-11, atol=1e-12)


def test_exact_change_along_signature_closed_form():
    rng = np.random.default_rng(4)
    s = rng.normal(size=500)
    eta, sigma2 = -0.03, 0.004
    g, e = directional_statistic(1.0 + eta * s, s, 1.0, sigma2)
    cum = np.cumsum(s * s)
    np.testing.assert_allclose(e, eta, rtol=1e-9)
    np.testing.assert_allclose(g, eta**2 * cum / (2 * sigma2), rtol=1e-9)


def test_anchored_statistic_is_chi_square_under_h0():
    rng = np.random.default_rng(5)
    runs, T = 4000, 300
    s = np.sin(np.arange(T) / 5.0) * np.linspace(0.1, 3.0, T)
    r = rng.normal(0.0, 0.2, size=(runs, T))
    g, eta = directional_statistic(r, np.broadcast_to(s, r.shape), 0.0, 0.04)
    two_g = 2 * g[:, -1]
    assert abs(two_g.mean() - 1.0) < 4 * np.sqrt(2 / runs)           # chi-square(1): mean 1, var 2
    assert abs(np.mean(two_g > 3.841) - 0.05) < 4 * np.sqrt(0.05 * 0.95 / runs)
    # the amplitude estimate is unbiased with variance 1 / information
    info = np.sum(s * s) / 0.04
    assert abs(eta[:, -1].mean()) < 4 / np.sqrt(info * runs)
    assert abs(eta[:, -1].var() * info - 1.0) < 0.1


def test_min_information_keeps_it_silent():
    s = np.linspace(0.0, 1.0, 101)
    r = 0.5 * s
    g, eta = directional_statistic(r, s, 0.0, 1.0, min_information=10.0)
    info = np.cumsum(s * s)
    assert np.all(g[info <= 10.0] == 0.0) and np.all(eta[info <= 10.0] == 0.0)
    np.testing.assert_allclose(eta[info > 10.0], 0.5)


@pytest.mark.parametrize("W", [None, 6])
def test_batch_equals_streaming_and_checkpoint(W):
    rng = np.random.default_rng(6)
    v = rng.normal(size=(3, 90, 2))
    sig = Signals(np.arange(90) * 0.1, v, ["r", "s"])
    t = DirectionalGLRT(["r"], ["s"], 0.1, 0.5, W)
    batch = t.run(sig).values
    t.reset(3)
    first = np.stack([t.step(v[:, k]) for k in range(40)], axis=1)
    state = t.get_state()
    t2 = DirectionalGLRT.from_dict(t.to_dict())
    t2.reset(3)
    t2.set_state(state)
    rest = np.stack([t2.step(v[:, k]) for k in range(40, 90)], axis=1)
    np.testing.assert_array_equal(batch, np.concatenate([first, rest], axis=1))
    assert t.output_names == ["s:dglrt", "s:eta"]


def test_long_windowed_record_does_not_drift():
    s = np.where(np.arange(1_000_000) % 2 == 0, 1.0, -1.0)
    r = 1e6 + 0.1 * s
    g, eta = directional_statistic(r, s, 1e6, 1.0, W=10)
    np.testing.assert_allclose(eta[-1], 0.1, rtol=1e-6)
    np.testing.assert_allclose(g[-1], 10 * 0.01 / 2, rtol=1e-6)


def test_artifact_round_trip(tmp_path):
    t = DirectionalGLRT(["r3"], ["sig:r3:I_w"], -1e-3, 4e-3, None, min_information=2500.0, name="G_D_Iw")
    back = load_artifact(save_artifact(tmp_path / "d", t), expect_inputs=["r3", "sig:r3:I_w"])
    assert back.to_dict() == t.to_dict()


def test_bad_input_is_named():
    sig = Signals(np.arange(5.0), np.ones((1, 5, 2)), ["r", "s"])
    with pytest.raises(DataError, match="W must be None"):
        DirectionalGLRT(["r"], ["s"], W=0)
    with pytest.raises(DataError, match="signature channels"):
        DirectionalGLRT(["r"], ["s", "t"])
    with pytest.raises(DataError, match="sigma2 must be positive; channel 'r'"):
        DirectionalGLRT(["r"], ["s"], sigma2=0.0)
    with pytest.raises(DataError, match="min_information"):
        DirectionalGLRT(["r"], ["s"], min_information=-1.0)
    with pytest.raises(DataError, match="shorter than the window W = 10"):
        DirectionalGLRT(["r"], ["s"], W=10).run(sig)
    v = np.ones((1, 5, 2))
    v[0, 3, 1] = np.nan
    with pytest.raises(DataError, match=r"channel .s. has a non-finite value \(nan\) at run 0, sample 3"):
        DirectionalGLRT(["r"], ["s"]).run(Signals(np.arange(5.0), v, ["r", "s"], check=False))
    t = DirectionalGLRT(["r"], ["s"])
    t.reset(1)
    t.step([0.0, 1.0])
    with pytest.raises(DataError, match=r"channel .r. has a non-finite value \(inf\) at run 0, sample 1"):
        t.step([np.inf, 1.0])
    with pytest.raises(DataError, match="same shape"):
        directional_statistic(np.ones(3), np.ones(4))


# ---------------------------------------------------------------------------------- signatures
@pytest.fixture(scope="module")
def abs_records():
    from fdikit.systems.abs.plant import Scenario, simulate

    nom = simulate(None, Scenario(snr_db=None, meas_var=0.0, t_end=6.0), runs=1, seed=0)
    f4 = simulate(None, Scenario(fault="F4", magnitude=0.02, snr_db=None, meas_var=0.0, t_end=6.0), runs=1,
                  seed=0)
    noisy = simulate(None, Scenario(t_end=6.0), runs=3, seed=1)
    return [r.y.concat_channels(r.u) for r in (nom, f4, noisy)]


def test_signature_predicts_the_fault_response(abs_records):
    """The I_w signature measured on the nominal record predicts what a +2 % I_w plant does to r3
    (to first order) before the two stops' slip cycles drift apart."""
    from fdikit.systems.abs.residuals import observer_sensitivity

    nom, f4, _ = abs_records
    gen = observer_sensitivity(0.01, ["I_w"])
    out0 = gen.run(nom)
    r4 = gen.run(f4)["r3"][0]
    d = (r4 - out0["r3"][0])[:320]          # up to 3.2 s: the first ABS cycles
    pred = 0.02 * out0["sig:r3:I_w"][0][:320]
    assert np.linalg.norm(d) > 1e-3
    assert d @ pred / (np.linalg.norm(d) * np.linalg.norm(pred)) > 0.95
    assert abs(np.linalg.norm(d) / np.linalg.norm(pred) - 1.0) < 0.25


def test_sensitivity_batch_equals_streaming_and_saves(abs_records, tmp_path):
    from fdikit.residuals import ParameterSensitivity
    from fdikit.systems.abs.residuals import observer_sensitivity

    sig = abs_records[2]
    gen = observer_sensitivity(0.01, ["I_w", "K_f"])
    assert gen.output_names == ["r3", "r4", "sig:r3:I_w", "sig:r4:I_w", "sig:r3:K_f", "sig:r4:K_f"]
    batch = gen.run(sig).values
    u, y = gen._inputs(sig)
    gen.reset(sig.runs)
    half = sig.n_samples // 2
    first = np.stack([gen.step(u[:, k], y[:, k]) for k in range(half)], axis=1)
    back = load_artifact(save_artifact(tmp_path / "sens", gen))
    assert isinstance(back, ParameterSensitivity) and back.output_names == gen.output_names
    back.reset(sig.runs)
    back.set_state(gen.get_state())
    rest = np.stack([back.step(u[:, k], y[:, k]) for k in range(half, sig.n_samples)], axis=1)
    np.testing.assert_allclose(batch, np.concatenate([first, rest], axis=1), rtol=1e-12, atol=1e-12)


def test_sensitivity_bad_input():
    from fdikit.residuals import ParameterSensitivity
    from fdikit.systems.abs.residuals import ABSObserver, ParityR1, observer_sensitivity

    with pytest.raises(DataError, match="tau_m and the pedal act through its P_m input"):
        observer_sensitivity(0.01, ["tau_m"])
    with pytest.raises(DataError, match="twin 'x' has u_names"):
        ParameterSensitivity(ABSObserver(0.01), {"x": ParityR1(0.01)})
    with pytest.raises(DataError, match="non-zero"):
        ParameterSensitivity(ABSObserver(0.01), {"I_w": ABSObserver(0.01)}, 0.0)
    with pytest.raises(DataError, match="outputs \\['r9'\\]"):
        ParameterSensitivity(ABSObserver(0.01), {"I_w": ABSObserver(0.01)}, outputs=["r9"])


def brute_force_decoupled(r, S, mu0, sigma2, W, min_info=0.0):
    """Decoupled statistic by least squares over every window (r: (T, C), S: (T, C, m))."""
    T = S.shape[0]
    g = np.zeros(T)
    eta = np.zeros(T)
    w = 1.0 / sigma2
    for k in range(T):
        starts = [0] if W is None else range(max(0, k - W + 1), k + 1)
        for j in starts:
            Sj = S[j:k + 1]
            G = np.einsum("tci,tcj,c->ij", Sj, Sj, w)
            A = np.einsum("tci,tc,c->i", Sj, r[j:k + 1] - mu0, w)
            if np.linalg.eigvalsh(G).min() <= 1e-8 * np.abs(np.diag(G)).max():
                continue
            Gi = np.linalg.inv(G)
            e = (Gi @ A)[0]
            if 1.0 / Gi[0, 0] > min_info and 0.5 * e * e / Gi[0, 0] > g[k]:
                g[k], eta[k] = 0.5 * e * e / Gi[0, 0], e
    return g, eta


def _decoupled_case(seed, T=160):
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    s = np.stack([np.sin(t / 6.0), np.cos(t / 9.0)], -1)                  # tested, 2 channels
    n1 = 0.8 * s + 0.3 * rng.normal(size=(T, 2))                          # overlapping nuisance
    n2 = np.stack([np.ones(T), np.linspace(-1, 1, T)], -1)
    S = np.stack([s, n1, n2], -1)                                         # (T, C, m)
    sigma2 = np.array([0.04, 0.09])
    r = 0.05 + rng.normal(size=(T, 2)) * np.sqrt(sigma2) + 0.3 * n1 - 0.2 * n2
    return r, S, np.array([0.05, 0.05]), sigma2


@pytest.mark.parametrize("W", [None, 1, 7, 30])
def test_decoupled_equals_least_squares(W):
    r, S, mu0, sigma2 = _decoupled_case(10 + (W or 0))
    names = ["a", "b", "sa", "sb", "na", "nb", "ma", "mb"]
    vals = np.concatenate([r, S[:, :, 0], S[:, :, 1], S[:, :, 2]], 1)[None]
    sig = Signals(np.arange(len(r)) * 0.1, vals, names)
    t = DirectionalGLRT(["a", "b"], ["sa", "sb"], mu0, sigma2, W, nuisance=[["na", "nb"], ["ma", "mb"]],
                        name="d")
    out = t.run(sig)
    g, eta = brute_force_decoupled(r, S, mu0, sigma2, W)
    np.testing.assert_allclose(out["d:dglrt"][0], g, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(out["d:eta"][0], eta, rtol=1e-8, atol=1e-10)
    # streaming, with a checkpoint half-way, gives the same numbers
    t.reset(1)
    half = [t.step(vals[:, k, t_idx(names, t)]) for k in range(80)]
    state = t.get_state()
    t2 = DirectionalGLRT.from_dict(t.to_dict())
    t2.reset(1)
    t2.set_state(state)
    rest = [t2.step(vals[:, k, t_idx(names, t)]) for k in range(80, len(r))]
    np.testing.assert_array_equal(np.concatenate(half + rest), out.values[0])


def t_idx(names, t):
    return [names.index(n) for n in t.input_names]


def test_decoupled_ignores_a_fault_along_the_nuisance():
    """A change along the nuisance signature moves the plain directional statistic (the signatures
    overlap) but leaves the decoupled one at its no-fault chi-square law."""
    rng = np.random.default_rng(20)
    runs, T = 2000, 200
    t = np.arange(T)
    s = np.sin(t / 5.0)
    n = 0.9 * s + 0.45 * np.cos(t / 3.0)          # cos(s, n) ~ 0.9
    r = rng.normal(size=(runs, T)) * 0.1 + 0.05 * n
    vals = np.stack([r, np.broadcast_to(s, r.shape), np.broadcast_to(n, r.shape)], -1)
    sig = Signals(t * 0.01, vals, ["r", "s", "n"])
    plain = DirectionalGLRT(["r"], ["s"], 0.0, 0.01, name="p").run(sig)["p:dglrt"][:, -1]
    dec = DirectionalGLRT(["r"], ["s"], 0.0, 0.01, nuisance=[["n"]], name="d").run(sig)["d:dglrt"][:, -1]
    assert np.median(2 * plain) > 15                       # the overlap fires the plain test
    assert abs(np.mean(2 * dec) - 1.0) < 4 * np.sqrt(2 / runs)
    assert abs(np.mean(2 * dec > 3.841) - 0.05) < 0.02


def test_decoupled_bad_input():
    with pytest.raises(DataError, match="list of signature-channel lists"):
        DirectionalGLRT(["r"], ["s"], nuisance=["n"])
    with pytest.raises(DataError, match="need 1 signature channels"):
        DirectionalGLRT(["r"], ["s"], nuisance=[["n", "m"]])
    with pytest.raises(DataError, match="repeat"):
        DirectionalGLRT(["r"], ["s"], nuisance=[["s"]])
