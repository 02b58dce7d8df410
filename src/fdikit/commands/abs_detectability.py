"""``fdikit abs detectability``: the best any detector can do for one ABS fault (Neyman-Pearson bound).

For a fault of known class and size, compares the noise-free measurements of the faulty and the
nominal stop over a window before the ABS engages, estimates the noise covariance of the same
quantities from nominal Monte Carlo runs, and prints ``d'`` and the detection probability of the
likelihood-ratio test for that known change at a false-alarm probability ``--pfa``: an upper
bound for every residual generator and test (:mod:`fdikit.systems.abs.detectability`). When the
faulty parameter no longer acts after the window (tau_m once the master-cylinder pressure has
settled), the bound covers the whole record.
"""

from __future__ import annotations

import argparse

from ..errors import DataError
from ._abs_options import snr_db

__all__ = ["add_detectability_parser"]


def add_detectability_parser(abs_subparsers) -> argparse.ArgumentParser:
    """Add the ``detectability`` action to the ``fdikit abs`` action subparsers.

    Examples
    --------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> a = add_detectability_parser(sub).parse_args(["--fault", "F5", "--magnitude", "0.15", "--json"])
    >>> a.fault, a.magnitude, a.window
    ('F5', 0.15, [0.5, 2.6])
    """
    p = abs_subparsers.add_parser(
        "detectability", help="Neyman-Pearson bound on detecting one ABS fault (known-signal d')",
        description=(
            "The best any detector can do for one ABS fault of known class and size\n"
            "(luo-et-al benchmark): an upper bound on the detection probability of every\n"
            "residual generator and test.\n"
            "\n"
            "Compares the noise-free measurements of the faulty and the nominal stop over\n"
            "a time window before the ABS engages, estimates the noise covariance of the\n"
            "same quantities from nominal Monte Carlo runs, and prints the detectability\n"
            "d' and the detection probability of the likelihood-ratio test for that known\n"
            "change at the false-alarm probability --pfa. When the faulty parameter no\n"
            "longer acts after the window (e.g. the master-cylinder time constant, F5,\n"
            "once the pressure has settled), it also prints the bound for the whole\n"
            "record. --json prints the results as one JSON object."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--fault", required=True,
                   help="fault class (Table II): F1.1, F1.2 wheel-speed sensor reading low; F2.1, F2.2 wheel "
                   "radius smaller; F3 brake torque gain; F4 wheel inertia; F5 master-cylinder time "
                   "constant")
    p.add_argument("--magnitude", type=float, required=True,
                   help="relative change of the faulty parameter, a fraction inside the class (e.g. 0.15 "
                   "for +15 %%)")
    p.add_argument("--snr", type=snr_db, default=23.0,
                   help="process-noise signal-to-noise ratio, dB, or 'none' for measurement noise only "
                   "(default 23)")
    p.add_argument("--window", type=float, nargs=2, default=[0.5, 2.6], metavar=("START", "END"),
                   help="start and end of the window, s from the start of the record (default 0.5 2.6: "
                   "braking before the ABS engages)")
    p.add_argument("--block", type=int, default=5,
                   help="consecutive measurement samples averaged into one quantity, samples (default 5)")
    p.add_argument("--runs", type=int, default=4000,
                   help="nominal Monte Carlo stops for the noise covariance, runs (default 4000; at least 2, "
                   "and more than the number of quantities)")
    p.add_argument("--pfa", type=float, default=1e-4,
                   help="false-alarm probability at which the bound is given (default 1e-4)")
    p.add_argument("--seed", type=int, default=0, help="master random seed (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    p.set_defaults(func=_detectability)
    return p


def _detectability(args) -> int:
    from ..systems.abs.detectability import abs_detectability
    from ._output import print_json

    if args.runs < 2:
        raise DataError(f"--runs must be >= 2, got {args.runs}")
    out = abs_detectability(args.fault, args.magnitude, snr_db=args.snr, window=tuple(args.window),
                            block=args.block, runs=args.runs, seed=args.seed, pfa=args.pfa)
    if args.json:
        print_json(out)
        return 0
    w = out["window"]
    print(f"{args.fault} {args.magnitude:+g} at {args.snr} dB, window {w[0]}-{w[1]} s, "
          f"{out['quantities']} quantities, {out['runs']} nominal runs")
    print(f"d' = {out['d_prime']:.2f} (measurement noise only: {out['d_prime_measurement_only']:.2f}); "
          f"Pd <= {out['pd_bound']:.4f} at Pfa {args.pfa:g} for any detector using this window")
    if out["d_prime_whole_record_bound"] is not None:
        print(f"the parameter no longer acts after the window: whole-record bound d' = "
              f"{out['d_prime_whole_record_bound']:.2f}, Pd <= {out['pd_bound_whole_record']:.4f}")
    else:
        print("the parameter still acts after the window: the bound covers the window only")
    return 0
