"""Progress of long work in named steps (rich, on standard error), quiet when nobody watches."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["ProgressSteps", "progress_steps", "progress_wanted"]


def progress_wanted(json_output: bool = False, stream=None) -> bool:
    """Show progress? Not with ``--json`` (one JSON object is all a script reads) and not when
    standard error is not a terminal (a log file, CI)."""
    stream = sys.stderr if stream is None else stream
    return not json_output and bool(getattr(stream, "isatty", lambda: False)())


class ProgressSteps:
    """Handle of :func:`progress_steps`: ``step(description)`` starts the next step."""

    def __init__(self, prog=None, task=None):
        self._prog = prog
        self._task = task
        self._started = False

    def step(self, description: str) -> None:
        """Finish the current step (if any) and start the next, shown as ``description``."""
        if self._prog is None:
            return
        if self._started:
            self._prog.advance(self._task, 1)
        self._started = True
        self._prog.update(self._task, description=description)

    def done(self) -> None:
        if self._prog is not None and self._started:
            self._prog.advance(self._task, 1)
            self._started = False


@contextmanager
def progress_steps(enabled: bool, total: int, what: str) -> Iterator[ProgressSteps]:
    """A progress display of ``total`` named steps, on standard error (nothing when disabled).

    Examples
    --------
    >>> with progress_steps(False, 2, "demo") as p:
    ...     p.step("first")
    ...     p.step("second")
    """
    if not enabled:
        yield ProgressSteps()
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    prog = Progress(
        SpinnerColumn(),
        TextColumn(f"[bold]{what}[/bold]"),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=False,
    )
    with prog:
        task = prog.add_task("", total=total)
        handle = ProgressSteps(prog, task)
        try:
            yield handle
        finally:
            handle.done()
