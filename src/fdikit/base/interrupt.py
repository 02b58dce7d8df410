"""Stopping: Ctrl-C (SIGINT) and SIGTERM as exceptions that every ``except Exception`` lets pass,
and a record of the signal that code which cannot see the exception checks (:func:`check`).

:func:`install` (called by the ``fdikit`` command) turns SIGINT into :class:`KeyboardInterrupt`
and SIGTERM into :class:`Terminated` (a subclass of it, so one ``except KeyboardInterrupt``
closes what can be closed for both) and records the signal. Some C code (NumPy's text-to-float
cast) clears a pending exception and goes on: :func:`check` raises the recorded signal again
at the next point that calls it (the CSV reader after each column, an output before it is renamed
into place), so a stop is never lost.

A blocking read never sees a signal that arrived while C code ran (a C loop parsing the data read
before it), nor one that the kernel delivered to another thread (a BLAS worker): the read goes on
waiting and the process hangs. :func:`wait_readable` waits instead on the file and on the signal
wake-up pipe (:func:`signal.set_wakeup_fd`), into which the C-level handler writes whichever
thread it runs on, so a stop always ends the wait.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import threading
from collections.abc import Iterator

__all__ = ["Terminated", "check", "install", "pending", "reset", "wait_readable", "wakeup"]

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


@contextlib.contextmanager
def wakeup() -> Iterator[int | None]:
    """The read end of a signal wake-up pipe while the block runs (None outside the main thread).

    Every signal that reaches the process while the block runs writes a byte into it, whichever
    thread the kernel chose and whatever C code ran: a :func:`select.select` that includes it
    returns. The previous wake-up file descriptor is restored on exit.

    Examples
    --------
    >>> with wakeup() as fd:
    ...     fd is None or fd >= 0
    True
    """
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    r, w = os.pipe()
    os.set_blocking(r, False)
    os.set_blocking(w, False)
    try:
        old = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except ValueError:   # not the main interpreter
        os.close(r)
        os.close(w)
        yield None
        return
    try:
        yield r
    finally:
        signal.set_wakeup_fd(old)
        os.close(r)
        os.close(w)


def wait_readable(fd: int, wake: int | None, timeout: float = 0.5) -> bool:
    """Wait until ``fd`` can be read; a stop signal that arrives meanwhile is raised at once.

    Parameters
    ----------
    fd : int
        The file descriptor to wait on (a FIFO, a pipe, a socket, a terminal).
    wake : int or None
        The read end of :func:`wakeup` (None: wait at most ``timeout`` s at a time).
    timeout : float
        Longest single wait (s): the signal handlers also run this often.

    Returns
    -------
    bool
        True when ``fd`` is readable (data or end of file), False after ``timeout``.

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C, or :class:`Terminated` for SIGTERM, received before or during the wait.

    Examples
    --------
    >>> r, w = os.pipe(); _ = os.write(w, b"x")
    >>> wait_readable(r, None)
    True
    >>> os.close(r); os.close(w)
    """
    check()
    ready = select.select([fd] if wake is None else [fd, wake], [], [], timeout)[0]
    if wake is not None and wake in ready:
        with contextlib.suppress(OSError):
            while os.read(wake, 512):   # drain: the signal's handler runs right after this call
                pass
    check()   # a handler whose exception some C code cleared
    return fd in ready
