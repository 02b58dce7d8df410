"""AO* with a node and time budget (issue 15): exact under budget, greedy completion with a reported
optimality gap over it, and a 42-test unreliable problem sequenced in seconds."""

import time

import numpy as np
import pytest

from fdikit.isolate import DMatrix, ao_star, exhaustive


def unreliable(nt, nf=8, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.random((nf, nt)) < 0.4
    d[0] = False
    pd = rng.uniform(0.6, 0.99, (nf, nt))
    pf = np.broadcast_to(rng.uniform(0.005, 0.05, nt), (nf, nt))
    return DMatrix([f"F{i}" for i in range(nf)], [f"t{j}" for j in range(nt)], d, pd=pd, pf=pf)


def perfect(nf, nt, seed):
    rng = np.random.default_rng(seed)
    d = rng.random((nf, nt)) < 0.5
    p = rng.dirichlet(np.ones(nf))
    c = rng.uniform(0.5, 2.0, nt)
    return DMatrix([f"F{i}" for i in range(nf)], [f"t{j}" for j in range(nt)], d), p, c


@pytest.mark.parametrize("seed", range(4))
def test_under_budget_equals_exhaustive_optimum(seed):
    dm, p, c = perfect(7, 6, seed)
    ref = exhaustive(dm, p, c).expected_cost
    tree = ao_star(dm, p, c, max_nodes=10_000, time_limit=30.0)
    assert tree.stats["budget_exceeded"] is None and tree.stats["optimal"] and tree.stats["gap"] == 0.0
    assert tree.expected_cost == pytest.approx(ref, abs=1e-12)
    dmu = unreliable(5, nf=5, seed=seed)
    refu = exhaustive(dmu, misdiagnosis_cost=10.0).expected_cost
    tu = ao_star(dmu, misdiagnosis_cost=10.0, max_nodes=100_000)
    assert tu.stats["optimal"] and tu.expected_cost == pytest.approx(refu, abs=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_over_budget_the_optimum_lies_within_the_reported_gap(seed):
    # perfect tests, 10 faults: the exhaustive optimum is known; the budget is far too small for AO*
    dm, p, c = perfect(10, 9, seed)
    opt = exhaustive(dm, p, c).expected_cost
    tree = ao_star(dm, p, c, max_nodes=15)
    st = tree.stats
    assert st["budget_exceeded"] == "node budget 15" and st["method"] == "ao*+greedy"
    assert tree.evaluate()["objective"] == pytest.approx(tree.expected_cost, abs=1e-12)
    assert st["lower_bound"] <= opt + 1e-12 <= tree.expected_cost + 2e-12
    assert tree.expected_cost - st["lower_bound"] == pytest.approx(st["gap"], abs=1e-12)
    # unreliable tests: same guarantee against the exhaustive DP
    dmu = unreliable(6, nf=6, seed=seed)
    optu = exhaustive(dmu, misdiagnosis_cost=10.0).expected_cost
    tu = ao_star(dmu, misdiagnosis_cost=10.0, max_nodes=40)
    assert tu.stats["budget_exceeded"] is not None
    assert tu.stats["lower_bound"] <= optu + 1e-12 <= tu.expected_cost + 2e-12
    assert tu.evaluate()["objective"] == pytest.approx(tu.expected_cost, abs=1e-12)


def test_42_tests_return_a_tree_in_seconds_with_its_gap():
    # issue 15: "14 tests took 27 s and 0.5 GB, 16 tests ran over 90 s. A 42-test problem cannot be
    # sequenced."
    dm = unreliable(42)
    seen = []
    t0 = time.perf_counter()
    tree = ao_star(dm, misdiagnosis_cost=20.0, time_limit=3.0, progress=seen.append)
    wall = time.perf_counter() - t0
    assert wall < 8.0
    st = tree.stats
    assert st["budget_exceeded"] == "time budget 3 s"
    assert 0.0 <= st["lower_bound"] <= tree.expected_cost
    assert st["relative_gap"] == pytest.approx(st["gap"] / tree.expected_cost)
    assert tree.evaluate()["objective"] == pytest.approx(tree.expected_cost, abs=1e-9)
    # never worse than stopping at once (declaring the prior's most likely class) or than the greedy tree
    stop_now = 20.0 * (1 - 1 / 8)
    assert tree.expected_cost < stop_now
    assert seen and seen[-1]["done"] and seen[-1]["nodes"] == st["nodes"]
    # the tree diagnoses: every leaf declares a class
    assert all(leaf.group for leaf in tree.leaves())


def test_default_budget_keeps_the_paper_size_problems_exact():
    # the ABS-size problem (8 faults x 9 tests, perfect) is far inside the default budget: the same tree
    dm, p, c = perfect(8, 9, 11)
    a = ao_star(dm, p, c)
    b = ao_star(dm, p, c, max_nodes=None, time_limit=None)
    assert a.to_text() == b.to_text() and a.stats["optimal"]


def test_budget_arguments_are_checked():
    dm, p, c = perfect(4, 3, 0)
    with pytest.raises(Exception, match="max_nodes"):
        ao_star(dm, p, c, max_nodes=0)
    with pytest.raises(Exception, match="time_limit"):
        ao_star(dm, p, c, time_limit=-1.0)
