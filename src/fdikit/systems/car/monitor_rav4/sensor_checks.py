"""The RAV4 sensor-fault checks (issue 16): the analytic-redundancy channels on the raw CAN
signals (:class:`Rav4SensorChannels`, fitted by :func:`fit_sensor_channels`) and the generic
stuck / drift / gain / intermittent detectors designed on them (:func:`design_sensor_detectors`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ....base.stage import ResidualGenerator
from ....errors import DataError
from ....signals import Signals
from ..monitor.sensor_checks import _biquads
from .channels import _RAW_U, _RAW_Y, Rav4Preprocessing

__all__ = ["SENSOR_CHANNELS", "Rav4SensorChannels", "design_sensor_detectors", "fit_sensor_channels"]


#: Channels of :class:`Rav4SensorChannels` (what the sensor-fault detectors read).
SENSOR_CHANNELS = ["chk:steer", "chk:steer_expected", "chk:yaw_vs_ay", "chk:yaw_vs_rear", "chk:front",
                   "chk:rear", "chk:axles", "chk:speed"]


class Rav4SensorChannels(ResidualGenerator):
    """The channels the RAV4 sensor-fault detectors read, from the raw CAN channels.

    * ``chk:steer`` -- the measured road-wheel angle (rad), unfiltered (a frozen sensor repeats
      its value exactly);
    * ``chk:steer_expected`` -- the road-wheel angle the yaw rate and the speed say
      (steady-state single track, ``c_1 r / U + c_2 r U + c_0``, fitted on the calibration half),
      low-passed at ``band_hz[0]``;
    * ``chk:yaw_vs_ay`` -- yaw rate minus what the accelerometer says (``a_y / U`` scaled),
      ``chk:yaw_vs_rear`` -- yaw rate minus what the rear wheel-speed difference says (the rear
      wheels are not steered), both low-passed at ``band_hz[1]`` (rad/s): a yaw-rate sensor
      fault moves both, an accelerometer or rear wheel-speed fault one;
    * ``chk:front``, ``chk:rear`` -- each axle's wheel-speed difference minus the yaw-rate
      kinematics (``k r``), and ``chk:axles`` -- the front difference minus the rear one scaled
      (``k_f / k_r``: both are the same yaw rate), low-passed at ``band_hz[2]`` (m/s): a front
      wheel-speed fault moves ``chk:front`` and ``chk:axles``, a rear one ``chk:rear`` and
      ``chk:axles`` (the other sign), a yaw-rate fault ``chk:front`` and ``chk:rear``;
    * ``chk:speed`` -- the vehicle speed (m/s).

    Parameters
    ----------
    pre : Rav4Preprocessing
    coef : dict
        ``steer`` (c_1, c_2, c_0), ``ay`` (gain, offset), ``rear`` (gain, offset), ``k_f``, ``k_r``.
    dt : float
        Sample time (s).
    band_hz : sequence of 3 floats
        Low-pass cut-offs (Hz) of the steering prediction, the yaw checks and the axle checks.

    Examples
    --------
    >>> pre = Rav4Preprocessing(16.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    >>> coef = {"steer": [2.6, 0.0, 0.0], "ay": [1.0, 0.0], "rear": [1.0, 0.0], "k_f": 1.5, "k_r": 1.0}
    >>> g = Rav4SensorChannels(pre, coef, 0.02)
    >>> g.reset(1)
    >>> out = g.step([0.16, 0.0, 20.0], [0.1, 2.0, 20.15, 20.0, 20.1, 20.0])   # r = 0.1, a_y = U r
    >>> # (k_f / k_r = 1.5: the front difference 0.15 = 1.5 x the rear one)
    >>> (np.round(out[0], 6) + 0.0).tolist()
    [0.01, 0.013, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0]
    """

    _state_attrs = ("_z", "_started")

    def __init__(self, pre: Rav4Preprocessing, coef: dict[str, Any], dt: float, band_hz=(1.0, 0.1, 3.0)):
        from scipy.signal import butter

        self.pre = pre
        self.coef = {"steer": [float(c) for c in coef["steer"]], "ay": [float(c) for c in coef["ay"]],
                     "rear": [float(c) for c in coef["rear"]], "k_f": float(coef["k_f"]),
                     "k_r": float(coef["k_r"])}
        if len(self.coef["steer"]) != 3 or len(self.coef["ay"]) != 2 or len(self.coef["rear"]) != 2:
            raise DataError(f"sensor-check coefficients need steer (3), ay (2), rear (2); got {self.coef}")
        self.dt = float(dt)
        self.band_hz = [float(f) for f in band_hz]
        if len(self.band_hz) != 3 or not all(0 < f < 0.5 / self.dt for f in self.band_hz):
            raise DataError(f"band_hz must be 3 cut-offs in (0, {0.5 / self.dt:g}) Hz, got {list(band_hz)}")
        fc = [self.band_hz[0], self.band_hz[1], self.band_hz[1]] + [self.band_hz[2]] * 3
        ba = [butter(2, f * 2 * self.dt) for f in fc]
        self._b = np.array([b for b, _a in ba])
        self._a = np.array([a for _b, a in ba])
        self._first = np.array([1, 0, 0, 0, 0, 0], np.int64)    # the steering prediction starts at its value
        self.u_names, self.y_names = list(_RAW_U), list(_RAW_Y)
        self.output_names = list(SENSOR_CHANNELS)
        self.output_units = ["rad", "rad", "rad/s", "rad/s", "m/s", "m/s", "m/s", "m/s"]
        self.reset(1)

    def __repr__(self) -> str:
        return f"Rav4SensorChannels(dt={self.dt:g}, band_hz={self.band_hz}, coef={self.coef})"

    def to_dict(self) -> dict[str, Any]:
        return {"pre": self.pre.to_dict(), "coef": self.coef, "dt": self.dt, "band_hz": self.band_hz}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Rav4SensorChannels:
        return cls(Rav4Preprocessing.from_dict(d["pre"]), d["coef"], d["dt"], d["band_hz"])

    def reset(self, runs: int = 1) -> None:
        self._z = np.zeros((runs, 6, 2))
        self._started = np.zeros(runs, np.int64)

    @staticmethod
    def regressors(pre: Rav4Preprocessing, u: np.ndarray, y: np.ndarray):
        """Monitor channels of raw ``u`` (..., 3) and ``y`` (..., 6): ``steer, U, a_y, r, fd, rd``."""
        uu, yy = pre.apply(u, y)
        U = np.maximum(uu[..., 1], 1.0)                  # (standing still: no lateral kinematics)
        return uu[..., 0], U, yy[..., 0], yy[..., 1], yy[..., 2], yy[..., 3]

    def _compute(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        steer, U, ay, r, fd, rd = self.regressors(self.pre, u, y)
        c = self.coef
        raw = np.stack([c["steer"][0] * r / U + c["steer"][1] * r * U, r - c["ay"][0] * ay / U - c["ay"][1],
                        r - c["rear"][0] * rd - c["rear"][1], fd - c["k_f"] * r, rd - c["k_r"] * r,
                        fd - c["k_f"] / c["k_r"] * rd], axis=-1)
        if not np.all(np.isfinite(raw)):
            run, k, j = np.argwhere(~np.isfinite(raw))[0]
            raise DataError(f"sensor-check channel {SENSOR_CHANNELS[j + 1]!r} is not finite at sample {k} "
                            f"(run {run})")
        lp = np.empty_like(raw)
        if raw.shape[0] != self._z.shape[0]:
            raise DataError(f"sample has {raw.shape[0]} runs; the generator was reset for {self._z.shape[0]}")
        _biquads(np.ascontiguousarray(raw), self._b, self._a, self._first, self._z, self._started, lp)
        lp[..., 0] += c["steer"][2]
        return np.concatenate([steer[..., None], lp, U[..., None]], axis=-1)

    def _step(self, u, y):
        return self._compute(u[:, None], y[:, None])[:, 0]

    def run(self, signals: Signals) -> Signals:
        u, y = self._inputs(signals)
        self.reset(signals.runs)
        return Signals(signals.t, self._compute(u, y), self.output_names, self.output_units, check=False)


def fit_sensor_channels(raw: Signals, half_s: float, pre: Rav4Preprocessing, rec: dict,
                        band_hz=(1.0, 0.1, 3.0), settle: float = 5.0) -> Rav4SensorChannels:
    """:class:`Rav4SensorChannels` with its coefficients fitted on ``t <= half_s`` of ``raw`` (least
    squares on the low-passed signals, the first ``settle`` s left out)."""
    dt = float(np.mean(np.diff(raw.t)))
    probe = Rav4SensorChannels(pre, {"steer": [1.0, 0.0, 0.0], "ay": [0.0, 0.0], "rear": [0.0, 0.0],
                                     "k_f": 0.0, "k_r": 0.0}, dt, band_hz)
    u, y = probe._inputs(raw)
    steer, U, ay, r, _fd, rd = (x[0] for x in probe.regressors(pre, u, y))
    t = raw.t - raw.t[0]
    cal = (t <= half_s) & (t >= settle)

    def lp(x, f):
        from scipy.signal import butter, lfilter, lfilter_zi

        b, a = butter(2, f * 2 * dt)
        return lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])[0]

    f0, f1 = band_hz[0], band_hz[1]
    X = np.column_stack([lp(r / U, f0), lp(r * U, f0), np.ones_like(U)])
    cs = np.linalg.lstsq(X[cal], steer[cal], rcond=None)[0]
    Xa = np.column_stack([lp(ay / U, f1), np.ones_like(U)])
    ca = np.linalg.lstsq(Xa[cal], lp(r, f1)[cal], rcond=None)[0]
    Xr = np.column_stack([lp(rd, f1), np.ones_like(U)])
    cr = np.linalg.lstsq(Xr[cal], lp(r, f1)[cal], rcond=None)[0]
    coef = {"steer": cs.tolist(), "ay": [float(ca[0]), float(ca[1])], "rear": [float(cr[0]), float(cr[1])],
            "k_f": rec["k_f"], "k_r": rec["k_r"]}
    return Rav4SensorChannels(pre, coef, dt, band_hz)


def design_sensor_detectors(nominal: Signals, dt: float, *, skip: int = 0, pfa: float = 1.0, per="hour",
                            margin: float = 0.0, drift_window: float = 20.0, drift_min: float = 2.0,
                            gain_window: float = 5.0, gain_min: float = 1.0, burst_window: float = 10.0,
                            min_bursts: int = 2, burst_margin: float = 0.5, stuck_margin: float = 0.5,
                            min_gain: float = 0.003, nominal_coef: dict | None = None):
    """The RAV4 sensor-fault detectors, calibrated on nominal :class:`Rav4SensorChannels` outputs.

    * stuck steering: :class:`~fdikit.detect.StuckDetector` on ``chk:steer`` against the steering
      the yaw rate says (``chk:steer_expected``): frozen for longer than the longest frozen run of
      the nominal data (the CAN angle legitimately repeats itself for up to 1.5 s on the highway)
      while the expected steering moved more than it does in half of all windows of that length,
      times ``1 + stuck_margin``;
    * yaw-rate drift: :class:`~fdikit.detect.DriftDetector` with the signature (+1, +1) on
      ``chk:yaw_vs_ay`` and ``chk:yaw_vs_rear`` (both must ramp: an accelerometer or rear-wheel
      fault ramps one), ramps told from steps (``vs_step``);
    * wheel-speed gain: :class:`~fdikit.detect.GainDetector` against the speed on
      (``chk:front``, ``chk:rear``, ``chk:axles``) with the signature (1, 0, 1) for a front wheel
      and (0, 1, -1) for a rear one, each with the other axle's and the yaw rate's (1, 1, 0) as
      rivals, and an indifference zone ``min_gain`` (0.3 %: a rolling-radius difference from
      tyre wear; ``nominal_coef``, the channels' coefficients, gives the axle ratio); the sign
      names the wheel (+: the left wheel reads high, a left gain > 1; -: the right one);
    * intermittent wheel speed: :class:`~fdikit.detect.IntermittentDetector` (signed) on
      ``chk:front`` and ``chk:rear``: ``min_bursts`` episodes within ``burst_window`` s, each above
      the largest nominal value times ``1 + burst_margin``.

    The thresholds are for ``pfa`` false alarms per ``per`` (default one per hour): half a minute
    of real data is far too short to show that rate, so :func:`~fdikit.detect.design_stuck` and
    the others scale the nominal maximum by the growth of an exponential tail's maximum
    (``ln n_target / ln n_eff``), times ``1 + margin``.

    Returns
    -------
    (list of detectors, dict statistic -> announced name)
    """
    from ....detect import design_drift, design_gain, design_intermittent, design_stuck

    n = lambda s: max(1, round(s / dt))  # noqa: E731
    kw = dict(pfa=pfa, per=per, margin=margin, skip=skip)
    stuck = design_stuck(nominal, "chk:steer", "chk:steer_expected", min_samples="auto", margin=stuck_margin,
                         skip=skip)
    drift = design_drift(nominal, ["chk:yaw_vs_ay", "chk:yaw_vs_rear"], n(drift_window), signature=(1, 1),
                         name="chk:yaw_rate", min_length=n(drift_min), vs_step=True, **kw)
    # residuals (front, rear, axles): front wheel (1, 0, 1), rear wheel (0, 1, -1), yaw rate (1, 1, 0)
    sigs = {"front": (1, 0, 1), "rear": (0, 1, -1), "yaw": (1, 1, 0)}
    kfr = abs(float(nominal_coef["k_f"] / nominal_coef["k_r"])) if nominal_coef else 1.0
    scale = {"front": (1.0, 1.0, 1.0), "rear": (1.0, 1.0, kfr)}      # how much of the gain reaches each
    gains = [design_gain(nominal, ["chk:front", "chk:rear", "chk:axles"], "chk:speed", n(gain_window),
                         min_length=n(gain_min), signature=sigs[a], name=f"chk:{a}",
                         rivals=[v for k, v in sigs.items() if k != a], min_gain=min_gain,
                         gain_scale=scale[a], **kw) for a in ("front", "rear")]
    burst = design_intermittent(nominal, ["chk:front", "chk:rear"], n(burst_window), min_bursts=min_bursts,
                                gap=n(0.2), margin=burst_margin, signed=True, skip=skip)
    names = {"chk:steer:stuck": "steering:stuck", "chk:yaw_rate:drift": "yaw_rate:drift",
             "chk:front:gain+": "wheel_fl:gain", "chk:front:gain-": "wheel_fr:gain",
             "chk:rear:gain+": "wheel_rl:gain", "chk:rear:gain-": "wheel_rr:gain",
             "chk:front:intermittent+": "wheel_fl:intermittent",
             "chk:front:intermittent-": "wheel_fr:intermittent",
             "chk:rear:intermittent+": "wheel_rl:intermittent",
             "chk:rear:intermittent-": "wheel_rr:intermittent"}
    return [stuck, drift, *gains, burst], names
