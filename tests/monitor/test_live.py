"""Live monitoring as a library (issue 25): ``fdikit.monitor.live`` without the CLI.

* follow mode from Python alone, in a fresh interpreter that never imports ``fdikit.commands``,
  gives the records the command prints;
* checkpoint and resume through the public state APIs only (``LiveMonitor.state/restore``,
  ``save_checkpoint/load_checkpoint``): the records before the checkpoint plus those of the
  resumed run equal an uninterrupted run, for CSV and for candump input;
* ``FrameGridder.state()/restore()`` continues bit for bit, through a checkpoint file, and a bad
  state is refused with a DataError that leaves the gridder as it was; likewise ``StreamTimes``
  and ``LiveClock``.
"""

import copy
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit import DataError
from fdikit.base.state import load_state, save_state
from fdikit.faults import Bias
from fdikit.io import StreamTimes
from fdikit.io.stream import FrameGridder
from fdikit.monitor import LiveClock, LiveMonitor
from fdikit.monitor.config import load_config, run_design
from fdikit.systems import two_mass

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "two-mass" / "monitor.toml"
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"

DBC_TEXT = '''VERSION ""
BO_ 180 SPEED: 8 XXX
 SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX
BO_ 170 WHEEL: 8 XXX
 SG_ FL : 7|16@0+ (0.01,0) [0|250] "km/h" XXX
 SG_ FR : 23|16@0+ (0.01,0) [0|250] "km/h" XXX
'''


# ------------------------------------------------------------------------------------ gridder
def _frames(seed=3, n=1500):
    """Two messages at jittered 50 and 80 Hz, a dropped stretch (a gap), a garbled payload."""
    rng = np.random.default_rng(seed)
    out = []
    for fid, rate in ((180, 50.0), (170, 80.0)):
        t = 1.7e9 + np.arange(n) / rate + rng.uniform(0, 2e-3, n)
        for k, tk in enumerate(t):
            if fid == 170 and 400 <= k < 480:
                continue  # a gap of one second in the wheel speeds
            if fid == 180:
                data = (int(5000 + 1000 * np.sin(k / 40)) << 8).to_bytes(8, "big")
            else:
                v = int(4000 + 900 * np.cos(k / 50))
                data = (v << 48 | (v + 7) << 32).to_bytes(8, "big")
            if fid == 180 and k == 700:
                data = b"\x01"  # cannot be decoded
            out.append((float(tk), fid, data))
    out.sort(key=lambda f: f[0])
    return out


def _gridder():
    import cantools

    db = cantools.database.load_string(DBC_TEXT, database_format="dbc")
    return FrameGridder(db, ["SPEED.SPEED", "WHEEL.FL", "WHEEL.FR"], rate=50.0)


def _key(samples):
    """Grid samples as comparable values, bit for bit (NaN by its bits)."""
    return [(np.float64(t).tobytes(), tuple(np.float64(v[s]).tobytes() for s in sorted(v)), why)
            for t, v, why in samples]


@pytest.mark.parametrize("cut", [0, 1, 37, 1234, 2919])
def test_gridder_state_round_trip_continues_bitwise(tmp_path, cut):
    frames = _frames()
    ref = _gridder()
    whole = [s for f in frames for s in ref.push(*f, "can0")] + ref.flush()
    assert any(why for _, _, why in whole) and sum(why is None for _, _, why in whole) > 800

    a = _gridder()
    first = [s for f in frames[:cut] for s in a.push(*f, "can0")]
    save_state(tmp_path / "g.npz", {"gridder": a.state()}, meta={"kind": "test"})
    b = _gridder()  # a fresh process would build this from the config
    b.restore(load_state(tmp_path / "g.npz")[0]["gridder"])
    assert b.state() == a.state()
    rest = [s for f in frames[cut:] for s in b.push(*f, "can0")] + b.flush()
    assert _key(first + rest) == _key(whole)
    assert (b.frames, b.undecodable, b.t0) == (ref.frames, ref.undecodable, ref.t0)


