"""``fdikit example-log CONFIG --out DIR``: simulated logs (nominal and faulty) to run an example
monitor on; the simulation and the writing are :mod:`fdikit.demo.example_logs`."""

from __future__ import annotations

import argparse
import time

from ..demo.example_logs import SYSTEMS, write_example_logs

__all__ = ["SYSTEMS", "register", "write_example_logs"]


def _cmd(args) -> int:
    from ._output import check_output_paths, print_json

    check_output_paths(args, folders=("out",))
    t0 = time.perf_counter()
    out = write_example_logs(args.config, args.out, fault=args.fault, seed=args.seed, duration=args.duration)
    out["wall_seconds"] = round(time.perf_counter() - t0, 3)
    if args.json:
        print_json(out)
    else:
        for k, p in out["logs"].items():
            print(f"{k}: {p}")
        if out["fault"]:
            print("fault: " + ", ".join(f"{k}={v}" for k, v in out["fault"].items()))
        print("then:\n  " + "\n  ".join(out["commands"]))
    return 0


def register(sub) -> None:
    """Add ``example-log`` to the ``fdikit`` command (once, whoever calls first)."""
    if "example-log" in sub.choices:
        return
    p = sub.add_parser(
        "example-log",
        help="write example logs (nominal and faulty) for an example monitor config",
        description=(
            "Simulate the system that an example monitor config (examples/*/monitor.toml)\n"
            "watches, and write two logs in the config's log format (CSV with its time\n"
            "column and source channels, in the source units): DIR/nominal.csv (no fault)\n"
            "and DIR/fault.csv (with --fault). Then\n"
            "    fdikit design CONFIG\n"
            "    fdikit monitor DIR/fault.csv --config CONFIG --json\n"
            "runs the monitor on it. Faults: two-mass and passenger car TARGET:MAGNITUDE[@START]\n"
            "(a bias, e.g. sensor:pos2:0.012@4 or sensor:a_x:0.6@8); ABS a fault class of\n"
            "Table II with an optional magnitude (F2.2:-0.25); aircraft 'rudder'. The RAV4\n"
            "config reads the real CAN log and has nothing to simulate. Prints the paths, or\n"
            "with --json one JSON object with the paths, the fault and the next commands."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "config", help="an example monitor configuration (TOML), e.g. examples/two-mass/monitor.toml"
    )
    p.add_argument("--out", required=True, help="folder to write nominal.csv and fault.csv into (created)")
    p.add_argument("--fault", help="the fault of fault.csv (default: one per system, see above)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulated noise (default 0)")
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="simulated time, s (default: 10 s; ABS 12.5 s; passenger car 14 s)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the paths")
    p.set_defaults(func=_cmd)
