"""DMatrix: construction, validation, ambiguity groups, learning Pd/Pf from Monte Carlo outcomes."""

import numpy as np
import pytest
from scipy.stats import binom, norm

from fdikit.errors import DataError, ModelError
from fdikit.isolate import DMatrix, ao_star, wilson_interval

# Table IV of luo-et-al (ABS test design)
TABLE_IV_TESTS = ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2", "S_Kf", "S_Iw"]
TABLE_IV_FAULTS = ["F0", "F1.1", "F1.2", "F2.1", "F2.2", "F3", "F4", "F5"]
TABLE_IV = [[0, 0, 0, 0, 0, 0, 0],
            [0, 1, 1, 0, 1, 0, 0],
            [1, 1, 1, 0, 1, 0, 0],
            [0, 1, 1, 0, 0, 0, 0],
            [1, 1, 1, 0, 0, 0, 0],
            [0, 1, 1, 1, 0, 1, 0],
            [0, 1, 1, 1, 0, 0, 1],
            [0, 1, 0, 0, 0, 0, 0]]


def test_table_iv_is_isolable():
    # the paper: "Since there are no identical rows in this matrix, all the faults can be uniquely isolated"
    dm = DMatrix(TABLE_IV_FAULTS, TABLE_IV_TESTS, TABLE_IV)
    assert dm.is_isolable
    assert dm.ambiguity_groups() == []
    assert len(dm.classes()) == 8
    assert dm.is_perfect
    assert dm.undetectable(nominal="F0") == []
    assert dm.row("F5").astype(int).tolist() == [0, 1, 0, 0, 0, 0, 0]


def test_identical_rows_reported_not_merged():
    d = [[0, 0, 0], [1, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1]]
    dm = DMatrix(["F0", "a", "b", "c", "d"], ["t1", "t2", "t3"], d)
    assert dm.ambiguity_groups() == [("a", "c")]
    assert not dm.is_isolable
    assert dm.faults == ["F0", "a", "b", "c", "d"]          # both rows are kept
    text = dm.to_text()
    assert text.count("<- ambiguity group 1") == 2
    # a diagnostic tree ends with the group as one leaf and still isolates the others
    tree = ao_star(dm)
    assert tree.ambiguity_groups == [("a", "c")]
    assert sorted(leaf.group for leaf in tree.leaves()) == [("F0",), ("a", "c"), ("b",), ("d",)]


def test_undetectable_fault_and_all_zero_row_group():
    dm = DMatrix(["F0", "F1", "F2"], ["t"], [[0], [1], [0]])
    assert dm.undetectable(nominal="F0") == ["F2"]
    assert dm.ambiguity_groups() == [("F0", "F2")]   # undetectable = indistinguishable from no fault


def test_fail_probability_broadcasting():
    dm = DMatrix(["a", "b"], ["t1", "t2"], [[1, 0], [0, 1]], pd=[0.9, 0.8], pf=0.05)
    np.testing.assert_array_equal(dm.fail_probability(), [[0.9, 0.05], [0.05, 0.8]])
    assert not dm.is_perfect
    assert "0.900" in dm.to_text(probabilities=True)
    again = DMatrix.from_dict(dm.to_dict())
    np.testing.assert_array_equal(again.fail_probability(), dm.fail_probability())
    assert again.tests == dm.tests


@pytest.mark.parametrize("d, match", [
    ([[0, 2], [1, 0]], r"\('F1', 't2'\) = 2 is not binary"),
    ([[0, 0.5], [1, 0]], "is not binary"),
    ([[0, 1, 0], [1, 0, 1]], r"shape \(2, 3\).*expected \(2, 2\)"),
    ([[0, np.nan], [1, 0]], "is not binary"),
])
def test_bad_matrix(d, match):
    with pytest.raises(ModelError, match=match):
        DMatrix(["F1", "F2"], ["t1", "t2"], d)


def test_bad_names_and_probabilities():
    with pytest.raises(ModelError, match="duplicated fault name 'a'"):
        DMatrix(["a", "a"], ["t"], [[0], [1]])
    with pytest.raises(ModelError, match="duplicated test name"):
        DMatrix(["a", "b"], ["t", "t"], [[0, 1], [1, 0]])
    with pytest.raises(ModelError, match=r"pd\['b', 't'\] = 1.2 is not a probability"):
        DMatrix(["a", "b"], ["t"], [[0], [1]], pd=[[1.0], [1.2]])
    with pytest.raises(ModelError, match="pf has shape"):
        DMatrix(["a", "b"], ["t"], [[0], [1]], pf=[0.1, 0.2, 0.3])
    with pytest.raises(ModelError, match="unknown fault 'zz'"):
        DMatrix(["a", "b"], ["t"], [[0], [1]]).row("zz")