def test_gridder_refuses_a_bad_state_and_keeps_its_own():
    g = _gridder()
    for f in _frames()[:300]:
        g.push(*f, "can0")
    good = g.state()
    before = json.dumps(good, sort_keys=True)

    def bad(**change):
        st = json.loads(before)
        for k, v in change.items():
            st[k] = v
        return st

    series = json.loads(before)["series"]
    backwards = json.loads(json.dumps(series))
    backwards["WHEEL.FL"]["t"] = backwards["WHEEL.FL"]["t"][::-1]
    short = json.loads(json.dumps(series))
    short["SPEED.SPEED"]["v"] = short["SPEED.SPEED"]["v"][:-1]
    cases = [
        ("not a dict", [1, 2], "must be a dict"),
        ("missing key", {k: v for k, v in good.items() if k != "k"}, "missing keys ['k']"),
        ("unknown key", bad(extra=1), "unknown keys ['extra']"),
        ("other signals", bad(series={"SPEED.SPEED": series["SPEED.SPEED"]}), "grids signals"),
        ("negative count", bad(k=-1), "k must be a count"),
        ("count as text", bad(frames="12"), "frames must be a count"),
        ("nan time", bad(t0=float("nan")), "t0 must be finite"),
        ("text time", bad(t_last="soon"), "t_last must be a number"),
        ("backwards", bad(series=backwards), "frame times go backwards"),
        ("lengths", bad(series=short), "frame times and"),
        ("bus", bad(bus={"x": "can0"}), "bus keys"),
    ]
    for what, st, msg in cases:
        with pytest.raises(DataError, match=msg.replace("[", r"\[").replace("]", r"\]")):
            g.restore(st)
        assert json.dumps(g.state(), sort_keys=True) == before, what  # nothing changed
    g.restore(json.loads(before))  # the good state is accepted
    assert json.dumps(g.state(), sort_keys=True) == before


def test_stream_times_and_live_clock_states():
    st = StreamTimes()
    assert st("1700000000.000") == 0.0
    st2 = StreamTimes()
    st2.restore(json.loads(json.dumps(st.state())))
    assert st2("1700000000.010") == st("1700000000.010") == 0.01
    for bad in ({"time_unit": "s"}, {"time_unit": "h", "rebase": None, "origin": None},
                {"time_unit": "s", "rebase": "yes", "origin": None},
                {"time_unit": "s", "rebase": None, "origin": [1, 2]}):
        fresh = StreamTimes()
        with pytest.raises(DataError, match="StreamTimes state|time_unit"):
            fresh.restore(bad)
        assert fresh.origin is None and fresh.time_unit == "auto"
    clock = LiveClock("auto")
    t = [clock.seconds(x, i) for i, x in enumerate(["1700000000.00", "1700000000.02"])]
    again = LiveClock("auto")
    again.restore(clock.state())
    assert t == [0.0, 0.02] and again.seconds("1700000000.04", 3) == clock.seconds("1700000000.04", 3)
    with pytest.raises(DataError, match="LiveClock state"):
        again.restore({"unit": "s"})


# ------------------------------------------------------------------------------------ follow mode
@pytest.fixture(scope="module")
def two_mass_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("live")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    run_design(load_config(d / "monitor.toml"))
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, 5)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df.loc[250, "P1"] = np.nan   # a held sample at 2.5 s
    df = df.drop(index=range(60, 80))  # a gap of 0.2 s
    lines = df.to_csv(index=False).splitlines(keepends=True)
    lines.insert(260, "garbage,line\n")  # an invalid line
    (d / "log.csv").write_text("".join(lines))
    return d / "monitor.toml", lines


class _Crash(Exception):
    pass


def _crashing(lines, n):
    """The input of a process that dies after reading ``n`` lines."""
    for k, line in enumerate(lines):
        if k == n:
            raise _Crash()
        yield line


def _crash_and_resume(cfg, lines, every, crash_after, via_file, tmp_path):
    """Records of a run that crashes after ``crash_after`` input lines, cut back to its last
    checkpoint, plus the records of a fresh LiveMonitor resumed from that checkpoint over the
    whole input (replayed from its start); and how many records the crashed run wrote after its
    last checkpoint."""
    got: list[dict] = []
    saved: dict = {}

    def checkpoint(live):
        if via_file:
            live.save_checkpoint(tmp_path / "ck.npz", events_bytes=len(got))
        else:
            saved["state"] = copy.deepcopy(live.state())  # nothing shared with the crashed run
            saved["n"] = len(got)

    live = LiveMonitor(cfg)
    with pytest.raises(_Crash):
        for rec in live.records(_crashing(lines, crash_after), checkpoint_every=every,
                                on_checkpoint=checkpoint):
            got.append(rec)
    resumed = LiveMonitor(cfg)
    if via_file:
        n = resumed.load_checkpoint(tmp_path / "ck.npz")["events_bytes"]
    else:
        resumed.restore(saved["state"])
        n = saved["n"]
    return got[:n] + list(resumed.records(iter(lines))), len(got) - n


@pytest.mark.parametrize("via_file", [False, True], ids=["state", "checkpoint-file"])
def test_csv_follow_resumed_equals_uninterrupted(two_mass_csv, tmp_path, via_file):
    cfg, lines = two_mass_csv
    ref = list(LiveMonitor(cfg).records(iter(lines)))
    kinds = {"gap" if r.get("gap") else r.get("kind") or ("line" if "line" in r else "invalid")
             for r in ref}
    assert {"gap", "onset", "line", "invalid"} <= kinds, kinds
    # crashed after line 280: its last checkpoint (200 samples) is before the held sample (line
    # 232) and the invalid line (261), which it had written: written again, not doubled
    got, after = _crash_and_resume(cfg, lines, 100, 280, via_file, tmp_path)
    assert after >= 2  # the crashed run had written records after its last checkpoint
    assert got == ref


