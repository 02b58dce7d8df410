"""``fdikit abs campaign``: Monte Carlo evaluation of the ABS diagnosis (luo-et-al, Section VII).

Designs the five GLRT tests (G_P1, G_O1, G_O2, G_O_T1, G_O_T2; with ``--tests extended`` also the
directional GLRT G_D_Iw) for a target false-alarm probability from nominal runs, runs ``--runs``
simulations of every fault class (twice as many nominal ones), and reports per-test Pd and Pf,
the learned D-matrix, the diagnosis sensitivity and specificity and the wall time.
``--complete`` adds the complete diagnoser (tree with the SVM tests S_Kf/S_Iw, SVM error,
severity-estimation errors; :mod:`fdikit.systems.abs.diagnoser`).
Wire it into ``fdikit abs`` with ``add_campaign_parser(abs_actions)``.
"""

from __future__ import annotations

import argparse

from ..errors import DataError
from ._abs_options import add_manoeuvre_args, snr_db

__all__ = ["add_campaign_parser"]


def add_campaign_parser(abs_subparsers) -> argparse.ArgumentParser:
    """Add the ``campaign`` action to the ``fdikit abs`` action subparsers; returns its parser.

    Examples
    --------
    >>> import argparse
    >>> sub = argparse.ArgumentParser().add_subparsers()
    >>> p = add_campaign_parser(sub)
    >>> a = p.parse_args(["--runs", "10", "--snr", "20", "--json"])
    >>> a.runs, a.snr, a.json, a.window
    (10, 20.0, True, None)
    """
    p = abs_subparsers.add_parser(
        "campaign", help="Monte Carlo Pd/Pf, D-matrix, sensitivity and specificity of the ABS tests",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=200, help="runs per fault class (default 200; paper 5000)")
    p.add_argument("--nominal-runs", type=int, default=None,
                   help="nominal evaluation runs (default 2 x --runs; paper 10000)")
    p.add_argument("--design-runs", type=int, default=None,
                   help="nominal runs for the threshold design (default: --nominal-runs), separate seeds")
    p.add_argument("--snr", type=snr_db, default=23.0,
                   help="process-noise SNR in dB (17, 20, 23; default 23)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    p.add_argument("--window", type=int, default=None,
                   help="one GLRT window for all tests (Table V uses 40; default Table III's 50/10)")
    p.add_argument("--magnitudes", choices=["draw", "min"], default="draw",
                   help="fault sizes: drawn per run inside each class, or each class's minimum (Table V)")
    p.add_argument("--pfa", type=float, default=0.0,
                   help="target per-run false-alarm probability of each test (default 0: thresholds "
                   "above every nominal design run, plus the margin)")
    p.add_argument("--margin", type=float, default=0.1, help="relative threshold margin (default 0.1)")
    add_manoeuvre_args(p)
    p.add_argument("--gate", type=float, default=0.5, help="gate time T of G_O_T1/G_O_T2, s (default 0.5)")
    p.add_argument("--tests", choices=["paper", "extended"], default="paper",
                   help="test set: the paper's five GLRT tests (default), or 'extended': those plus the "
                   "directional GLRT G_D_Iw of r3 along its I_w signature (detects the I_w fault F4)")
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="show a progress bar on stderr (default: when stderr is a terminal)")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    p.add_argument("--complete", action="store_true",
                   help="also evaluate the complete diagnoser: tree with the SVM tests S_Kf/S_Iw "
                   "(sensitivity, specificity), svm_error and the severity estimation errors (JSON key "
                   "'complete')")
    p.add_argument("--svm-per-size", type=int, default=20,
                   help="SVM training patterns per fault size with --complete (default 20: 720 patterns)")
    p.add_argument("--estimate-runs", type=int, default=10,
                   help="runs per class estimated/diagnosed in full with --complete (default 10)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_campaign)
    return p


def _campaign(args) -> int:
    import sys

    from ..systems.abs.campaign import run_campaign
    from ._output import print_json

    if args.runs < 1:
        raise DataError(f"--runs must be >= 1, got {args.runs}")
    if args.pedal_ramp is not None and not args.pedal_ramp > 0:
        raise DataError(f"--pedal-ramp must be > 0 s, got {args.pedal_ramp}")
    if args.complete and args.pedal_ramp is not None:
        raise DataError("--complete does not support --pedal-ramp (the complete diagnoser uses the step)")
    if args.window is not None and args.window < 1:
        raise DataError(f"--window must be >= 1, got {args.window}")
    res = run_campaign(args.runs, nominal_runs=args.nominal_runs, design_runs=args.design_runs,
                       snr_db=args.snr, seed=args.seed, W=args.window, gate=args.gate,
                       magnitudes=args.magnitudes, pfa=args.pfa, margin=args.margin,
                       noise_hold=args.noise_hold, pedal_ramp=args.pedal_ramp, tests=args.tests,
                       progress=sys.stderr.isatty() if args.progress is None else args.progress)
    out = res.to_dict()
    if args.complete:
        from ..systems.abs.diagnoser import complete_campaign

        if args.svm_per_size < 1 or args.estimate_runs < 0:
            raise DataError(f"--svm-per-size must be >= 1 and --estimate-runs >= 0, got {args.svm_per_size}, "
                            f"{args.estimate_runs}")
        out["complete"] = complete_campaign(args.runs, nominal_runs=args.nominal_runs, bank=res.bank,
                                            snr_db=args.snr, seed=args.seed, magnitudes=args.magnitudes,
                                            svm_per_size=args.svm_per_size, estimate_runs=args.estimate_runs)
    if args.json:
        print_json(out)
        return 0
    print(f"ABS campaign at {args.snr} dB: {out['runs']} runs, {out['wall_seconds']:.1f} s")
    print("thresholds: " + ", ".join(f"{k}={v:.4g}" for k, v in out["tests"]["thresholds"].items()))
    print("Pf: " + ", ".join(f"{k}={v:.4f}" for k, v in out["pf"].items()))
    print(res.dmatrix)
    sens, exact, spec = (100 * out[k] for k in ("sensitivity", "sensitivity_exact", "specificity"))
    print(f"sensitivity {sens:.2f} % (exact class {exact:.2f} %), specificity {spec:.2f} %")
    if args.complete:
        c = out["complete"]
        print(c["tree"]["listing"])
        print(f"complete tree: sensitivity {100 * c['sensitivity']:.2f} % (exact leaf "
              f"{100 * c['sensitivity_exact']:.2f} %), specificity {100 * c['specificity']:.2f} %, "
              f"SVM error {100 * c['svm_error']:.2f} %, full diagnoser exact "
              f"{100 * c['diagnoser']['sensitivity_exact']:.2f} %")
        for k, v in c["estimation"].items():
            print(f"  {k}: {v['param']} mean relative error {v['mean_relative_error_pct']:.3f} % "
                  f"({v['runs']} runs)")
    return 0
