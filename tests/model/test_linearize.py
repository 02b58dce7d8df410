import numpy as np
import pytest

from fdikit import ConditionError, ModelError
from fdikit.model import NonlinearModel, linearize, trim

G = 9.81


def _col(v):
    """A float or a (runs,) parameter array as a (runs or 1, 1) column."""
    return np.reshape(v, (-1, 1))


def _slip(x, p):
    v, om = x[:, 0], x[:, 1]
    R = np.reshape(p["R"], -1)
    lam = (v - R * om) / v
    mu = p_arr(p, "Dm") * np.tanh(p_arr(p, "Bs") * lam)
    dmu = p_arr(p, "Dm") * p_arr(p, "Bs") * (1.0 - np.tanh(p_arr(p, "Bs") * lam) ** 2)
    return lam, mu, dmu


def p_arr(p, k):
    return np.reshape(p[k], -1)


def f_brake(t, x, u, p):
    """Quarter-car braking: speed v (m/s), wheel speed om (rad/s), brake torque Tb (N m)."""
    v, _om, Tb = x.T
    Tc, slope, wn = u.T
    _, mu, _ = _slip(x, p)
    M, J, R, Fz, c, tau = (p_arr(p, k) for k in ("M", "J", "R", "Fz", "c", "tau"))
    dv = -(Fz * mu + c * v**2) / M - G * np.sin(slope)
    dom = (R * Fz * mu - Tb) / J + wn
    dT = (Tc - Tb) / tau
    return np.stack([dv, dom, dT], axis=1)


def h_brake(t, x, u, p):
    dv = f_brake(t, x, u, p)[:, 0]
    return np.stack([x[:, 1], dv, x[:, 2] ** 2 / 1000.0 + 0.01 * u[:, 0]], axis=1)


def jac_x_brake(t, x, u, p):
    v, om, _Tb = x[0]
    _lam, _mu, dmu = (a[0] for a in _slip(x, p))
    M, J, R, Fz, c, tau = (p[k] for k in ("M", "J", "R", "Fz", "c", "tau"))
    dl_dv, dl_dom = R * om / v**2, -R / v
    return np.array([[[-(Fz * dmu * dl_dv + 2 * c * v) / M, -Fz * dmu * dl_dom / M, 0.0],
                      [R * Fz * dmu * dl_dv / J, R * Fz * dmu * dl_dom / J, -1.0 / J],
                      [0.0, 0.0, -1.0 / tau]]])


def jac_u_brake(t, x, u, p):
    slope = u[0, 1]
    return np.array([[[0.0, -G * np.cos(slope), 0.0], [0.0, 0.0, 1.0], [1.0 / p["tau"], 0.0, 0.0]]])


PARAMS = {"M": 400.0, "J": 1.2, "R": 0.3, "Fz": 4000.0, "c": 0.4, "tau": 0.05, "Dm": 1.0, "Bs": 10.0}
X0 = np.array([20.0, 60.0, 800.0])  # slip 0.1
U0 = np.array([900.0, 0.05, 0.0])


@pytest.fixture
def brake():
    return NonlinearModel(f_brake, h_brake, ["v", "om", "Tb"], ["Tc", "slope", "wn"],
                          ["om_m", "ax", "Tb_m"], PARAMS, groups={"d": ["slope"], "w": ["wn"]},
                          jac_x=jac_x_brake, jac_u=jac_u_brake, name="brake")


def analytic(x0=X0, u0=U0):
    A = jac_x_brake(0, x0[None], u0[None], PARAMS)[0]
    B = jac_u_brake(0, x0[None], u0[None], PARAMS)[0]
    C = np.vstack([[0.0, 1.0, 0.0], A[0], [0.0, 0.0, 2 * x0[2] / 1000.0]])
    D = np.vstack([[0.0, 0.0, 0.0], B[0], [0.01, 0.0, 0.0]])
    return A, B, C, D


def assert_rel(num, ref, rtol=1e-6):
    """Relative error per entry, against the size of the reference matrix for zero entries."""
    num, ref = np.asarray(num), np.asarray(ref)
    err = np.abs(num - ref) / np.maximum(np.abs(ref), 1e-9 * np.max(np.abs(ref)))
    assert err.max() <= rtol, f"max relative error {err.max():.2e}\n{num}\n{ref}"


