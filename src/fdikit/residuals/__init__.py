"""Residual generators: observers, parity equations, fault detection filters, sliding mode observers
(fault reconstruction), parameter-signature generators, and data-driven monitors (PCA, dynamic
PCA, CVA) learnt from nominal data alone.

Every linear design returns plain matrices (its implementation form), an info record, and can be
checked exactly: :func:`internal_form` composes any design with a model and returns the transfer
from every input group (controls, disturbances, faults, noise) to the residual.
"""

from .bank import (
    BankResidual,
    FaultSignature,
    IsolabilityReport,
    ResidualBank,
    SensitivityWarning,
    check_sensitivity,
    design_residual_bank,
)
from .datadriven import CVAResidual, DPCAResidual, PCAResidual, q_limit, select_lags, t2_limit
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
    NOT_SLIDING,
    SATURATED,
    SLIDING,
    SlidingModeReconstructor,
    SMOConditions,
    check_conditions,
    design_reconstructor,
    estimate_noise_std,
    hinf_norm,
    integrate_observers,
    noise_response,
    simulate_plant,
    sliding_episodes,
)
from .transforms import band_limited, delayed_feedthrough, whiten_design

__all__ = [
    "NOT_SLIDING",
    "SATURATED",
    "SLIDING",
    "BankResidual",
    "CVAResidual",
    "CausalDerivative",
    "CausalLowPass",
    "DPCAResidual",
    "FaultDetectionFilter",
    "FaultSignature",
    "FilterDesign",
    "IsolabilityReport",
    "ObserverDesign",
    "ObserverResidual",
    "PCAResidual",
    "ParameterSensitivity",
    "ResidualBank",
    "SMOConditions",
    "ScheduledFilter",
    "SensitivityWarning",
    "SlidingModeReconstructor",
    "band_limited",
    "butter_sos",
    "causal_spline_derivative",
    "check_conditions",
    "check_sensitivity",
    "delayed_feedthrough",
    "design_filter_set",
    "design_observer_residual",
    "design_optimal_fdf",
    "design_reconstructor",
    "design_residual_bank",
    "design_uio",
    "estimate_noise_std",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "hinf_norm",
    "integrate_observers",
    "internal_form",
    "lowpass",
    "noise_response",
    "q_limit",
    "reduce_filter",
    "residual_covariance",
    "select_lags",
    "simulate_plant",
    "sliding_episodes",
    "spline_derivative",
    "spline_derivative_weights",
    "spline_lam",
    "stack_designs",
    "t2_limit",
    "whiten_design",
]
