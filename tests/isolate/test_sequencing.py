"""Optimal test sequencing: AO* against hand-solved trees and the exhaustive dynamic program."""

import itertools

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.isolate import DiagnosticTree, DMatrix, ao_star, exhaustive, huffman_cost

HEURISTICS = ["huffman", "entropy", "mincost", "zero"]

# hand-solvable example: A is the all-pass state; t1 isolates A, t2 splits {A,B} | {C,D},
# t3 splits {A,C} | {B,D}
HAND = DMatrix(list("ABCD"), ["t1", "t2", "t3"], [[0, 0, 0], [1, 0, 1], [1, 1, 0], [1, 1, 1]])
HAND_PRIOR = [0.4, 0.3, 0.2, 0.1]


def random_problem(seed, nf, nt, density=None):
    rng = np.random.default_rng(seed)
    dens = rng.uniform(0.25, 0.75) if density is None else density
    d = rng.random((nf, nt)) < dens
    dm = DMatrix([f"F{i}" for i in range(nf)], [f"t{j}" for j in range(nt)], d)
    return dm, rng.dirichlet(np.ones(nf)), rng.uniform(0.5, 3.0, nt)


def test_hand_example_unit_costs():
    # By hand (unit costs): t1 first isolates A (p 0.4) with one test; {B,C,D} then needs t2 (B | C,D)
    # and t3 (C | D): J = 0.4*1 + 0.3*2 + (0.2 + 0.1)*3 = 1.9. t2 or t3 first costs 2 for every
    # fault (J = 2.0), and t1 -> t3 costs 0.4 + 0.2*2 + 0.4*3 = 2.0. The Huffman bound is also 1.9.
    for h in HEURISTICS:
        tree = ao_star(HAND, HAND_PRIOR, heuristic=h)
        assert tree.expected_cost == pytest.approx(1.9, abs=1e-12)
        assert tree.root.test == "t1"
        assert tree.root.passed.group == ("A",)
        assert tree.root.failed.test == "t2"
        assert tree.root.failed.passed.group == ("B",)
        assert tree.root.failed.failed.test == "t3"
        assert [leaf.group for leaf in tree.leaves()] == [("A",), ("B",), ("C",), ("D",)]
        assert tree.depth == 3
        assert tree.go_path == ["t1"]
        assert tree.redundant_tests == []
    assert huffman_cost(HAND_PRIOR) == pytest.approx(1.9)


def test_hand_example_expensive_t1():
    # t1 costs 2: t1-first costs 0.4*2 + 0.3*3 + 0.3*4 = 2.9; t2 then t3 (or t3 then t2) costs 2 for
    # everyone: J = 2.0 and t1 is redundant.
    tree = ao_star(HAND, HAND_PRIOR, {"t1": 2.0, "t2": 1.0, "t3": 1.0})
    assert tree.expected_cost == pytest.approx(2.0, abs=1e-12)
    assert tree.root.test in ("t2", "t3")
    assert tree.redundant_tests == ["t1"]
    assert tree.depth == 2
    assert tree.evaluate()["expected_test_cost"] == pytest.approx(2.0, abs=1e-12)