def test_linearize_matches_analytic_jacobian(brake):
    lin = linearize(brake, X0, U0)
    A, B, C, D = analytic()
    # controls u = [Tc], disturbances d = [slope], noise w = [wn]
    assert_rel(lin.A, A)
    assert_rel(np.hstack([lin.B_of("u"), lin.B_of("d"), lin.B_of("w")]), B)
    assert_rel(lin.C, C)
    assert_rel(np.hstack([lin.D_of("u"), lin.D_of("d"), lin.D_of("w")]), D)
    assert lin.states == ["v", "om", "Tb"] and lin.outputs == ["om_m", "ax", "Tb_m"]
    assert lin.input_names("u") == ["Tc"] and lin.input_names("d") == ["slope"]
    assert lin.input_names("w") == ["wn"] and lin.name == "brake" and not lin.is_discrete


def test_linearize_at_other_points_and_mapping_inputs(brake):
    x0 = np.array([35.0, 100.0, 300.0])
    u0 = np.array([50.0, -0.1, 0.3])
    lin = linearize(brake, dict(zip(brake.states, x0, strict=True)), dict(zip(brake.inputs, u0, strict=True)))
    A, _, C, _ = analytic(x0, u0)
    assert_rel(lin.A, A)
    assert_rel(lin.C, C)


def test_linearize_one_batched_call(brake):
    calls = {"f": [], "h": []}

    class Counting(NonlinearModel):
        def f(self, t, x, u, p):
            calls["f"].append(x.shape[0])
            return f_brake(t, x, u, p)

        def h(self, t, x, u, p):
            calls["h"].append(x.shape[0])
            return h_brake(t, x, u, p)

    m = Counting(None, None, brake.states, brake.inputs, brake.outputs, PARAMS,
                 groups={"d": ["slope"], "w": ["wn"]})
    linearize(m, X0, U0)
    assert calls == {"f": [2 * (3 + 3)], "h": [2 * (3 + 3)]}
    calls["f"].clear()
    calls["h"].clear()
    linearize(m, X0, U0, faults=["param:Fz"])
    assert calls == {"f": [2 * (3 + 3 + 1)], "h": [2 * (3 + 3 + 1)]}


def test_linearize_parametric_fault_direction(brake):
    lin = linearize(brake, X0, U0, faults=["param:Fz", "param:tau", "actuator:Tc", "sensor:ax",
                                           "actuator:slope"])
    assert lin.fault_names == ["param:Fz", "param:tau", "actuator:Tc", "sensor:ax", "actuator:slope"]
    _, mu, _ = (a[0] for a in _slip(X0[None], PARAMS))
    M, J, R, tau = PARAMS["M"], PARAMS["J"], PARAMS["R"], PARAMS["tau"]
    # d f / d Fz and d h / d Fz by hand (h_2 = v' shares it)
    b, d = lin.fault_direction("param:Fz")
    assert_rel(b, [-mu / M, R * mu / J, 0.0])
    assert_rel(d, [0.0, -mu / M, 0.0])
    b, d = lin.fault_direction("param:tau")
    assert_rel(b, [0.0, 0.0, -(U0[0] - X0[2]) / tau**2])
    np.testing.assert_array_equal(d, 0.0)
    _A, B, _C, _D = analytic()
    b, d = lin.fault_direction("actuator:Tc")
    assert_rel(b, B[:, 0])
    b, _ = lin.fault_direction("actuator:slope")  # actuator fault on a disturbance input
    assert_rel(b, B[:, 1])
    b, d = lin.fault_direction("sensor:ax")
    np.testing.assert_array_equal(b, 0.0)
    np.testing.assert_array_equal(d, [0.0, 1.0, 0.0])


def test_linearize_analytic_method(brake):
    lin = linearize(brake, X0, U0, method="analytic")
    A, B, C, _ = analytic()
    np.testing.assert_array_equal(lin.A, A)
    np.testing.assert_array_equal(lin.B_of("u")[:, 0], B[:, 0])
    assert_rel(lin.C, C)
    plain = NonlinearModel(f_brake, h_brake, brake.states, brake.inputs, brake.outputs, PARAMS)
    with pytest.raises(ModelError, match="jac_x"):
        linearize(plain, X0, U0, method="analytic")


def test_linearize_linear_model_exact_and_steps():
    rng = np.random.default_rng(0)
    A, B, C, D = rng.standard_normal((3, 3)), rng.standard_normal((3, 2)), rng.standard_normal((2, 3)), \
        rng.standard_normal((2, 2))
    m = NonlinearModel(lambda t, x, u, p: x @ A.T + u @ B.T, lambda t, x, u, p: x @ C.T + u @ D.T,
                       ["a", "b", "c"], ["u1", "u2"], ["y1", "y2"])
    # state a = 1e4 puts rounding errors of ~eps * 1e4 / h into every column: still << 1e-6
    lin = linearize(m, [1e4, -3.0, 0.0], [0.0, 2.0], steps={"a": 10.0}, scales={"c": 1e3})
    for num, ref in ((lin.A, A), (lin.B, B), (lin.C, C), (lin.D, D)):
        assert_rel(num, ref, rtol=1e-6)
    # O(1) values: rounding level, eps * |f| / h ~ 1e-10 absolute
    lin = linearize(m, [1.0, -3.0, 0.5], [0.0, 2.0])
    for num, ref in ((lin.A, A), (lin.B, B), (lin.C, C), (lin.D, D)):
        assert_rel(num, ref, rtol=1e-8)


