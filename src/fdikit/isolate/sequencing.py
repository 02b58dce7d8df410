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

import heapq
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from .dmatrix import DMatrix

__all__ = ["DiagnosticTree", "TreeNode", "ao_star", "exhaustive", "huffman_cost"]

_HEURISTICS = {"perfect": ("huffman", "entropy", "mincost", "zero"),
               "unreliable": ("bayes", "mincost", "zero")}


# ---------------------------------------------------------------------------------------------- inputs
def _named_vector(values, names: list[str], what: str, per: str, owner: str) -> np.ndarray:
    """A finite, non-negative vector with one entry per name, from a mapping or a sequence."""
    if isinstance(values, Mapping):
        unknown = [k for k in values if k not in names]
        if unknown:
            raise DataError(f"{what} names {unknown} are not {per}s of the D-matrix {names}")
        missing = [f for f in names if f not in values]
        if missing:
            raise DataError(f"{what} has no {'probability' if what == 'prior' else 'value'} for {per}s "
                            f"{missing}")
        v = np.array([float(values[f]) for f in names])
    else:
        v = np.asarray(values, float).ravel()
        if v.shape != (len(names),):
            raise DataError(f"{what} has {v.size} entries but the D-matrix has {len(names)} {per}s {names}")
    bad = ~np.isfinite(v) | (v < 0)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise DataError(f"{what} of {per} {names[i]!r} is {v[i]}; {owner} must be finite and >= 0")
    return v


def _check_prior(dm: DMatrix, prior) -> np.ndarray:
    if prior is None:
        return np.full(len(dm.faults), 1.0 / len(dm.faults))
    p = _named_vector(prior, list(dm.faults), "prior", "fault", "priors")
    s = float(p.sum())
    if abs(s - 1.0) > 1e-9:
        raise DataError(f"prior probabilities sum to {s:.12g}, not 1 (single-fault assumption: the fault "
                        "states, including the no-fault state if modelled, are exhaustive and exclusive)")
    return p


def _check_cost(dm: DMatrix, cost) -> np.ndarray:
    if cost is None:
        return np.ones(len(dm.tests))
    return _named_vector(cost, list(dm.tests), "cost", "test", "test costs")


def _mode(dm: DMatrix, tests_model: str, misdiagnosis_cost) -> tuple[str, float | None]:
    if tests_model == "auto":
        tests_model = "perfect" if dm.is_perfect else "unreliable"
    if tests_model not in ("perfect", "unreliable"):
        raise DataError(f"tests_model must be 'auto', 'perfect' or 'unreliable', got {tests_model!r}")
    if tests_model == "unreliable":
        if misdiagnosis_cost is None:
            raise DataError("unreliable-test sequencing needs misdiagnosis_cost (the cost of declaring the "
                            "wrong fault, in test-cost units); the D-matrix has Pd < 1 or Pf > 0 entries")
        M = float(misdiagnosis_cost)
        if not np.isfinite(M) or M < 0:
            raise DataError(f"misdiagnosis_cost must be finite and >= 0, got {misdiagnosis_cost}")
        return tests_model, M
    return tests_model, None


def huffman_cost(masses) -> float:
    """Expected codeword length times total mass of the binary Huffman code of ``masses``.

    Equals ``sum_i m_i * len_i`` for the optimal binary prefix code (the sum of the merged weights).

    Examples
    --------
    >>> huffman_cost([0.4, 0.3, 0.2, 0.1])   # lengths 1, 2, 3, 3
    1.9
    >>> huffman_cost([0.7])
    0.0
    """
    h = [float(m) for m in masses]
    if len(h) < 2:
        return 0.0
    heapq.heapify(h)
    total = 0.0
    while len(h) > 1:
        s = heapq.heappop(h) + heapq.heappop(h)
        total += s
        heapq.heappush(h, s)
    return round(total, 15)


# ---------------------------------------------------------------------------------------------- tree
@dataclass
class TreeNode:
    """A node of a diagnostic tree.

    ``test`` is the test applied here (``None`` at a leaf). ``faults`` are the fault states still
    possible (perfect tests: consistent with the outcomes so far; unreliable tests: non-zero
    posterior); ``probability`` is the probability of reaching the node;
    ``posterior`` maps fault -> posterior probability at the node. A leaf's ``group`` is the diagnosis:
    the ambiguity group (perfect tests) or the maximum-posterior class (unreliable tests).
    ``passed`` / ``failed`` are the successors for outcome G / NG.
    """

    test: str | None
    faults: tuple[str, ...]
    probability: float
    posterior: dict[str, float]
    group: tuple[str, ...] | None = None
    passed: TreeNode | None = None
    failed: TreeNode | None = None

    @property
    def is_leaf(self) -> bool:
        return self.test is None


