"""Passenger car (ng-chen-speyer, Ng, Chen & Speyer): nonlinear mid-size sedan, its linear and reduced
models, and the lateral model fitted to a real Toyota RAV4 minute.

* :class:`PassengerCar` — the nonlinear model (:mod:`.model`, every parameter documented);
* :func:`linearize_car` — linearisation at straight driving, decoupling, reduction (:mod:`.linear`);
* :class:`DrivingCar`, :func:`driving_scenario`, :func:`simulate_drive` — automated driving
  (speed and path controllers), the paper's scenarios and injectable faults (:mod:`.driving`);
* :func:`nonlinearity_directions` — the nonlinearity direction of Section IV-A (:mod:`.nonlinearity`);
* :func:`~fdikit.systems.car.rav4.fit_rav4` — the lateral model fitted to a real CAN log
  (:mod:`.rav4`).
"""

from .driving import (
    DRIVE_OUTPUTS,
    FAULTS,
    DriveController,
    DrivingCar,
    Track,
    driving_scenario,
    simulate_drive,
)
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
from .nonlinearity import NonlinearityDirections, nonlinearity_directions

__all__ = [
    "ACTUATOR_FAULTS",
    "DEFAULT_PARAMS",
    "DRIVE_OUTPUTS",
    "FAULTS",
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
    "DriveController",
    "DrivingCar",
    "NonlinearityDirections",
    "PassengerCar",
    "Track",
    "balanced_residualization",
    "block",
    "channel_response_error",
    "decoupling_residue",
    "demo_summary",
    "driving_scenario",
    "linearize_car",
    "nonlinearity_directions",
    "reduce_fast_modes_named",
    "residualize_states",
    "simulate_drive",
]


def demo_summary(details: dict | None = None) -> dict:
    """Short passenger-car showcase for ``fdikit demo``: the linearisation at 20 m/s, a 2-second
    automated drive at 24 m/s in which a driver steps on the brake (a real brake-actuator fault the
    speed controller fights with the throttle, ng-chen-speyer Fig. 5), and the RAV4 fit if the data are
    there. ``details``, when given, receives ``drive`` (the drive's simulation result) and
    ``fault_onset_s``, for the demo's report."""
    import numpy as np

    from ...faults import Bias

    lin = linearize_car(20.0)
    s = lin.summary()
    res = simulate_drive("straight", 24.0, duration=1.2, dt=2.5e-3,
                         faults=[Bias("actuator:brake", 0.6, start=0.4)])
    if details is not None:
        details.update(drive=res, fault_onset_s=0.4)
    t, thr, v = res.u.t, res.u["throttle"][0], res.x["v_x"][0]
    drive = {"scenario": "straight at 24 m/s, +0.6 MPa brake from 0.4 s (driver's foot)",
             "throttle_before_deg": round(float(thr[t < 0.4].mean()), 2),
             "throttle_end_deg": round(float(thr[-1]), 2),
             "speed_min_m_s": round(float(v.min()), 3)}
    out = {"drive": drive}
    try:
        from .rav4 import default_data_path, fit_rav4

        if (default_data_path() / "drive.blf").exists():
            fit = fit_rav4(holdout=False)
            out["rav4_fit"] = {"yaw_rate_corr": round(fit.yaw_corr, 3),
                               "kinematic_corr": round(fit.kinematic_yaw_corr, 3),
                               "lat_acc_nrmse": round(fit.ay_nrmse, 3),
                               "understeer_deg_per_g": round(fit.understeer_gradient_deg_per_g, 2)}
    except Exception as exc:  # the demo must not fail on the optional real-data part
        out["rav4_fit"] = {"error": str(exc)}
    del np
    return {
        "speed_m_s": 20.0,
        "throttle_trim_deg": round(s["throttle_trim_deg"], 3),
        "engine_speed_trim_rpm": round(s["engine_speed_trim_rpm"], 1),
        "decoupling_residue": s["decoupling_residue"]["max"],
        "longitudinal_states": f"{lin.longitudinal.n_states} -> {lin.longitudinal_reduced.n_states}",
        "lateral_states": f"{lin.lateral.n_states} -> {lin.lateral_reduced.n_states}",
        "fr_error_below_5Hz": {k: round(v["max"], 4) for k, v in lin.fr_error.items()},
        **out,
    }
