"""The ABS plant of luo-et-al, eq. (19), as a :class:`~fdikit.model.NonlinearModel` (numpy, over runs)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ....errors import DataError, ModelError
from ....model.nonlinear import NonlinearModel
from .params import _PI, INPUTS, OUTPUTS, PARAM_NAMES, PARAM_UNITS, PARAMS, STATE_UNITS, STATES
from .tyre import mu, slip


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