@dataclass
class DiagnosticTree:
    """An optimal diagnostic (AND/OR) tree.

    Attributes
    ----------
    root : TreeNode
    dmatrix : DMatrix
    prior : ndarray (n_f,), cost : ndarray (n_t,)
    tests_model : {"perfect", "unreliable"}
    misdiagnosis_cost : float or None
    expected_cost : float
        Optimal objective found by the search: expected test cost (plus ``M`` x probability of
        misdiagnosis for unreliable tests), in the unit of the test costs.
    stats : dict
        ``method``, ``heuristic``, ``nodes`` (OR nodes generated), ``expanded``, ``wall_seconds``.
    """

    root: TreeNode
    dmatrix: DMatrix
    prior: np.ndarray
    cost: np.ndarray
    tests_model: str
    misdiagnosis_cost: float | None
    expected_cost: float
    stats: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ structure
    def leaves(self) -> list[TreeNode]:
        """Leaves in depth-first order, pass branch first (this order defines the C leaf index)."""
        out: list[TreeNode] = []

        def walk(n):
            if n.is_leaf:
                out.append(n)
            else:
                walk(n.passed)
                walk(n.failed)

        walk(self.root)
        return out

    @property
    def depth(self) -> int:
        """Largest number of tests on a root-to-leaf path."""
        def d(n):
            return 0 if n.is_leaf else 1 + max(d(n.passed), d(n.failed))

        return d(self.root)

    @property
    def go_path(self) -> list[str]:
        """Tests on the path where every test passes (the leftmost branch, leading to "system OK"
        when the no-fault state is modelled); these tests together detect every fault that the
        tree can tell from the pass-all leaf (luo-et-al, Section VII)."""
        out, n = [], self.root
        while not n.is_leaf:
            out.append(n.test)
            n = n.passed
        return out

    @property
    def tests_used(self) -> list[str]:
        """Tests appearing anywhere in the tree, in D-matrix column order."""
        used = set()

        def walk(n):
            if not n.is_leaf:
                used.add(n.test)
                walk(n.passed)
                walk(n.failed)

        walk(self.root)
        return [t for t in self.dmatrix.tests if t in used]

    @property
    def redundant_tests(self) -> list[str]:
        """Tests the optimal tree never requests."""
        used = set(self.tests_used)
        return [t for t in self.dmatrix.tests if t not in used]

    @property
    def ambiguity_groups(self) -> list[tuple[str, ...]]:
        """Leaf groups with more than one fault."""
        return [leaf.group for leaf in self.leaves() if len(leaf.group) > 1]

    # ------------------------------------------------------------------ use
    def _getter(self, outcomes) -> Callable[[str], bool]:
        tests = self.dmatrix.tests
        if callable(outcomes):
            return lambda t: bool(outcomes(t))
        if isinstance(outcomes, Mapping):
            def get(t):
                if t not in outcomes:
                    raise DataError(f"the tree requests test {t!r}, which is not in the outcomes "
                                    f"{sorted(outcomes)}")
                return bool(outcomes[t])
            return get
        arr = np.asarray(outcomes).ravel()
        if arr.size != len(tests):
            raise DataError(f"got {arr.size} outcomes for {len(tests)} tests {tests}")
        return lambda t: bool(arr[tests.index(t)])

    def leaf_for(self, outcomes) -> TreeNode:
        """The leaf reached with the given outcomes (mapping test -> bool, callable, or sequence in
        D-matrix column order; True = the test fails)."""
        get = self._getter(outcomes)
        n = self.root
        while not n.is_leaf:
            n = n.failed if get(n.test) else n.passed
        return n

    def diagnose(self, outcomes) -> tuple[str, ...]:
        """Diagnosis (leaf group) for the given test outcomes; only the tests on the path are read.

        Examples
        --------
        >>> dm = DMatrix(["F0", "F1", "F2"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1]])
        >>> ao_star(dm).diagnose({"t1": True, "t2": False})
        ('F1',)
        """
        return self.leaf_for(outcomes).group

    def evaluate(self) -> dict:
        """Recompute the tree's expected cost from the tree alone (independent of the search).

        Propagates, for every fault state, the probability of reaching each node (perfect tests:
        follows the fault's D-matrix row; unreliable: multiplies by ``q`` or ``1 - q``).

        Returns
        -------
        dict
            ``expected_test_cost``, ``misdiagnosis_probability``, ``objective`` (test cost plus
            ``M`` x misdiagnosis probability, or the test cost for perfect tests).
        """
        dm = self.dmatrix
        q = dm.d.astype(float) if self.tests_model == "perfect" else dm.fail_probability()
        col = {t: j for j, t in enumerate(dm.tests)}
        fidx = {f: i for i, f in enumerate(dm.faults)}
        test_cost = 0.0
        miss = 0.0

        def walk(n, r):
            nonlocal test_cost, miss
            if n.is_leaf:
                hit = sum(r[fidx[f]] for f in n.group)
                miss += float(r.sum() - hit)
                return
            j = col[n.test]
            test_cost += self.cost[j] * float(r.sum())
            walk(n.failed, r * q[:, j])
            walk(n.passed, r * (1.0 - q[:, j]))

        walk(self.root, self.prior.astype(float))
        M = self.misdiagnosis_cost or 0.0
        return {"expected_test_cost": test_cost, "misdiagnosis_probability": miss,
                "objective": test_cost + M * miss}

    # ------------------------------------------------------------------ display
    def to_text(self) -> str:
        """Indented text tree; G = pass branch, NG = fail branch.

        Examples
        --------
        >>> dm = DMatrix(["F0", "F1", "F2"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1]])
        >>> print(ao_star(dm, prior=[0.5, 0.25, 0.25]).to_text())
        Diagnostic tree: expected cost 1.5, depth 2, 3 leaves, go-path [t1] (perfect tests, ao*)
        t1  (P=1)
          G  -> F0  (P=0.5)
          NG -> t2  (P=0.5)
            G  -> F1  (P=0.25)
            NG -> F2  (P=0.25)
        """
        lines = [f"Diagnostic tree: expected cost {self.expected_cost:.6g}, depth {self.depth}, "
                 f"{len(self.leaves())} leaves, go-path [{', '.join(self.go_path)}] "
                 f"({self.tests_model} tests, {self.stats.get('method', '?')})"]

        def label(n):
            if n.is_leaf:
                s = " | ".join(n.group) if n.group else "(unreachable)"
                if self.tests_model == "unreliable":
                    s += f"  [posterior {sum(n.posterior.get(f, 0.0) for f in n.group):.4g}]"
                return f"{s}  (P={n.probability:.4g})"
            return f"{n.test}  (P={n.probability:.4g})"

        def walk(n, indent):
            for tag, child in (("G ", n.passed), ("NG", n.failed)):
                lines.append(f"{indent}{tag} -> {label(child)}")
                if not child.is_leaf:
                    walk(child, indent + "  ")

        lines.append(label(self.root))
        if not self.root.is_leaf:
            walk(self.root, "  ")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.to_text()

    def to_dict(self) -> dict:
        """JSON-ready nested dictionary: the tree, its summary, and everything :meth:`from_dict`
        needs to rebuild it (D-matrix, prior, costs, tests model, misdiagnosis cost).

        Examples
        --------
        >>> import json
        >>> dm = DMatrix(["F0", "F1", "F2"], ["t1", "t2"], [[0, 0], [1, 0], [1, 1]])
        >>> tree = ao_star(dm, prior=[0.5, 0.25, 0.25])
        >>> again = DiagnosticTree.from_dict(json.loads(json.dumps(tree.to_dict())))
        >>> again.to_text() == tree.to_text()
        True
        """
        def node(n):
            if n.is_leaf:
                return {"leaf": list(n.group), "probability": n.probability}
            return {"test": n.test, "probability": n.probability,
                    "pass": node(n.passed), "fail": node(n.failed)}

        return {"expected_cost": self.expected_cost, "depth": self.depth, "go_path": self.go_path,
                "tests_used": self.tests_used, "redundant_tests": self.redundant_tests,
                "tests_model": self.tests_model, "misdiagnosis_cost": self.misdiagnosis_cost,
                "prior": self.prior.tolist(), "cost": self.cost.tolist(),
                "dmatrix": self.dmatrix.to_dict(), "stats": dict(self.stats), "tree": node(self.root)}

    @classmethod
    def from_dict(cls, data: Mapping) -> DiagnosticTree:
        """Rebuild a tree saved with :meth:`to_dict` (e.g. as JSON): node probabilities and
        posteriors are recomputed from the D-matrix and the prior, so a hand-edited or foreign tree
        (such as the paper's Fig. 14) can be loaded and evaluated too.

        Raises
        ------
        DataError
            On an unknown test or fault name, or a test repeated on a path.
        """
        dm = DMatrix.from_dict(data["dmatrix"])
        p, c = _check_prior(dm, data["prior"]), _check_cost(dm, data["cost"])
        mode, M = _mode(dm, data.get("tests_model", "auto"), data.get("misdiagnosis_cost"))
        q = dm.d.astype(float) if mode == "perfect" else dm.fail_probability()

        def build(d, r, alive, used):
            pr = float(r.sum())
            names = tuple(f for f, keep in zip(dm.faults, alive) if keep)
            if pr > 0:
                post = {f: float(r[i] / pr) for i, f in enumerate(dm.faults) if alive[i]}
            else:
                post = {f: 1.0 / len(names) for f in names} if names else {}
            if "leaf" in d:
                group = tuple(str(f) for f in d["leaf"])
                for f in group:
                    dm.index(f)           # clear error on an unknown fault name
                return TreeNode(None, names, pr, post, group=group)
            t = str(d["test"])
            if t not in dm.tests:
                raise DataError(f"the tree applies test {t!r}, which is not in the D-matrix {dm.tests}")
            if t in used:
                raise DataError(f"test {t!r} is applied twice on one path")
            j = dm.tests.index(t)
            n = TreeNode(t, names, pr, post)
            rp, rf = r * (1.0 - q[:, j]), r * q[:, j]     # Bayes: joint probabilities after the outcome
            if mode == "perfect":     # the faults consistent with the outcome
                ap, af = alive & ~dm.d[:, j], alive & dm.d[:, j]
            else:
                ap, af = rp > 0, rf > 0
            n.passed = build(d["pass"], rp, ap, used | {t})
            n.failed = build(d["fail"], rf, af, used | {t})
            return n

        p0 = p.astype(float)
        root = build(data["tree"], p0, np.ones(len(p0), bool) if mode == "perfect" else p0 > 0, frozenset())
        stats = dict(data.get("stats", {}))
        stats.setdefault("method", "loaded")
        tree = cls(root, dm, p, c, mode, M, float("nan"), stats)
        tree.expected_cost = tree.evaluate()["objective"]     # recomputed, never trusted from the file
        return tree


