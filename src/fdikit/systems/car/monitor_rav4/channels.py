"""The RAV4 log's channels: what the monitor reads from CAN and how it becomes the monitor channels.

The raw CAN sources in SI units (:data:`RAW_SOURCES`), the monitor channels (:data:`CHANNELS`)
and the faults the lateral monitor isolates on them (:data:`RAV4_FAULTS`); the fitted
preprocessing map from one to the other (:class:`Rav4Preprocessing`) and the loader of the real
log onto one time grid (:func:`load_rav4_raw`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ....errors import DataError
from ....signals import Signals
from ..rav4 import default_data_path

__all__ = ["CHANNELS", "RAV4_FAULTS", "RAW_CHANNELS", "RAW_SOURCES", "Rav4Preprocessing", "load_rav4_raw"]


#: Monitored faults of the RAV4 lateral monitor -> (monitor channel the fault is injected on, magnitudes).
RAV4_FAULTS: dict[str, tuple[str, tuple[float, ...]]] = {
    "steering": ("steer", (-0.004, -0.006, -0.008, -0.010)),   # sensor +x = actuator -x (rad road wheel)
    "lateral_accelerometer": ("a_y", (0.3, 0.5, 0.7, 0.9)),     # m/s^2
    "yaw_rate": ("yaw_rate", (0.01, 0.02, 0.03, 0.04)),          # rad/s (0.6 .. 2.3 deg/s)
    "front_wheel_diff": ("w_front_diff", (0.3, 0.5, 0.7, 0.9)),  # m/s on one front wheel
    "rear_wheel_diff": ("w_rear_diff", (0.3, 0.5, 0.7, 0.9)),    # m/s on one rear wheel
}
_WHEEL = {"wheel_fl": ("w_front_diff", 1.0), "wheel_fr": ("w_front_diff", -1.0),
          "wheel_rl": ("w_rear_diff", 1.0), "wheel_rr": ("w_rear_diff", -1.0)}
#: Monitor channels after preprocessing (SI, offset-free; ``steer`` is the road-wheel angle).
CHANNELS = ["steer", "a_y", "yaw_rate", "w_front_diff", "w_rear_diff"]
#: Raw channels the runtime reads (SI units: rad, m/s, rad/s, m/s^2) -> CAN signal and the
#: scale from the DBC unit to SI (what a monitor config's [channels] table states).
RAW_SOURCES: dict[str, tuple[str, float, str]] = {
    "steer_angle": ("STEER_ANGLE_SENSOR.STEER_ANGLE", np.pi / 180.0, "rad"),
    "steer_fraction": ("STEER_ANGLE_SENSOR.STEER_FRACTION", np.pi / 180.0, "rad"),
    "speed": ("SPEED.SPEED", 1.0 / 3.6, "m/s"),
    "yaw_rate_raw": ("KINEMATICS.YAW_RATE", np.pi / 180.0, "rad/s"),
    "accel_y_raw": ("KINEMATICS.ACCEL_Y", 1.0, "m/s^2"),
    "wheel_fl": ("WHEEL_SPEEDS.WHEEL_SPEED_FL", 1.0 / 3.6, "m/s"),
    "wheel_fr": ("WHEEL_SPEEDS.WHEEL_SPEED_FR", 1.0 / 3.6, "m/s"),
    "wheel_rl": ("WHEEL_SPEEDS.WHEEL_SPEED_RL", 1.0 / 3.6, "m/s"),
    "wheel_rr": ("WHEEL_SPEEDS.WHEEL_SPEED_RR", 1.0 / 3.6, "m/s"),
}
RAW_CHANNELS = list(RAW_SOURCES)
_RAW_U = ["steer_angle", "steer_fraction", "speed"]
_RAW_Y = ["yaw_rate_raw", "accel_y_raw", "wheel_fl", "wheel_fr", "wheel_rl", "wheel_rr"]


class Rav4Preprocessing:
    """Fitted map from the raw CAN channels (SI) to the monitor channels.

    ``steer = (steer_angle + steer_fraction - delta_0) / i_s`` (road-wheel angle, rad),
    ``a_y = s_ay (accel_y_raw - b_ay)`` (left positive), ``yaw_rate = yaw_rate_raw - b_r``,
    ``w_front_diff = wheel_fl - wheel_fr - c_f speed``, ``w_rear_diff = wheel_rl - wheel_rr - c_r speed``.

    Parameters
    ----------
    i_s, delta_0, b_r, b_ay, ay_sign, c_f, c_r : float
        Steering ratio, hand-wheel angle offset (rad), yaw-rate offset (rad/s), accelerometer
        offset (m/s^2), sign of the accelerometer axis (+1 left positive), speed-proportional part
        of the front and rear wheel-speed differences (unequal rolling radii; dimensionless).

    Examples
    --------
    >>> p = Rav4Preprocessing(16.0, 0.016, 0.01, 0.1, -1.0, 0.0, 0.001)
    >>> u, y = p.apply(np.array([[0.16, 0.0, 20.0]]), np.array([[0.02, 0.6, 10.1, 10.0, 10.2, 10.0]]))
    >>> np.round(u, 6).tolist(), np.round(y, 6).tolist()
    ([[0.009, 20.0]], [[-0.5, 0.01, 0.1, 0.18]])
    """

    KEYS = ("i_s", "delta_0", "b_r", "b_ay", "ay_sign", "c_f", "c_r")

    def __init__(self, i_s: float, delta_0: float, b_r: float, b_ay: float, ay_sign: float, c_f: float,
                 c_r: float):
        vals = dict(zip(self.KEYS, (i_s, delta_0, b_r, b_ay, ay_sign, c_f, c_r), strict=True))
        for k, v in vals.items():
            if not np.isfinite(v):
                raise DataError(f"preprocessing parameter {k} must be finite, got {v}")
            setattr(self, k, float(v))
        if self.i_s <= 0 or self.ay_sign not in (-1.0, 1.0):
            raise DataError(f"steering ratio must be > 0 and ay_sign +-1, got {self.i_s}, {self.ay_sign}")

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in self.KEYS}

    @classmethod
    def from_dict(cls, d: dict[str, float]) -> Rav4Preprocessing:
        return cls(*(float(d[k]) for k in cls.KEYS))

    def apply(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw ``u`` (..., 3: steer_angle, steer_fraction, speed) and ``y`` (..., 6: yaw_rate_raw,
        accel_y_raw, wheel_fl, wheel_fr, wheel_rl, wheel_rr) -> ``(steer, speed)`` (..., 2) and
        ``(a_y, yaw_rate, w_front_diff, w_rear_diff)`` (..., 4)."""
        U = u[..., 2]
        steer = (u[..., 0] + u[..., 1] - self.delta_0) / self.i_s
        ay = self.ay_sign * (y[..., 1] - self.b_ay)
        yaw = y[..., 0] - self.b_r
        fd = y[..., 2] - y[..., 3] - self.c_f * U
        rd = y[..., 4] - y[..., 5] - self.c_r * U
        return np.stack([steer, U], axis=-1), np.stack([ay, yaw, fd, rd], axis=-1)


