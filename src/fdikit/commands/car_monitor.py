"""``fdikit car scenario`` and ``fdikit car monitor-log``: the passenger-car health monitor (ng-chen-speyer).

* ``fdikit car scenario --list``: the named experiments of Section V;
* ``fdikit car scenario NAME [--json] [--plot FILE] [--report FILE.html]``: run one (simulate,
  monitor, summarise: detection time, isolated fault, peak probability of every hypothesis, false
  announcements); ``--plot`` draws paper Figs. 4-7, ``--report`` writes the HTML report;
* ``fdikit car monitor-log PATH --inject SPEC [--json] [--plot FILE] [--report FILE.html]``: the lateral
  monitor designed for the RAV4 (:mod:`fdikit.systems.car.monitor_rav4`) on the real minute in PATH with
  faults of any type injected into the real signals (SPEC :data:`INJECT_HELP`:
  ``stuck:STEER_ANGLE_SENSOR@15``, ``drift:YAW_RATE:0.02/s@10`` (deg/s per s),
  ``gain:WHEEL_SPEED_FL:1.01@20``,
  ``bias:ACCEL_Y:1.0@25``, ``intermittent:WHEEL_SPEED_RL:1.0@12``, ``yaw_rate:0.03@40`` = a bias of 0.03 rad/s
  on the internal yaw-rate channel; comma-separated for several; ``none`` for the unaltered log).
"""

from __future__ import annotations

import argparse
from pathlib import Path

#: The --inject syntax (fdikit.systems.car.monitor_rav4.parse_inject).
INJECT_HELP = (
    "faults to inject, comma-separated: [TYPE:]SIGNAL[:VALUE]@START[-END][;period=P;duty=D], times in s "
    "from the start of the log. TYPE is bias (default), drift (VALUE a slope per s, e.g. 0.05/s), gain "
    "(VALUE the factor, 1.02 = reads 2 %% high), stuck (at its value at START, or at VALUE) or "
    "intermittent (a bias VALUE on for duty*period s of every period s; default period=2, duty=0.25). "
    "SIGNAL is a CAN signal in its own unit (STEER_ANGLE deg, YAW_RATE deg/s, ACCEL_Y m/s^2 in the "
    "sensor's sign, WHEEL_SPEED_FL..RR and SPEED km/h; also MESSAGE.SIGNAL), a CAN message (every "
    "signal of it, e.g. STEER_ANGLE_SENSOR: the whole steering sensor), a raw channel (steer_angle, "
    "yaw_rate_raw, wheel_rl ... SI units) or an internal channel (steer road-wheel rad, a_y m/s^2 left "
    "positive, yaw_rate rad/s, w_front_diff, w_rear_diff m/s). Examples: stuck:STEER_ANGLE_SENSOR@15, "
    "drift:YAW_RATE:0.02/s@10, gain:WHEEL_SPEED_FL:1.01@20, bias:ACCEL_Y:1.0@25, "
    "intermittent:WHEEL_SPEED_RL:1.0@12;period=2;duty=0.25, yaw_rate:0.03@40 (a 0.03 rad/s bias). "
    "'none' (default) runs the unaltered log")



def add_monitor_parsers(car_actions) -> None:
    """Add the ``scenario`` and ``monitor-log`` actions to the ``car`` actions subparser.

    Examples
    --------
    >>> import argparse
    >>> p = argparse.ArgumentParser()
    >>> add_monitor_parsers(p.add_subparsers(dest="car_action"))
    >>> p.parse_args(["scenario", "--list"]).list
    True
    """
    s = car_actions.add_parser(
        "scenario",
        help="run a health-monitor experiment of ng-chen-speyer, Section V",
        description="Run one of the named health-monitor experiments of ng-chen-speyer (Section V) on the "
        "simulated passenger car: simulate the drive with its fault, run the monitor and print "
        "the detection delay, the isolated fault, the number of false announcements and the "
        "peak probability of every fault hypothesis. Without NAME, or with --list, it lists "
        "the scenarios. --json prints one JSON object; --plot also writes a figure of the "
        "residual norms and the probabilities.",
    )
    s.add_argument("name", nargs="?", help="scenario name (see --list)")
    s.add_argument("--list", action="store_true", help="list the scenarios with a one-line description")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    s.add_argument(
        "--plot",
        metavar="FILE",
        help="write a figure of the residual norms and probabilities to this image file; the "
        "format follows the extension, e.g. .png or .pdf",
    )
    s.add_argument(
        "--report",
        metavar="FILE.html",
        help="write a self-contained HTML report (signals, residual norms, probabilities, events)",
    )
    s.add_argument("--seed", type=int, default=1, help="random seed of the simulated noise (default 1)")
    s.set_defaults(func=_scenario)

    m = car_actions.add_parser(
        "monitor-log",
        help="lateral monitor on a recorded log, with injected faults",
        description="Run the lateral health monitor designed for the Toyota RAV4 on its recorded minute "
        "of highway driving, with sensor faults added to the real signals. The monitor is "
        "calibrated on the first half of the minute. Prints the log length, the detection "
        "delay and the isolated fault of the first injected fault, the false announcements "
        "and the peak probability of every fault hypothesis. --json prints one JSON object.",
    )
    m.add_argument(
        "path",
        help="data directory holding the CAN log drive.blf and the signal database "
        "toyota_rav4.dbc (e.g. ../shared/data/rav4-highway)",
    )
    m.add_argument("--inject", default="none", help=INJECT_HELP)
    m.add_argument(
        "--plot",
        metavar="FILE",
        help="write a figure of the monitor channels, residual norms and probabilities with the "
        "announcements marked; the format follows the extension, e.g. .png or .pdf",
    )
    m.add_argument(
        "--report",
        metavar="FILE.html",
        help="write a self-contained HTML report of the run (raw and monitor signals, residual "
        "norms, probabilities, events)",
    )
    m.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    m.set_defaults(func=_monitor_log)


