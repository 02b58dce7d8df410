"""Checkpoint and restore: a monitor stopped mid-record, saved, restored in a new process and
continued gives the same outputs as an uninterrupted run."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.detect import GLRT, MHSSPT, Hold, TimeGated, UniformMeanGaussian
from fdikit.model import LinearFaultModel
from fdikit.monitor import Decision, Monitor, load_state, save_state
from fdikit.residuals import ObserverResidual, design_observer_residual

DT = 0.01


def build_monitor(**options) -> Monitor:
    A = [[0, 1, 0, 0], [-2, -0.4, 1, 0], [0, 0, 0, 1], [1, 0, -1, -0.3]]
    plant = LinearFaultModel(A, [[0], [1], [0], [0]], [[1, 0, 0, 0], [0, 0, 1, 0]],
                             inputs=["force"], outputs=["pos1", "pos2"])
    gen = ObserverResidual(design_observer_residual(plant, dt=DT, Q=np.eye(4) * 1e-8, R=np.eye(2) * 4e-6))
    glrt = GLRT(gen.output_names, mu0=0.0, sigma2=4e-6, W=20)
    hold = Hold(glrt.output_names, 30.0, Z=3, absolute=False)
    gate = TimeGated(glrt.output_names, q=30.0, T=1.0)
    mh = MHSSPT(["r:pos2"], {"ok": UniformMeanGaussian([0], [0], [0.002]),
                             "bias": UniformMeanGaussian([0.005], [0.05], [0.002])}, p=1e-3, q=1e-4)
    return Monitor([gen], [glrt, hold, gate, mh],
                   Decision(["r:pos2:glrt:alarm", "P:bias"], level=0.9), **options)


def record(runs=2, T=800, seed=3) -> Signals:
    rng = np.random.default_rng(seed)
    t = np.arange(T) * DT
    # a sampled plant response is not needed for the check: any finite record exercises the state
    u = np.sin(0.7 * t)
    y = 0.002 * rng.standard_normal((runs, T, 2))
    y[:, 400:, 1] += 0.02
    v = np.concatenate([np.broadcast_to(u[None, :, None], (runs, T, 1)), y], axis=2)
    return Signals(t, v, ["force", "pos1", "pos2"])


def test_state_round_trip_in_process(tmp_path):
    sig = record()
    full = build_monitor().stream(sig)
    mon = build_monitor()
    mon.reset(sig.runs)
    half = 350
    for k in range(half):
        mon.step(float(sig.t[k]), sig.values[:, k], sig.names)
    mon.save_checkpoint(tmp_path / "ck.npz")
    other = build_monitor()
    other.load_checkpoint(tmp_path / "ck.npz")
    R = []
    S = []
    for k in range(half, sig.n_samples):
        r, s, _ = other.step(float(sig.t[k]), sig.values[:, k], sig.names)
        R.append(r)
        S.append(s)
    np.testing.assert_array_equal(np.stack(R, 1), full.residuals.values[:, half:])
    np.testing.assert_array_equal(np.stack(S, 1), full.statistics.values[:, half:])
    assert full.events, "the record should raise alarms after the bias"


def test_restore_in_a_new_process(tmp_path):
    """Checkpoint, 'kill' (the process ends), restore in a fresh interpreter, continue."""
    sig = record(runs=1)
    np.savez(tmp_path / "rec.npz", t=sig.t, v=sig.values)
    here = Path(__file__).resolve().parent
    code = f"""
import sys, json, numpy as np
sys.path.insert(0, {str(here)!r})
from test_checkpoint import build_monitor
z = np.load({str(tmp_path / 'rec.npz')!r}); t, v = z["t"], z["v"]
names = ["force", "pos1", "pos2"]
mon = build_monitor()
stage = sys.argv[1]
if stage == "first":
    mon.reset(1)
    for k in range(500):
        mon.step(float(t[k]), v[:, k], names)
    mon.save_checkpoint({str(tmp_path / 'ck.npz')!r})
else:
    mon.load_checkpoint({str(tmp_path / 'ck.npz')!r})
    out = [mon.step(float(t[k]), v[:, k], names)[1][0].tolist() for k in range(500, len(t))]
    print(json.dumps(out))
"""
    for stage in ("first", "second"):
        res = subprocess.run([sys.executable, "-c", code, stage], capture_output=True, text=True,
                             timeout=300)
        assert res.returncode == 0, res.stderr
    resumed = np.array(json.loads(res.stdout))
    full = build_monitor().stream(sig).statistics.values[0, 500:]
    np.testing.assert_allclose(resumed, full, rtol=0, atol=1e-12)


def test_mismatch_and_corrupt_checkpoint(tmp_path):
    mon = build_monitor()
    mon.reset(1)
    state = mon.state()
    state["channels"]["inputs"] = ["force", "pos1", "speed"]
    with pytest.raises(DataError, match="checkpoint is for a monitor with channels"):
        build_monitor().restore(state)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(DataError, match="not a readable fdikit checkpoint"):
        build_monitor().load_checkpoint(bad)
    save_state(tmp_path / "other.npz", {"x": 1}, meta={"kind": "Something"})
    with pytest.raises(DataError, match="not a Monitor checkpoint"):
        build_monitor().load_checkpoint(tmp_path / "other.npz")


def test_state_file_round_trip_types(tmp_path):
    state = {"a": np.arange(6.0).reshape(2, 3), "b": (np.zeros(2, bool), 3), "c": None, "d": float("inf"),
             "e": [1, 2.5, "x"], "f": np.int64(4), "g": {"h": np.ones(1)}}
    save_state(tmp_path / "s.npz", state)
    back, _ = load_state(tmp_path / "s.npz")
    np.testing.assert_array_equal(back["a"], state["a"])
    assert back["b"][0].dtype == bool and back["b"][1] == 3 and back["c"] is None
    assert back["d"] == float("inf") and back["e"] == [1, 2.5, "x"] and back["f"] == 4
    np.testing.assert_array_equal(back["g"]["h"], [1.0])
    # the atomic write leaves no temporary file behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.npz"]


def test_batch_equals_streaming_with_time_gated_and_mhsspt():
    sig = record()
    a = build_monitor().run(sig)
    b = build_monitor().stream(sig)
    np.testing.assert_array_equal(a.statistics.values, b.statistics.values)
    assert a.events == b.events


def test_an_infinite_sample_is_held_in_streaming_as_in_batch_without_max_abs():
    """max_abs=None switches off the magnitude limit, not the finiteness check: +inf and -inf are
    held in streaming as in batch (the streaming screen compared the largest |x| with an infinite
    limit, and inf <= inf let +inf reach the filters)."""
    sig = record(runs=1, T=300)
    v = sig.values.copy()
    v[0, 150, 1] = np.inf
    v[0, 160, 2] = -np.inf
    bad = Signals(sig.t, v, sig.names, check=False)
    stream = build_monitor(max_abs=None, on_invalid="hold").stream(bad)
    assert not np.isinf(stream.residuals.values).any()
    assert stream.status[0, 150] != 0 and stream.status[0, 160] != 0
    with pytest.raises(DataError, match="non-finite value at sample 150"):
        build_monitor(max_abs=None).stream(bad)
