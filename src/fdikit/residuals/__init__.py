"""Residual generators: observers, parity equations, fault detection filters, sliding mode observers
(fault reconstruction), and parameter-signature generators.

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
from .parity import (
    CausalDerivative,
    CausalLowPass,
    butter_sos,
    causal_spline_derivative,
    lowpass,
    spline_derivative,
    spline_derivative_weights,
    spline_lam,
)
from .scheduled import ScheduledFilter
from .sensitivity import ParameterSensitivity
from .smo import (
    SlidingModeReconstructor,
    SMOConditions,
    check_conditions,
    design_reconstructor,
    hinf_norm,
    integrate_observers,
    simulate_plant,
)
from .transforms import band_limited, delayed_feedthrough, whiten_design

__all__ = [
    "CausalDerivative",
    "CausalLowPass",
    "FaultDetectionFilter",
    "FilterDesign",
    "ObserverDesign",
    "ObserverResidual",
    "ParameterSensitivity",
    "SMOConditions",
    "ScheduledFilter",
    "SlidingModeReconstructor",
    "band_limited",
    "butter_sos",
    "causal_spline_derivative",
    "check_conditions",
    "delayed_feedthrough",
    "design_filter_set",
    "design_observer_residual",
    "design_optimal_fdf",
    "design_reconstructor",
    "design_uio",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "hinf_norm",
    "integrate_observers",
    "internal_form",
    "lowpass",
    "reduce_filter",
    "residual_covariance",
    "simulate_plant",
    "spline_derivative",
    "spline_derivative_weights",
    "spline_lam",
    "stack_designs",
    "whiten_design",
]
