"""``fdikit validate CONFIG LOGS...``: a saved design's false-alarm claims re-measured on new
nominal logs, claimed and measured side by side with a verdict per claim; the work is
:func:`fdikit.evaluate.validate`."""

from __future__ import annotations

import argparse
import time

from ..errors import DataError
from ._output import print_json

__all__ = ["register"]

#: Exit code when a claim is contradicted (its measured interval misses the claimed one).
CONTRADICTED = 1


def _cmd(args) -> int:
    from ..evaluate.validate import claims_table, validate

    if not 0 < args.confidence < 1:
        raise DataError(f"--confidence must lie in (0, 1), got {args.confidence}")
    t0 = time.perf_counter()
    out = validate(args.config, args.logs, level=args.confidence)
    out["wall_seconds"] = round(time.perf_counter() - t0, 3)
    out["exit_code"] = CONTRADICTED if out["contradicted"] else 0
    if args.json:
        print_json(out)
    else:
        for line in claims_table(out):
            print(line)
        if out["contradicted"]:
            print(f"contradicted: {', '.join(out['contradicted'])}")
        else:
            print("no claim is contradicted by these logs")
    return out["exit_code"]


def register(sub) -> None:
    """Add ``validate`` to the ``fdikit`` command."""
    p = sub.add_parser(
        "validate", help="re-measure a saved design's false-alarm claims on new nominal logs",
        description=(
            "Run the monitor of CONFIG (designed before with 'fdikit design CONFIG') over new\n"
            "nominal (fault-free) logs and re-measure every false-alarm rate its design states\n"
            "(design_report.json: each threshold, their family, the announcements): the\n"
            "measured rate on the judged samples with its interval (per sample: Clopper-Pearson\n"
            "on effective samples; per run: over the logs; per hour: exact Poisson on alarm\n"
            "onsets), beside the claim and its interval, and a verdict per claim: inside (the\n"
            "intervals meet), above (more false alarms than claimed) or below. The\n"
            "announcements per hour are measured even when the design states no rate for them.\n"
            "\n"
            "Exit code: 0 when no claim is contradicted, 1 when at least one is (verdict above\n"
            "or below), 2 on an error (a config or design not found, a log lacking a channel).\n"
            "--json prints exactly one JSON object."),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", help="monitor configuration file (TOML) whose design 'fdikit design' saved")
    p.add_argument("logs", nargs="+", help="nominal logs in the config's log format (CSV, CAN, MDF4, "
                   "Parquet)")
    p.add_argument("--confidence", type=float, default=0.95,
                   help="confidence level of the measured intervals (default 0.95)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.set_defaults(func=_cmd)
