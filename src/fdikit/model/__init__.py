"""Model layer: linear fault models, the nonlinear model protocol, linearisation, reduction and
structural analysis."""

from .linear import GROUPS, InputGroup, LinearFaultModel
from .linearize import linearize, trim
from .nonlinear import NonlinearModel, NonlinearModelProtocol
from .reduction import (
    FrequencyResponseError,
    balanced_truncation,
    dc_gain,
    frequency_response,
    frequency_response_error,
    reduce_fast_modes,
    residualize,
)
from .structure import (
    RankDecision,
    RelativeDegree,
    default_tol,
    invariant_zeros,
    is_detectable,
    is_observable,
    markov_parameters,
    observability_matrix,
    rank,
    rank_decision,
    relative_degree,
    unobservable_modes,
)

__all__ = [
    "GROUPS",
    "FrequencyResponseError",
    "InputGroup",
    "LinearFaultModel",
    "NonlinearModel",
    "NonlinearModelProtocol",
    "RankDecision",
    "RelativeDegree",
    "balanced_truncation",
    "dc_gain",
    "default_tol",
    "frequency_response",
    "frequency_response_error",
    "invariant_zeros",
    "is_detectable",
    "is_observable",
    "linearize",
    "markov_parameters",
    "observability_matrix",
    "rank",
    "rank_decision",
    "reduce_fast_modes",
    "relative_degree",
    "residualize",
    "trim",
    "unobservable_modes",
]
