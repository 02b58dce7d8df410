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

Layout, one module per concept: :mod:`.params` (Table I and the names), :mod:`.tyre` (friction
and slip), :mod:`.model` (:class:`ABSPlant`), :mod:`.faults` (fault classes and
:class:`Scenario`), the numba kernel in :mod:`.rng` (random numbers), :mod:`.valves` (valve laws,
orifice step) and :mod:`.kernel` (controller and closed loop), and :mod:`.simulation`
(:func:`simulate`, :class:`ABSResult`, summaries).
"""

from .faults import FAULT_CLASSES, FaultClass, Scenario
from .kernel import _rhs_batch as _rhs_batch  # used by the tests
from .model import ABSPlant
from .params import INPUTS, OUTPUTS, PARAMS, STATES
from .params import PARAM_NAMES as PARAM_NAMES
from .params import PARAM_UNITS as PARAM_UNITS
from .params import STATE_UNITS as STATE_UNITS
from .params import G as G
from .simulation import ABSResult, demo_summary, fault_scenarios, simulate, state_mean_square, summarize
from .simulation import _run_kernel as _run_kernel  # estimation.ABSSimulator runs the kernel directly
from .tyre import _MU_TAB as _MU_TAB  # used by the tests
from .tyre import MU_SLIP, MU_TABLE, mu, slip

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
