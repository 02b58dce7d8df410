"""``fdikit demo``: a tour of what fdikit does, one short section per system, ending with one HTML
report of all sections. The sections and the report are :mod:`fdikit.demo`."""

from __future__ import annotations

from ..demo import sections
from ._output import print_json

__all__ = ["register", "run", "sections"]


def run(args) -> int:
    from ..demo import default_report_path, run_sections, write_report
    from ..report.progress import progress_steps, progress_wanted
    from ._output import check_output_paths

    available = sections()
    chosen = list(available) if not args.only else args.only
    unknown = [s for s in chosen if s not in available]
    if unknown:
        raise SystemExit(f"fdikit demo: unknown section(s) {unknown}; available: {list(available)}")
    report = args.report or default_report_path()
    args.report = report
    check_output_paths(args, "report")
    with progress_steps(progress_wanted(args.json), len(chosen) + 1, "fdikit demo") as steps:
        summary, details = run_sections({name: available[name] for name in chosen}, steps=steps,
                                        on_section=None if args.json else _print_section)
        steps.step("write the report")
        path = write_report(report, summary, details)
    if args.json:
        print_json({**summary, "report": path})
    else:
        print(f"report: {path}")
    return 0


def _print_section(name: str, out: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"fdikit demo: {name}", show_header=False, title_justify="left")
    table.add_column("what", style="bold")
    table.add_column("value")
    for k, v in out.items():
        if isinstance(v, float):
            v = f"{v:.4g}"
        elif isinstance(v, dict):
            v = ", ".join(f"{a}={b:.4g}" if isinstance(b, float) else f"{a}={b}" for a, b in v.items())
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            v = "\n".join(", ".join(f"{a}={b:.4g}" if isinstance(b, float) else f"{a}={b}"
                                    for a, b in item.items()) for item in v)
        table.add_row(k, str(v))
    Console().print(table)


def register(sub) -> None:
    p = sub.add_parser("demo", help="run a short demonstration of every system",
                       description="Simulate, detect, isolate and reconstruct faults on the "
                                   "library's example plants, and print what was found: one table per "
                                   "section, with the time each took. The sections are linear (a sensor "
                                   "bias on a linear two-mass plant), reconstruct (aircraft actuator fault "
                                   "reconstruction, ng-tan-edwards-kuang), abs, abs_diagnosis and "
                                   "abs_directional (the ABS benchmark of luo-et-al), car and car_monitor "
                                   "(the passenger car of ng-chen-speyer). --json prints one JSON object "
                                   "with one entry per section instead of the tables. It ends by writing "
                                   "one HTML report of all sections and printing its path.")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the tables")
    p.add_argument("--report", metavar="FILE.html",
                   help="where to write the HTML report of all sections (default: fdikit-demo-report.html in "
                   "the system's temporary folder); its path is printed at the end (JSON key 'report')")
    p.add_argument("--only", nargs="+", metavar="SECTION",
                   help="run only these sections, e.g. --only linear abs (default: all)")
    p.set_defaults(func=run)
