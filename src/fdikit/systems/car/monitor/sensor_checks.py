"""The sensor-fault checks of the simulated car (issue 16): the analytic-redundancy channels
(:class:`CarSensorChannels`, fitted by :func:`fit_car_sensor_channels`) and the lateral monitor
with the stuck / drift / gain / intermittent detectors added (:func:`with_sensor_checks`); the
compiled second-order sections they filter with (shared with the RAV4 checks).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit

from ....base import ResidualGenerator
from ....detect import Hold
from ....errors import ModelError
from ....monitor import Decision, Monitor
from ....signals import Signals
from .calibration import CarMonitor

__all__ = ["CAR_SENSOR_CHANNELS", "CarSensorChannels", "fit_car_sensor_channels", "with_sensor_checks"]


@njit(cache=True)
def _biquads(x, b, a, first, z, started, out):  # pragma: no cover - compiled
    """Second-order sections, one per channel: x (R, T, C), b and a (C, 3), state z (R, C, 2);
    a channel with ``first[c]`` starts in steady state at its first sample, the others at rest
    (zero: a residual's nominal value); ``started`` (R,) flags."""
    R, T, C = x.shape
    for r in range(R):
        for k in range(T):
            if started[r] == 0:
                for c in range(C):
                    x0 = x[r, k, c] if first[c] else 0.0
                    z[r, c, 1] = (b[c, 2] - a[c, 2]) * x0
                    z[r, c, 0] = (b[c, 1] - a[c, 1]) * x0 + z[r, c, 1]
                started[r] = 1
            for c in range(C):
                v = x[r, k, c]
                y = b[c, 0] * v + z[r, c, 0]
                z[r, c, 0] = b[c, 1] * v - a[c, 1] * y + z[r, c, 1]
                z[r, c, 1] = b[c, 2] * v - a[c, 2] * y
                out[r, k, c] = y


#: Channels of :class:`CarSensorChannels`.
CAR_SENSOR_CHANNELS = ["chk:yaw_rate", "chk:yaw_expected", "chk:yaw_vs_ay", "chk:yaw_vs_rear", "chk:front",
                       "chk:rear", "chk:axles", "chk:speed"]


class CarSensorChannels(ResidualGenerator):
    """The channels the sensor-fault detectors read on the simulated car (issue 16), from its
    measurements: the yaw rate (``chk:yaw_rate``, unfiltered) and the yaw rate the lateral
    acceleration says at the wheel speed (``chk:yaw_expected = g a_y / w_rear_sum + c``,
    low-passed at ``band_hz[0]``); the yaw rate minus what the accelerometer and the rear
    wheel-speed difference say (``chk:yaw_vs_ay``, ``chk:yaw_vs_rear``, low-passed at
    ``band_hz[1]``); each axle's wheel-speed difference minus the yaw-rate kinematics and the
    front difference minus the scaled rear one (``chk:front``, ``chk:rear``, ``chk:axles``,
    ``band_hz[2]``); the rear wheel-speed sum (``chk:speed``, rad/s). The same checks as
    :class:`~fdikit.systems.car.monitor_rav4.Rav4SensorChannels` on the real car.

    Parameters
    ----------
    coef : dict
        ``ay`` (gain, offset), ``rear`` (gain, offset), ``k_f``, ``k_r`` (:func:`fit_car_sensor_channels`).
    dt : float
        Sample time (s).
    band_hz : sequence of 3 floats
        Low-pass cut-offs (Hz).

    Examples
    --------
    >>> g = CarSensorChannels({"ay": [2.0, 0.0], "rear": [0.5, 0.0], "k_f": 2.0, "k_r": 2.0}, 0.01)
    >>> g.reset(1)
    >>> out = g.step(np.zeros((1, 0)), [[2.0, 0.1, 0.2, 0.2, 40.0]])   # a_y, r, w_fd, w_rd, w_rs
    >>> (np.round(out[0], 6) + 0.0).tolist()
    [0.1, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 40.0]
    """

    _state_attrs = ("_z", "_started")

    def __init__(self, coef: Mapping[str, Any], dt: float, band_hz=(1.0, 0.2, 3.0)):
        from scipy.signal import butter

        self.coef = {"ay": [float(c) for c in coef["ay"]], "rear": [float(c) for c in coef["rear"]],
                     "k_f": float(coef["k_f"]), "k_r": float(coef["k_r"])}
        if len(self.coef["ay"]) != 2 or len(self.coef["rear"]) != 2 or self.coef["k_r"] == 0:
            raise ModelError(f"sensor-check coefficients need ay (2), rear (2), k_f, k_r != 0; "
                             f"got {self.coef}")
        self.dt = float(dt)
        self.band_hz = [float(f) for f in band_hz]
        if len(self.band_hz) != 3 or not all(0 < f < 0.5 / self.dt for f in self.band_hz):
            raise ModelError(f"band_hz must be 3 cut-offs in (0, {0.5 / self.dt:g}) Hz, got {list(band_hz)}")
        fc = [self.band_hz[0], self.band_hz[1], self.band_hz[1]] + [self.band_hz[2]] * 3
        ba = [butter(2, f * 2 * self.dt) for f in fc]
        self._b = np.array([b for b, _a in ba])
        self._a = np.array([a for _b, a in ba])
        self._first = np.array([1, 0, 0, 0, 0, 0], np.int64)
        self.u_names = []
        self.y_names = ["a_y", "yaw_rate", "w_front_diff", "w_rear_diff", "w_rear_sum"]
        self.output_names = list(CAR_SENSOR_CHANNELS)
        self.reset(1)

    def __repr__(self) -> str:
        return f"CarSensorChannels(dt={self.dt:g}, band_hz={self.band_hz}, coef={self.coef})"

    def to_dict(self) -> dict[str, Any]:
        return {"coef": self.coef, "dt": self.dt, "band_hz": self.band_hz}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CarSensorChannels:
        return cls(d["coef"], d["dt"], d["band_hz"])

    def reset(self, runs: int = 1) -> None:
        self._z = np.zeros((runs, 6, 2))
        self._started = np.zeros(runs, np.int64)

    def _compute(self, y: np.ndarray) -> np.ndarray:
        from ....errors import DataError

        ay, r, fd, rd = y[..., 0], y[..., 1], y[..., 2], y[..., 3]
        ws = np.maximum(np.abs(y[..., 4]), 1.0)
        c = self.coef
        raw = np.stack([c["ay"][0] * ay / ws, r - c["ay"][0] * ay / ws - c["ay"][1],
                        r - c["rear"][0] * rd - c["rear"][1], fd - c["k_f"] * r, rd - c["k_r"] * r,
                        fd - c["k_f"] / c["k_r"] * rd], axis=-1)
        if raw.shape[0] != self._z.shape[0]:
            raise DataError(f"sample has {raw.shape[0]} runs; the generator was reset for {self._z.shape[0]}")
        lp = np.empty_like(raw)
        _biquads(np.ascontiguousarray(raw), self._b, self._a, self._first, self._z, self._started, lp)
        lp[..., 0] += c["ay"][1]
        return np.concatenate([r[..., None], lp, y[..., 4:5]], axis=-1)

    def _step(self, u, y):
        return self._compute(y[:, None])[:, 0]

    def run(self, signals: Signals) -> Signals:
        _u, y = self._inputs(signals)
        self.reset(signals.runs)
        return Signals(signals.t, self._compute(y), self.output_names, check=False)


def fit_car_sensor_channels(nominal: Signals, dt: float, *, band_hz=(1.0, 0.2, 3.0),
                            settle: float = 2.0) -> CarSensorChannels:
    """:class:`CarSensorChannels` with its coefficients fitted by least squares on nominal
    (fault-free) drives (the first ``settle`` s of each left out)."""
    from scipy.signal import butter, lfilter, lfilter_zi

    y = nominal.values[:, :, nominal.index(["a_y", "yaw_rate", "w_front_diff", "w_rear_diff", "w_rear_sum"])]
    keep = nominal.t - nominal.t[0] >= settle
    b, a = butter(2, band_hz[1] * 2 * dt)
    lp = lambda x: lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])[0]  # noqa: E731
    cols = {k: [] for k in ("r", "ay", "rd", "fd")}
    for run in range(y.shape[0]):
        ay, r, fd, rd, ws = (y[run, :, i] for i in range(5))
        ws = np.maximum(np.abs(ws), 1.0)
        cols["r"].append(r[keep])
        cols["ay"].append(ay[keep] / ws[keep])
        cols["rd"].append(rd[keep])
        cols["fd"].append(fd[keep])
        cols.setdefault("lr", []).append(lp(r)[keep])
        cols.setdefault("lay", []).append(lp(ay / ws)[keep])
        cols.setdefault("lrd", []).append(lp(rd)[keep])
    v = {k: np.concatenate(x) for k, x in cols.items()}
    one = np.ones_like(v["r"])
    ca = np.linalg.lstsq(np.c_[v["lay"], one], v["lr"], rcond=None)[0]
    cr = np.linalg.lstsq(np.c_[v["lrd"], one], v["lr"], rcond=None)[0]
    kf = float(np.linalg.lstsq(v["r"][:, None], v["fd"], rcond=None)[0][0])
    kr = float(np.linalg.lstsq(v["r"][:, None], v["rd"], rcond=None)[0][0])
    return CarSensorChannels({"ay": ca.tolist(), "rear": cr.tolist(), "k_f": kf, "k_r": kr}, dt, band_hz)


