"""``fdikit reconstruct aircraft``: robust actuator fault reconstruction of the aircraft
(ng-tan-edwards-kuang, Section IV); the experiment is :mod:`fdikit.systems.aircraft.reconstruction`,
its figure and report :mod:`fdikit.systems.aircraft.figures`."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _check_outputs(args) -> None:
    """The output paths and the numeric options, checked before any computation."""
    import math

    from ..errors import DataError
    from ._output import check_output_paths

    check_output_paths(args, "plot", "report")
    for flag, v in (("--h", args.h), ("--t-final", args.t_final)):
        if not (math.isfinite(v) and v > 0):
            raise DataError(f"{flag} must be a positive, finite number of seconds, got {v}")
    if not (math.isfinite(args.settle) and args.settle >= 0):
        raise DataError(f"--settle must be >= 0 s, got {args.settle}")
    if args.h >= args.t_final:
        raise DataError(f"--h = {args.h} s must be smaller than --t-final = {args.t_final} s")
    if args.settle >= args.t_final:
        raise DataError(f"--settle = {args.settle} s must be smaller than --t-final = {args.t_final} s "
                        "(the RMS error is scored after it)")


def _cmd(args: argparse.Namespace) -> int:
    from ..report.progress import progress_steps, progress_wanted
    from ..systems.aircraft.figures import reconstruction_figure, reconstruction_report
    from ..systems.aircraft.reconstruction import run_aircraft
    from ._output import print_json

    _check_outputs(args)
    keep = bool(args.plot or args.report)
    with progress_steps(progress_wanted(args.json), 1 + keep, "reconstruct aircraft") as steps:
        steps.step(f"design the observers (LMIs), simulate {args.t_final:g} s at h = {args.h:g} s twice")
        res = run_aircraft(
            t_final=args.t_final, h=args.h, settle=args.settle, keep_signals=keep, reading=args.reading
        )
        if keep:
            steps.step("figure and report")
            if args.plot:
                res["plot"] = reconstruction_figure(res, args.plot)
            if args.report:
                res["report"] = reconstruction_report(res, args.report)
            for k in ("t", "f", "fhat", "fhat_nominal"):
                res.pop(k)
    if args.json:
        print_json(res)
    else:
        c = res["conditions"]
        print(
            f"aircraft: case {res['case']}, A1 {c['A1']}, A2 {c['A2']}, B1 {c['B1']}, B2 {c['B2']}, "
            f"rank CM = {res['rank_CM']}, pbar = {res['pbar']}"
        )
        hc = res["hinf_check"] or {}
        print(
            f"L2 bound gamma-bar = {res['l2_bound']:.4f} (paper 1.3131); "
            f"H-inf of G(s) = {hc.get('hinf_bisection', float('nan')):.4f}"
        )
        print(
            f"RMS(f^ - f)/RMS(f) over t >= {res['settle_s']} s: {res['rmse_ratio']:.4f} with "
            f"uncertainty, {res['rmse_ratio_nominal']:.2e} nominal"
        )
        print(
            f"design {res['design_seconds']:.2f} s, simulation (2 runs) {res['sim_seconds_two_runs']:.2f} s"
        )
        for k in ("plot", "report"):
            if k in res:
                print(f"{k}: {res[k]}")
    return 0


def register(subparsers) -> None:
    """Add ``reconstruct`` to the ``fdikit`` command."""
    p = subparsers.add_parser(
        "reconstruct",
        help="robust actuator fault reconstruction with cascaded sliding mode observers",
        description=(
            "Reconstruct an actuator fault with cascaded sliding mode observers, robustly\n"
            "against model uncertainty (ng-tan-edwards-kuang, Section IV).\n"
            "\n"
            "The one system is 'aircraft': the 7-state lateral aircraft model with a fault\n"
            "on the rudder actuator. The command designs the observers, simulates the\n"
            "aircraft with and without the model uncertainty, and prints the design\n"
            "conditions, the L2 bound on the reconstruction error (with an independent\n"
            "H-infinity norm check), the relative RMS error of the reconstructed fault\n"
            "after the settling time, and the design and simulation times.\n"
            "\n"
            "--json prints one JSON object instead; --plot also writes the fault and its\n"
            "reconstruction (Fig. 1 of the paper) to an image file, --report an HTML report."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "system",
        choices=["aircraft"],
        help="benchmark system: aircraft (lateral aircraft model of ng-tan-edwards-kuang)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text summary")
    p.add_argument(
        "--plot",
        metavar="FILE",
        help="write a figure of the fault and its reconstruction (Fig. 1) to this image file; "
        "the format follows the extension, e.g. .png or .pdf",
    )
    p.add_argument(
        "--report",
        metavar="FILE.html",
        help="write a self-contained HTML report: the design record, the fault, its reconstruction and "
        "the reconstruction error (interactive plots)",
    )
    p.add_argument("--t-final", type=float, default=15.0, help="simulated time, s (default 15)")
    p.add_argument(
        "--h",
        type=float,
        default=1e-5,
        help="fixed integration step, which is also the sample time, s (default 1e-5)",
    )
    p.add_argument(
        "--settle",
        type=float,
        default=1.0,
        help="settling time: the RMS error is scored from this time on, s (default 1)",
    )
    p.add_argument(
        "--reading",
        choices=["consistent", "printed_xi", "literal"],
        default="consistent",
        help="how to read the paper's uncertainty, whose printed A + dA and factor Xi disagree: "
        "consistent (default: A + dA as printed, with the dropped entry A[3,2] read as nominal), "
        "printed_xi (the printed factor Xi) or literal (A + dA exactly as printed)",
    )
    p.set_defaults(func=_cmd)
