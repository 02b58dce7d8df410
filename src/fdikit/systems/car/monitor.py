"""Vehicle health monitor of the passenger car (ng-chen-speyer, Ng, Chen & Speyer, Sections IV and V).

Residual generator (Section IV-B..D):

* six fault detection filter sets of two filters each, designed on the reduced linear models at
  the operating speed (:func:`~fdikit.residuals.fault_detection_filter`: the exact unknown input
  observer where it exists, else the optimal stochastic filter):

  ====  ====================================  =======================================
  set   targets                               common nuisance
  ====  ====================================  =======================================
  1     engine-speed sensor, accelerometer    nonlinearity direction, road slope
  2     front / rear wheel-speed sum sensors  nonlinearity direction, road slope
  3     brake actuator, rear wheel-speed sum  nonlinearity direction, road slope
  4     steering actuator, front wheel diff
  5     yaw-rate sensor, rear wheel diff
  6     lateral accelerometer, rear wheel diff
  ====  ====================================  =======================================

  (each filter of a set takes the other target of the set as a nuisance too). The road slope is
  an unknown disturbance of the longitudinal block (the curve of Section V is built on a slope);
  it is blocked like the nonlinearity. The lateral filters (sets 4-6) are low-gain observers
  (:data:`LATERAL_Q_WEIGHT`) that block a sensor nuisance by not reading that sensor, with their
  residuals whitened (:func:`whiten_design`); the exact UIO depends on its nuisance only, so the
  six lateral filters are five distinct ones, each blind to one lateral fault (set 6's
  accelerometer filter is set 5's yaw-rate filter and gives no feature of its own; likewise set 3's
  brake filter is set 2's front wheel-speed filter, :meth:`CarMonitorDesign.residual_groups`).
* two parity equations (Section IV-D): throttle command vs throttle measurement, brake command
  through the brake actuator model (first-order lag ``tau_b``) vs brake-pressure measurement.

Residual processor (Section IV-E): the Euclidean norm of each distinct filter's residual and the
absolute value of each parity residual (low-pass smoothed) form the feature vector of a multiple-hypothesis
Shiryayev test (:class:`~fdikit.detect.MHSSPT`) whose uniform-mean Gaussian densities are
calibrated by simulating every fault over a range of magnitudes on the nonlinear car
(:func:`calibrate_monitor`): 15 longitudinal hypotheses (no fault + small/large for throttle,
brake actuator, brake sensor, engine speed, accelerometer, front and rear wheel-speed sums) and 11
lateral ones (steering actuator, lateral accelerometer, yaw rate, front and rear wheel-speed
differences).

The manifold-pressure sensor is not monitored: the paper detects it with a nonlinear parity
equation of its reference [13], which is not reproduced here.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit

from ...base import ResidualGenerator
from ...detect import Hold
from ...detect.features import FeatureNorms
from ...detect.mhsspt import WarmupMHSSPT, calibrate_densities, extend_ranges, floor_std
from ...errors import ConditionError, ModelError
from ...faults import Bias, Noise
from ...monitor import Decision, Monitor
from ...residuals import (
    FaultDetectionFilter,
    FilterDesign,
    fault_detection_filter,
    internal_form,
    stack_designs,
)
from ...residuals.scheduled import ScheduledFilter
from ...residuals.transforms import delayed_feedthrough, whiten_design
from ...signals import Signals
from .driving import DRIVE_OUTPUTS, simulate_drive
from .linear import CarLinearization, linearize_car
from .model import DEFAULT_PARAMS, OUTPUTS, PassengerCar

__all__ = [
    "BLOCK_SETTINGS",
    "CAR_SENSOR_CHANNELS",
    "FILTER_SETS",
    "LATERAL_FAULTS",
    "LONGITUDINAL_FAULTS",
    "MAGNITUDES",
    "SENSOR_NOISE_STD",
    "CarMonitor",
    "CarMonitorDesign",
    "CarSensorChannels",
    "OffsetFilter",
    "ParityEquations",
    "build_monitor",
    "calibrate_monitor",
    "car_signals",
    "design_car_monitor",
    "fit_car_sensor_channels",
    "isolation_study",
    "pattern_table",
    "with_sensor_checks",
]

#: The six filter sets of Section IV-B (two targets each).
FILTER_SETS: dict[int, tuple[str, str]] = {
    1: ("sensor:w_engine", "sensor:a_x"),
    2: ("sensor:w_front_sum", "sensor:w_rear_sum"),
    3: ("actuator:brake", "sensor:w_rear_sum"),
    4: ("actuator:steer", "sensor:w_front_diff"),
    5: ("sensor:yaw_rate", "sensor:w_rear_diff"),
    6: ("sensor:a_y", "sensor:w_rear_diff"),
}
LONGITUDINAL_SETS = (1, 2, 3)
LATERAL_SETS = (4, 5, 6)

#: Monitored faults -> the fault injected to calibrate it. "throttle" is one hypothesis for the
#: throttle actuator and the throttle sensor (parity equation 1 cannot tell them apart, paper
#: Section IV-D; the filters block the throttle actuator with the nonlinearity).
LONGITUDINAL_FAULTS: dict[str, str] = {
    "throttle": "sensor:throttle_meas",
    "brake_actuator": "actuator:brake",
    "brake_sensor": "sensor:brake_meas",
    "engine_speed": "sensor:w_engine",
    "accelerometer": "sensor:a_x",
    "front_wheel_sum": "sensor:w_front_sum",
    "rear_wheel_sum": "sensor:w_rear_sum",
}
LATERAL_FAULTS: dict[str, str] = {
    "steering_actuator": "actuator:steer",
    "lateral_accelerometer": "sensor:a_y",
    "yaw_rate": "sensor:yaw_rate",
    "front_wheel_diff": "sensor:w_front_diff",
    "rear_wheel_diff": "sensor:w_rear_diff",
}

#: Calibration magnitudes per injected fault (units of the channel). Chosen around the sizes of
#: the paper's experiments (accelerometer 0.4-0.8 m/s^2; a driver's foot on the brake ~0.5 MPa;
#: a hand on the wheel ~1 deg of road-wheel angle) and well above the sensor noise.
MAGNITUDES: dict[str, tuple[float, ...]] = {
    "sensor:throttle_meas": (1.0, 2.0, 3.0, 4.0),
    "actuator:throttle": (1.0, 2.0, 3.0, 4.0),
    "actuator:brake": (0.3, 0.5, 0.7, 0.9),
    "sensor:brake_meas": (0.3, 0.5, 0.7, 0.9),
    "sensor:w_engine": (10.0, 15.0, 20.0, 25.0),
    "sensor:a_x": (0.4, 0.6, 0.8, 1.0),
    "sensor:w_front_sum": (1.5, 2.5, 3.5, 4.5),
    "sensor:w_rear_sum": (1.5, 2.5, 3.5, 4.5),
    "actuator:steer": (0.01, 0.015, 0.02, 0.025),
    "sensor:a_y": (0.4, 0.6, 0.8, 1.0),
    "sensor:yaw_rate": (0.02, 0.03, 0.04, 0.05),
    "sensor:w_front_diff": (0.4, 0.6, 0.8, 1.0),
    "sensor:w_rear_diff": (0.4, 0.6, 0.8, 1.0),
}

#: Riccati state weight of the lateral filters (sets 4-6; ``Q = LATERAL_Q_WEIGHT I`` in the modal
#: coordinates of the reduced lateral model, ``R`` the sensor-noise covariance). A steering fault
#: enters the lateral acceleration instantly (the tyre force, ``D = 67 m/s^2 per rad``) and the yaw
#: rate and wheel-speed differences only through the yaw dynamics: for the first samples it is a
#: lateral-accelerometer bias. What tells the two apart is the yaw rate, the most precise lateral
#: sensor (0.002 rad/s); with ``Q = 1e-6 I`` the observer follows the yaw-rate measurement within a
#: few samples and the steering fault's trace in the residual of the filter that blocks the
#: accelerometer (set 6, target rear wheel difference) stays at 3 noise standard deviations; a
#: lower-gain observer keeps the model's own prediction and that trace grows to ~6 after 20 ms
#: and ~20 after 0.1 s (see :func:`whiten_design`). The lateral model is close to linear on the
#: scenarios' 300 m curve, so little model error is let through.
LATERAL_Q_WEIGHT = 1e-10
#: Blocks whose filter residuals are scaled to unit noise covariance before their norm is taken.
WHITENED_BLOCKS: tuple[str, ...] = ("lateral",)

#: MHSSPT settings per block: change probability per sample ``p`` and std inflation ``inflate``
#: (the lateral block keeps the smaller prior change rate that held its curve-entry transient).
#: ``transient`` (s): the fault hypotheses' mean ranges also span the features' means over the
#: first ``transient`` seconds after the onset (:func:`extend_ranges`): a fault's residual passes
#: through its rise before it settles, and a hypothesis calibrated on the settled features only
#: leaves the rise to whichever other hypothesis lies near it (the steering fault's first samples
#: look like a lateral-accelerometer bias, see :data:`LATERAL_Q_WEIGHT`).
#: ``rise_path`` (1: on): the rise is first clipped to the way from the no-fault mean to the settled
#: range (:func:`extend_ranges` ``path``). Longitudinal: the brake actuator reaches the brake-pressure
#: parity residual within ``tau_b`` but the filter residuals only through the car's deceleration
#: (|set1/w_engine| 0.15 -> 0.39 over 0.4 s at 0.3 MPa), so during the rise its features are the
#: brake sensor's settled ones (parity 2 up, filters at no fault) and the brake sensor was announced
#: (0.3 and 0.9 MPa); the engine-speed filter's own residual settles over 0.5 s while the front-wheel
#: filter's jumps at once, and a 10 rpm bias was announced as a front wheel-speed sum for its first
#: samples. The plain box over the rise (``rise_path`` off) fixes those but takes in the rear
#: wheel-speed sum's one-sample onset spike (its large hypothesis's ranges in |set1/w_engine| and
#: |set2/w_rear_sum| 0.35-0.40 and 0.23-0.29 -> 0.02-4.2 and 0.05-4.4: each of the two densities
#: about 4 times lower at every later sample) and 30 ms window noise in features the
#: accelerometer does not move (|set2/w_rear_sum| high 0.175 -> 0.32): the rear sum at 1.5 and 2.5
#: then ended on the accelerometer (``isolation_study``, seed 5). With the path clip both hold:
#: every run isolated at every magnitude but the front wheel-speed sum at 1.5 (see
#: ``tests/test_car_monitor.py::test_longitudinal_isolation_at_the_calibration_magnitudes``).
#: ``hold``: samples a fault's probability must stay at the announcement level before it is
#: announced. Lateral: 5 (50 ms): a steering fault and a lateral-accelerometer bias give the same
#: residuals at the first sample (the tyre force is instant), and the residual that blocks the
#: accelerometer sees the smallest calibrated steering fault (0.01 rad) only through the yaw
#: dynamics: 2, 4 and 6 noise standard deviations after 1, 2 and 3 samples
#: (``tests/test_car_monitor.py::test_steering_separates_from_accelerometer``); before that the
#: probability may rightly sit on the accelerometer. Lateral ``inflate`` 2: the whitened no-fault
#: features follow the chi law of sensor noise (the lateral model is close to linear on the 300 m
#: curve), whose upper tail is heavier than the Gaussian density's, and one noisy wheel-speed
#: sample reaches four of the five features at once (the features are not independent); with 1.5
#: the front-wheel-difference probability reached 0.82 in the ten-minute nominal drive, with 2
#: 0.007.
BLOCK_SETTINGS: dict[str, dict[str, float]] = {
    "longitudinal": {"p": 1e-3, "inflate": 1.5, "transient": 0.5, "hold": 3, "rise_path": 1.0},
    "lateral": {"p": 1e-4, "inflate": 2.0, "transient": 0.5, "hold": 5}}

#: Standard deviation of the white measurement noise of every sensor in the simulations (units of
#: the channel): automotive-grade sensors sampled at 100 Hz.
SENSOR_NOISE_STD: dict[str, float] = {
    "p_man": 0.3, "w_engine": 1.0, "a_x": 0.05, "w_front_sum": 0.1, "w_rear_sum": 0.1,
    "throttle_meas": 0.05, "brake_meas": 0.005, "a_y": 0.05, "yaw_rate": 0.002,
    "w_front_diff": 0.05, "w_rear_diff": 0.05, "lateral_offset": 0.01, "heading_error": 0.001,
}


def sensor_noise(scale: float = 1.0) -> Noise:
    """Measurement noise of the simulations (:data:`SENSOR_NOISE_STD`, times ``scale``)."""
    return Noise(measurement=[(scale * SENSOR_NOISE_STD[y]) ** 2 for y in DRIVE_OUTPUTS])


# ---------------------------------------------------------------------------------- runtime pieces
class OffsetFilter(FaultDetectionFilter):
    """:class:`~fdikit.residuals.FaultDetectionFilter` fed with deviations from the operating point.

    The filters are designed on a linearisation about ``(u0, y0)`` (paper Section V: "the
    nominal values of the control commands and measurements have to be subtracted"); this runs
    the design on ``u - u0``, ``y - y0``. Batch and streaming share the compiled row update.

    Parameters
    ----------
    design : FilterDesign
    u0 : array (len(design.u_names),)
    y0 : array (len(design.y_names),)

    Examples
    --------
    >>> d = FilterDesign(np.array([[0.5]]), np.zeros((1, 0)), np.array([[1.0]]), np.array([[1.0]]),
    ...                  np.zeros((1, 0)), np.array([[-1.0]]), 0.1, [], ["y"], ["r"])
    >>> f = OffsetFilter(d, [], [2.0])
    >>> f.reset(1)
    >>> float(f.step(np.zeros(0), [3.0])[0, 0])
    -1.0
    """

    def __init__(self, design: FilterDesign, u0: Any, y0: Any):
        super().__init__(design)
        self.u0 = np.asarray(u0, float).reshape(len(design.u_names))
        self.y0 = np.asarray(y0, float).reshape(len(design.y_names))

    def _step(self, u, y):
        return super()._step(u - self.u0, y - self.y0)

    def _inputs(self, signals):
        u, y = super()._inputs(signals)
        return u - self.u0, y - self.y0


@njit(cache=True)
def _parity_kernel(u, y, a, state, out):  # pragma: no cover - compiled
    """u, y (runs, T, 2) = (throttle, brake) commands and measurements; state (runs, 2) = (brake
    model, previous throttle command; NaN: take the current one)."""
    for i in range(u.shape[0]):
        p = state[i, 0]
        prev = state[i, 1]
        for k in range(u.shape[1]):
            if np.isnan(prev):
                prev = u[i, k, 0]
            out[i, k, 0] = y[i, k, 0] - prev
            out[i, k, 1] = y[i, k, 1] - p
            p = a * p + (1.0 - a) * u[i, k, 1]
            prev = u[i, k, 0]
        state[i, 0] = p
        state[i, 1] = prev


class ParityEquations(ResidualGenerator):
    """The two parity equations of ng-chen-speyer, Section IV-D.

    ``parity1[k] = throttle_meas[k] - throttle[k-1]`` (the throttle actuator follows its command
    within a sample; the measurement at ``t_k`` sees the command held over the previous sample,
    ``throttle[k-1]``: the command ``throttle[k]`` is computed from the measurements at ``t_k``);
    ``parity2[k] = brake_meas[k] - p_hat[k]`` with the brake actuator model
    ``tau_b p' = p_cmd - p`` discretised exactly for a command held over the sample:
    ``p_hat[k+1] = a p_hat[k] + (1 - a) brake[k]``, ``a = exp(-dt / tau_b)``.

    Parameters
    ----------
    dt : float
        Sample time (s).
    tau_b : float
        Brake actuator time constant (s).
    p0 : float
        Initial brake-pressure estimate (MPa).

    Examples
    --------
    >>> pe = ParityEquations(0.01, 0.1)
    >>> pe.reset(1)
    >>> pe.step([10.0, 1.0], [10.5, 0.0]).round(6).tolist()
    [[0.5, 0.0]]
    >>> pe.step([12.0, 1.0], [10.5, 0.0]).round(6).tolist()   # throttle[k-1] = 10; -(1 - exp(-0.1))
    [[0.5, -0.095163]]
    """

    def __init__(self, dt: float, tau_b: float, p0: float = 0.0):
        self.u_names = ["throttle", "brake"]
        self.y_names = ["throttle_meas", "brake_meas"]
        self.output_names = ["parity1", "parity2"]
        if not (dt > 0 and tau_b > 0):
            raise ModelError(f"dt and tau_b must be positive, got {dt}, {tau_b}")
        self.dt, self.tau_b, self.p0 = float(dt), float(tau_b), float(p0)
        self.a = float(np.exp(-dt / tau_b))
        self.reset(1)

    def reset(self, runs: int = 1) -> None:
        self._p = np.column_stack([np.full(runs, self.p0), np.full(runs, np.nan)])

    def _step(self, u, y):
        out = np.empty((u.shape[0], 1, 2))
        _parity_kernel(np.ascontiguousarray(u[:, None]), np.ascontiguousarray(y[:, None]), self.a,
                       self._p, out)
        return out[:, 0]

    def run(self, signals: Signals) -> Signals:
        u, y = self._inputs(signals)
        self.reset(signals.runs)
        out = np.empty((signals.runs, signals.n_samples, 2))
        _parity_kernel(np.ascontiguousarray(u), np.ascontiguousarray(y), self.a, self._p, out)
        return Signals(signals.t, out, self.output_names, check=False)


# ---------------------------------------------------------------------------------- design
@dataclass
class CarMonitorDesign:
    """Filters and parity equations of the car monitor at one operating speed.

    Attributes
    ----------
    speed, dt : float
        Operating speed (m/s) and sample time (s).
    lin : CarLinearization
    designs : dict
        ``{set number: {target: FilterDesign}}``.
    models : dict
        ``{"longitudinal" | "lateral": LinearFaultModel}``: the (reduced) design models, with the
        nonlinearity and slope nuisances declared on the longitudinal one.
    u0, y0 : dict
        Operating-point inputs and outputs by channel name.
    nonlinearity_energy : float
        Share of the state-equation mismatch the nonlinearity direction captures.
    """

    speed: float
    dt: float
    lin: CarLinearization
    designs: dict[int, dict[str, FilterDesign]]
    models: dict[str, Any]
    u0: dict[str, float]
    y0: dict[str, float]
    nonlinearity_energy: float
    info: dict[str, Any] = field(default_factory=dict)

    def filters(self, sets: Sequence[int]) -> list[FilterDesign]:
        return [d for s in sets for d in self.designs[s].values()]

    def residual_groups(self, sets: Sequence[int], *, unique: bool = True) -> dict[str, list[str]]:
        """Feature name ``"|<set>/<target>|"`` -> the filter's residual channels.

        With ``unique``, a filter identical to an earlier one (same matrices to 1e-12: the exact
        unknown input observer depends on its nuisance only, not on its target) gives no feature
        of its own: the MHSSPT densities treat the features as independent, and a duplicated
        residual would count its evidence twice. Set 6's accelerometer filter (nuisance the rear
        wheel-speed difference) is set 5's yaw-rate filter, and set 3's brake filter (nuisance
        the rear wheel-speed sum and the nonlinearity; the slope is not separable from either
        target) is set 2's front wheel-speed filter."""
        out: dict[str, list[str]] = {}
        seen: list[FilterDesign] = []
        for d in self.filters(sets):
            if unique and any(_same_filter(d, o) for o in seen):
                continue
            seen.append(d)
            out[f"|{d.residual_names[0].rsplit(':', 1)[0]}|"] = list(d.residual_names)
        return out


