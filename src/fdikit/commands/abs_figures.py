"""``fdikit abs figure N --plot FILE``: the figures of luo-et-al, one command each; the figures are
:mod:`fdikit.systems.abs.figures`."""

from __future__ import annotations

import argparse
import time
from typing import TYPE_CHECKING

from ..errors import DataError

if TYPE_CHECKING:
    from ..systems.abs.figures import FIGURES, abs_stop_figure, abs_stop_panels

__all__ = ["FIGURES", "abs_stop_figure", "abs_stop_panels", "add_figure_parser"]

#: The figures the command offers, for its help (the same lines as the descriptions in
#: :data:`fdikit.systems.abs.figures.FIGURES`, here so that building the parser imports no system).
_FIGURE_HELP = {
    3: "an ABS stop: speeds, slip, brake torque, pressures",
    7: "GLRT of r3 (G_O1): nominal, R_w -2 %, sensor -2 %",
    8: "GLRT of r4 (G_O2): nominal, R_w -2 %, sensor -2 %",
    9: "GLRT of r3 with a tau_m fault",
    10: "histogram of the detection time of G_P1 for F1.2 and F2.2",
    15: "Pd of G_P1 over SNR and GLRT window (contour)",
    16: "Pd of S_Kf and S_Iw over SNR and fault size (contour)",
}

#: Names that moved to :mod:`fdikit.systems.abs.figures`, still importable from here (lazily).
_MOVED = ("FIGURES", "FIG15_MAGNITUDES", "FIG15_PFA", "FIG15_SNRS", "FIG15_T_DETECT", "FIG15_WINDOWS",
          "abs_stop_figure", "abs_stop_panels")


def __getattr__(name: str):
    if name in _MOVED:
        from ..systems.abs import figures

        return getattr(figures, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _cmd(args) -> int:
    from ..report.figures import save
    from ..report.progress import progress_steps, progress_wanted
    from ..systems.abs.figures import FIGURES, luo_figure
    from ._output import check_output_paths, print_json

    if args.number not in _FIGURE_HELP:
        raise DataError(f"luo-et-al figure {args.number} is not reproduced; figures: {sorted(_FIGURE_HELP)}")
    check_output_paths(args, "plot", "report")
    for k in ("runs", "design_runs", "per_size"):
        if getattr(args, k) < 1:
            raise DataError(f"--{k.replace('_', '-')} must be >= 1, got {getattr(args, k)}")
    t0 = time.perf_counter()
    with progress_steps(progress_wanted(args.json), FIGURES[args.number][1],
                        f"luo-et-al Fig. {args.number}") as steps:
        fig, data, what = luo_figure(args.number, args, steps)
    out = {
        "figure": args.number,
        "what": what,
        "snr_db": args.snr,
        "data": data,
        "plot": save(fig, args.plot),
        "wall_seconds": round(time.perf_counter() - t0, 2),
    }
    if args.json:
        print_json(out)
    else:
        print(f"luo-et-al Fig. {args.number} ({what}): {out['plot']} ({out['wall_seconds']} s)")
    return 0


def add_figure_parser(abs_actions) -> argparse.ArgumentParser:
    """Add ``figure`` to the ``fdikit abs`` actions."""
    p = abs_actions.add_parser(
        "figure",
        help="reproduce a figure of luo-et-al (3, 7, 8, 9, 10, 15, 16)",
        description="Reproduce one figure of luo-et-al and write it to an image file:\n"
        + "\n".join(f"  {k:>2}  {v}" for k, v in _FIGURE_HELP.items())
        + "\n--json prints one JSON object with the numbers behind the figure.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("number", type=int, help=f"figure number: {', '.join(map(str, _FIGURE_HELP))}")
    p.add_argument(
        "--plot",
        required=True,
        metavar="FILE",
        help="image file to write; the format follows the extension, e.g. .png or .pdf",
    )
    p.add_argument(
        "--snr", type=float, default=23.0, help="process-noise SNR, dB (default 23; Figs. 15, 16 sweep it)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--fault", default=None, help="fault class of Fig. 3 (default F0)")
    p.add_argument(
        "--runs",
        type=int,
        default=200,
        help="stops per fault class for Figs. 10 and 15 (default 200; the paper uses 5000)",
    )
    p.add_argument(
        "--design-runs", type=int, default=300, help="nominal stops for the threshold designs (default 300)"
    )
    p.add_argument(
        "--per-size",
        type=int,
        default=5,
        help="SVM patterns per fault size and fault for Fig. 16 (default 5; the paper uses 20)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object with the figure's numbers")
    p.set_defaults(func=_cmd)
    return p
