"""Live CAN: FrameGridder (frames -> grid as they arrive) equals the batch loader, and
``fdikit monitor --follow`` on candump lines equals the batch run on the same candump log."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError
from fdikit.io import read_log
from fdikit.io.can import _read_frames
from fdikit.io.stream import FrameGridder, parse_candump_line

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rav4-highway"
BLF = DATA / "drive.blf"
DBC = DATA / "toyota_rav4.dbc"
needs_data = pytest.mark.skipif(not BLF.exists(), reason=f"real RAV4 data not found at {DATA}")
SIGNALS = ["SPEED.SPEED", "KINEMATICS.YAW_RATE", "WHEEL_SPEEDS.WHEEL_SPEED_FL",
           "WHEEL_SPEEDS.WHEEL_SPEED_FR", "STEER_ANGLE_SENSOR.STEER_ANGLE"]


def stream_all(g, ts, ids, data, buses=None):
    out = []
    for k in range(len(ts)):
        out += g.push(ts[k], ids[k], data[k], None if buses is None else buses[k])
    return out + g.flush()


@pytest.fixture(scope="module")
def frames():
    if not BLF.exists():
        pytest.skip(f"real RAV4 data not found at {DATA}")
    return _read_frames(BLF)


@needs_data
@pytest.mark.parametrize("method", ["linear", "previous"])
def test_gridder_equals_batch_loader_bitwise(frames, method):
    ts, ids, data = frames
    batch = read_log(BLF, DBC, SIGNALS, rate=50.0, method=method)
    out = stream_all(FrameGridder(DBC, SIGNALS, 50.0, method=method), ts, ids, data)
    assert len(out) == batch.n_samples
    assert np.array_equal([o[0] for o in out], batch.t)
    V = np.array([[o[1][s] for s in SIGNALS] for o in out])
    assert np.array_equal(V, batch.values[0])  # the same arithmetic, not just close
    assert all(o[2] is None for o in out) and batch.valid.all()


@needs_data
def test_gridder_gap_and_bad_frames_flagged_like_batch(frames, tmp_path):
    """Drop 1.5 s of the wheel-speed message and corrupt one speed frame (a 1-byte payload):
    the stream flags exactly the grid samples the batch loader flags, with a reason."""
    from fdikit.io.formats import frames_to_signals

    ts, ids, data = frames
    fid_w = 0xAA  # WHEEL_SPEEDS
    t_rel = ts - ts[0]
    keep = ~((ids == fid_w) & (t_rel > 20.0) & (t_rel < 21.5))
    ts2, ids2 = ts[keep], ids[keep]
    data2 = [data[k] for k in np.flatnonzero(keep)]
    k_bad = int(np.flatnonzero((ids2 == 0xB4) & (ts2 - ts2[0] > 30.0))[0])  # SPEED
    data2[k_bad] = b"\x00"
    batch = frames_to_signals(ts2, ids2, data2, DBC, SIGNALS, 50.0)
    out = stream_all(FrameGridder(DBC, SIGNALS, 50.0), ts2, ids2, data2)
    assert len(out) == batch.n_samples
    bad_stream = np.array([o[2] is not None for o in out])
    bad_batch = ~batch.valid[0].all(axis=1)
    assert bad_batch.sum() > 70  # the gap (~75 samples) and the corrupt frame
    assert np.array_equal(bad_stream, bad_batch)
    reasons = " ".join(o[2] for o in out if o[2])
    assert "WHEEL_SPEEDS.WHEEL_SPEED_FL: no frame for" in reasons and "SPEED.SPEED: undecodable" in reasons
    V = np.array([[o[1][s] for s in SIGNALS] for o in out])
    ok = ~bad_batch
    assert np.array_equal(V[ok], batch.values[0][ok])


def test_gridder_refuses_bad_input():
    db_text = 'VERSION ""\nBO_ 180 SPEED: 8 XXX\n SG_ SPEED : 47|16@0+ (0.01,0) [0|250] "km/h" XXX\n'
    import cantools

    db = cantools.database.load_string(db_text, database_format="dbc")
    with pytest.raises(DataError, match="rate must be a positive"):
        FrameGridder(db, ["SPEED.SPEED"], 0.0)
    with pytest.raises(DataError, match="NOPE"):
        FrameGridder(db, ["SPEED.NOPE"], 10.0)
    g = FrameGridder(db, ["SPEED.SPEED"], 10.0)
    g.push(1.0, 180, bytes(8), "can0")
    with pytest.raises(DataError, match="several buses"):
        g.push(1.1, 180, bytes(8), "can1")
    with pytest.raises(DataError, match="time goes backwards"):
        g.push(0.5, 180, bytes(8), "can0")
    with pytest.raises(DataError, match="line 7 is not a frame"):
        parse_candump_line("garbage here", 7)
    with pytest.raises(DataError, match="odd number of hex digits"):
        parse_candump_line("(1.0) can0 0B4#123", 3)
    assert parse_candump_line("  ") is None
    assert parse_candump_line("(2.5) vcan0 1A0#R") == (2.5, "vcan0", 0x1A0, b"")
    assert parse_candump_line("(2.5) can0 0B4#00FF R") == (2.5, "can0", 0xB4, b"\x00\xff")


# ---------------------------------------------------------------- end to end: fdikit monitor --follow
CONFIG = """
[monitor]
name = "RAV4 wheel-speed difference"
artifacts = "designs"
on_invalid = "hold"

[log]
format = "can"
dbc = "{dbc}"
rate = 50

[channels.speed]
source = "SPEED.SPEED"
unit = "km/h"

[channels.wfl]
source = "WHEEL_SPEEDS.WHEEL_SPEED_FL"
unit = "km/h"

