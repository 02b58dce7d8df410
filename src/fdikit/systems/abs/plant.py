"""Antilock braking system (ABS) benchmark plant of luo-et-al (Luo et al., Sections II-III).

A quarter-car braking model with a hydraulic modulator and a sliding-mode PWM slip controller,
the fault universe F0-F5 of Section III-A and its noise model, with a numba Monte Carlo kernel
vectorised (parallel) over runs.

States (luo-et-al, eq. (19)) and units used throughout:

====  =========  ===========================================  ==========
 x     name       meaning                                      unit
====  =========  ===========================================  ==========
 x1    omega_w    wheel angular speed                          rad/s
 x2    omega_v    vehicle speed as wheel-angular speed V/R_w   rad/s
 x3    T_b        brake torque                                 N·m
 x4    dT_b       derivative of the brake torque               N·m/s
 x5    P_s        wheel-cylinder oil pressure                  MPa
 x6    P_m        master-cylinder oil pressure                 MPa
====  =========  ===========================================  ==========

Pressures are in MPa (so that ``K_f = 100`` N·m/MPa of Table I applies as printed) and the
pedal force in kN. Measurements are ``y = [k_ws·x1, x2] + v`` (``k_ws`` is the wheel-speed
sensor gain, 1 when healthy; F1 lowers it), sampled every 10 ms.

Modelling choices where the paper is garbled, silent or inconsistent (each is also noted
beside its constant in :data:`PARAMS`):

* Vehicle deceleration. Eq. (16)/(19) with the usual quarter-car load ``N_v = M_v g/4`` would
  give ``dV/dt = -g·mu`` (a ~2.5 s stop), whereas the observer model of eq. (30) has
  ``dx2/dt = -g mu/(4 R_w)`` and the event times of Section V (valve operation at ~5 s, ABS
  engaged at ~7 s, detection delays up to 7 s) need a stop lasting most of the 12.5 s record.
  We keep the *form* of eqs. (19) and (25) (``dx2/dt = -4 N_v mu/(R_w M_v)``) and choose
  ``N_v = m g/4`` with ``m = 1200`` kg and ``M_v = 4 m``: the braked corner's tyre force
  decelerates the whole vehicle mass (only the instrumented wheel brakes). Then eqs. (19),
  (25) and (30) hold literally with the same numbers.
* Orifice flow. Eqs. (6)-(7) print ``sqrt(rho·dP)``, which is not a flow; we use the standard
  orifice law ``Q = C A_eff sqrt(2 dP/rho)`` (Merritt, *Hydraulic Control Systems*, 1967),
  signed so that a reversed pressure difference gives a reversed flow.
* Valves. The build-up (inlet) valve is commanded open while ``sat(S) > 0`` and the release
  (outlet) valve while ``sat(S) < 0``; each valve's effective area follows the opening law
  (8) from its last open command and the closing law (9) from its last close command. When a
  valve is reversed half-way through a transition, the new law is entered at the point of
  equal area (no jump). While a valve closes, its PWM duty stays at the last commanded
  ``|sat(S)|``. Once the closing transients are over this is exactly eq. (19)'s switch
  between ``beta_s Q_in/V_s`` and ``-beta_s Q_out/V_s``.
* Controller. Eq. (2) prints a forward difference ``(e(k+1) - e(k))/t_s``, which is not
  causal; we use the backward difference ``(e(k) - e(k-1))/t_s``. The controller sees the
  true (noise-free) slip: measurement noise and the sensor fault F1 act on the diagnostic
  measurements ``y(t_k)`` of eq. (19) only, so a sensor fault leaves the true states
  unchanged. Below ``v_off`` (2 m/s) the ABS is switched off (as production ABS are), the
  inlet valve stays open and the wheel locks until the car stops.
* Standstill. The vehicle speed cannot become negative; once it reaches zero the car stays
  at rest (wheel and vehicle speed 0). The wheel speed cannot become negative (a brake does
  not drive the wheel backwards).

Integration: explicit Euler-Maruyama at ``dt = 1 ms`` for x1-x4 and x6; the wheel-cylinder
pressure x5 is advanced with the exact solution of the orifice equation over the step
(``d sqrt(dP)/dt = -k/2`` with the valve opening frozen over the step; inflow then outflow,
Lie splitting), which Euler would turn into a limit cycle near ``P_s = P_m``.

Noise (Section III-A): measurement noise ``v ~ N(0, 0.004)`` on each channel at every 10 ms
sample; process noise ``w_i`` on every state ``i``: a white sequence held over each 1 ms step
(``x_{k+1} = x_k + dt (f(x_k) + w_k)``) with variance ``10^(-SNR/10)`` times the mean-square
value of state ``i`` (SNR = 23 dB gives 0.5 %; 20 dB 1 %; 17 dB 2 %). The mean-square values
come from one nominal (F0) noise-free run of the same manoeuvre over the whole record at 1 ms.

How we read Section III-A, and why. The text fixes (i) *what* is noisy: every state, the noise
entering the state equations as ``+ w_i`` in eq. (19), and the two measurements; (ii) the *size*:
"variance of 0.5 % of the mean-square values of the states they are added to (... +23 dB)", so
``var(w_i) = 10^(-SNR/10) · ms(x_i)`` with the state (not its derivative) as the signal, and
Section VII varies only this process noise (23/20/17 dB) with the measurement noise fixed. It
leaves open (iii) the *rate* of the white sequence. The paper simulates at a fixed 1 ms step
(Section VII, t_s of Table I), so the default draws a new ``w`` every 1 ms step and holds it over
the step (``Scenario.noise_hold = None``); ``noise_hold = 0.01`` holds each draw over a 10 ms
sample instead (ten times the noise power spectral density), the selectable alternative. Table III
decides between them: its observer-residual variances 4.5e-3 (r3) and 4.0e-3 (r4) are the
measurement noise's 0.004 plus a small share. Measured (40 nominal runs, 23 dB, the observer of
:class:`fdikit.systems.abs.residuals.ABSObserver`): var(r3), var(r4) = 4.8e-3, 4.9e-3 with the
1 ms hold; 7.4e-3, 8.5e-3 with the 10 ms hold; 4.5e-3, 4.5e-3 without process noise. Adding the
noise to the states themselves (``x += w`` with that variance, 3.4 rad/s per step on the wheel
speed) would be far larger still. Hence the 1 ms reading. (With the earlier observer, estimate not
held in the output injection, the nominal r3 variance was 8.1e-3 with process noise and 7.7e-3
without it: that observer's own error dominated.) This noise is, however, what makes the two
smallest parametric faults of Table II invisible to any detector before the ABS engages: the
Neyman-Pearson bound of the known tau_m +15 % and I_w +2 % signatures over 0.5-2.6 s is
d' = 0.96 and 1.10 at 23 dB, against 9.0 and 11.1 with measurement noise only
(:mod:`fdikit.systems.abs.detectability`); noise on the speeds alone, or on the brake torque alone,
already brings tau_m's to 1.6 and 1.5.

Random numbers: run ``i`` uses the streams of ``numpy.random.SeedSequence(seed,
spawn_key=(i, 0))`` (noise, a xoshiro256** generator seeded from it and run inside the
kernel) and ``spawn_key=(i, 1)`` (fault magnitude), so a run is identical alone, inside a
batch of any size and in any process.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numba import njit, prange

from ...errors import DataError, ModelError
from ...model.nonlinear import NonlinearModel
from ...signals import Signals

__all__ = [
    "FAULT_CLASSES",
    "INPUTS",
    "MU_SLIP",
    "MU_TABLE",
    "OUTPUTS",
    "PARAMS",
    "STATES",
    "ABSPlant",
    "ABSResult",
    "FaultClass",
    "Scenario",
    "demo_summary",
    "fault_scenarios",
    "mu",
    "simulate",
    "slip",
    "state_mean_square",
    "summarize",
]

# --------------------------------------------------------------------------------------------
# Parameters: luo-et-al, Table I, with garbled/missing values replaced (reasons beside each).
# --------------------------------------------------------------------------------------------
G = 9.81  # m/s^2
_M_CAR = 1200.0  # kg, vehicle mass m of eq. (30) (not given in the paper; a compact car)

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

# --------------------------------------------------------------------------------------------
# Tyre-road friction: 1-D lookup table for dry asphalt.
# Source: Burckhardt's tyre model mu(lam) = c1 (1 - exp(-c2 lam)) - c3 lam with the dry-asphalt
# coefficients c1 = 1.2801, c2 = 23.99, c3 = 0.52 (M. Burckhardt, Fahrwerktechnik:
# Radschlupf-Regelsysteme, Vogel, 1993; tabulated in U. Kiencke and L. Nielsen, Automotive
# Control Systems, Springer, 2000/2005). Tabulated every 0.01 in slip, linear in between;
# extended as an odd function for negative slip (a wheel faster than the car drives it).
# --------------------------------------------------------------------------------------------
_BURCKHARDT_DRY = (1.2801, 23.99, 0.52)
MU_SLIP = np.linspace(0.0, 1.0, 101)
MU_TABLE = (_BURCKHARDT_DRY[0] * (1.0 - np.exp(-_BURCKHARDT_DRY[1] * MU_SLIP))
            - _BURCKHARDT_DRY[2] * MU_SLIP)
_MU_N = MU_SLIP.size - 1
_WV_EPS = 1e-6  # rad/s, below this the slip is taken as 0 (car at rest)


def mu(lam: Any) -> np.ndarray:
    """Tyre-road friction coefficient for dry asphalt from the lookup table.

    Parameters
    ----------
    lam : array_like
        Wheel slip (eq. (14)), any shape. Values beyond [-1, 1] are clipped.

    Returns
    -------
    ndarray
        ``mu(lam)``, same shape (odd in ``lam``).

    Examples
    --------
    >>> from fdikit.systems.abs.plant import mu
    >>> round(float(mu(0.2)), 3), round(float(mu(1.0)), 3)
    (1.166, 0.76)
    """
    lam = np.asarray(lam, dtype=float)
    return np.sign(lam) * np.interp(np.abs(lam), MU_SLIP, MU_TABLE)


def slip(omega_w: Any, omega_v: Any) -> np.ndarray:
    """Wheel slip ``(omega_v - omega_w)/omega_v`` (luo-et-al, eq. (14)); 0 where the car is at rest.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import slip
    >>> float(slip(80.0, 100.0))
    0.2
    """
    ww = np.asarray(omega_w, dtype=float)
    wv = np.asarray(omega_v, dtype=float)
    ok = wv > _WV_EPS
    return np.where(ok, (wv - ww) / np.where(ok, wv, 1.0), 0.0)


# --------------------------------------------------------------------------------------------
# The plant as a NonlinearModel (numpy, vectorised over runs)
# --------------------------------------------------------------------------------------------
def _signed_orifice(dp_mpa, rho):
    """Orifice velocity term sign(dP) sqrt(2 |dP| / rho) in m/s for dP in MPa."""
    return np.sign(dp_mpa) * np.sqrt(2e6 * np.abs(dp_mpa) / rho)


class ABSPlant(NonlinearModel):
    """The ABS plant of luo-et-al, eq. (19), as a :class:`~fdikit.model.NonlinearModel`.

    ``f(t, x, u, p)`` is the open-loop vector field (valve openings are inputs; the sliding-mode
    controller and the valve laws live in :func:`simulate`). Everything is vectorised over
    runs: ``x`` (runs, 6), ``u`` (runs, 9) in the order of :data:`INPUTS`, ``p`` a mapping of
    floats or (runs,) arrays.

    Parameters
    ----------
    params : mapping, optional
        Overrides of :data:`PARAMS` (unknown names raise :class:`ModelError`).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit.systems.abs.plant import ABSPlant
    >>> plant = ABSPlant()
    >>> x = np.array([[70.0, 80.0, 900.0, 0.0, 10.0, 14.0]])
    >>> u = np.zeros((1, 9)); u[0, 0] = 7.0
    >>> dx = plant.f(0.0, x, u, plant.params)
    >>> dx.shape, round(float(dx[0, 2]), 1)
    ((1, 6), 0.0)
    """

    def __init__(self, params: Mapping[str, float] | None = None):
        p = dict(PARAMS)
        for k, v in (params or {}).items():
            if k not in p:
                raise ModelError(f"unknown ABS parameter {k!r}; parameters: {list(PARAMS)}")
            p[k] = float(v)
        units = dict(zip(STATES, STATE_UNITS))
        units.update(PARAM_UNITS)
        units.update({"F_p": "kN", "u_in": "", "u_out": ""})
        super().__init__(
            states=STATES, inputs=INPUTS, outputs=OUTPUTS, params=p,
            groups={"u": ["F_p", "u_in", "u_out"], "w": ["w1", "w2", "w3", "w4", "w5", "w6"]},
            units=units, name="ABS (Luo et al. 2010)",
        )
        self._ms_cache: dict[tuple, np.ndarray] = {}

    def f(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """State derivative ``(runs, 6)`` of eq. (19) (units: see the module docstring)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        u = np.atleast_2d(np.asarray(u, dtype=float))
        if x.shape[1] != 6 or u.shape[1] != len(INPUTS):
            raise DataError(f"ABS f expects x (runs, 6) and u (runs, {len(INPUTS)}), "
                            f"got {x.shape} and {u.shape}")
        x1, x2, x3, x4, x5, x6 = x.T
        F_p, u_in, u_out = u[:, 0], u[:, 1], u[:, 2]
        w = u[:, 3:9]
        R_w, N_v, I_w = p["R_w"], p["N_v"], p["I_w"]
        m = mu(slip(x1, x2))  # eq. (13)-(15)
        dx = np.empty_like(x)
        dx[:, 0] = (R_w * N_v * m - x3) / I_w  # eq. (17)-(18)
        dx[:, 1] = -4.0 * N_v * m / (R_w * p["M_v"])  # eq. (16) in wheel-angular units
        dx[:, 2] = x4  # eq. (12)
        wn = p["omega_n"]
        dx[:, 3] = wn**2 * (p["K_f"] * x5 - 2.0 * p["zeta"] * x4 / wn - x3)
        gain = p["beta_s"] / p["V_s"] * p["A_0"]  # eqs. (6)-(11), orifice law Q = C A sqrt(2dP/rho)
        q_in = p["C_in"] * u_in * _signed_orifice(x6 - x5, p["rho"])
        q_out = p["C_out"] * u_out * _signed_orifice(x5 - p["P_lp"], p["rho"])
        dx[:, 4] = gain * (q_in - q_out)
        # eq. (5) with P_m = F_m/A_m: kN -> N (1e3), Pa -> MPa (1e-6)
        dx[:, 5] = p["K_m"] * F_p * 1e-3 / (p["A_m"] * p["tau_m"]) - x6 / p["tau_m"]
        return dx + w

    def h(self, t: float, x: np.ndarray, u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Noise-free measurements ``(runs, 2)``: ``[k_ws·omega_w, omega_v]`` (rad/s)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return np.stack([p["k_ws"] * x[:, 0], x[:, 1]], axis=1)

    # convenience ---------------------------------------------------------------------------
    def param_matrix(self, runs: int, overrides: Mapping[str, Any] | None = None) -> np.ndarray:
        """Parameters as a ``(runs, n_params)`` array in the order of ``PARAM_NAMES``."""
        P = np.tile(np.array([self.params[n] for n in PARAM_NAMES]), (runs, 1))
        for k, v in (overrides or {}).items():
            if k not in _PI:
                raise ModelError(f"unknown ABS parameter {k!r}; parameters: {list(PARAMS)}")
            P[:, _PI[k]] = v
        return P

    def pedal_force(self, t: Any, t_brake: float, ramp: float | None = None) -> np.ndarray:
        """Pedal force ``F_p(t)`` in kN (0 before ``t_brake``).

        Parameters
        ----------
        t : array_like
            Times, s, any shape.
        t_brake : float
            Brake application time, s.
        ramp : float or None
            None (default): the step response of eq. (4), ``K_p (1 - exp(-(t - t_brake)/tau_p))``.
            A duration ``T_ramp > 0`` (s): the opt-in ramp profile of :class:`Scenario`,
            ``K_p min((t - t_brake)/T_ramp, 1)``.

        Returns
        -------
        ndarray
            ``F_p``, same shape as ``t``.

        Examples
        --------
        >>> from fdikit.systems.abs.plant import ABSPlant
        >>> ABSPlant().pedal_force([0.0, 2.0, 4.0, 9.0], 0.5, ramp=3.0).round(3).tolist()
        [0.0, 3.5, 7.0, 7.0]
        """
        t = np.asarray(t, dtype=float)
        tt = np.maximum(t - t_brake, 0.0)
        if ramp is not None:
            if not ramp > 0:
                raise DataError(f"pedal ramp duration must be > 0 s, got {ramp}")
            return np.where(t >= t_brake, self.params["K_p"] * np.minimum(tt / ramp, 1.0), 0.0)
        return np.where(t >= t_brake, self.params["K_p"] * (1.0 - np.exp(-tt / self.params["tau_p"])), 0.0)


# --------------------------------------------------------------------------------------------
# Fault universe (luo-et-al, Section III-A, Table II)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FaultClass:
    """One fault class: a relative change ``magnitude`` of one parameter.

    The faulty value is ``nominal · (1 + magnitude)``; ``magnitude`` lies in ``[lo, hi]``, or
    in ``[-hi, -lo] ∪ [lo, hi]`` when ``symmetric``.
    """

    name: str
    param: str | None
    lo: float
    hi: float
    symmetric: bool
    description: str

    def check(self, magnitude: float) -> None:
        """Raise :class:`DataError` if ``magnitude`` lies outside this class."""
        if self.param is None:
            if magnitude != 0.0:
                raise DataError(f"fault class {self.name} (nominal) takes no magnitude, got {magnitude}")
            return
        a = abs(magnitude) if self.symmetric else magnitude
        if not (self.lo - 1e-12 <= a <= self.hi + 1e-12):
            rng = (f"±[{self.lo:g}, {self.hi:g}]" if self.symmetric else f"[{self.lo:g}, {self.hi:g}]")
            raise DataError(f"magnitude {magnitude:g} outside fault class {self.name} "
                            f"({self.description}): allowed {rng}")

    def draw(self, rng: np.random.Generator, step: float | None = None) -> float:
        """One magnitude drawn uniformly inside the class (random sign when symmetric).

        With ``step``, drawn uniformly from the grid ``lo, lo + step, ..., hi`` instead (the
        paper's F3/F4 sizes ±2 %, ±3 %, ..., ±10 % are ``step=0.01``).
        """
        if self.param is None:
            return 0.0
        if step is None:
            m = rng.uniform(self.lo, self.hi)
        else:
            n = int(np.floor((self.hi - self.lo) / step + 1e-9))
            m = self.lo + step * rng.integers(0, n + 1)
        if self.symmetric and rng.random() < 0.5:
            m = -m
        return float(m)


#: Fault classes of Table II. Upper bounds where the paper gives only a lower one (F1.2, F2.2,
#: F5) are our choice: 10 %, 30 % and 50 %.
FAULT_CLASSES: dict[str, FaultClass] = {
    "F0": FaultClass("F0", None, 0.0, 0.0, False, "nominal"),
    "F1.1": FaultClass("F1.1", "k_ws", -0.05, -0.02, False, "wheel-speed sensor reading 2-5 % low"),
    "F1.2": FaultClass("F1.2", "k_ws", -0.10, -0.05, False, "wheel-speed sensor reading >= 5 % low"),
    "F2.1": FaultClass("F2.1", "R_w", -0.20, -0.02, False, "wheel radius R_w 2-20 % smaller"),
    "F2.2": FaultClass("F2.2", "R_w", -0.30, -0.20, False, "wheel radius R_w >= 20 % smaller"),
    "F3": FaultClass("F3", "K_f", 0.02, 0.10, True, "brake torque gain K_f ±2-10 %"),
    "F4": FaultClass("F4", "I_w", 0.02, 0.10, True, "wheel inertia I_w ±2-10 %"),
    "F5": FaultClass("F5", "tau_m", 0.15, 0.50, False, "master-cylinder time constant tau_m +15 % or more"),
}


@dataclass(frozen=True)
class Scenario:
    """A braking manoeuvre with one fault class and the noise model.

    Parameters
    ----------
    fault : str
        Key of :data:`FAULT_CLASSES` ("F0", "F1.1", ..., "F5").
    magnitude : float or None
        Relative parameter change (e.g. -0.05 for K_f -5 %). ``None`` draws one per run,
        uniformly inside the class (0 for F0).
    snr_db : float or None
        Process-noise signal-to-noise ratio (23, 20 or 17 dB in the paper); None: no process noise.
    meas_var : float
        Variance of the measurement noise on each channel, (rad/s)^2 (0.004 in the paper).
    v0 : float
        Initial vehicle speed, m/s.
    t_brake : float
        Time the driver steps on the brake, s.
    t_end : float
        Length of the record, s (12.5 s: N = 1250 samples at 10 ms).
    dt, sample_dt : float
        Integration/controller step (1 ms = t_s) and diagnostic sample interval (10 ms), s.
    v_off : float
        Vehicle speed below which the ABS switches off and the wheel may lock, m/s.
    grid_step : float or None
        When magnitudes are drawn, draw them on a grid of this step inside the class
        (0.01 gives the paper's ±2 %, ±3 %, ..., ±10 % for F3/F4); None: uniform.
    noise_hold : float or None
        Time over which one process-noise sample is held, s (a multiple of ``dt``). None (the
        default, the reading Table III supports; see the module docstring): a new sample every
        integration step of 1 ms. 0.01: one per 10 ms measurement sample (ten times the power).
    pedal : {"step", "ramp"}
        Driver's pedal-force profile. ``"step"`` (default): the step response of eq. (4) with
        ``tau_p`` (K_p reached within ~0.1 s). ``"ramp"`` (opt-in experiment): ``F_p`` rises
        linearly from 0 at ``t_brake`` to ``K_p`` at ``t_brake + pedal_ramp`` and is then held
        (no ``tau_p`` lag). The same profile drives the plant and the nominal P_m input the
        observer receives (only ``tau_m`` differs between them under F5). See the comment beside
        ``tau_p`` in :data:`PARAMS`.
    pedal_ramp : float or None
        Ramp duration T_ramp, s (> 0); required with ``pedal="ramp"``, must be None with "step".
    """

    fault: str = "F0"
    magnitude: float | None = None
    snr_db: float | None = 23.0
    meas_var: float = 0.004
    v0: float = 28.0
    t_brake: float = 0.5
    t_end: float = 12.5
    dt: float = 1e-3
    sample_dt: float = 1e-2
    v_off: float = 2.0
    grid_step: float | None = None
    noise_hold: float | None = None
    pedal: str = "step"
    pedal_ramp: float | None = None

    def __post_init__(self):
        if self.fault not in FAULT_CLASSES:
            raise DataError(f"unknown fault {self.fault!r}; known: {list(FAULT_CLASSES)}")
        if self.magnitude is not None:
            FAULT_CLASSES[self.fault].check(float(self.magnitude))
        sub = self.sample_dt / self.dt
        if self.dt <= 0 or abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
            raise DataError(f"sample_dt ({self.sample_dt}) must be a positive multiple of dt ({self.dt})")
        n = self.t_end / self.sample_dt
        if abs(n - round(n)) > 1e-9 or round(n) < 1:
            raise DataError(f"t_end ({self.t_end}) must be a positive multiple of "
                            f"sample_dt ({self.sample_dt})")
        if self.meas_var < 0:
            raise DataError(f"meas_var must be >= 0, got {self.meas_var}")
        if self.noise_hold is not None:
            nh = self.noise_hold / self.dt
            if self.noise_hold <= 0 or abs(nh - round(nh)) > 1e-9:
                raise DataError(f"noise_hold ({self.noise_hold} s) must be a positive multiple of dt "
                                f"({self.dt} s)")
        if self.pedal not in ("step", "ramp"):
            raise DataError(f"pedal must be 'step' or 'ramp', got {self.pedal!r}")
        if self.pedal == "ramp" and (self.pedal_ramp is None or not self.pedal_ramp > 0):
            raise DataError(f"pedal='ramp' needs pedal_ramp > 0 s, got {self.pedal_ramp}")
        if self.pedal == "step" and self.pedal_ramp is not None:
            raise DataError(f"pedal_ramp ({self.pedal_ramp} s) is only used with pedal='ramp'")
        if self.v0 <= self.v_off:
            raise DataError(f"initial speed v0 = {self.v0} m/s must exceed v_off = {self.v_off} m/s")

    @property
    def n_steps(self) -> int:
        return round(self.t_end / self.dt)

    @property
    def n_samples(self) -> int:
        return round(self.t_end / self.sample_dt)

    @property
    def substeps(self) -> int:
        return round(self.sample_dt / self.dt)

    @property
    def ramp_time(self) -> float:
        """Pedal ramp duration, s, as the kernel takes it (0.0: the step of eq. (4))."""
        return float(self.pedal_ramp) if self.pedal == "ramp" else 0.0

    @property
    def noise_hold_steps(self) -> int:
        """Integration steps over which one process-noise sample is held (1: a new one every step)."""
        return 1 if self.noise_hold is None else round(self.noise_hold / self.dt)


# --------------------------------------------------------------------------------------------
# numba kernel
# --------------------------------------------------------------------------------------------
_MU_TAB = MU_TABLE.copy()
_U64 = np.uint64


@njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << _U64(k)) | (x >> _U64(64 - k))


