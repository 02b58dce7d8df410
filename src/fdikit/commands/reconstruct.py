"""``fdikit reconstruct aircraft``: robust actuator fault reconstruction of the aircraft
(ng-tan-edwards-kuang, Section IV); the experiment is :mod:`fdikit.systems.aircraft.reconstruction`."""

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


def _figure(res: dict, path: str) -> str:
    """Ng, Tan, Edwards & Kuang, Fig. 1: the fault (left) and its reconstruction (right), with
    units, the fault's onset marked and the reconstruction error below."""
    import numpy as np

    from ..report.figures import panel_figure, save

    t, f, fh, fn = res["t"], res["f"], res["fhat"], res["fhat_nominal"]
    onset = float(t[np.flatnonzero(f != 0)[0]]) if np.any(f != 0) else None
    pad = 0.5 * max(float(np.ptp(f)), 1e-3)
    lim = (float(f.min()) - pad, float(f.max()) + pad)  # clips the observers' initial transient
    left = [
        {
            "title": "fault f (rudder actuator)",
            "ylabel": "f",
            "unit": "rad",
            "ylim": lim,
            "traces": [("f", f, {"color": "k"})],
            "legend": False,
        }
    ]
    right = [
        {
            "title": f"reconstruction f^ (RMS error ratio {res['rmse_ratio']:.3f} with uncertainty)",
            "ylabel": "f^",
            "unit": "rad",
            "ylim": lim,
            "traces": [
                ("with uncertainty", fh, {"color": "tab:blue"}),
                ("nominal plant", fn, {"color": "tab:red", "ls": "--", "lw": 0.8}),
            ],
        },
        {
            "title": f"reconstruction error (scored from t = {res['settle_s']:g} s)",
            "ylabel": "f^ - f",
            "unit": "rad",
            "ylim": (-0.25 * pad, 0.25 * pad),
            "traces": [
                ("with uncertainty", fh - f, {"color": "tab:blue"}),
                ("nominal plant", fn - f, {"color": "tab:red", "lw": 0.8}),
            ],
        },
    ]
    events = [(onset, "fault starts")] if onset is not None else []
    fig = panel_figure(
        t,
        [left, right],
        title="actuator fault reconstruction, cascaded sliding mode observers (ng-tan-edwards-kuang, Fig. 1)",
        events=events,
        panel_size=(5.2, 2.3),
    )
    return save(fig, path, dpi=120)


def _report(res: dict, path: str) -> str:
    import numpy as np

    from ..report import Report, add_events, stacked_time_figure

    rep = Report("fdikit reconstruct aircraft: actuator fault reconstruction (ng-tan-edwards-kuang)")
    rep.section(
        "Run",
        "Cascaded sliding mode observers designed by LMIs; the aircraft simulated with and without "
        "the model uncertainty.",
    )
    from .. import __version__

    c = res["conditions"]
    info = {
        "fdikit version": __version__,
        "case": res["case"],
        "conditions A1, A2, B1, B2": c,
        "rank CM": res["rank_CM"],
        "pbar": res["pbar"],
        "L2 bound gamma-bar": res["l2_bound"],
        "paper's L2 bound": res["l2_bound_paper"],
        "H-inf of G(s)": (res["hinf_check"] or {}).get("hinf_bisection"),
        "RMS(f^ - f) / RMS(f), with uncertainty": res["rmse_ratio"],
        "RMS(f^ - f) / RMS(f), nominal": res["rmse_ratio_nominal"],
        "scored from (s)": res["settle_s"],
        "step h (s)": res["h"],
        "simulated (s)": res["t_final"],
        "uncertainty reading": res["uncertainty_reading"],
        "design (s)": res["design_seconds"],
        "simulation, two runs (s)": res["sim_seconds_two_runs"],
    }
    rep.table(info)
    rep.data["metadata"] = {k: v for k, v in info.items() if isinstance(v, int | float | str)}
    t, f = res["t"], res["f"]
    onset = float(t[np.flatnonzero(f != 0)[0]]) if np.any(f != 0) else None
    add_events(rep, [], (float(t[0]), float(t[-1])), title="Events")
    rep.text(
        "No announcements: a reconstructor estimates the fault signal; the dotted line marks the "
        "fault's onset."
    )
    pad = 0.5 * max(float(np.ptp(f)), 1e-3)
    marks = [(onset, "fault starts")] if onset is not None else []
    rep.section(
        "Fault and reconstruction",
        "The rudder actuator fault f and its reconstruction f^ (with the "
        "uncertain plant and the nominal one), and the reconstruction errors (decimated for display, "
        "keeping each bucket's minimum and maximum).",
    )
    panels = [
        {
            "title": "fault and reconstruction",
            "ylabel": "rudder fault",
            "unit": "rad",
            "range": [float(f.min()) - pad, float(f.max()) + pad],
            "traces": [
                ("f", f),
                ("f^ (with uncertainty)", res["fhat"]),
                ("f^ (nominal)", res["fhat_nominal"]),
            ],
        },
        {
            "title": "reconstruction error",
            "ylabel": "f^ - f",
            "unit": "rad",
            "range": [-0.25 * pad, 0.25 * pad],
            "traces": [("with uncertainty", res["fhat"] - f), ("nominal", res["fhat_nominal"] - f)],
        },
    ]
    rep.figure(
        stacked_time_figure(
            t, panels, title="fault reconstruction", events=marks, max_points=rep.max_points, panel_height=260
        )
    )
    return str(rep.write(path))


def _cmd(args: argparse.Namespace) -> int:
    from ..report.progress import progress_steps, progress_wanted
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
                res["plot"] = _figure(res, args.plot)
            if args.report:
                res["report"] = _report(res, args.report)
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
