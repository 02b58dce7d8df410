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
        description=(
            "Monte Carlo evaluation of the ABS fault diagnosis of luo-et-al (Section VII).\n"
            "\n"
            "Designs the thresholds of the GLRT tests (G_P1, G_O1, G_O2, G_O_T1, G_O_T2;\n"
            "with --tests extended also the directional tests G_D_Iw, G_D_Kf, G_D_Rw)\n"
            "from nominal runs, then simulates --runs stops of every fault class (and\n"
            "twice as many nominal ones by default) and prints the thresholds, the\n"
            "false-alarm rate Pf of each test, the learned D-matrix (which test fires\n"
            "for which fault), the sensitivity and specificity of the diagnosis and the\n"
            "wall time. --json prints all of it, with the detection probabilities Pd and\n"
            "a histogram of the detection times, as one JSON object.\n"
            "\n"
            "--complete also evaluates the complete diagnoser: the decision tree with the\n"
            "SVM tests S_Kf and S_Iw, the SVM error and the errors of the fault-size\n"
            "estimates. The paper's size (--runs 5000, 55,000 stops in all) takes a few\n"
            "minutes.\n"
            "\n"
            "--workers N runs the simulations as tasks of --chunk-size runs on a local Dask\n"
            "cluster of N worker processes, --scheduler ADDRESS on a running Dask cluster.\n"
            "Every run has its own seed, so the numbers are bitwise those of a run in this\n"
            "process, for any number of workers and chunk size, even when a worker dies\n"
            "and its chunk is rerun."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=200,
                   help="simulated stops per fault class, runs (default 200; the paper uses 5000)")
    p.add_argument("--nominal-runs", type=int, default=None,
                   help="nominal (fault-free) stops for the evaluation, runs (default: 2 x --runs; the "
                   "paper uses 10000)")
    p.add_argument("--design-runs", type=int, default=None,
                   help="nominal stops for the threshold design, simulated with separate seeds, runs "
                   "(default: --nominal-runs)")
    p.add_argument("--snr", type=snr_db, default=23.0,
                   help="process-noise signal-to-noise ratio, dB (the paper uses 17, 20 and 23), or 'none' "
                   "for no process noise (default 23)")
    p.add_argument("--seed", type=int, default=0, help="master random seed (default 0)")
    p.add_argument("--window", type=int, default=None,
                   help="one GLRT window length for all tests, samples of 10 ms (Table V uses 40; default: "
                   "Table III's 50 for G_P1 and 10 for the others)")
    p.add_argument("--magnitudes", choices=["draw", "min"], default="draw",
                   help="fault sizes: 'draw' (default) draws one per run inside each class; 'min' uses each "
                   "class's smallest fault (Table V)")
    p.add_argument("--pfa", type=float, default=0.0,
                   help="target false-alarm probability per run of each test, a probability (default 0: "
                   "each threshold lies above every nominal design run, plus the margin)")
    p.add_argument("--margin", type=float, default=0.1,
                   help="threshold margin, relative to the threshold (default 0.1, i.e. 10 %%)")
    add_manoeuvre_args(p)
    p.add_argument("--gate", type=float, default=0.5,
                   help="gate time T of the tests G_O_T1 and G_O_T2, counted from the start of the record "
                   "(they fire only when the alarm is off up to T and on after it), s (default 0.5)")
    p.add_argument("--tests", choices=["paper", "extended"], default="paper",
                   help="test set: 'paper' (default), the paper's five GLRT tests; 'extended', those plus "
                   "the directional GLRTs G_D_Iw (detects the wheel-inertia fault F4), G_D_Kf and G_D_Rw "
                   "(tell F3 from F2.1)")
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="show a progress bar on standard error (default: when standard error is a terminal)")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="show no progress bar")
    p.add_argument("--complete", action="store_true",
                   help="also evaluate the complete diagnoser: the tree with the SVM tests S_Kf and S_Iw "
                   "(sensitivity, specificity), the SVM error and the errors of the fault-size estimates "
                   "(JSON key 'complete')")
    p.add_argument("--svm-per-size", type=int, default=20,
                   help="SVM training patterns per fault size with --complete (default 20, 720 patterns "
                   "in all)")
    p.add_argument("--estimate-runs", type=int, default=10,
                   help="stops per fault class diagnosed and size-estimated in full with --complete, runs "
                   "(default 10)")
    p.add_argument("--workers", type=int, default=None,
                   help="run the simulations on a local Dask cluster of this many worker processes "
                   "(default: in this process)")
    p.add_argument("--scheduler", default=None,
                   help="run the simulations on a running Dask cluster, given by its scheduler address "
                   "(e.g. tcp://127.0.0.1:8786)")
    p.add_argument("--chunk-size", type=int, default=None,
                   help="runs per task with --workers or --scheduler (default 250)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text report")
    p.add_argument("--report", metavar="FILE.html", help="write a self-contained HTML report of the campaign")
    p.set_defaults(func=_campaign)
    return p


