"""Never lose data, never hang, stop cleanly (issue 30, items 1, 2, 3, 5 and 6).

Each test fails on the code before the fix: an output written onto its input or onto another
output, raw OSError tracebacks on a full disk (``/dev/full``), a partial output left behind
after a stop, Ctrl-C lost in NumPy's text cast, Ctrl-C / SIGTERM / a closed pipe giving a
traceback, follow mode silent on a clean stream, a FIFO that nobody reads hanging ``--events``,
two followers writing every event twice into one log, ``--resume`` on a different log skipping
its first lines, a 1 MB line a ``_csv.Error`` traceback, a fleet dying whole on a full disk or
merging two vehicles through ``--path-fields``, and a persistent bias reported "cleared".
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import fdikit
from fdikit.errors import DataError

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "two-mass" / "monitor.toml"
# the subprocesses run the fdikit this test imports (a source tree on PYTHONPATH or the installed one)
ENV = {**os.environ, "PYTHONPATH": str(Path(fdikit.__file__).resolve().parents[1])}


def _log(path: Path, duration: float = 10.0, seed: int = 5) -> Path:
    from fdikit.faults import Bias
    from fdikit.systems import two_mass

    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, seed, duration=duration)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    from fdikit.monitor.config import load_config, run_design

    d = tmp_path_factory.mktemp("safe")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    run_design(load_config(d / "monitor.toml"))
    _log(d / "log.csv")
    _log(d / "long.csv", duration=400.0)
    return d


def cli(*args):
    from fdikit.cli import main

    return main([str(a) for a in args])


def run_cmd(*args, **kw):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, env=ENV, timeout=kw.pop("timeout", 300), **kw)


def no_traceback(err: str) -> None:
    assert "Traceback" not in err and "Exception ignored" not in err, err


# ------------------------------------------------------------------ 1. outputs
def test_an_output_never_overwrites_the_input(setup, tmp_path, capsys):
    log = tmp_path / "log.csv"
    shutil.copy(setup / "log.csv", log)
    before = log.read_bytes()
    assert cli("monitor", log, "--config", setup / "monitor.toml", "--events", log) == 2
    assert "is the input LOG" in capsys.readouterr().err
    assert log.read_bytes() == before
    cfg = setup / "monitor.toml"
    assert cli("monitor", log, "--config", cfg, "--stats", cfg) == 2
    assert "is the input --config" in capsys.readouterr().err


def test_two_outputs_never_share_a_file(setup, tmp_path, capsys):
    out = tmp_path / "x"
    rc = cli("monitor", setup / "log.csv", "--config", setup / "monitor.toml", "--events", out,
             "--stats", tmp_path / "." / "x")
    assert rc == 2 and "is also the output of --events" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("option", ["--events", "--stats"])
def test_a_full_disk_is_one_message_naming_the_file(setup, option, capsys):
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    assert cli("monitor", setup / "log.csv", "--config", setup / "monitor.toml", option, "/dev/full") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/dev/full" in err and "disk is full" in err, err


@pytest.mark.parametrize("stop", [KeyboardInterrupt, OSError])
def test_a_stopped_or_failed_output_leaves_the_old_file_and_no_partial(tmp_path, stop):
    from fdikit.base.outputs import open_output

    p = tmp_path / "stats.parquet"
    p.write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt if stop is KeyboardInterrupt else DataError):
        with open_output(p) as fh:
            fh.write(b"half a parquet")
            raise stop(errno.ENOSPC, "No space left on device") if stop is OSError else stop()
    assert p.read_bytes() == b"old" and sorted(os.listdir(tmp_path)) == ["stats.parquet"]


def test_a_fifo_nobody_reads_is_an_error_not_a_hang(setup, tmp_path):
    fifo = tmp_path / "ev.fifo"
    os.mkfifo(fifo)
    out = run_cmd("monitor", setup / "log.csv", "--config", setup / "monitor.toml", "--events", fifo,
                  timeout=120)
    assert out.returncode == 2 and "no process reads" in out.stderr, out.stderr
    no_traceback(out.stderr)


def test_two_followers_never_share_an_event_log(tmp_path):
    from fdikit.monitor.live import EventLog

    with EventLog(tmp_path / "ev.jsonl"):
        with pytest.raises(DataError, match="another process"):
            EventLog(tmp_path / "ev.jsonl")


def test_a_full_disk_in_the_event_log_keeps_whole_lines(tmp_path, monkeypatch):
    from fdikit.monitor.live import EventLog

    p = tmp_path / "ev.jsonl"
    with EventLog(p) as log:
        log.start()
        log.write('{"t": 0.5}')

        class Full:
            def __init__(self, fh):
                self.fh = fh

            def __getattr__(self, name):
                return getattr(self.fh, name)

            def write(self, data):
                self.fh.write(bytes(data[:3]))
                raise OSError(errno.ENOSPC, "No space left on device")

        log.fh = Full(log.fh)
        with pytest.raises(DataError, match="ev.jsonl: cannot write: no space left"):
            log.write('{"t": 0.7}')
        log.fh = log.fh.fh
    assert p.read_text() == '{"t": 0.5}\n'


# ------------------------------------------------------------------ 2. signals
def test_a_ctrl_c_that_numpy_swallowed_still_stops_the_reader(setup):
    from fdikit.base import interrupt
    from fdikit.io import read_csv

    interrupt.reset()
    interrupt._PENDING.append(signal.SIGINT)   # what the handler records before NumPy clears it
    try:
        with pytest.raises(KeyboardInterrupt):
            read_csv(setup / "log.csv", time="time")
    finally:
        interrupt.reset()


def _stop_after(args, sig, wait_for, **kw):
    """Start a command, wait for a line on stderr or stdout (or a time), send ``sig``."""
    p = subprocess.Popen([sys.executable, "-m", "fdikit.cli", *map(str, args)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=ENV, **kw)
    if isinstance(wait_for, float):
        time.sleep(wait_for)
    else:
        wait_for(p)
    t0 = time.monotonic()
    p.send_signal(sig)
    out, err = p.communicate(timeout=120)
    return p.returncode, out, err, time.monotonic() - t0


@pytest.mark.parametrize("sig, code, word",
                         [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_a_stopped_batch_run_exits_cleanly_and_leaves_no_stats(setup, tmp_path, sig, code, word):
    """The log comes through a FIFO that is half written when the signal is sent: the run is
    certainly in progress (reading), on a fast machine as on a slow one. The writer keeps the FIFO
    open, so a read that missed the signal (it arrived while C code parsed the page, or on a BLAS
    thread) would wait for ever: the reader waits on the signal wake-up pipe too
    (:mod:`fdikit.base.inputs`)."""
    stats = tmp_path / "st.parquet"
    fifo = tmp_path / "long.csv"
    os.mkfifo(fifo)
    p = subprocess.Popen([sys.executable, "-m", "fdikit.cli", "monitor", str(fifo), "--config",
                          str(setup / "monitor.toml"), "--stats", str(stats)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=ENV)
    fd = None
    try:
        deadline = time.monotonic() + 120
        while fd is None:   # the open succeeds once the command opened the log for reading
            try:
                fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
            except OSError as exc:
                if exc.errno != errno.ENXIO or p.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"the command never opened its log: {p.communicate()}") from None
                time.sleep(0.01)
        with contextlib.suppress(BlockingIOError):   # a page of the log: fits any pipe, never blocks
            os.write(fd, (setup / "long.csv").read_bytes()[:4096])
        p.send_signal(sig)
        err = p.communicate(timeout=120)[1]
    finally:
        if fd is not None:
            os.close(fd)
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == code and f"stopped ({word})" in err, err
    no_traceback(err)
    assert not stats.exists() and not [f for f in os.listdir(tmp_path) if "partial" in f]


_EARLY = r"""
import sys
from fdikit.base import interrupt
from fdikit.cli import main