@njit(cache=True)
def _next_u64(s):
    """xoshiro256** (Blackman & Vigna, 2018) on the 4-word state ``s`` (updated in place)."""
    s0, s1, s2, s3 = s[0], s[1], s[2], s[3]
    result = _rotl(s1 * _U64(5), 7) * _U64(9)
    t = s1 << _U64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    s[0], s[1], s[2], s[3] = s0, s1, s2, s3
    return result


@njit(cache=True)
def _uniform(s):
    """Uniform on [0, 1) with 53 random bits."""
    return float(_next_u64(s) >> _U64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _normal_pair(s):
    """Two independent standard normals (Marsaglia polar method)."""
    while True:
        a = 2.0 * _uniform(s) - 1.0
        b = 2.0 * _uniform(s) - 1.0
        r = a * a + b * b
        if 0.0 < r < 1.0:
            f = math.sqrt(-2.0 * math.log(r) / r)
            return a * f, b * f


@njit(cache=True)
def _mu_nb(lam, tab):
    a = abs(lam)
    if a >= 1.0:
        m = tab[_MU_N]
    else:
        z = a * _MU_N
        i = int(z)
        fr = z - i
        m = tab[i] + fr * (tab[i + 1] - tab[i])
    return m if lam >= 0.0 else -m


@njit(cache=True)
def _slip_nb(ww, wv):
    if wv > _WV_EPS:
        return (wv - ww) / wv
    return 0.0


@njit(cache=True)
def _rhs_nb(x, F_p, u_in, u_out, p, tab, out):
    """Eq. (19) without noise, one run: writes dx/dt into ``out`` (6,). Mirrors ABSPlant.f."""
    m = _mu_nb(_slip_nb(x[0], x[1]), tab)
    out[0] = (p[_RW] * p[_NV] * m - x[2]) / p[_IW]
    out[1] = -4.0 * p[_NV] * m / (p[_RW] * p[_MV])
    out[2] = x[3]
    wn = p[_WN]
    out[3] = wn * wn * (p[_KF] * x[4] - 2.0 * p[_ZETA] * x[3] / wn - x[2])
    c = p[_BETA] / p[_VS] * p[_A0]
    d_in = x[5] - x[4]
    d_out = x[4] - p[_PLP]
    q_in = p[_CIN] * u_in * math.copysign(math.sqrt(2e6 * abs(d_in) / p[_RHO]), d_in)
    q_out = p[_COUT] * u_out * math.copysign(math.sqrt(2e6 * abs(d_out) / p[_RHO]), d_out)
    out[4] = c * (q_in - q_out)
    out[5] = p[_KM] * F_p * 1e-3 / (p[_AM] * p[_TAUM]) - x[5] / p[_TAUM]


@njit(cache=True)
def _rhs_batch(x, u, P, tab):
    """Vectorised-over-runs wrapper of :func:`_rhs_nb` (for tests): x (runs,6), u (runs,3)."""
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        _rhs_nb(x[i], u[i, 0], u[i, 1], u[i, 2], P[i], tab, out[i])
    return out


@njit(cache=True)
def _area_open(e, p):
    return 0.5 + 0.5 * math.tanh((e - p[_TOPD]) / p[_TOPR])  # eq. (8), normalised by A_0


@njit(cache=True)
def _area_close(e, p):
    return 0.5 - 0.5 * math.tanh((e - p[_TCLD]) / p[_TCLR])  # eq. (9), normalised by A_0


@njit(cache=True)
def _clip01(a):
    return min(max(a, 1e-15), 1.0 - 1e-15)


@njit(cache=True)
def _orifice_step(P, P_up, k, dt):
    """Exact step of dP/dt = k sign(P_up - P) sqrt|P_up - P| over dt (k >= 0 frozen)."""
    d = P_up - P
    r = math.sqrt(abs(d)) - 0.5 * k * dt
    if r <= 0.0:
        return P_up
    return P_up - math.copysign(r * r, d)


@njit(cache=True)
def _run_one(p, x0, s, q_std, r_std, dt, n_steps, sub, t_brake, v_off, stride, tab,
             y, uv, xs, ev, nsw, swt, noise, nhold, ramp):
    x = x0.copy()
    wk = np.zeros(6)  # process-noise sample w_k, held over nhold steps
    dx = np.empty(6)
    nx = xs.shape[0]
    max_ev = swt.shape[1]
    ts = p[_TS]
    # valve state: the inlet valve starts open (base position), the outlet valve closed
    cmd_in, cmd_out = True, False
    e_in, e_out = 1e3, 1e3  # elapsed time in the current open/close law, s
    duty_in, duty_out = 1.0, 0.0
    lam = _slip_nb(x[0], x[1])
    e_prev = p[_LAMS] - lam
    t_on = np.nan
    t_off = np.nan
    t_stop = np.nan
    dist = 0.0
    slip_sum = 0.0
    slip_n = 0
    stopped = False
    j = 0
    jx = 0
    korf = math.sqrt(2e6 / p[_RHO]) * p[_BETA] / p[_VS] * p[_A0]
    for k in range(n_steps):
        t = k * dt
        if k % sub == 0:  # diagnostic sample y(t_k), eq. (19)
            v1 = 0.0
            v2 = 0.0
            if noise:
                v1, v2 = _normal_pair(s)
            y[j, 0] = p[_KWS] * x[0] + r_std[0] * v1
            y[j, 1] = x[1] + r_std[1] * v2
            uv[j, 0] = 0.0
            uv[j, 1] = 0.0
            j += 1
        if nx > 0 and k % stride == 0:
            for i in range(6):
                xs[jx, i] = x[i]
            jx += 1
        braking = t >= t_brake
        if not braking:
            F_p = 0.0
        elif ramp > 0.0:  # opt-in ramp profile (Scenario.pedal = "ramp"), see PARAMS["tau_p"]
            F_p = p[_KP] * min((t - t_brake) / ramp, 1.0)
        else:
            F_p = p[_KP] * (1.0 - math.exp(-(t - t_brake) / p[_TAUP]))  # eq. (4)
        lam = _slip_nb(x[0], x[1])
        # sliding-mode PWM controller, eqs. (1)-(3); backward difference for de/dt
        e = p[_LAMS] - lam
        edot = (e - e_prev) / ts
        e_prev = e
        abs_enabled = braking and (not stopped) and p[_RW] * x[1] > v_off
        if abs_enabled:
            S = e + p[_ALPHA] * edot
            if S >= p[_PHI]:
                sat = 1.0
            elif S <= -p[_PHI]:
                sat = -1.0
            else:
                sat = S / p[_PHI]
        else:
            sat = 1.0
            if braking and not np.isnan(t_on) and np.isnan(t_off):
                t_off = t
        if abs_enabled and not np.isnan(t_on):
            slip_sum += lam
            slip_n += 1
        # valves: commands, switching times, effective areas (eqs. (8)-(9))
        want_in = sat > 0.0
        want_out = sat < 0.0
        if want_in != cmd_in:
            a = _area_open(e_in, p) if cmd_in else _area_close(e_in, p)
            a = _clip01(a)
            if want_in:
                e_in = max(p[_TOPD] + p[_TOPR] * math.atanh(2.0 * a - 1.0), 0.0)
            else:
                e_in = max(p[_TCLD] + p[_TCLR] * math.atanh(1.0 - 2.0 * a), 0.0)
            cmd_in = want_in
            if nsw[0] < max_ev:
                swt[0, nsw[0]] = t
            nsw[0] += 1
        if want_out != cmd_out:
            a = _area_open(e_out, p) if cmd_out else _area_close(e_out, p)
            a = _clip01(a)
            if want_out:
                e_out = max(p[_TOPD] + p[_TOPR] * math.atanh(2.0 * a - 1.0), 0.0)
            else:
                e_out = max(p[_TCLD] + p[_TCLR] * math.atanh(1.0 - 2.0 * a), 0.0)
            cmd_out = want_out
            if want_out and np.isnan(t_on):
                t_on = t  # ABS engages: first pressure release
            if nsw[1] < max_ev:
                swt[1, nsw[1]] = t
            nsw[1] += 1
        if cmd_in:
            duty_in = sat
        if cmd_out:
            duty_out = -sat
        a_in = _area_open(e_in, p) if cmd_in else _area_close(e_in, p)
        a_out = _area_open(e_out, p) if cmd_out else _area_close(e_out, p)
        u_in = duty_in * a_in
        u_out = duty_out * a_out
        uv[j - 1, 0] += u_in / sub  # mean valve openings over the sample interval
        uv[j - 1, 1] += u_out / sub
        e_in += dt
        e_out += dt
        # dynamics: Euler(-Maruyama) for x1-x4, x6; exact orifice steps for x5
        _rhs_nb(x, F_p, u_in, u_out, p, tab, dx)
        if braking and not stopped:
            dist += p[_RW] * x[1] * dt
        p5 = _orifice_step(x[4], x[5], korf * p[_CIN] * u_in, dt)
        p5 = _orifice_step(p5, p[_PLP], korf * p[_COUT] * u_out, dt)
        for i in range(6):
            if i != 4:
                x[i] += dt * dx[i]
        x[4] = p5
        if noise:
            if k % nhold == 0:  # a new process-noise sample every nhold steps, held in between
                wk[0], wk[1] = _normal_pair(s)
                wk[2], wk[3] = _normal_pair(s)
                wk[4], wk[5] = _normal_pair(s)
            if not stopped:
                x[0] += dt * q_std[0] * wk[0]
                x[1] += dt * q_std[1] * wk[1]
            x[2] += dt * q_std[2] * wk[2]
            x[3] += dt * q_std[3] * wk[3]
            x[4] += dt * q_std[4] * wk[4]
            x[5] += dt * q_std[5] * wk[5]
        if stopped or x[1] <= 0.0:
            if not stopped:
                t_stop = t + dt
                stopped = True
            x[0] = 0.0
            x[1] = 0.0
        if x[0] < 0.0:
            x[0] = 0.0  # the brake does not turn the wheel backwards
    ev[0] = t_on
    ev[1] = t_off
    ev[2] = t_stop
    ev[3] = dist
    ev[4] = slip_sum / slip_n if slip_n > 0 else np.nan
    ev[5] = slip_n


@njit(cache=True, parallel=True)
def _mc_kernel(P, X0, S, q_std, r_std, dt, n_steps, sub, t_brake, v_off, stride, tab,
               y, uv, xs, ev, nsw, swt, noise, nhold, ramp):
    for i in prange(P.shape[0]):
        s = S[i].copy()
        _run_one(P[i], X0[i], s, q_std, r_std, dt, n_steps, sub, t_brake, v_off, stride, tab,
                 y[i], uv[i], xs[i], ev[i], nsw[i], swt[i], noise, nhold, ramp)


# --------------------------------------------------------------------------------------------
# Public simulation API
# --------------------------------------------------------------------------------------------
@dataclass
class ABSResult:
    """Output of :func:`simulate`.

    Attributes
    ----------
    y : Signals
        Measurements ``omega_w``, ``omega_v`` (rad/s), values (runs, N, 2) at 10 ms.
    u : Signals
        Known inputs, values (runs, N, 3): ``P_m`` (MPa), the master-cylinder pressure of the
        *nominal* pedal/master-cylinder model (4)-(5) (luo-et-al, Section V-B: "P_m generated by
        (4) and (5)"; a tau_m fault (F5) changes the true pressure, not this input), and
        ``u_in``, ``u_out``: the ECU's inlet/outlet valve openings (PWM duty times A_eff/A_0,
        the ``u_in``/``u_out`` inputs of :class:`ABSPlant`) averaged over each sample interval
        ``[t_k, t_k + 10 ms)``, for integrating x5 as in eq. (26) or the observer (32).
    x : Signals or None
        True states (runs, T_x, 6) every ``state_stride`` steps when ``keep_states``.
    magnitudes : ndarray (runs,)
        Relative fault magnitude of each run.
    fault_param : str or None
        Name of the faulted parameter; ``params`` holds its per-run value.
    params : dict
        Per-run parameter values ``(runs,)`` of the faulted parameter and every parameter as
        float otherwise.
    events : dict of ndarray (runs,)
        ``t_abs_on`` (first pressure release, s; NaN if ABS never engaged), ``t_abs_off``
        (ABS switched off at v_off), ``t_stop`` (car at rest, s; NaN if still moving),
        ``stop_distance`` (m travelled after t_brake), ``mean_slip`` (mean true slip while ABS
        active), ``n_switch_in``, ``n_switch_out`` (valve command changes) and, when asked
        for, ``switch_times_in``/``switch_times_out`` (runs, max_switch_events), NaN padded.
    process_noise_var : ndarray (6,)
        Variance of w1..w6 used (0 when no process noise).
    state_mean_square : ndarray (6,)
        Mean-square values of the states from the nominal noise-free run (SNR reference).
    """

    y: Signals
    u: Signals
    x: Signals | None
    magnitudes: np.ndarray
    fault_param: str | None
    params: dict[str, Any]
    events: dict[str, np.ndarray]
    scenario: Scenario
    process_noise_var: np.ndarray
    state_mean_square: np.ndarray
    run_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


def _seed_states(seed: int, run_ids: np.ndarray) -> np.ndarray:
    out = np.empty((run_ids.size, 4), dtype=np.uint64)
    for j, i in enumerate(run_ids):
        st = np.random.SeedSequence(seed, spawn_key=(int(i), 0)).generate_state(4, np.uint64)
        if not st.any():  # xoshiro's forbidden all-zero state (probability 2^-256)
            st[0] = 1
        out[j] = st
    return out


def _magnitudes(sc: Scenario, seed: int, run_ids: np.ndarray) -> np.ndarray:
    fc = FAULT_CLASSES[sc.fault]
    if sc.magnitude is not None:
        return np.full(run_ids.size, float(sc.magnitude))
    return np.array([fc.draw(np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(i), 1))),
                             sc.grid_step) for i in run_ids])


