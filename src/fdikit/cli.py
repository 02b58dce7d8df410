"""The ``fdikit`` command.

Subcommands live in :mod:`fdikit.commands`, one module each, with a ``register(subparsers)``
function that adds its parser and sets ``func`` (called with the parsed arguments; returns the
exit code). Commands that report results accept ``--json`` and then print exactly one JSON
object on standard output.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .commands._output import print_json
from .errors import FdikitError

__all__ = ["build_parser", "main", "print_json"]

#: Modules under fdikit.commands that register subcommands, in help order.
COMMAND_MODULES = ("demo", "reconstruct", "abs", "car", "monitor", "report", "fleet")
COMMAND_MODULES += ("codegen",)  # issue 29


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fdikit",
        description="Model-based fault detection, isolation and reconstruction for vehicles. Run "
                    "'fdikit COMMAND --help' for what a command does and its options. Commands that "
                    "report results print a text summary, or exactly one JSON object on standard "
                    "output with --json.",
    )
    parser.add_argument("--version", action="version", version=f"fdikit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"fdikit.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"fdikit.commands.{name}":
                continue  # that system has not landed yet
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except FdikitError as exc:
        print(f"fdikit: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
