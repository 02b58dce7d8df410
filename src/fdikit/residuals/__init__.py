"""Residual generators: observers, parity equations, fault detection filters, sliding mode observers.

Every linear design returns plain matrices (its implementation form), an info record, and can be
checked exactly: :func:`internal_form` composes any design with a model and returns the transfer
from every input group (controls, disturbances, faults, noise) to the residual.
"""

from .fdf import (
    FaultDetectionFilter,
    FilterDesign,
    design_filter_set,
    design_optimal_fdf,
    design_uio,
    fault_detection_filter,
    fault_direction_split,
    fault_directions,
    internal_form,
    reduce_filter,
    residual_covariance,
    stack_designs,
)
from .observer import ObserverDesign, ObserverResidual, design_observer_residual
from .sensitivity import ParameterSensitivity

__all__ = [
    "FaultDetectionFilter",
    "FilterDesign",
    "ObserverDesign",
    "ObserverResidual",
    "ParameterSensitivity",
    "design_filter_set",
    "design_observer_residual",
    "design_optimal_fdf",
    "design_uio",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "internal_form",
    "reduce_filter",
    "residual_covariance",
    "stack_designs",
]