# ---------------------------------------------------------------------------------------------- perfect
class _Perfect:
    """Bitmask machinery shared by AO* and the exhaustive DP for perfect (binary) tests."""

    def __init__(self, dm: DMatrix, prior: np.ndarray, cost: np.ndarray):
        self.dm, self.p, self.c = dm, prior, cost
        nf, nt = dm.shape
        self.nf, self.nt = nf, nt
        self.fail = [sum(1 << i for i in range(nf) if dm.d[i, j]) for j in range(nt)]
        # class (identical rows) of every fault as a bitmask
        cls = {}
        for i in range(nf):
            cls.setdefault(dm.d[i].tobytes(), []).append(i)
        self.class_mask = [0] * nf
        for members in cls.values():
            m = sum(1 << i for i in members)
            for i in members:
                self.class_mask[i] = m

    def bits(self, x: int) -> list[int]:
        return [i for i in range(self.nf) if x >> i & 1]

    def prob(self, x: int) -> float:
        return float(sum(self.p[i] for i in self.bits(x)))

    def splitting(self, x: int) -> list[int]:
        return [j for j in range(self.nt) if 0 != (x & self.fail[j]) != x]

    def class_masses(self, x: int) -> list[float]:
        seen, out = 0, []
        for i in self.bits(x):
            if not seen >> i & 1:
                m = self.class_mask[i] & x
                seen |= m
                out.append(self.prob(m))
        return out

    def node(self, x: int, best: Callable[[int], int | None]) -> TreeNode:
        """Build the tree below ``x`` following ``best(x)`` (test index or None at a leaf)."""
        names = [self.dm.faults[i] for i in self.bits(x)]
        px = self.prob(x)
        post = {f: (float(self.p[self.dm.faults.index(f)]) / px if px > 0 else 1.0 / len(names))
                for f in names}
        j = best(x)
        if j is None:
            return TreeNode(None, tuple(names), px, post, group=tuple(names))
        n = TreeNode(self.dm.tests[j], tuple(names), px, post)
        n.passed = self.node(x & ~self.fail[j], best)
        n.failed = self.node(x & self.fail[j], best)
        return n


