"""The diagnostic tree that test sequencing produces: its nodes, its evaluation (expected test
cost, misdiagnosis), diagnosis from test outcomes, text and the artifact form."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ...errors import DataError
from ..dmatrix import DMatrix
from .problem import _check_cost, _check_prior, _mode

__all__ = ["DiagnosticTree", "TreeNode"]


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
        >>> from fdikit.isolate import ao_star
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
        >>> from fdikit.isolate import ao_star
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
        >>> from fdikit.isolate import ao_star
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
