"""Automated driving of the passenger car: a speed controller (throttle and brake), a path
controller (steering), a test track, and the scenarios of ng-chen-speyer, Section V.

The car in the paper runs under automatic control (California PATH Buick LeSabre) while a
driver injects real actuator faults — extra brake pressure, extra steering angle — that the
controllers then fight (Section V-A). Here:

* :class:`DrivingCar` appends the planar position and heading (X, Y, psi) to
  :class:`~fdikit.systems.car.PassengerCar` and adds two navigation outputs, the
  lateral offset from the path and the heading error (PATH's cars measured the offset with
  magnetic markers in the road); every sensor of the car stays an output, so sensor faults
  (``"sensor:<output>"``) and actuator faults (``"actuator:throttle" | "brake" | "steer"``) are
  injected by :func:`fdikit.sim.simulate` exactly as in the linear models;
* :class:`Track`: a straight followed by a constant-radius left curve;
* :class:`DriveController`: PI speed control through a desired acceleration split into throttle
  (with the trim throttle as feed-forward) and brake, and a path controller with curvature
  feed-forward through the understeer gradient plus offset and heading feedback;
* :func:`driving_scenario`: straight at constant speed, speed changes, and the curved track on a
  slight slope, at 20 or 24 m/s, with optional faults.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ModelError
from ...model.nonlinear import NonlinearModel
from .model import INPUTS, OUTPUTS, PassengerCar

__all__ = ["DRIVE_OUTPUTS", "FAULTS", "DriveController", "DrivingCar", "Track", "driving_scenario",
           "simulate_drive"]

#: Outputs of :class:`DrivingCar`: the car's sensors plus the navigation measurements.
DRIVE_OUTPUTS = [*OUTPUTS, "lateral_offset", "heading_error"]

#: Every fault of the paper as a fault name of the nonlinear simulation and of the linear models.
FAULTS = [f"sensor:{y}" for y in OUTPUTS] + ["actuator:throttle", "actuator:brake", "actuator:steer"]


@dataclass(frozen=True)
class Track:
    """A straight of length ``straight`` (m) along +X from the origin, then a left curve of radius
    ``radius`` (m) (``radius = inf``: straight only).

    Examples
    --------
    >>> tr = Track(straight=100.0, radius=200.0)
    >>> tr.errors(np.array([50.0]), np.array([0.5]), np.array([0.01]))
    (array([0.5]), array([0.01]), array([0.]))
    """

    straight: float = 100.0
    radius: float = np.inf

    def errors(self, X: np.ndarray, Y: np.ndarray, psi: np.ndarray):
        """Lateral offset (m, left of the path positive), heading error (rad) and path curvature
        (1/m) at the nearest path point, vectorised."""
        X, Y, psi = np.broadcast_arrays(np.asarray(X, float), np.asarray(Y, float), np.asarray(psi, float))
        e_y = Y.copy()
        e_psi = psi.copy()
        kappa = np.zeros_like(X)
        if np.isfinite(self.radius):
            R = self.radius
            on_curve = X > self.straight
            cx, cy = self.straight, R  # centre of the left curve
            dx, dy = X - cx, Y - cy
            dist = np.hypot(dx, dy)
            theta = np.arctan2(dx, -dy)  # path angle travelled on the curve
            e_y = np.where(on_curve, R - dist, e_y)
            e_psi = np.where(on_curve, np.angle(np.exp(1j * (psi - theta))), e_psi)
            kappa = np.where(on_curve, 1.0 / R, 0.0)
        return e_y, e_psi, kappa


class DrivingCar(NonlinearModel):
    """The passenger car with planar position and heading, on a :class:`Track`.

    States: :class:`PassengerCar` states + ``X, Y, psi`` (m, m, rad). Inputs and parameters as the
    car. Outputs :data:`DRIVE_OUTPUTS`.

    Examples
    --------
    >>> dc = DrivingCar(Track(100.0, 300.0))
    >>> x0, u0 = dc.cruise(20.0)
    >>> dc.f(0.0, x0[None], u0[None], dc.params)[0, -3:].round(9).tolist()  # X' = 20, Y' = 0, psi' = 0
    [20.0, 0.0, 0.0]
    """

    def __init__(self, track: Track | None = None, car: PassengerCar | None = None,
                 params: Mapping[str, float] | None = None):
        self.car = car or PassengerCar(params)
        self.track = track or Track()
        super().__init__(states=[*self.car.states, "X", "Y", "psi"], inputs=INPUTS, outputs=DRIVE_OUTPUTS,
                         params=self.car.params, groups={"u": ["throttle", "brake", "steer"], "d": ["slope"]},
                         units={**self.car.units, "X": "m", "Y": "m", "psi": "rad", "lateral_offset": "m",
                                "heading_error": "rad"}, name="passenger car on a track")

    def f(self, t, x, u, p):
        x = np.atleast_2d(np.asarray(x, float))
        dx = np.empty_like(x)
        dx[:, :22] = self.car.f(t, x[:, :22], u, p)
        vx, vy, r, psi = x[:, 2], x[:, 14], x[:, 17], x[:, 24]
        c, s = np.cos(psi), np.sin(psi)
        dx[:, 22] = vx * c - vy * s
        dx[:, 23] = vx * s + vy * c
        dx[:, 24] = r
        return dx

    def h(self, t, x, u, p):
        x = np.atleast_2d(np.asarray(x, float))
        y = np.empty((x.shape[0], len(DRIVE_OUTPUTS)))
        y[:, :11] = self.car.h(t, x[:, :22], u, p)
        e_y, e_psi, _ = self.track.errors(x[:, 22], x[:, 23], x[:, 24])
        y[:, 11] = e_y
        y[:, 12] = e_psi
        return y

    def cruise(self, speed: float, slope: float = 0.0):
        """Straight-driving trim with the position at the origin: ``(x0 (25,), u0 (4,))``."""
        x, u = self.car.cruise(speed, slope=slope)
        return np.r_[x, 0.0, 0.0, 0.0], u


class DriveController:
    """Speed and path controller of the automated car, vectorised over runs.

    Speed: PI on the speed error (speed measured from the rear, undriven wheel-speed sensors),
    giving a desired acceleration ``a_des`` (an internal command, clipped to +-10 m/s^2);
    throttle = trim throttle at the reference speed + ``a_des / g_thr`` (``g_thr``: acceleration
    per degree of throttle near cruise, from the trims on a 1 % slope) when ``a_des`` is above the
    coasting deceleration, brake pressure = ``(a_coast - a_des) * m r_w / (k_bf + k_br)`` below it;
    the integrator is frozen while the acting actuator saturates (anti-windup). Path: steering =
    curvature feed-forward ``kappa (L + K_us v^2)`` - ``k_y e_y`` - ``k_psi e_psi`` - ``k_i int e_y``
    with gains giving the kinematic path-error dynamics (``e_y' = v e_psi``,
    ``e_psi' = v delta / L - v kappa``) the characteristic polynomial
    ``s^3 + 2 zeta omega s^2 + omega^2 s + c0`` (``k_y = omega^2 L / v^2``,
    ``k_psi = 2 zeta omega L / v``, ``k_i = c0 L / v^2``; stable for ``2 zeta omega^3 > c0``); the
    integral removes the offset a steering bias would leave.

    Parameters
    ----------
    car : DrivingCar
    speed_ref : callable or float
        Reference speed (m/s) as a function of time, or a constant.
    dt : float
        Controller sample time (s) (the integrator step).
    slope : float
        Road slope the feed-forward assumes (rad).
    kp, ki : float
        Speed PI gains (1/s, 1/s^2).
    omega, zeta, c0 : float
        Path-error dynamics.
    """

    def __init__(self, car: DrivingCar, speed_ref, *, dt: float = 0.01, slope: float = 0.0, kp: float = 0.8,
                 ki: float = 0.15, omega: float = 1.2, zeta: float = 0.9, c0: float = 0.3):
        self.car = car
        self.speed_ref = speed_ref if callable(speed_ref) else (lambda t, v=float(speed_ref): v)
        self.dt, self.kp, self.ki, self.omega, self.zeta, self.c0 = float(dt), kp, ki, omega, zeta, c0
        p = car.params
        self.L = p["a"] + p["b"]
        self.K_us = p["m"] / self.L * (p["b"] / (2 * p["C_alpha_f"]) - p["a"] / (2 * p["C_alpha_r"]))
        self.r_w = p["r_w"]
        self.brake_gain = p["m"] * p["r_w"] / (p["k_bf"] + p["k_br"])  # MPa per m/s^2
        # throttle feed-forward table: trim throttle against speed (on the assumed slope)
        speeds = np.linspace(8.0, 36.0, 15)
        self._ff_v = speeds
        self._ff_thr = np.array([car.car.cruise(v, slope=slope)[1][0] for v in speeds])
        # throttle -> acceleration gain near cruise: a slope of 1 % is a deceleration of g sin(0.01);
        # the extra trim throttle that holds the speed on it is the equivalent throttle
        thr_up = car.car.cruise(20.0, slope=slope + 0.01)[1][0]
        thr_0 = np.interp(20.0, speeds, self._ff_thr)
        self.acc_per_deg = 9.80665 * np.sin(0.01) / max(thr_up - thr_0, 1e-6)
        self.a_coast = -0.25  # m/s^2 below which the brake is used
        self.reset(1)

    def reset(self, runs: int) -> None:
        self._i = np.zeros(runs)
        self._iy = np.zeros(runs)

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        y = np.atleast_2d(y)
        runs = y.shape[0]
        if self._i.shape[0] != runs:
            self.reset(runs)
        v = self.r_w * y[:, 4] / 2.0  # rear wheel-speed sum -> speed
        v_ref = float(self.speed_ref(t))
        e = v_ref - v
        a_des = np.clip(self.kp * e + self.ki * self._i, -10.0, 10.0)
        thr_ff = np.interp(v_ref, self._ff_v, self._ff_thr)
        thr_raw = thr_ff + a_des / self.acc_per_deg
        thr = np.clip(thr_raw, 0.0, 83.0)
        brake_raw = (self.a_coast - a_des) * self.brake_gain
        brake = np.clip(brake_raw, 0.0, 10.0)
        thr = np.where(brake > 0, 0.0, thr)
        # anti-windup (conditional integration): freeze the integrator while the actuator that
        # should act is saturated in the direction of the error
        saturated = ((e > 0) & ((thr_raw >= 83.0) | (a_des >= 10.0))) | ((e < 0) & ((brake_raw >= 10.0)
                                                                                  | (a_des <= -10.0)))
        self._i += np.where(saturated, 0.0, e * self.dt)
        e_y, e_psi = y[:, 11], y[:, 12]
        kappa = self._kappa(y)
        vv = np.maximum(v, 3.0)
        k_y = self.omega**2 * self.L / vv**2
        k_psi = 2 * self.zeta * self.omega * self.L / vv
        k_iy = self.c0 * self.L / vv**2
        self._iy += e_y * self.dt
        steer = kappa * (self.L + self.K_us * vv**2) - k_y * e_y - k_psi * e_psi - k_iy * self._iy
        return np.column_stack([thr, brake, np.clip(steer, -0.5, 0.5)])

    def _kappa(self, y):
        """Path curvature feed-forward (1/m); none without a map (see the track controller)."""
        return np.zeros(y.shape[0])


def driving_scenario(kind: str = "straight", speed: float = 20.0, *, duration: float = 20.0,
                     faults: Sequence[Any] = (), slope: float | None = None, dt: float = 1e-3,
                     sample_time: float = 0.01, noise=None, params: Mapping[str, Any] | None = None):
    """A scenario of ng-chen-speyer, Section V-B, for :func:`fdikit.sim.simulate`.

    Parameters
    ----------
    kind : {"straight", "speed_change", "curve"}
        ``"straight"``: constant ``speed`` on a straight flat road; ``"speed_change"``: steps of
        the reference speed ``speed -> speed + 4 -> speed`` (at 1/3 and 2/3 of the duration);
        ``"curve"``: 100 m straight then a left curve of radius 300 m built on a slight slope
        (default 2 %), at ``speed``.
    speed : float
        Reference speed (m/s), 20 or 24 in the paper.
    duration, dt, sample_time : float
        Simulated time, integration step and measurement/controller sample time (s).
    faults : sequence of Fault
        :mod:`fdikit.faults` faults targeting names in :data:`FAULTS` (e.g.
        ``Step("actuator:brake", 2.0, start=5.0)`` is a driver stepping on the brake).
    slope : float, optional
        Road slope (rad); default 0, and 0.02 for ``"curve"``.
    noise : Noise, optional
    params : mapping, optional
        Parameter overrides of the car (floats or per-run arrays).

    Returns
    -------
    model : DrivingCar
    scenario : Scenario
    controller : DriveController

    Examples
    --------
    >>> model, sc, ctrl = driving_scenario("curve", 20.0, duration=2.0)  # doctest: +SKIP
    """
    from ...faults import Scenario

    if kind not in ("straight", "speed_change", "curve"):
        raise ModelError(f"unknown driving scenario {kind!r}; use 'straight', 'speed_change' or 'curve'")
    if slope is None:
        slope = 0.02 if kind == "curve" else 0.0
    track = Track(straight=100.0, radius=300.0) if kind == "curve" else Track(straight=1e9)
    model = DrivingCar(track, params=None)
    x0, _u0 = model.cruise(speed, slope=slope)
    if kind == "speed_change":
        t1, t2 = duration / 3, 2 * duration / 3

        def v_ref(t):
            return speed + (4.0 if t1 <= t < t2 else 0.0)
    else:
        v_ref = float(speed)
    ctrl = _TrackController(model, v_ref, dt=sample_time, slope=slope)
    sc = Scenario(duration=duration, dt=dt, sample_time=sample_time, faults=list(faults), x0=x0,
                  controller=ctrl, disturbances=np.array([slope]), noise=noise, params=params,
                  name=f"{kind} at {speed:g} m/s")
    return model, sc, ctrl


class _TrackController(DriveController):
    """:class:`DriveController` that knows the track's curvature (a map) from the car's arc length
    estimate (integrated measured speed)."""

    def reset(self, runs: int) -> None:
        super().reset(runs)
        self._s = np.zeros(runs)

    def __call__(self, t, y):
        y = np.atleast_2d(y)
        if self._i.shape[0] != y.shape[0]:
            self.reset(y.shape[0])
        self._s = self._s + self.r_w * y[:, 4] / 2.0 * self.dt
        return super().__call__(t, y)

    def _kappa(self, y):
        tr = self.car.track
        if not np.isfinite(tr.radius):
            return np.zeros(y.shape[0])
        return np.where(self._s > tr.straight, 1.0 / tr.radius, 0.0)


def simulate_drive(kind: str = "straight", speed: float = 20.0, *, duration: float = 20.0,
                   faults: Sequence[Any] = (), runs: int | None = None, seed: int = 0, **kw):
    """Run :func:`driving_scenario` through :func:`fdikit.sim.simulate`, keeping y, x and u.

    Returns
    -------
    SimResult

    Examples
    --------
    >>> res = simulate_drive("straight", 20.0, duration=1.0)  # doctest: +SKIP
    """
    from ...sim import simulate

    model, sc, _ = driving_scenario(kind, speed, duration=duration, faults=faults, **kw)
    return simulate(model, sc, runs=runs, seed=seed, keep=("y", "x", "u"))
