"""``fdikit car``: the passenger car of ng-chen-speyer (Ng, Chen & Speyer).

Actions (sub-subcommands):

* ``fdikit car linearize [--speed 20] [--method modal|residualize|balanced] [--json]``: linearise the
  nonlinear sedan about straight driving, report state/input/output names, eigenvalues of the
  full and reduced longitudinal and lateral models, the decoupling residue and the
  frequency-response error of the reduced models below 5 Hz;
* ``fdikit car fit [PATH] [--json]``: fit the lateral (single-track + roll) model to the real
  RAV4 minute in PATH (default ``../shared/data/rav4-highway``) and report the fitted
  parameters and the correlation and NRMSE of yaw rate and lateral acceleration.

Later actions (``scenario``, ...) register themselves on the same ``car`` parser.
"""

from __future__ import annotations

import argparse

import numpy as np


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``car`` command and its actions; returns the action subparsers."""
    p = subparsers.add_parser("car", help="passenger-car plant (ng-chen-speyer): linearisation, "
                              "real-data fit, scenarios, RAV4 monitor",
                              description=(
                                  "The passenger car of ng-chen-speyer: a nonlinear sedan model, its\n"
                                  "linearisation and reduction, a fit of its lateral model to a real\n"
                                  "Toyota RAV4 CAN log, the health-monitor experiments of the paper, and\n"
                                  "a lateral monitor run on the recorded RAV4 data.\n"
                                  "\n"
                                  "Choose an ACTION; 'fdikit car ACTION --help' lists its options. Every\n"
                                  "action prints a text summary, or one JSON object with --json."),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = p.add_subparsers(dest="car_action", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 0)[1])
    p.car_actions = actions  # later issues: register more actions here

    s = actions.add_parser(
        "linearize", help="linearise at straight driving, reduce, report",
        description="Linearise the nonlinear passenger car of ng-chen-speyer about straight driving on a "
                    "flat road at the given speed, split it into longitudinal and lateral models and "
                    "reduce both. Prints the trim (throttle, engine speed), the size of the "
                    "longitudinal/lateral cross terms, the states, inputs and outputs of each model, the "
                    "eigenvalues of the reduced models and the frequency-response error of the reduced "
                    "models up to --f-max. --json prints one JSON object with the names and the "
                    "eigenvalues of the full and the reduced models.")
    s.add_argument("--speed", type=float, default=20.0,
                   help="operating speed, m/s (default 20; the paper uses 20 and 24)")
    s.add_argument("--method", choices=["modal", "residualize", "balanced"], default="modal",
                   help="model reduction: 'modal' (default) truncates the fast modes with steady-state "
                   "correction and keeps named physical states; 'residualize' residualises the fast states "
                   "(wheel spin, wheel hop); 'balanced' is balanced residualisation. All three keep the DC "
                   "gain exactly")
    s.add_argument("--f-max", type=float, default=5.0,
                   help="upper frequency of the reported frequency-response error, Hz (default 5)")
    s.add_argument("--parity", action="store_true",
                   help="add the throttle and brake measurements (and their sensor faults) to the "
                   "longitudinal outputs, for the parity equations")
    s.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    s.set_defaults(func=_linearize)

    f = actions.add_parser(
        "fit", help="fit the lateral model to a real RAV4 CAN log",
        description="Fit the lateral model of the passenger car (single track plus roll) to one minute "
                    "of real highway driving of a Toyota RAV4, read from its CAN log. Prints the fitted "
                    "parameters, the correlation and normalised RMS error of the modelled yaw rate and "
                    "lateral acceleration against the measured ones, a hold-out check (fit on the first "
                    "40 s, test on the last 20 s), comparisons with a kinematic bicycle model and a free "
                    "FIR filter, and the understeer gradient. --json prints one JSON object.")
    f.add_argument("path", nargs="?", default=None,
                   help="data directory holding the CAN log drive.blf and the signal database "
                   "toyota_rav4.dbc (default: $FDIKIT_RAV4 if set, else ../shared/data/rav4-highway)")
    f.add_argument("--rate", type=float, default=50.0,
                   help="rate of the time grid the signals are resampled to, Hz (default 50)")
    f.add_argument("--ay-weight", type=float, default=0.5,
                   help="weight of the lateral-acceleration error relative to the yaw-rate error in the "
                   "fit, unitless (default 0.5)")
    f.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    f.set_defaults(func=_fit)
    from .car_monitor import add_monitor_parsers

    add_monitor_parsers(actions)
    return actions


def _linearize(args) -> int:
    from ..systems.car import linearize_car
    from ._output import print_json

    lin = linearize_car(args.speed, method=args.method, f_max=args.f_max, parity_outputs=args.parity)
    out = lin.summary()
    if args.json:
        print_json(out)
        return 0
    print(f"passenger car linearised at {args.speed:g} m/s (straight, flat road); reduction: {args.method}")
    print(f"  trim: throttle {out['throttle_trim_deg']:.2f} deg, "
          f"engine {out['engine_speed_trim_rpm']:.0f} rpm")
    print(f"  longitudinal/lateral cross terms (relative): {out['decoupling_residue']['max']:.3g}")
    for key in ("longitudinal", "lateral"):
        b = out[key]
        print(f"  {key}: {len(b['states'])} -> {len(b['reduced_states'])} states, inputs {b['inputs']}, "
              f"outputs {b['outputs']}")
        ev = np.array([complex(*e) for e in b["eigenvalues_reduced"]])
        print("    reduced eigenvalues: " + ", ".join(f"{e.real:.3g}{e.imag:+.3g}j" for e in ev))
        f5 = b["fr_error_first_5pct_hz"]
        print(f"    frequency-response error up to {args.f_max:g} Hz: {100 * b['fr_error_max']:.2f} % "
              f"(DC abs {b['fr_error_dc_abs']:.2g}; first exceeds 5 % at "
              f"{'-' if f5 is None else f'{f5:.2f} Hz'})")
    return 0


def _fit(args) -> int:
    from ..systems.car.rav4 import fit_rav4
    from ._output import print_json

    fit = fit_rav4(args.path, rate=args.rate, ay_weight=args.ay_weight)
    out = fit.summary()
    if args.json:
        print_json(out)
        return 0
    print("RAV4 lateral model fit (single track + roll)")
    for k, v in out["fitted_parameters"].items():
        print(f"  {k:8s} = {v:.6g}")
    y, a = out["yaw_rate"], out["lateral_acceleration"]
    print(f"  yaw rate: correlation {y['correlation']:.3f} (target {y['target_correlation']}, kinematic "
          f"bicycle {y['kinematic_bicycle_correlation']:.3f}), NRMSE {y['nrmse']:.3f}")
    print(f"  lateral acceleration: correlation {a['correlation']:.3f}, NRMSE {a['nrmse']:.3f} "
          f"(ACCEL_Y is {a['sign_of_ACCEL_Y']})")
    h = out["holdout_last_third"]
    print(f"  hold-out (fit on 0-40 s, test 40-60 s): yaw corr {h['yaw_corr']:.3f} (kinematic "
          f"{h['kinematic_yaw_corr']:.3f})")
    r = out["reference"]
    print(f"  reference: free {r['fir_taps']}-tap FIR in-sample {r['fir_in_sample_corr']:.3f}, hold-out "
          f"{r['fir_holdout_corr']:.3f}; model vs yaw low-passed at 2 Hz "
          f"{r['model_corr_vs_yaw_lowpass_2hz']:.3f}")
    print(f"  understeer gradient {out['understeer_gradient_deg_per_g']:.2f} deg/g")
    return 0
