"""Passenger car (paper 1, Ng, Chen & Speyer): nonlinear mid-size sedan, its linear and reduced
models, and the lateral model fitted to a real Toyota RAV4 minute.

* :class:`PassengerCar` — the nonlinear model (:mod:`.model`, every parameter documented);
* :func:`linearize_car` — linearisation at straight driving, decoupling, reduction (:mod:`.linear`);
* :func:`fit_rav4` — the lateral model fitted to a real CAN log (:mod:`.rav4`).
"""

from .linear import (
    ACTUATOR_FAULTS,
    SENSOR_FAULTS,
    CarLinearization,
    balanced_residualization,
    block,
    channel_response_error,
    decoupling_residue,
    linearize_car,
    reduce_fast_modes_named,
    residualize_states,
)
from .model import (
    DEFAULT_PARAMS,
    INPUTS,
    LATERAL_INPUTS,
    LATERAL_OUTPUTS,
    LATERAL_REDUCED,
    LATERAL_STATES,
    LONGITUDINAL_INPUTS,
    LONGITUDINAL_OUTPUTS,
    LONGITUDINAL_REDUCED,
    LONGITUDINAL_STATES,
    OUTPUTS,
    PARAM_DOC,
    PassengerCar,
)

__all__ = [
    "ACTUATOR_FAULTS",
    "DEFAULT_PARAMS",
    "INPUTS",
    "LATERAL_INPUTS",
    "LATERAL_OUTPUTS",
    "LATERAL_REDUCED",
    "LATERAL_STATES",
    "LONGITUDINAL_INPUTS",
    "LONGITUDINAL_OUTPUTS",
    "LONGITUDINAL_REDUCED",
    "LONGITUDINAL_STATES",
    "OUTPUTS",
    "PARAM_DOC",
    "SENSOR_FAULTS",
    "CarLinearization",
    "PassengerCar",
    "balanced_residualization",
    "block",
    "channel_response_error",
    "decoupling_residue",
    "demo_summary",
    "linearize_car",
    "reduce_fast_modes_named",
    "residualize_states",
]


def demo_summary() -> dict:
    """Short passenger-car summary for ``fdikit demo`` (linearisation at 20 m/s)."""
    lin = linearize_car(20.0)
    s = lin.summary()
    return {
        "speed_m_s": 20.0,
        "throttle_trim_deg": round(s["throttle_trim_deg"], 3),
        "engine_speed_trim_rpm": round(s["engine_speed_trim_rpm"], 1),
        "decoupling_residue": s["decoupling_residue"]["max"],
        "longitudinal_states": f"{lin.longitudinal.n_states} -> {lin.longitudinal_reduced.n_states}",
        "lateral_states": f"{lin.lateral.n_states} -> {lin.lateral_reduced.n_states}",
        "fr_error_below_5Hz": {k: round(v["max"], 4) for k, v in lin.fr_error.items()},
    }
