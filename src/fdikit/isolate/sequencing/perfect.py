"""Test sequencing with perfect (binary) tests: ambiguity sets as bitmasks, the Huffman-code
heuristic, AO* over them and the exhaustive dynamic programme over all subsets."""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable

import numpy as np

from ..dmatrix import DMatrix
from .search import _aostar_loop, _budget_result, _OrNode, _OutOfBudget
from .tree import TreeNode


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