def _same_filter(a: FilterDesign, b: FilterDesign) -> bool:
    mats = ("A", "Bu", "By", "C", "Du", "Dy")
    if (a.u_names, a.y_names) != (b.u_names, b.y_names) or any(
            getattr(a, k).shape != getattr(b, k).shape for k in mats):
        return False
    def close(x, y):
        return np.allclose(x, y, rtol=1e-12, atol=1e-12 * max(1.0, float(np.abs(y).max(initial=0.0))))

    return all(close(getattr(a, k), getattr(b, k)) for k in mats)


@functools.lru_cache(maxsize=8)
def design_car_monitor(speed: float = 20.0, dt: float = 0.01, *, fast_accelerometer: bool = False,
                       q_weight: float = 1e-6, nl_duration: float = 6.0,
                       reduced: bool = True, lateral_q_weight: float | None = LATERAL_Q_WEIGHT,
                       whiten: tuple[str, ...] = WHITENED_BLOCKS,
                       lateral_sensor_nuisance: str = "output") -> CarMonitorDesign:
    """Design the six filter sets and the parity equations at ``speed`` (cached in memory).

    Parameters
    ----------
    speed : float
        Operating speed (m/s) of the linearisation (20 or 24 in the paper).
    dt : float
        Sample time of the monitor (s).
    fast_accelerometer : bool
        Re-tune the accelerometer filter of set 1 for speed (paper Fig. 4, second column): its
        Riccati state weight is 100 times larger (a faster, noisier filter).
    q_weight : float
        State weight ``Q = q_weight I`` of the Riccati equation of every observer gain (the
        measurement weight is the sensor-noise covariance :data:`SENSOR_NOISE_STD`).
    nl_duration : float
        Length (s) of the nominal simulations the nonlinearity direction is estimated from.
    reduced : bool
        Design on the reduced models (10 + 6 states, paper Section III) or on the full blocks
        (14 + 8 states, with the fast wheel-slip and wheel-hop modes).
    lateral_q_weight : float or None
        Riccati state weight of the lateral filters (sets 4-6); None: ``q_weight``. Default
        :data:`LATERAL_Q_WEIGHT`.
    whiten : tuple of {"longitudinal", "lateral"}
        Blocks whose filter residuals are scaled to unit measurement-noise covariance
        (:func:`whiten_design`). Default :data:`WHITENED_BLOCKS`.
    lateral_sensor_nuisance : {"output", "state"}
        How the lateral filters block a sensor-fault nuisance: ``"output"`` projects the sensor's
        output direction out of the measurements (the filter does not read that sensor);
        ``"state"`` blocks its state-space equivalent ``[f, A f]`` (``f = C^+ e_j``). The two
        wheel-speed differences both read roll and yaw (``w_diff = -97 phi - 4.8 r + 61 d``): with
        ``"state"`` the blocked subspace ``[f, A f]`` of one of them takes in the suspension-roll
        coupling that the other sees, and the other's fault reaches the residual at 2 noise
        standard deviations instead of 6 (the front and rear patterns become parallel).

    Returns
    -------
    CarMonitorDesign

    Examples
    --------
    >>> des = design_car_monitor(20.0)                  # doctest: +SKIP
    >>> sorted(des.designs[1])                          # doctest: +SKIP
    ['sensor:a_x', 'sensor:w_engine']
    """
    from .nonlinearity import nonlinearity_directions

    if lateral_sensor_nuisance not in ("output", "state"):
        raise ModelError("lateral_sensor_nuisance must be 'output' or 'state', "
                         f"got {lateral_sensor_nuisance!r}")
    bad = [b for b in whiten if b not in ("longitudinal", "lateral")]
    if bad:
        raise ModelError(f"whiten names unknown blocks {bad}; blocks: 'longitudinal', 'lateral'")
    t0 = time.perf_counter()
    lin = linearize_car(float(speed))
    nd = nonlinearity_directions(lin, "longitudinal", k=1, duration=nl_duration, dt=2.5e-3)
    lon = nd.reduced if reduced else nd.model
    lat = lin.lateral_reduced if reduced else lin.lateral
    lon_d = lon.discretize(dt)
    lat_d = lat.discretize(dt)
    slope_nuis = ("slope", lon_d.B_of("d"))  # the road slope: an unknown disturbance, blocked
    designs: dict[int, dict[str, FilterDesign]] = {}
    for s, targets in FILTER_SETS.items():
        model = lon_d if s in LONGITUDINAL_SETS else lat_d
        common = ["nonlinearity:1", slope_nuis] if s in LONGITUDINAL_SETS else []
        designs[s] = {}
        for t in targets:
            others = [o for o in targets if o != t] + common
            # observer gain K1 from the Riccati equation with the sensor-noise covariance as R and a
            # small state weight: a low-gain observer keeps the sensor biases in the residual and
            # filters the noise (Q = I, R = I lets the noisy engine-speed sensor dominate)
            V = np.diag([SENSOR_NOISE_STD[y] ** 2 for y in model.outputs])
            qw = q_weight if s in LONGITUDINAL_SETS or lateral_q_weight is None else lateral_q_weight
            qw = qw * (100.0 if fast_accelerometer and s == 1 and t == "sensor:a_x" else 1.0)
            kw: dict[str, Any] = {"Q": qw * np.eye(model.n_states), "R": V}
            if s in LATERAL_SETS and lateral_sensor_nuisance == "output":
                designs[s][t] = _design_projecting_sensors(model, t, others, qw, name=f"set{s}/{t}")
                if "lateral" in whiten:
                    designs[s][t] = whiten_design(designs[s][t], SENSOR_NOISE_STD)
                designs[s][t].internal = internal_form(designs[s][t], model)
                continue
            try:
                designs[s][t] = fault_detection_filter(model, t, others, name=f"set{s}/{t}", **kw)
            except ConditionError as exc:
                if slope_nuis not in others:
                    raise
                # the slope is not separable from this target: block the nonlinearity only
                others = [o for o in others if o is not slope_nuis]
                designs[s][t] = fault_detection_filter(model, t, others, name=f"set{s}/{t}", **kw)
                designs[s][t].info["slope_not_blocked"] = str(exc)
            if ("longitudinal" if s in LONGITUDINAL_SETS else "lateral") in whiten:
                designs[s][t] = whiten_design(designs[s][t], SENSOR_NOISE_STD)
                designs[s][t].internal = internal_form(designs[s][t], model)
    car = PassengerCar()
    y0 = car.h(0.0, lin.x0[None], lin.u0[None], car.params)[0]
    y0d = dict(zip(OUTPUTS, map(float, y0)))
    u0d = {"throttle": float(lin.u0[0]), "brake": float(lin.u0[1]), "steer": float(lin.u0[2])}
    info = {"design_seconds": time.perf_counter() - t0,
            "slope_blocked": {f"set{s}/{t}": "slope_not_blocked" not in d.info
                              for s, ds in designs.items() if s in LONGITUDINAL_SETS for t, d in ds.items()},
            "methods": {f"set{s}/{t}": d.info.get("method")
                        for s, ds in designs.items() for t, d in ds.items()}}
    models = {"longitudinal": lon_d, "lateral": lat_d}
    return CarMonitorDesign(float(speed), float(dt), lin, designs, models,
                            u0d, y0d, float(nd.energy[0]), info)