def _nominal_pm(plant: ABSPlant, sc: Scenario) -> np.ndarray:
    """Master-cylinder pressure of the nominal model (4)-(5), same Euler scheme, at every step."""
    from scipy.signal import lfilter

    p = plant.params
    t = np.arange(sc.n_steps + 1) * sc.dt
    F_p = plant.pedal_force(t, sc.t_brake, sc.pedal_ramp if sc.pedal == "ramp" else None)
    a = 1.0 - sc.dt / p["tau_m"]
    b = sc.dt * p["K_m"] * 1e-3 / (p["A_m"] * p["tau_m"])
    return lfilter([0.0, b], [1.0, -a], F_p)


def _run_kernel(plant, sc, P, X0, S, q_std, r_std, keep_states, stride, max_ev, noise):
    runs = P.shape[0]
    n_x = (sc.n_steps + stride - 1) // stride if keep_states else 0
    y = np.empty((runs, sc.n_samples, 2))
    uv = np.empty((runs, sc.n_samples, 2))
    xs = np.empty((runs, n_x, 6))
    ev = np.empty((runs, 6))
    nsw = np.zeros((runs, 2), dtype=np.int64)
    swt = np.full((runs, 2, max_ev), np.nan)
    _mc_kernel(P, X0, S, q_std, r_std, sc.dt, sc.n_steps, sc.substeps, sc.t_brake, sc.v_off, stride,
               _MU_TAB, y, uv, xs, ev, nsw, swt, noise, sc.noise_hold_steps, sc.ramp_time)
    return y, uv, xs, ev, nsw, swt


