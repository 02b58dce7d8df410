"""The hydraulic modulator's valves for the numba kernel: opening and closing laws (eqs. (8)-(9))
and the exact orifice step of the wheel-cylinder pressure.
"""

from __future__ import annotations

import math

from numba import njit

from .params import _TCLD, _TCLR, _TOPD, _TOPR


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