_install = interrupt.install


def install():   # report when the policy is in place, and whether NumPy was imported before it
    _install()
    print(f"installed, numpy imported: {'numpy' in sys.modules}", file=sys.stderr, flush=True)


interrupt.install = install
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.2])
def test_ctrl_c_during_the_first_imports_exits_130_in_one_line(setup, delay):
    """Ctrl-C while ``fdikit`` still imports NumPy, SciPy, numba ...: the signal policy is installed
    before any of them (``import fdikit.cli`` is light), so the stop is one line and 130. The child
    is the console script's ``from fdikit.cli import main; sys.exit(main())``, telling when the
    policy is installed; the signal follows ``delay`` s later."""
    p = subprocess.Popen([sys.executable, "-c", _EARLY, "monitor", str(setup / "long.csv"), "--config",
                          str(setup / "monitor.toml")], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=ENV)
    first = p.stderr.readline()
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=120)[1]
    assert first == "installed, numpy imported: False\n", first + err
    assert p.returncode == 130 and err == "fdikit: stopped (Ctrl-C)\n", err


def test_fdikit_cli_imports_no_numpy_before_main():
    code = ("import sys, fdikit.cli; "
            "print(sorted(m for m in ('numpy', 'scipy', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=120)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_follow_mode_stops_on_ctrl_c_with_its_summary(setup):
    def first_record(p):
        p.stdin.write((setup / "log.csv").read_text())
        p.stdin.flush()
        p.stdout.readline()   # the onset: the stream is being followed

    rc, _, err, dt = _stop_after(["monitor", "-", "--config", setup / "monitor.toml", "--follow"],
                                 signal.SIGINT, first_record, stdin=subprocess.PIPE)
    assert rc == 130 and "stopped (Ctrl-C)" in err, err
    assert re.search(r"follow: \d+ samples, 1 announcements", err), err
    no_traceback(err)
    assert dt < 5.0


_QUIET = r"""
import signal, sys, threading, time
from fdikit.cli import main

sleeper = threading.Thread(target=time.sleep, args=(120,), daemon=True)
sleeper.start()


def waiting():   # the main thread sleeps in read, poll or select (x86-64, arm64 numbers)
    with open(f"/proc/self/task/{threading.main_thread().native_id}/syscall") as fh:
        return fh.read().split()[0] in ("0", "7", "23", "63", "73", "270", "271")


def stop():   # once the follower waits for lines, SIGINT reaches a thread that is not the reader
    while "fdikit.monitor.live" not in sys.modules:
        time.sleep(0.05)
    quiet = 0
    while quiet < 20:   # waiting for input for 1 s on end
        quiet = quiet + 1 if waiting() else 0
        time.sleep(0.05)
    signal.pthread_kill(sleeper.ident, signal.SIGINT)


threading.Thread(target=stop, daemon=True).start()
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("via", ["stdin", "fifo"])
def test_a_follower_waiting_on_a_quiet_stream_stops_on_ctrl_c(setup, tmp_path, via):
    """``candump -L can0 | fdikit monitor - --follow`` on a quiet bus: the writer keeps the pipe
    open and sends nothing, and SIGINT reaches another thread (as when a BLAS thread takes it), so
    the reader's ``read`` never returns EINTR. Before: a hang until the next line; now the wait
    includes the signal wake-up pipe (:func:`fdikit.base.inputs.iter_lines`), and a FIFO is a
    valid follow-mode log (before: "no such log file")."""
    head = (setup / "log.csv").read_text().splitlines(keepends=True)[:3]
    log = "-"
    if via == "fifo":
        log = tmp_path / "bus.csv"
        os.mkfifo(log)
    p = subprocess.Popen([sys.executable, "-c", _QUIET, "monitor", str(log), "--config",
                          str(setup / "monitor.toml"), "--follow"], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    fh = p.stdin
    deadline = time.monotonic() + 120
    while via == "fifo" and fh is p.stdin:   # opens once the follower opened its FIFO
        try:
            fh = os.fdopen(os.open(log, os.O_WRONLY | os.O_NONBLOCK), "w")
        except OSError as exc:
            if exc.errno != errno.ENXIO or p.poll() is not None or time.monotonic() > deadline:
                p.kill()
                raise AssertionError(f"the follower never opened its FIFO: {p.communicate()[1]}") from None
            time.sleep(0.01)
    try:
        fh.write("".join(head))
        fh.flush()
        try:
            p.wait(timeout=60)   # not communicate(): it would close standard input, an end of file
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            pytest.fail("the follower did not stop on Ctrl-C (a hang)")
    finally:
        fh.close()
        p.stdin.close()
    err = p.stderr.read()
    p.stdout.close()
    p.stderr.close()
    assert p.returncode == 130 and "stopped (Ctrl-C)" in err and "follow: 2 samples" in err, err
    no_traceback(err)


def test_follow_mode_prints_its_summary_on_a_clean_stream(setup):
    out = run_cmd("monitor", setup / "log.csv", "--config", setup / "monitor.toml", "--follow")
    assert out.returncode == 0 and "follow: 1001 samples, 1 announcements" in out.stderr, out.stderr


def test_a_closed_pipe_ends_quietly(setup):
    p = subprocess.Popen([sys.executable, "-m", "fdikit.cli", "monitor", str(setup / "long.csv"), "--config",
                          str(setup / "monitor.toml"), "--follow"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=ENV)
    p.stdout.readline()
    p.stdout.close()   # `| head -n 1`
    err = p.stderr.read().decode()
    p.wait(timeout=300)
    no_traceback(err)
    assert p.returncode == 141 and "BrokenPipe" not in err, err


# ------------------------------------------------------------------ 3. the fleet
def test_a_full_disk_in_a_fleet_is_that_logs_error_record(setup, tmp_path, monkeypatch):
    import fdikit.fleet
    import fdikit.fleet.process as process

    logs = tmp_path / "logs" / "veh1"
    logs.mkdir(parents=True)
    for name in ("a", "b"):
        shutil.copy(setup / "log.csv", logs / f"{name}.csv")
    real = process._commit

    def full(table, final, **kw):
        if "events" in final.parts and final.name.startswith("veh1_a"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(table, final, **kw)

    monkeypatch.setattr(process, "_commit", full)
    rep = fdikit.fleet.run([str(tmp_path / "logs")], setup / "monitor.toml", tmp_path / "out",
                           in_process=True)
    assert rep["ok"] == 1 and rep["errors"] == 1, rep
    assert "disk is full" in rep["error_records"][0]["error"]
    assert "events" in rep["error_records"][0]["error"]


def test_a_fleet_never_merges_two_vehicles_through_path_fields(setup, tmp_path):
    from fdikit.fleet import plan

    for car in ("car1", "car2"):
        (tmp_path / car / "run1").mkdir(parents=True)
        shutil.copy(setup / "log.csv", tmp_path / car / "run1" / "x.csv")
    with pytest.raises(DataError, match="two vehicles would be merged"):
        plan([str(tmp_path)], setup / "monitor.toml", tmp_path / "out")
    tasks = plan([str(tmp_path)], setup / "monitor.toml", tmp_path / "out",
                 template="{vehicle}/{run}/{route}")
    assert sorted(t.vehicle for t in tasks) == ["car1", "car2"]


def test_a_fleet_never_merges_two_vehicles_whose_logs_have_other_names(setup, tmp_path):
    """``car1/run1/a.csv`` and ``car2/run1/b.csv``: before, both were vehicle ``run1`` (routes
    ``a`` and ``b``) without a word; only logs of one name were refused."""
    from fdikit.fleet import plan

    for car, name in (("car1", "a"), ("car2", "b")):
        (tmp_path / car / "run1").mkdir(parents=True)
        shutil.copy(setup / "log.csv", tmp_path / car / "run1" / f"{name}.csv")
    with pytest.raises(DataError, match=r"'car1/run1/a.csv' and 'car2/run1/b.csv' both get vehicle 'run1'.*"
                                        r"two vehicles would be merged"):
        plan([str(tmp_path)], setup / "monitor.toml", tmp_path / "out")


# ------------------------------------------------------------------ 5. follow-mode findings
def test_resume_on_a_different_log_is_refused(setup, tmp_path):
    from fdikit.monitor.live import LiveMonitor

    ck = tmp_path / "ck.npz"
    LiveMonitor(setup / "monitor.toml").follow(open(setup / "log.csv"), checkpoint=ck)
    other = _log(tmp_path / "other.csv", seed=9)
    with pytest.raises(DataError, match="not the first line of the checkpointed run"):
        LiveMonitor(setup / "monitor.toml").follow(open(other), checkpoint=ck, resume=True)
    # the same log replayed resumes (nothing left to do)
    again = LiveMonitor(setup / "monitor.toml")
    assert again.follow(open(setup / "log.csv"), checkpoint=ck, resume=True) == 0


def test_a_1mb_line_in_follow_mode_is_an_invalid_line(setup, tmp_path):
    from fdikit.monitor.live import LiveMonitor

    lines = (setup / "log.csv").read_text().splitlines(keepends=True)
    lines.insert(5, "0.035," + "9" * 1_100_000 + ",1,2\n")
    recs = list(LiveMonitor(setup / "monitor.toml").records(lines))
    assert recs[0]["line"] == 6 and "cannot be read as CSV" in recs[0]["invalid"]


# ------------------------------------------------------------------ 6. episodes
def test_a_persistent_bias_is_not_seen_any_more_not_cleared(setup, capsys):
    """The bias lasts to the end of the log; its residual decays and the episode ends: the record
    and the text say "not seen any more", the event kind stays "cleared" (unchanged numbers)."""
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
    from fdikit.monitor.records import batch_records

    cfg = load_config(setup / "monitor.toml")
    sig = map_channels(cfg, read_log(cfg, setup / "log.csv"))
    recs = [r for r in batch_records(sig, build_monitor(cfg).run(sig)) if r.get("kind") == "cleared"]
    assert recs and all(r["label"] == "not seen any more" for r in recs)
    assert cli("monitor", setup / "log.csv", "--config", setup / "monitor.toml") == 0
    out = capsys.readouterr().out
    assert "not seen any more" in out and " cleared " not in out, out
    assert json.loads(json.dumps(recs[0]))["kind"] == "cleared"


def test_outputs_refused_before_any_computation(setup, tmp_path, monkeypatch):
    import fdikit.monitor.config as config

    def boom(*a, **k):
        raise AssertionError("computed before the outputs were checked")

    monkeypatch.setattr(config, "build_monitor", boom)
    assert cli("monitor", setup / "log.csv", "--config", setup / "monitor.toml", "--events",
               setup / "log.csv") == 2


def test_a_half_written_checkpoint_is_a_clear_error(setup, tmp_path):
    from fdikit.monitor.live import LiveMonitor

    ck = tmp_path / "ck.npz"
    LiveMonitor(setup / "monitor.toml").follow(open(setup / "log.csv"), checkpoint=ck)
    half = tmp_path / "half.npz"
    half.write_bytes(ck.read_bytes()[: ck.stat().st_size // 3])
    with pytest.raises(DataError, match="not a readable fdikit checkpoint"):
        LiveMonitor(setup / "monitor.toml").load_checkpoint(half)


@pytest.mark.parametrize("kind, word", [("gzip", "gzip-compressed"), ("xlsx", "ZIP archive"),
                                        ("parquet", "Parquet file")])
def test_a_binary_file_named_csv_says_what_it_is(setup, tmp_path, kind, word):
    import gzip
    import zipfile

    from fdikit.io import read_csv

    p = tmp_path / "log.csv"
    text = (setup / "log.csv").read_bytes()
    if kind == "gzip":
        p.write_bytes(gzip.compress(text))
    elif kind == "xlsx":
        with zipfile.ZipFile(p, "w") as z:
            z.writestr("xl/workbook.xml", "<workbook/>")
    else:
        pd.read_csv(setup / "log.csv").to_parquet(p)
    with pytest.raises(DataError, match=word):
        read_csv(p, time="time")


@pytest.mark.parametrize("cut", ["header", "half", "flipped"])
def test_a_corrupt_mdf4_is_one_clear_error_and_nothing_else(setup, tmp_path, cut):
    """asammdf's half-built MDF object used to print "Exception ignored in MDF4.__del__" and its
    traceback after fdikit's clear error (a 100-byte MDF4)."""
    import numpy as np
    from asammdf import MDF, Signal

    t = np.arange(200) * 0.01
    m = MDF(version="4.10")
    m.append([Signal(np.ones(200), t, name=n) for n in ("F", "P1", "P2")])
    m.save(tmp_path / "good.mf4", overwrite=True)
    m.close()
    data = bytearray((tmp_path / "good.mf4").read_bytes())
    if cut == "header":
        data = data[:100]
    elif cut == "half":
        data = data[: len(data) // 2]
    else:
        for i in range(200, min(len(data), 2000), 7):
            data[i] ^= 0xFF
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    cfg = tmp_path / "m.toml"
    cfg.write_text((setup / "monitor.toml").read_text().replace('format = "csv"', 'format = "auto"')
                   .replace('artifacts = "designs"', f'artifacts = "{(setup / "designs").as_posix()}"'))
    out = run_cmd("monitor", bad, "--config", cfg)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("fdikit: error: MDF file 'bad.mf4' is not a readable MDF file"), out.stderr
    assert out.stderr.count("\n") == 1, out.stderr
    no_traceback(out.stderr)