def _check_outputs(args) -> None:
    """Output paths are checked before any computation."""
    from ..errors import DataError
    from ..report import check_output_path

    if getattr(args, "report", None):
        check_output_path(args.report)
    if getattr(args, "plot", None):
        p = Path(args.plot)
        if not (p.parent if str(p.parent) else Path(".")).is_dir():
            raise DataError(f"{p}: the folder {str(p.parent)!r} does not exist")
        if p.suffix.lower() not in (
            ".png",
            ".pdf",
            ".svg",
            ".jpg",
            ".jpeg",
            ".eps",
            ".ps",
            ".tif",
            ".tiff",
            ".webp",
        ):
            raise DataError(f"{p}: unknown image format {p.suffix!r} (use .png, .pdf, .svg, ...)")


def _scenario(args: argparse.Namespace) -> int:
    from ..report.progress import progress_wanted
    from ..systems.car.scenarios import SCENARIOS, plot_scenario, run_scenario
    from ._output import print_json

    if args.list or not args.name:
        rows = {n: s.description for n, s in SCENARIOS.items()}
        if args.json:
            print_json({"scenarios": rows})
        else:
            for n, d in rows.items():
                print(f"{n:28s} {d}")
        return 0
    _check_outputs(args)
    out = run_scenario(args.name, seed=args.seed, progress=progress_wanted(args.json))
    s = out["summary"]
    if args.plot:
        s["plot"] = plot_scenario(out, args.plot)
    if args.report:
        s["report"] = str(_scenario_report(out, args.report))
    if args.json:
        print_json(s)
    else:
        print(f"{s['name']}: {s['description']}")
        print(
            f"  detection delay {s['detection_delay_s']} s, isolated {s['isolated']}, "
            f"false announcements {len(s['false_announcements'])}"
        )
        for f, p in s["peak_probability"].items():
            print(f"  peak P({f}) = {p:.4f}")
        for k in ("plot", "report"):
            if k in s:
                print(f"  {k}: {s[k]}")
    return 0


def _scenario_report(out: dict, path: str):
    from ..report import monitor_report

    s = out["summary"]
    sig = out["inputs"].concat_channels(out["measurements"])
    stats = out["features"].concat_channels(out["probabilities"])
    meta = {
        "scenario": s["name"],
        "description": s["description"],
        "block": s["block"],
        "injected": "{target} {magnitude} from {onset_s} s".format(**s["injected"]),
        "detection delay (s)": s["detection_delay_s"],
        "isolated": s["isolated"],
        "false announcements": len(s["false_announcements"]),
        "design": "calibrated in this run (fdikit.systems.car.monitor.calibrate_monitor)",
    }
    return monitor_report(
        path,
        signals=sig,
        statistics=stats,
        events=out.get("events", []),
        level=s.get("announcement_level"),
        title=f"fdikit car scenario: {s['name']}",
        meta=meta,
    )


#: Units of the RAV4 monitor channels (fdikit.systems.car.monitor_rav4.CHANNELS and the speed).
_UNITS = {
    "steer": "rad",
    "speed": "m/s",
    "a_y": "m/s^2",
    "yaw_rate": "rad/s",
    "w_front_diff": "m/s",
    "w_rear_diff": "m/s",
}


def _rav4_run(args):
    """The RAV4 monitor's signals and result for the figure and the report (the design is cached)."""
    from ..systems.car.monitor_rav4 import inject, parse_inject, rav4_monitor

    mon = rav4_monitor(str(args.path))
    faults = parse_inject(args.inject)
    sig = inject(mon.raw, faults, mon.artifacts["filter"].pre)
    return mon, faults, sig, mon.run(sig)


