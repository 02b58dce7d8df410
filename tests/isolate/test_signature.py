"""Isolation for any system (issue 15): DMatrix.diagnose (maximum likelihood with Pd/Pf, nominal class
included, ambiguity sets) and SignatureIsolator (structured residuals, given or from a residual bank)."""

import itertools
import warnings

import numpy as np
import pytest

from fdikit.isolate import DMatrix, SignatureIsolator, diagnose_ml


def brute_force_ml(o, q, prior=None):
    """Likelihood of every class by the product formula, one outcome vector at a time."""
    q = np.clip(q, 1e-6, 1 - 1e-6)
    L = np.array([np.prod(np.where(o, qi, 1 - qi)) for qi in q])
    return L * (np.ones(len(q)) if prior is None else np.asarray(prior))


def test_dmatrix_diagnose_is_maximum_likelihood_over_every_class_including_nominal():
    rng = np.random.default_rng(0)
    d = rng.random((5, 4)) < 0.5
    d[0] = False
    dm = DMatrix(["F0", "A", "B", "C", "D"], ["t1", "t2", "t3", "t4"], d, pd=rng.uniform(0.7, 0.99, (5, 4)),
                 pf=rng.uniform(0.01, 0.1, 4))
    outs = np.array(list(itertools.product([0, 1], repeat=4)), bool)
    diag = dm.diagnose(outs)
    for k, o in enumerate(outs):
        L = brute_force_ml(o, dm.fail_probability())
        assert diag.best[k] == dm.faults[int(np.argmax(L))]
        assert np.allclose(diag.posterior[k], L / L.sum())
    # the nominal class competes: a single firing of a test with a high false-alarm rate can stay nominal
    assert "F0" in diag.best


def test_dmatrix_diagnose_ambiguity_sets_and_priors():
    dm = DMatrix(["F0", "F1", "F2", "F3"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1], [1, 1]], pd=0.95, pf=0.02)
    d = dm.diagnose({"t1": [True, True], "t2": [True, False]})
    assert d.ambiguity == [("F2", "F3"), ("F1",)]
    assert not d.isolated[0] and d.isolated[1]
    d = dm.diagnose([1, 1], prior={"F0": 0.1, "F1": 0.1, "F2": 0.2, "F3": 0.6})
    assert d.best == ["F3"] and d.ambiguity == [("F3",)]
    with pytest.raises(Exception, match="miss tests"):
        dm.diagnose({"t1": [True]})
    with pytest.raises(Exception, match=r"\(runs, 2\)"):
        dm.diagnose(np.zeros((3, 5)))


def test_dmatrix_diagnose_reports_ties_with_the_nominal_class():
    # with diagnose_ml and no nominal class an undetectable fault 'U' (rates a hair below the nominal
    # false alarms) wins every all-pass run; DMatrix.diagnose keeps both in the ambiguity set instead
    dm = DMatrix(["F0", "U", "A"], ["t1", "t2"], [[0, 0], [0, 0], [1, 0]], pd=0.9,
                 pf=np.array([[0.05, 0.05], [0.05, 0.05], [0.05, 0.05]]))
    d = dm.diagnose([[0, 0]])
    assert d.ambiguity == [("F0", "U")]
    best, _ = diagnose_ml(np.array([[0, 0]], bool), dm.fail_probability(), dm.faults)
    assert dm.faults[best[0]] == "F0"        # first on ties, the ambiguity is silent there


def test_signature_isolator_exact_nearest_and_ambiguity():
    S = [[0, 1, 1], [1, 0, 1], [1, 1, 0]]
    iso = SignatureIsolator(S, ["V", "i", "w"], ["r1", "r2", "r3"])
    pats = np.array(list(itertools.product([0, 1], repeat=3)))
    d = iso.diagnose(pats)
    full = np.vstack([np.zeros(3), S])
    for k, pat in enumerate(pats):
        ham = np.abs(full - pat).sum(axis=1)
        nearest = tuple(np.array(iso.faults)[ham == ham.min()])
        assert d.ambiguity[k] == nearest                     # Hamming-nearest signatures, all of them
    assert iso.diagnose([0, 1, 1]).best == ["V"]
    assert iso.diagnose({"r1": True, "r2": False, "r3": True}).best == ["i"]


def test_signature_isolator_from_a_residual_bank_end_to_end():
    from fdikit.faults import Bias, Noise, Scenario
    from fdikit.model import LinearFaultModel
    from fdikit.residuals.bank import design_residual_bank
    from fdikit.sim import simulate

    rng = np.random.default_rng(5)
    A = np.diag([0.95, 0.9, 0.85, 0.8]) + 0.02 * rng.normal(size=(4, 4))
    m = LinearFaultModel(A, rng.normal(size=(4, 2)), np.eye(4)[:3], dt=0.01,
                         faults=["actuator:u0", "actuator:u1", "sensor:y2"])
    noise = {"measurement": [1e-4] * 3}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bank = design_residual_bank(m, noise=noise, fault_sizes=1.0)
    iso = SignatureIsolator(bank.signature, use="useful")
    gen = bank.generator()
    cov = {r.name: r.noise_cov for r in bank.residuals}
    for f in bank.faults:
        sc = Scenario(duration=6.0, dt=0.01, faults=[Bias(f, 1.0, start=2.0)],
                      noise=Noise(measurement=[1e-4] * 3))
        r = gen.run(simulate(m, sc, seed=1).signals())
        late = r.t > 5.0
        alarms = []
        for res in bank.residuals:
            x = r.values[0][late][:, r.index(res.channels)].mean(axis=0)
            chi = float(x @ np.linalg.pinv(cov[res.name] / late.sum()) @ x)
            alarms.append(chi > 30.0)
        d = iso.diagnose(np.array(alarms)[None])
        assert d.best == [f], (f, alarms, bank.signature.to_text())
