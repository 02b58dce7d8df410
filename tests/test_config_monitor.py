"""Config-driven monitors: fdikit design, fdikit monitor (batch, follow), config validation."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit import DataError
from fdikit.faults import Bias
from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log
from fdikit.systems import two_mass

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "two-mass" / "monitor.toml"


def cli(*args, stdin=None):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *map(str, args)], capture_output=True,
                          text=True, input=stdin, timeout=600)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cfg")
    shutil.copy(EXAMPLE, d / "monitor.toml")
    out = cli("design", d / "monitor.toml", "--json")
    assert out.returncode == 0, out.stderr
    arts = json.loads(out.stdout)["artifacts"]
    assert set(arts) == {"observer", "hold"} and all(Path(p).exists() for p in arts.values())
    s = two_mass.record([Bias("sensor:pos2", 0.012, start=4.0)], 1, 5)
    df = pd.DataFrame({"time": s.t, "F": s["force"][0], "P1": 1000 * s["pos1"][0], "P2": 1000 * s["pos2"][0]})
    df.loc[150, "P1"] = np.nan           # a dropout: flagged and held, not fatal
    df.to_csv(d / "log.csv", index=False)
    return d


def test_batch_monitor_detects_and_writes_outputs(workdir):
    out = cli("monitor", workdir / "log.csv", "--config", workdir / "monitor.toml", "--json",
              "--events", workdir / "ev.jsonl", "--stats", workdir / "st.parquet")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1
    summary = json.loads(lines[0])
    assert summary["first_event"]["hypothesis"] == "sensor:pos2"
    assert 4.0 < summary["first_event"]["t"] < 4.5 and summary["n_events"] >= 1
    assert summary["invalid_samples"] == 1
    events = [json.loads(x) for x in (workdir / "ev.jsonl").read_text().splitlines()]
    assert events[0]["invalid"].startswith("channel 'pos1' has a non-finite value at sample 150")
    stats = pd.read_parquet(workdir / "st.parquet")
    assert {"t", "r:pos1", "r:pos2", "r:pos1:alarm", "valid"} <= set(stats.columns)
    assert not stats["valid"][150] and stats["valid"].sum() == len(stats) - 1
    assert np.isfinite(stats.drop(columns=["valid"]).to_numpy()).all()


def test_follow_mode_equals_batch(workdir):
    out = cli("monitor", workdir / "log.csv", "--config", workdir / "monitor.toml", "--events",
              workdir / "ev_follow_ref.jsonl")
    assert out.returncode == 0, out.stderr
    batch = [json.loads(x) for x in (workdir / "ev_follow_ref.jsonl").read_text().splitlines()]
    out = cli("monitor", "-", "--config", workdir / "monitor.toml", "--follow",
              stdin=(workdir / "log.csv").read_text())
    assert out.returncode == 0, out.stderr
    follow = [json.loads(x) for x in out.stdout.splitlines()]
    key = [(e.get("hypothesis"), e.get("invalid"), e["t"]) for e in batch]
    assert [(e.get("hypothesis"), e.get("invalid"), e["t"]) for e in follow] == key
    # and the statistics themselves: stream through the Python API against the batch run
    cfg = load_config(workdir / "monitor.toml")
    sig = map_channels(cfg, read_log(cfg, workdir / "log.csv"))
    a, b = build_monitor(cfg).run(sig), build_monitor(cfg).stream(sig)
    np.testing.assert_array_equal(a.statistics.values, b.statistics.values)


@pytest.mark.parametrize("text, match", [
    ("[channels.a]\nsource = 1\n[[generators]]\nartifact = 'x'\n", r"\[channels.a\].source must be str"),
    ("[channels.a]\nsorce = 'a'\n[[generators]]\nartifact = 'x'\n", "unknown key 'sorce'"),
    ("[chanels.a]\n", r"unknown section \[chanels\]"),
    ("[channels.a]\n", r"at least one \[\[generators\]\]"),
    ("[channels.a]\nscale = 0.0\n[[generators]]\nartifact = 'x'\n", "scale must be finite and non-zero"),
    ("[monitor]\non_invalid = 'ignore'\n[channels.a]\n[[generators]]\nartifact = 'x'\n", "on_invalid"),
    ("[channels.a\n", "not valid TOML"),
    ("[channels.a]\n[[generators]]\nartefact = 'x'\n", "unknown key 'artefact'"),
])
def test_bad_configs(tmp_path, text, match):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(DataError, match=match):
        load_config(p)


def test_artifact_for_other_channels_is_refused(workdir, tmp_path):
    text = (workdir / "monitor.toml").read_text().replace("[channels.pos2]", "[channels.height]")
    text = text.replace('artifacts = "designs"', f'artifacts = "{workdir / "designs"}"')
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(DataError, match=r"reads channels \['pos2'\] that the config does not define"):
        build_monitor(load_config(p))
    out = cli("monitor", workdir / "nope.csv", "--config", p)
    assert out.returncode == 2 and "no such log file" in out.stderr
