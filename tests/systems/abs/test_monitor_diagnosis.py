"""Issue 16, item 4 (ABS): the ABS config monitor announces its diagnosis -- one episode per fault,
naming the fault class by the D-matrix decision of its tests -- instead of its test firings; and
the generic processor behind it, :class:`fdikit.isolate.DMatrixDecision`."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit import Signals
from fdikit.errors import DataError, ModelError
from fdikit.isolate import DMatrix, DMatrixDecision
from fdikit.monitor import load_artifact, save_artifact

EXAMPLES = Path(__file__).parents[3] / "examples"
TESTS = ["r1:glrt:alarm", "r3:glrt:alarm", "r4:glrt:alarm", "r3:glrt:alarm:gated", "r4:glrt:alarm:gated"]


# ----------------------------------------------------------------------------- the processor
def _dm():
    return DMatrix(["F0", "A", "B", "C", "D"], ["t1", "t2", "t3"],
                   [[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 0], [0, 1, 1]],
                   pd=[[0.0] * 3, [0.9, 0.0, 0.0], [0.9, 0.8, 0.0], [0.9, 0.8, 0.0], [0.0, 0.7, 0.95]],
                   pf=0.0)


def _alarms(rng, T=400):
    a = np.zeros((3, T, 3))
    a[0, 50:80, 0] = 1            # run 0: t1 alone -> A
    a[1, 40:60, 0] = 1            # run 1: t1, then t2 within the settling time, and intermittently
    a[1, 55:58, 1] = a[1, 90:95, 1] = 1   # -> B|C (identical rows)
    a[2, 100:300, 1] = 1          # run 2: t2 and t3 -> D, with a size channel
    a[2, 120:300, 2] = 1
    size = np.zeros((3, T, 1))
    size[2] = rng.normal(0.3, 0.01, (T, 1))
    return Signals(np.arange(T) * 0.01, np.concatenate([a, size], axis=2), ["a1", "a2", "a3", "eta"])


def test_dmatrix_decision_decides_once_per_episode_batch_equals_streaming():
    d = DMatrixDecision(_dm(), ["a1", "a2", "a3"], settle=20, sizes={"D": "eta"})
    assert d.groups == [("A",), ("B", "C"), ("D",)]
    assert d.output_names == ["fault:A", "fault:B|C", "fault:D", "fault:D:size"]
    assert d.announce == {"fault:A": "A", "fault:B|C": "B|C", "fault:D": "D"}
    assert d.size_channels == {"fault:D": "fault:D:size"}
    sig = _alarms(np.random.default_rng(0))
    out = d.run(sig)
    v = out.values
    # each run decides exactly once, 20 samples after its last new test, and holds the decision
    first = [int(np.argmax(v[r, :, :3].sum(axis=1) > 0)) for r in range(3)]
    assert first == [50 + 20, 55 + 20, 120 + 20]
    assert (v[0, 70:, 0] > 0.5).all() and (v[0, :, 1:3] == 0).all()
    assert (v[1, 75:, 1] > 0.99).all() and (v[1][:, [0, 2]] == 0).all()
    assert (v[2, 140:, 2] > 0.99).all()
    np.testing.assert_allclose(v[2, 140:, 3], sig.values[2, 140, 3])      # the size at the decision
    # posterior: an independent computation of the likelihood over the rows (F0 excluded)
    p = np.clip(_dm().fail_probability()[1:], 1e-6, 1 - 1e-6)
    o = np.array([1.0, 0.0, 0.0])
    lik = np.exp(o @ np.log(p).T + (1 - o) @ np.log1p(-p).T)
    assert v[0, -1, 0] == pytest.approx(lik[0] / lik.sum(), rel=1e-12)
    # streaming, with a checkpoint half way
    d2 = DMatrixDecision(_dm(), ["a1", "a2", "a3"], settle=20, sizes={"D": "eta"})
    d2.reset(3)
    S = []
    for k in range(sig.n_samples):
        if k == 200:
            state = d2.get_state()
            d2 = DMatrixDecision.from_dict(d2.to_dict())
            d2.reset(3)
            d2.set_state(state)
        S.append(d2.step(sig.values[:, k]))
    np.testing.assert_array_equal(np.stack(S, 1), v)


def test_dmatrix_decision_clears_and_decides_again():
    d = DMatrixDecision(_dm(), ["a1", "a2", "a3"], settle=5, clear=30)
    a = np.zeros((1, 200, 3))
    a[0, 10:20, 0] = 1                 # episode 1: A
    a[0, 100:120, 1:] = 1              # episode 2 (after 80 quiet samples): D
    v = d.run(Signals(np.arange(200) * 0.01, a, ["a1", "a2", "a3"])).values[0]
    assert v[15:49, 0].min() > 0.5 and v[49:100].max() == 0         # cleared at the 30th quiet sample
    assert v[105:149, 2].min() > 0.99 and v[149:].max() == 0 and v[105:, 0].max() == 0


def test_dmatrix_decision_is_an_artifact_and_refuses_bad_input(tmp_path):
    d = DMatrixDecision(_dm(), ["a1", "a2", "a3"], settle=7, sizes={"B": "eta"})
    back = load_artifact(save_artifact(tmp_path / "diag", d))
    assert back.to_dict() == d.to_dict() and back.output_names == d.output_names
    with pytest.raises(ModelError, match="2 alarm channels .* for the 3 tests"):
        DMatrixDecision(_dm(), ["a1", "a2"])
    with pytest.raises(ModelError, match="sizes name rows \\['Z'\\]"):
        DMatrixDecision(_dm(), ["a1", "a2", "a3"], sizes={"Z": "eta"})
    d.reset(1)
    with pytest.raises(DataError, match="input channel 'a2' is not finite"):
        d.step([0.0, np.nan, 0.0, 0.0])
    assert not d.get_state()["_fired"].any()          # the bad sample did not touch the state


# ----------------------------------------------------------------------------- the ABS config monitor
def _abs_csv(path, fault, magnitude, seed):
    from fdikit.systems.abs.plant import Scenario, simulate

    res = simulate(None, Scenario(fault, magnitude=magnitude), runs=1, seed=seed)
    pd.DataFrame({"time": res.u.t, "P_m": 10.0 * res.u["P_m"][0], "u_in": res.u["u_in"][0],
                  "u_out": res.u["u_out"][0], "omega_w": res.y["omega_w"][0],
                  "omega_v": res.y["omega_v"][0]}).to_csv(path, index=False)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def abs_config(tmp_path_factory):
    d = tmp_path_factory.mktemp("abs")
    shutil.copy(EXAMPLES / "abs" / "monitor.toml", d / "monitor.toml")
    out = cli("design", d / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    assert "diagnosis" in json.loads(out.stdout)["artifacts"]
    _abs_csv(d / "rw.csv", "F2.2", -0.25, seed=11)
    _abs_csv(d / "nom.csv", "F0", None, seed=101)
    return d


def test_single_rw_fault_gives_one_diagnosis_naming_its_class(abs_config):
    d = abs_config
    out = cli("monitor", d / "rw.csv", "--config", d / "monitor.toml", "--json", "--events", d / "ev.jsonl",
              "--stats", d / "st.parquet")
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    assert s["n_events"] == 1, s["events"]
    e = s["events"][0]
    assert e["hypothesis"] == "F2.2" and e["kind"] == "onset" and e["episode"] == 0
    assert 0.5 < e["value"] <= 1.0                         # the posterior probability of F2.2
    assert 0.5 < e["t"] < 4.0                              # braking starts at 0.5 s
    # the tests themselves fired (and re-armed) several times: what used to be announced
    st = pd.read_parquet(d / "st.parquet")
    on = st[TESTS].to_numpy() > 0.5
    firings = int(on[0].sum() + (on[1:] & ~on[:-1]).sum())
    assert firings >= 5, firings
    recs = [json.loads(x) for x in (d / "ev.jsonl").read_text().splitlines()]
    assert [r["hypothesis"] for r in recs if r.get("announcement")] == ["F2.2"]
    # follow mode gives the same records
    f = cli("monitor", d / "rw.csv", "--config", d / "monitor.toml", "--follow", "--events", d / "fo.jsonl")
    assert f.returncode == 0, f.stderr
    assert (d / "fo.jsonl").read_text() == (d / "ev.jsonl").read_text()


def test_nominal_abs_stop_announces_nothing(abs_config):
    d = abs_config
    out = cli("monitor", d / "nom.csv", "--config", d / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["n_events"] == 0


def test_decision_processor_must_be_a_processor_that_announces(tmp_path, abs_config):
    from fdikit.monitor.config import build_monitor, load_config

    text = (abs_config / "monitor.toml").read_text()
    p = abs_config / "other.toml"
    p.write_text(text.replace('processor = "diagnosis"', 'processor = "hold_r1"'))
    with pytest.raises(DataError, match="'hold_r1' is a Hold, which announces nothing"):
        build_monitor(load_config(p))
    p.write_text(text.replace('processor = "diagnosis"', 'processor = "nothing"'))
    with pytest.raises(DataError, match="is not one of the \\[\\[processors\\]\\] artifacts"):
        load_config(p)
