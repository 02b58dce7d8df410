"""Follow mode survives `kill -9`: periodic checkpoints, `--resume`, and an event log that is exactly once.

The monitor runs in a real subprocess fed through a pipe; it is killed with SIGKILL mid-stream,
after a checkpoint and after records were written past it. The resumed process reads the same
input from its start. The event log then equals that of an uninterrupted run: nothing doubled,
nothing lost.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit.faults import Bias
from fdikit.systems import two_mass

from ..systems.car.rav4_example import DATA, rav4_config

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "two-mass" / "monitor.toml"


def follow_cmd(cfg, events, ckpt=None, every=None, resume=False):
    cmd = [sys.executable, "-m", "fdikit.cli", "monitor", "-", "--config", str(cfg), "--follow",
           "--events", str(events)]
    if ckpt is not None:
        cmd += ["--checkpoint", str(ckpt), "--checkpoint-every", str(every)]
    if resume:
        cmd += ["--resume"]
    return cmd


def wait_for(pred, timeout=120.0):
    t_end = time.time() + timeout
    while time.time() < t_end:
        if pred():
            return True
        time.sleep(0.02)
    return False


def lines_of(p):
    return p.read_text().splitlines() if p.exists() else []


def crash_and_resume(cfg, lines, tmp, every, kill_after, wait_record):
    """Reference run, then a run killed with SIGKILL after ``kill_after`` input lines and
    ``wait_record`` in its event log, then --resume over the whole input; both event logs."""
    ref = tmp / "ref.jsonl"
    r = subprocess.run(follow_cmd(cfg, ref), input="".join(lines), text=True, capture_output=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    ev, ck = tmp / "ev.jsonl", tmp / "ck.npz"
    p = subprocess.Popen(follow_cmd(cfg, ev, ck, every), stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    p.stdin.write("".join(lines[:kill_after]))
    p.stdin.flush()
    if wait_record is None:  # no record expected before the kill: a checkpoint, then a little more input
        assert wait_for(ck.exists), "no checkpoint was written"
        time.sleep(1.0)
    else:
        assert wait_for(lambda: ck.exists() and any(wait_record in x for x in lines_of(ev))), "no record"
    written = len(lines_of(ev))
    os.kill(p.pid, signal.SIGKILL)  # kill -9: no cleanup, no final checkpoint
    p.wait(timeout=60)
    p.stdin.close()
    p.stderr.close()
    assert p.returncode == -signal.SIGKILL
    r = subprocess.run(follow_cmd(cfg, ev, ck, every, resume=True), input="".join(lines), text=True,
                       capture_output=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return lines_of(ref), lines_of(ev), written


@pytest.fixture(scope="module")
def two_mass_cfg(tmp_path_factory):
    d = tmp_path_factory.mktemp("follow")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    r = subprocess.run([sys.executable, "-m", "fdikit.cli", "design", str(d / "monitor.toml"), "--json"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, 5)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df.loc[150, "P1"] = np.nan  # an invalid sample at 1.5 s: a record before the kill
    text = df.to_csv(index=False)
    lines = text.splitlines(keepends=True)
    lines.insert(260, "garbage,line\n")  # an invalid line: a record that has no time
    return d / "monitor.toml", lines


def test_csv_follow_resumed_after_kill9_equals_uninterrupted(two_mass_cfg, tmp_path):
    cfg, lines = two_mass_cfg
    # checkpoints every 100 samples; killed once the invalid line (~2.6 s) is logged, i.e. after
    # the checkpoint at sample 200 and with records after it; the fault (4 s) comes after the kill
    ref, got, written = crash_and_resume(cfg, lines, tmp_path, every=100, kill_after=300,
                                         wait_record='"line": 261')
    assert written >= 2  # the killed run had written records (some after its last checkpoint)
    assert any("hypothesis" in x for x in ref) and any("invalid" in x for x in ref)
    assert got == ref  # the same records, in order: no duplicate, no loss
    assert len(set(got)) == len(got)


def test_resume_refuses_another_config_and_a_foreign_log(two_mass_cfg, tmp_path):
    cfg, lines = two_mass_cfg
    ev, ck = tmp_path / "ev.jsonl", tmp_path / "ck.npz"
    r = subprocess.run(follow_cmd(cfg, ev, ck, 50), input="".join(lines[:200]), text=True,
                       capture_output=True, timeout=600)
    assert r.returncode == 0 and ck.exists() and lines_of(ev), r.stderr  # the invalid sample at 150
    other = tmp_path / "other.toml"
    shutil.copy(cfg, other)
    shutil.copytree(cfg.parent / "designs", tmp_path / "designs")
    r = subprocess.run(follow_cmd(other, ev, ck, 50, resume=True), input="".join(lines), text=True,
                       capture_output=True, timeout=600)
    assert r.returncode == 2 and "checkpoint of config" in r.stderr
    ev.write_text("")
    r = subprocess.run(follow_cmd(cfg, ev, ck, 50, resume=True), input="".join(lines), text=True,
                       capture_output=True, timeout=600)
    assert r.returncode == 2 and "shorter" in r.stderr
    r = subprocess.run([sys.executable, "-m", "fdikit.cli", "monitor", "-", "--config", str(cfg), "--follow",
                        "--resume"], input="", text=True, capture_output=True, timeout=600)
    assert r.returncode == 2 and "--checkpoint" in r.stderr


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "drive.blf").exists(), reason=f"real RAV4 data not found at {DATA}")
def test_candump_follow_resumed_after_kill9_equals_uninterrupted(tmp_path):
    """The real RAV4 minute as candump lines with a yaw-rate fault: the gridder's state is in the
    checkpoint too."""
    import cantools

    from fdikit.io.decode import decode_message, read_blf_table, set_signal

    cfg = rav4_config(tmp_path)
    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    db = cantools.database.load_file(str(DATA / "toyota_rav4.dbc"), strict=False)
    msg = db.get_message_by_name("KINEMATICS")
    sel = np.flatnonzero((ids == msg.frame_id) & (ts - ts[0] >= 35.0))
    v, _ = decode_message(msg, ["YAW_RATE"], pay.take(sel))
    pay.matrix[sel] = set_signal(msg, "YAW_RATE", pay.take(sel), v[:, 0] + 5.0).matrix
    lines = [f"({t:.6f}) can0 {i:03X}#{pay[k].hex().upper()}\n" for k, (t, i) in enumerate(zip(ts, ids))]
    kill_at = int(np.searchsorted(ts - ts[0], 30.0))
    ref, got, _ = crash_and_resume(cfg, lines, tmp_path, every=300, kill_after=kill_at, wait_record=None)
    assert any("hypothesis" in x for x in ref)
    assert got == ref and len(set(got)) == len(got)
    assert all(json.loads(x).get("t", 0) >= 0 for x in got)