def test_table_iv_tree_go_path_and_redundant_svm_test():
    # Luo et al. Table IV, unit costs, P(F0) = 0.93 and 0.01 for each of the 7 faults.
    # By hand: only G_O1 separates F0 from every fault, and any tree not starting with it spends >= 2
    # tests on F0 (>= 1.86), so the root is G_O1 (Go-path [G_O1], as in the paper). Among the 7 faults the
    # first test splits them 2/5 at best (G_P1, G_O_T1, G_O_T2) or 1/6; 2/5 then the best 5-fault
    # tree (depths 2,2,2,3,3) gives total depth 2*2 + 5 + 12 = 21, the Huffman bound with a 2/5 root;
    # 1/6 gives >= 1 + 6 + 16 = 23. So J = 0.93*1 + 0.01*(7 + 21) = 1.21. The paper's tree (Fig. 14 /
    # the listing) has depths F0 1, F3 3, F4 3, F5 4, F2.x 5, F1.x 4: 0.93 + 0.01*28 = 1.21 as well.
    # S_Kf and S_Iw are the only tests that separate F3 from F4, so exactly one of them is redundant.
    tests = ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2", "S_Kf", "S_Iw"]
    faults = ["F0", "F1.1", "F1.2", "F2.1", "F2.2", "F3", "F4", "F5"]
    d = [[0, 0, 0, 0, 0, 0, 0], [0, 1, 1, 0, 1, 0, 0], [1, 1, 1, 0, 1, 0, 0], [0, 1, 1, 0, 0, 0, 0],
         [1, 1, 1, 0, 0, 0, 0], [0, 1, 1, 1, 0, 1, 0], [0, 1, 1, 1, 0, 0, 1], [0, 1, 0, 0, 0, 0, 0]]
    dm = DMatrix(faults, tests, d)
    prior = [0.93] + [0.01] * 7
    tree = ao_star(dm, prior)
    assert tree.expected_cost == pytest.approx(1.21, abs=1e-12)
    assert exhaustive(dm, prior).expected_cost == pytest.approx(1.21, abs=1e-12)
    assert tree.go_path == ["G_O1"]
    assert tree.root.passed.group == ("F0",)
    assert len(tree.redundant_tests) == 1 and tree.redundant_tests[0] in ("S_Kf", "S_Iw")
    assert sorted(leaf.group for leaf in tree.leaves()) == sorted((f,) for f in faults)
    assert tree.stats["wall_seconds"] < 1.0


@pytest.mark.parametrize("seed", range(8))
def test_ao_star_equals_exhaustive_random(seed):
    rng = np.random.default_rng(100 + seed)
    nf, nt = int(rng.integers(6, 13)), int(rng.integers(4, 11))
    if seed < 2:
        nf, nt = 12, 10
    dm, p, c = random_problem(seed, nf, nt)
    ref = exhaustive(dm, p, c)
    assert ref.evaluate()["objective"] == pytest.approx(ref.expected_cost, rel=1e-12)
    for h in HEURISTICS:
        tree = ao_star(dm, p, c, heuristic=h)
        assert tree.expected_cost == pytest.approx(ref.expected_cost, rel=1e-10, abs=1e-12), h
        # the cost recomputed from the tree alone agrees with the search's value
        assert tree.evaluate()["objective"] == pytest.approx(tree.expected_cost, rel=1e-10)
        # every fault lands in the leaf that holds its ambiguity class
        for f in dm.faults:
            assert f in tree.diagnose(dm.row(f))
        assert sorted(leaf.group for leaf in tree.leaves()) == sorted(dm.classes())


def test_ao_star_equals_exhaustive_sweep():
    # 60 random problems from 2x1 to 12x10; every third with equal costs (many ties)
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        nf, nt = int(rng.integers(2, 13)), int(rng.integers(1, 11))
        dm, p, c = random_problem(seed + 5000, nf, nt)
        if seed % 3 == 0:
            c = np.ones(nt)
        ref = exhaustive(dm, p, c).expected_cost
        for h in HEURISTICS:
            got = ao_star(dm, p, c, heuristic=h).expected_cost
            assert got == pytest.approx(ref, rel=1e-10, abs=1e-12), (seed, h)


@pytest.mark.slow
@pytest.mark.parametrize("shape", [(12, 10), (14, 12)])
def test_ao_star_equals_exhaustive_large_sweep(shape):
    nf, nt = shape
    for seed in range(150 if nf == 12 else 30):
        dm, p, c = random_problem(seed + 9000, nf, nt)
        if seed % 2:
            c = np.ones(nt)
        ref = exhaustive(dm, p, c).expected_cost
        for h in HEURISTICS:
            got = ao_star(dm, p, c, heuristic=h).expected_cost
            assert got == pytest.approx(ref, rel=1e-10, abs=1e-12), (seed, h)


