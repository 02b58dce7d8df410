"""Optimal test sequencing on a D-matrix: AO* search on the AND/OR graph, and an exhaustive reference.

Problem (single-fault assumption; Pattipati & Alexandridis, IEEE SMC 20(4), 1990; paper
luo-et-al, Section VII): fault states ``s_i`` with prior probabilities ``p_i`` (summing to 1),
tests ``t_j`` with costs ``c_j >= 0`` and a D-matrix. Find the decision tree (apply a test, branch
on pass / fail, ...) that isolates the fault state with minimum expected test cost

    J = sum_i p_i * (sum of c_j over the tests on the path of s_i).

The search space is an AND/OR graph: an OR node is an ambiguity set ``x`` (the fault states still
possible, a bitmask here), and an AND node is "apply test ``t_j`` at ``x``" with the two successors
``x ∩ pass_j`` and ``x ∩ fail_j``. With unnormalised probabilities ``p(x) = sum_{i in x} p_i`` the
cost-to-go obeys

    h*(x) = min_j [ c_j p(x) + h*(x ∩ pass_j) + h*(x ∩ fail_j) ],   h*(x) = 0 if no test splits x,

which AO* solves best-first, expanding only the partial solution graph that currently looks best.
It is exact when the heuristic underestimates ``h*`` (admissible).

**Heuristic (perfect tests).** The leaves of any complete tree below ``x`` are the classes of
identical D-matrix rows inside ``x`` (a leaf is a set no test splits), so the tree is a binary
prefix code for those classes and ``sum_leaves p(leaf) * depth(leaf)`` is at least the expected
length of the Huffman code of the class masses (Huffman is the optimal prefix code). Every test on
the path costs at least ``c_min(x)``, the cheapest test that splits ``x``. Hence

    h(x) = c_min(x) * Huffman(x)  <=  h*(x)                           (``heuristic="huffman"``)

is admissible (the Huffman-code bound in the spirit of Pattipati & Alexandridis's heuristic
evaluation functions; with equal costs it is their information-theoretic bound).
``"entropy"`` uses the weaker ``c_min(x) * p(x) * H(x)`` (Shannon entropy in bits, ``H <= Huffman``),
``"mincost"`` uses ``c_min(x) * p(x)`` (at least one test is needed) and ``"zero"`` turns AO* into
uniform-cost dynamic programming. All four give the same optimal cost; they differ in how many
nodes are expanded.

**Unreliable tests.** With detection probabilities ``Pd_ij`` and false-alarm probabilities ``Pf_ij``
a test outcome only updates the belief: the OR node is the (unnormalised) joint probability vector
``b_i = p_i * prod_{applied j} P(outcome_j | s_i)`` and its set of unused tests; the AND node for
``t_j`` has the successors ``b * q_j`` (fail) and ``b * (1 - q_j)`` (pass), ``q_ij = P(t_j fails | s_i)``,
i.e. the posterior is updated by Bayes' rule and tests are conditionally independent given the
fault state. Because certainty is never reached, stopping is an option at every OR node: the tree
then declares the maximum-posterior class (faults with identical ``q`` rows) and pays a
misdiagnosis cost ``M`` times the posterior probability of being wrong. The objective is the
expected test cost plus ``M`` times the probability of misdiagnosis (the POMDP view of paper
luo-et-al, Section VII, with a terminal cost). Each test is applied at most once on a path.
Heuristics (all admissible): either stop now (exact cost ``stop(x)``) or apply at least one more
test, which costs at least ``c_min(x) p(x)`` and still leaves at least the Bayes error that
would remain if *every* unused test were applied (more test outcomes never increase the error of
the maximum-posterior decision), so

    h(x) = min( stop(x), c_min(x) p(x) + M * E_all(x) )                  (``heuristic="bayes"``)

where ``E_all`` sums ``p - max class mass`` over the ``2^r`` outcome vectors of the ``r`` unused
tests (used when ``r <= 14``, else ``E_all = 0``); ``"mincost"`` drops the ``E_all`` term and
``"zero"`` uses ``h = 0``. With ``Pd = 1``, ``Pf = 0`` and a large ``M`` the result equals the
perfect-test tree.

**Exhaustive reference.** :func:`exhaustive` solves the same recursion by brute-force dynamic
programming over *all* subsets of faults (perfect tests) or all (applied tests, outcomes) states
(unreliable tests), with no heuristic and no pruning; it is the test oracle of :func:`ao_star`.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...errors import DataError
from ..dmatrix import DMatrix
from .perfect import _ao_perfect, _exhaustive_perfect
from .problem import _HEURISTICS, _check_cost, _check_prior, _mode
from .search import _Budget
from .tree import DiagnosticTree
from .unreliable import _ao_unreliable, _exhaustive_unreliable

__all__ = ["ao_star", "exhaustive"]


def ao_star(dm: DMatrix, prior=None, cost=None, *, tests_model: str = "auto",
            misdiagnosis_cost: float | None = None, heuristic: str = "auto",
            max_nodes: int | None = 200_000, time_limit: float | None = 10.0,
            progress: Callable[[dict], None] | None = None, bayes_max_tests: int = 14) -> DiagnosticTree:
    """Optimal diagnostic tree by AO* search on the AND/OR graph (Pattipati & Alexandridis 1990).

    Parameters
    ----------
    dm : DMatrix
        The D-matrix (``n_f`` fault states x ``n_t`` tests), with Pd/Pf for unreliable tests.
    prior : array_like (n_f,) or mapping fault -> probability, optional
        Prior probabilities of the fault states (single-fault assumption: they sum to 1).
        Default: uniform.
    cost : array_like (n_t,) or mapping test -> cost, optional
        Test costs (>= 0; any unit, e.g. seconds of ECU time). Default: 1 each.
    tests_model : {"auto", "perfect", "unreliable"}
        ``"perfect"`` uses the binary matrix only; ``"unreliable"`` uses ``dm.fail_probability()``
        and Bayes-updated beliefs; ``"auto"`` picks ``"perfect"`` when ``dm.is_perfect``.
    misdiagnosis_cost : float, optional
        Cost (in test-cost units) of declaring the wrong fault class; required for unreliable tests.
    heuristic : {"auto", "huffman", "entropy", "mincost", "zero", "bayes"}
        Admissible lower bound used by the search (module docstring): ``"huffman"``, ``"entropy"``,
        ``"mincost"``, ``"zero"`` for perfect tests; ``"bayes"``, ``"mincost"``, ``"zero"`` for
        unreliable tests. ``"auto"``: ``"huffman"`` (perfect) or ``"bayes"`` (unreliable).
    max_nodes : int or None
        Budget of OR nodes the search may generate (memory: a few hundred bytes each plus a belief
        vector for unreliable tests). ``None``: no limit.
    time_limit : float or None
        Budget of wall-clock seconds. ``None``: no limit. When either budget is spent the search stops
        and the tree is completed by the greedy rule (perfect tests: the test with the most information
        per unit cost; unreliable tests: one-step look-ahead on test plus misdiagnosis cost), the better
        of that completion and the pure greedy tree is returned, and ``stats`` reports the
        ``lower_bound`` (the search's root value; admissible heuristics make it a bound on the
        optimum), the ``gap`` between the tree's evaluated cost and that bound, ``relative_gap`` and
        ``budget_exceeded``. Within budget the result is the exact optimum, as without a budget.
    progress : callable, optional
        Called now and then with ``{"nodes", "expanded", "seconds", "lower_bound", "done"}``.
    bayes_max_tests : int
        The ``"bayes"`` heuristic enumerates the ``2^r`` outcomes of the ``r`` unused tests when
        ``r <= bayes_max_tests`` (default 14, as before); its cost per node grows as ``2^r``.

    Returns
    -------
    DiagnosticTree
        With ``expected_cost`` the optimal expected cost (or, over budget, the cost of the returned
        tree) and ``stats`` (nodes, expansions, time; ``gap`` and ``lower_bound``; ``optimal``).

    Examples
    --------
    >>> dm = DMatrix(list("ABCD"), ["t1", "t2", "t3"],
    ...              [[0, 0, 0], [1, 0, 1], [1, 1, 0], [1, 1, 1]])
    >>> tree = ao_star(dm, prior=[0.4, 0.3, 0.2, 0.1])
    >>> round(tree.expected_cost, 12), tree.go_path
    (1.9, ['t1'])
    """
    p, c = _check_prior(dm, prior), _check_cost(dm, cost)
    mode, M = _mode(dm, tests_model, misdiagnosis_cost)
    if heuristic == "auto":
        heuristic = "huffman" if mode == "perfect" else "bayes"
    if heuristic not in _HEURISTICS[mode]:
        raise DataError(f"heuristic for {mode} tests must be 'auto' or one of {_HEURISTICS[mode]}, "
                        f"got {heuristic!r}")
    for v, what in ((max_nodes, "max_nodes"), (time_limit, "time_limit")):
        if v is not None and not (np.isfinite(v) and v > 0):
            raise DataError(f"{what} must be a positive number or None, got {v}")
    budget = _Budget(None if max_nodes is None else int(max_nodes), time_limit, progress)
    if mode == "perfect":
        J, root, stats = _ao_perfect(dm, p, c, heuristic, budget)
    else:
        J, root, stats = _ao_unreliable(dm, p, c, M, heuristic, budget, int(bayes_max_tests))
    stats.setdefault("budget_exceeded", None)
    if stats["budget_exceeded"] is None:
        stats.update(lower_bound=float(J), gap=0.0, relative_gap=0.0, optimal=True)
    stats.update(method="ao*" if stats["budget_exceeded"] is None else "ao*+greedy", heuristic=heuristic)
    tree = DiagnosticTree(root, dm, p, c, mode, M, float(J), stats)
    if progress is not None:
        progress({"nodes": stats["nodes"], "expanded": stats["expanded"], "seconds": stats["wall_seconds"],
                  "lower_bound": stats["lower_bound"], "done": True})
    return tree


def exhaustive(dm: DMatrix, prior=None, cost=None, *, tests_model: str = "auto",
               misdiagnosis_cost: float | None = None) -> DiagnosticTree:
    """Optimal diagnostic tree by brute-force dynamic programming (the reference for :func:`ao_star`).

    Perfect tests: the recursion of the module docstring over all ``2^n_f - 1`` subsets, in order of
    size (memory and time ``O(2^n_f n_t)``; practical up to about 16 faults). Unreliable tests: the
    recursion over all (applied tests, outcomes) states (``3^n_t`` of them). Parameters as
    :func:`ao_star`.

    Examples
    --------
    >>> dm = DMatrix(list("ABCD"), ["t1", "t2", "t3"],
    ...              [[0, 0, 0], [1, 0, 1], [1, 1, 0], [1, 1, 1]])
    >>> round(exhaustive(dm, prior=[0.4, 0.3, 0.2, 0.1]).expected_cost, 12)
    1.9
    """
    p, c = _check_prior(dm, prior), _check_cost(dm, cost)
    mode, M = _mode(dm, tests_model, misdiagnosis_cost)
    if mode == "perfect":
        if len(dm.faults) > 22:
            raise DataError(f"exhaustive search over 2^{len(dm.faults)} subsets is too large; use ao_star")
        J, root, stats = _exhaustive_perfect(dm, p, c)
    else:
        J, root, stats = _exhaustive_unreliable(dm, p, c, M)
    stats.update(method="exhaustive", heuristic=None)
    return DiagnosticTree(root, dm, p, c, mode, M, float(J), stats)

