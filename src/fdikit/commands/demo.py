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


def section_linear(seed: int = 0, details: dict | None = None) -> dict:
    """Sensor-bias detection on a linear two-mass plant (fdikit.systems.two_mass).

    ``details``, when given, receives the signals, the monitor and its result (for the report).
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


def _linear_report(rep, det: dict) -> None:
    """The linear section in full: the monitor run, the fault signature and an ROC."""
    import numpy as np

    from ..faults import Bias
    from ..report import add_monitor, add_roc, add_signature, monitor_thresholds, roc_curve
    from ..systems import two_mass

    mon, res = det["monitor"], det["result"]
    sig = det["signals"]
    from ..signals import Signals

    sig = Signals(sig.t, sig.values, sig.names, ["N", "m", "m"], check=False)
    add_monitor(rep, signals=sig, result=res, thresholds=monitor_thresholds(mon), title_prefix="linear: ")
    gen = mon.generators[0]
    thr = monitor_thresholds(mon)
    # the fault signature: mean |residual| / threshold after the onset, for each sensor fault
    faults = ["sensor:pos1", "sensor:pos2"]
    sigm = np.zeros((len(faults), len(gen.output_names)))
    for i, f in enumerate(faults):
        r = gen.run(two_mass.record([Bias(f, det["bias"], start=det["onset"])], 20, det["seed"] + 11))
        k = r.t >= det["onset"] + 1.0
        for j, n in enumerate(gen.output_names):
            sigm[i, j] = float(np.mean(np.abs(r[n][:, k]))) / thr[n][0]
    add_signature(rep, {"matrix": sigm, "rows": faults, "columns": gen.output_names,
                        "title": "linear: fault signature", "colorbar": "mean |r| / threshold (–)",
                        "intro": "Mean absolute residual from 1 s after the onset of a sensor bias of "
                        f"{det['bias']} m, in units of each residual's threshold (20 runs each): each fault "
                        "moves its own residual."})
    # ROC of the largest |r:pos2| per run, threshold swept (200 nominal, 200 faulty runs)
    nom = gen.run(two_mass.record([], 200, det["seed"] + 21))
    bad = gen.run(two_mass.record([Bias("sensor:pos2", det["bias"] / 3, start=det["onset"])], 200,
                                  det["seed"] + 22))
    k0 = nom.t >= 1.0
    rep.section("linear: ROC", f"Largest |r:pos2| of each run after 1 s, for a threshold swept over it: 200 "
                f"nominal runs against 200 runs with a pos2 bias of {det['bias'] / 3:.3g} m (a third of the "
                "demo's).")
    add_roc(rep, {"r:pos2, max over the run": roc_curve(np.abs(nom["r:pos2"][:, k0]).max(axis=1),
                                                        np.abs(bad["r:pos2"][:, k0]).max(axis=1))})


def _write_report(path, summary: dict, details: dict) -> str:
    from .. import __version__
    from ..report import Report

    rep = Report("fdikit demo")
    rep.section("Demo", "Every section of `fdikit demo`: what ran and what it found.")
    rep.table({"fdikit version": __version__, "sections": ", ".join(summary),
               "seconds": round(sum(v.get("seconds", 0.0) for v in summary.values()), 2)})
    for name, out in summary.items():
        rep.section(f"{name}", (out.get("name") or out.get("plant") or out.get("scenario") or "") or None)
        rows = [{"key": k, "value": v if not isinstance(v, list) or len(v) <= 12 else f"{len(v)} items"}
                for k, v in out.items()]
        rep.table(rows, columns=["key", "value"])
        if name == "linear" and details.get("linear"):
            _linear_report(rep, details["linear"])
    rep.data["summary"] = summary
    return str(rep.write(path))


def default_report_path() -> str:
    import tempfile
    from pathlib import Path

    return str(Path(tempfile.gettempdir()) / "fdikit-demo-report.html")


def run(args) -> int:
    from ..report.progress import progress_steps, progress_wanted

    available = sections()
    chosen = list(available) if not args.only else args.only
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise SystemExit(f"fdikit demo: unknown section(s) {unknown}; available: {list(available)}")
    from ._output import check_output_paths

    report = args.report or default_report_path()
    args.report = report
    check_output_paths(args, "report")
    summary: dict = {}
    details: dict = {}
    with progress_steps(progress_wanted(args.json), len(chosen) + 1, "fdikit demo") as steps:
        for name in chosen:
            steps.step(f"section {name}")
            t0 = time.perf_counter()
            if name == "linear":
                details["linear"] = {}
                out = section_linear(details=details["linear"])
            else:
                out = available[name]()
            out["seconds"] = round(time.perf_counter() - t0, 3)
            summary[name] = out
            if not args.json:
                _print_section(name, out)
        steps.step("write the report")
        path = _write_report(report, summary, details)
    if args.json:
        print_json({**summary, "report": path})
    else:
        print(f"report: {path}")
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
                                   "with one entry per section instead of the tables. It ends by writing "
                                   "one HTML report of all sections and printing its path.")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the tables")
    p.add_argument("--report", metavar="FILE.html",
                   help="where to write the HTML report of all sections (default: fdikit-demo-report.html in "
                   "the system's temporary folder); its path is printed at the end (JSON key 'report')")
    p.add_argument("--only", nargs="+", metavar="SECTION",
                   help="run only these sections, e.g. --only linear abs (default: all)")
    p.set_defaults(func=run)
