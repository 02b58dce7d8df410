"""The complete ABS diagnoser: tree from the learned D-matrix, SVM on request, severity estimate."""

import itertools

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.isolate import DMatrix, compile_python, exhaustive
from fdikit.systems.abs.campaign import PAPER_TABLE_IV
from fdikit.systems.abs.diagnoser import (
    PAPER_PRIOR,
    SVM_TESTS,
    ABSDiagnoser,
    abs_tree,
    complete_campaign,
    extend_with_svm,
    svm_outcomes,
)
from fdikit.systems.abs.plant import PARAMS, Scenario, simulate

GLRT_TESTS = ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2"]


@pytest.fixture(scope="module")
def dg():
    return ABSDiagnoser.design(design_runs=100, runs=16, svm_per_size=3, seed=0)


def _paper_dm():
    return extend_with_svm(DMatrix(list(PAPER_TABLE_IV), GLRT_TESTS, list(PAPER_TABLE_IV.values())))


def test_table_iv_tree_reproduces_fig14_go_path_redundancy_and_cost():
    tree = abs_tree(_paper_dm())
    assert tree.go_path == ["G_O1"]
    assert tree.redundant_tests == ["S_Iw"]
    # expected cost of the paper's own listing, by hand with P(F0) = 0.93 and 0.01 per fault:
    # G_O1 always (1), G_O_T1 after G_O1 NG (0.07), G_O_T2 after G_O_T1 G (F1.x, F2.x, F5: 0.05),
    # G_O2 after G_O_T2 G (F2.x, F5: 0.03), G_P1 twice (0.02 each), S_Kf after G_O_T1 NG (0.02)
    paper_listing_cost = 1 + 0.07 + 0.05 + 0.03 + 0.02 + 0.02 + 0.02
    assert tree.expected_cost == pytest.approx(paper_listing_cost, abs=1e-12)
    ex = exhaustive(DMatrix(tree.dmatrix.faults, tree.dmatrix.tests, tree.dmatrix.d),
                    prior=[PAPER_PRIOR[f] for f in tree.dmatrix.faults])
    assert tree.expected_cost == pytest.approx(ex.expected_cost, abs=1e-12)
    for i, f in enumerate(tree.dmatrix.faults):  # Table IV + SVM columns: every fault unique
        assert tree.diagnose(tree.dmatrix.d[i]) == (f,)


def test_learned_tree_agrees_with_dmatrix_rows_and_generated_python(dg):
    dm, tree = dg.dmatrix, dg.tree
    assert dm.tests == [*GLRT_TESTS, *SVM_TESTS]
    f = compile_python(tree)
    for i, fault in enumerate(dm.faults):
        leaf = tree.diagnose(dict(zip(dm.tests, dm.d[i].tolist())))
        assert fault in leaf
        assert f(dict(zip(dm.tests, dm.d[i].tolist()))) == leaf
    for bits in itertools.product([False, True], repeat=len(dm.tests)):
        o = dict(zip(dm.tests, bits))
        assert f(o) == tree.diagnose(o)
    # the learned tree keeps Fig. 14's structure: G_O1 alone on the Go-path, S_Iw redundant,
    # S_Kf separating the K_f and I_w faults
    assert tree.go_path == ["G_O1"]
    assert "S_Iw" in tree.redundant_tests
    kf = tree.diagnose(dict(zip(dm.tests, dm.d[dm.faults.index("F3")].tolist())))
    assert kf == ("F3",)


def test_svm_outcomes_only_after_a_detection():
    fired = np.array([[0, 0, 0, 0, 0], [0, 1, 0, 1, 0], [0, 1, 0, 1, 0]], bool)
    out = svm_outcomes(fired, np.array(["K_f", "K_f", "I_w"]))
    assert out.tolist() == [[False, False], [True, False], [False, True]]
    with pytest.raises(DataError):
        svm_outcomes(fired, np.array(["K_f"]))


def test_monitor_alarms_equal_the_test_bank(dg):
    rec = simulate(None, Scenario(fault="F2.1", magnitude=-0.12), runs=2, seed=91)
    mon, chan = dg.monitor()
    res = mon.run(rec.y.concat_channels(rec.u))
    fired, first = dg.outcomes(rec)
    for j, name in enumerate(dg.bank.names):
        a = res.statistics.values[:, :, res.statistics.index([chan[name]])[0]] > 0.5
        np.testing.assert_array_equal(a.any(axis=1), fired[:, j])
        t = np.where(a.any(axis=1), rec.y.t[a.argmax(axis=1)], np.nan)
        np.testing.assert_array_equal(t, first[:, j])


CASES = [("F0", None), ("F1.1", -0.045), ("F1.2", -0.08), ("F2.1", -0.12), ("F2.2", -0.25),
         ("F3", -0.08), ("F3", 0.09), ("F4", -0.09)]


@pytest.mark.parametrize("fault,mag", CASES)
def test_diagnoser_isolates_each_detectable_class_on_fresh_seeds(dg, fault, mag):
    rec = simulate(None, Scenario(fault=fault, magnitude=mag), runs=2, seed=777)
    for run in range(2):
        out = dg.diagnose(rec, run)
        assert out["fault"] == fault, out
        if mag is None:
            assert out["fired"] == {} and out["relative_change"] is None
        else:
            # 23 dB process noise: the severity is recovered to a fraction of the fault size
            assert abs(out["relative_change"] - mag) < 0.25 * abs(mag), out
            assert all(0.0 <= t <= 12.5 for t in out["fired"].values())
        if fault in ("F3", "F4"):
            assert out["svm"] == {"F3": "K_f", "F4": "I_w"}[fault]