def state_mean_square(plant: ABSPlant, scenario: Scenario) -> np.ndarray:
    """Mean-square value of each state over the nominal noise-free run of ``scenario``'s manoeuvre.

    The reference for the process-noise SNR: every 1 ms step of the whole record, F0, no noise.

    Returns
    -------
    ndarray (6,)
    """
    key = (tuple(plant.params.values()), scenario.v0, scenario.t_brake, scenario.t_end, scenario.dt,
           scenario.v_off, scenario.ramp_time)
    if key not in plant._ms_cache:
        sc = replace(scenario, fault="F0", magnitude=None, snr_db=None, meas_var=0.0)
        P = plant.param_matrix(1)
        w0 = sc.v0 / plant.params["R_w"]
        X0 = np.array([[w0, w0, 0.0, 0.0, 0.0, 0.0]])
        _, _, xs, _, _, _ = _run_kernel(plant, sc, P, X0, np.ones((1, 4), np.uint64), np.zeros(6),
                                     np.zeros(2), True, 1, 0, False)
        plant._ms_cache[key] = np.mean(xs[0] ** 2, axis=0)
    return plant._ms_cache[key]


def simulate(
    plant: ABSPlant | None,
    scenario: Scenario,
    runs: int = 1,
    seed: int = 0,
    *,
    first_run: int = 0,
    keep_states: bool = False,
    state_stride: int = 10,
    max_switch_events: int = 0,
) -> ABSResult:
    """Monte Carlo simulation of the closed-loop ABS, all runs at once (numba, parallel over runs).

    Parameters
    ----------
    plant : ABSPlant or None
        The plant (nominal parameters); None for ``ABSPlant()``.
    scenario : Scenario
        Manoeuvre, fault class/magnitude and noise.
    runs : int
        Number of runs.
    seed : int
        Master seed; run ``i`` (global index ``first_run + j``) uses streams derived from
        ``SeedSequence(seed, spawn_key=(i, ...))`` and is the same whatever the batch.
    first_run : int
        Global index of the first run (to simulate a slice of a campaign).
    keep_states : bool
        Also return the true states every ``state_stride`` steps of 1 ms (memory:
        runs · n_steps/state_stride · 48 bytes).
    state_stride : int
        Decimation of the returned true states (10: the 10 ms diagnostic grid).
    max_switch_events : int
        Record up to this many valve switching times per valve and run.

    Returns
    -------
    ABSResult

    Examples
    --------
    >>> from fdikit.systems.abs.plant import Scenario, simulate
    >>> res = simulate(None, Scenario(fault="F3", magnitude=-0.05, t_end=2.0, v0=10.0), runs=2, seed=1)
    >>> res.y.values.shape, res.u.names, res.params["K_f"].tolist()
    ((2, 200, 2), ['P_m', 'u_in', 'u_out'], [95.0, 95.0])
    """
    plant = plant if plant is not None else ABSPlant()
    if runs < 1:
        raise DataError(f"runs must be >= 1, got {runs}")
    if state_stride < 1:
        raise DataError(f"state_stride must be >= 1, got {state_stride}")
    sc = scenario
    run_ids = np.arange(first_run, first_run + runs)
    fc = FAULT_CLASSES[sc.fault]
    mags = _magnitudes(sc, seed, run_ids)
    P = plant.param_matrix(runs)
    params: dict[str, Any] = dict(plant.params)
    if fc.param is not None:
        P[:, _PI[fc.param]] *= 1.0 + mags
        params[fc.param] = P[:, _PI[fc.param]].copy()
    R_w = P[:, _RW]
    w0 = sc.v0 / R_w  # the car rolls freely at v0: omega_w = omega_v = v0 / R_w (true radius)
    X0 = np.zeros((runs, 6))
    X0[:, 0] = w0
    X0[:, 1] = w0
    if sc.snr_db is not None:
        ms = state_mean_square(plant, sc)
        qvar = ms * 10.0 ** (-sc.snr_db / 10.0)
    else:
        ms = state_mean_square(plant, sc)
        qvar = np.zeros(6)
    noise = bool(sc.snr_db is not None or sc.meas_var > 0)
    S = _seed_states(seed, run_ids)
    y, uv, xs, ev, nsw, swt = _run_kernel(plant, sc, P, X0, S, np.sqrt(qvar),
                                      np.full(2, math.sqrt(sc.meas_var)), keep_states, state_stride,
                                      int(max_switch_events), noise)
    t = np.arange(sc.n_samples) * sc.sample_dt
    ysig = Signals(t, y, OUTPUTS, ["rad/s", "rad/s"])  # checks for NaN/inf (names run and sample)
    pm = _nominal_pm(plant, sc)[:: sc.substeps][: sc.n_samples]
    uval = np.empty((runs, sc.n_samples, 3))
    uval[:, :, 0] = pm[None, :]
    uval[:, :, 1:] = uv
    usig = Signals(t, uval, ["P_m", "u_in", "u_out"], ["MPa", "", ""])
    xsig = None
    if keep_states:
        tx = np.arange(xs.shape[1]) * sc.dt * state_stride
        xsig = Signals(tx, xs, STATES, STATE_UNITS)
    events = {
        "t_abs_on": ev[:, 0], "t_abs_off": ev[:, 1], "t_stop": ev[:, 2], "stop_distance": ev[:, 3],
        "mean_slip": ev[:, 4], "n_switch_in": nsw[:, 0], "n_switch_out": nsw[:, 1],
    }
    if max_switch_events > 0:
        events["switch_times_in"] = swt[:, 0]
        events["switch_times_out"] = swt[:, 1]
    return ABSResult(ysig, usig, xsig, mags, fc.param, params, events, sc, qvar, ms, run_ids)


