"""The ``fdikit`` command.

Subcommands live in :mod:`fdikit.commands`, one module each, with a ``register(subparsers)``
function that adds its parser and sets ``func`` (called with the parsed arguments; returns the
exit code). Commands that report results accept ``--json`` and then print exactly one JSON
object on standard output.

One signal policy for every command (:func:`main`): Ctrl-C (SIGINT) and SIGTERM stop it with one
line on standard error and exit code 130 / 143, after the ``finally`` blocks and context managers
closed what they hold (outputs are written atomically, :mod:`fdikit.base.outputs`, so a stopped
run leaves no partial file that looks valid); a closed standard output (``| head -n 1``) ends
the command quietly (exit code 141, 128 + SIGPIPE); an I/O error that no command turned into a
clear error is one line naming the file (exit code 2).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import TYPE_CHECKING

from . import __version__
from .base import interrupt  # first, and light: no NumPy before main() installs the signal policy
from .errors import FdikitError

if TYPE_CHECKING:
    from .commands._output import print_json

__all__ = ["build_parser", "main", "print_json"]


def __getattr__(name: str):
    if name == "print_json":   # re-exported, loaded on first use (it imports NumPy)
        from .commands._output import print_json

        return print_json
    raise AttributeError(f"module 'fdikit.cli' has no attribute {name!r}")

#: Modules under fdikit.commands that register subcommands, in help order.
COMMAND_MODULES = ("demo", "reconstruct", "abs", "car", "monitor", "report", "fleet")
COMMAND_MODULES += ("codegen",)  # issue 29
COMMAND_MODULES += ("validate",)  # issue 26


def build_parser() -> argparse.ArgumentParser:
    """The ``fdikit`` argument parser: one subcommand per module of :data:`COMMAND_MODULES`."""
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


def _quiet_stdout() -> None:
    """Standard output was closed by its reader: send what is still buffered nowhere."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _stopped(exc: BaseException) -> int:
    term = isinstance(exc, interrupt.Terminated) or interrupt.pending() == 15
    try:
        print(f"fdikit: stopped ({'SIGTERM' if term else 'Ctrl-C'})", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass
    return 143 if term else 130


def main(argv: list[str] | None = None) -> int:
    """Run the ``fdikit`` command; returns its exit code (see the module docstring)."""
    interrupt.reset()
    interrupt.install()   # before any heavy import: Ctrl-C in the first second exits 130 too
    try:
        parser = build_parser()
        interrupt.check()   # a stop that an import swallowed
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 0
        try:
            code = int(args.func(args) or 0)
            interrupt.check()  # a stop that some C code swallowed still stops with its code
            return code
        except FdikitError as exc:
            print(f"fdikit: error: {exc}", file=sys.stderr)
            return 2
        except BrokenPipeError:
            _quiet_stdout()
            return 141
        except OSError as exc:  # an I/O error no command made clear: one line naming the file
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"fdikit: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, and SIGTERM (interrupt.Terminated)
        return _stopped(exc)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