def test_resume_skips_only_what_was_consumed(two_mass_csv):
    """A resumed run that is not given the replayed input but the stream going on (later lines,
    no header) steps every line it gets."""
    cfg, lines = two_mass_csv
    ref = list(LiveMonitor(cfg).records(iter(lines)))
    a = LiveMonitor(cfg)
    first = list(a.records(iter(lines[:401])))
    b = LiveMonitor(cfg)
    b.restore(a.state())
    assert first + list(b.records(iter(lines[401:]))) == ref


def test_live_restore_refuses_foreign_states(two_mass_csv, tmp_path):
    cfg, lines = two_mass_csv
    live = LiveMonitor(cfg)
    list(live.records(iter(lines[:100])))
    st = live.state()
    with pytest.raises(DataError, match="keys"):
        LiveMonitor(cfg).restore({"monitor": st["monitor"]})
    with pytest.raises(DataError, match="gridder state"):
        LiveMonitor(cfg).restore(dict(st, gridder={"series": {}}))
    live.save_checkpoint(tmp_path / "ck.npz")
    other = tmp_path / "other.toml"
    shutil.copy(cfg, other)
    shutil.copytree(cfg.parent / "designs", tmp_path / "designs")
    with pytest.raises(DataError, match="checkpoint of config"):
        LiveMonitor(other).load_checkpoint(tmp_path / "ck.npz")


def test_follow_from_python_alone_equals_the_command(two_mass_csv, tmp_path):
    """Follow mode with an event log and checkpoints in a fresh interpreter that imports only the
    library: the records the command prints, and no fdikit.commands module loaded."""
    cfg, _ = two_mass_csv
    log = cfg.parent / "log.csv"
    code = f"""
import json, sys
from fdikit.monitor.live import LiveMonitor
live = LiveMonitor({str(cfg)!r})
with open({str(log)!r}) as fh:
    n = live.follow(fh, on_record=lambda r: print(json.dumps(r)), events={str(tmp_path / 'lib.jsonl')!r},
                    checkpoint={str(tmp_path / 'lib.npz')!r}, checkpoint_every=50)
assert n > 0
assert not any(m == "fdikit.commands" or m.startswith("fdikit.commands.") or m == "fdikit.cli"
               for m in sys.modules), sorted(m for m in sys.modules if m.startswith("fdikit.c"))
"""
    lib = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert lib.returncode == 0, lib.stderr
    cmd = subprocess.run([sys.executable, "-m", "fdikit.cli", "monitor", str(log), "--config", str(cfg),
                          "--follow", "--events", str(tmp_path / "cli.jsonl")],
                         capture_output=True, text=True, timeout=600)
    assert cmd.returncode == 0, cmd.stderr
    assert lib.stdout == cmd.stdout and lib.stdout.count("\n") > 3
    assert (tmp_path / "lib.jsonl").read_bytes() == (tmp_path / "cli.jsonl").read_bytes()
    state, meta = load_state(tmp_path / "lib.npz")
    assert meta["kind"] == "follow"
    assert state["follow"]["events_bytes"] == (tmp_path / "lib.jsonl").stat().st_size


# ------------------------------------------------------------------------------------ candump


@pytest.mark.skipif(not (DATA / "drive.blf").exists(), reason=f"real RAV4 data not found at {DATA}")
def test_candump_follow_resumed_equals_uninterrupted(tmp_path):
    """The first 25 s of the real RAV4 minute as candump lines, crashed mid-stream and resumed
    from a checkpoint file: the gridder's state goes through its public API."""
    from fdikit.io.decode import read_blf_table

    from .test_follow_candump import wheel_difference_monitor

    cfg = wheel_difference_monitor(tmp_path, DATA / "toyota_rav4.dbc")
    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    keep = np.flatnonzero(ts - ts[0] <= 25.0)
    lines = [f"({ts[k]:.6f}) can0 {ids[k]:03X}#{pay[k].hex().upper()}\n" for k in keep]
    lines[40] = "not a frame\n"
    ref = list(LiveMonitor(cfg).records(iter(lines)))
    assert sum(r.get("kind") == "onset" for r in ref) >= 1 and ref[0]["line"] == 41
    onset = next(r for r in ref if r.get("kind") == "onset")
    # checkpoints every 250 samples; the crash comes 0.5 s after the first onset, which the crashed
    # run had written after its last checkpoint
    crash = int(np.searchsorted(ts[keep] - ts[0], onset["t"] + 0.5))
    got, after = _crash_and_resume(cfg, lines, 250, crash, True, tmp_path)
    assert after >= 1 and onset["sample"] > 250
    assert got == ref
    assert not any(math.isnan(r.get("t", 0.0)) for r in got)