def test_heuristic_is_admissible_and_prunes():
    # the Huffman bound at the root never exceeds the optimum; informed heuristics expand fewer nodes
    for seed in range(6):
        dm, p, c = random_problem(seed + 20, 10, 8)
        opt = exhaustive(dm, p, c).expected_cost
        masses = [sum(p[dm.faults.index(f)] for f in g) for g in dm.classes()]
        split = [j for j in range(8) if 0 < dm.d[:, j].sum() < 10]
        assert min(c[split]) * huffman_cost(masses) <= opt + 1e-12
    dm, p, c = random_problem(7, 12, 10, density=0.5)
    expanded = {h: ao_star(dm, p, c, heuristic=h).stats["expanded"] for h in HEURISTICS}
    assert expanded["huffman"] <= expanded["zero"]
    assert expanded["mincost"] <= expanded["zero"]


def test_huffman_cost_against_code_lengths():
    # p = (0.5, 0.25, 0.125, 0.125): lengths 1, 2, 3, 3 -> 1.75 (= entropy, dyadic)
    assert huffman_cost([0.125, 0.5, 0.25, 0.125]) == pytest.approx(1.75)
    # 5 equal masses: lengths 2, 2, 2, 3, 3 -> 12/5
    assert huffman_cost([0.2] * 5) == pytest.approx(2.4)
    assert huffman_cost([]) == 0.0


def test_ambiguity_group_leaf_and_zero_prior():
    dm = DMatrix(["F0", "a", "b", "c"], ["t1", "t2"], [[0, 0], [1, 0], [1, 0], [1, 1]])
    tree = ao_star(dm, [0.5, 0.2, 0.0, 0.3])
    assert tree.ambiguity_groups == [("a", "b")]
    assert tree.diagnose([1, 0]) == ("a", "b")
    # by hand: t1 then t2 on its fail branch: 1 + 0.5 = 1.5; t2 first: 1 + (0.5 + 0.2) = 1.7
    assert tree.expected_cost == pytest.approx(1.5)


def _policies_two_tests(tests):
    """Every decision policy that applies each test at most once: None = stop."""
    pols = [None]
    for a, b in itertools.permutations(tests, 2):
        for on_pass in (None, b):
            for on_fail in (None, b):
                pols.append((a, on_pass, on_fail))
    for a in tests:
        pols.append((a, None, None))
    return pols


def test_unreliable_hand_example():
    # Two states A (prior 0.6), B (0.4); P(fail | A), P(fail | B): t1 (0.9, 0.2), t2 (0.95, 0.3); unit costs;
    # misdiagnosis costs M = 30. By hand:
    #   t1 pass: joint A 0.06, B 0.32 -> declare B, error 0.06;
    #   t1 fail: joint A 0.54, B 0.08; applying t2 (cost 0.62): fail A 0.513, B 0.024 -> A (error 0.024);
    #            pass A 0.027, B 0.056 -> B (error 0.027); error 0.051.
    #   J = 1 + 0.62 + 30 (0.06 + 0.051) = 4.95.
    # Alternatives: stop at once 30*0.4 = 12; t1 then stop 1 + 30 (0.06 + 0.08) = 5.2; t2 first then t1
    # on its fail branch only: 1 + 0.69 + 30 (0.03 + 0.024 + 0.057) = 5.02; both branches 5.33.
    dm = DMatrix(["A", "B"], ["t1", "t2"], [[1, 1], [0, 0]],
                 pd=[[0.9, 0.95], [1, 1]], pf=[[0, 0], [0.2, 0.3]])
    prior, M = [0.6, 0.4], 30.0
    tree = ao_star(dm, prior, misdiagnosis_cost=M)
    assert tree.tests_model == "unreliable"
    assert tree.expected_cost == pytest.approx(4.95, abs=1e-12)
    assert tree.root.test == "t1"
    assert tree.root.passed.is_leaf and tree.root.passed.group == ("B",)
    assert tree.root.failed.test == "t2"
    assert tree.root.failed.failed.group == ("A",)
    assert tree.root.failed.failed.posterior["A"] == pytest.approx(0.513 / 0.537)    # Bayes
    ev = tree.evaluate()
    assert ev["expected_test_cost"] == pytest.approx(1.62)
    assert ev["misdiagnosis_probability"] == pytest.approx(0.111)
    assert exhaustive(dm, prior, misdiagnosis_cost=M).expected_cost == pytest.approx(4.95, abs=1e-12)

    # independent brute force over the explicit policies (joint probabilities summed per fault)
    q = {"t1": (0.9, 0.2), "t2": (0.95, 0.3)}

    def policy_cost(pol):
        total = 0.0
        for i, pi in enumerate(prior):
            for o1, o2 in itertools.product((0, 1), repeat=2):
                def pr(t, o, i=i):
                    return q[t][i] if o else 1 - q[t][i]
                if pol is None:
                    path, w = [], pi if (o1, o2) == (0, 0) else 0.0
                else:
                    a, on_pass, on_fail = pol
                    nxt = on_fail if o1 else on_pass
                    path = [(a, o1)] + ([(nxt, o2)] if nxt else [])
                    w = pi * np.prod([pr(t, o) for t, o in path]) * (1.0 if nxt or o2 == 0 else 0.0)
                if w == 0.0:
                    continue
                # MAP decision at the leaf from the joint of both states
                joint = [pj * np.prod([(q[t][k] if o else 1 - q[t][k]) for t, o in path])
                         for k, pj in enumerate(prior)]
                decide = int(np.argmax(joint))
                total += w * (len(path) + (M if decide != i else 0.0))
        return total

    costs = [policy_cost(pol) for pol in _policies_two_tests(["t1", "t2"])]
    assert min(costs) == pytest.approx(4.95, abs=1e-12)


