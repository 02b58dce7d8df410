"""The design model of the RAV4 monitor, fitted on the calibration half of the real minute.

:func:`_preprocessing` fits the single track (:func:`~fdikit.systems.car.rav4.fit_rav4`), the
preprocessing offsets, the wheel-speed-difference coefficients and the channels' noise levels on
``t <= half_s``; :func:`_linear_model` is that single track linearised at one speed with the four
lateral measurements.
"""

from __future__ import annotations

import numpy as np

from ....model.linear import LinearFaultModel
from ....signals import Signals
from ..rav4 import RAV4
from .channels import _RAW_U, _RAW_Y, CHANNELS, Rav4Preprocessing


def _linear_model(fit_params: dict[str, float], U0: float, s_ay: float, k_f: float,
                  k_r: float) -> LinearFaultModel:
    """Continuous linear model of the fitted single track at speed U0 (see the module docstring)."""
    c = RAV4
    m, L = c["m"], c["L"]
    a, b = (1.0 - c["front_share"]) * L, c["front_share"] * L
    Iz = m * a * b
    w, z = c["w_phi"], c["zeta_phi"]
    Cf, Cr = fit_params["C_f"], fit_params["C_r"]
    tau = max(fit_params["tau_s"], 0.02)  # the fitted lag is ~5 ms; 20 ms keeps the model well scaled
    sig = max(fit_params["sigma"], 0.05)
    kphi = fit_params["k_phi"]
    g = 9.80665
    # states: delta_s, v_y, r, F_f, F_r, phi, p
    A = np.zeros((7, 7))
    A[0, 0] = -1.0 / tau
    lam = U0 / sig
    # F_f' = lam (Cf (delta - (vy + a r)/U0) - F_f)
    A[3, 0], A[3, 1], A[3, 2], A[3, 3] = lam * Cf, -lam * Cf / U0, -lam * Cf * a / U0, -lam
    A[4, 1], A[4, 2], A[4, 4] = -lam * Cr / U0, lam * Cr * b / U0, -lam
    A[1, 3], A[1, 4], A[1, 2] = 1.0 / m, 1.0 / m, -U0
    A[2, 3], A[2, 4] = a / Iz, -b / Iz
    A[5, 6] = 1.0
    A[6, 3], A[6, 4], A[6, 5], A[6, 6] = w * w * kphi / m, w * w * kphi / m, -w * w, -2 * z * w
    B = np.zeros((7, 1))
    B[0, 0] = 1.0 / tau
    C = np.zeros((4, 7))
    C[0, 3], C[0, 4], C[0, 5] = s_ay / m, s_ay / m, s_ay * g
    C[1, 2] = 1.0
    C[2, 2] = k_f
    C[3, 2] = k_r
    return LinearFaultModel(A, B, C, states=["delta_s", "v_y", "r", "F_f", "F_r", "phi", "p"],
                            inputs=["steer"], outputs=CHANNELS[1:],
                            faults=["actuator:steer"] + [f"sensor:{y}" for y in CHANNELS[1:]],
                            name=f"RAV4 lateral @ {U0:.1f} m/s")


def _preprocessing(raw: Signals, half_s: float, rate: float) -> tuple[Rav4Preprocessing, dict]:
    """Fit the model and the preprocessing on ``t <= half_s`` of ``raw``; the design record."""
    from ..rav4 import SIGNALS, fit_rav4

    col = {n: i for i, n in enumerate(raw.names)}
    v = raw.values[0]
    from ....io.can import LogSignals

    sel = v[:, [col[n] for n in ("steer_angle", "steer_fraction", "speed", "yaw_rate_raw", "accel_y_raw")]]
    fs = LogSignals(raw.t, sel[None], SIGNALS, valid=np.ones((1, *sel.shape), bool))
    fit = fit_rav4(signals=fs, rate=rate, holdout=False, fit_until=half_s)
    p = fit.params
    half = raw.t - raw.t[0] <= half_s
    U = v[:, col["speed"]]
    yaw = v[:, col["yaw_rate_raw"]] - p["b_r"]
    fd = v[:, col["wheel_fl"]] - v[:, col["wheel_fr"]]
    rd = v[:, col["wheel_rl"]] - v[:, col["wheel_rr"]]
    # wheel differences: k r + c U (track width x yaw rate; unequal rolling radii), calibration half
    X = np.column_stack([yaw, U])[half]
    kf, cf = np.linalg.lstsq(X, fd[half], rcond=None)[0]
    kr, cr = np.linalg.lstsq(X, rd[half], rcond=None)[0]
    pre = Rav4Preprocessing(RAV4["i_s"], p["delta_0"], p["b_r"], p["b_ay"], fit.ay_sign, cf, cr)
    uu, yy = pre.apply(v[:, [col[n] for n in _RAW_U]], v[:, [col[n] for n in _RAW_Y]])
    vals = np.column_stack([uu[:, 0], yy])
    # measurement noise: white part from first differences (sigma^2 = var(diff) / 2)
    noise = {n: float(np.std(np.diff(vals[half, i])) / np.sqrt(2)) for i, n in enumerate(CHANNELS)}
    rec = {"U_mean": float(U[half].mean()), "U_range": [float(U[half].min()), float(U[half].max())],
           "k_f": float(kf), "k_r": float(kr), "c_f": float(cf), "c_r": float(cr), "noise": noise,
           "fit": dict(p), "fit_on_s": [0.0, float(half_s)], "ay_sign": float(fit.ay_sign),
           "dt": float(np.mean(np.diff(raw.t))), "half_s": float(half_s)}
    return pre, rec
