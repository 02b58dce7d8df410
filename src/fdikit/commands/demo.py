"""``fdikit demo``: a tour of what fdikit does, one short section per system.

Sections (each a function returning a JSON-able summary):

* ``linear``: a linear two-mass plant with a sensor bias; an observer residual, a threshold
  designed for a target false-alarm probability from nominal Monte Carlo runs, a hold rule and
  the Monitor say which sensor failed and when.
* the papers' systems, as they land: aircraft actuator fault reconstruction with cascaded
  sliding mode observers, an ABS stop, the passenger car.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable

from ._output import print_json


def section_linear(seed: int = 0) -> dict:
    """Sensor-bias detection on a linear two-mass plant (fdikit.systems.two_mass)."""
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


def run(args) -> int:
    available = sections()
    chosen = list(available) if not args.only else args.only
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise SystemExit(f"fdikit demo: unknown section(s) {unknown}; available: {list(available)}")
    summary: dict = {}
    for name in chosen:
        t0 = time.perf_counter()
        out = available[name]()
        out["seconds"] = round(time.perf_counter() - t0, 3)
        summary[name] = out
        if not args.json:
            _print_section(name, out)
    if args.json:
        print_json(summary)
    return 0


def _print_section(name: str, out: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"fdikit demo: {name}", show_header=False, title_justify="left")
    table.add_column("what", style="bold")
    table.add_column("value")
    for k, v in out.items():
        if isinstance(v, float):
            v = f"{v:.4g}"
        elif isinstance(v, dict):
            v = ", ".join(f"{a}={b:.4g}" if isinstance(b, float) else f"{a}={b}" for a, b in v.items())
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            v = "\n".join(", ".join(f"{a}={b:.4g}" if isinstance(b, float) else f"{a}={b}"
                                    for a, b in item.items()) for item in v)
        table.add_row(k, str(v))
    Console().print(table)


def register(sub) -> None:
    p = sub.add_parser("demo", help="run a short demonstration of every system",
                       description="Simulate, detect, isolate and reconstruct faults on the "
                                   "library's example plants, and print what was found: one table per "
                                   "section, with the time each took. The sections are linear (a sensor "
                                   "bias on a linear two-mass plant), reconstruct (aircraft actuator fault "
                                   "reconstruction, ng-tan-edwards-kuang), abs, abs_diagnosis and "
                                   "abs_directional (the ABS benchmark of luo-et-al), car and car_monitor "
                                   "(the passenger car of ng-chen-speyer). --json prints one JSON object "
                                   "with one entry per section instead of the tables.")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the tables")
    p.add_argument("--only", nargs="+", metavar="SECTION",
                   help="run only these sections, e.g. --only linear abs (default: all)")
    p.set_defaults(func=run)
