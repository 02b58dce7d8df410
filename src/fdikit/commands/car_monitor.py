"""``fdikit car scenario`` and ``fdikit car monitor-log``: the passenger-car health monitor (ng-chen-speyer).

* ``fdikit car scenario --list``: the named experiments of Section V;
* ``fdikit car scenario NAME [--json] [--plot FILE]``: run one (simulate, monitor, summarise:
  detection time, isolated fault, peak probability of every hypothesis, false announcements);
* ``fdikit car monitor-log PATH --inject SPEC [--json]``: the lateral monitor designed for the
  RAV4 (:mod:`fdikit.systems.car.monitor_rav4`) on the real minute in PATH with faults
  injected into the real signals (SPEC ``yaw_rate:0.03@40`` = a bias of 0.03 rad/s on the
  yaw-rate sensor from 40 s; ``wheel_rl:0.6@40`` = +0.6 m/s on the rear-left wheel-speed sensor;
  comma-separated for several; ``none`` for the unaltered log).
"""

from __future__ import annotations

import argparse


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
        "scenario", help="run a health-monitor experiment of ng-chen-speyer, Section V",
        description="Run one of the named health-monitor experiments of ng-chen-speyer (Section V) on the "
                    "simulated passenger car: simulate the drive with its fault, run the monitor and print "
                    "the detection delay, the isolated fault, the number of false announcements and the "
                    "peak probability of every fault hypothesis. Without NAME, or with --list, it lists "
                    "the scenarios. --json prints one JSON object; --plot also writes a figure of the "
                    "residual norms and the probabilities.")
    s.add_argument("name", nargs="?", help="scenario name (see --list)")
    s.add_argument("--list", action="store_true", help="list the scenarios with a one-line description")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    s.add_argument("--plot", metavar="FILE",
                   help="write a figure of the residual norms and probabilities to this image file; the "
                   "format follows the extension, e.g. .png or .pdf")
    s.add_argument("--seed", type=int, default=1, help="random seed of the simulated noise (default 1)")
    s.set_defaults(func=_scenario)

    m = car_actions.add_parser(
        "monitor-log", help="lateral monitor on a recorded log, with injected faults",
        description="Run the lateral health monitor designed for the Toyota RAV4 on its recorded minute "
                    "of highway driving, with sensor faults added to the real signals. The monitor is "
                    "calibrated on the first half of the minute. Prints the log length, the detection "
                    "delay and the isolated fault of the first injected fault, the false announcements "
                    "and the peak probability of every fault hypothesis. --json prints one JSON object.")
    m.add_argument("path", help="data directory holding the CAN log drive.blf and the signal database "
                   "toyota_rav4.dbc (e.g. ../shared/data/rav4-highway)")
    m.add_argument("--inject", default="none",
                   help="faults to inject, CHANNEL:MAGNITUDE@START with START in s, comma-separated for "
                   "several: e.g. yaw_rate:0.03@40 (a 0.03 rad/s bias on the yaw-rate sensor from 40 s) or "
                   "wheel_rl:0.6@40 (+0.6 m/s on the rear-left wheel-speed sensor). CHANNEL is steer "
                   "(road-wheel angle, rad), a_y (lateral acceleration, m/s^2, left positive), yaw_rate "
                   "(rad/s), w_front_diff or w_rear_diff (left-right wheel-speed difference of an axle, "
                   "m/s), or one wheel-speed sensor wheel_fl, wheel_fr, wheel_rl, wheel_rr (m/s). 'none' "
                   "(default) runs the unaltered log")
    m.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    m.set_defaults(func=_monitor_log)


def _scenario(args: argparse.Namespace) -> int:
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
    out = run_scenario(args.name, seed=args.seed)
    s = out["summary"]
    if args.plot:
        s["plot"] = plot_scenario(out, args.plot)
    if args.json:
        print_json(s)
    else:
        print(f"{s['name']}: {s['description']}")
        print(f"  detection delay {s['detection_delay_s']} s, isolated {s['isolated']}, "
              f"false announcements {len(s['false_announcements'])}")
        for f, p in s["peak_probability"].items():
            print(f"  peak P({f}) = {p:.4f}")
    return 0


def _monitor_log(args: argparse.Namespace) -> int:
    from ..systems.car.monitor_rav4 import run_rav4_log
    from ._output import print_json

    res = run_rav4_log(args.path, args.inject)
    if args.json:
        print_json(res)
    else:
        print(f"{res['data']}: {res['seconds']:.1f} s, calibrated on {res['calibrated_on_s']} s")
        if "expected" in res:
            print(f"  injected {res['inject']}: isolated {res['isolated']} (expected {res['expected']}), "
                  f"delay {res['detection_delay_s']} s")
        print(f"  false announcements: {len(res['false_announcements'])}")
        for f, p in res["peak_probability"].items():
            print(f"  peak P({f}) = {p:.4f}")
    return 0
