"""Design of the car monitor's residual generators at one operating speed: the six filter sets
on the reduced linear models and the parity equations' operating point
(:func:`design_car_monitor`, :class:`CarMonitorDesign`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ....errors import ConditionError, ModelError
from ....residuals import FilterDesign, fault_detection_filter, internal_form
from ....residuals.transforms import whiten_design
from ..linear import CarLinearization, linearize_car
from ..model import OUTPUTS, PassengerCar
from .settings import (
    FILTER_SETS,
    LATERAL_Q_WEIGHT,
    LATERAL_SETS,
    LONGITUDINAL_SETS,
    SENSOR_NOISE_STD,
    WHITENED_BLOCKS,
)

__all__ = ["CarMonitorDesign", "design_car_monitor"]


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
    from ..nonlinearity import nonlinearity_directions

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
    from ....model.linear import GROUPS

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
