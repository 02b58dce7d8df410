"""The runtime residual generators of the car monitor: the filters fed with deviations from the
operating point (:class:`OffsetFilter`), the parity equations (:class:`ParityEquations`), and the
generators and feature groups of one block built from a design (speed-scheduled for the
longitudinal block).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from ....base import ResidualGenerator
from ....detect.features import FeatureNorms
from ....errors import ModelError
from ....residuals import FaultDetectionFilter, FilterDesign, stack_designs
from ....residuals.scheduled import ScheduledFilter
from ....residuals.transforms import delayed_feedthrough
from ....signals import Signals
from ..model import DEFAULT_PARAMS
from .design import CarMonitorDesign, design_car_monitor
from .settings import LATERAL_SETS, LONGITUDINAL_SETS

__all__ = ["OffsetFilter", "ParityEquations"]


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
