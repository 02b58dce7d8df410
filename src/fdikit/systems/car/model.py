"""Passenger car: nonlinear longitudinal + lateral model of a mid-size front-wheel-drive sedan.

The plant of the vehicle health monitor of ng-chen-speyer (Ng, Chen & Speyer, Section III). The Buick
LeSabre model used there is not published, so this is a model of a car of that class built
from textbook sub-models, with every parameter and its source documented in
:data:`DEFAULT_PARAMS`:

* **engine**: mean-value engine model (Hendricks & Sorenson 1990, SAE 900616; Guzzella & Onder
  2010, *Introduction to Modeling and Control of IC Engine Systems*, ch. 2): manifold air-mass
  balance with isentropic throttle flow and speed-density port flow, torque proportional to
  the air charge (indicated efficiency), Heywood's friction and the pumping loss;
* **driveline**: torque converter in its coupling region (Kotwicki 1982, SAE 820393, torque
  linear in slip), fixed gear (no shifting), differential, front-wheel drive, per-axle wheel
  spin dynamics;
* **tyres**: Pacejka "magic formula" (Pacejka 2012, *Tire and Vehicle Dynamics*, ch. 4) for
  the longitudinal (slip ratio) and lateral (slip angle) force, peak = mu * F_z, cornering
  and slip stiffness proportional to the normal load, friction-ellipse limit for combined
  slip;
* **chassis**: planar body (longitudinal, lateral, yaw), sprung-mass heave, pitch and roll on
  four suspension corners (spring, damper, anti-roll bars), four unsprung masses on vertical
  tyre springs (Gillespie 1992, *Fundamentals of Vehicle Dynamics*; Rajamani 2012, *Vehicle
  Dynamics and Control*, ch. 2-3 and 9); normal loads from the tyre deflections, so pitch and
  roll dynamics carry the load transfer;
* **brake**: first-order hydraulic actuator lag from commanded to actual brake pressure, brake
  torque proportional to pressure with a fixed front/rear split;
* **road slope** as a disturbance input.

Suspension corners are described by sums and differences of the suspension deflections
(``s_* = l_L + l_R``, ``d_* = l_L - l_R``), as in the paper, which makes the linearisation
about straight driving split exactly into a longitudinal block (sums) and a lateral block
(differences).

Frames and signs (ISO 8855): x forward, y left, z up; yaw rate positive turning left; roll
positive when the left side rises (right side down, the outward roll of a left turn); pitch
positive nose down (braking); steering positive to the left. All units SI except the inputs
throttle (plate angle above closed, deg) and brake (pressure, MPa).

The state vector is ``LONGITUDINAL_STATES + LATERAL_STATES`` (14 + 8). The paper's reduced
models keep 10 longitudinal states (:data:`LONGITUDINAL_REDUCED`) and 6 lateral states
(:data:`LATERAL_REDUCED`); the removed ones are the fast wheel-spin and wheel-hop modes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...errors import ModelError
from ...model.nonlinear import NonlinearModel

__all__ = [
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
    "PassengerCar",
]

G = 9.80665

#: States of the longitudinal model (engine, driveline, wheels), slow ones first.
LONGITUDINAL_STATES = [
    "m_air",       # manifold air mass (kg)
    "w_e",         # engine speed (rad/s)
    "v_x",         # longitudinal velocity, body frame (m/s)
    "z",           # sprung-mass heave, up (m), deviation from static
    "v_z",         # heave velocity (m/s)
    "theta",       # pitch angle, nose down (rad)
    "q",           # pitch rate (rad/s)
    "s_f",         # sum of the front suspension extensions l_FL + l_FR (m)
    "s_r",         # sum of the rear suspension extensions (m)
    "p_b",         # brake pressure, the brake actuator state (MPa)
    "ds_f",        # rate of s_f (m/s)                       - fast (wheel hop)
    "ds_r",        # rate of s_r (m/s)                       - fast (wheel hop)
    "w_f",         # front axle mean wheel speed (rad/s)     - fast (tyre slip)
    "w_r",         # rear axle mean wheel speed (rad/s)      - fast (tyre slip)
]
#: States of the lateral model (yaw, sideslip, suspension), slow ones first.
LATERAL_STATES = [
    "v_y",         # lateral velocity, body frame (m/s)
    "phi",         # roll angle (rad)
    "p",           # roll rate (rad/s)
    "r",           # yaw rate (rad/s)
    "d_f",         # difference of the front suspension extensions l_FL - l_FR (m)
    "d_r",         # difference of the rear suspension extensions (m)
    "dd_f",        # rate of d_f (m/s)                       - fast (wheel hop, antisymmetric)
    "dd_r",        # rate of d_r (m/s)                       - fast
]
#: The slow longitudinal states kept by the reduced (residualised) model.
LONGITUDINAL_REDUCED = LONGITUDINAL_STATES[:10]
#: The slow lateral states kept by the reduced (residualised) model.
LATERAL_REDUCED = LATERAL_STATES[:6]

#: Inputs of the nonlinear car: throttle (deg), brake (MPa), steering (rad), road slope (rad).
INPUTS = ["throttle", "brake", "steer", "slope"]
#: Inputs of the longitudinal linear model.
LONGITUDINAL_INPUTS = ["throttle", "brake"]
#: Inputs of the lateral linear model.
LATERAL_INPUTS = ["steer"]

#: Sensors of the car, in the order of the output vector (units in the comments).
OUTPUTS = [
    "p_man",       # manifold pressure sensor (kPa)
    "w_engine",    # engine speed sensor (rad/s)
    "a_x",         # longitudinal accelerometer, specific force along body x (m/s^2)
    "w_front_sum", # sum of the front wheel speed sensors (rad/s)
    "w_rear_sum",  # sum of the rear wheel speed sensors (rad/s)
    "throttle_meas",  # throttle position sensor (deg)
    "brake_meas",  # brake pressure sensor (MPa)
    "a_y",         # lateral accelerometer, specific force along body y (m/s^2)
    "yaw_rate",    # yaw rate sensor (rad/s)
    "w_front_diff",  # difference FL - FR of the front wheel speed sensors (rad/s): yaw + load transfer
    "w_rear_diff",   # difference RL - RR of the rear wheel speed sensors (rad/s)
]
#: Sensors of the longitudinal linear model.
LONGITUDINAL_OUTPUTS = ["p_man", "w_engine", "a_x", "w_front_sum", "w_rear_sum"]
#: Sensors of the lateral linear model.
LATERAL_OUTPUTS = ["a_y", "yaw_rate", "w_front_diff", "w_rear_diff"]

UNITS = {
    "m_air": "kg", "w_e": "rad/s", "v_x": "m/s", "z": "m", "v_z": "m/s", "theta": "rad", "q": "rad/s",
    "s_f": "m", "s_r": "m", "p_b": "MPa", "ds_f": "m/s", "ds_r": "m/s", "w_f": "rad/s", "w_r": "rad/s",
    "v_y": "m/s", "phi": "rad", "p": "rad/s", "r": "rad/s", "d_f": "m", "d_r": "m", "dd_f": "m/s",
    "dd_r": "m/s", "throttle": "deg", "brake": "MPa", "steer": "rad", "slope": "rad", "p_man": "kPa",
    "w_engine": "rad/s", "a_x": "m/s^2", "w_front_sum": "rad/s", "w_rear_sum": "rad/s",
    "throttle_meas": "deg", "brake_meas": "MPa", "a_y": "m/s^2", "yaw_rate": "rad/s",
    "w_front_diff": "rad/s", "w_rear_diff": "rad/s",
}

#: Parameters: name -> (value, unit, source / reasoning). A Buick LeSabre class car
#: (1997-2005: 3.8 L V6, 4-speed automatic 4T65-E, front-wheel drive).
PARAM_DOC: dict[str, tuple[float, str, str]] = {
    # ---- mass and geometry
    "m": (1650.0, "kg", "total mass: LeSabre curb weight ~1,580 kg + driver and instruments"),
    "a": (1.07, "m", "CG to front axle: 62 % of the weight on the front axle (FWD sedan), a = 0.38 L"),
    "b": (1.744, "m", "CG to rear axle: L = a + b = 2.814 m, the LeSabre wheelbase (110.8 in)"),
    "t_f": (1.59, "m", "front track (LeSabre 62.6 in)"),
    "t_r": (1.57, "m", "rear track (LeSabre 61.8 in)"),
    "h_cg": (0.55, "m", "CG height of a sedan (Gillespie 1992, table of typical values 0.5-0.6 m)"),
    "h_s": (0.45, "m", "sprung-mass CG above the roll/pitch axes (roll centres ~0.1 m high)"),
    "I_z": (2900.0, "kg m^2", "yaw inertia ~ m a b (Rajamani 2012, typical sedan 2,500-3,000)"),
    "I_x": (550.0, "kg m^2", "sprung-mass roll inertia (Gillespie 1992: 400-700 for sedans)"),
    "I_y": (2700.0, "kg m^2", "sprung-mass pitch inertia (~0.95 I_z)"),
    "m_uf": (45.0, "kg", "front unsprung mass per corner (wheel, tyre, brake, knuckle, half shaft)"),
    "m_ur": (38.0, "kg", "rear unsprung mass per corner"),
    # ---- suspension (per corner); ride frequency ~1.2-1.4 Hz (Gillespie 1992 ch. 6)
    "k_sf": (30000.0, "N/m", "front spring rate at the wheel: ride frequency 1.3 Hz"),
    "k_sr": (24000.0, "N/m", "rear spring rate at the wheel: ride frequency 1.4 Hz"),
    "c_sf": (3000.0, "N s/m", "front damper: ~0.3 of critical for the sprung corner"),
    "c_sr": (2500.0, "N s/m", "rear damper: ~0.3 of critical"),
    "k_arbf": (12000.0, "N/m", "front anti-roll bar, as a force per unit left-right deflection difference"),
    "k_arbr": (4000.0, "N/m", "rear anti-roll bar"),
    "k_t": (200000.0, "N/m", "tyre vertical stiffness (P215/70R15: ~200 kN/m, Gillespie 1992)"),
    # ---- tyres (Pacejka 2012 magic formula, per tyre; stiffness per unit load)
    "r_w": (0.33, "m", "rolling radius of a 215/70R15 tyre"),
    "mu": (0.9, "-", "peak road friction, dry asphalt"),
    "C_alpha_f": (55000.0, "N/rad", "front cornering stiffness per tyre at its static load (Rajamani 2012 "
                  "ex.: 40-80 kN/rad); lower per unit load than the rear -> understeer ~2 deg/g"),
    "C_alpha_r": (60000.0, "N/rad", "rear cornering stiffness per tyre at its static load"),
    "C_kappa": (80000.0, "N", "longitudinal slip stiffness per tyre at 4 kN (~20 F_z, Pacejka 2012 ch. 4)"),
    "Cy_shape": (1.3, "-", "magic-formula shape factor, lateral (Pacejka 2012: 1.3)"),
    "Cx_shape": (1.65, "-", "magic-formula shape factor, longitudinal (Pacejka 2012: 1.65)"),
    "v_eps": (1.0, "m/s", "slip regularisation speed: slip = (r w - v)/max(|v|, v_eps)"),
    # ---- resistances
    "rho_air": (1.2, "kg/m^3", "air density"),
    "cd_A": (0.70, "m^2", "drag area C_d A: C_d 0.33 x frontal area 2.1 m^2"),
    "f_roll": (0.012, "-", "rolling-resistance coefficient, radial tyres (Gillespie 1992)"),
    # ---- engine: 3.8 L V6, mean-value model (Guzzella & Onder 2010, ch. 2; Hendricks 1990)
    "V_d": (3.8e-3, "m^3", "displacement (GM 3800 Series II)"),
    "V_m": (4.0e-3, "m^3", "intake manifold + plenum volume (~displacement)"),
    "T_m": (300.0, "K", "manifold air temperature"),
    "p_amb": (101325.0, "Pa", "ambient pressure"),
    "T_amb": (298.0, "K", "ambient temperature"),
    "R_air": (287.0, "J/(kg K)", "gas constant of air"),
    "kappa": (1.4, "-", "ratio of specific heats of air"),
    "D_th": (0.065, "m", "throttle bore (65 mm)"),
    "alpha0_deg": (7.0, "deg", "throttle plate angle when closed"),
    "Cd_th": (0.8, "-", "throttle discharge coefficient (Guzzella & Onder 2010)"),
    "A_leak": (2.0e-5, "m^2", "idle bypass / leakage area (~4 g/s of air at idle)"),
    "eta_vol": (0.85, "-", "volumetric efficiency, speed-density port flow (Hendricks 1990)"),
    "eta_ind": (0.36, "-", "indicated efficiency (Heywood 1988: 0.3-0.4 for SI engines)"),
    "H_l": (43.0e6, "J/kg", "lower heating value of gasoline"),
    "afr": (14.7, "-", "stoichiometric air-fuel ratio"),
    "fmep0": (97.0e3, "Pa", "friction mep at 0 rpm (Heywood 1988 eq. 13.20: 0.97 bar)"),
    "fmep1": (15.0e3, "Pa", "friction mep per 1000 rpm (Heywood 1988: 0.15 bar)"),
    "fmep2": (5.0e3, "Pa", "friction mep per (1000 rpm)^2 (Heywood 1988: 0.05 bar)"),
    "J_e": (0.20, "kg m^2", "engine + torque-converter pump inertia"),
    # ---- driveline: 4T65-E automatic, coupling-region torque converter (Kotwicki 1982)
    "k_tc": (0.09, "N m s^2/rad^2", "converter coupling: T = k_tc w_e (w_e - w_t); ~3 % slip at 20 m/s"),
    "i_gear": (0.70, "-", "gear ratio in use: 4T65-E 4th gear 0.70 (1st 2.92, 2nd 1.57, 3rd 1.00)"),
    "i_final": (2.86, "-", "final drive ratio (LeSabre 4T65-E: 2.86)"),
    "eta_dl": (0.92, "-", "driveline efficiency"),
    "J_wf": (2.4, "kg m^2", "front axle: 2 wheels x 1.1 + turbine and gears reflected (0.05 x (i_g i_fd)^2)"),
    "J_wr": (2.0, "kg m^2", "rear axle: 2 wheels x 1.0"),
    # ---- brakes
    "tau_b": (0.1, "s", "brake actuator lag, command -> pressure (PATH automated Buick: ~0.1 s)"),
    "k_bf": (450.0, "N m/MPa", "front axle brake torque per MPa (two discs)"),
    "k_br": (180.0, "N m/MPa", "rear axle brake torque per MPa (~70/30 split)"),
    "w_b_eps": (1.0, "rad/s", "wheel speed below which brake torque fades to zero (tanh), no stiction"),
}
#: Parameter values by name (the first entries of :data:`PARAM_DOC`).
DEFAULT_PARAMS: dict[str, float] = {k: v[0] for k, v in PARAM_DOC.items()}


def _psi(pr: np.ndarray, kappa: Any) -> np.ndarray:
    """Isentropic throttle flow function (Guzzella & Onder 2010, eq. 2.7), choked below the
    critical pressure ratio, linearised within 1 % of pr = 1 so that its slope stays finite."""
    crit = (2.0 / (kappa + 1.0)) ** (kappa / (kappa - 1.0))

    def sub(x):
        x = np.maximum(x, 1e-9)
        return np.sqrt(2.0 * kappa / (kappa - 1.0) * (x ** (2.0 / kappa) - x ** ((kappa + 1.0) / kappa)))

    pr_l = 0.99
    psi_choked = sub(crit)
    psi_l = sub(pr_l)
    lin = psi_l * (1.0 - pr) / (1.0 - pr_l)
    return np.where(pr < crit, psi_choked, np.where(pr > pr_l, lin, sub(np.clip(pr, crit, pr_l))))


def _magic(slip: np.ndarray, stiffness: np.ndarray, peak: np.ndarray, shape: Any) -> np.ndarray:
    """Pacejka magic formula D sin(C atan(B x)) with B = stiffness / (C D) (Pacejka 2012, eq. 4.49)."""
    D = np.maximum(peak, 1e-6)
    B = stiffness / (shape * D)
    return D * np.sin(shape * np.arctan(B * slip))


class PassengerCar(NonlinearModel):
    """Nonlinear mid-size sedan: 22 states, inputs throttle/brake/steer/slope, 11 sensors.

    Parameters
    ----------
    params : mapping, optional
        Overrides of :data:`DEFAULT_PARAMS` (see :data:`PARAM_DOC` for units and sources).

    Notes
    -----
    ``f`` and ``h`` are vectorised over runs: ``x`` (runs, 22), ``u`` (runs, 4); parameters may be
    floats or arrays (runs,). ``u = [throttle (deg above closed), brake pressure command (MPa),
    road-wheel steering angle (rad, left positive), road slope (rad, uphill positive)]``. The
    brake command is meant to be >= 0 (a controller clips it); the model itself is smooth.

    Examples
    --------
    >>> car = PassengerCar()
    >>> x0, u0 = car.cruise(20.0)
    >>> round(float(x0[car.states.index("v_x")]), 6), car.f(0.0, x0[None], u0[None], car.params).shape
    (20.0, (1, 22))
    """

    def __init__(self, params: Mapping[str, float] | None = None):
        p = dict(DEFAULT_PARAMS)
        for k, v in (params or {}).items():
            if k not in p:
                raise ModelError(f"unknown passenger-car parameter {k!r}; parameters: {sorted(p)}")
            p[k] = float(v)
        super().__init__(states=LONGITUDINAL_STATES + LATERAL_STATES, inputs=INPUTS, outputs=OUTPUTS,
                         params=p, groups={"u": ["throttle", "brake", "steer"], "d": ["slope"]},
                         units=UNITS, name="passenger car (mid-size FWD sedan)")
        self._ix = {s: i for i, s in enumerate(self.states)}

    # ------------------------------------------------------------------ shared computation
    def _forces(self, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> dict[str, np.ndarray]:
        x = np.atleast_2d(np.asarray(x, float))
        u = np.atleast_2d(np.asarray(u, float))
        if x.shape[1] != 22 or u.shape[1] != 4:
            raise ModelError(f"passenger car needs x (runs, 22) and u (runs, 4); got {x.shape}, {u.shape}")
        (m_air, w_e, v_x, _z, _vz, theta, _q, s_f, s_r, p_b, ds_f, ds_r, w_f, w_r,
         v_y, phi, _pr, r, d_f, d_r, dd_f, dd_r) = x.T
        thr, _brake, delta, slope = u.T
        a, b = p["a"], p["b"]
        m = p["m"]
        m_uf, m_ur = p["m_uf"], p["m_ur"]
        m_s = m - 2.0 * (m_uf + m_ur)

        # ---------------- engine: mean-value model (Guzzella & Onder 2010, eqs. 2.5-2.30)
        R, T_m = p["R_air"], p["T_m"]
        p_m = m_air * R * T_m / p["V_m"]                                    # ideal gas in the manifold
        alpha0 = np.deg2rad(p["alpha0_deg"])
        alpha = alpha0 + np.deg2rad(np.clip(thr, 0.0, 90.0 - p["alpha0_deg"]))
        A_th = np.pi * p["D_th"] ** 2 / 4.0 * (1.0 - np.cos(alpha) / np.cos(alpha0)) + p["A_leak"]
        mdot_in = (p["Cd_th"] * A_th * p["p_amb"] / np.sqrt(R * p["T_amb"])
                   * _psi(p_m / p["p_amb"], p["kappa"]))                    # isentropic throttle flow
        mdot_out = p["eta_vol"] * p["V_d"] * w_e * p_m / (4.0 * np.pi * R * T_m)  # speed-density
        imep = p["eta_ind"] * p["H_l"] * p["eta_vol"] * p_m / (p["afr"] * R * T_m)
        n_k = w_e * 30.0 / np.pi / 1000.0                                   # engine speed, 1000 rpm
        fmep = p["fmep0"] + p["fmep1"] * n_k + p["fmep2"] * n_k**2           # Heywood 1988 eq. 13.20
        pmep = p["p_amb"] - p_m                                             # pumping loss
        T_e = p["V_d"] / (4.0 * np.pi) * (imep - fmep - pmep)

        # ---------------- driveline: coupling-region torque converter, fixed gear, FWD
        i_tot = p["i_gear"] * p["i_final"]
        w_t = i_tot * w_f                                                   # turbine speed
        T_c = p["k_tc"] * w_e * (w_e - w_t)                                 # Kotwicki 1982, coupling
        T_drive = p["eta_dl"] * i_tot * T_c                                 # at the front axle

        # ---------------- brakes
        sgn_f = np.tanh(w_f / p["w_b_eps"])
        sgn_r = np.tanh(w_r / p["w_b_eps"])
        T_bf = p["k_bf"] * p_b * sgn_f
        T_br = p["k_br"] * p_b * sgn_r

        # ---------------- vertical: corners from sums/differences; normal loads from tyre deflection
        l_fl, l_fr = 0.5 * (s_f + d_f), 0.5 * (s_f - d_f)
        l_rl, l_rr = 0.5 * (s_r + d_r), 0.5 * (s_r - d_r)
        # body corner heights (small angles): z_c = z - x_i theta + y_i phi
        zc_f = x[:, 3] - a * theta
        zc_r = x[:, 3] + b * theta
        zu_fl = zc_f + 0.5 * p["t_f"] * phi - l_fl
        zu_fr = zc_f - 0.5 * p["t_f"] * phi - l_fr
        zu_rl = zc_r + 0.5 * p["t_r"] * phi - l_rl
        zu_rr = zc_r - 0.5 * p["t_r"] * phi - l_rr
        Fz0_f = m * G * b / (2.0 * (a + b))                                 # static load per front tyre
        Fz0_r = m * G * a / (2.0 * (a + b))
        kt = p["k_t"]
        Fz_fl = np.maximum(Fz0_f - kt * zu_fl, 0.0)
        Fz_fr = np.maximum(Fz0_f - kt * zu_fr, 0.0)
        Fz_rl = np.maximum(Fz0_r - kt * zu_rl, 0.0)
        Fz_rr = np.maximum(Fz0_r - kt * zu_rr, 0.0)
        Fz_f = Fz_fl + Fz_fr
        Fz_r = Fz_rl + Fz_rr

        # ---------------- tyres: slips per axle, magic formula, friction ellipse
        cd, sd = np.cos(delta), np.sin(delta)
        vwx_f = v_x * cd + (v_y + a * r) * sd                               # front wheel-centre speed
        vwy_f = -v_x * sd + (v_y + a * r) * cd                              # along / across the wheel
        vwx_r = v_x
        vwy_r = v_y - b * r
        veps = p["v_eps"]
        den_f = np.sqrt(vwx_f**2 + veps**2)
        den_r = np.sqrt(vwx_r**2 + veps**2)
        kappa_f = (p["r_w"] * w_f - vwx_f) / den_f                           # slip ratio
        kappa_r = (p["r_w"] * w_r - vwx_r) / den_r
        alpha_f = -np.arctan2(vwy_f, np.sqrt(vwx_f**2 + veps**2 * 1e-4))     # slip angle
        alpha_r = -np.arctan2(vwy_r, np.sqrt(vwx_r**2 + veps**2 * 1e-4))
        mu = p["mu"]
        Fx_f = _magic(kappa_f, 2.0 * p["C_kappa"] * Fz_f / 8000.0, mu * Fz_f, p["Cx_shape"])
        Fx_r = _magic(kappa_r, 2.0 * p["C_kappa"] * Fz_r / 8000.0, mu * Fz_r, p["Cx_shape"])
        Fy_f = _magic(alpha_f, p["C_alpha_f"] * Fz_f / Fz0_f, mu * Fz_f, p["Cy_shape"])
        Fy_r = _magic(alpha_r, p["C_alpha_r"] * Fz_r / Fz0_r, mu * Fz_r, p["Cy_shape"])
        # combined slip: scale onto the friction ellipse (circle) when beyond it
        for Fx, Fy, Fz in ((Fx_f, Fy_f, Fz_f), (Fx_r, Fy_r, Fz_r)):
            util = np.hypot(Fx, Fy) / np.maximum(mu * Fz, 1e-6)
            sc = np.where(util > 1.0, 1.0 / np.maximum(util, 1e-12), 1.0)
            Fx *= sc
            Fy *= sc

        # ---------------- body: planar forces (Rajamani 2012, eqs. 2.x / 3.x)
        F_aero = 0.5 * p["rho_air"] * p["cd_A"] * v_x * np.abs(v_x)
        F_roll = p["f_roll"] * m * G * np.tanh(v_x / 0.5)
        FX = Fx_f * cd - Fy_f * sd + Fx_r - F_aero - F_roll - m * G * np.sin(slope)
        FY = Fx_f * sd + Fy_f * cd + Fy_r
        MZ = a * (Fx_f * sd + Fy_f * cd) - b * Fy_r
        a_xb = FX / m                                                        # v_x' - r v_y
        a_yb = FY / m                                                        # v_y' + r v_x
        return dict(p_m=p_m, mdot_in=mdot_in, mdot_out=mdot_out, T_e=T_e, T_c=T_c, T_drive=T_drive,
                    T_bf=T_bf, T_br=T_br, Fx_f=Fx_f, Fx_r=Fx_r, Fy_f=Fy_f, Fy_r=Fy_r, FX=FX, FY=FY,
                    MZ=MZ, a_xb=a_xb, a_yb=a_yb, l=(l_fl, l_fr, l_rl, l_rr),
                    zu=(zu_fl, zu_fr, zu_rl, zu_rr), Fz=(Fz_fl, Fz_fr, Fz_rl, Fz_rr), m_s=m_s,
                    kappa_f=kappa_f, kappa_r=kappa_r, alpha_f=alpha_f, alpha_r=alpha_r,
                    dl=(0.5 * (ds_f + dd_f), 0.5 * (ds_f - dd_f), 0.5 * (ds_r + dd_r), 0.5 * (ds_r - dd_r)),
                    s=(s_f, s_r, d_f, d_r))

    # ------------------------------------------------------------------ the protocol
    def f(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """State derivative, shape (runs, 22); see the class notes for units."""
        x = np.atleast_2d(np.asarray(x, float))
        u = np.atleast_2d(np.asarray(u, float))
        F = self._forces(x, u, p)
        (_m_air, _w_e, v_x, _z, v_z, theta, q, _s_f, _s_r, p_b, ds_f, ds_r, _w_f, _w_r,
         v_y, phi, pr, r, _d_f, _d_r, dd_f, dd_r) = x.T
        brake = u[:, 1]
        a, b = p["a"], p["b"]
        m_s = F["m_s"]
        dx = np.empty_like(x)
        dx[:, 0] = F["mdot_in"] - F["mdot_out"]                                # manifold air mass
        dx[:, 1] = (F["T_e"] - F["T_c"]) / p["J_e"]                             # engine speed
        dx[:, 2] = F["a_xb"] + r * v_y                                          # v_x
        # wheel spin (per axle): J w' = T_drive - T_brake - r_w F_x
        dx[:, 12] = (F["T_drive"] - F["T_bf"] - p["r_w"] * F["Fx_f"]) / p["J_wf"]
        dx[:, 13] = (-F["T_br"] - p["r_w"] * F["Fx_r"]) / p["J_wr"]
        dx[:, 9] = (brake - p_b) / p["tau_b"]                                   # brake actuator lag
        # suspension forces on the body, up (spring, damper, anti-roll bar)
        l_fl, l_fr, l_rl, l_rr = F["l"]
        dl_fl, dl_fr, dl_rl, dl_rr = F["dl"]
        _s_f, _s_r, d_f, d_r = F["s"]
        Fs_fl = -p["k_sf"] * l_fl - p["c_sf"] * dl_fl - p["k_arbf"] * d_f
        Fs_fr = -p["k_sf"] * l_fr - p["c_sf"] * dl_fr + p["k_arbf"] * d_f
        Fs_rl = -p["k_sr"] * l_rl - p["c_sr"] * dl_rl - p["k_arbr"] * d_r
        Fs_rr = -p["k_sr"] * l_rr - p["c_sr"] * dl_rr + p["k_arbr"] * d_r
        hs = p["h_s"]
        # sprung mass: heave, pitch (nose down +), roll (left up +); inertial load transfer acts at h_s
        v_z_dot = (Fs_fl + Fs_fr + Fs_rl + Fs_rr) / m_s
        q_dot = (-a * (Fs_fl + Fs_fr) + b * (Fs_rl + Fs_rr) - hs * m_s * F["a_xb"]
                 + m_s * G * hs * theta) / p["I_y"]
        p_dot = (0.5 * p["t_f"] * (Fs_fl - Fs_fr) + 0.5 * p["t_r"] * (Fs_rl - Fs_rr)
                 + hs * m_s * F["a_yb"] + m_s * G * hs * phi) / p["I_x"]
        dx[:, 3] = v_z
        dx[:, 4] = v_z_dot
        dx[:, 5] = q
        dx[:, 6] = q_dot
        dx[:, 15] = pr
        dx[:, 16] = p_dot
        dx[:, 17] = F["MZ"] / p["I_z"]                                          # yaw
        dx[:, 14] = F["a_yb"] - r * v_x                                         # v_y
        # unsprung masses: m_u z_u'' = F_tyre - F_susp (deviations from static); l = z_c - z_u
        zu = F["zu"]
        kt = p["k_t"]
        zu_dd = [(-kt * zu[0] - Fs_fl) / p["m_uf"], (-kt * zu[1] - Fs_fr) / p["m_uf"],
                 (-kt * zu[2] - Fs_rl) / p["m_ur"], (-kt * zu[3] - Fs_rr) / p["m_ur"]]
        zc_dd_f = v_z_dot - a * q_dot
        zc_dd_r = v_z_dot + b * q_dot
        hf, hr = 0.5 * p["t_f"] * p_dot, 0.5 * p["t_r"] * p_dot
        l_dd = [zc_dd_f + hf - zu_dd[0], zc_dd_f - hf - zu_dd[1], zc_dd_r + hr - zu_dd[2],
                zc_dd_r - hr - zu_dd[3]]
        dx[:, 7] = ds_f
        dx[:, 8] = ds_r
        dx[:, 10] = l_dd[0] + l_dd[1]
        dx[:, 11] = l_dd[2] + l_dd[3]
        dx[:, 18] = dd_f
        dx[:, 19] = dd_r
        dx[:, 20] = l_dd[0] - l_dd[1]
        dx[:, 21] = l_dd[2] - l_dd[3]
        return dx

    def h(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Sensor outputs, shape (runs, 11), in the order of :data:`OUTPUTS`."""
        x = np.atleast_2d(np.asarray(x, float))
        u = np.atleast_2d(np.asarray(u, float))
        F = self._forces(x, u, p)
        w_e, theta, p_b, w_f, w_r, phi, r = x[:, 1], x[:, 5], x[:, 9], x[:, 12], x[:, 13], x[:, 15], x[:, 17]
        delta, slope = u[:, 2], u[:, 3]
        y = np.empty((x.shape[0], 11))
        y[:, 0] = F["p_m"] / 1000.0
        y[:, 1] = w_e
        # accelerometers fixed to the body: specific force = acceleration - gravity, in body axes;
        # body pitch above the horizon = slope - theta, left side up by phi
        y[:, 2] = F["a_xb"] + G * np.sin(slope - theta)
        y[:, 3] = 2.0 * w_f
        y[:, 4] = 2.0 * w_r
        y[:, 5] = u[:, 0]
        y[:, 6] = p_b
        y[:, 7] = F["a_yb"] + G * np.sin(phi)
        y[:, 8] = r
        # left/right wheels roll at their own wheel-centre speed (along the wheel) over their own
        # effective rolling radius, which shrinks by a third of the extra tyre deflection (radial
        # tyres, Pacejka 2012 sec. 7.2: r_e ~ r_free - deflection / 3), with the axle's slip ratio:
        # yaw rate AND load transfer (roll, suspension differences) move the differences
        v_x, v_y = x[:, 2], x[:, 14]
        a = p["a"]
        zu_fl, zu_fr, zu_rl, zu_rr = F["zu"]
        cd, sd = np.cos(delta), np.sin(delta)
        side = (v_y + a * r) * sd
        v_fl = (v_x - 0.5 * p["t_f"] * r) * cd + side
        v_fr = (v_x + 0.5 * p["t_f"] * r) * cd + side
        v_rl = v_x - 0.5 * p["t_r"] * r
        v_rr = v_x + 0.5 * p["t_r"] * r
        rw = p["r_w"]
        y[:, 9] = (1.0 + F["kappa_f"]) * (v_fl / (rw + zu_fl / 3.0) - v_fr / (rw + zu_fr / 3.0))
        y[:, 10] = (1.0 + F["kappa_r"]) * (v_rl / (rw + zu_rl / 3.0) - v_rr / (rw + zu_rr / 3.0))
        return y

    # ------------------------------------------------------------------ operating points
    def cruise(self, speed: float, *, slope: float = 0.0, params: Mapping[str, float] | None = None,
               tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
        """Trim for straight driving at ``speed`` (m/s) on a road of constant ``slope`` (rad).

        Solves ``f(x, u) = 0`` for every longitudinal state and the throttle angle, with the lateral
        states zero and no brake, by :func:`fdikit.model.trim`.

        Returns
        -------
        x0 : ndarray (22,)
        u0 : ndarray (4,)  [throttle (deg), 0, 0, slope]
        """
        from ...model.linearize import trim

        p = self.param_values(params)
        i_tot = p["i_gear"] * p["i_final"]
        x0 = np.zeros(22)
        x0[2] = speed
        x0[12] = x0[13] = speed / p["r_w"]
        x0[1] = 1.03 * i_tot * speed / p["r_w"]
        x0[0] = 35e3 * p["V_m"] / (p["R_air"] * p["T_m"])
        u0 = np.array([10.0, 0.0, 0.0, slope])
        free = ["m_air", "w_e", "z", "theta", "s_f", "s_r", "w_f", "w_r"]
        constrained = {s: 0.0 for s in LONGITUDINAL_STATES}
        xs, us, info = trim(self, x0, u0, p, free_states=free, free_inputs=["throttle"],
                            derivatives=constrained, tol=tol)
        res = np.abs(self.f(0.0, xs[None], us[None], p)[0])
        if res.max() > 1e-6 * max(1.0, speed):
            bad = self.states[int(np.argmax(res))]
            raise ModelError(f"no straight-driving trim at {speed} m/s, slope {slope} rad: derivative of "
                             f"{bad!r} is {res.max():.3g} (info {info})")
        return xs, us