def test_unreliable_with_perfect_probabilities_equals_perfect():
    for seed in range(4):
        dm, p, c = random_problem(seed + 40, 6, 5)
        perfect = ao_star(dm, p, c).expected_cost
        as_unrel = ao_star(dm, p, c, tests_model="unreliable", misdiagnosis_cost=1e4)
        assert as_unrel.expected_cost == pytest.approx(perfect, rel=1e-10)
        assert as_unrel.evaluate()["misdiagnosis_probability"] == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_unreliable_ao_star_equals_exhaustive(seed):
    rng = np.random.default_rng(seed + 300)
    nf, nt = int(rng.integers(2, 8)), int(rng.integers(1, 7))
    d = rng.random((nf, nt)) < 0.5
    dm = DMatrix([f"F{i}" for i in range(nf)], [f"t{j}" for j in range(nt)], d,
                 pd=rng.uniform(0.6, 1.0, (nf, nt)), pf=rng.uniform(0.0, 0.3, (nf, nt)))
    p, c, M = rng.dirichlet(np.ones(nf)), rng.uniform(0.5, 3, nt), float(rng.uniform(2, 60))
    ref = exhaustive(dm, p, c, misdiagnosis_cost=M)
    for h in ("bayes", "mincost", "zero"):
        tree = ao_star(dm, p, c, misdiagnosis_cost=M, heuristic=h)
        assert tree.expected_cost == pytest.approx(ref.expected_cost, rel=1e-10)
        assert tree.evaluate()["objective"] == pytest.approx(tree.expected_cost, rel=1e-10)


def test_tree_text_and_dict():
    tree = ao_star(HAND, HAND_PRIOR)
    text = tree.to_text()
    assert text.splitlines()[0].startswith(
        "Diagnostic tree: expected cost 1.9, depth 3, 4 leaves, go-path [t1]")
    assert "  NG -> t2  (P=0.6)" in text
    d = tree.to_dict()
    assert d["tree"]["test"] == "t1" and d["tree"]["pass"]["leaf"] == ["A"]
    assert d["go_path"] == ["t1"]


def test_diagnose_inputs():
    tree = ao_star(HAND, HAND_PRIOR)
    assert tree.diagnose({"t1": 1, "t2": 1, "t3": 0}) == ("C",)
    assert tree.diagnose([1, 1, 1]) == ("D",)
    asked = []
    assert tree.diagnose(lambda t: asked.append(t) or t != "t1") == ("A",)
    assert asked == ["t1"]
    with pytest.raises(DataError, match="requests test 't2'"):
        tree.diagnose({"t1": True})
    with pytest.raises(DataError, match="got 2 outcomes for 3 tests"):
        tree.diagnose([1, 0])