def _design_projecting_sensors(model, target: str, nuisance: Sequence[str], q: float, *,
                               name: str) -> FilterDesign:
    """Exact UIO on the noise-scaled model (outputs divided by :data:`SENSOR_NOISE_STD`, so that
    ``R = I``) whose sensor-fault nuisances are blocked by projecting their output directions out
    of the measurements (``sensor="output"``: the filter does not read a sensor it must not trust)
    instead of through their state-space equivalent ``[f, A f]``; the scaling is folded back into
    the measurement gains (the filter reads the measurements in their units)."""
    from ...model.linear import GROUPS

    S = np.array([1.0 / SENSOR_NOISE_STD[y] for y in model.outputs])
    scaled = model.with_matrices(model.A, S[:, None] * model.C,
                                 {g: (model.B_of(g), S[:, None] * model.D_of(g)) for g in GROUPS})
    sensor = "output" if all(str(o).startswith("sensor:") for o in nuisance) else "auto"
    n_proj = sum(str(o).startswith("sensor:") for o in nuisance) if sensor == "output" else 0
    R = np.eye(model.n_outputs - n_proj)
    d = fault_detection_filter(scaled, target, list(nuisance), Q=q * np.eye(model.n_states), R=R,
                               sensor=sensor, name=name, method="uio")
    iy = [model.outputs.index(y) for y in d.y_names]
    d.By, d.Dy = d.By * S[iy], d.Dy * S[iy]
    d.info["sensor_nuisance"] = sensor
    d.internal = None  # against the scaled model; the caller recomputes it against ``model``
    return d