def test_linearize_errors(brake):
    with pytest.raises(ModelError, match="3 entries"):
        linearize(brake, [1.0, 2.0], U0)
    with pytest.raises(ModelError, match="not finite"):
        linearize(brake, [np.nan, 60.0, 800.0], U0)
    with pytest.raises(ModelError, match="unknown parameter"):
        linearize(brake, X0, U0, faults=["param:nope"])
    with pytest.raises(ModelError, match="unknown input"):
        linearize(brake, X0, U0, faults=["actuator:nope"])
    # v = 0: slip 0/0 at the operating point -> the model is NaN when perturbing
    with pytest.raises(ModelError, match="not finite"), np.errstate(divide="ignore", invalid="ignore"):
        linearize(brake, [0.0, 0.0, 800.0], U0)
    # a model that does not broadcast (runs,) parameter arrays gets a hint
    bad = NonlinearModel(lambda t, x, u, p: -p["k"] * x, lambda t, x, u, p: x, ["x"], ["u"], ["y"],
                         {"k": 1.0})
    with pytest.raises(ModelError, match="broadcast"):
        linearize(bad, [1.0], [0.0], faults=["param:k"])


# ------------------------------------------------------------------ trim
def _tanks():
    def f(t, x, u, p):
        q = u[:, 0]
        o1 = _col(p["k1"])[:, 0] * np.sqrt(np.abs(x[:, 0]))
        o2 = _col(p["k2"])[:, 0] * np.sqrt(np.abs(x[:, 1]))
        return np.stack([(q - o1) / 2.0, (o1 - o2) / 3.0], axis=1)

    return NonlinearModel(f, lambda t, x, u, p: x.copy(), ["h1", "h2"], ["q"], ["l1", "l2"],
                          {"k1": 0.5, "k2": 0.8})


def test_trim_known_equilibrium():
    m = _tanks()
    x, u, info = trim(m, [1.0, 1.0], [1.2])
    np.testing.assert_allclose(x, [(1.2 / 0.5) ** 2, (1.2 / 0.8) ** 2], rtol=1e-9)
    assert u[0] == 1.2 and info["max_residual"] < 1e-8 and info["free"] == ["h1", "h2"]


def test_trim_free_input_with_target():
    m = _tanks()
    x, u, info = trim(m, [1.0, 1.0], [0.1], free_inputs=["q"], targets={"l2": 2.0})
    q = 0.8 * np.sqrt(2.0)
    np.testing.assert_allclose(u, [q], rtol=1e-9)
    np.testing.assert_allclose(x, [(q / 0.5) ** 2, 2.0], rtol=1e-9)
    assert set(info["residuals"]) == {"dh1/dt", "dh2/dt", "output l2"}


def test_trim_steady_condition_and_bounds(brake):
    # steady braking at v = 20 m/s: wheel and torque derivatives zero, v' free -> slip where
    # R Fz mu(lambda) = Tb = Tc; solve for om and Tb with Tc = 900 N m
    x, _u, _info = trim(brake, X0, U0, free_states=["om", "Tb"], derivatives={"om": 0.0, "Tb": 0.0},
                      bounds={"om": (0.0, 66.0)})
    assert x[2] == pytest.approx(900.0, rel=1e-10)
    mu = 900.0 / (PARAMS["R"] * PARAMS["Fz"])
    lam = np.arctanh(mu / PARAMS["Dm"]) / PARAMS["Bs"]
    assert x[1] == pytest.approx(20.0 * (1 - lam) / PARAMS["R"], rel=1e-9)
    assert x[0] == 20.0


def test_trim_fails_clearly():
    m = NonlinearModel(lambda t, x, u, p: x**2 + 1.0 + u, lambda t, x, u, p: x, ["x"], ["u"], ["y"])
    with pytest.raises(ConditionError, match=r"dx/dt") as e:
        trim(m, [0.3], [0.0])
    assert e.value.condition == "trim" and e.value.details["max_residual"] >= 1.0 - 1e-9
    with pytest.raises(ModelError, match="free state"):
        trim(m, [0.3], [0.0], free_states=["nope"])
    with pytest.raises(ModelError, match="no free"):
        trim(m, [0.3], [0.0], free_states=[])
