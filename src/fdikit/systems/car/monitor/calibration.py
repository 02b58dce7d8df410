"""Calibration of the car monitor (ng-chen-speyer, Section IV-E): the MHSSPT densities of one
block from simulations of every fault (:func:`calibrate_monitor`), and the monitor assembled from a
design and a calibration (:func:`build_monitor`, :class:`CarMonitor`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ....base import ResidualGenerator
from ....detect import Hold
from ....detect.features import FeatureNorms
from ....detect.mhsspt import WarmupMHSSPT, calibrate_densities, extend_ranges, floor_std
from ....faults import Bias
from ....monitor import Decision, Monitor
from ....signals import Signals
from ..driving import simulate_drive
from .design import CarMonitorDesign, design_car_monitor
from .generators import _generators, _generators_and_features
from .settings import (
    BLOCK_SETTINGS,
    LATERAL_FAULTS,
    LONGITUDINAL_FAULTS,
    MAGNITUDES,
    car_signals,
    sensor_noise,
)

__all__ = ["CarMonitor", "build_monitor", "calibrate_monitor"]


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