def _campaign(args) -> int:
    import sys

    from ..systems.abs.campaign import run_campaign
    from ._output import check_output_paths, print_json

    check_output_paths(args, "report")
    if args.runs < 1:
        raise DataError(f"--runs must be >= 1, got {args.runs}")
    if args.pedal_ramp is not None and not args.pedal_ramp > 0:
        raise DataError(f"--pedal-ramp must be > 0 s, got {args.pedal_ramp}")
    if args.complete and args.pedal_ramp is not None:
        raise DataError("--complete does not support --pedal-ramp (the complete diagnoser uses the step)")
    if args.window is not None and args.window < 1:
        raise DataError(f"--window must be >= 1, got {args.window}")
    if args.workers is not None and args.workers < 1:
        raise DataError(f"--workers must be >= 1, got {args.workers}")
    if args.chunk_size is not None and args.chunk_size < 1:
        raise DataError(f"--chunk-size must be >= 1, got {args.chunk_size}")
    if args.chunk_size is not None and args.workers is None and args.scheduler is None:
        raise DataError("--chunk-size needs --workers or --scheduler")
    engine = None
    if args.workers is not None or args.scheduler is not None:
        from ..evaluate.distributed import Engine

        engine = Engine(args.workers, scheduler=args.scheduler, dask=True,
                        env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    try:
        if engine is not None:
            engine.start()
        res = run_campaign(args.runs, nominal_runs=args.nominal_runs, design_runs=args.design_runs,
                           snr_db=args.snr, seed=args.seed, W=args.window, gate=args.gate,
                           magnitudes=args.magnitudes, pfa=args.pfa, margin=args.margin,
                           noise_hold=args.noise_hold, pedal_ramp=args.pedal_ramp, tests=args.tests,
                           progress=sys.stderr.isatty() if args.progress is None else args.progress,
                           engine=engine, chunk_size=args.chunk_size or (250 if engine else None))
        out = res.to_dict()
        if engine is not None:
            out["engine"] = engine.describe()
    finally:
        if engine is not None:
            engine.close()
    if args.complete:
        from ..systems.abs.diagnoser import complete_campaign

        if args.svm_per_size < 1 or args.estimate_runs < 0:
            raise DataError(f"--svm-per-size must be >= 1 and --estimate-runs >= 0, got {args.svm_per_size}, "
                            f"{args.estimate_runs}")
        from ..report.progress import progress_steps, progress_wanted

        with progress_steps(progress_wanted(args.json), 1, "complete diagnoser") as steps:
            steps.step("SVM training, tree, diagnosis and size estimation")
            out["complete"] = complete_campaign(args.runs, nominal_runs=args.nominal_runs, bank=res.bank,
                                                snr_db=args.snr, seed=args.seed, magnitudes=args.magnitudes,
                                                svm_per_size=args.svm_per_size,
                                                estimate_runs=args.estimate_runs)
    if args.report:
        from ..report import campaign_report

        out["report"] = str(campaign_report(out, args.report, source="fdikit abs campaign"))
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
