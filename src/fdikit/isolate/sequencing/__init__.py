"""Optimal test sequencing on a D-matrix: AO* search on the AND/OR graph, and an exhaustive reference.

* :mod:`.solve` -- :func:`ao_star` and :func:`exhaustive`, and the theory (objective, heuristics,
  unreliable tests) in its docstring;
* :mod:`.tree` -- :class:`DiagnosticTree` and :class:`TreeNode`, the result;
* :mod:`.problem` -- priors, costs and the test model checked against the D-matrix;
* :mod:`.search` -- the generic AO* loop and its node / time budget;
* :mod:`.perfect`, :mod:`.unreliable` -- the two test models (AO* and the exhaustive DP of each),
  with :func:`huffman_cost`, the perfect-test heuristic.
"""

from .perfect import huffman_cost
from .solve import ao_star, exhaustive
from .tree import DiagnosticTree, TreeNode

__all__ = ["DiagnosticTree", "TreeNode", "ao_star", "exhaustive", "huffman_cost"]
