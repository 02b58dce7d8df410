"""Residual generators of the ABS benchmark (luo-et-al, Section V): parity residuals r1, r2
and the nonlinear Luenberger observer residuals r3, r4.

All three generators read the plant's 10 ms measurements ``omega_w``, ``omega_v`` (rad/s) and,
where needed, the known inputs ``P_m`` (MPa, nominal master-cylinder pressure), ``u_in`` and
``u_out`` (the ECU's mean valve openings over ``[t_k, t_k + 10 ms)``) of
:func:`fdikit.systems.abs.plant.simulate`; each has a vectorised batch :meth:`run` and a streaming
:meth:`step` that agree (a test proves it).

* :class:`ParityR1` -- eq. (25): ``r1 = dy2/dt + 4 N_v mu(lambda(y)) / (R_w M_v)`` (rad/s^2) on
  low-passed measurements (10th-order Butterworth, 10 Hz) with a smoothing-spline derivative.
  ``variant="causal"`` is online (streaming) capable; ``"zero_phase"`` is offline only.
  Eq. (25) contains neither K_f nor I_w, so faults F3/F4 do not enter r1 except through the
  operating point.
* :class:`ParityR2` -- eq. (26): ``r2 = x3'' - w_n^2 K_f x5 + 2 zeta w_n x3' + w_n^2 x3`` with
  ``x3 = R_w N_v mu(lambda) - I_w dy1/dt`` (eq. (19), x1 row; the paper prints the sign of
  ``R_w N_v mu`` wrongly) and ``x5`` integrated from the valve openings and ``P_m`` from zero.
  It needs the third derivative of the wheel speed; :func:`r2_magnitude_study` shows with
  numbers why the paper dropped it.
* :class:`ABSObserver` -- eqs. (29)-(33): a Luenberger observer on x1..x5 with P_m as input and
  sample-and-hold measurements, integrated at 1 ms (the plant's own Euler scheme, with the
  exact orifice step for x5), residuals ``r3 = y1 - x1_hat`` and ``r4 = y2 - x2_hat`` at each
  sample before the correction over the next interval. The output injection is eq. (32)'s
  ``L (y^h - x_hat^h)`` with the estimate held as well as the measurement (without that hold
  the nominal noise-free residuals carried a deterministic bias of ``-s dt/2`` for a speed
  falling at ``s`` rad/s^2, larger than the faults of Table II's minimum sizes). The gain comes from
  :func:`observer_gain` (steady-state Kalman-Bucy gain of the linear part A of eq. (30), the
  documented method; or pole placement).
* :func:`observer_sensitivity` -- the observer with twins on perturbed models
  (:class:`~fdikit.residuals.sensitivity.ParameterSensitivity`): r3, r4 and their signatures for
  small changes of named plant parameters, for the directional tests of
  :class:`fdikit.detect.DirectionalGLRT` (an I_w change of 2 % leaves the mean of r3 unchanged,
  its signature flips sign with every slip cycle, but its evidence summed over a stop is
  about 5 standard deviations at 23 dB).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numba import njit, prange

from ...base.stage import ResidualGenerator
from ...errors import ConditionError, DataError
from ...residuals.parity import (
    CausalDerivative,
    CausalLowPass,
    butter_sos,
    causal_spline_derivative,
    lowpass,
    spline_derivative,
    spline_lam,
)
from ...signals import Signals, check_finite

__all__ = [
    "ABSObserver",
    "ParityR1",
    "ParityR2",
    "linear_part",
    "observer_gain",
    "observer_sensitivity",
    "r2_magnitude_study",
]

_Y = ["omega_w", "omega_v"]
_U = ["P_m", "u_in", "u_out"]


def _params(params: Mapping[str, float] | None) -> dict[str, float]:
    from .plant import PARAMS

    p = dict(PARAMS)
    for k, v in (params or {}).items():
        if k not in p:
            raise DataError(f"unknown ABS parameter {k!r}")
        p[k] = float(v)
    return p


def _dt_of(signals: Signals) -> float:
    if signals.n_samples < 2:
        raise DataError("need at least 2 samples to know the sample interval")
    d = np.diff(signals.t)
    if np.ptp(d) > 1e-9 * max(1.0, abs(d[0])):
        raise DataError(f"samples must be uniformly spaced (dt from {d.min()} to {d.max()} s)")
    return float(d[0])


def _mu_term(y1, y2, p):
    """``4 N_v mu(lambda) / (R_w M_v)`` (rad/s^2) from wheel and vehicle speeds (eqs. (13)-(16))."""
    from .plant import mu, slip

    return 4.0 * p["N_v"] * mu(slip(y1, y2)) / (p["R_w"] * p["M_v"])


# --------------------------------------------------------------------------------------------
# Parity residual r1, eq. (25)
# --------------------------------------------------------------------------------------------
class ParityR1(ResidualGenerator):
    """Parity residual r1 of luo-et-al, eq. (25), in rad/s^2.

    Parameters
    ----------
    dt : float
        Sample interval of the measurements, s (0.01 for the ABS plant).
    params : mapping, optional
        Nominal plant parameters (defaults: :data:`fdikit.systems.abs.plant.PARAMS`).
    variant : {"causal", "zero_phase"}
        ``"causal"`` (online, streaming capable): causal Butterworth ``sosfilt`` and the
        causal sliding-window spline derivative. ``"zero_phase"`` (offline only): ``sosfiltfilt``
        and one smoothing spline over the whole record; :meth:`step` raises.
    order, cutoff_hz : int, float
        Butterworth low-pass (10th order, 10 Hz in the paper).
    window : int
        Sliding window of the causal spline derivative, samples (25 = 0.25 s).
    spline_cutoff_hz : float
        Half-power frequency of the smoothing spline (:func:`~fdikit.residuals.parity.spline_lam`).
    v_min : float
        Validity limit, m/s: where the filtered vehicle speed ``R_w y2`` is below it, r1 is set
        to 0 (its nominal value). Near standstill the slip ``(v - w)/v`` is ill-conditioned and
        the ABS is off (below 2 m/s the wheel locks), so eq. (25) is not a usable consistency
        check there: in 12.5 s records ending at rest, this region alone made the nominal r1
        variance 5 times larger than while braking (measured: std 3.9 vs 0.43 rad/s^2).

    Examples
    --------
    >>> import numpy as np
    >>> from fdikit import Signals
    >>> t = np.arange(200) * 0.01
    >>> y = np.stack([np.full(200, 80.0), np.full(200, 80.0)], axis=-1)   # rolling, no slip
    >>> r = ParityR1(0.01).run(Signals(t, y, ["omega_w", "omega_v"]))
    >>> float(np.abs(r["r1"]).max()) < 1e-9
    True
    """

    def __init__(self, dt: float, params: Mapping[str, float] | None = None, *, variant: str = "causal",
                 order: int = 10, cutoff_hz: float = 10.0, window: int = 25, spline_cutoff_hz: float = 3.0,
                 v_min: float = 3.0):
        if variant not in ("causal", "zero_phase"):
            raise DataError(f"variant must be 'causal' or 'zero_phase', got {variant!r}")
        if dt <= 0:
            raise DataError(f"sample interval dt must be positive, got {dt}")
        self.dt = float(dt)
        self.p = _params(params)
        self.variant = variant
        self.v_min = float(v_min)
        self.order, self.cutoff_hz = int(order), float(cutoff_hz)
        self.spline_cutoff_hz = float(spline_cutoff_hz)
        self.sos = butter_sos(order, cutoff_hz, 1.0 / self.dt)
        self.window = int(window)
        self.lam = spline_lam(spline_cutoff_hz, self.dt)
        self.u_names: list[str] = []
        self.y_names = list(_Y)
        self.output_names = ["r1"]
        self.output_units = ["rad/s^2"]
        self._lp = CausalLowPass(self.sos)
        self._der = CausalDerivative(self.window, self.dt, self.lam, 1)
        self.reset(1)

    _state_attrs = ("_lp", "_der")

    def to_dict(self) -> dict:
        """The design as plain data (a design artifact, :mod:`fdikit.base.artifacts`).

        The constructor's arguments, the nominal parameters and the Butterworth sections
        ``sos`` (ceil(order/2), 6), which the loaded design uses as saved.
        """
        return {"dt": self.dt, "params": dict(self.p), "variant": self.variant, "order": self.order,
                "cutoff_hz": self.cutoff_hz, "window": self.window,
                "spline_cutoff_hz": self.spline_cutoff_hz, "v_min": self.v_min, "sos": self.sos.copy()}

    @classmethod
    def from_dict(cls, d: Mapping) -> ParityR1:
        """Rebuild from :meth:`to_dict`; the stored ``sos`` is used as saved."""
        g = cls(d["dt"], d["params"], variant=d["variant"], order=d["order"], cutoff_hz=d["cutoff_hz"],
                window=d["window"], spline_cutoff_hz=d["spline_cutoff_hz"], v_min=d["v_min"])
        if "sos" in d:
            sos = np.asarray(d["sos"], float)
            if sos.shape != g.sos.shape:
                raise DataError(f"r1 design: stored Butterworth sections have shape {sos.shape}, order "
                                f"{g.order} needs {g.sos.shape}")
            g.sos = sos
            g._lp = CausalLowPass(sos)
            g.reset(1)
        return g

    def reset(self, runs: int = 1) -> None:
        self._lp.reset(runs, 2)
        self._der.reset(runs, 1)

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        if self.variant != "causal":
            raise DataError("the zero-phase r1 needs the whole record (offline only): use run()")
        check_finite(y[:, None, :], self.y_names, what="r1 measurement")
        yf = self._lp.step(y)
        d2 = self._der.step(yf[:, 1:2])
        return self._r1(d2[:, 0], yf[:, 0], yf[:, 1])[:, None]

    def _r1(self, dy2, y1f, y2f):
        r1 = dy2 + _mu_term(y1f, y2f, self.p)  # luo-et-al, eq. (25)
        return np.where(self.p["R_w"] * y2f >= self.v_min, r1, 0.0)

    def run(self, signals: Signals) -> Signals:
        _, y = self._inputs(signals)
        check_finite(y, self.y_names, what="r1 measurement")
        if self.variant == "causal":
            if signals.n_samples < self.window:
                raise DataError(f"record of {signals.n_samples} samples is shorter than the r1 "
                                f"derivative window ({self.window})")
            yf = lowpass(y, self.sos, axis=1)
            d2 = causal_spline_derivative(yf[:, :, 1], self.dt, window=self.window, lam=self.lam, axis=1)
        else:
            yf = lowpass(y, self.sos, axis=1, zero_phase=True)
            d2 = spline_derivative(yf[:, :, 1], self.dt, lam=self.lam, axis=1)
        r1 = self._r1(d2, yf[:, :, 0], yf[:, :, 1])
        self.reset(signals.runs)
        return Signals(signals.t, r1[:, :, None], self.output_names, self.output_units, check=False)


# --------------------------------------------------------------------------------------------
# numba helpers shared by r2 (x5 reconstruction) and the observer
# --------------------------------------------------------------------------------------------
_NP = 15  # packed parameter vector
(_RW, _NV, _MV, _IW, _KF, _WN, _ZETA, _CIN, _COUT, _PLP, _KORF, _SUB, _H, _EPS, _HELD) = range(_NP)


def _pack(p: Mapping[str, float], dt_sample: float, substeps: int, held: bool = True) -> np.ndarray:
    korf = math.sqrt(2e6 / p["rho"]) * p["beta_s"] / p["V_s"] * p["A_0"]  # orifice law, MPa units
    return np.array([p["R_w"], p["N_v"], p["M_v"], p["I_w"], p["K_f"], p["omega_n"], p["zeta"],
                     p["C_in"], p["C_out"], p["P_lp"], korf, substeps, dt_sample / substeps, 1e-6,
                     1.0 if held else 0.0])


@njit(cache=True)
def _mu_nb(lam, tab):  # pragma: no cover - compiled; same table and interpolation as the plant
    n = tab.shape[0] - 1
    a = abs(lam)
    if a >= 1.0:
        m = tab[n]
    else:
        z = a * n
        i = int(z)
        m = tab[i] + (z - i) * (tab[i + 1] - tab[i])
    return m if lam >= 0.0 else -m


@njit(cache=True)
def _orifice(P, P_up, k, h):  # pragma: no cover - compiled
    """Exact step of dP/dt = k sign(P_up - P) sqrt|P_up - P| over h (k >= 0 held)."""
    d = P_up - P
    r = math.sqrt(abs(d)) - 0.5 * k * h
    if r <= 0.0:
        return P_up
    return P_up - math.copysign(r * r, d)


@njit(cache=True)
def _x5_advance(x5, pm, uin, uout, q):  # pragma: no cover - compiled
    """x5 (P_s) over one sample interval, eq. (19) x5 row without noise (inflow, then outflow)."""
    h = q[_H]
    for _ in range(int(q[_SUB])):
        x5 = _orifice(x5, pm, q[_KORF] * q[_CIN] * uin, h)
        x5 = _orifice(x5, q[_PLP], q[_KORF] * q[_COUT] * uout, h)
    return x5


@njit(cache=True)
def _x5_series(u, q, out):  # pragma: no cover - compiled
    """u (runs, T, 3) -> out (runs, T): x5 at each sample, from 0 (eq. (26) construction)."""
    R, T = out.shape
    for r in range(R):
        x5 = 0.0
        for k in range(T):
            out[r, k] = x5
            x5 = _x5_advance(x5, u[r, k, 0], u[r, k, 1], u[r, k, 2], q)


@njit(cache=True)
def _obs_sample(xh, y1, y2, pm, uin, uout, q, L, tab, r):  # pragma: no cover - compiled
    """Residuals at this sample (eq. (33)) into r (2,), then advance xh (5,) over one sample
    interval with held y, P_m and valve openings (eq. (32)). ``q[_HELD] = 1``: the output
    injection ``L (y^h - x_hat^h)`` of eq. (32) with both the measurement and the estimate held
    (constant ``L r_k`` over the interval); 0: ``L (y^h - x_hat(t))`` with the estimate running."""
    r[0] = y1 - xh[0]
    r[1] = y2 - xh[1]
    h = q[_H]
    wn = q[_WN]
    held = q[_HELD] > 0.5
    e1 = r[0]
    e2 = r[1]
    for _ in range(int(q[_SUB])):
        if not held:
            e1 = y1 - xh[0]
            e2 = y2 - xh[1]
        lam = (xh[1] - xh[0]) / xh[1] if xh[1] > q[_EPS] else 0.0
        m = _mu_nb(lam, tab)
        d0 = (q[_RW] * q[_NV] * m - xh[2]) / q[_IW] + L[0, 0] * e1 + L[0, 1] * e2  # eq. (30), x1
        d1 = -4.0 * q[_NV] * m / (q[_RW] * q[_MV]) + L[1, 0] * e1 + L[1, 1] * e2  # x2
        d2 = xh[3] + L[2, 0] * e1 + L[2, 1] * e2  # x3
        d3 = wn * wn * (q[_KF] * xh[4] - 2.0 * q[_ZETA] * xh[3] / wn - xh[2]) + L[3, 0] * e1 + L[3, 1] * e2
        x5 = _orifice(xh[4], pm, q[_KORF] * q[_CIN] * uin, h)  # x5: exact orifice steps
        x5 = _orifice(x5, q[_PLP], q[_KORF] * q[_COUT] * uout, h)
        xh[0] += h * d0
        xh[1] += h * d1
        xh[2] += h * d2
        xh[3] += h * d3
        xh[4] = x5 + h * (L[4, 0] * e1 + L[4, 1] * e2)
        if xh[0] < 0.0:
            xh[0] = 0.0
        if xh[1] < 0.0:
            xh[1] = 0.0


@njit(cache=True, parallel=True)
def _obs_batch(y, u, xh, q, L, tab, out):  # pragma: no cover - compiled
    """y (R, T, 2), u (R, T, 3), xh (R, 5) state (updated), out (R, T, 2)."""
    R, T = y.shape[0], y.shape[1]
    for i in prange(R):
        x = xh[i]
        r = np.empty(2)
        for k in range(T):
            _obs_sample(x, y[i, k, 0], y[i, k, 1], u[i, k, 0], u[i, k, 1], u[i, k, 2], q, L, tab, r)
            out[i, k, 0] = r[0]
            out[i, k, 1] = r[1]


@njit(cache=True)
def _obs_serial(y, u, xh, q, L, tab, out):  # pragma: no cover - compiled
    """As :func:`_obs_batch` without the thread launch (one streaming sample of one run: the
    launch cost ~20 ms a call on a loaded machine; the arithmetic is the same)."""
    for i in range(y.shape[0]):
        x = xh[i]
        r = np.empty(2)
        for k in range(y.shape[1]):
            _obs_sample(x, y[i, k, 0], y[i, k, 1], u[i, k, 0], u[i, k, 1], u[i, k, 2], q, L, tab, r)
            out[i, k, 0] = r[0]
            out[i, k, 1] = r[1]


# --------------------------------------------------------------------------------------------
# Parity residual r2, eq. (26)
# --------------------------------------------------------------------------------------------
class ParityR2(ResidualGenerator):
    """Parity residual r2 of luo-et-al, eq. (26), in N·m/s^2 (the paper drops it).

    ``x3 = R_w N_v mu(lambda) - I_w dy1/dt`` from the low-passed measurements; ``x3'``, ``x3''``
    by smoothing-spline derivatives of ``x3`` (so the wheel speed is differentiated three
    times); ``x5`` integrated from zero with the valve openings and ``P_m`` (exact orifice
    steps at ``substeps`` per sample). Same variants as :class:`ParityR1`.

    Examples
    --------
    >>> g = ParityR2(0.01)
    >>> g.u_names, g.output_names
    (['P_m', 'u_in', 'u_out'], ['r2'])
    """

    def __init__(self, dt: float, params: Mapping[str, float] | None = None, *, variant: str = "causal",
                 order: int = 10, cutoff_hz: float = 10.0, window: int = 25, spline_cutoff_hz: float = 3.0,
                 substeps: int = 10):
        self._r1 = ParityR1(dt, params, variant=variant, order=order, cutoff_hz=cutoff_hz, window=window,
                            spline_cutoff_hz=spline_cutoff_hz)
        self.dt, self.p, self.variant = self._r1.dt, self._r1.p, variant
        self.substeps = int(substeps)
        self.q = _pack(self.p, self.dt, int(substeps))
        self.u_names = list(_U)
        self.y_names = list(_Y)
        self.output_names = ["r2"]
        self.output_units = ["N·m/s^2"]
        self._d = [CausalDerivative(self._r1.window, self.dt, self._r1.lam, 1) for _ in range(3)]
        self.reset(1)

    def _x3(self, y1f, y2f, dy1):
        from .plant import mu, slip

        return self.p["R_w"] * self.p["N_v"] * mu(slip(y1f, y2f)) - self.p["I_w"] * dy1

    _state_attrs = ("_r1", "_d", "_x5")

    def to_dict(self) -> dict:
        """The design as plain data (a design artifact): the constructor's arguments and parameters."""
        r1 = self._r1
        return {"dt": self.dt, "params": dict(self.p), "variant": self.variant, "order": r1.order,
                "cutoff_hz": r1.cutoff_hz, "window": r1.window, "spline_cutoff_hz": r1.spline_cutoff_hz,
                "substeps": self.substeps}

    @classmethod
    def from_dict(cls, d: Mapping) -> ParityR2:
        """Rebuild from :meth:`to_dict`."""
        return cls(d["dt"], d["params"], variant=d["variant"], order=d["order"], cutoff_hz=d["cutoff_hz"],
                   window=d["window"], spline_cutoff_hz=d["spline_cutoff_hz"], substeps=d["substeps"])

    def reset(self, runs: int = 1) -> None:
        self._r1.reset(runs)
        for d in self._d:
            d.reset(runs, 1)
        self._x5 = np.zeros(runs)

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        if self.variant != "causal":
            raise DataError("the zero-phase r2 needs the whole record (offline only): use run()")
        check_finite(y[:, None, :], self.y_names, what="r2 measurement")
        check_finite(u[:, None, :], self.u_names, what="r2 input")
        yf = self._r1._lp.step(y)
        dy1 = self._d[0].step(yf[:, 0:1])
        x3 = self._x3(yf[:, 0:1], yf[:, 1:2], dy1)
        x3d = self._d[1].step(x3)
        x3dd = self._d[2].step(x3d)
        x5 = self._x5.copy()
        for r in range(u.shape[0]):
            self._x5[r] = _x5_advance(self._x5[r], u[r, 0], u[r, 1], u[r, 2], self.q)
        return self._combine(x3, x3d, x3dd, x5[:, None])

    def _combine(self, x3, x3d, x3dd, x5):
        p = self.p
        wn = p["omega_n"]
        return x3dd - wn**2 * p["K_f"] * x5 + 2 * p["zeta"] * wn * x3d + wn**2 * x3  # luo-et-al, eq. (26)

    def run(self, signals: Signals) -> Signals:
        u, y = self._inputs(signals)
        check_finite(y, self.y_names, what="r2 measurement")
        check_finite(u, self.u_names, what="r2 input")
        w, lam = self._r1.window, self._r1.lam
        if self.variant == "causal":
            if signals.n_samples < w:
                raise DataError(f"record of {signals.n_samples} samples is shorter than the r2 window ({w})")
            yf = lowpass(y, self._r1.sos, axis=1)

            def der(x):
                return causal_spline_derivative(x, self.dt, window=w, lam=lam, axis=1)
        else:
            yf = lowpass(y, self._r1.sos, axis=1, zero_phase=True)

            def der(x):
                return spline_derivative(x, self.dt, lam=lam, axis=1)
        x3 = self._x3(yf[:, :, 0], yf[:, :, 1], der(yf[:, :, 0]))
        x3d = der(x3)
        x3dd = der(x3d)
        x5 = np.empty(y.shape[:2])
        _x5_series(np.ascontiguousarray(u), self.q, x5)
        r2 = self._combine(x3, x3d, x3dd, x5)
        self.reset(signals.runs)
        return Signals(signals.t, r2[:, :, None], self.output_names, self.output_units, check=False)