[channels.wfr]
source = "WHEEL_SPEEDS.WHEEL_SPEED_FR"
unit = "km/h"

[[generators]]
artifact = "diff"

[[processors]]
artifact = "hold"

[decision]
channels = ["r:diff:alarm"]
names = {{ "r:diff:alarm" = "front wheels differ" }}
"""


def wheel_difference_monitor(folder, dbc) -> Path:
    """A config and its designs in ``folder``: a first-order low-passed front wheel-speed
    difference (km/h) held over 0.3 for 5 samples; its real excursions in the RAV4 minute's
    curves give announcements to compare. Returns the config's path."""
    from fdikit.detect import Hold
    from fdikit.monitor import save_artifact
    from fdikit.residuals import FilterDesign

    a = float(np.exp(-0.02 / 0.2))
    diff = FilterDesign(np.array([[a]]), np.zeros((1, 1)), np.array([[1 - a, -(1 - a)]]), np.ones((1, 1)),
                        np.zeros((1, 1)), np.zeros((1, 2)), 0.02, ["speed"], ["wfl", "wfr"], ["r:diff"])
    (folder / "designs").mkdir()
    save_artifact(folder / "designs" / "diff", diff)
    save_artifact(folder / "designs" / "hold", Hold(["r:diff"], 0.3, Z=5))
    cfg = folder / "m.toml"
    cfg.write_text(CONFIG.format(dbc=Path(dbc).resolve().as_posix()))
    return cfg


def cli(*args, stdin=None):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, input=stdin, timeout=600)


@needs_data
def test_follow_candump_equals_batch(tmp_path, frames):
    import can

    wheel_difference_monitor(tmp_path, DBC)
    with can.CanutilsLogWriter(str(tmp_path / "drive.log")) as w:
        for m in can.LogReader(str(BLF)):
            w.on_message_received(m)
    out = cli("monitor", tmp_path / "drive.log", "--config", tmp_path / "m.toml", "--json",
              "--events", tmp_path / "ev.jsonl")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["n_events"] >= 1, summary
    batch = [json.loads(x) for x in (tmp_path / "ev.jsonl").read_text().splitlines()]
    text = (tmp_path / "drive.log").read_text()
    text = text.replace(text.splitlines()[5], "this line is not a frame", 1)  # one garbled line
    ls = text.splitlines()
    ls.insert(20, "(0.000001) can0 0B4#0000000000000000")  # an extra frame whose time goes back
    text = "\n".join(ls) + "\n"
    fol = cli("monitor", "-", "--config", tmp_path / "m.toml", "--follow", stdin=text)
    assert fol.returncode == 0, fol.stderr
    follow = [json.loads(x) for x in fol.stdout.splitlines()]
    assert follow[0]["line"] == 6 and "not a frame" in follow[0]["invalid"]
    assert follow[1]["line"] == 21 and "time goes backwards" in follow[1]["invalid"]
    # the garbled line was an early frame of a message sent at >= 50 Hz: the grid is unchanged
    got = [(e["hypothesis"], e["sample"], e["t"], e["value"]) for e in follow[2:]]
    want = [(e["hypothesis"], e["sample"], e["t"], e["value"]) for e in batch]
    assert got == want


@needs_data
def test_follow_candump_bad_lines_flagged_and_stream_continues(tmp_path, frames):
    """A live stream with a garbled line, a frame whose time goes back, a truncated payload and an
    unparsable time: each is reported (line number and reason), none stops the stream, and the
    grid the monitor sees equals the batch loader's on the log without the refused lines."""
    import can

    from fdikit.io.formats import read_candump

    with can.CanutilsLogWriter(str(tmp_path / "drive.log")) as w:
        for m in can.LogReader(str(BLF)):
            w.on_message_received(m)
    lines = (tmp_path / "drive.log").read_text().splitlines()
    k_speed = next(i for i in range(2000, len(lines)) if " 0B4#" in lines[i])
    bad = dict(lines=list(lines))
    bad["lines"][1000] = "(12x.5) can0 0B4#00"                       # unparsable time
    bad["lines"][1500] = "(0.000001) can0 0B4#0000000000000000"      # time goes back
    bad["lines"][k_speed] = bad["lines"][k_speed].split("#")[0] + "#00"  # truncated SPEED payload
    text = "\n".join(bad["lines"]) + "\n"
    g = FrameGridder(DBC, ["SPEED.SPEED", "KINEMATICS.YAW_RATE"], 50.0)
    reports, out = [], []
    for i, line in enumerate(text.splitlines(), start=1):
        try:
            fr = parse_candump_line(line, i)
            if fr is not None:
                out += g.push(fr[0], fr[2], fr[3], fr[1])
        except DataError as exc:
            reports.append((i, str(exc)))
    out += g.flush()
    assert [r[0] for r in reports] == [1001, 1501]
    assert "not a frame" in reports[0][1] and "time goes backwards" in reports[1][1]
    # reference: the batch reader on the same log without the two refused lines
    keep = [ln for i, ln in enumerate(bad["lines"]) if i not in (1000, 1500)]
    (tmp_path / "ref.log").write_text("\n".join(keep) + "\n")
    ref = read_candump(tmp_path / "ref.log", DBC, ["SPEED.SPEED", "KINEMATICS.YAW_RATE"], 50.0)
    V = np.array([[o[1]["SPEED.SPEED"], o[1]["KINEMATICS.YAW_RATE"]] for o in out])
    flagged = np.array([o[2] is not None for o in out])
    assert np.array_equal(flagged, ~ref.valid[0].all(axis=1)) and flagged.sum() >= 1
    assert np.array_equal(V[~flagged], ref.values[0][~flagged])
    assert all("SPEED.SPEED: undecodable" in o[2] for o in out if o[2])
