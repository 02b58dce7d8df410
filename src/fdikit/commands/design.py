"""``fdikit design CONFIG``: the design artifacts of a monitor config (its recipe, or a declarative
``[design]``), and what its false-alarm rates rest on: a declarative design set on simulated noise
says on standard error that its rates are model-based."""

from __future__ import annotations

import json
import sys
import time

from ..base.outputs import io_error
from ._output import print_json

__all__ = ["register"]

#: What ``fdikit design`` prints (standard error) for rates set on simulated noise only.
MODEL_BASED = ("fdikit design: the false-alarm rates are model-based: the thresholds are set on simulated "
               "noise of the {what} model, and hold only if the plant and its noise are as modelled. {how}"
               "Check a saved design with 'fdikit validate CONFIG LOGS...'")


def _design(args) -> int:
    from ..monitor.config import load_config, run_design
    from ..report.progress import progress_steps, progress_wanted

    t0 = time.perf_counter()
    cfg = load_config(args.config)
    with progress_steps(progress_wanted(args.json), 1, "fdikit design") as steps:
        steps.step(f"recipe {cfg.design.get('recipe') or 'declarative [design]'}")
        try:
            paths = run_design(cfg)
        except OSError as exc:  # a full disk: one message naming the artifacts' folder
            raise io_error(exc.filename or cfg.artifacts, exc) from None
    out = {"config": str(cfg.path), "artifacts": {k: str(v) for k, v in paths.items()},
           "wall_seconds": round(time.perf_counter() - t0, 3)}
    if "design_report" in paths:
        rates = json.loads(paths["design_report"].read_text()).get("rates")
        if rates:
            out["rates"] = rates
        if rates == "model-based":
            declarative = not cfg.design.get("recipe")
            how = ("Give [design].nominal_log = [...] (real nominal logs) to set and check them on data. "
                   if declarative else "")
            what = "declared" if declarative else "recipe's"
            print(MODEL_BASED.format(what=what, how=how), file=sys.stderr)
    if args.json:
        print_json(out)
    else:
        for k, v in paths.items():
            print(f"{k}: {v}")
    return 0


def register(sub) -> None:
    """Add ``design`` to the ``fdikit`` command."""
    p = sub.add_parser("design", help="make the design artifacts of a monitor config",
                       description="Run the design recipe of a monitor configuration (a TOML file) and "
                                   "save every design it returns as a versioned artifact (a JSON file and "
                                   "an NPZ file) in the configuration's artifact directory, ready for "
                                   "'fdikit monitor'. Prints the path of each artifact; --json prints one "
                                   "JSON object with the paths and the wall time. A declarative design "
                                   "whose thresholds rest on simulated noise says so (its rates are "
                                   "model-based); with [design].nominal_log they are set on those real "
                                   "nominal logs and checked on held-out parts of them. 'fdikit validate' "
                                   "re-measures a saved design on new nominal logs.")
    p.add_argument("config", help="monitor configuration file (TOML) with a [design] recipe")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the paths")
    p.set_defaults(func=_design)