def r2_magnitude_study(y: Signals, u: Signals, x_true: Signals | None = None, *,
                       params: Mapping[str, float] | None = None, skip: float = 1.0) -> dict[str, float]:
    """Why the paper dropped r2: the nominal magnitude of r2 against that of its terms.

    Parameters
    ----------
    y, u : Signals
        Measurements and known inputs of nominal runs (from :func:`fdikit.systems.abs.plant.simulate`).
    x_true : Signals, optional
        True states (10 ms) to evaluate eq. (26) on noise-free states as a reference.
    skip : float
        Seconds left out at the start of each record.

    Returns
    -------
    dict
        RMS of nominal r2 (causal and zero-phase variants), of the torque term ``w_n^2 x3`` it
        must balance, of the change a +10 % K_f fault makes in r2 (``w_n^2 0.1 K_f x5``, the
        largest F3 fault), the fault-to-noise ratio of that change against the nominal r2, and
        the RMS of eq. (26) on the true states (finite differences at 10 ms) when given.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import Scenario, simulate
    >>> res = simulate(None, Scenario(t_end=4.0), runs=2, seed=0)
    >>> out = r2_magnitude_study(res.y, res.u)
    >>> out["fault_to_noise_kf10_causal"] < 0.5     # a 10 % K_f fault is buried in r2's noise
    True
    """
    sig = y.concat_channels(u)
    dt = _dt_of(sig)
    k0 = round(skip / dt)
    p = _params(params)
    out: dict[str, float] = {}
    for variant in ("causal", "zero_phase"):
        g = ParityR2(dt, p, variant=variant)
        r2 = g.run(sig)["r2"][:, k0:]
        out[f"rms_r2_{variant}"] = float(np.sqrt(np.mean(r2**2)))
        out[f"max_abs_r2_{variant}"] = float(np.max(np.abs(r2)))
    yf = lowpass(sig.values[:, :, sig.index(_Y)], butter_sos(10, 10.0, 1 / dt), axis=1)
    from .plant import mu, slip

    x3 = p["R_w"] * p["N_v"] * mu(slip(yf[:, :, 0], yf[:, :, 1]))
    out["rms_torque_term"] = float(np.sqrt(np.mean((p["omega_n"] ** 2 * x3[:, k0:]) ** 2)))
    out["ratio_causal"] = out["rms_r2_causal"] / out["rms_torque_term"]
    x5 = np.empty(sig.values.shape[:2])
    _x5_series(np.ascontiguousarray(sig.values[:, :, sig.index(_U)]), _pack(p, dt, 10), x5)
    eff = p["omega_n"] ** 2 * 0.1 * p["K_f"] * x5[:, k0:]
    out["rms_kf10_effect"] = float(np.sqrt(np.mean(eff**2)))
    for variant in ("causal", "zero_phase"):
        out[f"fault_to_noise_kf10_{variant}"] = out["rms_kf10_effect"] / out[f"rms_r2_{variant}"]
    if x_true is not None:
        x = x_true.values
        wn = p["omega_n"]
        dtx = _dt_of(x_true)
        x3 = x[:, :, 2]
        x3d = np.gradient(x3, dtx, axis=1)
        x3dd = np.gradient(x3d, dtx, axis=1)
        ref = x3dd - wn**2 * p["K_f"] * x[:, :, 4] + 2 * p["zeta"] * wn * x3d + wn**2 * x3
        out["rms_r2_true_states"] = float(np.sqrt(np.mean(ref[:, round(skip / dtx):] ** 2)))
    return out


