"""Tyre-road friction (dry-asphalt Burckhardt table) and wheel slip, in numpy and for the numba kernel."""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

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


_MU_TAB = MU_TABLE.copy()


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
