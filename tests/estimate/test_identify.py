"""Model identification from nominal logs (issue 15, item 3): held-out fit on plants with known matrices."""

import numpy as np
import pytest

from fdikit.estimate import fit_percent, identify
from fdikit.faults import Noise, Scenario
from fdikit.model import LinearFaultModel, frequency_response
from fdikit.sim import simulate

DT = 0.05


def _record(T=3000, seed=2, meas=1e-4):
    A = [[-1.0, 2.0, 0.0], [-2.0, -1.0, 0.5], [0.0, 0.0, -3.0]]     # a resonance and a real pole
    B = [[0.0, 1.0], [1.0, 0.0], [0.5, 1.0]]
    C = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    plant = LinearFaultModel(A, B, C, inputs=["a", "b"], outputs=["p", "q"])
    rng = np.random.default_rng(seed)
    U = np.repeat(rng.normal(size=(T // 10 + 1, 2)), 10, axis=0)[: T + 1] + np.array([3.0, -1.0])
    sc = Scenario(duration=T * DT, dt=DT, inputs=U, noise=Noise(measurement=[meas, meas]))
    return plant, simulate(plant, sc, runs=1, seed=seed).signals()


FIT_BOUND = 95.0     # % on held-out data with measurement noise std 0.01 (outputs of order 1)


@pytest.mark.parametrize("method", ["n4sid", "arx"])
def test_identified_model_predicts_held_out_data(method):
    plant, sig = _record()
    model, info = identify(sig, ["a", "b"], ["p", "q"], method=method)
    assert model.is_discrete and model.dt == pytest.approx(DT)
    assert model.inputs == ["a", "b"] and model.outputs == ["p", "q"]
    assert min(info["fit"].values()) > FIT_BOUND, info["fit"]
    if method == "n4sid":
        assert info["order"] == 3                                   # the true order is selected
        sv = np.asarray(info["singular_values"])
        assert sv[2] / sv[3] > 10                                  # a clear gap after the third value
    # independent check: the frequency response matches the known plant's (sampled) one up to 1 Hz
    f = np.linspace(0.0, 1.0, 21)
    G = frequency_response(plant.discretize(DT), f)
    Gi = frequency_response(model, f)
    assert np.max(np.abs(G - Gi)) / np.max(np.abs(G)) < 0.1


def test_fit_is_computed_on_held_out_samples_by_the_formula():
    _, sig = _record(T=1500)
    ident = identify(sig, ["a", "b"], ["p", "q"], order=3, validation=0.4)
    assert ident.info["validation_samples"] == 1501 - ident.info["estimation_samples"]
    assert set(ident.info["orders_tried"]) == {3}
    y = np.c_[np.sin(np.arange(50.0)), np.cos(np.arange(50.0))]
    yh = y + 0.1
    expect = 100 * (1 - np.linalg.norm(y - yh, axis=0) / np.linalg.norm(y - y.mean(0), axis=0))
    assert np.allclose(fit_percent(y, yh), expect)


def test_identify_errors_name_the_input():
    _, sig = _record(T=400)
    with pytest.raises(Exception, match="'nope'"):
        identify(sig, ["a", "nope"], ["p"])
    with pytest.raises(Exception, match="validation"):
        identify(sig, ["a"], ["p"], validation=1.5)
