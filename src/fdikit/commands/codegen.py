"""``fdikit codegen CONFIG --out DIR``: portable C99 of a designed monitor (:mod:`fdikit.codegen`).

Writes ``<name>.h`` / ``<name>.c`` (double), ``<name>_f32.h`` / ``<name>_f32.c`` (float32) and their
layouts; ``--compile`` also builds them with the system compiler under the strict flags
(``-std=c99 -Wall -Wextra -Werror -pedantic``) and reports the state size.
"""

from __future__ import annotations

import argparse
import time

__all__ = ["register"]


def _codegen(args) -> int:
    from pathlib import Path

    from ..codegen import CMonitor, compile_shared
    from ..codegen import generate as gen
    from ._output import print_json

    t0 = time.perf_counter()
    res = gen(args.config, args.out, name=args.name, stop_after=args.stop_after)
    name = res["name"]
    out = {"config": str(args.config), "out": str(args.out), "name": name, "design_hash": res["design_hash"],
           "stages": res["layout"]["stages"], "inputs": res["layout"]["inputs"],
           "files": res["files"], "code_bytes": res["code_bytes"],
           "generation_seconds": round(res["seconds"], 4)}
    if args.can:  # the DBC decoder and the follow-mode gridder feeding the monitor's inputs
        from ..codegen.can import generate_can

        can = generate_can(args.config, args.out, res["layout"]["inputs"], name=f"{name}_can")
        out["files"] += can["files"]
        if args.compile:
            compile_shared([Path(args.out) / f"{name}_can.c"], Path(args.out) / f"lib{name}_can.so")
    if args.compile:
        libs = {}
        for variant, stem in (("double", name), ("float", f"{name}_f32")):
            lib = compile_shared([Path(args.out) / f"{stem}.c"], Path(args.out) / f"lib{stem}.so")
            cm = CMonitor(lib, Path(args.out) / f"{stem}.layout.json")
            cm.check_design(res["design_hash"])
            libs[variant] = {"library": str(lib), "state_bytes": cm.state_bytes}
        out["compiled"] = libs
    out["seconds"] = round(time.perf_counter() - t0, 3)
    if args.json:
        print_json(out)
    else:
        print(f"{name}: {', '.join(out['stages'])}")
        for f in out["files"]:
            print(f)
        for v, d in out.get("compiled", {}).items():
            print(f"{v}: {d['library']} (state {d['state_bytes']} bytes)")
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "codegen",
        help="generate portable C99 of a designed monitor (double and float32)",
        description=(
            "Generate C99 from a monitor config's designed artifacts (run 'fdikit design CONFIG'\n"
            "first): a header with a fixed-size state struct and init, reset, step, checkpoint\n"
            "and restore; no dynamic memory, no globals with state, only <math.h> and <stdint.h>.\n"
            "The design hash is compiled in. A stage that cannot be generated is refused by name.\n"
            "Prints the generated files, or with --json one JSON object with the files, the\n"
            "stages, the design hash, the code and state sizes in bytes and the time taken."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("config", help="the monitor configuration (TOML)")
    p.add_argument("--out", required=True, help="directory for the generated files")
    p.add_argument("--name", help="C prefix of the generated names (default fdk_<config folder>)")
    p.add_argument("--compile", action="store_true",
                   help="compile both variants with the system C compiler (strict flags) and load them")
    p.add_argument("--stop-after", metavar="ARTIFACT",
                   help="generate the processors up to this one (the decision keeps its channels still "
                        "produced), e.g. when a later stage cannot be generated yet")
    p.add_argument("--can", action="store_true",
                   help="also write <name>_can.h/.c: the DBC decoder of the config's CAN signals and the "
                        "follow-mode gridder feeding the monitor's inputs (a CAN log config)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_codegen)
