"""Issue 31, item 5 (n = 60 within budget): the self-check shares its plant runs across the layers
a design tries and stops a layer's disturbance runs at the first that shows it cannot claim
gamma-bar -- without changing what a complete check measures."""

import warnings

import numpy as np
import pytest

from fdikit.errors import ModelError
from fdikit.model.random_systems import as_fault_model, random_fault_system
from fdikit.residuals.smo import design_reconstructor, self_check
from fdikit.residuals.smo import selfcheck as sc_mod


@pytest.fixture(scope="module")
def rec():
    A, M, C, Q = random_fault_system(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return design_reconstructor(as_fault_model(A, M, C, Q), hinf_check=False, check_horizon=0.3)


def test_the_design_leaves_no_plant_runs_behind(rec):
    assert "self_check_plant_runs" not in rec.details


def test_a_stopped_check_is_one_run_and_a_complete_one_is_unchanged(rec, monkeypatch):
    kw = {"fault_bound": 0.5, "xi_amplitude": 1.0, "horizon": 0.2}
    full = self_check(rec, **kw)
    assert not full.get("xi_partial") and len(full["xi_probes"]) >= 5
    runs = []
    real = sc_mod.integrate_observers

    def counting(r, U, Y, **k):
        runs.append(Y.shape[0])
        return real(r, U, Y, **k)

    monkeypatch.setattr(sc_mod, "integrate_observers", counting)
    sims = []
    real_sim = sc_mod.simulate_plant
    monkeypatch.setattr(sc_mod, "simulate_plant", lambda *a, **k: sims.append(1) or real_sim(*a, **k))
    # a bound nothing meets: the step run, then one disturbance run, and the plant is not re-run
    stopped = self_check(rec, xi_gain_max=0.0, **kw)
    assert stopped["xi_partial"] and runs == [1, 1] and sims == []
    i = stopped["xi_worst_index"]
    assert stopped["xi_gain"] == (full["xi_gain_smooth"] if i == 0 else full["xi_probes"][i - 1]["gain"])
    # a bound everything meets: every run, the same numbers as the complete check
    runs.clear()
    again = self_check(rec, xi_gain_max=np.inf, xi_first=0, **kw)
    assert sum(runs) == 1 + 1 + len(full["xi_probes"])
    assert {k: v for k, v in again.items()} == full
    with pytest.raises(ModelError, match="xi_first"):
        self_check(rec, xi_gain_max=0.0, xi_first=99, **kw)


def test_the_ladder_records_which_layers_stopped_early(rec):
    tried = rec.info["boundary_layers"]["tried"]
    gam = rec.info["l2_bound"]
    for x in tried[:-1]:  # every layer before the pick missed the accuracy or gamma-bar
        assert x.get("xi_skipped") or x.get("xi_partial") or x["xi_gain"] > gam
    assert not rec.info["self_check"].get("xi_partial")
    assert rec.info["self_check"]["xi_gain"] <= gam
