"""The generic AO* search on an AND/OR graph: OR nodes, the node and time budget, the best-first
expand-and-revise loop, and the best complete tree once the budget is spent."""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable

import numpy as np

from .tree import DiagnosticTree


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
