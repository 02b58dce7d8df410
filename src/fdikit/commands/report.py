"""``fdikit report OUT.html``: one self-contained HTML report from saved results.

* a monitor run: ``fdikit report out.html --events ev.jsonl --stats st.parquet --log LOG --config CONFIG``
  (the files ``fdikit monitor LOG --config CONFIG --events ev.jsonl --stats st.parquet`` writes;
  any subset, the config adds units, sources, thresholds and the design hash);
* a campaign: ``fdikit report out.html --campaign campaign.json`` (e.g. the JSON of
  ``fdikit abs campaign --json``).

The page opens offline (plotly.js is embedded); see :mod:`fdikit.report`. This module also
registers ``fdikit example-log`` (:mod:`fdikit.commands.example_log`) when the command list does
not name it.
"""

from __future__ import annotations

import argparse
import time

__all__ = ["register"]


def _report(args) -> int:
    from ..report import report_from_files
    from ._output import check_output_paths, print_json

    check_output_paths(args, "out", suffixes={"out": (".html", ".htm")}, labels={"out": "OUT"},
                       inputs=("events", "stats", "log", "config", "campaign"))
    t0 = time.perf_counter()
    out = report_from_files(
        args.out,
        events=args.events,
        stats=args.stats,
        log=args.log,
        config=args.config,
        campaign=args.campaign,
        title=args.title,
    )
    from pathlib import Path

    out["bytes"] = Path(out["report"]).stat().st_size
    out["seconds"] = round(time.perf_counter() - t0, 3)
    if args.json:
        print_json(out)
    else:
        print(out["report"])
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "report",
        help="write a self-contained HTML report of a monitor run or a campaign",
        description=(
            "Write one HTML file, which opens in any browser without a network, holding\n"
            "the report of saved results:\n"
            "\n"
            "  a monitor run  --events EV.jsonl --stats ST.parquet --log LOG --config CONFIG\n"
            "                 (what 'fdikit monitor LOG --config CONFIG --events ... --stats ...'\n"
            "                 writes; any of them, at least one of events, stats, log): the\n"
            "                 metadata (config, design hash, fdikit version, log, channels),\n"
            "                 the signals with held and invalid samples shaded, the residuals\n"
            "                 with their thresholds, the test statistics, the fault\n"
            "                 probabilities and the events timeline;\n"
            "  a campaign     --campaign CAMPAIGN.json (e.g. 'fdikit abs campaign --json >\n"
            "                 CAMPAIGN.json'): Pd/Pf per test and class, the D-matrix, the\n"
            "                 confusion matrix, sensitivity and specificity, detection-time\n"
            "                 histograms, and ROC curves where a threshold was swept.\n"
            "\n"
            "Plots are interactive (zoom, pan); long logs are decimated for display keeping\n"
            "each bucket's minimum and maximum, so no spike disappears. Prints the path of\n"
            "the report, or with --json one JSON object with the path, its size and the time."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("out", help="the HTML file to write (.html)")
    p.add_argument("--events", help="announcements and held samples, JSON Lines (fdikit monitor --events)")
    p.add_argument("--stats", help="residuals and statistics, Parquet (fdikit monitor --stats)")
    p.add_argument("--log", help="the recorded log the monitor read (read as the config's [log] says)")
    p.add_argument(
        "--config", help="the monitor configuration (TOML): units, sources, thresholds, design hash"
    )
    p.add_argument("--campaign", help="a campaign result, JSON (e.g. fdikit abs campaign --json)")
    p.add_argument("--title", help="page title (default: from the config or the file name)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the path")
    p.set_defaults(func=_report)
    if "example-log" not in sub.choices:
        from . import example_log

        example_log.register(sub)