class _OrNode:
    __slots__ = ("best", "children", "expanded", "f", "h", "key", "level", "parents", "prob", "solved",
                 "stop")

    def __init__(self, key, prob, h, level):
        self.key, self.prob, self.h, self.f, self.level = key, prob, h, h, level
        self.solved = False
        self.expanded = False
        self.best = None          # test index of the marked connector (None = stop / leaf)
        self.children = {}        # test index -> (pass node, fail node)
        self.parents = []
        self.stop = None


class _OutOfBudget(Exception):
    """Raised inside the search when the node or time budget is spent."""


class _Budget:
    """Node and wall-time budget of one search, with a progress callback."""

    def __init__(self, max_nodes: int | None, time_limit: float | None, progress: Callable | None):
        self.max_nodes, self.time_limit, self.progress = max_nodes, time_limit, progress
        self.t0 = time.perf_counter()
        self.nodes = 0
        self.expansions = 0
        self.exceeded: str | None = None

    def node(self) -> None:
        self.nodes += 1
        if self.max_nodes is not None and self.nodes > self.max_nodes:
            self.exceeded = f"node budget {self.max_nodes}"
            raise _OutOfBudget
        if self.time_limit is not None and self.nodes % 64 == 0 and self.elapsed() > self.time_limit:
            self.exceeded = f"time budget {self.time_limit:g} s"
            raise _OutOfBudget

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def report(self, root: _OrNode, done: bool = False) -> None:
        if self.progress is not None:
            self.progress({"nodes": self.nodes, "expanded": self.expansions, "seconds": self.elapsed(),
                           "lower_bound": float(root.f), "done": done})