def test_wilson_closed_form_and_coverage():
    # k = 0: lower bound 0, upper bound z^2 / (n + z^2) (closed form of the Wilson interval)
    z = norm.ppf(0.975)
    lo, hi = wilson_interval(0, 5000)
    assert lo == 0.0 and hi == pytest.approx(z**2 / (5000 + z**2), rel=1e-12)
    # k = n mirrors k = 0
    lo, hi = wilson_interval(40, 40)
    assert hi == 1.0 and lo == pytest.approx(40 / (40 + z**2), rel=1e-12)
    # exact coverage by summing the binomial pmf over the k whose interval contains p
    for n, p in [(50, 0.3), (200, 0.05), (1000, 0.9)]:
        k = np.arange(n + 1)
        lo, hi = wilson_interval(k, n)
        coverage = binom.pmf(k, n, p)[(lo <= p) & (p <= hi)].sum()
        assert 0.925 < coverage < 0.975, (n, p, coverage)
    with pytest.raises(DataError, match="confidence"):
        wilson_interval(1, 10, confidence=1.0)
    with pytest.raises(DataError, match=r"\[0, n\]"):
        wilson_interval(11, 10)


def _outcomes(rng, probs, runs):
    """Boolean outcomes (runs, tests) with exactly round(p * runs) firing runs per test (shuffled)."""
    out = np.zeros((runs, len(probs)), bool)
    for j, p in enumerate(probs):
        out[: round(p * runs), j] = True
        rng.shuffle(out[:, j])
    return out


def test_from_outcomes_counts_threshold_and_intervals():
    rng = np.random.default_rng(1)
    tests = ["g1", "g2", "g3"]
    outcomes = {"F0": _outcomes(rng, [0.01, 0.0, 0.02], 1000),
                "F1": _outcomes(rng, [0.98, 0.5, 0.02], 400),      # 0.5 is *at* the level: entry 0
                "F2": _outcomes(rng, [0.01, 0.51, 0.90], 200)}
    dm = DMatrix.from_outcomes(outcomes, tests)
    assert dm.faults == ["F0", "F1", "F2"]
    assert dm.d.astype(int).tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 1]]
    np.testing.assert_allclose(dm.pd, [[0.01, 0.0, 0.02], [0.98, 0.5, 0.02], [0.01, 0.51, 0.90]])
    # Pf from the nominal runs for every fault (pf_source="nominal")
    np.testing.assert_allclose(dm.pf, [[0.01, 0.0, 0.02]] * 3)
    assert dm.runs == {"F0": 1000, "F1": 400, "F2": 200}
    # the intervals are the Wilson intervals of the counts
    lo, hi = wilson_interval(392, 400)
    assert dm.pd_ci[1, 0].tolist() == pytest.approx([float(lo), float(hi)])
    z2 = norm.ppf(0.975) ** 2
    assert dm.pf_ci[2, 1, 0] == 0.0                      # no nominal alarm of g2 in 1000 runs
    assert dm.pf_ci[2, 1, 1] == pytest.approx(z2 / (1000 + z2), rel=1e-12)
    # the probability a test fails under F1 is Pd where d = 1 and the nominal Pf elsewhere
    np.testing.assert_allclose(dm.fail_probability()[1], [0.98, 0.0, 0.02])
    # pf_source="class": the class's own firing fraction
    dmc = DMatrix.from_outcomes(outcomes, tests, pf_source="class")
    np.testing.assert_allclose(dmc.fail_probability()[1], [0.98, 0.5, 0.02])
    # a lower level moves F1/g2 into the signature
    assert DMatrix.from_outcomes(outcomes, tests, level=0.4).d[1, 1]


def test_from_outcomes_nominal_row_is_zero_even_with_many_alarms():
    out = {"F0": np.ones((10, 1), bool), "F1": np.ones((10, 1), bool)}
    dm = DMatrix.from_outcomes(out, ["t"])
    assert dm.d.astype(int).tolist() == [[0], [1]]
    assert dm.pf[1, 0] == 1.0


def test_from_outcomes_errors():
    ok = np.zeros((5, 2), bool)
    with pytest.raises(DataError, match="nominal class 'F0' not in outcomes"):
        DMatrix.from_outcomes({"F1": ok}, ["a", "b"])
    with pytest.raises(DataError, match=r"outcomes\['F1'\] has shape \(5, 3\)"):
        DMatrix.from_outcomes({"F0": ok, "F1": np.zeros((5, 3), bool)}, ["a", "b"])
    bad = np.zeros((5, 2))
    bad[3, 1] = np.nan
    with pytest.raises(DataError, match=r"outcomes\['F1'\] run 3, test 'b' is NaN"):
        DMatrix.from_outcomes({"F0": ok, "F1": bad}, ["a", "b"])
    bad[3, 1] = 0.7
    with pytest.raises(DataError, match="is not a boolean outcome"):
        DMatrix.from_outcomes({"F0": ok, "F1": bad}, ["a", "b"])
    with pytest.raises(DataError, match="needs a nominal class"):
        DMatrix.from_outcomes({"F1": ok}, ["a", "b"], nominal=None)
    dm = DMatrix.from_outcomes({"F1": ok, "F2": ~ok}, ["a", "b"], nominal=None, pf_source="class")
    assert dm.d.astype(int).tolist() == [[0, 0], [1, 1]]