def with_sensor_checks(mon: CarMonitor, nominal: Signals, *, warmup: float = 2.0, hold: int = 5,
                       pfa: float = 1.0, per="hour", margin: float = 0.0, drift_window: float = 10.0,
                       drift_min: float = 1.0, gain_window: float = 2.0, gain_min: float = 0.5,
                       min_gain: float = 0.003, burst_window: float = 5.0, min_bursts: int = 2) -> CarMonitor:
    """A lateral :class:`CarMonitor` with the sensor-fault detectors of issue 16 added (an opt-in:
    the paper's monitor and its numbers are unchanged without it).

    :class:`CarSensorChannels` is fitted on ``nominal`` (fault-free drives, monitor inputs) and
    the detectors are designed on it (:func:`~fdikit.detect.design_stuck`, ``design_drift``,
    ``design_gain``, ``design_intermittent``; thresholds for ``pfa`` false alarms per ``per``):
    stuck yaw-rate sensor (against the yaw rate the accelerometer says), yaw-rate drift (signature
    on the checks against the accelerometer and the rear wheels), wheel-speed-difference gain
    (front / rear, with the other axle and the yaw rate as rivals) and intermittent
    wheel-speed difference. Announcements name the sensor and the fault type
    (``"yaw_rate:stuck"``, ``"yaw_rate:drift"``, ``"w_front_diff:gain"``,
    ``"w_rear_diff:intermittent"``).

    Returns
    -------
    CarMonitor
        The same design and calibration; ``monitor`` with the extra generator and processors,
        ``info["sensor_checks"]`` the detectors.
    """
    from ....detect import design_drift, design_gain, design_intermittent, design_stuck

    if mon.block != "lateral":
        raise ModelError(f"sensor checks are for the lateral block, got {mon.block!r}")
    dt = mon.design.dt
    chk = fit_car_sensor_channels(nominal, dt, settle=warmup)
    x = chk.run(nominal)
    n = lambda s: max(1, round(s / dt))  # noqa: E731
    skip = n(warmup)
    kw = dict(pfa=pfa, per=per, margin=margin, skip=skip)
    sigs = {"front": (1, 0, 1), "rear": (0, 1, -1), "yaw": (1, 1, 0)}
    kfr = abs(chk.coef["k_f"] / chk.coef["k_r"])
    dets = [
        design_stuck(x, "chk:yaw_rate", "chk:yaw_expected", min_samples="auto", skip=skip),
        design_drift(x, ["chk:yaw_vs_ay", "chk:yaw_vs_rear"], n(drift_window), signature=(1, 1),
                     name="chk:yaw_drift", min_length=n(drift_min), vs_step=True, **kw),
        *[design_gain(x, ["chk:front", "chk:rear", "chk:axles"], "chk:speed", n(gain_window),
                      min_length=n(gain_min), signature=sigs[a], name=f"chk:{a}", min_gain=min_gain,
                      gain_scale=(1.0, 1.0, 1.0) if a == "front" else (1.0, 1.0, kfr),
                      rivals=[v for k, v in sigs.items() if k != a], **kw) for a in ("front", "rear")],
        design_intermittent(x, ["chk:front", "chk:rear"], n(burst_window), min_bursts=min_bursts, gap=n(0.2),
                            skip=skip),
    ]
    names = {"chk:yaw_rate:stuck": "yaw_rate:stuck", "chk:yaw_drift:drift": "yaw_rate:drift",
             "chk:front:gain": "w_front_diff:gain", "chk:rear:gain": "w_rear_diff:gain",
             "chk:front:intermittent": "w_front_diff:intermittent",
             "chk:rear:intermittent": "w_rear_diff:intermittent"}
    shold = Hold(list(names), 1.0, Z=max(1, int(hold)), absolute=False)
    old = mon.monitor
    dec = Decision([*old.decision.alarm_channels, *shold.output_names], level=old.decision.level,
                   names={**old.decision.names, **{f"{s}:alarm": v for s, v in names.items()}})
    new = Monitor([*old.generators, chk], [*old.processors, *dets, shold], dec)
    info = {**mon.info, "sensor_checks": [repr(d) for d in dets], "sensor_channels": chk.coef}
    return dataclasses.replace(mon, monitor=new, info=info)
