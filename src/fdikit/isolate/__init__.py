"""Fault isolation: D-matrices, optimal test sequencing (AO*), diagnostic trees and their code
generation, and data-driven classifiers.

Generic machinery for any test design: build or learn a :class:`DMatrix`, find the minimum expected
cost :class:`DiagnosticTree` with :func:`ao_star` (checked against :func:`exhaustive`), and emit the
tree as IF-THEN-ELSE logic in Python or C (:func:`to_python`, :func:`to_c`, :func:`to_listing`),
as in luo-et-al, Section VII; decide from binary outcomes by maximum likelihood
(:func:`diagnose_ml`, :meth:`DMatrix.diagnose` with ambiguity sets) or down a tree
(:func:`diagnose_tree`); isolate by a fault signature matrix of structured residuals
(:class:`SignatureIsolator`); announce one diagnosis per fault episode from streaming test alarms
(:class:`DMatrixDecision`). AO* takes a node and time budget and then falls back to a greedy
completion with its optimality gap reported. :class:`SVMIsolator` (scikit-learn)
separates faults that the residual tests cannot (luo-et-al, Section VI); :class:`ForestIsolator`
wraps a scikit-learn ensemble over window features with a rejection calibrated at a false-alarm
target on held-out nominal windows.
"""

from .classify import WindowedIsolator, moving_average
from .codegen import compile_python, to_c, to_listing, to_python
from .decide import Diagnosis, diagnose_likelihood, diagnose_ml, diagnose_tree
from .dmatrix import DMatrix, wilson_interval
from .fault_type import FAULT_TYPES, FaultTypeClassifier
from .forest import ForestIsolator, window_features
from .online import DMatrixDecision
from .sequencing import DiagnosticTree, TreeNode, ao_star, exhaustive, huffman_cost
from .signature import SignatureDecision, SignatureIsolator

_SVM_NAMES = ("BlockedStratifiedKFold", "SVMDecision", "SVMIsolator", "WindowFeatures", "concat_measurements",
              "cv_pipeline", "rbf_gamma")


def __getattr__(name: str):
    # the SVM part imports scikit-learn (about 1 s): load it only when it is used
    if name in _SVM_NAMES:
        from . import svm

        return getattr(svm, name)
    raise AttributeError(f"module 'fdikit.isolate' has no attribute {name!r}")

__all__ = [
    "FAULT_TYPES",
    "BlockedStratifiedKFold",
    "DMatrix",
    "DMatrixDecision",
    "Diagnosis",
    "DiagnosticTree",
    "FaultTypeClassifier",
    "ForestIsolator",
    "SVMDecision",
    "SVMIsolator",
    "SignatureDecision",
    "SignatureIsolator",
    "TreeNode",
    "WindowFeatures",
    "WindowedIsolator",
    "ao_star",
    "compile_python",
    "concat_measurements",
    "cv_pipeline",
    "diagnose_likelihood",
    "diagnose_ml",
    "diagnose_tree",
    "exhaustive",
    "huffman_cost",
    "moving_average",
    "rbf_gamma",
    "to_c",
    "to_listing",
    "to_python",
    "wilson_interval",
    "window_features",
]