def _aostar_loop(root: _OrNode, expand: Callable[[_OrNode], None], revise: Callable[[_OrNode], bool],
                 budget: _Budget | None = None) -> int:
    """Generic AO*: repeatedly expand the unexpanded tips of the marked partial solution graph and
    revise costs bottom-up (children before parents) until the root is solved. Returns expansions.

    With a ``budget`` the search stops when it is spent (:class:`_OutOfBudget` propagates after the
    costs of the expanded tips have been revised, so every ``f`` stays a lower bound)."""
    expansions = 0
    while not root.solved:
        tips, stack, seen = [], [root], set()
        while stack:
            n = stack.pop()
            if n.solved or id(n) in seen:
                continue
            seen.add(id(n))
            if not n.expanded:
                tips.append(n)
            elif n.best is not None:
                stack.extend(n.children[n.best])
        if not tips:   # cannot happen with a consistent graph; guard against an infinite loop
            raise RuntimeError("AO*: the marked solution graph has no tip but the root is unsolved")
        heap, queued = [], set()
        stop = False
        for n in tips:
            try:
                expand(n)
            except _OutOfBudget:
                stop = True
                break
            expansions += 1
            if budget is not None:
                budget.expansions = expansions
            heapq.heappush(heap, (n.level, id(n), n))
            queued.add(id(n))
        while heap:
            _, _, n = heapq.heappop(heap)
            queued.discard(id(n))
            if revise(n):
                for par in n.parents:
                    if id(par) not in queued:
                        heapq.heappush(heap, (par.level, id(par), par))
                        queued.add(id(par))
        if budget is not None and budget.progress is not None and expansions % 256 < len(tips):
            budget.report(root)
        if stop:
            raise _OutOfBudget
    return expansions


def _split_score(pf: float, pp: float, cost: float) -> float:
    """Information (bits) of a binary split per unit cost (the greedy rule)."""
    tot = pf + pp
    if tot <= 0 or pf <= 0 or pp <= 0:
        return 0.0
    a, b = pf / tot, pp / tot
    return -(a * np.log2(a) + b * np.log2(b)) / max(cost, 1e-12)