def test_bad_inputs():
    with pytest.raises(DataError, match="sum to 0.9"):
        ao_star(HAND, [0.4, 0.3, 0.1, 0.1])
    with pytest.raises(DataError, match="prior of fault 'B' is -0.1"):
        ao_star(HAND, [0.6, -0.1, 0.4, 0.1])
    with pytest.raises(DataError, match="prior has 3 entries but the D-matrix has 4 faults"):
        ao_star(HAND, [0.4, 0.3, 0.3])
    with pytest.raises(DataError, match=r"prior names \['E'\] are not faults"):
        ao_star(HAND, {"A": 0.4, "B": 0.3, "C": 0.2, "E": 0.1})
    with pytest.raises(DataError, match=r"prior has no probability for faults \['D'\]"):
        ao_star(HAND, {"A": 0.4, "B": 0.3, "C": 0.3})
    with pytest.raises(DataError, match="cost of test 't2' is -1.0"):
        ao_star(HAND, HAND_PRIOR, [1, -1, 1])
    with pytest.raises(DataError, match=r"cost names \['t9'\] are not tests"):
        exhaustive(HAND, HAND_PRIOR, {"t1": 1, "t2": 1, "t9": 1})
    with pytest.raises(DataError, match="heuristic for perfect tests must be 'auto' or one of"):
        ao_star(HAND, heuristic="greedy")
    with pytest.raises(DataError, match="heuristic for unreliable tests"):
        ao_star(DMatrix(["a", "b"], ["t"], [[1], [0]], pd=0.9), misdiagnosis_cost=5.0, heuristic="huffman")
    unrel = DMatrix(["a", "b"], ["t"], [[1], [0]], pd=0.9)
    with pytest.raises(DataError, match="needs misdiagnosis_cost"):
        ao_star(unrel)
    with pytest.raises(DataError, match="tests_model must be"):
        ao_star(unrel, tests_model="noisy")


def test_learned_dmatrix_end_to_end():
    # outcomes simulated from a known firing-probability matrix; the learned binary matrix equals the
    # true one (entries far from the 0.5 level), so the perfect-test tree is the same; the unreliable
    # tree from the learned Pd/Pf has an objective within Monte Carlo error of the true model's.
    rng = np.random.default_rng(11)
    faults, tests = ["F0", "F1", "F2", "F3"], ["a", "b", "c"]
    q = np.array([[0.01, 0.02, 0.0], [0.97, 0.02, 0.9], [0.95, 0.99, 0.05], [0.03, 0.9, 0.95]])
    outcomes = {f: rng.random((4000, 3)) < q[i] for i, f in enumerate(faults)}
    learned = DMatrix.from_outcomes(outcomes, tests, pf_source="class")
    true = DMatrix(faults, tests, q > 0.5, pd=q, pf=q)
    assert (learned.d == true.d).all()
    assert np.abs(learned.fail_probability() - q).max() < 0.02
    prior = [0.7, 0.1, 0.1, 0.1]
    t_learned = ao_star(learned, prior, tests_model="perfect")
    t_true = ao_star(true, prior, tests_model="perfect")
    assert t_learned.to_dict()["tree"] == t_true.to_dict()["tree"]
    u_learned = ao_star(learned, prior, misdiagnosis_cost=50.0)
    u_true = ao_star(true, prior, misdiagnosis_cost=50.0)
    strip = {"probability"}

    def shape(node):
        return {k: (shape(v) if isinstance(v, dict) else v) for k, v in node.items() if k not in strip}

    assert shape(u_learned.to_dict()["tree"]) == shape(u_true.to_dict()["tree"])
    # objective = test cost (~1.8) + 50 x misdiagnosis probability (~0.03): entries learned to about
    # +-0.003 move it by well under 0.2
    assert abs(u_learned.expected_cost - u_true.expected_cost) < 0.2


def _leaf(f):
    return {"leaf": [f]}


def _test(t, on_pass, on_fail):
    return {"test": t, "pass": on_pass, "fail": on_fail}


