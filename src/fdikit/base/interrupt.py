"""Stopping: Ctrl-C (SIGINT) and SIGTERM as exceptions that every ``except Exception`` lets pass,
and a record of the signal that code which cannot see the exception checks (:func:`check`).

:func:`install` (called by the ``fdikit`` command) turns SIGINT into :class:`KeyboardInterrupt`
and SIGTERM into :class:`Terminated` (a subclass of it, so one ``except KeyboardInterrupt``
closes what can be closed for both) and records the signal. Some C code (NumPy's text-to-float
cast) clears a pending exception and goes on: :func:`check` raises the recorded signal again
at the next point that calls it (the CSV reader after each column, an output before it is renamed
into place), so a stop is never lost.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["Terminated", "check", "install", "pending", "reset"]

_PENDING: list[int] = []


class Terminated(KeyboardInterrupt):
    """The process was asked to stop by SIGTERM (exit code 143)."""


def _raise(signum: int) -> None:
    if signum == signal.SIGTERM:
        raise Terminated("SIGTERM")
    raise KeyboardInterrupt


def _handler(signum, frame) -> None:
    _PENDING.append(signum)
    _raise(signum)


def install() -> None:
    """Make SIGINT and SIGTERM raise (and record) :class:`KeyboardInterrupt` / :class:`Terminated`.

    Does nothing outside the main thread (signal handlers can only be set there).

    Examples
    --------
    >>> install()  # doctest: +SKIP
    """
    if threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)


def pending() -> int | None:
    """The first signal received since :func:`install` (or :func:`reset`), else None.

    Examples
    --------
    >>> reset(); pending() is None
    True
    """
    return _PENDING[0] if _PENDING else None


def check() -> None:
    """Raise the recorded stop again (a signal whose exception some C code swallowed); else nothing.

    Examples
    --------
    >>> reset(); check()
    """
    if _PENDING:
        _raise(_PENDING[0])


def reset() -> None:
    """Forget a recorded signal (for a process that goes on after handling it, e.g. tests)."""
    _PENDING.clear()
