"""``fdikit car scenario`` and ``fdikit car monitor-log``: the passenger-car health monitor (ng-chen-speyer).

* ``fdikit car scenario --list``: the named experiments of Section V;
* ``fdikit car scenario NAME [--json] [--plot FILE] [--report FILE.html]``: run one (simulate,
  monitor, summarise: detection time, isolated fault, peak probability of every hypothesis, false
  announcements); ``--plot`` draws paper Figs. 4-7, ``--report`` writes the HTML report;
* ``fdikit car monitor-log PATH --inject SPEC [--json] [--plot FILE] [--report FILE.html]``: the lateral
  RAV4 monitor on the real minute in PATH with faults injected into the real signals (SPEC
  :data:`INJECT_HELP`, e.g. ``stuck:STEER_ANGLE_SENSOR@15``; ``none`` for the unaltered log).

The runs, figures and reports are :mod:`fdikit.systems.car.runs` and :mod:`~fdikit.systems.car.monitor_rav4`.
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
    from ._output import IMAGE_SUFFIXES

    if getattr(args, "report", None):
        check_output_path(args.report)
    if getattr(args, "plot", None):
        p = Path(args.plot)
        if not (p.parent if str(p.parent) else Path(".")).is_dir():
            raise DataError(f"{p}: the folder {str(p.parent)!r} does not exist")
        if p.suffix.lower() not in IMAGE_SUFFIXES:
            raise DataError(f"{p}: unknown image format {p.suffix!r} (use .png, .pdf, .svg, ...)")


def _scenario(args: argparse.Namespace) -> int:
    from ..report.progress import progress_wanted
    from ..systems.car.runs import scenario_report
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
        s["report"] = str(scenario_report(out, args.report))
    if args.json:
        print_json(s)
        return 0
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


def _monitor_log(args: argparse.Namespace) -> int:
    from ..report.progress import progress_steps, progress_wanted
    from ..systems.car.monitor_rav4 import run_rav4_log
    from ..systems.car.runs import rav4_log_figure, rav4_log_report, rav4_log_run
    from ._output import print_json

    _check_outputs(args)
    extra = bool(args.plot or args.report)
    with progress_steps(progress_wanted(args.json), 2 + extra, "car monitor-log") as steps:
        steps.step("read the log, fit the model, design and calibrate the monitor, run it")
        res = run_rav4_log(args.path, args.inject)
        if extra:
            steps.step("figure and report")
            run = rav4_log_run(args.path, args.inject)
            if args.plot:
                res["plot"] = rav4_log_figure(*run, args.plot)
            if args.report:
                res["report"] = rav4_log_report(*run, args.report, data=args.path)
        steps.step("done")
    if args.json:
        print_json(res)
        return 0
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