def _filter_generator(des: CarMonitorDesign, sets: Sequence[int]) -> OffsetFilter:
    st = delayed_feedthrough(stack_designs(des.filters(sets)))
    return OffsetFilter(st, [des.u0[u] for u in st.u_names], [des.y0[y] for y in st.y_names])


def _generators(des: CarMonitorDesign, block: str) -> tuple[list[ResidualGenerator], dict[str, list[str]]]:
    if block == "longitudinal":
        fg: ResidualGenerator = _filter_generator(des, LONGITUDINAL_SETS)
        sched = des.info.get("schedule") or []
        if sched:
            speeds, fs = [des.speed], [fg]
            for v in sorted(set(sched) - {des.speed}):
                for dv in (0.0, -0.5, -1.0, -1.5, -2.0):  # the reduction may fail at a speed (split pair)
                    try:
                        other = design_car_monitor(v + dv, des.dt)
                        break
                    except ModelError:
                        other = None
                if other is None:
                    raise ModelError(f"no design for the speed schedule near {v} m/s")
                speeds.append(other.speed)
                fs.append(_filter_generator(other, LONGITUDINAL_SETS))
            order = np.argsort(speeds)
            # the speed measured by the rear (undriven) wheels, v = r_w w_rear_sum / 2
            fg = ScheduledFilter([speeds[i] for i in order], [fs[i] for i in order], variable="w_rear_sum",
                                 scale=DEFAULT_PARAMS["r_w"] / 2.0)
        gens: list[ResidualGenerator] = [fg, ParityEquations(des.dt, _tau_b())]
        groups = des.residual_groups(LONGITUDINAL_SETS)
        groups.update({"|parity1|": ["parity1"], "|parity2|": ["parity2"]})
    elif block == "lateral":
        gens = [_filter_generator(des, LATERAL_SETS)]
        groups = des.residual_groups(LATERAL_SETS)
    else:
        raise ModelError(f"block must be 'longitudinal' or 'lateral', got {block!r}")
    return gens, groups