@pytest.mark.xfail(strict=True, reason="tau_m +15..50 % moves no GLRT statistic over its zero-false-alarm "
                   "threshold in this plant: with the step pedal force P_m settles ~0.1 s after the brake "
                   "(tau_m = 0.02 s), long before the valves act. Measured (23 dB, 200 runs, W = 40 "
                   "thresholds from 2000 nominal runs): Pd 0 for every test at +15, +30 and +50 %; "
                   "noise-free, the largest 40-sample mean of the r3 change is 0.007 (+15 %) and "
                   "0.024 rad/s (+50 %) against the ~0.058 rad/s G_O1 needs. F5 is diagnosed 'system OK'. "
                   "No detector can do much better: the Neyman-Pearson bound of the known signature over "
                   "the whole record (fdikit.systems.abs.detectability, 23 dB) is d' = 0.96 at +15 % and "
                   "3.25 at +50 %, Pd <= 0.003 and <= 0.32 at Pfa 1e-4")
def test_tau_m_fault_is_isolated(dg):
    rec = simulate(None, Scenario(fault="F5", magnitude=0.5), seed=5)
    assert dg.diagnose(rec)["fault"] == "F5"


@pytest.mark.parametrize("fault,param,mag", [("F3", "K_f", -0.07), ("F2.1", "R_w", -0.1)])
def test_estimation_noise_free_exact_and_within_crlb_with_measurement_noise(dg, fault, param, mag):
    from fdikit.systems.abs.estimation import ABSSimulator

    truth = PARAMS[param] * (1 + mag)
    clean = simulate(None, Scenario(fault=fault, magnitude=mag, snr_db=None, meas_var=0.0), seed=3)
    e = dg.estimate_param(clean.y.values[0], param)
    assert e["estimate"] == pytest.approx(truth, rel=1e-6)
    # with white measurement noise of variance s2 only, the least-squares estimate has standard
    # deviation ~ sqrt(s2 / ||dy/dtheta||^2) (Cramer-Rao, linearised at the truth)
    s2 = 0.004
    sim = ABSSimulator()
    h = 1e-3 * truth
    y0, y1 = sim.batch([{**sim.params, param: truth - h}, {**sim.params, param: truth + h}])
    sd = np.sqrt(s2 / np.sum(((y1 - y0) / (2 * h)) ** 2))
    noisy = simulate(None, Scenario(fault=fault, magnitude=mag, snr_db=None, meas_var=s2), runs=3, seed=4)
    for k in range(3):
        est = dg.estimate_param(noisy.y.values[k], param)["estimate"]
        assert abs(est - truth) < 5 * sd + 1e-4 * truth, (est, truth, sd)


def test_record_checks(dg):
    rec = simulate(None, Scenario(), seed=1)
    with pytest.raises(DataError, match="run 3"):
        dg.diagnose(rec, 3)
    with pytest.raises(DataError, match="lacks channels"):
        dg.diagnose(rec.y)


def test_complete_campaign_metrics_are_consistent_with_its_confusion():
    out = complete_campaign(6, design_runs=40, svm_per_size=1, estimate_runs=1, scan=5)
    conf = out["confusion"]
    faulty = [c for c in conf if c != "F0"]
    assert sum(conf["F0"].values()) == 12 and all(sum(conf[c].values()) == 6 for c in faulty)
    ok = sum(n for c in faulty for k, n in conf[c].items() if c in k.split("|") and "F0" not in k.split("|"))
    assert out["sensitivity"] == pytest.approx(ok / (6 * len(faulty)))
    spec = sum(n for k, n in conf["F0"].items() if "F0" in k.split("|")) / 12
    assert out["specificity"] == pytest.approx(spec)
    assert 0.0 <= out["svm_error"] <= 1.0
    assert set(out["estimation"]) == {"F1.1", "F1.2", "F2.1", "F2.2", "F3", "F4", "F5"}


def test_cli_campaign_complete_json():
    import argparse
    import io
    import json
    from contextlib import redirect_stdout

    from fdikit.commands.abs_campaign import add_campaign_parser

    top = argparse.ArgumentParser()
    add_campaign_parser(top.add_subparsers())
    args = top.parse_args(["campaign", "--runs", "4", "--design-runs", "30", "--complete", "--svm-per-size",
                           "1", "--estimate-runs", "1", "--json", "--no-progress"])
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert args.func(args) == 0
    lines = buf.getvalue().strip().splitlines()
    assert len(lines) == 1
    c = json.loads(lines[0])["complete"]
    for key in ("sensitivity", "specificity", "svm_error", "estimation", "tree", "diagnoser"):
        assert key in c
    assert c["runs"]["F3"] == 4 and c["runs"]["F0"] == 8
    assert c["estimation"]["F3"]["param"] == "K_f"
    # every run is diagnosed: the complete tree's leaves hold all runs of each class
    assert all(sum(v.values()) == c["runs"][k] for k, v in c["confusion"].items())


def test_unreliable_tree_on_learned_pd_pf(dg):
    tree = abs_tree(dg.dmatrix, tests_model="unreliable", misdiagnosis_cost=100.0)
    ev = tree.evaluate()  # recomputed from the tree alone, by propagating each fault's Pd/Pf
    assert ev["objective"] == pytest.approx(tree.expected_cost, rel=1e-9)
    # more than the perfect-test tree's cost: the unreliable model pays for misdiagnoses too
    assert tree.expected_cost > abs_tree(dg.dmatrix).expected_cost
    f = compile_python(tree)
    for bits in itertools.product([False, True], repeat=len(dg.dmatrix.tests)):
        o = dict(zip(dg.dmatrix.tests, bits))
        assert f(o) == tree.diagnose(o)
    with pytest.raises(DataError, match="tests_model"):
        abs_tree(dg.dmatrix, tests_model="noisy")