def test_paper_fig14_tree_loaded_and_evaluated():
    # The tree of luo-et-al Fig. 14 / the IF-THEN-ELSE listing, with leaves named from Table IV
    # (the listing's R_w / sensor labels under G_O_T2 are swapped with respect to Table IV, where
    # G_O_T2 fires for the R_w faults F1.x). By hand its depths are F0 1, F3 3, F4 3, F1.x 4, F5 4,
    # F2.x 5: with P(F0) = 0.93 and 0.01 per fault, J = 0.93 + 0.01 * 28 = 1.21, equal to the AO* optimum.
    tests = ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2", "S_Kf", "S_Iw"]
    faults = ["F0", "F1.1", "F1.2", "F2.1", "F2.2", "F3", "F4", "F5"]
    d = [[0, 0, 0, 0, 0, 0, 0], [0, 1, 1, 0, 1, 0, 0], [1, 1, 1, 0, 1, 0, 0], [0, 1, 1, 0, 0, 0, 0],
         [1, 1, 1, 0, 0, 0, 0], [0, 1, 1, 1, 0, 1, 0], [0, 1, 1, 1, 0, 0, 1], [0, 1, 0, 0, 0, 0, 0]]
    dm = DMatrix(faults, tests, d)
    prior = [0.93] + [0.01] * 7
    fig14 = _test("G_O1", _leaf("F0"),
                  _test("G_O_T1",
                        _test("G_O_T2",
                              _test("G_O2", _leaf("F5"), _test("G_P1", _leaf("F2.1"), _leaf("F2.2"))),
                              _test("G_P1", _leaf("F1.1"), _leaf("F1.2"))),
                        _test("S_Kf", _leaf("F4"), _leaf("F3"))))
    data = {"dmatrix": dm.to_dict(), "prior": prior, "cost": [1.0] * 7, "tests_model": "perfect",
            "tree": fig14}
    paper = DiagnosticTree.from_dict(data)
    assert paper.expected_cost == pytest.approx(1.21, abs=1e-12)
    assert paper.expected_cost == pytest.approx(ao_star(dm, prior).expected_cost, abs=1e-12)
    assert paper.go_path == ["G_O1"]
    assert paper.redundant_tests == ["S_Iw"]
    assert paper.depth == 5
    for f in faults:                              # every fault reaches its own leaf
        assert paper.diagnose(dm.row(f)) == (f,)
    # a wrong leaf is detected by simulating the faults through the loaded tree
    bad = dict(data, tree=_test("G_O1", _leaf("F0"), _test("S_Kf", _leaf("F4"), _leaf("F3"))))
    loaded = DiagnosticTree.from_dict(bad)
    assert loaded.diagnose(dm.row("F5")) == ("F4",)
    assert loaded.evaluate()["misdiagnosis_probability"] > 0
    with pytest.raises(DataError, match="test 'G_O9', which is not in the D-matrix"):
        DiagnosticTree.from_dict(dict(data, tree=_test("G_O9", _leaf("F0"), _leaf("F1.1"))))
    with pytest.raises(DataError, match="test 'G_O1' is applied twice"):
        DiagnosticTree.from_dict(dict(data, tree=_test("G_O1", _leaf("F0"),
                                                       _test("G_O1", _leaf("F0"), _leaf("F1.1")))))


def test_tree_json_roundtrip():
    import json

    cases = [ao_star(HAND, HAND_PRIOR)]
    rng = np.random.default_rng(3)
    dm = DMatrix(list("abcde"), ["u", "v", "w", "x"], rng.random((5, 4)) < 0.5,
                 pd=rng.uniform(0.7, 1, (5, 4)), pf=rng.uniform(0, 0.2, (5, 4)))
    cases.append(ao_star(dm, misdiagnosis_cost=20.0))
    for tree in cases:
        again = DiagnosticTree.from_dict(json.loads(json.dumps(tree.to_dict())))
        assert again.to_text().splitlines()[1:] == tree.to_text().splitlines()[1:]
        assert again.expected_cost == pytest.approx(tree.expected_cost, rel=1e-12)
        assert again.tests_model == tree.tests_model
        for o in itertools.product((0, 1), repeat=len(tree.dmatrix.tests)):
            assert again.diagnose(o) == tree.diagnose(o)