def _tau_b() -> float:
    return float(DEFAULT_PARAMS["tau_b"])


def _generators_and_features(des, block, tau):
    gens, groups = _generators(des, block)
    return gens, [FeatureNorms(groups, des.dt, tau)]


def car_signals(res) -> Signals:
    """Monitor input signals from a :func:`simulate_drive` result: commands ``throttle, brake,
    steer`` followed by every measurement."""
    return res.u.concat_channels(res.y)


# ---------------------------------------------------------------------------------- calibration
@dataclass
class CarMonitor:
    """A calibrated monitor of one block: a :class:`~fdikit.monitor.Monitor` and what built it.

    Attributes
    ----------
    block : str
    monitor : Monitor
        Generators (filters, parity), processors (:class:`FeatureNorms`, :class:`MHSSPT`),
        decision (announce ``P:<fault>`` at ``level``).
    faults : list of str
        Monitored faults (MHSSPT groups).
    features : list of str
    calibration : MHSSPTCalibration
    """

    block: str
    monitor: Monitor
    faults: list[str]
    features: list[str]
    calibration: Any
    design: CarMonitorDesign
    info: dict[str, Any] = field(default_factory=dict)

    def run(self, signals: Signals):
        return self.monitor.run(signals)


def build_monitor(des: CarMonitorDesign, block: str, calibration, *, tau: float = 0.0, p: float = 1e-3,
                  q: float = 0.0, level: float = 0.95, warmup: float = 2.0, hold: int = 3,
                  generators: Sequence[ResidualGenerator] | None = None,
                  groups: Mapping[str, Sequence[str]] | None = None) -> CarMonitor:
    """Assemble a :class:`CarMonitor` from a design and a calibration (see :func:`calibrate_monitor`).

    ``q`` is the MHSSPT's return probability (``q > 0`` tracks intermittent faults); the test
    starts after ``warmup`` seconds (:class:`WarmupMHSSPT`); a fault is announced when its
    probability has been >= ``level`` for ``hold`` consecutive samples
    (:class:`~fdikit.detect.Hold`). ``generators`` and ``groups`` (feature -> residual channels)
    replace the design's filters and parity equations when given (e.g. a speed-scheduled filter)."""
    if generators is None:
        gens, groups = _generators(des, block)
    else:
        gens, groups = list(generators), dict(groups or {})
    feats = FeatureNorms(groups, des.dt, tau)
    faults = list(calibration.groups)
    test = WarmupMHSSPT(feats.output_names, calibration.densities, p=p, q=q, groups=calibration.groups,
                        warmup=round(warmup / des.dt))
    # announcement (paper: "a simple threshold mapping"): P:<fault> >= level for `hold` samples
    announce = Hold([f"P:{f}" for f in faults], level, Z=max(1, int(hold)), absolute=False)
    dec = Decision(announce.output_names, level=0.5,
                   names={f"P:{f}:alarm": f for f in faults})
    mon = Monitor(gens, [feats, test, announce], dec)
    return CarMonitor(block, mon, faults, feats.output_names, calibration, des, {"p": p, "q": q, "tau": tau})


