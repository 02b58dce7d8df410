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
    s = car_actions.add_parser("scenario",
                               help="run a health-monitor experiment of ng-chen-speyer, Section V")
    s.add_argument("name", nargs="?", help="scenario name (see --list)")
    s.add_argument("--list", action="store_true", help="list the scenarios")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.add_argument("--plot", metavar="FILE", help="save the figure of residual norms and probabilities")
    s.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    s.set_defaults(func=_scenario)

    m = car_actions.add_parser("monitor-log", help="lateral monitor on a recorded log, with injected faults")
    m.add_argument("path", help="data directory (e.g. ../shared/data/rav4-highway)")
    m.add_argument("--inject", default="none", help="fault SPEC: CHANNEL:MAGNITUDE@START or 'none'")
    m.add_argument("--json", action="store_true", help="print one JSON object")
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