def _rav4_plot(mon, faults, sig, res, path: str) -> str:
    from ..report.figures import panel_figure, save

    t = sig.t - sig.t[0]
    chans = mon.artifacts["filter"].monitor_channels(sig)
    col1 = [
        {
            "title": f"monitor channel {n}",
            "ylabel": n,
            "unit": u or _UNITS.get(n, ""),
            "traces": [(n, chans.values[0, :, j])],
            "legend": False,
        }
        for j, (n, u) in enumerate(zip(chans.names, chans.units))
    ]
    st = res.statistics
    feats = [n for n in st.names if n.startswith("|")]
    col2 = [
        {"title": n, "ylabel": "residual norm", "unit": "–", "traces": [(n, st[n][0])], "legend": False}
        for n in feats
    ]
    probs = [f"P:{f}" for f in mon.faults if f"P:{f}" in st.names]
    col2.append(
        {
            "title": "fault probabilities (MHSSPT)",
            "ylabel": "probability",
            "unit": "–",
            "ylim": (-0.05, 1.05),
            "thresholds": [("announce (held 10 samples)", 0.95)],
            "traces": [(n, st[n][0]) for n in probs],
        }
    )
    events = [(e.t - sig.t[0], e.hypothesis) for e in res.events]
    shade = [(f.start, float(f.end if f.end is not None else t[-1]), "fault", "tab:red") for f in faults[:1]]
    half = mon.record.get("half_s")
    if half:
        shade.append((0.0, float(half), "calibration", "0.6"))
    fig = panel_figure(
        t,
        [col1, col2],
        title=f"RAV4 lateral monitor, injected: {args_inject(faults)} "
        "(grey: calibration half; red: injected fault)",
        events=events,
        shade=shade,
        panel_size=(6.0, 1.35),
    )
    return save(fig, path)


def args_inject(faults) -> str:
    """A one-line description of injected faults (Fault objects or (channel, magnitude, start) biases)."""
    out = []
    for f in faults:
        if isinstance(f, tuple):
            out.append(f"{f[0]} {f[1]:+g} from {f[2]:g} s")
        else:
            val = {k: getattr(f, k) for k in ("magnitude", "slope", "gain", "value") if hasattr(f, k)}
            v = ", ".join(f"{k} {x:g}" for k, x in val.items() if x is not None)
            what = f"{type(f).__name__.lower()} on {f.target}" + (f" ({v})" if v else "")
            out.append(f"{what} from {f.start:g} s")
    return ", ".join(out) or "none"


def _rav4_report(args, mon, faults, sig, res) -> str:
    from ..report import monitor_report, monitor_thresholds

    t0 = sig.t[0]
    meta = {
        "data": str(args.path),
        "injected": args_inject(faults),
        "calibrated on (s)": mon.record.get("half_s"),
        "design": "fitted and calibrated in this run (fdikit.systems.car.monitor_rav4.rav4_monitor)",
    }
    from ..signals import Signals

    sig0 = Signals(sig.t - t0, sig.values, sig.names, sig.units, check=False)
    shift = lambda s: Signals(s.t - t0, s.values, s.names, s.units, check=False)  # noqa: E731
    from ..monitor import MonitorResult

    r0 = MonitorResult(
        shift(res.residuals),
        shift(res.statistics),
        [type(e)(e.run, e.k, e.t - t0, e.hypothesis, e.value) for e in res.events],
        res.valid,
        res.invalid,
    )
    return str(
        monitor_report(
            args.report,
            signals=sig0,
            result=r0,
            thresholds=monitor_thresholds(mon.monitor),
            level=float(mon.decision.level),
            title="fdikit car monitor-log: RAV4 lateral monitor",
            meta=meta,
        )
    )


def _monitor_log(args: argparse.Namespace) -> int:
    from ..report.progress import progress_steps, progress_wanted
    from ..systems.car.monitor_rav4 import run_rav4_log
    from ._output import print_json

    _check_outputs(args)
    extra = bool(args.plot or args.report)
    with progress_steps(progress_wanted(args.json), 2 + extra, "car monitor-log") as steps:
        steps.step("read the log, fit the model, design and calibrate the monitor, run it")
        res = run_rav4_log(args.path, args.inject)
        if extra:
            steps.step("figure and report")
            run = _rav4_run(args)
            if args.plot:
                res["plot"] = _rav4_plot(*run, args.plot)
            if args.report:
                res["report"] = _rav4_report(args, *run)
        steps.step("done")
    if args.json:
        print_json(res)
    else:
        print(f"{res['data']}: {res['seconds']:.1f} s, calibrated on {res['calibrated_on_s']} s")
        if "expected_sensor" in res:
            print(
                f"  injected {res['inject']}: isolated {res['isolated']} (sensor {res['expected_sensor']}, "
                f"{'right' if res['isolated_ok'] else 'WRONG'}), "
                f"detection delay {res['detection_delay_s']} s, "
                f"announced after {res['announcement_delay_s']} s"
            )
        print(f"  false announcements: {len(res['false_announcements'])}")
        for part in ("calibration", "held_out"):
            h = res[part]
            print(
                f"  {part.replace('_', '-')} half {h['span_s']} s: {h['announcements']} announcements, "
                f"{len(h['false_announcements'])} false, "
                f"max wrong probability {h['max_wrong_probability']:.3g}"
            )
        for f, p in res["peak_probability"].items():
            print(f"  peak P({f}) = {p:.4f}")
        for k in ("plot", "report"):
            if k in res:
                print(f"  {k}: {res[k]}")
    return 0