@functools.lru_cache(maxsize=8)
def calibrate_monitor(block: str = "longitudinal", speed: float = 20.0, *, kind: str = "curve",
                      onset: float = 6.0, duration: float = 10.0, settle: float = 0.1, tau: float = 0.0,
                      p: float | None = None, q: float = 0.0, inflate: float | None = None,
                      std_floor: float = 0.05, hold: int | None = None, dt_sim: float = 2.5e-3,
                      nominal_kinds: tuple[str, ...] = ("speed_change",), h0_floor: bool = True,
                      schedule: tuple[float, ...] | None = None,
                      fast_accelerometer: bool = False, seed: int = 11,
                      transient: float | None = None) -> CarMonitor:
    """Calibrate the MHSSPT densities of one block by simulating every fault (ng-chen-speyer, Section IV-E).

    One vectorised simulation of the nonlinear car on ``kind`` at ``speed``: run 0 nominal, then
    one run per (fault, magnitude) of :data:`MAGNITUDES` with the fault from ``onset``; the
    features ``settle`` s after the onset to the end give each magnitude's mean and spread
    (:func:`~fdikit.detect.calibrate_densities`, two hypotheses per fault), the nominal run's
    features from 2 s give H0 (named ``"none:<block>"``), together with those of fault-free drives
    of the kinds ``nominal_kinds`` (e.g. ``("speed_change",)``). ``p`` (change probability per sample),
    ``inflate`` (std factor), ``transient`` (seconds after the onset whose feature means widen
    the hypotheses' ranges, :func:`extend_ranges`) and ``hold`` (samples a probability must stay
    at the announcement level) default to :data:`BLOCK_SETTINGS`. The longitudinal filters are
    also designed at the speeds ``schedule`` (default ``speed + 4``, the scenarios' speed steps)
    and blended by the speed the rear wheels measure (:class:`~fdikit.residuals.ScheduledFilter`);
    ``()`` for one design.
    Every density's standard deviation of a feature is then floored at ``std_floor`` times its
    upper mean and, with ``h0_floor``, at the no-fault std (:func:`floor_std`; a fault adds to the
    noise, and a fault hypothesis narrower than H0 would out-score H0 at the no-fault mean
    itself): the parity residuals are nearly noise-free, and without a floor a sample on the rise
    of a fault (between two calibrated magnitudes' ranges) would be hundreds of standard
    deviations from every hypothesis and the winner decided by rounding.

    Returns
    -------
    CarMonitor

    Examples
    --------
    >>> mon = calibrate_monitor("lateral", 20.0)            # doctest: +SKIP
    >>> mon.faults[:2]                                      # doctest: +SKIP
    ['steering_actuator', 'lateral_accelerometer']
    """
    des = design_car_monitor(speed, fast_accelerometer=fast_accelerometer)
    if schedule is None:
        schedule = (speed + 4.0,)  # the scenarios' speed steps: +4 m/s
    if schedule and block == "longitudinal":
        # speed-scheduled longitudinal filters (designs at these speeds too, blended by speed)
        des = dataclasses.replace(des, info={**des.info, "schedule": [float(v) for v in schedule]})
    table = LONGITUDINAL_FAULTS if block == "longitudinal" else LATERAL_FAULTS
    p = BLOCK_SETTINGS[block]["p"] if p is None else p
    inflate = BLOCK_SETTINGS[block]["inflate"] if inflate is None else inflate
    transient = BLOCK_SETTINGS[block].get("transient", 0.0) if transient is None else transient
    hold = int(BLOCK_SETTINGS[block].get("hold", 3)) if hold is None else hold
    runs = [("nominal", None, 0.0)] + [(name, f, m) for name, f in table.items() for m in MAGNITUDES[f]]
    R = len(runs)
    faults = []
    for f in dict.fromkeys(r[1] for r in runs[1:]):
        mags = np.array([m if r[1] == f else 0.0 for r in runs for m in [r[2]]])
        faults.append(Bias(f, mags, start=onset))
    res = simulate_drive(kind, speed, duration=duration, faults=faults, runs=R, seed=seed, dt=dt_sim,
                         noise=sensor_noise())
    sig = car_signals(res)
    gens, groups = _generators(des, block)
    feats = FeatureNorms(groups, des.dt, tau)
    mon = Monitor(gens, [feats])
    X = mon.run(sig).statistics.values  # (R, T, C)
    t = sig.t
    nominal = X[0, t >= 2.0]
    for extra in nominal_kinds:
        # more fault-free manoeuvres in H0 (e.g. the speed steps the linear filters see as
        # nonlinearity): simulated separately, same noise model
        r2 = simulate_drive(extra, speed, duration=duration, runs=1, seed=seed + 1, dt=dt_sim,
                            noise=sensor_noise())
        X2 = Monitor(*_generators_and_features(des, block, tau)).run(car_signals(r2)).statistics.values
        nominal = np.concatenate([nominal, X2[0, r2.y.t >= 2.0]])
    by_fault: dict[str, dict[float, np.ndarray]] = {}
    for i, (name, _f, m) in enumerate(runs[1:], start=1):
        by_fault.setdefault(name, {})[m] = X[i, t >= onset + settle]
    cal = calibrate_densities(nominal, by_fault, inflate=inflate, no_fault=f"none:{block}")
    if transient > 0:
        # the rise of every fault's features: means over windows of 3 samples from the onset
        win = 3
        k0 = int(np.searchsorted(t, onset - 1e-9))
        nk = round(transient / des.dt) // win * win
        rise: dict[str, dict[float, np.ndarray]] = {}
        for i, (name, _f, m) in enumerate(runs[1:], start=1):
            seg = X[i, k0:k0 + nk]
            rise.setdefault(name, {})[m] = seg.reshape(-1, win, seg.shape[-1]).mean(1)
        path = (next(iter(cal.densities.values())).low
                if BLOCK_SETTINGS[block].get("rise_path", 0.0) else None)
        cal = extend_ranges(cal, rise, path=path)
    cal = floor_std(cal, std_floor, h0_floor=h0_floor)
    out = build_monitor(des, block, cal, tau=tau, p=p, q=q, hold=hold)
    out.info.update(calibration_runs=R, calibration_kind=kind, speed=speed,
                    feature_means={name: {str(m): by_fault[name][m].mean(0).round(4).tolist()
                                          for m in by_fault[name]} for name in by_fault},
                    nominal_mean=nominal.mean(0).round(4).tolist(),
                    nominal_std=nominal.std(0).round(4).tolist())
    return out


