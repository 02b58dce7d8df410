"""Robust actuator fault reconstruction with sliding mode observers (ng-tan-edwards-kuang)."""

from .design import (
    DELTA_LADDER,  # noqa: F401 (re-exported)
    NOT_SLIDING,  # noqa: F401 (re-exported)
    RANK_ATOL_SCALE,  # noqa: F401 (re-exported)
    SATURATED,  # noqa: F401 (re-exported)
    SLIDING,  # noqa: F401 (re-exported)
    STATUS_LABELS,  # noqa: F401 (re-exported)
    AugmentedSystem,
    CanonicalForm,
    FictitiousSystem,
    Lemma1Form,
    SlidingModeReconstructor,
    SMOConditions,
    augment,  # noqa: F401 (re-exported)
    check_conditions,
    design_reconstructor,
    fictitious_system,
    hinf_norm,
    injection_peak_gains,
    integrate_observers,
    lemma1_form,
    lemma4_form,
    noise_response,
    peak_gain,
    self_check,
    simulate_plant,
    sliding_episodes,
)

__all__ = [
    "AugmentedSystem",
    "CanonicalForm",
    "FictitiousSystem",
    "Lemma1Form",
    "SMOConditions",
    "SlidingModeReconstructor",
    "check_conditions",
    "design_reconstructor",
    "fictitious_system",
    "hinf_norm",
    "injection_peak_gains",
    "integrate_observers",
    "lemma1_form",
    "lemma4_form",
    "noise_response",
    "peak_gain",
    "self_check",
    "simulate_plant",
    "sliding_episodes",
]
