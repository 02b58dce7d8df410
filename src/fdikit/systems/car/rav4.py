"""The lateral (single-track + roll) model fitted to one real minute of a Toyota RAV4.

Data: ``../shared/data/rav4-highway`` (comma2k19, a 2018 RAV4 on a highway; README there). The
model is the linear lateral block of the passenger car reduced to what the CAN bus observes —
a single-track ("bicycle") model with linear axle cornering stiffnesses, a first-order
steering lag, and a second-order body roll that feeds the lateral accelerometer (ng-chen-speyer's
lateral states v_y, r, phi, p):

    delta_s' = (delta_sw / i_s - delta_s) / tau_s                   steering lag (road wheel, rad)
    alpha_f = delta_s - (v_y + a r) / U,  alpha_r = -(v_y - b r) / U   (Rajamani 2012, eq. 2.x)
    v_y' = (C_f alpha_f + C_r alpha_r) / m - U r
    r'   = (a C_f alpha_f - b C_r alpha_r) / I_z
    a_y  = (C_f alpha_f + C_r alpha_r) / m                             (ISO, left positive)
    phi'' = w_phi^2 (k_phi a_y - phi) - 2 zeta_phi w_phi phi'          roll, k_phi in rad per m/s^2
    yaw_meas = r + b_r,   ay_meas = s_ay (a_y + g phi) + b_ay

driven by the measured hand-wheel angle ``delta_sw`` (STEER_ANGLE + STEER_FRACTION) and the
measured speed ``U`` (SPEED.SPEED). Known: mass, wheelbase, steering ratio (README). Fixed
from typical values: CG position (58 % front weight), yaw inertia ``I_z = m a b`` (radius of
gyration sqrt(ab), Rajamani 2012), roll frequency and damping. Fitted by
:func:`scipy.optimize.least_squares`: the axle cornering stiffnesses, the steering lag, the
steering-angle offset, the yaw-rate offset, the roll gain and the accelerometer offset. The
sign of KINEMATICS.ACCEL_Y (``s_ay``) is taken from the data (it is positive to the RIGHT on
this car: its correlation with U r is negative).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from ...errors import DataError
from ...io import read_can_log

__all__ = ["RAV4", "Rav4Fit", "default_data_path", "fit_rav4", "load_rav4", "simulate_single_track"]

G = 9.80665

#: What the README gives, and typical values for what it does not.
RAV4 = {
    "m": 1656.0,          # kg, README (3,650 lb)
    "L": 2.65,            # m, wheelbase, README
    "i_s": 16.88,         # steering ratio, README
    "front_share": 0.58,  # static front-axle load share of a 2018 RAV4 (typical compact SUV 57-60 %)
    "w_phi": 2 * np.pi * 1.5,  # rad/s, roll natural frequency (Gillespie 1992: 1-2 Hz)
    "zeta_phi": 0.5,      # roll damping ratio
}

SIGNALS = ["STEER_ANGLE_SENSOR.STEER_ANGLE", "STEER_ANGLE_SENSOR.STEER_FRACTION", "SPEED.SPEED",
           "KINEMATICS.YAW_RATE", "KINEMATICS.ACCEL_Y"]

#: Fitted parameters: name, initial value, lower and upper bound, unit.
FIT_PARAMS = [
    ("C_f", 1.2e5, 1.5e4, 6e5, "N/rad"),       # front axle cornering stiffness
    ("C_r", 1.4e5, 1.5e4, 6e5, "N/rad"),       # rear axle cornering stiffness
    ("tau_s", 0.1, 0.0, 0.6, "s"),             # steering lag
    ("delta_0", 0.0, -0.1, 0.1, "rad"),        # hand-wheel angle offset
    ("b_r", 0.0, -0.05, 0.05, "rad/s"),        # yaw-rate sensor offset
    ("k_phi", 0.008, 0.0, 0.05, "rad/(m/s^2)"),  # roll gain
    ("b_ay", 0.0, -1.0, 1.0, "m/s^2"),         # accelerometer offset (road bank, mounting)
    ("sigma", 0.3, 0.0, 1.0, "m"),             # tyre relaxation length (force lag sigma / U; Pacejka 2012:
                                               # of the order of the tyre radius)
]


def default_data_path() -> Path:
    """Where the RAV4 minute is looked for when no path is given.

    ``$FDIKIT_RAV4`` if set; else ``../shared/data/rav4-highway`` relative to the working
    directory (a checkout's root, as in CI) or to the source tree (an editable install). The
    first that exists is returned (the working-directory one when none does).
    """
    env = os.environ.get("FDIKIT_RAV4")
    if env:
        return Path(env)
    rel = Path("..") / "shared" / "data" / "rav4-highway"
    candidates = [Path.cwd() / rel, Path(__file__).resolve().parents[4] / rel]
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[0]


def load_rav4(path: str | os.PathLike | None = None, rate: float = 50.0):
    """The signals of the fit on one grid, SI units (rad, rad/s, m/s, m/s^2).

    Parameters
    ----------
    path : path-like, optional
        The data directory (``drive.blf`` and ``toyota_rav4.dbc``); default
        :func:`default_data_path`.
    rate : float
        Grid rate (Hz).

    Returns
    -------
    LogSignals
        Channels as :data:`SIGNALS`.

    Examples
    --------
    >>> s = load_rav4()                                    # doctest: +SKIP
    >>> s.units                                            # doctest: +SKIP
    ['rad', 'rad', 'm/s', 'rad/s', 'm/s^2']
    """
    d = Path(path) if path is not None else default_data_path()
    blf, dbc = d / "drive.blf", d / "toyota_rav4.dbc"
    if not blf.exists() or not dbc.exists():
        raise DataError(f"RAV4 data not found: need {blf} and {dbc}")
    return read_can_log(blf, dbc, SIGNALS, rate=rate, units="si")


@njit(cache=True)
def _sim_batch(theta, U, dsw, dt, m, a, b, Iz, w_phi, zeta, s_ay, r0):  # pragma: no cover - numba
    """Single-track + roll for a batch of parameter sets. theta (P, 8); U, dsw (T,).
    Returns yaw (P, T) and ay (P, T) as measured (offsets and sign included)."""
    P = theta.shape[0]
    T = U.shape[0]
    yaw = np.empty((P, T))
    ay = np.empty((P, T))
    nsub = 4
    h = dt / nsub
    for j in range(P):
        Cf, Cr, tau, d0, br, kphi, bay = (theta[j, 0], theta[j, 1], theta[j, 2], theta[j, 3], theta[j, 4],
                                          theta[j, 5], theta[j, 6])
        sig = theta[j, 7]
        Ff = 0.0
        Fr = 0.0
        ds = (dsw[0] - d0)
        vy = 0.0
        r = r0 - br
        phi = 0.0
        pr = 0.0
        for k in range(T):
            u = max(U[k], 1.0)
            target = dsw[k] - d0
            for _ in range(nsub):
                # exact first-order lag, semi-implicit (symplectic Euler) for the rest: h << 1/|lambda|
                if tau > 1e-6:
                    ds += (target - ds) * (1.0 - np.exp(-h / tau))
                else:
                    ds = target
                af = ds - (vy + a * r) / u
                ar = -(vy - b * r) / u
                # tyre relaxation: F' = (U / sigma) (C alpha - F), exact over the sub-step
                if sig > 1e-6:
                    e = 1.0 - np.exp(-h * u / sig)
                    Ff += (Cf * af - Ff) * e
                    Fr += (Cr * ar - Fr) * e
                else:
                    Ff = Cf * af
                    Fr = Cr * ar
                acc = (Ff + Fr) / m
                vy += h * (acc - u * r)
                r += h * (a * Ff - b * Fr) / Iz
                pr += h * (w_phi * w_phi * (kphi * acc - phi) - 2.0 * zeta * w_phi * pr)
                phi += h * pr
            acc = (Ff + Fr) / m
            yaw[j, k] = r + br
            ay[j, k] = s_ay * (acc + 9.80665 * phi) + bay
    return yaw, ay


def simulate_single_track(theta: dict[str, float] | np.ndarray, U: np.ndarray, delta_sw: np.ndarray,
                          dt: float,
                          *, car: dict[str, float] | None = None, s_ay: float = -1.0,
                          r0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Measured yaw rate and lateral acceleration of the single-track + roll model.

    Parameters
    ----------
    theta : mapping or ndarray (8,) or (P, 8)
        Parameters of :data:`FIT_PARAMS` (a batch of P sets is simulated at once).
    U : ndarray (T,)
        Speed (m/s).
    delta_sw : ndarray (T,)
        Road-wheel angle command = hand-wheel angle / steering ratio (rad).
    dt : float
        Sample interval (s).
    car : mapping, optional
        ``m``, ``L``, ``front_share``, ``w_phi``, ``zeta_phi`` (default :data:`RAV4`).
    s_ay : float
        Sign of the accelerometer axis (+1 left positive, -1 right positive).
    r0 : float
        Initial measured yaw rate (rad/s).

    Returns
    -------
    yaw, ay : ndarray (T,) or (P, T)

    Examples
    --------
    >>> import numpy as np
    >>> U, d = np.full(2000, 20.0), np.full(2000, 0.002)
    >>> yaw, ay = simulate_single_track(np.array([1e5, 1e5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3]), U, d, 0.01)
    >>> a, b = 0.42 * 2.65, 0.58 * 2.65                        # CG position of the default car
    >>> K = 1656 / 2.65 * (b / 1e5 - a / 1e5)                  # understeer gradient, rad/(m/s^2)
    >>> round(float(yaw[-1]), 5) == round(20 * 0.002 / (2.65 + K * 20**2), 5)  # r = U delta / (L + K U^2)
    True
    """
    c = dict(RAV4)
    c.update(car or {})
    th = np.array([theta[n] for n, *_ in FIT_PARAMS]) if isinstance(theta, dict) else np.asarray(theta, float)
    single = th.ndim == 1
    th = np.atleast_2d(th)
    a = (1.0 - c["front_share"]) * c["L"]
    b = c["front_share"] * c["L"]
    Iz = c["m"] * a * b
    yaw, ay = _sim_batch(th, np.asarray(U, float), np.asarray(delta_sw, float), float(dt), c["m"], a, b, Iz,
                         c["w_phi"], c["zeta_phi"], float(s_ay), float(r0))
    return (yaw[0], ay[0]) if single else (yaw, ay)


def _nrmse(model: np.ndarray, meas: np.ndarray) -> float:
    """RMS error over the standard deviation of the measurement (0 perfect, 1 = no better than its mean)."""
    return float(np.sqrt(np.mean((model - meas) ** 2)) / np.std(meas))


def _reference(U, dsw, yaw_m, yaw_model, cut, rate: float, taps: int = 100) -> dict[str, float]:
    """What any causal linear model driven by the same inputs can reach, for context: a free
    ``taps``-tap FIR from (U delta_sw, delta_sw, 1) to the yaw rate by least squares (in-sample
    and trained on the first two thirds / tested on the last), and the model's correlation with
    the measured yaw rate low-passed at 2 Hz (zero-phase; above ~1 Hz the measured yaw rate is
    hardly coherent with the steering)."""
    from scipy.signal import butter, filtfilt

    T = yaw_m.size
    cols = [np.roll(U * dsw, k) for k in range(taps)] + [np.roll(dsw, k) for k in range(taps)]
    X = np.column_stack([*cols, np.ones(T)])[taps:]
    y = yaw_m[taps:]
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    k = cut - taps
    c2, *_ = np.linalg.lstsq(X[:k], y[:k], rcond=None)
    b, a = butter(2, 2.0 / (rate / 2.0))
    y_lp = filtfilt(b, a, yaw_m)
    return {"fir_taps": taps, "fir_in_sample_corr": float(np.corrcoef(X @ c, y)[0, 1]),
            "fir_holdout_corr": float(np.corrcoef(X[k:] @ c2, y[k:])[0, 1]),
            "model_corr_vs_yaw_lowpass_2hz": float(np.corrcoef(yaw_model, y_lp)[0, 1])}


@dataclass
class Rav4Fit:
    """Result of :func:`fit_rav4`. Correlations are Pearson's; NRMSE = RMS error / std(measured)."""

    params: dict[str, float]
    fixed: dict[str, float]
    yaw_corr: float
    yaw_nrmse: float
    ay_corr: float
    ay_nrmse: float
    kinematic_yaw_corr: float
    holdout: dict[str, float]
    reference: dict[str, float]
    understeer_gradient_deg_per_g: float
    ay_sign: float
    n_samples: int
    rate: float
    seconds: float
    t: np.ndarray = field(repr=False, default=None)
    yaw_model: np.ndarray = field(repr=False, default=None)
    yaw_meas: np.ndarray = field(repr=False, default=None)
    ay_model: np.ndarray = field(repr=False, default=None)
    ay_meas: np.ndarray = field(repr=False, default=None)

    def summary(self) -> dict[str, Any]:
        return {
            "fitted_parameters": self.params, "fixed_parameters": self.fixed,
            "yaw_rate": {"correlation": self.yaw_corr, "nrmse": self.yaw_nrmse,
                         "kinematic_bicycle_correlation": self.kinematic_yaw_corr,
                         "target_correlation": 0.85},
            "lateral_acceleration": {"correlation": self.ay_corr, "nrmse": self.ay_nrmse,
                                     "sign_of_ACCEL_Y": ("right positive" if self.ay_sign < 0
                                                         else "left positive")},
            "holdout_last_third": self.holdout,
            "reference": self.reference,
            "understeer_gradient_deg_per_g": self.understeer_gradient_deg_per_g,
            "samples": self.n_samples, "rate_hz": self.rate, "fit_seconds": self.seconds,
        }


def fit_rav4(path: str | os.PathLike | None = None, *, rate: float = 50.0, ay_weight: float = 0.5,
             signals=None, holdout: bool = True, fit_until: float | None = None) -> Rav4Fit:
    """Fit the lateral model to the RAV4 minute and compare it with the measured yaw rate and lateral
    acceleration.

    Parameters
    ----------
    path : path-like, optional
        Data directory (default :func:`default_data_path`).
    rate : float
        Grid rate of the fit (Hz).
    ay_weight : float
        Weight of the (noisier) lateral-acceleration residual relative to the yaw-rate residual,
        each normalised by its signal's standard deviation.
    signals : LogSignals, optional
        Already loaded :func:`load_rav4` signals.
    holdout : bool
        Also fit on the first two thirds and evaluate on the last (and compute the LTI reference);
        ``False`` halves the time.
    fit_until : float, optional
        Fit the parameters on the samples with ``t <= fit_until`` only (s; e.g. the calibration
        half of the minute, so that the rest stays held out for an evaluation); the figures are
        still computed over the whole minute. Default: the whole minute.

    Returns
    -------
    Rav4Fit
        Fitted parameters, yaw-rate and lateral-acceleration correlation and NRMSE over the
        whole minute (the yaw-rate offset is one of the fitted parameters, so the correlation
        is that of the offset-free signals), the kinematic-bicycle baseline, and the same figures
        on the last third of the minute for a fit on the first two thirds (hold-out).

    Examples
    --------
    >>> fit = fit_rav4()                                   # doctest: +SKIP
    >>> fit.yaw_corr > 0.85                                # doctest: +SKIP
    True
    """
    t_start = time.perf_counter()
    s = signals if signals is not None else load_rav4(path, rate)
    if not s.valid.all():
        bad = [n for i, n in enumerate(s.names) if not s.valid[0, :, i].all()]
        raise DataError(f"the RAV4 signals have gaps in {bad}; the fit needs complete data")
    v = s.values[0]
    col = {n: i for i, n in enumerate(s.names)}
    dsw = (v[:, col["STEER_ANGLE_SENSOR.STEER_ANGLE"]] + v[:, col["STEER_ANGLE_SENSOR.STEER_FRACTION"]])
    U = v[:, col["SPEED.SPEED"]]
    yaw_m = v[:, col["KINEMATICS.YAW_RATE"]]
    ay_m = v[:, col["KINEMATICS.ACCEL_Y"]]
    dt = float(np.mean(np.diff(s.t)))
    i_s = RAV4["i_s"]
    T = U.size
    n_fit = T if fit_until is None else int(np.searchsorted(s.t - s.t[0], fit_until, side="right"))
    if n_fit < 100:
        raise DataError(f"fit_until = {fit_until} s leaves {n_fit} samples; the fit needs at least 100")
    fs = slice(0, n_fit)
    # sign of the accelerometer axis from the (fitted part of the) data: a_y ~ U r in a steady turn
    s_ay = float(np.sign(np.corrcoef(ay_m[fs], U[fs] * yaw_m[fs])[0, 1]) or 1.0)
    kin = U * dsw / i_s / RAV4["L"]
    kin_corr = float(np.corrcoef(kin, yaw_m)[0, 1])
    names = [p[0] for p in FIT_PARAMS]
    x0 = np.array([p[1] for p in FIT_PARAMS])
    lo = np.array([p[2] for p in FIT_PARAMS])
    hi = np.array([p[3] for p in FIT_PARAMS])
    scale = np.array([1e5, 1e5, 0.1, 0.01, 0.005, 0.01, 0.1, 0.3])
    # initial offsets from the data: the yaw offset is the mean yaw rate minus the kinematic mean
    x0[4] = float(np.mean(yaw_m[fs]) - np.mean(kin[fs]))

    def make(sl):
        d, u_, ym, am = dsw[sl] / i_s, U[sl], yaw_m[sl], ay_m[sl]
        sy, sa = np.std(ym), np.std(am)

        def resid_batch(Z):
            th = Z * scale
            th = th.copy()
            th[:, 3] = th[:, 3] / i_s  # hand-wheel offset -> road-wheel offset
            yaw, ay = simulate_single_track(th, u_, d, dt, s_ay=s_ay, r0=float(ym[0]))
            return np.concatenate([(yaw - ym) / sy, ay_weight * (ay - am) / sa], axis=1)

        def fun(z):
            return resid_batch(z[None])[0]

        def jac(z):
            h = 1e-6 * np.maximum(np.abs(z), 1e-2)
            Z = np.concatenate([z + np.diag(h), z - np.diag(h)])
            R = resid_batch(Z)
            n = z.size
            return ((R[:n] - R[n:]) / (2 * h[:, None])).T

        return fun, jac

    def solve(sl):
        fun, jac = make(sl)
        z0 = np.clip(x0, lo, hi) / scale
        sol = least_squares(fun, z0, jac=jac, bounds=(lo / scale, hi / scale), method="trf", x_scale="jac",
                            max_nfev=200)
        return sol.x * scale

    th = solve(fs)
    th_road = th.copy()
    th_road[3] /= i_s
    yaw, ay = simulate_single_track(th_road, U, dsw / i_s, dt, s_ay=s_ay, r0=float(yaw_m[0]))
    br, bay = th[4], th[6]
    yaw_corr = float(np.corrcoef(yaw - br, yaw_m - br)[0, 1])
    ay_corr = float(np.corrcoef(ay, ay_m)[0, 1])
    cut = 2 * T // 3
    holdout_fig: dict[str, float] = {}
    if holdout:
        # hold-out: fit on the first two thirds, evaluate on the last third
        th_h = solve(slice(0, cut))
        th_hr = th_h.copy()
        th_hr[3] /= i_s
        yaw_h, ay_h = simulate_single_track(th_hr, U, dsw / i_s, dt, s_ay=s_ay, r0=float(yaw_m[0]))
        sl = slice(cut, T)
        holdout_fig = {"yaw_corr": float(np.corrcoef(yaw_h[sl], yaw_m[sl])[0, 1]),
                       "yaw_nrmse": _nrmse(yaw_h[sl], yaw_m[sl]),
                       "ay_corr": float(np.corrcoef(ay_h[sl], ay_m[sl])[0, 1]),
                       "ay_nrmse": _nrmse(ay_h[sl], ay_m[sl]),
                       "kinematic_yaw_corr": float(np.corrcoef(kin[sl], yaw_m[sl])[0, 1])}
    params = dict(zip(names, (float(x) for x in th), strict=True))
    reference = _reference(U, dsw, yaw_m, yaw, cut, 1.0 / dt) if holdout else {}
    a = (1.0 - RAV4["front_share"]) * RAV4["L"]
    b = RAV4["front_share"] * RAV4["L"]
    K = RAV4["m"] / RAV4["L"] * (b / params["C_f"] - a / params["C_r"])
    fixed = {"m": RAV4["m"], "L": RAV4["L"], "steering_ratio": i_s, "a": a, "b": b, "I_z": RAV4["m"] * a * b,
             "roll_frequency_hz": RAV4["w_phi"] / (2 * np.pi), "roll_damping": RAV4["zeta_phi"]}
    del bay
    return Rav4Fit(params=params, fixed=fixed, yaw_corr=yaw_corr, yaw_nrmse=_nrmse(yaw, yaw_m),
                   ay_corr=ay_corr, ay_nrmse=_nrmse(ay, ay_m), kinematic_yaw_corr=kin_corr,
                   holdout=holdout_fig,
                   understeer_gradient_deg_per_g=float(np.rad2deg(K * G)), ay_sign=s_ay, reference=reference,
                   n_samples=int(T),
                   rate=float(rate), seconds=time.perf_counter() - t_start, t=s.t, yaw_model=yaw,
                   yaw_meas=yaw_m, ay_model=ay, ay_meas=ay_m)
