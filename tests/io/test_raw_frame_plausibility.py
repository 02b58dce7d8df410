"""Issue 27 item 4: plausibility on the raw frames, before resampling, and the log's clock.

On the real RAV4 minute written back to BLF files with python-can: one frame with a 120 deg/s yaw
rate is refused on its own (one implausible frame, the grid samples it touches flagged, no
announcement of the monitor); a clock jump forward is a gap the monitor sees as one; a clock step
back splits the log into two segments, both judged, with the break listed.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
BLF, DBC = DATA / "drive.blf", DATA / "toyota_rav4.dbc"
EXAMPLE = ROOT / "examples" / "rav4-lateral" / "monitor.toml"
pytestmark = pytest.mark.skipif(not BLF.exists(), reason=f"RAV4 data not found at {DATA}")
YAW = "KINEMATICS.YAW_RATE"
SIGNALS = ["STEER_ANGLE_SENSOR.STEER_ANGLE", "STEER_ANGLE_SENSOR.STEER_FRACTION", "SPEED.SPEED", YAW,
           "KINEMATICS.ACCEL_Y", "WHEEL_SPEEDS.WHEEL_SPEED_FL", "WHEEL_SPEEDS.WHEEL_SPEED_FR",
           "WHEEL_SPEEDS.WHEEL_SPEED_RL", "WHEEL_SPEEDS.WHEEL_SPEED_RR"]


@pytest.fixture(scope="module")
def msgs():
    import can

    return list(can.LogReader(str(BLF)))


def _write(msgs, path, edit=None):
    import can

    with can.BLFWriter(str(path)) as w:
        for i, m in enumerate(msgs):
            m2 = edit(i, m) if edit else m
            if m2 is not None:
                w.on_message_received(m2)
    return path


def _copy(m, **kw):
    import can

    a = {"timestamp": m.timestamp, "arbitration_id": m.arbitration_id, "data": bytes(m.data),
         "is_extended_id": m.is_extended_id, "channel": m.channel}
    a.update(kw)
    return can.Message(**a)


@pytest.fixture(scope="module")
def spiked(msgs, tmp_path_factory):
    """drive.blf with one KINEMATICS frame (the first after 40 s) reading 120 deg/s."""
    import cantools

    db = cantools.database.load_file(str(DBC), strict=False)
    kin = db.get_message_by_name("KINEMATICS")
    t_first = msgs[0].timestamp
    k = next(i for i, m in enumerate(msgs)
             if m.arbitration_id == kin.frame_id and m.timestamp - t_first > 40.0)
    vals = kin.decode(bytes(msgs[k].data), decode_choices=False)
    vals["YAW_RATE"] = 120.0
    data = kin.encode(vals, strict=False)
    path = _write(msgs, tmp_path_factory.mktemp("spike") / "spike.blf",
                  lambda i, m: _copy(m, data=data) if i == k else m)
    return path, msgs[k].timestamp - t_first


def _shifted(msgs, path, after, dt):
    t_first = msgs[0].timestamp
    return _write(msgs, path, lambda i, m: _copy(m, timestamp=m.timestamp + dt)
                  if m.timestamp - t_first > after else m)


@pytest.mark.parametrize("rule", [{"spike": 8.0}, {"min": -100.0, "max": 100.0}])
def test_a_single_frame_spike_is_one_implausible_frame(spiked, rule):
    from fdikit.io import read_log

    path, t_spike = spiked
    plain = read_log(path, DBC, SIGNALS, rate=50.0)
    assert plain.valid.all()  # today: spread over two grid samples, both in range
    s = read_log(path, DBC, SIGNALS, rate=50.0, plausibility={YAW: rule})
    q = s.info[YAW]
    assert q.n_implausible == 1 and q.n_nonfinite == 0
    bad = np.flatnonzero(~s.valid[0, :, s.names.index(YAW)])
    assert 1 <= bad.size <= 2 and np.all(np.abs(s.t[bad] - t_spike) < 0.02)
    assert s.valid[0][:, [i for i, n in enumerate(s.names) if n != YAW]].all()
    why = s.invalid_reason(int(bad[0]))
    assert "implausible source sample" in why and "119.976" in why
    assert ("spike" in why) == ("spike" in rule)


def test_the_spike_rule_works_on_a_quantised_signal():
    """41 of 50 increments zero: the scale comes from the moving ones, not 0."""
    from fdikit.io.formats.raw_checks import implausible_samples

    rng = np.random.default_rng(3)
    x = np.cumsum(np.where(rng.random(400) < 0.18, rng.choice([-0.244, 0.244], 400), 0.0))
    x[300] += 120.0
    bad, why = implausible_samples(np.arange(400) * 0.01, x, {"spike": 8.0})
    assert np.flatnonzero(bad).tolist() == [300] and "spike" in why[0]


def test_the_monitor_spike_rule_works_on_a_quantised_signal():
    from fdikit.monitor import Plausibility, PlausibilityChecker

    c = PlausibilityChecker(["y"], {"y": Plausibility(spike=8.0)}, max_abs=None)
    c.reset(1, dt=0.01)
    x = np.zeros(60)
    x[::5] = 0.244  # quantised: most increments are zero
    x = np.cumsum(x)
    for k, v in enumerate(x):
        assert c.check(k, k * 0.01, np.array([[v]])) is None
        c.observe(k * 0.01, np.array([[v]]), True)
    assert "spike" in c.check(60, 0.6, np.array([[x[-1] + 5.0]]))


def test_a_clock_jump_forward_is_a_gap(msgs, tmp_path):
    from fdikit.io import read_log

    s = read_log(_shifted(msgs, tmp_path / "jump.blf", 30.0, 2.0), DBC, SIGNALS, rate=50.0)
    assert s.valid.all()  # no run of NaN samples: the grid time jumps
    assert np.diff(s.t).max() > 2.0 and all(q.n_gaps == 1 for q in s.info.values())
    assert len(s.breaks) == 1 and "clock jump" in s.breaks[0][2] and s.n_segments == 1
    a, b, _ = s.breaks[0]
    assert 29.9 < a < 30.0 + 3 * 0.012 and 32.0 < b < 32.1  # the causal grid holds <= 3 periods


def test_a_clock_step_back_gives_two_segments_and_a_flag(msgs, tmp_path):
    from fdikit.io import read_log

    s = read_log(_shifted(msgs, tmp_path / "back.blf", 30.0, -0.5), DBC, SIGNALS, rate=50.0)
    assert s.n_segments == 2 and len(s.breaks) == 1
    a, b, why = s.breaks[0]
    assert "clock steps back by 0.49" in why and "new segment" in why
    assert s.valid.all()
    k = int(np.argmax(np.diff(s.t))) + 1
    assert s.t[k] == pytest.approx(b) and s.t[k - 1] == pytest.approx(a)
    assert k > 1400 and s.n_samples - k > 1400  # both segments on the grid (about 30 s each)
    # a shuffled log (a swap of two frames, a step back of milliseconds) is still refused
    from fdikit.errors import DataError

    swapped = list(msgs)
    swapped[1000], swapped[1001] = swapped[1001], swapped[1000]
    with pytest.raises(DataError, match="goes backwards"):
        read_log(_write(swapped, tmp_path / "swap.blf"), DBC, SIGNALS, rate=50.0)


# ------------------------------------------------------------------ the monitor on these logs
def _cli(*args):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=900, cwd=ROOT)


@pytest.fixture(scope="module")
def monitor():
    """The monitor of examples/rav4-lateral/monitor.toml, designed (its artifacts in a temp dir)."""
    import tempfile

    from fdikit.monitor.config import build_monitor, load_config

    tmp = Path(tempfile.mkdtemp(prefix="rav4cfg"))
    text = EXAMPLE.read_text().replace('dbc = "../../../shared/data/rav4-highway/toyota_rav4.dbc"',
                                       f'dbc = "{DBC.resolve()}"')
    (tmp / "monitor.toml").write_text(text)
    out = _cli("design", tmp / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    cfg = load_config(tmp / "monitor.toml")
    return cfg, build_monitor(cfg)


def _run(monitor, log):
    from fdikit.monitor.config import map_channels

    cfg, mon = monitor
    return mon.run(map_channels(cfg, log))


def test_the_monitor_announces_nothing_for_a_spike_frame_refused_before_resampling(spiked, monitor):
    from fdikit.io import read_log

    path, _t_spike = spiked
    res = _run(monitor, read_log(path, DBC, SIGNALS, rate=50.0, plausibility={YAW: {"spike": 8.0}}))
    assert res.events == []
    assert 1 <= len(res.invalid) <= 2


def test_the_monitor_holds_over_a_clock_jump_and_judges_both_segments(msgs, monitor, tmp_path):
    from fdikit.io import read_log
    from fdikit.monitor import STATUS_NAMES

    for dt in (2.0, -0.5):
        log = read_log(_shifted(msgs, tmp_path / f"j{dt}.blf", 30.0, dt), DBC, SIGNALS, rate=50.0)
        res = _run(monitor, log)
        assert len(res.gaps) == 1 and res.events == []
        k = int(np.argmax(np.diff(log.t))) + 1
        ok = STATUS_NAMES.index("ok")
        status = res.status[0]  # judged in both segments, warm-up again after the break
        assert (status[:k] == ok).any() and (status[k:] == ok).any() and status[k] != ok
        json.dumps([list(b) for b in log.breaks])


def test_follow_mode_cuts_a_clock_jump_as_the_batch_loader_does():
    """FrameGridder (follow mode) on the frames with a +2 s jump: the same grid times and values
    as the batch loader, the gap samples dropped, also across a checkpoint taken mid-gap."""
    from fdikit.io import FrameGridder, frames_to_signals
    from fdikit.io.can import _read_frame_table

    ts, ids, data = _read_frame_table(BLF)
    ts = np.where(ts > 30.0, ts + 2.0, ts)
    sig = ["STEER_ANGLE_SENSOR.STEER_ANGLE", "SPEED.SPEED", YAW, "WHEEL_SPEEDS.WHEEL_SPEED_FL"]
    batch = frames_to_signals(ts, ids, data, DBC, sig, rate=50.0)
    g = FrameGridder(DBC, sig, 50.0)
    out, saved = [], False
    for t, i, d in zip(ts, ids, data):
        out += g.push(t, int(i), bytes(d))
        if g._pending and not saved:  # a checkpoint while the gap run is held back
            h = FrameGridder(DBC, sig, 50.0)
            h.restore(json.loads(json.dumps(g.state())))
            g, saved = h, True
    out += g.flush()
    assert saved
    t = np.array([o[0] for o in out])
    v = np.array([[o[1][n] for n in sig] for o in out])
    assert np.array_equal(t, batch.t) and np.diff(t).max() > 2.0
    assert np.array_equal(v, batch.values[0]) and all(o[2] is None for o in out)