def pattern_table(speed: float = 20.0, *, kind: str = "straight", duration: float = 6.0, onset: float = 2.0,
                  threshold: float = 3.0, seed: int = 3) -> dict[str, Any]:
    """Residual pattern table (ng-chen-speyer, Fig. 2) computed on the nonlinear car.

    Every fault of :data:`LONGITUDINAL_FAULTS` and :data:`LATERAL_FAULTS` is simulated at the middle
    of its calibration magnitudes (throttle actuator and sensor both); a residual "responds"
    (1) when the mean of its feature after ``onset + 1`` s exceeds the nominal mean by more than
    ``threshold`` nominal standard deviations and by 10 % of the largest response in its row.

    Returns
    -------
    dict
        ``columns`` (feature names), ``rows`` {fault: [0/1, ...]}, ``ratio`` {fault: [response /
        nominal std, ...]}, ``distinct`` (every binary row distinct and non-zero), ``max_cosine``
        and ``closest_pair`` (largest cosine between two hypotheses' graded rows), ``text``.
    """
    des = design_car_monitor(speed)
    faults = {**{k: v for k, v in LONGITUDINAL_FAULTS.items()}, "throttle_actuator": "actuator:throttle",
              **LATERAL_FAULTS}
    names = list(faults)
    R = 1 + len(names)
    bias = []
    for i, n in enumerate(names, start=1):
        mags = np.zeros(R)
        mags[i] = MAGNITUDES[faults[n]][1]
        bias.append(Bias(faults[n], mags, start=onset))
    res = simulate_drive(kind, speed, duration=duration, faults=bias, runs=R, seed=seed, dt=2.5e-3,
                         noise=sensor_noise())
    sig = car_signals(res)
    cols, X = [], []
    for block in ("longitudinal", "lateral"):
        gens, groups = _generators(des, block)
        st = Monitor(gens, [FeatureNorms(groups, des.dt, 0.03)]).run(sig).statistics
        cols += st.names
        X.append(st.values)
    X = np.concatenate(X, axis=2)
    t = sig.t
    nom = X[0, (t >= 1.0)]
    mu0, sd0 = nom.mean(0), np.maximum(nom.std(0), 1e-12)
    rows, ratio = {}, {}
    for i, n in enumerate(names, start=1):
        d = X[i, t >= onset + 1.0].mean(0) - mu0
        z = d / sd0
        rows[n] = [int(z[j] > threshold and d[j] > 0.1 * d.max()) for j in range(len(cols))]
        ratio[n] = z.round(1).tolist()
    keys = [tuple(v) for v in rows.values()]
    # throttle actuator and sensor share a hypothesis (paper IV-D): compare the hypotheses' rows
    hyp_rows = {n: tuple(v) for n, v in rows.items() if n != "throttle_actuator"}
    distinct = len(set(hyp_rows.values())) == len(hyp_rows) and all(any(v) for v in hyp_rows.values())
    # graded patterns (what the MHSSPT densities see): unit vectors of the positive z-scores; the
    # largest cosine between two hypotheses' rows
    hyp = [n for n in names if n != "throttle_actuator"]
    Z = np.array([np.clip(ratio[n], 0.0, None) for n in hyp])
    Zn = Z / np.maximum(np.linalg.norm(Z, axis=1, keepdims=True), 1e-300)
    cos = Zn @ Zn.T - 2 * np.eye(len(hyp))
    i, j = np.unravel_index(np.argmax(cos), cos.shape)
    short = [c.strip("|").replace("sensor:", "").replace("actuator:", "") for c in cols]
    w = max(len(n) for n in names)
    lines = [" " * w + " | " + " ".join(f"{j:>2d}" for j in range(len(cols)))]
    lines += [f"{n:<{w}} | " + " ".join(f"{'X' if v else '.':>2s}" for v in rows[n]) for n in names]
    lines += ["columns: " + ", ".join(f"{j}={c}" for j, c in enumerate(short))]
    del keys
    return {"columns": cols, "rows": rows, "ratio": ratio, "distinct": bool(distinct),
            "max_cosine": float(cos[i, j]), "closest_pair": [hyp[i], hyp[j]],
            "throttle_actuator_equals_sensor": rows["throttle_actuator"] == rows["throttle"],
            "text": "\n".join(lines)}