def summarize(res: ABSResult) -> dict[str, Any]:
    """Summary figures of a simulation (means over runs), as printed by ``fdikit abs simulate``.

    Returns
    -------
    dict
        ``runs``, ``samples``, ``fault``, ``magnitude_mean``, ``v0``, ``stopping_time`` (s from
        t_brake to rest; NaN if not stopped), ``stopping_distance`` (m), ``abs_engaged_at`` (s),
        ``mean_slip_abs`` (mean slip while the ABS is active), ``valve_switches``,
        ``stopped_fraction``.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import Scenario, simulate, summarize
    >>> s = summarize(simulate(None, Scenario(t_end=1.0, v0=5.0, snr_db=None, meas_var=0.0)))
    >>> s["samples"], s["runs"]
    (100, 1)
    """
    ev = res.events
    sc = res.scenario

    def _m(a):
        a = np.asarray(a, float)
        return float(np.nanmean(a)) if np.isfinite(a).any() else float("nan")

    return {
        "fault": sc.fault,
        "magnitude_mean": float(np.mean(res.magnitudes)),
        "runs": int(res.y.runs),
        "samples": int(res.y.n_samples),
        "sample_dt": sc.sample_dt,
        "v0": sc.v0,
        "t_brake": sc.t_brake,
        "stopping_time": _m(ev["t_stop"] - sc.t_brake),
        "stopping_distance": _m(ev["stop_distance"]),
        "abs_engaged_at": _m(ev["t_abs_on"]),
        "mean_slip_abs": _m(ev["mean_slip"]),
        "valve_switches": _m(ev["n_switch_in"] + ev["n_switch_out"]),
        "stopped_fraction": float(np.mean(np.isfinite(ev["t_stop"]))),
        "snr_db": sc.snr_db,
        "meas_var": sc.meas_var,
        "noise_hold": sc.noise_hold,
        "pedal": sc.pedal,
        "pedal_ramp": sc.pedal_ramp,
    }


def demo_summary(details: dict | None = None) -> dict[str, Any]:
    """A single short ABS stop (15 m/s, 8 s record, one noisy run) for ``fdikit demo``.

    ``details``, when given, receives ``result``: the :class:`ABSResult` of the stop, with its true
    states (``keep_states``), for the demo's report.

    Returns
    -------
    dict
        :func:`summarize` of the run.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import demo_summary
    >>> d = demo_summary()
    >>> d["stopped_fraction"], 0.1 < d["mean_slip_abs"] < 0.3
    (1.0, True)
    """
    sc = Scenario(v0=15.0, t_brake=0.2, t_end=8.0)
    res = simulate(None, sc, runs=1, seed=0, keep_states=details is not None)
    if details is not None:
        details["result"] = res
    return summarize(res)


def fault_scenarios(snr_db: float | None = 23.0, **kw) -> dict[str, Scenario]:
    """One :class:`Scenario` per fault class (magnitudes drawn per run), keyed by class name.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import fault_scenarios
    >>> list(fault_scenarios())[:3]
    ['F0', 'F1.1', 'F1.2']
    """
    return {name: Scenario(fault=name, snr_db=snr_db, **kw) for name in FAULT_CLASSES}
