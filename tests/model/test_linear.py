import control
import numpy as np
import pytest
from scipy.signal import cont2discrete

from fdikit import ModelError
from fdikit.model import LinearFaultModel


@pytest.fixture
def model():
    A = [[-1.0, 0.5], [0.0, -2.0]]
    B = [[1.0, 0.0], [0.0, 2.0]]
    C = [[1.0, 0.0], [1.0, 1.0], [0.0, 3.0]]
    return LinearFaultModel(
        A, B, C, states=["v", "p"], inputs=["throttle", "brake"], outputs=["v_m", "s", "p_m"],
        Bd=[[0.3], [0.0]], disturbances=["slope"], Bw=np.eye(2), noises=["w1", "w2"],
        faults=["actuator:brake", "sensor:p_m", ("nl", [1.0, -1.0], None)], name="toy",
    )


def test_fault_directions(model):
    b, d = model.fault_direction("actuator:brake")
    np.testing.assert_array_equal(b, [0.0, 2.0])
    np.testing.assert_array_equal(d, [0, 0, 0])
    b, d = model.fault_direction("sensor:p_m")
    np.testing.assert_array_equal(b, [0, 0])
    np.testing.assert_array_equal(d, [0, 0, 1])
    np.testing.assert_array_equal(model.fault_direction("nl")[0], [1, -1])
    assert model.input_names() == ["throttle", "brake", "slope", "actuator:brake", "sensor:p_m",
                                   "nl", "w1", "w2"]
    assert model.B_all.shape == (2, 8) and model.D_all.shape == (3, 8)


def test_statespace_round_trip(model):
    sys = model.to_statespace()
    assert list(sys.input_labels) == model.input_names()
    back = LinearFaultModel.from_statespace(sys, controls=["throttle", "brake"], disturbances=["slope"],
                                            noises=["w1", "w2"])
    np.testing.assert_array_equal(back.A, model.A)
    np.testing.assert_array_equal(back.B_of("d"), model.B_of("d"))
    np.testing.assert_array_equal(back.B_of("w"), model.B_of("w"))
    assert back.outputs == model.outputs and back.states == model.states
    # python-control agrees on the DC gain of the control channels
    dc = control.dcgain(model.to_statespace(groups=("u",)))
    np.testing.assert_allclose(dc, -model.C @ np.linalg.solve(model.A, model.B), rtol=1e-12)


def test_discretize_matches_scipy(model):
    md = model.discretize(0.05)
    Ad, Bd, _, _, _ = cont2discrete((model.A, model.B_all, model.C, model.D_all), 0.05)
    np.testing.assert_allclose(md.A, Ad, rtol=1e-14)
    np.testing.assert_allclose(md.B_all, Bd, rtol=1e-14)
    # the brake actuator fault stays aligned with the discretised brake column
    np.testing.assert_allclose(md.B_of("f")[:, 0], md.B_of("u")[:, 1], rtol=1e-14)
    assert md.dt == 0.05 and md.fault_names == model.fault_names
    with pytest.raises(ModelError, match="already discrete"):
        md.discretize(0.1)


def test_similarity_transform_keeps_transfer(model):
    T = np.array([[2.0, 1.0], [0.0, 1.0]])
    mt = model.similarity_transform(T)
    for s in (0.0, 1j, 3.0 + 2j):
        G = model.C @ np.linalg.solve(s * np.eye(2) - model.A, model.B_all) + model.D_all
        Gt = mt.C @ np.linalg.solve(s * np.eye(2) - mt.A, mt.B_all) + mt.D_all
        np.testing.assert_allclose(Gt, G, rtol=1e-12, atol=1e-14)


def test_repr_lists_groups(model):
    r = repr(model)
    assert "disturbances: slope" in r and "faults:" in r and "actuator:brake" in r


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"A": [[1, 2]]}, "A must be square"),
        ({"C": [[1.0, 0.0, 0.0]]}, "C must have 2 columns"),
        ({"faults": ["actuator:steer"]}, "unknown control input 'steer'"),
        ({"faults": ["sensor:nope"]}, "unknown output 'nope'"),
        ({"faults": ["bias"]}, "must be 'actuator:<input>' or 'sensor:<output>'"),
        ({"faults": [("x", [1.0], None)]}, "direction b needs 2 entries"),
        ({"inputs": ["a", "a"], "B": np.ones((2, 2))}, "duplicated input names"),
        ({"Bd": [[1.0], [0.0]], "disturbances": ["u0"]}, "unique across groups"),
        ({"A": [[np.nan, 0], [0, 1]]}, "NaN or inf"),
    ],
)
def test_bad_models(kwargs, match):
    base = {"A": np.eye(2), "B": np.ones((2, 1)), "C": np.eye(2)}
    base.update(kwargs)
    A, B, C = base.pop("A"), base.pop("B"), base.pop("C")
    with pytest.raises(ModelError, match=match):
        LinearFaultModel(A, B, C, **base)