def load_rav4_raw(path: str | Path | None = None, rate: float = 50.0) -> Signals:
    """The raw channels :data:`RAW_CHANNELS` of the real log in SI units, on one ``rate`` grid.

    Parameters
    ----------
    path : path-like, optional
        Data directory with ``drive.blf`` and ``toyota_rav4.dbc`` (default :func:`default_data_path`).
    rate : float
        Grid rate (Hz).

    Returns
    -------
    Signals
        One run, T samples (the log's own time axis, s), channels :data:`RAW_CHANNELS`.

    Examples
    --------
    >>> s = load_rav4_raw()                                # doctest: +SKIP
    >>> s.names[:3]                                        # doctest: +SKIP
    ['steer_angle', 'steer_fraction', 'speed']
    """
    from ....io import read_can_log

    d = Path(path) if path is not None else default_data_path()
    blf, dbc = d / "drive.blf", d / "toyota_rav4.dbc"
    if not blf.exists() or not dbc.exists():
        raise DataError(f"RAV4 data not found: need {blf} and {dbc}")
    srcs = [RAW_SOURCES[n][0] for n in RAW_CHANNELS]
    s = read_can_log(blf, dbc, srcs, rate=rate)
    breaks = getattr(s, "breaks", [])
    if breaks:  # the design fits and calibrates on this log: it needs one contiguous grid
        raise DataError(f"the RAV4 log {blf} is not contiguous: {breaks[0][2]} (grid time "
                        f"{breaks[0][0]:.3f} s -> {breaks[0][1]:.3f} s); the RAV4 design fits its model on "
                        "the log itself. Run a designed monitor on it instead (fdikit monitor LOG --config "
                        "examples/rav4-lateral/monitor.toml), which holds over the break and judges both "
                        "sides")
    if not s.valid.all():
        bad = [n for i, n in enumerate(s.names) if not s.valid[0, :, i].all()]
        raise DataError(f"the RAV4 log has gaps in {bad}")
    # the same conversion a monitor config states: value = scale * source
    v = s.values * np.array([RAW_SOURCES[n][1] for n in RAW_CHANNELS])
    return Signals(s.t, v, RAW_CHANNELS, [RAW_SOURCES[n][2] for n in RAW_CHANNELS], check=False)
