"""The numba closed-loop kernel: eq. (19)'s vector field, the sliding-mode PWM controller, the valve
switching, Euler-Maruyama integration and noise, one run per thread (parallel over runs).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .params import (
    _A0,
    _ALPHA,
    _AM,
    _BETA,
    _CIN,
    _COUT,
    _IW,
    _KF,
    _KM,
    _KP,
    _KWS,
    _LAMS,
    _MV,
    _NV,
    _PHI,
    _PLP,
    _RHO,
    _RW,
    _TAUM,
    _TAUP,
    _TCLD,
    _TCLR,
    _TOPD,
    _TOPR,
    _TS,
    _VS,
    _WN,
    _ZETA,
)
from .rng import _normal_pair
from .tyre import _mu_nb, _slip_nb
from .valves import _area_close, _area_open, _clip01, _orifice_step


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
