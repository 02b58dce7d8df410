"""Output files: written atomically (a temporary file in the same folder, fsync, rename), never
onto an input or onto one another, and an I/O error (a full disk) one clear message naming the file.

* :func:`check_outputs` -- refuses, before any computation, an output that is an input (the same
  file by path, link or hard link) or the output of another option;
* :func:`open_output` -- a file object whose content appears under the final name only when it is
  complete: an error, Ctrl-C or SIGTERM while writing removes the temporary file, so a partial
  output never looks valid. An existing character device (``/dev/stdout``, ``/dev/null``,
  ``/dev/full``) is written directly; a FIFO only when a process reads it (never a hang on open);
* :func:`io_error` -- an :class:`OSError` as a :class:`~fdikit.errors.DataError` naming the file.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any

from ..errors import DataError
from . import interrupt

__all__ = ["check_outputs", "io_error", "open_device", "open_output"]


def io_error(path: str | os.PathLike, exc: OSError, what: str = "cannot write") -> DataError:
    """An I/O error as one clear message naming the file.

    Examples
    --------
    >>> import errno
    >>> str(io_error("ev.jsonl", OSError(errno.ENOSPC, "No space left on device")))
    'ev.jsonl: cannot write: no space left on device (the disk is full)'
    """
    if exc.errno == errno.ENOSPC:
        why = "no space left on device (the disk is full)"
    elif exc.errno == errno.EDQUOT:
        why = "disk quota exceeded"
    else:
        why = (exc.strerror or str(exc) or type(exc).__name__)
        why = why[:1].lower() + why[1:]
    return DataError(f"{path}: {what}: {why}")


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def check_outputs(outputs: Mapping[str, Any], inputs: Mapping[str, Any] = {}) -> None:
    """Refuse an output that is an input or another output, before any computation.

    Parameters
    ----------
    outputs : mapping of str to path-like
        How each output is named in messages (e.g. ``"--events"``) to its path; ``None`` or an
        empty path is skipped.
    inputs : mapping of str to path-like
        The same for the files the command reads (``-`` for standard input is skipped).

    Raises
    ------
    DataError
        Naming both options and the path.

    Examples
    --------
    >>> check_outputs({"--events": "a.jsonl", "--stats": "a.parquet"}, {"LOG": "log.csv"})
    >>> check_outputs({"--events": "log.csv"}, {"LOG": "log.csv"})
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: --events log.csv: is the input LOG; an output never overwrites an input
    >>> check_outputs({"--events": "x", "--stats": "./x"})
    Traceback (most recent call last):
    ...
    fdikit.errors.DataError: --stats ./x: is also the output of --events; each output needs its own file
    """
    ins = [(k, Path(v)) for k, v in inputs.items() if v and str(v) != "-"]
    seen: list[tuple[str, Path]] = []
    for label, value in outputs.items():
        if not value:
            continue
        p = Path(value)
        for k, q in ins:
            if _same(p, q):
                raise DataError(f"{label} {value}: is the input {k}; an output never overwrites an input")
        for k, q in seen:
            if _same(p, q) and not _is_device(p):
                raise DataError(f"{label} {value}: is also the output of {k}; each output needs its own file")
        seen.append((label, p))


def _is_device(p: Path) -> bool:
    try:
        return stat.S_ISCHR(os.stat(p).st_mode)
    except OSError:
        return False


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def open_device(path: str | os.PathLike, mode: str = "wb") -> IO | None:
    """A file object on an existing FIFO or character device, else None (a regular file or none).

    A FIFO is opened only when a process reads it (a DataError now, never a hang on open).

    Examples
    --------
    >>> open_device("/dev/null").close()
    >>> open_device("no-such-file.jsonl") is None
    True
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError:
        return None
    if stat.S_ISFIFO(st.st_mode):
        try:  # non-blocking: a FIFO nobody reads is an error now, not a hang
            fd = os.open(p, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as exc:
            if exc.errno == errno.ENXIO:
                raise DataError(f"{p}: cannot write: it is a FIFO (named pipe) that no process reads"
                                ) from None
            raise io_error(p, exc) from None
        os.set_blocking(fd, True)
        return os.fdopen(fd, mode)
    if stat.S_ISCHR(st.st_mode):
        try:
            return open(p, mode)
        except OSError as exc:
            raise io_error(p, exc) from None
    if not stat.S_ISREG(st.st_mode):
        raise DataError(f"{p}: cannot write: it is not a regular file, a device or a FIFO")
    return None


@contextlib.contextmanager
def open_output(path: str | os.PathLike, mode: str = "wb", *, encoding: str | None = None
                ) -> Iterator[IO]:
    """Open an output file; its content appears under ``path`` only once it is complete.

    The file is written under a temporary name in the same folder, flushed to disk and renamed
    into place when the block ends without an error. On an error, Ctrl-C or SIGTERM the
    temporary file is removed and ``path`` is left as it was (never a partial file that looks
    valid). An existing character device or FIFO (read by a process) is written directly.

    Parameters
    ----------
    path : path-like
    mode : {"wb", "w"}
    encoding : str, optional
        Text mode's encoding (default UTF-8).

    Yields
    ------
    file object

    Raises
    ------
    DataError
        An I/O error (a full disk, a missing folder, no permission) naming the file.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "ev.jsonl")
    >>> with open_output(p, "w") as fh:
    ...     _ = fh.write('{"t": 0.5}\\n')
    >>> open(p).read()
    '{"t": 0.5}\\n'
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"open_output: mode must be 'wb' or 'w', got {mode!r}")
    p = Path(path)
    enc = None if mode == "wb" else (encoding or "utf-8")
    special = open_device(p, mode)
    if special is not None:
        try:
            with special as fh:
                yield fh
        except OSError as exc:
            raise io_error(p, exc) from None
        return
    parent = p.parent if str(p.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".partial", dir=parent)
    except OSError as exc:
        raise io_error(p, exc) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, mode, encoding=enc) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        interrupt.check()  # a stop that some C code swallowed: never rename a run cut short
        os.replace(tmp, p)
    except OSError as exc:
        raise io_error(p, exc) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
