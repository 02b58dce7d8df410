"""The RAV4 lateral filter bank: filter sets 4-6 designed on the fitted model, and the runtime
generator that reads the raw CAN channels (:class:`Rav4LateralFilter`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ....errors import DataError
from ....model.linear import GROUPS, LinearFaultModel
from ....residuals import FilterDesign, fault_detection_filter
from ....residuals.scheduled import ScheduledFilter
from ....signals import Signals
from ..monitor.settings import FILTER_SETS, LATERAL_SETS
from .channels import _RAW_U, _RAW_Y, CHANNELS, Rav4Preprocessing

__all__ = ["DISTURBANCES", "Rav4LateralFilter"]


#: Disturbance directions that can join every filter's nuisance set (state-equation columns of the
#: linear model, per unit of disturbance): road bank (a lateral force m g sin(theta) at the centre of
#: gravity: v_y' += g sin(theta); the accelerometer measures the tyre forces, so it does not see
#: the bank directly) and a yaw-moment disturbance (r' += M_z / I_z).
DISTURBANCES = {"road_bank": 1, "yaw_moment": 2}


def _design_sets(model: LinearFaultModel, dt: float, noise: dict[str, float], q_weight: float,
                 nuisance: tuple[str, ...] = ()):
    """Sets 4-6 on ``model`` (discretised at ``dt``).

    Designed on outputs scaled by their noise (unit measurement noise, R = I in whatever output
    space the design projects to: yaw rate and wheel-speed differences are all multiples of r
    here, so rank C = 2 and the sensor faults are partly removed by projection); the scaling is
    then folded into the filter's measurement gains: filter(y) = filter_scaled(S y).
    """
    if nuisance:
        n = model.n_states
        extra = []
        for name in nuisance:
            if name not in DISTURBANCES:
                raise DataError(f"unknown disturbance {name!r}; known: {sorted(DISTURBANCES)}")
            extra.append((name, np.eye(n)[:, DISTURBANCES[name]], np.zeros(model.n_outputs)))
        model = model.with_faults(*extra)
    md = model.discretize(dt)
    S = np.array([1.0 / max(noise[y], 1e-9) for y in md.outputs])
    ms = md.with_matrices(md.A, S[:, None] * md.C, {g: (md.B_of(g), S[:, None] * md.D_of(g)) for g in GROUPS})
    designs: dict[int, dict[str, Any]] = {}
    for s in LATERAL_SETS:
        designs[s] = {}
        for t in FILTER_SETS[s]:
            others = [o for o in FILTER_SETS[s] if o != t] + list(nuisance)
            d = fault_detection_filter(ms, t, others, name=f"set{s}/{t}", Q=q_weight * np.eye(md.n_states))
            iy = [md.outputs.index(y) for y in d.y_names]
            d.By, d.Dy = d.By * S[iy], d.Dy * S[iy]
            d.internal = None  # against the scaled model; recompute with internal_form(d, model)
            designs[s][t] = d
    return md, designs


class Rav4LateralFilter(ScheduledFilter):
    """The RAV4 lateral residual generator on the raw CAN channels: preprocessing, then the
    speed-scheduled (band-limited) filter bank.

    Reads ``u`` = ``steer_angle, steer_fraction, speed`` and ``y`` = ``yaw_rate_raw, accel_y_raw,
    wheel_fl, wheel_fr, wheel_rl, wheel_rr`` (SI: rad, m/s, rad/s, m/s^2; :data:`RAW_CHANNELS`),
    maps them with ``pre`` to the monitor channels and runs :class:`~fdikit.residuals.ScheduledFilter`
    (scheduled by the speed) on them.
    Saveable (``to_dict`` / ``from_dict``: a design artifact) and checkpointable (the filter
    states).

    Parameters
    ----------
    pre : Rav4Preprocessing
    speeds : sequence of float
        Design speeds (m/s).
    designs : sequence of FilterDesign
        One per speed, reading ``u = [steer]`` and ``y = [a_y, yaw_rate, w_front_diff, w_rear_diff]``.

    Examples
    --------
    >>> mk = lambda g: FilterDesign(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((0, 4)), np.zeros((1, 0)),
    ...                             np.zeros((1, 1)), np.array([[0.0, g, 0.0, 0.0]]), 0.02, ["steer"],
    ...                             ["a_y", "yaw_rate", "w_front_diff", "w_rear_diff"], ["r"])
    >>> pre = Rav4Preprocessing(16.0, 0.0, 0.01, 0.0, 1.0, 0.0, 0.0)
    >>> g = Rav4LateralFilter(pre, [10.0, 20.0], [mk(1.0), mk(3.0)])
    >>> g.reset(1)
    >>> round(float(g.step([0.0, 0.0, 15.0], [0.03, 0.0, 1.0, 1.0, 1.0, 1.0])[0, 0]), 12)  # 2 (0.03 - 0.01)
    0.04
    """

    def __init__(self, pre: Rav4Preprocessing, speeds, designs):
        super().__init__(speeds, designs)
        d0 = self.designs[0]
        if list(d0.u_names) != ["steer"] or list(d0.y_names) != CHANNELS[1:]:
            raise DataError(f"RAV4 filters must read u = ['steer'], y = {CHANNELS[1:]}; got {d0.u_names}, "
                            f"{d0.y_names}")
        self.pre = pre
        self.u_names = list(_RAW_U)
        self.y_names = list(_RAW_Y)

    def to_dict(self) -> dict[str, Any]:
        # the filter matrices as arrays: an artifact stores them in its NPZ (compact, exact)
        mats = ("A", "Bu", "By", "C", "Du", "Dy")
        designs = [{k: (np.asarray(v, float) if k in mats else v) for k, v in d.to_dict().items()}
                   for d in self.designs]
        return {"pre": self.pre.to_dict(), "speeds": self.speeds.tolist(), "designs": designs}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Rav4LateralFilter:
        return cls(Rav4Preprocessing.from_dict(d["pre"]), d["speeds"],
                   [FilterDesign.from_dict(x) for x in d["designs"]])

    def monitor_channels(self, signals: Signals) -> Signals:
        """The preprocessed channels ``steer, speed`` + :data:`CHANNELS` [1:] of raw ``signals``."""
        u, y = self.pre.apply(signals.values[:, :, signals.index(self.u_names)],
                              signals.values[:, :, signals.index(self.y_names)])
        return Signals(signals.t, np.concatenate([u, y], axis=2), ["steer", "speed", *CHANNELS[1:]],
                       check=False)

    def _step(self, u, y):
        uu, yy = self.pre.apply(u, y)
        return super()._step(uu, yy)

    def run(self, signals: Signals) -> Signals:
        return super().run(self.monitor_channels(signals))