def _ao_perfect(dm, p, c, heuristic, budget=None):
    P = _Perfect(dm, p, c)
    nodes: dict[int, _OrNode] = {}

    def h_of(x, px):
        split = P.splitting(x)
        if not split:
            return 0.0, True
        cmin = min(c[j] for j in split)
        if heuristic == "huffman":
            return cmin * huffman_cost(P.class_masses(x)), False
        if heuristic == "entropy":
            m = np.array([v for v in P.class_masses(x) if v > 0])
            return (cmin * float(np.sum(m * np.log2(px / m))) if px > 0 else 0.0), False
        if heuristic == "mincost":
            return cmin * px, False
        return 0.0, False

    def get(x):
        n = nodes.get(x)
        if n is None:
            if budget is not None:
                budget.node()
            px = P.prob(x)
            h, terminal = h_of(x, px)
            n = _OrNode(x, px, h, bin(x).count("1"))
            if terminal:
                n.solved, n.expanded, n.f = True, True, 0.0
            nodes[x] = n
        return n

    def expand(n):
        x = n.key
        for j in P.splitting(x):
            a, b = get(x & ~P.fail[j]), get(x & P.fail[j])
            a.parents.append(n)
            b.parents.append(n)
            n.children[j] = (a, b)
        n.expanded = True

    def revise(n):
        best, val = None, np.inf
        for j, (a, b) in n.children.items():
            v = c[j] * n.prob + a.f + b.f      # cost of the AND node (connector) for test j
            if best is None or v < val - 1e-12 * max(1.0, abs(val)):
                best, val = j, v
        a, b = n.children[best]
        solved = a.solved and b.solved
        f = val if solved else max(n.h, val)
        changed = (f != n.f) or (solved != n.solved) or (best != n.best)
        n.best, n.f, n.solved = best, f, solved
        return changed

    def greedy(x):
        split = P.splitting(x)
        if not split:
            return None
        px = P.prob(x)
        scores = [_split_score(P.prob(x & P.fail[j]), px - P.prob(x & P.fail[j]), c[j]) for j in split]
        return split[int(np.argmax(scores))]

    t0 = time.perf_counter()
    full = (1 << P.nf) - 1
    root = get(full)
    try:
        expansions = _aostar_loop(root, expand, revise, budget)
        tree_root = P.node(full, lambda x: nodes[x].best)
        return root.f, tree_root, {"nodes": len(nodes), "expanded": expansions,
                                   "wall_seconds": time.perf_counter() - t0}
    except _OutOfBudget:
        pass
    # budget spent: the marked choices where a node is solved, the greedy rule elsewhere
    def policy(x):
        n = nodes.get(x)
        if n is not None and n.solved:
            return n.best
        if n is not None and n.expanded and n.best is not None:
            return n.best
        return greedy(x)

    return _budget_result(dm, p, c, "perfect", None, root, nodes, budget, t0,
                          [P.node(full, policy), P.node(full, greedy)])


def _budget_result(dm, p, c, mode, M, root, nodes, budget, t0, candidates):
    """Best complete tree among the candidates once the budget is spent, with the optimality gap:
    the search's root value is a lower bound of the optimum (admissible heuristics), the tree's own
    evaluated cost an upper bound."""
    best_J, best_root = np.inf, None
    for cand in candidates:
        J = DiagnosticTree(cand, dm, p, c, mode, M, float("nan")).evaluate()["objective"]
        if J < best_J - 1e-12 * max(1.0, abs(best_J) if np.isfinite(best_J) else 1.0):
            best_J, best_root = J, cand
    lower = min(float(root.f), best_J)
    gap = best_J - lower
    stats = {"nodes": len(nodes), "expanded": budget.expansions, "wall_seconds": time.perf_counter() - t0,
             "budget_exceeded": budget.exceeded, "fallback": "greedy", "lower_bound": lower,
             "gap": gap, "relative_gap": gap / best_J if best_J > 0 else 0.0, "optimal": gap <= 1e-12}
    return best_J, best_root, stats


