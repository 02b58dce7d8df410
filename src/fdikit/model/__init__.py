"""Model layer: linear fault models, the nonlinear model protocol, linearisation, reduction and
structural analysis."""

from .linear import GROUPS, InputGroup, LinearFaultModel
from .linearize import linearize, trim
from .nonlinear import NonlinearModel, NonlinearModelProtocol
from .structure import (
    RelativeDegree,
    default_tol,
    invariant_zeros,
    is_detectable,
    is_observable,
    markov_parameters,
    observability_matrix,
    rank,
    relative_degree,
    unobservable_modes,
)

__all__ = [
    "GROUPS",
    "InputGroup",
    "LinearFaultModel",
    "NonlinearModel",
    "NonlinearModelProtocol",
    "RelativeDegree",
    "default_tol",
    "invariant_zeros",
    "is_detectable",
    "is_observable",
    "linearize",
    "markov_parameters",
    "observability_matrix",
    "rank",
    "relative_degree",
    "trim",
    "unobservable_modes",
]
