"""Progress bars for long work (rich, on stderr so that a JSON object on stdout stays alone)."""

from __future__ import annotations

__all__ = ["progress_bar"]


def progress_bar(enabled: bool, total: int, what: str):
    """A rich progress bar on stderr for ``total`` steps of ``what``, or nothing.

    Parameters
    ----------
    enabled : bool
        False: no bar.
    total : int
        Number of steps.
    what : str
        The label shown beside the bar.

    Returns
    -------
    progress : rich.progress.Progress or contextlib.nullcontext
        The context to enter while the work runs.
    task : (str, int) or None
        ``(what, total)`` to add as the task of ``progress``; None when disabled.
    """
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(), None
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    # on stderr, so that a JSON object on stdout stays the only thing there
    prog = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TextColumn("runs"), TimeElapsedColumn(), TimeRemainingColumn(), transient=False,
                    console=Console(stderr=True))
    return prog, (what, total)
