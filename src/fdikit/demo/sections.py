"""The demo's sections: what ``fdikit demo`` runs, one short section per system.

Each section is a function returning a JSON-able summary (and, given ``details=``, the series its
part of the report plots):

* ``linear`` (:func:`section_linear`): a linear two-mass plant with a sensor bias; an observer
  residual, a threshold designed for a target false-alarm probability from nominal Monte Carlo runs,
  a hold rule and the Monitor say which sensor failed and when.
* the papers' systems, as they land (each system's ``demo_summary``): aircraft actuator fault
  reconstruction with cascaded sliding mode observers, an ABS stop, the ABS diagnosis and its
  directional test, the passenger car and its health monitor.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Mapping

__all__ = ["run_section", "run_sections", "section_linear", "sections"]


def section_linear(seed: int = 0, details: dict | None = None) -> dict:
    """Sensor-bias detection on a linear two-mass plant (fdikit.systems.two_mass).

    Parameters
    ----------
    seed : int
        Seed of the design runs (the faulty record uses ``seed + 1``).
    details : dict, optional
        When given, receives the signals, the monitor and its result (for the report).

    Returns
    -------
    dict
        The thresholds, the hold length, the detected fault, its detection time and delay (s), the
        false alarms before the onset and every alarm.
    """
    from ..faults import Bias
    from ..monitor import Decision, Monitor
    from ..residuals import ObserverResidual
    from ..systems import two_mass

    onset, bias = 4.0, 0.012
    # observer residuals, thresholds for a 0.1 % per-run false-alarm probability from 300 nominal
    # runs, hold Z = 5 (the same recipe as examples/two-mass/monitor.toml)
    designs = two_mass.design({"seed": seed})
    gen = ObserverResidual(designs["observer"])
    hold = designs["hold"]
    names = {f"r:{y}:alarm": f"sensor:{y}" for y in ("pos1", "pos2")}
    monitor = Monitor([gen], [hold], Decision(hold.output_names, names=names))
    faulty = two_mass.record([Bias("sensor:pos2", bias, start=onset)], 1, seed + 1)
    res = monitor.run(faulty)
    ev = res.first_event(0)
    false_alarms = [e for e in res.events if e.t < onset]
    if details is not None:
        details.update(signals=faulty, result=res, monitor=monitor, onset=onset, bias=bias, seed=seed)
    return {
        "plant": "linear two-mass system, 4 states, sensors pos1 and pos2",
        "fault": f"sensor:pos2 bias {bias} from t = {onset} s",
        "thresholds": dict(zip(gen.output_names, hold.threshold.tolist())),
        "hold_Z": hold.Z,
        "detected": ev.hypothesis if ev else None,
        "detection_time_s": ev.t if ev else None,
        "delay_s": (ev.t - onset) if ev else None,
        "false_alarms_before_onset": len(false_alarms),
        "alarms": [f"{e.hypothesis}@{e.t:.2f}s" for e in res.events],
    }


def _external(module: str, func: str = "demo_summary") -> Callable[[], dict] | None:
    """A section provided by a system module, if that system has landed."""
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name == module:
            return None
        raise
    return getattr(mod, func)


def sections() -> dict[str, Callable[[], dict]]:
    """The demo's sections that have landed: name -> a function returning its JSON-able summary.

    Returns
    -------
    dict
        ``linear`` (:func:`section_linear`), then ``reconstruct``, ``abs``, ``abs_diagnosis``,
        ``abs_directional``, ``car`` and ``car_monitor``: each system's ``demo_summary``.
    """
    out: dict[str, Callable[[], dict]] = {"linear": section_linear}
    for name, module in (("reconstruct", "fdikit.systems.aircraft.reconstruction"),
                         ("abs", "fdikit.systems.abs.plant"),
                         ("abs_diagnosis", "fdikit.systems.abs.diagnoser"),
                         ("abs_directional", "fdikit.systems.abs.detectability"),
                         ("car", "fdikit.systems.car"),
                         ("car_monitor", "fdikit.systems.car.scenarios")):
        f = _external(module)
        if f is not None:
            out[name] = f
    return out


def _accepts_details(func: Callable) -> bool:
    import inspect

    try:
        return "details" in inspect.signature(func).parameters
    except (TypeError, ValueError):
        return False


def run_section(name: str, func: Callable, det: dict) -> dict:
    """Run one section; ``det`` receives the series its report plots (when the section gives them).

    Parameters
    ----------
    name : str
        The section's name (a key of :func:`sections`).
    func : callable
        The section's function.
    det : dict
        Filled with the section's details (``details=`` of its function, when it takes one).

    Returns
    -------
    dict
        The section's JSON-able summary.
    """
    if name == "linear":
        return section_linear(details=det)
    if _accepts_details(func):
        return func(details=det)
    return func()


def run_sections(chosen: Mapping[str, Callable], steps=None,
                 on_section: Callable[[str, dict], None] | None = None) -> tuple[dict, dict]:
    """Run demo sections one after another, timing each.

    Parameters
    ----------
    chosen : mapping
        Section name -> its function, in the order to run them (a selection of :func:`sections`).
    steps : object, optional
        Progress: its ``step(text)`` is called before each section
        (e.g. :func:`fdikit.report.progress.progress_steps`).
    on_section : callable, optional
        Called as ``on_section(name, summary)`` after each section (e.g. to print it).

    Returns
    -------
    summary : dict
        Section name -> its summary, with ``seconds`` (wall time of the section, s) added.
    details : dict
        Section name -> the series its part of the report plots (:func:`write_report`).
    """
    summary: dict = {}
    details: dict = {}
    for name, func in chosen.items():
        if steps is not None:
            steps.step(f"section {name}")
        t0 = time.perf_counter()
        details[name] = {}
        out = run_section(name, func, details[name])
        out["seconds"] = round(time.perf_counter() - t0, 3)
        summary[name] = out
        if on_section is not None:
            on_section(name, out)
    return summary, details