def _exhaustive_perfect(dm, p, c):
    P = _Perfect(dm, p, c)
    t0 = time.perf_counter()
    nf = P.nf
    size = 1 << nf
    # p(x) for every subset by the lowest-bit recursion
    prob = np.zeros(size)
    for x in range(1, size):
        low = x & -x
        prob[x] = prob[x ^ low] + p[low.bit_length() - 1]
    J = np.zeros(size)
    best = np.full(size, -1, int)
    for x in sorted(range(1, size), key=lambda v: bin(v).count("1")):
        val, arg = np.inf, -1
        for j in range(P.nt):
            f = x & P.fail[j]
            if f == 0 or f == x:
                continue
            v = c[j] * prob[x] + J[x ^ f] + J[f]
            if arg < 0 or v < val - 1e-12 * max(1.0, abs(val)):
                val, arg = v, j
        if arg >= 0:
            J[x], best[x] = val, arg
    full = size - 1
    root = P.node(full, lambda x: None if best[x] < 0 else int(best[x]))
    return float(J[full]), root, {"nodes": size - 1, "expanded": size - 1,
                                  "wall_seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------------------- unreliable
class _Unreliable:
    def __init__(self, dm: DMatrix, p, c, M):
        self.dm, self.p, self.c, self.M = dm, p, c, M
        self.q = dm.fail_probability()
        nf, nt = dm.shape
        self.nf, self.nt = nf, nt
        groups: dict[bytes, list[int]] = {}
        for i in range(nf):
            groups.setdefault(self.q[i].tobytes(), []).append(i)
        self.groups = list(groups.values())
        self.G = np.zeros((nf, len(self.groups)))
        for k, g in enumerate(self.groups):
            self.G[g, k] = 1.0

    def bayes_error_all(self, b: np.ndarray, tests: list[int]) -> float:
        """Probability of misdiagnosis (joint, not normalised) if all ``tests`` were applied to ``b``:
        sum over the 2^r outcome vectors of (mass - largest class mass)."""
        L = b[None, :]
        for j in tests:
            L = np.concatenate([L * (1.0 - self.q[:, j]), L * self.q[:, j]])
        return max(0.0, float(L.sum() - (L @ self.G).max(axis=1).sum()))

    def stop(self, b: np.ndarray) -> tuple[float, list[int]]:
        """Misdiagnosis cost of stopping with joint belief ``b`` and the declared (MAP) class."""
        masses = b @ self.G
        k = int(np.argmax(masses))
        return self.M * max(0.0, float(b.sum()) - float(masses[k])), self.groups[k]

    def children(self, key, b, j):
        used, fail = key
        bit = 1 << j
        return ((used | bit, fail), b * (1.0 - self.q[:, j])), ((used | bit, fail | bit), b * self.q[:, j])

    def build(self, key, b, choice: Callable) -> TreeNode:
        dm = self.dm
        pb = float(b.sum())
        names = tuple(dm.faults[i] for i in range(self.nf) if b[i] > 0)
        post = {dm.faults[i]: float(b[i] / pb) for i in range(self.nf) if b[i] > 0} if pb > 0 else {}
        j = choice(key)
        if j is None:
            _, g = self.stop(b)
            group = tuple(dm.faults[i] for i in g) if pb > 0 else ()
            return TreeNode(None, names, pb, post, group=group)
        n = TreeNode(dm.tests[j], names, pb, post)
        (kp, bp), (kf, bf) = self.children(key, b, j)
        n.passed = self.build(kp, bp, choice)
        n.failed = self.build(kf, bf, choice)
        return n


def _ao_unreliable(dm, p, c, M, heuristic, budget=None, bayes_max_tests=14):
    U = _Unreliable(dm, p, c, M)
    nodes: dict[tuple[int, int], _OrNode] = {}
    beliefs: dict[tuple[int, int], np.ndarray] = {}

    def informative(key, b):
        used = key[0]
        pfail = b @ U.q                      # probability of a fail outcome of each test
        ppass = b @ (1.0 - U.q)
        return [j for j in range(U.nt) if not used >> j & 1 and pfail[j] > 0.0 and ppass[j] > 0.0]

    def get(key, b):
        n = nodes.get(key)
        if n is None:
            if budget is not None:
                budget.node()
            pb = float(b.sum())
            stop, _ = U.stop(b)
            tests = informative(key, b)
            if not tests or stop == 0.0:
                h = stop
            elif heuristic == "zero":
                h = 0.0
            else:   # stop now, or pay at least the cheapest remaining informative test (+ Bayes error)
                h = min(c[j] for j in tests) * pb
                unused = [j for j in range(U.nt) if not key[0] >> j & 1]
                if heuristic == "bayes" and len(unused) <= bayes_max_tests:
                    h += M * U.bayes_error_all(b, unused)
                h = min(stop, h)
            n = _OrNode(key, pb, h, -bin(key[0]).count("1"))   # more tests applied = deeper = first
            n.stop = stop
            if not tests or stop == 0.0:
                n.solved, n.expanded, n.f = True, True, stop
            nodes[key] = n
            beliefs[key] = b
        return n

    def expand(n):
        b = beliefs[n.key]
        for j in informative(n.key, b):
            (kp, bp), (kf, bf) = U.children(n.key, b, j)
            a, f = get(kp, bp), get(kf, bf)
            a.parents.append(n)
            f.parents.append(n)
            n.children[j] = (a, f)
        n.expanded = True

    def revise(n):
        best, val = None, n.stop
        for j, (a, b) in n.children.items():
            v = c[j] * n.prob + a.f + b.f
            if v < val - 1e-12 * max(1.0, abs(val)):
                best, val = j, v
        if best is None:
            solved = True
        else:
            a, b = n.children[best]
            solved = a.solved and b.solved
        f = val if solved else max(n.h, val)
        changed = (f != n.f) or (solved != n.solved) or (best != n.best)
        n.best, n.f, n.solved = best, f, solved
        return changed

    greedy_memo: dict[tuple[int, int], int | None] = {}

    def greedy_from(key, b):
        """One-step look-ahead: the test whose outcome lowers (test cost + stop cost) most, or stop."""
        if key in greedy_memo:
            return greedy_memo[key]
        stop, _ = U.stop(b)
        best, val = None, stop
        if stop > 0.0:
            for j in informative(key, b):
                (_, bp), (_, bf) = U.children(key, b, j)
                v = c[j] * float(b.sum()) + U.stop(bp)[0] + U.stop(bf)[0]
                if v < val - 1e-12 * max(1.0, abs(val)):
                    best, val = j, v
        greedy_memo[key] = best
        return best

    t0 = time.perf_counter()
    b0 = p.astype(float)
    root = get((0, 0), b0)
    try:
        expansions = _aostar_loop(root, expand, revise, budget)
        tree_root = U.build((0, 0), b0, lambda k: nodes[k].best)
        return root.f, tree_root, {"nodes": len(nodes), "expanded": expansions,
                                   "wall_seconds": time.perf_counter() - t0}
    except _OutOfBudget:
        pass

    def build_with(choice):
        def walk(key, b):
            j = choice(key, b)
            if j is None:
                _, g = U.stop(b)
                pb = float(b.sum())
                names = tuple(dm.faults[i] for i in range(U.nf) if b[i] > 0)
                post = {dm.faults[i]: float(b[i] / pb) for i in range(U.nf) if b[i] > 0} if pb > 0 else {}
                return TreeNode(None, names, pb, post, group=tuple(dm.faults[i] for i in g) if pb > 0 else ())
            pb = float(b.sum())
            names = tuple(dm.faults[i] for i in range(U.nf) if b[i] > 0)
            post = {dm.faults[i]: float(b[i] / pb) for i in range(U.nf) if b[i] > 0} if pb > 0 else {}
            n = TreeNode(dm.tests[j], names, pb, post)
            (kp, bp), (kf, bf) = U.children(key, b, j)
            n.passed, n.failed = walk(kp, bp), walk(kf, bf)
            return n
        return walk((0, 0), b0)

    def policy(key, b):
        n = nodes.get(key)
        if n is not None and n.expanded and (n.solved or n.best is not None):
            return n.best
        return greedy_from(key, b)

    return _budget_result(dm, p, c, "unreliable", M, root, nodes, budget, t0,
                          [build_with(policy), build_with(greedy_from)])


def _exhaustive_unreliable(dm, p, c, M):
    U = _Unreliable(dm, p, c, M)
    memo: dict[tuple[int, int], tuple[float, int | None]] = {}

    def V(key, b):
        if key in memo:
            return memo[key][0]
        stop, _ = U.stop(b)
        val, arg = stop, None
        if float(b.sum()) > 0.0:
            for j in range(U.nt):
                if key[0] >> j & 1:
                    continue
                (kp, bp), (kf, bf) = U.children(key, b, j)
                v = c[j] * float(b.sum()) + V(kp, bp) + V(kf, bf)
                if v < val - 1e-12 * max(1.0, abs(val)):
                    val, arg = v, j
        memo[key] = (val, arg)
        return val

    t0 = time.perf_counter()
    J = V((0, 0), p.astype(float))
    root = U.build((0, 0), p.astype(float), lambda k: memo[k][1])
    return J, root, {"nodes": len(memo), "expanded": len(memo), "wall_seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------------------------- public
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

