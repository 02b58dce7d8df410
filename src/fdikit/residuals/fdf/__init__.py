"""Fault detection filters: exact unknown input observer and optimal stochastic fault detection filter."""

from ...base.stage import ResidualGenerator  # noqa: F401 (old import path: tests subclass fdf.ResidualGenerator)
from .design import (
    CHUNK,  # noqa: F401 (re-exported)
    FaultDetectionFilter,
    FilterDesign,
    _complement_rows,  # noqa: F401 (re-exported)
    _discrete,  # noqa: F401 (re-exported)
    _orth,  # noqa: F401 (re-exported)
    _row_chunks,  # noqa: F401 (re-exported)
    _run_kernel_chunked,  # noqa: F401 (re-exported)
    conditioned_invariant_subspace,
    design_filter_set,
    design_optimal_fdf,
    design_uio,
    fault_detection_filter,
    fault_direction_split,
    fault_directions,
    filter_frequency_response,
    internal_form,
    modal_observability,
    reduce_filter,
    residual_covariance,
    stack_designs,
)

__all__ = [
    "FaultDetectionFilter",
    "FilterDesign",
    "conditioned_invariant_subspace",
    "design_filter_set",
    "design_optimal_fdf",
    "design_uio",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "filter_frequency_response",
    "internal_form",
    "modal_observability",
    "reduce_filter",
    "residual_covariance",
    "stack_designs",
]
