"""Inputs that reading consumes (issue 30, "Ctrl-C on a FIFO log can hang"): a FIFO or pipe is read
once, whole and interruptibly, and a stop signal ends the wait for its data whichever thread the
kernel delivers it to and whatever C code ran when it arrived."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import fdikit
from fdikit.base.inputs import is_stream, read_stream, spooled, stream_kind
from fdikit.errors import DataError

ENV = {**os.environ, "PYTHONPATH": str(Path(fdikit.__file__).resolve().parents[1])}


def _writer(fifo: Path, text: str, hold: threading.Event | None = None) -> threading.Thread:
    def write():
        with open(fifo, "w") as fh:   # blocks until the reader opened the FIFO
            fh.write(text)
            fh.flush()
            if hold is not None:
                hold.wait(30)

    th = threading.Thread(target=write, daemon=True)
    th.start()
    return th


def test_a_fifo_is_a_stream_and_a_file_is_not(tmp_path):
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    (tmp_path / "x.csv").write_text("t\n")
    assert is_stream(fifo) and stream_kind(fifo) == "FIFO"
    assert not is_stream(tmp_path / "x.csv") and not is_stream(tmp_path) and not is_stream(tmp_path / "no")
    r, w = os.pipe()
    try:
        assert stream_kind(f"/proc/self/fd/{r}") == "pipe"
    finally:
        os.close(r)
        os.close(w)


def test_a_fifo_is_read_to_its_end_and_spooled_under_its_name(tmp_path):
    fifo = tmp_path / "drive.csv"
    os.mkfifo(fifo)
    th = _writer(fifo, "t,x\n0,1\n" * 20000)   # more than a pipe holds: many reads
    assert read_stream(fifo) == b"t,x\n0,1\n" * 20000
    th.join()
    th = _writer(fifo, "t,x\n0,1\n")
    with spooled(fifo) as p:
        assert p != fifo and p.name == "drive.csv" and p.is_file() and p.read_text() == "t,x\n0,1\n"
    th.join()
    assert not p.exists() and not p.parent.exists()
    f = tmp_path / "x.csv"
    f.write_text("t\n")
    with spooled(f) as p:
        assert p == f


def test_a_fifo_log_reads_as_the_file_it_carries(tmp_path):
    from fdikit.io import read_csv, read_log

    text = "time,x\n0,1\n0.1,2\n0.2,3\n"
    fifo = tmp_path / "drive.csv"
    os.mkfifo(fifo)
    _writer(fifo, text)
    s = read_csv(fifo, time="time")
    assert s.values[0, :, 0].tolist() == [1.0, 2.0, 3.0]
    _writer(fifo, text)
    s = read_log(fifo, time="time")   # before: "is empty (0 bytes)"
    assert s.values[0, :, 0].tolist() == [1.0, 2.0, 3.0] and s.source.path == str(fifo)


def test_the_format_of_a_fifo_is_never_sniffed_from_bytes_the_reader_needs(tmp_path):
    from fdikit.io.formats import detect_format

    fifo = tmp_path / "drive"
    os.mkfifo(fifo)
    with pytest.raises(DataError, match=r"'drive' is a FIFO: its format cannot be told from its first bytes"):
        detect_format(fifo)   # and returns at once: nothing was opened
    os.rename(fifo, tmp_path / "drive.log")
    assert detect_format(tmp_path / "drive.log") == "candump"


_OTHER_THREAD = r"""
import os, signal, sys, threading, time
from fdikit.base import interrupt
from fdikit.io import read_csv

fifo = sys.argv[1]
interrupt.install()
sleeper = threading.Thread(target=time.sleep, args=(60,), daemon=True)
sleeper.start()


def writer():   # writes a header and keeps the FIFO open: no end of file ever comes
    fd = os.open(fifo, os.O_WRONLY)
    os.write(fd, b"time,x\n0,1\n")
    time.sleep(0.5)
    signal.pthread_kill(sleeper.ident, signal.SIGINT)   # the kernel's choice when a BLAS thread runs
    time.sleep(60)


threading.Thread(target=writer, daemon=True).start()
try:
    read_csv(fifo, time="time")
except KeyboardInterrupt:
    sys.exit(130)
sys.exit(0)
"""


def test_ctrl_c_delivered_to_another_thread_ends_the_wait_for_a_fifo(tmp_path):
    """The main thread waits for the rest of a FIFO log whose writer stays open; SIGINT reaches
    another thread, so no read of the main thread returns EINTR. A plain blocking read waits
    for ever; the wait on the signal wake-up pipe returns and the stop is raised."""
    fifo = tmp_path / "long.csv"
    os.mkfifo(fifo)
    try:
        out = subprocess.run([sys.executable, "-c", _OTHER_THREAD, str(fifo)], capture_output=True,
                             text=True, env=ENV, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("Ctrl-C delivered to another thread did not stop the read of the FIFO (hang)")
    assert out.returncode == 130, out.stderr


_NO_WRITER = r"""
import os, signal, sys, threading, time
from fdikit.base import interrupt
from fdikit.base.inputs import read_stream

interrupt.install()
threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
try:
    read_stream(sys.argv[1])
except interrupt.Terminated:
    sys.exit(143)
sys.exit(0)
"""


def test_sigterm_ends_the_wait_for_a_fifo_that_no_process_writes(tmp_path):
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    out = subprocess.run([sys.executable, "-c", _NO_WRITER, str(fifo)], capture_output=True, text=True,
                         env=ENV, timeout=60)
    assert out.returncode == 143, out.stderr


def test_a_full_temporary_folder_is_one_error_naming_the_input(tmp_path, monkeypatch):
    import errno

    fifo = tmp_path / "drive.csv"
    os.mkfifo(fifo)
    _writer(fifo, "t,x\n0,1\n")

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(DataError, match=r"drive.csv: cannot be copied into the temporary folder "
                                        r".*fdikit-input-.*: no space left on device \(the disk is full\)"):
        with spooled(fifo):
            pass
