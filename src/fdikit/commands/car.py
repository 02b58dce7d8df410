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
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    actions = p.add_subparsers(dest="car_action", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 0)[1])
    p.car_actions = actions  # later issues: register more actions here

    s = actions.add_parser("linearize", help="linearise at straight driving, reduce, report")
    s.add_argument("--speed", type=float, default=20.0, help="operating speed, m/s (default 20)")
    s.add_argument("--method", choices=["modal", "residualize", "balanced"], default="modal",
                   help="reduction: fast modes truncated with steady-state correction, in the named "
                   "states (default); residualisation of the named fast states; or balanced "
                   "residualisation")
    s.add_argument("--f-max", type=float, default=5.0, help="upper frequency of the error report, Hz")
    s.add_argument("--parity", action="store_true",
                   help="add the throttle and brake measurements to the longitudinal outputs")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=_linearize)

    f = actions.add_parser("fit", help="fit the lateral model to a real RAV4 CAN log")
    f.add_argument("path", nargs="?", default=None,
                   help="directory with drive.blf and toyota_rav4.dbc (default ../shared/data/rav4-highway)")
    f.add_argument("--rate", type=float, default=50.0, help="grid rate of the fit, Hz (default 50)")
    f.add_argument("--ay-weight", type=float, default=0.5,
                   help="weight of the lateral-acceleration residual (default 0.5)")
    f.add_argument("--json", action="store_true", help="print one JSON object")
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