# --------------------------------------------------------------------------------------------
# Nonlinear Luenberger observer, eqs. (29)-(33)
# --------------------------------------------------------------------------------------------
def linear_part(params: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Linear part ``A`` (5 x 5) of eq. (30) and the output matrix ``C = [I_2, 0]``.

    Examples
    --------
    >>> A, C = linear_part()
    >>> A.shape, C.shape, float(A[0, 2])
    ((5, 5), (2, 5), -0.2)
    """
    p = _params(params)
    wn, z = p["omega_n"], p["zeta"]
    A = np.zeros((5, 5))
    A[0, 2] = -1.0 / p["I_w"]  # luo-et-al, eq. (30)
    A[2, 3] = 1.0
    A[3, 2] = -wn**2
    A[3, 3] = -2.0 * z * wn
    A[3, 4] = wn**2 * p["K_f"]
    C = np.zeros((2, 5))
    C[0, 0] = C[1, 1] = 1.0
    return A, C


def observer_gain(params: Mapping[str, float] | None = None, *, method: str = "kalman",
                  process_var: Sequence[float] | None = None, meas_var: float = 0.004,
                  dt_plant: float = 1e-3, dt_sample: float = 1e-2, poles: Sequence[float] | None = None
                  ) -> np.ndarray:
    """Observer gain ``L`` (5 x 2) for eq. (32), designed on the linear part of eq. (30).

    ``method="kalman"`` (default): the steady-state Kalman-Bucy gain ``L = P C' R^-1`` with
    ``A P + P A' - P C' R^-1 C P + Q = 0`` (scipy ``solve_continuous_are``), where the process
    noise intensity ``Q = diag(process_var) * dt_plant`` is that of the plant's white noise held
    over ``dt_plant`` and ``R = meas_var * dt_sample`` that of the held, sampled measurement
    noise. ``process_var`` defaults to the plant's 23 dB noise (0.5 % of the states' mean-square
    values). ``method="place"``: pole placement (scipy ``place_poles``) at ``poles`` (rad/s).

    The gain must keep the error dynamics slow against the 10 ms hold: a
    :class:`ConditionError` is raised if any closed-loop eigenvalue has ``|s| dt_sample > 0.5``.

    Returns
    -------
    ndarray (5, 2)

    Examples
    --------
    >>> L = observer_gain()
    >>> L.shape
    (5, 2)
    """
    from scipy.linalg import solve_continuous_are
    from scipy.signal import place_poles

    p = _params(params)
    A, C = linear_part(p)
    if method == "kalman":
        if process_var is None:
            from .plant import ABSPlant, Scenario, state_mean_square

            process_var = state_mean_square(ABSPlant(), Scenario())[:5] * 10 ** (-23.0 / 10)
        qv = np.asarray(process_var, float)
        if qv.shape != (5,) or np.any(qv < 0):
            raise DataError(f"process_var must be 5 non-negative variances, got {qv}")
        if meas_var <= 0:
            raise DataError(f"meas_var must be positive, got {meas_var}")
        Q = np.diag(qv * dt_plant)
        R = np.eye(2) * meas_var * dt_sample
        P = solve_continuous_are(A.T, C.T, Q, R)
        L = P @ C.T @ np.linalg.inv(R)
    elif method == "place":
        if poles is None or len(poles) != 5:
            raise DataError("pole placement needs 5 poles")
        L = place_poles(A.T, C.T, np.asarray(poles, float)).gain_matrix.T
    else:
        raise DataError(f"unknown gain method {method!r}; use 'kalman' or 'place'")
    eig = np.linalg.eigvals(A - L @ C)
    if np.any(eig.real >= 0):
        raise ConditionError("observer stability", f"A - L C has eigenvalues {eig} not in the open left "
                             "half plane", {"eigenvalues": eig.tolist()})
    if np.max(np.abs(eig)) * dt_sample > 0.5:
        raise ConditionError("sample-and-hold", f"fastest observer eigenvalue |s| = {np.abs(eig).max():.1f} "
                             f"rad/s is too fast for the {dt_sample} s hold (|s| dt must be <= 0.5)",
                             {"eigenvalues": eig.tolist()})
    return L


class ABSObserver(ResidualGenerator):
    """Nonlinear Luenberger observer of luo-et-al, eqs. (29)-(33); residuals r3, r4 (rad/s).

    Parameters
    ----------
    dt : float
        Sample interval of the measurements, s (0.01).
    params : mapping, optional
        Nominal plant parameters.
    L : array (5, 2), optional
        Observer gain; default :func:`observer_gain` ``(method="kalman")``.
    substeps : int
        Integration steps per sample interval (10: the plant's 1 ms).
    injection : {"held", "continuous"}
        ``"held"`` (default, eq. (32) as printed): the correction ``L (y^h - x_hat^h)`` with the
        measurement *and* the estimate sampled and held, i.e. the constant ``L r_k`` over
        ``[t_k, t_{k+1})`` (Hostetter's sampled-data updating, the paper's ref. [40]). With a
        matched model the sampled error then obeys ``e_{k+1} = (Phi - Gamma L C) e_k`` and a
        steadily decelerating car leaves no residual. ``"continuous"``: ``L (y^h - x_hat(t))``
        with the estimate running against the held measurement; a speed changing at ``s`` rad/s^2
        then biases the residual by about ``-s dt/2`` (measured on the nominal noise-free stop:
        r4 mean -0.033 rad/s against the measurement noise's standard deviation 0.063 rad/s).
    v_min : float
        Validity limit, m/s, as in :class:`ParityR1`: where the measured vehicle speed ``R_w y2``
        is below it, r3 and r4 are set to 0 (their nominal value); the observer keeps running.
        Below 2 m/s the ABS is off and the wheel locks; the clamped, locked wheel under process
        noise makes r3 non-stationary there (measured, 200 nominal runs at 23 dB: the largest
        nominal GLRT values of r3, W = 40, all fell 0.1-0.3 s before standstill, 99th percentile
        56.8 against a median of 9.1). ``0`` keeps every sample.

    Notes
    -----
    The state starts at ``[y1_0, y2_0, 0, 0, 0]`` at the first sample (car rolling, brake off).
    At sample ``k`` the residual is ``y_k - C x_hat(t_k)`` (eq. (33)); then ``x_hat`` is
    integrated to ``t_{k+1}`` with ``y_k`` held (eq. (31)) and ``P_m``, ``u_in``, ``u_out`` of
    sample ``k`` held.

    Examples
    --------
    >>> from fdikit.systems.abs.plant import Scenario, simulate
    >>> res = simulate(None, Scenario(t_end=2.0), runs=2, seed=0)
    >>> r = ABSObserver(0.01).run(res.y.concat_channels(res.u))
    >>> r.names, r.values.shape
    (['r3', 'r4'], (2, 200, 2))
    """

    def __init__(self, dt: float, params: Mapping[str, float] | None = None, *, L=None, substeps: int = 10,
                 injection: str = "held", v_min: float = 3.0):
        from .plant import MU_TABLE

        if injection not in ("held", "continuous"):
            raise DataError(f"injection must be 'held' or 'continuous', got {injection!r}")
        if dt <= 0:
            raise DataError(f"sample interval dt must be positive, got {dt}")
        if int(substeps) != substeps or substeps < 1:
            raise DataError(f"substeps must be an integer >= 1, got {substeps}")
        self.dt = float(dt)
        self.p = _params(params)
        L = observer_gain(self.p, dt_sample=self.dt) if L is None else L
        self.L = np.ascontiguousarray(L, dtype=float)
        if self.L.shape != (5, 2):
            raise DataError(f"observer gain must be 5 x 2, got {self.L.shape}")
        self.substeps = int(substeps)
        self.injection = injection
        self.v_min = float(v_min)
        self.q = _pack(self.p, self.dt, int(substeps), held=injection == "held")
        self._tab = np.ascontiguousarray(MU_TABLE, dtype=float)
        self.u_names = list(_U)
        self.y_names = list(_Y)
        self.output_names = ["r3", "r4"]
        self.output_units = ["rad/s", "rad/s"]
        self.reset(1)

    _state_attrs = ("_x", "_started")

    def to_dict(self) -> dict:
        """The design as plain data (a design artifact): ``dt``, the nominal parameters, the gain
        ``L`` (5, 2), ``substeps`` and ``injection``."""
        return {"dt": self.dt, "params": dict(self.p), "L": self.L.copy(), "substeps": self.substeps,
                "injection": self.injection, "v_min": self.v_min}

    @classmethod
    def from_dict(cls, d: Mapping) -> ABSObserver:
        """Rebuild from :meth:`to_dict` (the stored gain is used as saved)."""
        return cls(d["dt"], d["params"], L=np.asarray(d["L"], float), substeps=d["substeps"],
                   injection=d.get("injection", "continuous"), v_min=d.get("v_min", 0.0))

    def reset(self, runs: int = 1) -> None:
        self._x = np.zeros((runs, 5))
        self._started = False

    @property
    def state(self) -> np.ndarray:
        """Current estimate ``x_hat`` (runs, 5): omega_w, omega_v, T_b, dT_b, P_s."""
        return self._x.copy()

    def _init(self, y0: np.ndarray) -> None:
        self._x[:] = 0.0
        self._x[:, :2] = y0
        self._started = True

    def _step(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        if y.shape[0] != self._x.shape[0]:
            raise DataError(f"sample has {y.shape[0]} runs; the observer was reset for {self._x.shape[0]}")
        check_finite(y[:, None, :], self.y_names, what="observer measurement")
        check_finite(u[:, None, :], self.u_names, what="observer input")
        if not self._started:
            self._init(y)
        out = np.empty((y.shape[0], 1, 2))
        kern = _obs_batch if y.shape[0] > 1 else _obs_serial
        kern(np.ascontiguousarray(y[:, None, :]), np.ascontiguousarray(u[:, None, :]), self._x,
             self.q, self.L, self._tab, out)
        return self._valid(out, y[:, None, :])[:, 0]

    def _valid(self, out: np.ndarray, y: np.ndarray) -> np.ndarray:
        """r3, r4 set to 0 where the measured vehicle speed is below ``v_min`` (m/s)."""
        if self.v_min <= 0.0:
            return out
        return np.where(self.p["R_w"] * y[:, :, 1:2] >= self.v_min, out, 0.0)

    def run(self, signals: Signals) -> Signals:
        u, y = self._inputs(signals)
        check_finite(y, self.y_names, what="observer measurement")
        check_finite(u, self.u_names, what="observer input")
        self.reset(signals.runs)
        self._init(y[:, 0])
        out = np.empty((signals.runs, signals.n_samples, 2))
        _obs_batch(np.ascontiguousarray(y), np.ascontiguousarray(u), self._x, self.q, self.L, self._tab, out)
        out = self._valid(out, y)
        return Signals(signals.t, out, self.output_names, self.output_units, check=False)


#: Observer-model parameters a signature can be taken for (those :func:`_pack` reads; ``tau_m``
#: and the pedal parameters are not in the observer, whose P_m is an input).
OBSERVER_PARAMS = ("R_w", "N_v", "M_v", "I_w", "K_f", "omega_n", "zeta", "C_in", "C_out", "P_lp", "rho",
                   "beta_s", "V_s", "A_0")


def observer_sensitivity(dt: float, names: Sequence[str] = ("I_w",), *, rel_step: float = 0.01,
                         params: Mapping[str, float] | None = None, L=None,
                         outputs: Sequence[str] = ("r3", "r4"), **observer_kw):
    """The ABS observer with its residual signatures for relative changes of plant parameters.

    Builds :class:`ABSObserver` on the nominal parameters and one twin per name with that
    parameter scaled by ``1 + rel_step``, all with the *same* gain ``L`` (default
    :func:`observer_gain` of the nominal parameters), wrapped in
    :class:`~fdikit.residuals.sensitivity.ParameterSensitivity`.

    Parameters
    ----------
    dt : float
        Sample interval, s.
    names : sequence of str
        Parameters of :data:`OBSERVER_PARAMS` (e.g. ``["I_w", "K_f"]``).
    rel_step : float
        Relative finite-difference step (1 %: the signature of a 2 % fault is then within
        about 1 % of the measured response, since the response is nearly linear at that size).
    params, L, **observer_kw
        Nominal parameters, gain and further :class:`ABSObserver` options.

    Returns
    -------
    ParameterSensitivity
        Outputs ``r3``, ``r4`` and ``sig:<r>:<name>`` (rad/s per unit relative change).

    Examples
    --------
    >>> observer_sensitivity(0.01, ["I_w", "K_f"], outputs=["r3"]).output_names
    ['r3', 'r4', 'sig:r3:I_w', 'sig:r3:K_f']
    """
    from ...residuals.sensitivity import ParameterSensitivity

    p = _params(params)
    names = [str(n) for n in names]
    bad = [n for n in names if n not in OBSERVER_PARAMS]
    if bad:
        raise DataError(f"no observer signature for {bad}: the observer model contains "
                        f"{list(OBSERVER_PARAMS)} "
                        "(tau_m and the pedal act through its P_m input)")
    if len(set(names)) != len(names):
        raise DataError(f"parameter names repeat: {names}")
    L = observer_gain(p, dt_sample=dt) if L is None else np.asarray(L, float)
    base = ABSObserver(dt, p, L=L, **observer_kw)
    twins = {n: ABSObserver(dt, dict(p, **{n: p[n] * (1.0 + rel_step)}), L=L, **observer_kw) for n in names}
    return ParameterSensitivity(base, twins, rel_step, outputs=outputs)
