"""The ABS plant's parameters (luo-et-al, Table I, with the replacements and their reasons) and its
state, input and output names.
"""

from __future__ import annotations

# --------------------------------------------------------------------------------------------
# Parameters: luo-et-al, Table I, with garbled/missing values replaced (reasons beside each).
# --------------------------------------------------------------------------------------------
G = 9.81  # m/s^2
_M_CAR = 1200.0  # kg, vehicle mass m of eq. (30) (not given in the paper; a compact car)

#: The plant and controller parameters by name (luo-et-al Table I; the values the paper prints
#: garbled or omits are replaced, each with its reason beside it).
PARAMS: dict[str, float] = {
    # sliding-mode PWM controller, eqs. (1)-(3)
    "alpha": 0.01,  # s, Table I
    "phi": 0.02,  # boundary layer, Table I
    "t_s": 1e-3,  # s, controller sampling interval, Table I
    "lam_star": 0.2,  # target slip, Table I
    # pedal and master cylinder, eqs. (4)-(5)
    # Pedal-force profile (Scenario.pedal). Default "step": eq. (4)'s lagged step, K_p reached
    # within ~5 tau_p = 0.1 s, so P_m has settled long before the ABS valves act (~2 s after
    # t_brake here) and a tau_m change (F5) leaves no trace when the valves start. The paper
    # says "A fault in tau_m can be detected by a GLRT on residual r3 at the beginning of the
    # valve operation ... The GLRT for r3 shows a change at 5 s" and "after the ABS engages the
    # valve at around 7 s" (Section IV); Fig. 3 shows valve activity at 5-7 s. That timing fits
    # a pedal force rising slowly over seconds, not eq. (4) with tau_p = 0.02 s; the text never
    # states such a ramp (only that "the same brake torque was applied" to both models of
    # Fig. 3). Opt-in experiment: Scenario(pedal="ramp", pedal_ramp=T) rises linearly to K_p
    # over T seconds and holds it; plant and nominal P_m input share it (only tau_m differs).
    # Measured, it does not reveal F5: a slower pedal *shrinks* the tau_m signature, since two
    # lags (5) differing by d·tau_m differ by ~d·tau_m·dP_m/dt = d·tau_m·P_ss/T (noise-free max
    # |dP_m| at +15 %: 0.549 MPa with the step, 0.014 with T = 3 s, 0.008 with T = 5 s; ABS on at
    # 2.7/4.5/6.0 s). Table V setting, 23 dB, 500 runs/class: F5 and F4 (+-2 %) Pd <= 0.004 on
    # every test (Pf level) for step, 3 s and 5 s; sensitivity 71.4/71.4/71.3 %.
    "tau_p": 0.02,  # s, Table I
    # kN. Table I prints K_p = 4.2 (unitless), giving P_m = K_m K_p/A_m = 8.4 kPa (or 8.4 MPa if
    # read as kN), i.e. at most K_f P_m = 840 N·m of brake torque, less than the 1.1 kN·m the
    # tyre can transmit: the wheel would never reach the target slip and ABS never engage. A
    # panic-stop force of 7 kN on the master-cylinder side gives P_m = 14 MPa (a typical
    # hard-braking line pressure) and 1.4 kN·m.
    "K_p": 7.0,
    "K_m": 5.0,  # Table I
    "tau_m": 0.02,  # s, Table I
    "A_m": 2.5e-3,  # m^2, Table I
    # hydraulic modulator, eqs. (6)-(9)
    "C_in": 2e-4,  # Table I; C_in·A_0 = 0.5 mm^2, a realistic ABS inlet orifice
    "C_out": 4e-4,  # Table I; C_out·A_0 = 1.0 mm^2
    "A_0": 2.5e-3,  # m^2, Table I
    "rho": 910.0,  # kg/m^3, Table I
    # MPa. Table I prints 100 MPa, above any line pressure, so the release flow (7) would run
    # backwards into the wheel cylinder; a low-pressure accumulator works at ~0.1 MPa.
    "P_lp": 0.1,
    "t_opdelay": 4e-3,  # s, Table I
    "t_oprate": 3e-4,  # s, Table I
    # s. Table I prints t_cldelay = 0.2 s twice (one row is a duplicate). A 0.2 s closing delay
    # would keep the valve flowing for 200 controller periods; solenoid valves close in a few
    # ms, so we use 2 ms, of the order of t_opdelay.
    "t_cldelay": 2e-3,
    "t_clrate": 2e-4,  # s, Table I
    # wheel cylinder, eqs. (10)-(11)
    # MPa. Table I prints 1.72e+9 "MPa"; 1.72e9 Pa = 1720 MPa is the bulk modulus of brake
    # fluid. With V_s this gives a build-up from 0 to 14 MPa in ~50 ms.
    "beta_s": 1720.0,
    "V_s": 2.5e-4,  # m^3, Table I
    # brake torque, eq. (12)
    "K_f": 100.0,  # N·m/MPa, Table I (pressures in MPa)
    "omega_n": 7.07,  # rad/s, Table I
    # Table I prints 3.54e+2, which with omega_n = 7.07 puts a pole at -0.01 1/s (the torque
    # would take ~100 s to build). We keep the digits and drop the exponent: zeta = 3.54, i.e.
    # omega_n^2 = 50 and 2 zeta omega_n = 50 in eq. (19)'s x4 equation (poles -1.0 and -49 1/s).
    # The other reading, 0.354, gives a lightly damped 1.1 Hz torque and a slip limit cycle
    # between 0 and 0.8 (no regulation near 0.2); 3.54 gives slip cycling 0.08-0.24 (mean 0.15)
    # and the ABS engaging ~2 s after the brake is applied, the lag Section VI describes.
    "zeta": 3.54,
    # wheel and vehicle, eqs. (13)-(18)
    "I_w": 5.0,  # kg m^2, Table I
    "R_w": 0.318,  # m, Table I
    "N_v": _M_CAR * G / 4.0,  # N, normal load on the braked wheel (not given): quarter of m g
    # kg. Not given. M_v/4 in eq. (16) is the mass the braked corner decelerates; M_v = 4 m
    # makes eq. (19) reproduce eq. (30) (dx2/dt = -g mu/(4 R_w)); see the module docstring.
    "M_v": 4.0 * _M_CAR,
    # wheel-speed sensor gain (1 = healthy); fault F1 lowers it
    "k_ws": 1.0,
}

