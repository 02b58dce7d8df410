"""``fdikit abs``: the antilock braking benchmark of luo-et-al (Luo et al.).

Actions (sub-subcommands):

* ``fdikit abs simulate --fault F3 --magnitude -0.05 [--runs N] [--json] [--plot FILE]``:
  simulate braking stops with one fault class and print a summary (stopping time and
  distance, when the ABS engaged, mean slip while it is active, number of samples);
  ``--plot`` writes a figure like the paper's Fig. 3 for the first run;
* ``fdikit abs figure N --plot FILE``: the paper's Figs. 3, 7-10, 15 and 16
  (:mod:`fdikit.commands.abs_figures`).

Later actions (``campaign``, ...) register themselves on the same ``abs`` parser.
"""

from __future__ import annotations

import argparse

from ..errors import DataError
from ._abs_options import add_manoeuvre_args, snr_db


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``abs`` command and its actions; returns the ``abs`` parser's action subparsers.

    Nothing heavy is imported here (every ``fdikit`` call registers every command): the fault
    class is checked (by :class:`fdikit.systems.abs.plant.Scenario`) when the action runs.
    """
    p = subparsers.add_parser(
        "abs", help="antilock braking system benchmark (luo-et-al)",
        description=(
            "The antilock braking system (ABS) benchmark of luo-et-al: a quarter-car\n"
            "braking stop with a hydraulic brake and a slip controller, the fault classes\n"
            "F0 (nominal) to F5 of Table II, and the GLRT tests that detect and isolate\n"
            "them.\n"
            "\n"
            "Choose an ACTION; 'fdikit abs ACTION --help' lists its options. Every action\n"
            "prints a text summary, or one JSON object with --json."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = p.add_subparsers(dest="abs_action", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 0)[1])
    p.abs_actions = actions  # later issues: register more actions here

    s = actions.add_parser(
        "simulate", help="simulate ABS stops with a fault and print a summary",
        description="Simulate braking stops of the luo-et-al ABS benchmark with one fault class and print "
                    "a summary, averaged over the runs: the fault and its mean magnitude, the number of "
                    "runs and samples, the stopping time and distance, when the ABS engaged, the mean "
                    "wheel slip while it was active, the number of valve switches and the fraction of "
                    "runs that came to rest. --json prints the summary as one JSON object; --plot also "
                    "writes a figure of the first run (speeds, slip, brake torque and pressures, like "
                    "Fig. 3 of the paper).")
    s.add_argument("--fault", default="F0",
                   help="fault class (Table II): F0 nominal (default); F1.1, F1.2 wheel-speed sensor reading "
                   "low; F2.1, F2.2 wheel radius smaller; F3 brake torque gain; F4 wheel inertia; F5 "
                   "master-cylinder time constant")
    s.add_argument("--magnitude", type=float, default=None,
                   help="relative change of the faulty parameter, a fraction: e.g. -0.05 for -5 %% "
                   "(default: drawn per run inside the class)")
    s.add_argument("--runs", type=int, default=1,
                   help="number of Monte Carlo runs, each one simulated stop (default 1)")
    s.add_argument("--seed", type=int, default=0, help="master random seed (default 0)")
    s.add_argument("--snr", type=snr_db, default=23.0,
                   help="process-noise signal-to-noise ratio, dB (the paper uses 23, 20 and 17), or 'none' "
                   "for no process noise (default 23)")
    s.add_argument("--meas-var", type=float, default=0.004,
                   help="variance of the wheel- and vehicle-speed measurement noise, (rad/s)^2 "
                   "(default 0.004)")
    add_manoeuvre_args(s)
    s.add_argument("--v0", type=float, default=28.0, help="initial vehicle speed, m/s (default 28)")
    s.add_argument("--t-brake", type=float, default=0.5,
                   help="time at which the brake is applied, s (default 0.5)")
    s.add_argument("--t-end", type=float, default=12.5,
                   help="length of the simulated record, s (default 12.5)")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    s.add_argument("--plot", metavar="FILE", default=None,
                   help="write a figure of the first run (like Fig. 3) to this image file; the format "
                   "follows the extension, e.g. .png or .pdf")
    s.set_defaults(func=_simulate)
    from .abs_campaign import add_campaign_parser
    from .abs_detectability import add_detectability_parser
    from .abs_figures import add_figure_parser

    add_campaign_parser(actions)
    add_detectability_parser(actions)
    add_figure_parser(actions)
    return actions


def _simulate(args) -> int:
    from ..systems.abs.plant import Scenario, simulate, summarize  # Scenario refuses an unknown fault class
    from ._output import print_json

    if args.runs < 1:
        raise DataError(f"--runs must be >= 1, got {args.runs}")
    from ._output import check_output_paths

    check_output_paths(args, "plot")
    sc = Scenario(fault=args.fault, magnitude=args.magnitude, snr_db=args.snr, meas_var=args.meas_var,
                  v0=args.v0, t_brake=args.t_brake, t_end=args.t_end, noise_hold=args.noise_hold,
                  pedal="step" if args.pedal_ramp is None else "ramp", pedal_ramp=args.pedal_ramp)
    res = simulate(None, sc, runs=args.runs, seed=args.seed, keep_states=bool(args.plot))
    out = summarize(res)
    if args.plot:
        _plot(res, args.plot)
        out["plot"] = args.plot
    if args.json:
        print_json(out)
    else:
        for k, v in out.items():
            print(f"{k:>20}: {v:.4g}" if isinstance(v, float) else f"{k:>20}: {v}")
    return 0


def _plot(res, path: str) -> None:
    """luo-et-al Fig. 3 for the first run (units on every axis, brake / ABS / stop marked)."""
    from .abs_figures import abs_stop_figure

    abs_stop_figure(res, path)
