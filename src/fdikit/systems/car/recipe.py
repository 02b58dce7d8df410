"""Design recipe of the config-driven passenger-car health monitor (``examples/passenger-car``).

``fdikit design examples/passenger-car/monitor.toml`` calls :func:`design` with the config's
``[design.params]`` and saves what it returns as artifacts: the whole calibrated car monitor
(both blocks: six filter sets, two parity equations, features, both MHSSPTs, warm-up and
hold-then-announce) as one :class:`~fdikit.systems.car.monitor_fused.FusedCarMonitor`,
whose announcement channels ``A:<fault>`` the config's ``[decision]`` reads directly.

The monitor reads deviations from the operating point (ng-chen-speyer, Section V: "the nominal values
of the control commands and measurements have to be subtracted from the vehicle generated
data"): the config subtracts them with each channel's ``offset``, and
:func:`operating_point` gives the values for a design speed.
"""

from __future__ import annotations

from typing import Any

from ...errors import DataError
from .monitor import calibrate_monitor, design_car_monitor
from .monitor_fused import FusedCarMonitor

__all__ = ["DEFAULTS", "design", "design_claim", "operating_point"]

#: Default recipe parameters (see :func:`design`).
DEFAULTS: dict[str, Any] = {"speed": 20.0, "dt": 0.01, "seed": 11, "calibration_seconds": 10.0}

#: Onset (s) of the faults in the calibration simulations (:func:`calibrate_monitor`'s default).
_ONSET = 6.0


def operating_point(speed: float = 20.0) -> dict[str, float]:
    """Nominal commands and measurements (channel units) of the design at ``speed`` (m/s): the
    ``offset`` of each channel in the config.

    Examples
    --------
    >>> op = operating_point(20.0)                     # doctest: +SKIP
    >>> round(op["w_rear_sum"], 3)                     # doctest: +SKIP
    121.212
    """
    des = design_car_monitor(float(speed))
    return {**des.u0, **des.y0}


def design(params: dict | None = None) -> dict[str, Any]:
    """Design and calibrate the car monitor: ``{"car": FusedCarMonitor}``.

    Parameters
    ----------
    params : dict, optional
        ``speed`` (m/s, default 20): operating speed of the linearisation, of the filter designs
        and of the calibration drives (the paper uses 20 and 24 m/s); the config's offsets must be
        :func:`operating_point` at this speed.
        ``dt`` (s, default 0.01): sample time of the monitor; the log must be sampled at it (the
        car monitor is designed for 100 Hz: other values are refused).
        ``seed`` (int, default 11): noise seed of the calibration simulations.
        ``calibration_seconds`` (s, default 10, >= 8): length of every calibration simulation (the
        faults start at 6 s; the densities use the features from 6.1 s to the end, so this
        sets the calibration sample size).

    Returns
    -------
    dict
        ``"car"``: the :class:`FusedCarMonitor` (``deviations=True``), outputs ``P:<fault>``
        (probability) and ``A:<fault>`` (announced, 0/1) for the 7 longitudinal and 5 lateral
        faults.

    Examples
    --------
    >>> designs = design({"speed": 20.0})              # doctest: +SKIP
    >>> designs["car"].faults[:2]                      # doctest: +SKIP
    ['throttle', 'brake_actuator']
    """
    p = {**DEFAULTS, **(params or {})}
    unknown = sorted(set(p) - set(DEFAULTS))
    if unknown:
        raise DataError(f"car recipe: unknown parameters {unknown}; known: {sorted(DEFAULTS)}")
    speed, dt, seed, dur = float(p["speed"]), float(p["dt"]), int(p["seed"]), float(p["calibration_seconds"])
    if not 5.0 <= speed <= 40.0:
        raise DataError(f"car recipe: speed must be in [5, 40] m/s, got {speed}")
    des_dt = design_car_monitor(speed).dt
    if abs(dt - des_dt) > 1e-12:
        raise DataError(f"car recipe: dt = {dt} s, but the car monitor is designed for dt = {des_dt} s")
    if dur < _ONSET + 2.0:
        raise DataError(f"car recipe: calibration_seconds must be >= {_ONSET + 2.0} (faults start at "
                        f"{_ONSET} s), got {dur}")
    # the fused runtime needs fixed-speed filters: no speed schedule
    blocks = [calibrate_monitor(b, speed, duration=dur, seed=seed, schedule=()) for b in ("longitudinal",
                                                                                          "lateral")]
    car = FusedCarMonitor(blocks, deviations=True)
    return {"car": car, "_report": {"rates": "model-based (simulated nominal drives)",
                                    "claims": [design_claim(car, speed, dur, seed)]}}


def design_claim(car: FusedCarMonitor, speed: float, duration: float, seed: int) -> dict[str, Any]:
    """The announcement-rate claim of the designed car monitor (``design_report.json``).

    The monitor (announcing ``A:<fault>`` at 0.5, as the example config's ``[decision]``) runs over
    fault-free drives of the calibration's kinds (``curve`` at seed ``seed``, ``speed_change`` at
    ``seed + 1``, as :func:`~fdikit.systems.car.monitor.calibrate_monitor` simulates them for the
    no-fault densities), ``duration`` s each; the announcements per hour and their Poisson interval
    (:func:`fdikit.evaluate.announcement_claim`) are the claim ``fdikit validate`` checks on other
    nominal logs. The design data are short (two drives of ``duration`` s), so the interval is wide.

    Parameters
    ----------
    car : FusedCarMonitor
    speed : float
        Design speed, m/s.
    duration : float
        Seconds of every drive.
    seed : int
        The calibration's noise seed.

    Returns
    -------
    dict
        A ``kind="decision"`` claim per hour.
    """
    import numpy as np

    from ...evaluate import announcement_claim
    from ...monitor import Decision, Monitor
    from ...signals import Signals
    from .driving import simulate_drive
    from .monitor import car_signals, sensor_noise

    op = operating_point(speed)
    channels = [n for n in car.output_names if n.startswith("A:")]
    results = []
    for kind, sd in (("curve", seed), ("speed_change", seed + 1)):
        res = simulate_drive(kind, speed, duration=duration, runs=1, seed=sd, dt=2.5e-3, noise=sensor_noise())
        sig = car_signals(res)
        trim = np.array([op.get(n, 0.0) for n in sig.names])
        dev = Signals(sig.t, sig.values - trim, sig.names, sig.units, check=False)
        results.append(Monitor([car], [], Decision(channels, 0.5)).run(dev))
    return announcement_claim(results, f"fault-free drives of the calibration's kinds at {speed:g} m/s "
                              f"(curve, speed change; seeds {seed}, {seed + 1}; {duration:g} s each)")