PARAM_UNITS = {
    "alpha": "s", "phi": "", "t_s": "s", "lam_star": "", "tau_p": "s", "K_p": "kN", "K_m": "",
    "tau_m": "s", "A_m": "m^2", "C_in": "", "C_out": "", "A_0": "m^2", "rho": "kg/m^3",
    "P_lp": "MPa", "t_opdelay": "s", "t_oprate": "s", "t_cldelay": "s", "t_clrate": "s",
    "beta_s": "MPa", "V_s": "m^3", "K_f": "N·m/MPa", "omega_n": "rad/s", "zeta": "",
    "I_w": "kg m^2", "R_w": "m", "N_v": "N", "M_v": "kg", "k_ws": "",
}

PARAM_NAMES: tuple[str, ...] = tuple(PARAMS)
_PI = {n: i for i, n in enumerate(PARAM_NAMES)}
# indices used by the numba kernel (kept as module-level ints so numba freezes them)
(_ALPHA, _PHI, _TS, _LAMS, _TAUP, _KP, _KM, _TAUM, _AM, _CIN, _COUT, _A0, _RHO, _PLP, _TOPD, _TOPR,
 _TCLD, _TCLR, _BETA, _VS, _KF, _WN, _ZETA, _IW, _RW, _NV, _MV, _KWS) = range(len(PARAM_NAMES))
assert PARAM_NAMES[_KWS] == "k_ws" and PARAM_NAMES[_ZETA] == "zeta"

STATES = ["omega_w", "omega_v", "T_b", "dT_b", "P_s", "P_m"]
STATE_UNITS = ["rad/s", "rad/s", "N·m", "N·m/s", "MPa", "MPa"]
OUTPUTS = ["omega_w", "omega_v"]
#: Inputs of the :class:`ABSPlant` model: pedal force F_p (kN, output of eq. (4)), the inlet
#: and outlet valve openings u_in, u_out (PWM duty times A_eff/A_0, in [0, 1]) and the
#: process noise w1..w6 (group ``w``).
INPUTS = ["F_p", "u_in", "u_out", "w1", "w2", "w3", "w4", "w5", "w6"]
