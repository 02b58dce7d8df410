"""Fault isolation: D-matrices, optimal test sequencing (AO*), diagnostic trees and their code
generation, and data-driven classifiers.

Generic machinery for any test design: build or learn a :class:`DMatrix`, find the minimum expected
cost :class:`DiagnosticTree` with :func:`ao_star` (checked against :func:`exhaustive`), and emit the
tree as IF-THEN-ELSE logic in Python or C (:func:`to_python`, :func:`to_c`, :func:`to_listing`),
as in luo-et-al, Section VII; decide from binary outcomes by maximum likelihood
(:func:`diagnose_ml`) or down a tree (:func:`diagnose_tree`). :class:`SVMIsolator` (scikit-learn)
separates faults that the residual tests cannot (luo-et-al, Section VI).
"""

from .codegen import compile_python, to_c, to_listing, to_python
from .decide import diagnose_ml, diagnose_tree
from .dmatrix import DMatrix, wilson_interval
from .sequencing import DiagnosticTree, TreeNode, ao_star, exhaustive, huffman_cost

_SVM_NAMES = ("SVMDecision", "SVMIsolator", "WindowFeatures", "concat_measurements", "cv_pipeline",
              "rbf_gamma")


def __getattr__(name: str):
    # the SVM part imports scikit-learn (about 1 s): load it only when it is used
    if name in _SVM_NAMES:
        from . import svm

        return getattr(svm, name)
    raise AttributeError(f"module 'fdikit.isolate' has no attribute {name!r}")

__all__ = ["DMatrix", "DiagnosticTree", "SVMDecision", "SVMIsolator", "TreeNode", "WindowFeatures",
           "ao_star", "compile_python", "concat_measurements", "cv_pipeline", "diagnose_ml", "diagnose_tree",
           "exhaustive", "huffman_cost", "rbf_gamma", "to_c", "to_listing", "to_python", "wilson_interval"]
