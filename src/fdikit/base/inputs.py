"""Inputs that reading consumes: a log given as a FIFO (``mkfifo``), a pipe (``<(zcat drive.csv.gz)``,
``/dev/stdin``) or a socket is read once, whole and interruptibly, into a temporary file that every
later step (the format sniffing, the reader and its error messages) reads as often as it needs.

* :func:`is_stream` -- whether a path is such an input (reading it takes its bytes away);
* :func:`read_stream` -- its bytes, up to the end of the input (its last writer closed it),
  waiting for data with :func:`fdikit.base.interrupt.wait_readable`: Ctrl-C or SIGTERM stop the
  wait at once (never a hang on a writer that keeps the FIFO open and sends nothing);
* :func:`spooled` -- a regular file holding a stream's bytes, with the stream's file name (so
  messages and suffix-based format detection read as for the original), removed afterwards; a
  regular file or folder is passed through untouched;
* :func:`open_lines` and :func:`iter_lines` -- follow mode's input (standard input, a FIFO, a
  file), line by line as it arrives: a stream is opened without blocking and each wait for its
  next line ends at once on Ctrl-C or SIGTERM, even on a quiet bus that sends nothing.
"""

from __future__ import annotations

import codecs
import contextlib
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from ..errors import DataError
from . import interrupt
from .outputs import io_error

__all__ = ["is_stream", "iter_lines", "open_lines", "read_stream", "spooled", "stream_kind"]


def stream_kind(path: str | os.PathLike) -> str | None:
    """What a path is when reading it consumes it: ``"FIFO"``, ``"pipe"``, ``"socket"`` or
    ``"character device"``; None for a regular file, a folder or a missing path.

    Examples
    --------
    >>> stream_kind(__file__) is None
    True
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISFIFO(mode):   # a named FIFO, or an anonymous pipe seen through /dev/fd or /proc
        return "FIFO" if stat.S_ISFIFO(os.lstat(path).st_mode) else "pipe"
    if stat.S_ISSOCK(mode):
        return "socket"
    if stat.S_ISCHR(mode):
        return "character device"
    return None


def _fd_kind(fd: int) -> bool:
    try:
        mode = os.fstat(fd).st_mode
    except OSError:
        return False
    return stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stat.S_ISCHR(mode)


def is_stream(path: str | os.PathLike) -> bool:
    """Whether reading ``path`` consumes it (a FIFO, a pipe, a socket or a character device).

    Examples
    --------
    >>> is_stream(__file__)
    False
    """
    return stream_kind(path) is not None


def read_stream(path: str | os.PathLike, *, chunk: int = 1 << 16) -> bytes:
    """Every byte of a stream input, read without ever blocking where a signal cannot stop it.

    The input is opened without blocking (no hang on a FIFO that no process writes yet) and read
    whenever :func:`fdikit.base.interrupt.wait_readable` says it has data, until its end (every
    writer closed it; a FIFO that no writer has opened yet is waited for).

    Parameters
    ----------
    path : path-like
        A FIFO, pipe, socket or character device.
    chunk : int
        Bytes per read.

    Returns
    -------
    bytes

    Raises
    ------
    DataError
        The input cannot be opened or read (naming it).
    KeyboardInterrupt
        Ctrl-C (or :class:`~fdikit.base.interrupt.Terminated` for SIGTERM) while waiting or reading.

    Examples
    --------
    >>> import tempfile, threading
    >>> fifo = os.path.join(tempfile.mkdtemp(), "log.csv"); os.mkfifo(fifo)
    >>> def write():
    ...     with open(fifo, "w") as fh:
    ...         _ = fh.write("t,x\\n0,1\\n")
    >>> threading.Thread(target=write).start()
    >>> read_stream(fifo)
    b't,x\\n0,1\\n'
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise DataError(f"{path}: cannot be opened for reading: {exc.strerror or exc}") from None
    parts: list[bytes] = []
    try:
        with interrupt.wakeup() as wake:
            while True:
                if not interrupt.wait_readable(fd, wake):
                    continue
                try:
                    data = os.read(fd, chunk)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError as exc:
                    raise DataError(f"{path}: cannot be read: {exc.strerror or exc}") from None
                if not data:
                    return b"".join(parts)
                parts.append(data)
    finally:
        os.close(fd)


@contextlib.contextmanager
def spooled(path: str | os.PathLike) -> Iterator[Path]:
    """A path that can be read as often as needed: ``path`` itself, or for a stream input
    (:func:`is_stream`) a temporary regular file of the same name holding all its bytes
    (:func:`read_stream`), removed when the block ends.

    Parameters
    ----------
    path : path-like
        A log file, folder or stream.

    Yields
    ------
    pathlib.Path

    Raises
    ------
    DataError
        The stream cannot be read, or the temporary folder is full (naming both).

    Examples
    --------
    >>> with spooled(__file__) as p:
    ...     p == Path(__file__)
    True
    """
    p = Path(path)
    if not is_stream(p):
        yield p
        return
    data = read_stream(p)
    with tempfile.TemporaryDirectory(prefix="fdikit-input-") as tmp:
        q = Path(tmp) / (p.name or "input")
        try:
            q.write_bytes(data)
        except OSError as exc:   # a full temporary folder: name the input and the folder
            raise io_error(p, exc, f"cannot be copied into the temporary folder {tmp}") from None
        del data
        yield q


def open_lines(path: str | os.PathLike, encoding: str = "utf-8"):
    """A text file object over ``path`` for :func:`iter_lines`: a stream (a FIFO) is opened without
    blocking, so waiting for its first writer is a wait that Ctrl-C ends, not a blocked ``open``.

    Examples
    --------
    >>> with open_lines(__file__) as fh:
    ...     next(iter_lines(fh)).endswith("\\n")
    True
    """
    if not is_stream(path):
        return open(path, encoding=encoding, newline=None)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    return os.fdopen(fd, encoding=encoding, newline=None)


def iter_lines(lines: Iterable[str]) -> Iterator[str]:
    """The lines of ``lines`` as they arrive (each with its ``"\\n"``; ``"\\r\\n"`` read as
    ``"\\n"``), waiting for a stream's data on the signal wake-up pipe too
    (:func:`fdikit.base.interrupt.wait_readable`): Ctrl-C or SIGTERM end the wait at once.

    A file object on a FIFO, pipe, socket or terminal is read through its file descriptor (with its
    own encoding); anything else (a regular file, a list of strings) is iterated as it is.

    Parameters
    ----------
    lines : iterable of str
        A text file object (``sys.stdin``, :func:`open_lines`) or any iterable of lines.

    Yields
    ------
    str

    Examples
    --------
    >>> list(iter_lines(["t,x\\n", "0,1\\n"]))
    ['t,x\\n', '0,1\\n']
    """
    try:
        fd = lines.fileno()   # type: ignore[attr-defined]
    except (AttributeError, OSError, ValueError):
        fd = None
    if fd is None or not _fd_kind(fd):
        yield from lines
        return
    decoder = codecs.getincrementaldecoder(getattr(lines, "encoding", None) or "utf-8")(
        getattr(lines, "errors", None) or "strict")
    pending = ""
    with interrupt.wakeup() as wake:
        while True:
            if not interrupt.wait_readable(fd, wake):
                continue
            try:
                data = os.read(fd, 1 << 16)
            except (BlockingIOError, InterruptedError):
                continue
            pending += decoder.decode(data, final=not data)
            *done, pending = pending.split("\n")
            for line in done:
                yield (line[:-1] if line.endswith("\r") else line) + "\n"
            if not data:
                break
    if pending:
        yield pending