def isolation_study(block: str = "longitudinal", speed: float = 20.0, *, kind: str = "curve",
                    onset: float = 6.0, duration: float = 10.0, seed: int = 5, **cal_kw) -> dict[str, Any]:
    """Detection and isolation of every fault at every calibration magnitude, on fresh noise.

    One vectorised simulation (a nominal run and one run per fault and magnitude of
    :data:`MAGNITUDES`, noise seed ``seed`` different from the calibration's) through the
    calibrated monitor (:func:`calibrate_monitor` with ``cal_kw``). A run is *isolated* when at the
    end its fault's probability is >= 0.95, every other fault's <= 0.05 and no other fault was
    announced after the warm-up.

    Returns
    -------
    dict
        ``runs``: per fault and magnitude ``{isolated, delay_s, final_own, final_max_other,
        wrong}``; ``smallest_isolated``: per fault the smallest magnitude isolated (None if none);
        ``nominal_wrong`` and ``nominal_max_probability`` for the nominal run.
    """
    mon = calibrate_monitor(block, speed, kind=kind, **cal_kw)
    table = LONGITUDINAL_FAULTS if block == "longitudinal" else LATERAL_FAULTS
    runs = [("nominal", None, 0.0)] + [(name, f, m) for name, f in table.items() for m in MAGNITUDES[f]]
    R = len(runs)
    faults = []
    for f in dict.fromkeys(r[1] for r in runs[1:]):
        mags = np.array([r[2] if r[1] == f else 0.0 for r in runs])
        faults.append(Bias(f, mags, start=onset))
    res = simulate_drive(kind, speed, duration=duration, faults=faults, runs=R, seed=seed, dt=2.5e-3,
                         noise=sensor_noise())
    sig = car_signals(res)
    out = mon.run(sig)
    t = sig.t
    P = np.stack([out.statistics[f"P:{f}"] for f in mon.faults], axis=-1)  # (R, T, F)
    report: dict[str, Any] = {"runs": {}, "smallest_isolated": {}}
    for i, (name, _f, m) in enumerate(runs):
        ev = [e for e in out.events if e.run == i]
        if name == "nominal":
            report["nominal_wrong"] = [(round(e.t, 3), e.hypothesis) for e in ev]
            report["nominal_max_probability"] = round(float(P[i].max()), 4)
            continue
        j = mon.faults.index(name)
        others = [k for k in range(len(mon.faults)) if k != j]
        wrong = [(round(e.t, 3), e.hypothesis) for e in ev if e.hypothesis != name]
        own = np.flatnonzero((t >= onset) & (P[i, :, j] >= 0.95))
        iso = bool(P[i, -1, j] >= 0.95 and P[i, -1, others].max() <= 0.05 and not wrong)
        report["runs"].setdefault(name, {})[str(m)] = {
            "isolated": iso, "delay_s": round(float(t[own[0]] - onset), 3) if own.size else None,
            "final_own": round(float(P[i, -1, j]), 4),
            "final_max_other": round(float(P[i, -1, others].max()), 4),
            "wrong": wrong}
    for name, by in report["runs"].items():
        ok = [float(m) for m, r in by.items() if r["isolated"]]
        report["smallest_isolated"][name] = min(ok) if ok else None
    return report


# ---------------------------------------------------------------------------------- sensor checks
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
        from ...errors import DataError

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
    from ...detect import design_drift, design_gain, design_intermittent, design_stuck

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
