"""Test sequencing with unreliable tests: Bayes-updated beliefs, stopping with a misdiagnosis
cost, AO* over (applied tests, outcomes) states and the exhaustive recursion over all of them."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..dmatrix import DMatrix
from .search import _aostar_loop, _budget_result, _OrNode, _OutOfBudget
from .tree import TreeNode


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
